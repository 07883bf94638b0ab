//! Contact switching (CS): a detach / re-attach joint trajectory for one finger (paper:
//! `psi_CS(s) = dq_switch(h)`, h = 1..H), derived from that finger's joints.
//!
//! **Choice of finger.** When no trajectory is running, a finger is drawn uniformly from
//! those in contact that may switch, and only when at least `min_remaining_contacts` (3)
//! *other* fingertips touch the object, so the grasp keeps k >= 3 while one finger is
//! away (on the Allegro's four fingers: exactly one finger free at a time). With fewer
//! contacts CS has no action ([`ControllerError::TooFewContacts`]). A finger may switch
//! when
//! - the other contacts do not all push the same way: some two of their inward normals are
//!   more than 60 deg apart ([`OPPOSING_NORMALS_MAX_COS`]). Lifting the Allegro's thumb
//!   leaves three fingertips on one face, which nothing opposes, and the cube falls; on
//!   vge15 any three of its five fingertips touch at least two faces, so every finger in
//!   contact may switch, as before;
//! - it has a joint that lifts it ([`SwitchJoints::of_finger`]).
//!
//! **Joints** (per finger, from the hand's description and kinematics, [`SwitchJoints`]):
//! the finger's first joint is its *lateral* joint (roll, spread: it moves the tip along
//! the object's surface); of the others, the one that moves the contact point fastest along
//! the contact normal is its *lift* joint, and the Jacobian's sign there says which way
//! opens (moves the tip away from the object). On vge15 these are the roll and the proximal
//! flexion, opening at negative flexion: the fixed `[roll, flex_prox, flex_dist]` profile
//! this controller had before hands were files, to the bit.
//!
//! **Profile** (velocities in rad/s, the step is velocity x control period): lateral speed
//! `v_r` and lift speed `v_f` are drawn uniformly in `[0.1, 0.4]` rad/s when the finger is
//! chosen; the finger's other joints are held (velocity 0).
//! - detach, steps `0 .. H_open` with `H_open = round(open_fraction * H)` (default 40 %):
//!   the lift joint opens at `v_f` (the tip moves away from the object) while the lateral
//!   joint moves the finger sideways (`s v_r`) to a new place on the object;
//! - attach, steps `H_open .. H`: lateral joint held, the lift joint closes at `v_f` for the
//!   remaining 60 % of the steps, i.e. `(H - 2 H_open) v_f dt` *past* its starting target,
//!   so the tip comes back in and re-makes contact at the new place with some squeeze.
//!
//! The lateral direction s is towards the lateral joint's centre ([`lateral_centre_rad`]:
//! the hand's start grasp, else the middle of the joint's range; vge15: roll 0) when the
//! finger's lateral target is more than `0.05` rad off it, which is where IGM's rotation
//! leaves the fingers (it rolls them with the object), so the switch restores range;
//! otherwise it is drawn at random, or, with [`LateralDirection::CentreElseTowardsObject`],
//! it is the way that moves the contact point towards the object's centre line. Other
//! fingers get zero.

use std::sync::Arc;

use nalgebra::Vector3;
use rand::RngExt;
use vge_hand::Hand;

use super::{Controller, ControllerError, ControllerInput, FingerContact, limit_to_joint_range};

/// A finger may switch only if two of the other contacts' inward normals have a dot
/// product below this (more than 60 deg apart): otherwise they all push the object one way.
pub const OPPOSING_NORMALS_MAX_COS: f32 = 0.5;

/// Lateral offset from the centre (rad) beyond which the lateral move goes back towards it.
const OFF_CENTRE_RAD: f32 = 0.05;

/// Which way a switching finger moves sideways (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LateralDirection {
    /// Back towards the lateral joint's centre when more than 0.05 rad off it, else a fair
    /// coin: the rule CS was tuned with on vge15, whose fingers close onto its cube at roll 0
    /// (+- the grasp noise) with room on both sides.
    CentreElseRandom,
    /// Back towards the centre when more than 0.05 rad off it, else the way that moves the
    /// contact point towards the object's centre line: the contact's offset from the object
    /// centre, less its part along the normal, against the lateral joint's Jacobian column.
    /// For a grasp a file places near the object's edges: the Allegro's three fingers share
    /// one face of its 65 mm cube, the outer two 8 mm inside its edges, and a random
    /// outward move carried their tips off the face (2 of 20 seeded switches; none this
    /// way).
    CentreElseTowardsObject,
}

