//! Simulator crate of vge: a hand read from its description file ([`hands`], `vge_hand::Hand`)
//! and the objects it turns.
//!
//! The hand is described once, as data (an MJCF file), and every consumer (the rapier3d
//! world, the observation and action sizes, the in-grasp controllers) derives what it needs
//! from that data through the same forward kinematics, so the physics and the controllers
//! cannot disagree about where a fingertip is or how many there are.
//!
//! # Features
//! - `physics` (default): the rapier3d world and everything built on it ([`world`],
//!   [`objects`], [`env`], [`env_keys`], [`vec_env`], [`bench`], and [`mjcf`], the same task
//!   written for MuJoCo). Without it the crate is the hand description alone, with no rapier3d
//!   or rayon: the shipped hands ([`hands`]: geometry, joint limits and kinematics are
//!   `vge_hand::Hand`'s), the observation layout and its builder ([`observation`]), the
//!   action's default step ([`action`]), contact switches ([`gait`]), fingertip slip
//!   ([`slip`]) and [`rotation_about_z_rad`]; what the bridge needs to drive a real hand
//!   (`vge-bridge` without its `sim` feature).
//!
//! With `physics`, [`recording`] writes episodes as JSON Lines files (`vge eval --record`,
//! `vge-bridge run --record`) that the Python package shows in the Rerun viewer.

pub mod action;
pub mod angle;
#[cfg(feature = "physics")]
pub mod bench;
#[cfg(feature = "physics")]
pub mod env;
#[cfg(feature = "physics")]
pub mod env_keys;
pub mod episode;
pub mod error;
pub mod gait;
#[cfg(feature = "physics")]
mod grasp;
pub mod hands;
#[cfg(feature = "physics")]
pub mod mjcf;
#[cfg(feature = "physics")]
pub mod objects;
pub mod observation;
pub mod policy_interface;
#[cfg(feature = "physics")]
pub mod recording;
pub mod slip;
#[cfg(feature = "physics")]
pub mod vec_env;
#[cfg(feature = "physics")]
pub mod world;

pub use angle::rotation_about_z_rad;
#[cfg(feature = "physics")]
pub use env::{
    DomainRandomization, Env, EnvConfig, GraspConfig, NoiseConfig, PerturbationConfig, PrivilegedState,
    ResetInfo, StepInfo, StepResult, check_action,
};
#[cfg(feature = "physics")]
pub use env_keys::EnvSection;
pub use episode::{EpisodeOutcome, EpisodeTracker};
pub use error::SimError;
#[cfg(feature = "physics")]
pub use objects::{ObjectConfig, ObjectShape};
pub use observation::{
    FingertipReading, ObservationLayout, ObservationSet, Observer, ProprioHistory, build_observation,
};
pub use policy_interface::check_policy_interface;
#[cfg(feature = "physics")]
pub use recording::{EpisodeRecorder, RecordingError};
#[cfg(feature = "physics")]
pub use vec_env::VecEnv;
/// A joint's range of motion, as the hand's description and the servos give it.
pub use vge_hand::JointLimit;
#[cfg(feature = "physics")]
pub use world::{ContactReading, HandOrientation, HandWorld, JointServo, ObjectState, PhysicsConfig};
