//! Contact switching (CS): a fixed detach / re-attach joint trajectory for one finger
//! (paper: `psi_CS(s) = dq_switch(h)`, h = 1..H).
//!
//! **Choice of finger.** When no trajectory is running, a finger is drawn uniformly from
//! those in contact, and only when at least `min_remaining_contacts` (3) *other*
//! fingertips touch the object, so the grasp keeps k >= 3 while one finger is away. With
//! fewer contacts CS has no action ([`ControllerError::TooFewContacts`]).
//!
//! **Profile** (per finger, velocities in rad/s, the step is velocity x control period):
//! roll speed `v_r` and proximal ("middle") flexion speed `v_f` are drawn uniformly in
//! `[0.1, 0.4]` rad/s when the finger is chosen, distal flexion is held (velocity 0).
//! - detach, steps `0 .. H_open` with `H_open = round(open_fraction * H)` (default 40 %):
//!   proximal flexion opens (`-v_f`, the tip moves radially out, away from the object)
//!   while the roll moves the finger sideways (`s v_r`) to a new place on the object;
//! - attach, steps `H_open .. H`: roll held, proximal flexion closes (`+v_f`) for the
//!   remaining 60 % of the steps, i.e. `(H - 2 H_open) v_f dt` *past* its starting target,
//!   so the tip comes back in and re-makes contact at the new place with some squeeze.
//!
//! The roll direction s is towards roll 0 (`-sign(roll)`) when the finger's roll target
//! is more than `0.05` rad off centre, which is where IGM's rotation leaves the fingers
//! (it rolls them with the object), so the switch restores roll range; otherwise it is
//! drawn at random. Other fingers get zero.

use rand::RngExt;
use vge_sim::kinematics::joint_index;
use vge_sim::{HandModel, JOINTS_PER_FINGER, NUM_JOINTS};

use super::{Controller, ControllerError, ControllerInput, limit_to_joint_range};

/// Parameters of CS.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsConfig {
    /// H, steps of one switching trajectory.
    pub horizon_steps: usize,
    /// The env's control period (s): a step's target change is velocity x this.
    pub control_period_s: f32,
    /// Range of the roll and proximal-flexion speeds (rad/s).
    pub speed_min_rad_s: f32,
    /// Upper end of that range.
    pub speed_max_rad_s: f32,
    /// Fraction of H spent detaching (the rest attaches); in (0, 0.5].
    pub open_fraction: f32,
    /// Contacts that must remain on the other fingers for a finger to be chosen.
    pub min_remaining_contacts: usize,
}

impl CsConfig {
    /// The defaults at `env`'s control period.
    #[must_use]
    pub fn for_env(env: &vge_sim::EnvConfig) -> Self {
        Self { control_period_s: env.control_dt_s(), ..Self::default() }
    }
}

impl Default for CsConfig {
    /// H = 50 steps at 0.05 s (2.5 s, the env's 20 Hz), speeds in [0.1, 0.4] rad/s, 40 %
    /// detach, keep 3. Tuned on the env (cube, 20 seeded single switches): the grasp
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
        }
    }
}

/// One drawn switching trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsProfile {
    /// The switching finger.
    pub finger: usize,
    /// Signed roll velocity during the detach phase (rad/s).
    pub roll_velocity_rad_s: f32,
    /// Proximal flexion speed (rad/s, > 0): opens at -this, closes at +this.
    pub flex_speed_rad_s: f32,
    /// H.
    pub horizon_steps: usize,
    /// Steps of the detach phase.
    pub open_steps: usize,
}

impl CsProfile {
    /// Joint velocities [roll, proximal flexion, distal flexion] (rad/s) of the switching
    /// finger at step `h` (zero from H on).
    #[must_use]
    pub fn finger_velocity(&self, h: usize) -> [f32; JOINTS_PER_FINGER] {
        if h >= self.horizon_steps {
            [0.0; JOINTS_PER_FINGER]
        } else if h < self.open_steps {
            [self.roll_velocity_rad_s, -self.flex_speed_rad_s, 0.0]
        } else {
            [0.0, self.flex_speed_rad_s, 0.0]
        }
    }

    /// Joint-target change of all 15 joints at step `h`: velocity x `period_s` on the
    /// switching finger, zero elsewhere.
    #[must_use]
    pub fn delta(&self, h: usize, period_s: f32) -> [f32; NUM_JOINTS] {
        let mut delta = [0.0; NUM_JOINTS];
        let v = self.finger_velocity(h);
        for (j, vj) in v.iter().enumerate() {
            delta[joint_index(self.finger, j)] = vj * period_s;
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
    /// The hand (joint limits).
    pub hand: HandModel,
    /// CS parameters.
    pub config: CsConfig,
    plan: Option<CsPlan>,
}

impl CsController {
    /// CS on `hand` with `config`.
    #[must_use]
    pub fn new(hand: HandModel, config: CsConfig) -> Self {
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

    /// Draw a new trajectory for `input` (module docs), without starting it.
    pub fn draw_profile(
        &self,
        input: &ControllerInput,
        rng: &mut dyn rand::Rng,
    ) -> Result<CsProfile, ControllerError> {
        let in_contact = input.fingers_in_contact();
        let need = self.config.min_remaining_contacts + 1;
        if in_contact.len() < need {
            return Err(ControllerError::TooFewContacts { got: in_contact.len(), need });
        }
        let finger = in_contact[rng.random_range(0..in_contact.len())];
        let (lo, hi) = (self.config.speed_min_rad_s, self.config.speed_max_rad_s);
        let roll_speed = rng.random_range(lo..=hi);
        let flex_speed = rng.random_range(lo..=hi);
        let roll = input.q_target_rad[joint_index(finger, 0)];
        let sign = if roll.abs() > 0.05 {
            -roll.signum()
        } else if rng.random_bool(0.5) {
            1.0
        } else {
            -1.0
        };
        let h = self.config.horizon_steps.max(1);
        let open = ((self.config.open_fraction * h as f32).round() as usize).clamp(1, h);
        Ok(CsProfile {
            finger,
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
    ) -> Result<(usize, [f32; NUM_JOINTS]), ControllerError> {
        let mut plan = match self.plan {
            Some(plan) => plan,
            None => CsPlan { profile: self.draw_profile(input, rng)?, next_step: 0 },
        };
        let delta = plan.profile.delta(plan.next_step, self.config.control_period_s);
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

    fn act(
        &mut self,
        input: &ControllerInput,
        rng: &mut dyn rand::Rng,
    ) -> Result<[f32; NUM_JOINTS], ControllerError> {
        let (_, delta) = self.raw_step(input, rng)?;
        Ok(limit_to_joint_range(&self.hand, &input.q_target_rad, &delta))
    }
}