/// Parameters of CS.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsConfig {
    /// H, steps of one switching trajectory.
    pub horizon_steps: usize,
    /// The env's control period (s): a step's target change is velocity x this.
    pub control_period_s: f32,
    /// Range of the lateral and lift speeds (rad/s).
    pub speed_min_rad_s: f32,
    /// Upper end of that range.
    pub speed_max_rad_s: f32,
    /// Fraction of H spent detaching (the rest attaches); in (0, 0.5].
    pub open_fraction: f32,
    /// Contacts that must remain on the other fingers for a finger to be chosen.
    pub min_remaining_contacts: usize,
    /// Which way the finger moves sideways.
    pub lateral: LateralDirection,
}

impl CsConfig {
    /// The defaults at `env`'s control period, moving sideways towards the object
    /// ([`LateralDirection::CentreElseTowardsObject`]) on a hand whose file names its start
    /// grasp (the Allegro), at random as tuned on one that closes its fingers itself (vge15).
    #[must_use]
    pub fn for_env(env: &vge_sim::EnvConfig) -> Self {
        let lateral = if env.hand.start_grasp_rad().is_some() {
            LateralDirection::CentreElseTowardsObject
        } else {
            LateralDirection::CentreElseRandom
        };
        Self { control_period_s: env.control_dt_s(), lateral, ..Self::default() }
    }
}

impl Default for CsConfig {
    /// H = 50 steps at 0.05 s (2.5 s, the env's 20 Hz), speeds in [0.1, 0.4] rad/s, 40 %
    /// detach, keep 3, sideways at random unless off centre. Tuned on the env (vge15, cube, 20 seeded single switches): the grasp
    /// squeezes 0.05 rad past first contact and the other fingers push the object after a
    /// retreating tip, so the detach phase must open the proximal flexion by well over
    /// that at the slowest speed. H = 20 (8 detach steps, >= 0.04 rad) broke and remade
    /// the contact in 15/20, H = 30-40 in 16/20, H = 50 (20 detach steps, >= 0.1 rad,
    /// then 30 closing: 0.05-0.2 rad past the start) in 18/20; H = 60 in 17/20.
    fn default() -> Self {
        Self {
            horizon_steps: 50,
            control_period_s: 0.05,
            speed_min_rad_s: 0.1,
            speed_max_rad_s: 0.4,
            open_fraction: 0.4,
            min_remaining_contacts: 3,
            lateral: LateralDirection::CentreElseRandom,
        }
    }
}

/// The joints a finger switches with (module docs), as indices into the hand's joint vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwitchJoints {
    /// The finger's first joint: moves the tip sideways along the object.
    pub lateral: usize,
    /// The joint that moves the contact point fastest along the contact normal.
    pub lift: usize,
    /// +1 or -1: the lift joint opens (moves the tip out of the object) at this sign.
    pub lift_opening_sign: f32,
}

impl SwitchJoints {
    /// The switching joints of `finger` touching the object at `contact`, at joints `q_rad`,
    /// on an object centred at `object_position_m`; `None` when the finger has fewer than two
    /// joints or none of its joints after the first moves the contact along its normal.
    pub fn of_finger(
        hand: &Hand,
        finger: usize,
        q_rad: &[f32],
        contact: &FingerContact,
        object_position_m: Vector3<f32>,
    ) -> Result<Option<Self>, ControllerError> {
        let count = hand.num_fingers();
        let joints =
            hand.fingers().get(finger).map(|f| f.joints.clone()).ok_or_else(|| {
                ControllerError::Kinematics(format!("finger {finger} of a hand of {count}"))
            })?;
        if joints.len() < 2 {
            return Ok(None);
        }
        let q: Vec<f64> = q_rad.iter().map(|&v| f64::from(v)).collect();
        let point = contact.point_m.cast::<f64>();
        let jacobian = hand.fingertip_jacobian_at_point(finger, &q, &point)?;
        let inward = (object_position_m - contact.point_m).cast::<f64>();
        let normal = contact.normal.cast::<f64>();
        let normal = if normal.dot(&inward) < 0.0 { -normal } else { normal };
        let Some(normal) = normal.try_normalize(1e-9) else {
            return Err(ControllerError::NonFinite(format!("contact normal of finger {finger}")));
        };
        // The first of the largest, so that ties keep the joint nearer the palm.
        let mut best: Option<(usize, f64)> = None;
        for j in joints.clone().skip(1) {
            let along = jacobian.column(j).dot(&normal);
            if !along.is_finite() {
                return Err(ControllerError::NonFinite(format!("Jacobian of finger {finger}")));
            }
            if best.is_none_or(|(_, b)| along.abs() > b.abs()) {
                best = Some((j, along));
            }
        }
        Ok(best.filter(|(_, along)| along.abs() > 1e-9).map(|(lift, along)| Self {
            lateral: joints.start,
            lift,
            lift_opening_sign: if along > 0.0 { -1.0 } else { 1.0 },
        }))
    }
}

