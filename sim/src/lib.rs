//! Simulator crate of vge: the 15-DOF fingertip-grasp hand and its objects.
//!
//! The hand is described once, as data ([`kinematics::HandModel`]), and every consumer
//! (the rapier3d world, the in-grasp controllers) derives what it needs from that data
//! through the same forward kinematics, so the physics and the controllers cannot
//! disagree about where a fingertip is.

pub mod bench;
pub mod env;
pub mod error;
pub mod gait;
pub mod kinematics;
pub mod objects;
pub mod observation;
pub mod vec_env;
pub mod world;

pub use env::wrap_angle_rad;
pub use env::{
    DomainRandomization, Env, EnvConfig, GraspConfig, NoiseConfig, PerturbationConfig, PrivilegedState,
    ResetInfo, StepInfo, StepResult,
};
pub use error::SimError;
pub use kinematics::{
    Contact, FingerModel, HandModel, JOINTS_PER_FINGER, JointLimit, KinematicsError, NOMINAL_CUBE_SIDE_M,
    NUM_FINGERS, NUM_JOINTS, grasp_map,
};
pub use objects::{ObjectConfig, ObjectShape};
pub use observation::{FingertipReading, OBS_DIM, build_observation};
pub use vec_env::VecEnv;
pub use world::{ContactReading, HandWorld, ObjectState, PhysicsConfig};
