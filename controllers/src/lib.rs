//! vge-controllers: the paper's sub-skill controllers that steer VGE's exploration: in-grasp manipulation
//! (IGM, [`igm`]), contact switching (CS, [`cs`]) and their superposition, finger-gaiting
//! (FG, [`fg`]); plus the contact-force QP of IGM's stability term ([`qp`]) and the grasp
//! map it is built on ([`grasp`]).
//!
//! Controllers run in training only, so they read privileged simulator state (the object
//! pose). They do not depend on the simulator's env types: the env's privileged state is
//! converted into a [`ControllerInput`] by one adapter,
//! [`ControllerInput::from_privileged`] ([`input`]), and every
//! controller is a function of that plus its own small state and a seeded rng.
//!
//! Every controller works on any hand read from its description ([`vge_hand::Hand`]): the
//! joint and finger counts, the joint limits and the kinematics (J_S, CS's lift direction)
//! all come from the hand, so vge15 (5 fingers x 3 joints) and the Allegro (4 x 4) run the
//! same code.
//!
//! Conventions (those of [`vge_hand`]): world frame, z up; joint vectors are the hand's joint
//! vector (finger-major, [`vge_hand::Finger::joints`]); the grasp map is G (6 x 3k) with
//! `w = G f` and `J_S dq = G^T do`. A controller's output is a change of the joint *targets*
//! for one control step (radians, one entry per joint), the env's action.
//!
//! A crate of its own (sim <- controllers <- trainer) so that the controllers, `vge
//! controller`'s rollouts and their tests build and run without libtorch; the test command
//! checks that this crate and the bridge never depend on torch-sys.

pub mod cs;
pub mod fg;
pub mod grasp;
pub mod igm;
pub mod input;
pub mod qp;
pub mod rollout;

use nalgebra::{UnitQuaternion, Vector3};
use thiserror::Error;
use vge_hand::{Hand, HandError};

pub use cs::{CsConfig, CsController, CsPlan, CsProfile, LateralDirection, SwitchJoints};
pub use fg::FgController;
pub use grasp::grasp_map;
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
/// Sized by the hand: `q_rad` and `q_target_rad` have one entry per joint, `contacts` one
/// per finger; a controller refuses an input of other sizes
/// ([`ControllerError::InputSize`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerInput {
    /// Measured joint angles q (rad).
    pub q_rad: Vec<f32>,
    /// Current joint targets q' (rad); controllers return changes of these.
    pub q_target_rad: Vec<f32>,
    /// Fingertip contact of each finger, in finger order.
    pub contacts: Vec<Option<FingerContact>>,
    /// Object centre in the world frame (m); the grasp map's reference point.
    pub object_position_m: Vector3<f32>,
    /// Object orientation in the world frame (not needed by IGM/CS/FG today).
    pub object_orientation: UnitQuaternion<f32>,
}

impl ControllerInput {
    /// Fingers whose tip touches the object, ascending.
    #[must_use]
    pub fn fingers_in_contact(&self) -> Vec<usize> {
        self.contacts.iter().enumerate().filter(|(_, c)| c.is_some()).map(|(f, _)| f).collect()
    }

    /// Checks the sizes against `hand` (module docs of [`ControllerInput`]).
    pub fn check_sizes(&self, hand: &Hand) -> Result<(), ControllerError> {
        let joints = hand.num_joints();
        for (what, got, expected) in [
            ("q_rad", self.q_rad.len(), joints),
            ("q_target_rad", self.q_target_rad.len(), joints),
            ("contacts", self.contacts.len(), hand.num_fingers()),
        ] {
            if got != expected {
                return Err(ControllerError::InputSize { what, expected, got });
            }
        }
        Ok(())
    }
}

/// Why a controller has no action this step. The behaviour policy should then use the
/// learner's action; none of these is a bug, all are states a rollout can reach.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ControllerError {
    /// The contact-force QP rejected the contact set or failed.
    #[error("contact-force QP: {0}")]
    Qp(#[from] QpError),
    /// The hand's kinematics rejected the input (non-finite joints or points); the
    /// [`HandError`]'s message (that type is neither `Clone` nor `PartialEq`).
    #[error("kinematics: {0}")]
    Kinematics(String),
    /// Too few fingertips touch the object for the controller to act.
    #[error("{got} fingertip contacts, the controller needs at least {need}")]
    TooFewContacts {
        /// Contacts available to the controller.
        got: usize,
        /// Contacts it needs.
        need: usize,
    },
    /// Enough fingertips touch the object, but lifting any of them would leave contacts
    /// that all push it one way, or the fingers in contact have no joint that lifts them
    /// ([`cs`]'s choice of finger).
    #[error("none of the {contacts} fingers in contact can switch while the others hold the object")]
    NoFingerToSwitch {
        /// Fingertips in contact.
        contacts: usize,
    },
    /// A non-finite value in the input (force, normal, target).
    #[error("non-finite input: {0}")]
    NonFinite(String),
    /// An input vector whose length is not the hand's.
    #[error("{what} has {got} entries, the hand has {expected}")]
    InputSize {
        /// Which field.
        what: &'static str,
        /// The hand's joint or finger count.
        expected: usize,
        /// Entries given.
        got: usize,
    },
}

impl From<HandError> for ControllerError {
    fn from(e: HandError) -> Self {
        Self::Kinematics(e.to_string())
    }
}

/// A sub-skill controller: joint-target changes from the observation plus privileged state.
pub trait Controller {
    /// Short name ("igm", "cs", "fg").
    fn name(&self) -> &'static str;
    /// Forget any episode state (e.g. an unfinished switching trajectory).
    fn reset(&mut self, rng: &mut dyn rand::Rng);
    /// The change of the joint targets for this step (rad, one entry per joint of the
    /// hand), or why there is none.
    fn act(&mut self, input: &ControllerInput, rng: &mut dyn rand::Rng) -> Result<Vec<f32>, ControllerError>;
}

/// `delta` reduced so that `q_target + delta` stays inside the hand's joint limits (a
/// target already outside its range may move back towards it but not further out; a joint
/// without a range is not limited). One entry per entry of `delta_rad`; a joint the hand
/// or `q_target_rad` lacks is left as given.
#[must_use]
pub fn limit_to_joint_range(hand: &Hand, q_target_rad: &[f32], delta_rad: &[f32]) -> Vec<f32> {
    let joints = hand.joints();
    delta_rad
        .iter()
        .enumerate()
        .map(|(j, &delta)| {
            let (Some(limit), Some(&target)) =
                (joints.get(j).and_then(|joint| joint.limit), q_target_rad.get(j))
            else {
                return delta;
            };
            let wanted = target + delta;
            let reached = wanted.clamp(limit.lower_rad.min(target), limit.upper_rad.max(target));
            reached - target
        })
        .collect()
}