/// The lateral joint's centre (rad): its angle in the hand's start grasp when the hand's file
/// names one, else the middle of its range (vge15's roll: 0), else 0.
#[must_use]
pub fn lateral_centre_rad(hand: &Hand, joint: usize) -> f32 {
    if let Some(q) = hand.start_grasp_rad().and_then(|q| q.get(joint).copied()) {
        return q;
    }
    hand.joints().get(joint).and_then(|j| j.limit).map_or(0.0, |l| 0.5 * (l.lower_rad + l.upper_rad))
}

/// Whether the contacts other than `finger`'s push the object from more than one side
/// (module docs).
fn others_oppose(input: &ControllerInput, finger: usize) -> bool {
    let inward: Vec<Vector3<f32>> = input
        .contacts
        .iter()
        .enumerate()
        .filter(|(f, _)| *f != finger)
        .filter_map(|(_, c)| c.as_ref())
        .filter_map(|c| {
            let n =
                if c.normal.dot(&(input.object_position_m - c.point_m)) < 0.0 { -c.normal } else { c.normal };
            n.try_normalize(1e-9)
        })
        .collect();
    inward
        .iter()
        .enumerate()
        .any(|(i, a)| inward[i + 1..].iter().any(|b| a.dot(b) < OPPOSING_NORMALS_MAX_COS))
}

/// One drawn switching trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsProfile {
    /// The switching finger.
    pub finger: usize,
    /// Its joints.
    pub joints: SwitchJoints,
    /// Signed lateral velocity during the detach phase (rad/s).
    pub roll_velocity_rad_s: f32,
    /// Lift speed (rad/s, > 0): opens at this, closes at this.
    pub flex_speed_rad_s: f32,
    /// H.
    pub horizon_steps: usize,
    /// Steps of the detach phase.
    pub open_steps: usize,
}

impl CsProfile {
    /// Velocities (rad/s) of the lateral and the lift joint at step `h` (zero from H on);
    /// the finger's other joints are held.
    #[must_use]
    pub fn joint_velocities(&self, h: usize) -> (f32, f32) {
        let open = self.joints.lift_opening_sign;
        if h >= self.horizon_steps {
            (0.0, 0.0)
        } else if h < self.open_steps {
            (self.roll_velocity_rad_s, open * self.flex_speed_rad_s)
        } else {
            (0.0, -open * self.flex_speed_rad_s)
        }
    }

    /// Joint-target change of all `num_joints` joints at step `h`: velocity x `period_s` on
    /// the switching finger's lateral and lift joints, zero elsewhere.
    #[must_use]
    pub fn delta(&self, h: usize, period_s: f32, num_joints: usize) -> Vec<f32> {
        let mut delta = vec![0.0; num_joints];
        let (lateral, lift) = self.joint_velocities(h);
        if let Some(d) = delta.get_mut(self.joints.lateral) {
            *d = lateral * period_s;
        }
        if let Some(d) = delta.get_mut(self.joints.lift) {
            *d = lift * period_s;
        }
        delta
    }
}

/// A running trajectory: the profile and the next step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsPlan {
    /// What is being followed.
    pub profile: CsProfile,
    /// Next step index h (0-based).
    pub next_step: usize,
}

/// CS as a [`Controller`] (module docs).
#[derive(Debug, Clone)]
pub struct CsController {
    /// The hand (joints, limits, kinematics).
    pub hand: Arc<Hand>,
    /// CS parameters.
    pub config: CsConfig,
    plan: Option<CsPlan>,
}

impl CsController {
    /// CS on `hand` with `config`.
    #[must_use]
    pub fn new(hand: Arc<Hand>, config: CsConfig) -> Self {
        Self { hand, config, plan: None }
    }

    /// The running trajectory, if any.
    #[must_use]
    pub fn plan(&self) -> Option<&CsPlan> {
        self.plan.as_ref()
    }

    /// The finger currently switching, if any.
    #[must_use]
    pub fn switching_finger(&self) -> Option<usize> {
        self.plan.map(|p| p.profile.finger)
    }

    /// The fingers in contact that may switch now, ascending, with their joints (module
    /// docs).
    pub fn switchable_fingers(
        &self,
        input: &ControllerInput,
    ) -> Result<Vec<(usize, SwitchJoints)>, ControllerError> {
        let mut out = Vec::new();
        for finger in input.fingers_in_contact() {
            let Some(contact) = input.contacts[finger].as_ref() else { continue };
            if !others_oppose(input, finger) {
                continue;
            }
            if let Some(joints) =
                SwitchJoints::of_finger(&self.hand, finger, &input.q_rad, contact, input.object_position_m)?
            {
                out.push((finger, joints));
            }
        }
        Ok(out)
    }

