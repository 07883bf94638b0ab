//! Hand kinematics: model data, per-finger forward kinematics and Jacobians, grasp map.
//!
//! Conventions (shared by the simulator and the controllers):
//! - World frame: z up, gravity along -z, the object (nominally a 10 cm cube) centred
//!   near the origin, the palm fixed above it and facing down.
//! - Joint vector of the whole hand is finger-major:
//!   `[f0.roll, f0.flex_prox, f0.flex_dist, f1.roll, ...]` ([`joint_index`]).
//! - Public API is `f32` in SI units; the forward kinematics of a single finger is also
//!   available generically over [`nalgebra::RealField`] so that checks can run in `f64`.

mod error;
mod finger;
mod grasp;
mod hand;
mod stacked;

pub use error::KinematicsError;
pub use grasp::grasp_map;
pub use hand::{
    FINGER_NAMES, FINGER_TORQUE_CAP_NM, FingerModel, HandModel, JOINT_NAMES, JOINTS_PER_FINGER, JointLimit,
    NOMINAL_BASE_RADIUS_M, NOMINAL_CUBE_SIDE_M, NOMINAL_PALM_HEIGHT_M, NUM_FINGERS, NUM_JOINTS,
    THUMB_TORQUE_CAP_NM, joint_index,
};
pub use stacked::Contact;
