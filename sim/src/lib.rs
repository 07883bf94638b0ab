//! Simulator crate of vge: the 15-DOF fingertip-grasp hand and its objects.
//!
//! The hand is described once, as data ([`kinematics::HandModel`]), and every consumer
//! (the rapier3d world, the in-grasp controllers) derives what it needs from that data
//! through the same forward kinematics, so the physics and the controllers cannot
//! disagree about where a fingertip is.

pub mod kinematics;

pub use kinematics::{
    Contact, FingerModel, HandModel, JOINTS_PER_FINGER, JointLimit, KinematicsError, NOMINAL_CUBE_SIDE_M,
    NUM_FINGERS, NUM_JOINTS, grasp_map,
};
