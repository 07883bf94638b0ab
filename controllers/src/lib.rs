//! vge-controllers: the paper's sub-skill controllers that steer VGE's exploration: in-grasp manipulation
//! (IGM, [`igm`]), contact switching (CS, [`cs`]) and their superposition, finger-gaiting
//! (FG, [`fg`]); plus the contact-force QP of IGM's stability term ([`qp`]).
//!
//! Controllers run in training only, so they read privileged simulator state (the object
//! pose). They do not depend on the simulator's env types: the env's privileged state is
//! converted into a [`ControllerInput`] by one adapter,
//! [`ControllerInput::from_privileged`] ([`input`]), and every
//! controller is a function of that plus its own small state and a seeded rng.
//!
//! Conventions (those of [`vge_sim::kinematics`]): world frame, z up; joint vectors are
//! finger-major `[f0.roll, f0.flex_prox, f0.flex_dist, f1.roll, ...]`; the grasp map is
//! G (6 x 3k) with `w = G f` and `J_S dq = G^T do`. A controller's output is a change of
//! the joint *targets* for one control step (radians), the env's action.
//!
//! A crate of its own (sim <- controllers <- trainer) so that the controllers, `vge
//! controller`'s rollouts and their tests build and run without libtorch; the test command
//! checks that this crate and the bridge never depend on torch-sys.

pub mod cs;
pub mod fg;
pub mod igm;
pub mod input;
pub mod qp;
pub mod rollout;

use nalgebra::{UnitQuaternion, Vector3};
use thiserror::Error;
use vge_sim::{HandModel, KinematicsError, NUM_FINGERS, NUM_JOINTS};

pub use cs::{CsConfig, CsController, CsPlan, CsProfile};
pub use fg::FgController;
pub use igm::{ForceScaling, ForceSelection, IgmConfig, IgmController, IgmOutput, TipContact, igm_step};
pub use qp::{ContactForces, QpError, contact_force_qp, nearest_balanced_forces};
pub use rollout::{ControllerKind, EpisodeStats, RolloutOptions, RolloutSummary};

/// One fingertip's contact with the object, as the simulator reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FingerContact {
    /// Contact point in the world frame (m).
    pub point_m: Vector3<f32>,
    /// Contact normal in the world frame. Either orientation is accepted: the controllers
    /// orient it to point *into* the object (the direction of the fingertip's push),
    /// using the object centre (right for convex objects, which all of ours are).
    pub normal: Vector3<f32>,
    /// Magnitude of the normal contact force (N), >= 0.
    pub force_n: f32,
}

/// What a controller sees at one control step: the paper's observation
/// `s = [q, q', p_1..p_m, n_1..n_m, c_1..c_m]` plus the privileged object pose.
///
/// The env's privileged state converts into this: per finger, `Some` when its fingertip
/// touches the object (if the physics reports several contact points on one fingertip,
/// pass the force-weighted mean point, the normalised sum of normals and the summed force).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerInput {
    /// Measured joint angles q (rad).
    pub q_rad: [f32; NUM_JOINTS],
    /// Current joint targets q' (rad); controllers return changes of these.
    pub q_target_rad: [f32; NUM_JOINTS],
    /// Fingertip contact of each finger, in finger order.
    pub contacts: [Option<FingerContact>; NUM_FINGERS],
    /// Object centre in the world frame (m); the grasp map's reference point.
    pub object_position_m: Vector3<f32>,
    /// Object orientation in the world frame (not needed by IGM/CS/FG today).
    pub object_orientation: UnitQuaternion<f32>,
}

impl ControllerInput {
    /// Fingers whose tip touches the object, ascending.
    #[must_use]
    pub fn fingers_in_contact(&self) -> Vec<usize> {
        (0..NUM_FINGERS).filter(|&f| self.contacts[f].is_some()).collect()
    }
}

/// Why a controller has no action this step. The behaviour policy should then use the
/// learner's action; none of these is a bug, all are states a rollout can reach.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ControllerError {
    /// The contact-force QP rejected the contact set or failed.
    #[error("contact-force QP: {0}")]
    Qp(#[from] QpError),
    /// Kinematics rejected the input (non-finite joints or points).
    #[error("kinematics: {0}")]
    Kinematics(#[from] KinematicsError),
    /// Too few fingertips touch the object for the controller to act.
    #[error("{got} fingertip contacts, the controller needs at least {need}")]
    TooFewContacts {
        /// Contacts available to the controller.
        got: usize,
        /// Contacts it needs.
        need: usize,
    },
    /// A non-finite value in the input (force, normal, target).
    #[error("non-finite input: {0}")]
    NonFinite(String),
}

/// A sub-skill controller: joint-target changes from the observation plus privileged state.
pub trait Controller {
    /// Short name ("igm", "cs", "fg").
    fn name(&self) -> &'static str;
    /// Forget any episode state (e.g. an unfinished switching trajectory).
    fn reset(&mut self, rng: &mut dyn rand::Rng);
    /// The change of the 15 joint targets for this step (rad), or why there is none.
    fn act(
        &mut self,
        input: &ControllerInput,
        rng: &mut dyn rand::Rng,
    ) -> Result<[f32; NUM_JOINTS], ControllerError>;
}

/// `delta` reduced so that `q_target + delta` stays inside the hand's joint limits (a
/// target already outside its range may move back towards it but not further out).
#[must_use]
pub fn limit_to_joint_range(
    hand: &HandModel,
    q_target_rad: &[f32; NUM_JOINTS],
    delta_rad: &[f32; NUM_JOINTS],
) -> [f32; NUM_JOINTS] {
    let limits = hand.joint_limits();
    std::array::from_fn(|j| {
        let (lo, hi) = (limits[j].lower_rad, limits[j].upper_rad);
        let target = q_target_rad[j];
        let wanted = target + delta_rad[j];
        let reached = wanted.clamp(lo.min(target), hi.max(target));
        reached - target
    })
}