    /// +1 or -1: the sign of a `lateral` joint motion that moves `finger`'s contact point
    /// towards the object's centre line ([`LateralDirection::CentreElseTowardsObject`]).
    fn towards_object(
        &self,
        input: &ControllerInput,
        finger: usize,
        lateral: usize,
    ) -> Result<f32, ControllerError> {
        let Some(contact) = input.contacts.get(finger).and_then(Option::as_ref) else {
            return Ok(1.0);
        };
        let q: Vec<f64> = input.q_rad.iter().map(|&v| f64::from(v)).collect();
        let jacobian = self.hand.fingertip_jacobian_at_point(finger, &q, &contact.point_m.cast::<f64>())?;
        let offset = (contact.point_m - input.object_position_m).cast::<f64>();
        let normal = contact.normal.cast::<f64>().try_normalize(1e-9).unwrap_or_else(Vector3::zeros);
        let tangential = offset - normal * offset.dot(&normal);
        Ok(if jacobian.column(lateral).dot(&tangential) > 0.0 { -1.0 } else { 1.0 })
    }

    /// Draw a new trajectory for `input` (module docs), without starting it.
    pub fn draw_profile(
        &self,
        input: &ControllerInput,
        rng: &mut dyn rand::Rng,
    ) -> Result<CsProfile, ControllerError> {
        input.check_sizes(&self.hand)?;
        let in_contact = input.fingers_in_contact().len();
        let need = self.config.min_remaining_contacts + 1;
        if in_contact < need {
            return Err(ControllerError::TooFewContacts { got: in_contact, need });
        }
        let candidates = self.switchable_fingers(input)?;
        if candidates.is_empty() {
            return Err(ControllerError::NoFingerToSwitch { contacts: in_contact });
        }
        let (finger, joints) = candidates[rng.random_range(0..candidates.len())];
        let (lo, hi) = (self.config.speed_min_rad_s, self.config.speed_max_rad_s);
        let roll_speed = rng.random_range(lo..=hi);
        let flex_speed = rng.random_range(lo..=hi);
        let off_centre = input.q_target_rad[joints.lateral] - lateral_centre_rad(&self.hand, joints.lateral);
        let sign = if off_centre.abs() > OFF_CENTRE_RAD {
            -off_centre.signum()
        } else {
            match self.config.lateral {
                LateralDirection::CentreElseRandom => {
                    if rng.random_bool(0.5) {
                        1.0
                    } else {
                        -1.0
                    }
                }
                LateralDirection::CentreElseTowardsObject => {
                    self.towards_object(input, finger, joints.lateral)?
                }
            }
        };
        let h = self.config.horizon_steps.max(1);
        let open = ((self.config.open_fraction * h as f32).round() as usize).clamp(1, h);
        Ok(CsProfile {
            finger,
            joints,
            roll_velocity_rad_s: sign * roll_speed,
            flex_speed_rad_s: flex_speed,
            horizon_steps: h,
            open_steps: open,
        })
    }

    /// This step's target change before the joint-limit clamp: starts a trajectory when
    /// none runs, follows it, and ends it after H steps (the next call draws a new one).
    /// Returns the switching finger with the change.
    pub fn raw_step(
        &mut self,
        input: &ControllerInput,
        rng: &mut dyn rand::Rng,
    ) -> Result<(usize, Vec<f32>), ControllerError> {
        input.check_sizes(&self.hand)?;
        let mut plan = match self.plan {
            Some(plan) => plan,
            None => CsPlan { profile: self.draw_profile(input, rng)?, next_step: 0 },
        };
        let delta = plan.profile.delta(plan.next_step, self.config.control_period_s, self.hand.num_joints());
        plan.next_step += 1;
        self.plan = (plan.next_step < plan.profile.horizon_steps).then_some(plan);
        Ok((plan.profile.finger, delta))
    }
}

impl Controller for CsController {
    fn name(&self) -> &'static str {
        "cs"
    }

    fn reset(&mut self, _rng: &mut dyn rand::Rng) {
        self.plan = None;
    }

    fn act(&mut self, input: &ControllerInput, rng: &mut dyn rand::Rng) -> Result<Vec<f32>, ControllerError> {
        let (_, delta) = self.raw_step(input, rng)?;
        Ok(limit_to_joint_range(&self.hand, &input.q_target_rad, &delta))
    }
}
