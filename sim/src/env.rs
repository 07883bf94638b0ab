//! Gymnasium-shaped environment: `reset(seed) -> (obs, info)`,
//! `step(action) -> StepResult { obs, reward, terminated, truncated, info }`.
//!
//! - Action: one joint-target delta (rad) per joint of the hand, each clipped to
//!   [`EnvConfig::max_action_rad`]; the new targets are clipped to the joint limits.
//! - Observation: [`crate::observation`]'s full observation (its size from the hand: 65
//!   floats for vge15), with the configured noise.
//! - Reward: the object's angular velocity about world z (rad/s) averaged over the control
//!   period (its yaw change divided by the period), while at least
//!   [`EnvConfig::reward_min_contacts`] fingertips touch it, else 0. It is clipped to
//!   +-[`EnvConfig::max_reward_rad_per_s`]: a fingertip slipping off can flick the object
//!   for a step at several rad/s, a spike that says nothing about gaiting and would
//!   dominate the critic's targets. With [`EnvConfig::charge_reverse_rotation`] (the
//!   default) a turn backwards (negative) is charged whatever the number of contacts, so
//!   no back-and-forth earns reward. The one other term is [`EnvConfig::drop_penalty`]
//!   (0 by default), subtracted on the step the object drops.
//! - Terminated: the object centre fell more than [`EnvConfig::drop_height_m`] below its
//!   height after the grasp, measured along gravity (world -z with the palm down, the
//!   hand's +x side on: [`crate::HandOrientation`]), i.e. it left the hand (a drop, the
//!   paper's only end besides the time limit); with [`EnvConfig::upright_within_rad`] set, it
//!   tipped past that bound (counted as a drop); or, when [`EnvConfig::min_contacts`] > 0,
//!   fewer than that many fingertips touch it.
//! - Truncated: [`EnvConfig::episode_length_steps`] control steps without termination.
//!
//! Every random draw (grasp randomisation, noise, perturbation forces) comes from the
//! env's own ChaCha8 generator, seeded in [`Env::reset`]: same seed and actions, same
//! bits.

use std::sync::Arc;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vge_hand::Hand;

use crate::action::DEFAULT_MAX_ACTION_RAD;
use crate::angle::rotation_vector_rad;
use crate::episode::{EpisodeOutcome, EpisodeTracker};
use crate::error::SimError;
use crate::objects::ObjectConfig;
use crate::observation::{FingertipReading, ObservationLayout, ObservationSet, build_observation};
use crate::world::{ContactReading, HandWorld, JointServo, ObjectState, PhysicsConfig};

/// How the initial grasp is made. A hand whose file names a start grasp (a keyframe) starts
/// there, each grasping finger closed onto the object along the surface normal and its
/// targets set to press with `squeeze_force_n_per_kg`; otherwise each finger closes (every
/// joint after its first together) until it touches the object, found geometrically by
/// bisection on the closing angle, and the targets of every joint after each finger's first
/// are set `squeeze_rad` further. The object is then held in place for `hold_s` while the
/// grip builds, released and left to settle for `settle_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GraspConfig {
    /// Extra flexion of the targets past first contact (rad), for a hand without a start
    /// grasp; the motor torque caps then set the grip force (notes: ~0.05 rad).
    pub squeeze_rad: f32,
    /// A hand that starts from its file's grasp (a keyframe) presses each fingertip into the
    /// object with this normal force per kg of the object's mass (N/kg), instead of
    /// `squeeze_rad`: targets set from the fingertip Jacobians, the finger named `thumb`
    /// pressing against the others' resultant. Per kg, so that a drawn mass is gripped as
    /// firmly for its weight: on the Allegro 5 N/kg holds 0.01-0.25 kg still for 30 s, 2 N/kg
    /// drops them (sim/tests/allegro.rs).
    pub squeeze_force_n_per_kg: f32,
    /// Time the object is held fixed while the fingers press (s).
    pub hold_s: f32,
    /// Time the released object settles in the grasp before the episode starts (s).
    pub settle_s: f32,
    /// Randomise which fingers grasp: with probability 0.5 one of the fingers not named
    /// `thumb` stays open (its joints at 0, clamped to their ranges).
    pub randomize_fingers: bool,
    /// Uniform noise (rad, +-) on each finger's first joint (its roll or spread) and, opening
    /// only, on its closing joints. From a start grasp the finger is then closed back onto
    /// the object, so the noise moves where its tip touches.
    pub pose_noise_rad: f32,
}

impl Default for GraspConfig {
    fn default() -> Self {
        Self {
            squeeze_rad: 0.05,
            squeeze_force_n_per_kg: 5.0,
            hold_s: 0.05,
            settle_s: 0.25,
            randomize_fingers: false,
            pose_noise_rad: 0.0,
        }
    }
}

/// Observation noise (zero-mean Gaussian), applied to the observation only: the
/// privileged state stays exact.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NoiseConfig {
    /// Standard deviation of the noise on each joint angle (rad).
    pub q_std_rad: f32,
    /// Standard deviation of the noise on each contact-normal component, as a fraction of
    /// the unit normal (the noisy normal is re-normalised).
    pub normal_std_frac: f32,
    /// Standard deviation of the noise on each contact-point coordinate (m).
    pub position_std_m: f32,
}

/// Random external forces on the object: at each control step, with probability
/// `change_probability` a new force is drawn, otherwise the previous one is kept. A draw is
/// either Gaussian per component (`force_std_n`) or of a fixed magnitude in a uniformly
/// random direction (`force_magnitude_n`); at most one of the two is set.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PerturbationConfig {
    /// Standard deviation of each force component (N); 0 disables this draw. At the object's
    /// weight the force's mean magnitude is about 1.6 times the weight, and often over 3.
    pub force_std_n: f32,
    /// Magnitude of the force (N) in a uniformly random direction; 0 disables this draw.
    /// The paper's "perturbation forces equivalent to the full weight of the object", read
    /// literally: the force is the object's weight in size whatever its direction.
    pub force_magnitude_n: f32,
    /// Probability per control step of drawing a new force.
    pub change_probability: f32,
}

impl PerturbationConfig {
    /// Whether any force is drawn.
    pub fn is_active(&self) -> bool {
        self.force_std_n > 0.0 || self.force_magnitude_n > 0.0
    }
}

/// The longest episode an env runs: 1,000,000 control steps, about 14 h at the default
/// 20 Hz. Episode traces are reserved up front, so an absurd length would abort on the
/// allocation instead of failing with a message.
pub const MAX_EPISODE_STEPS: usize = 1_000_000;

/// Everything that defines an environment.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvConfig {
    /// The hand, as its description file gives it (shared with the controllers).
    pub hand: Arc<Hand>,
    /// Each joint's servo, in the hand's joint order: the description's, changed by the
    /// task's knobs ([`Self::set_motor_torque_cap_nm`], [`Self::set_motor_stiffness_nm_per_rad`]).
    pub servos: Vec<JointServo>,
    /// Physics parameters (rate, solver, contacts, motors).
    pub physics: PhysicsConfig,
    /// The object.
    pub object: ObjectConfig,
    /// Control rate (Hz); must divide the physics rate into a whole number of steps.
    /// Default 20 Hz: each control step is 6 physics steps at 120 Hz (the paper's hand
    /// runs position targets at a few tens of Hz; see `physics_hz` for the physics).
    pub control_hz: f32,
    /// Largest joint-target change per control step (rad).
    pub max_action_rad: f32,
    /// Episode length in control steps (truncation), at most [`MAX_EPISODE_STEPS`].
    pub episode_length_steps: usize,
    /// Terminate when fewer fingertips than this touch the object (0: never; the paper ends
    /// episodes on a drop or the time limit only).
    pub min_contacts: usize,
    /// Reward is paid only while at least this many fingertips touch the object.
    pub reward_min_contacts: usize,
    /// Charge a backward turn (negative reward) also while fewer than
    /// `reward_min_contacts` fingertips touch. The paper pays and charges only while >= 3
    /// touch, and that reward pays for a back-and-forth: turn forward on three fingertips,
    /// back on two. A VGE seed learned exactly that (9.8 rad paid per episode for 0.38 rad
    /// net, 10.6 rad turned back unpaid). With this on, an episode's return (times the
    /// control period) is at most its net rotation, up to the clip. `false`: the paper's.
    pub charge_reverse_rotation: bool,
    /// Terminate when the object centre has fallen this far along gravity from its
    /// post-grasp position (m).
    pub drop_height_m: f32,
    /// End the episode, as a drop, once the object has tipped more than this from upright
    /// ([`crate::angle::tilt_rad`] since the post-grasp orientation; rad, in (0, π]). None:
    /// no bound, the paper's task, which a policy can pass by tumbling the object about a
    /// leaning axis (the Allegro's did). A bound makes turning about z upright the task, in
    /// training and in the success test alike.
    pub upright_within_rad: Option<f32>,
    /// Subtracted from the reward of the step on which the object drops (the reward's units,
    /// rad/s). 0: the paper's reward, where a drop costs only the turn it ends. A training
    /// term for gaits that must hold under pushes: the success and robustness tests run
    /// without it.
    pub drop_penalty: f32,
    /// Reward clip (rad/s).
    pub max_reward_rad_per_s: f32,
    /// Initial grasp.
    pub grasp: GraspConfig,
    /// Observation noise.
    pub noise: NoiseConfig,
    /// External forces on the object.
    pub perturbation: PerturbationConfig,
    /// Per-episode randomisation of the object's physics and of the action's timing.
    pub randomization: DomainRandomization,
    /// What a policy acting in this env observes ([`crate::Observer`] makes it from the env's
    /// own full observation): the full set, or joints and targets with their history for a
    /// hand without fingertip sensing.
    pub observation: ObservationSet,
}

/// Domain randomisation for policies that must survive a real hand: the object's mass and
/// friction drawn per episode, and a delay between an action and its effect. The defaults
/// change nothing and draw nothing from the generator, so runs without it are unchanged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DomainRandomization {
    /// At every reset the object's mass is multiplied by a factor drawn uniformly from
    /// `[lo, hi]`; `[1, 1]` is off.
    pub mass_scale: [f32; 2],
    /// Likewise the object's friction coefficient.
    pub friction_scale: [f32; 2],
    /// Control steps between an action and the targets it sets (0: the same step). The
    /// actions in flight at a reset are zero.
    pub action_latency_steps: usize,
}

impl Default for DomainRandomization {
    fn default() -> Self {
        Self { mass_scale: [1.0, 1.0], friction_scale: [1.0, 1.0], action_latency_steps: 0 }
    }
}

impl DomainRandomization {
    /// A factor from `range`, drawing only when the range is not a single value.
    fn draw(rng: &mut ChaCha8Rng, range: [f32; 2]) -> f32 {
        if range[0] < range[1] { rng.random_range(range[0]..=range[1]) } else { range[0] }
    }
}

impl Default for EnvConfig {
    /// vge's own hand ([`crate::hands::vge15`]) and the 10 cm cube it is sized for.
    fn default() -> Self {
        // The shipped file is compiled in and read by every test: it cannot fail at run time.
        #[allow(clippy::expect_used)]
        let hand = crate::hands::vge15().expect("the shipped vge15 hand reads");
        #[allow(clippy::expect_used)]
        Self::for_hand(hand).expect("the shipped vge15 hand has a servo on every joint")
    }
}

impl EnvConfig {
    /// The task's defaults on `hand`: its servos as its file gives them, and a cube of the
    /// size and mass its file names (else the 10 cm, 0.15 kg cube).
    pub fn for_hand(hand: Arc<Hand>) -> Result<Self, SimError> {
        let servos = JointServo::from_description(&hand)?;
        let mut object = ObjectConfig::default();
        if let Some(nominal) = hand.nominal_object() {
            object.width_m = nominal.width_m;
            object.mass_kg = nominal.mass_kg;
        }
        Ok(Self {
            hand,
            servos,
            physics: PhysicsConfig::default(),
            object,
            control_hz: 20.0,
            max_action_rad: DEFAULT_MAX_ACTION_RAD,
            episode_length_steps: 400,
            min_contacts: 0,
            reward_min_contacts: 3,
            charge_reverse_rotation: true,
            drop_height_m: 0.03,
            upright_within_rad: None,
            drop_penalty: 0.0,
            max_reward_rad_per_s: 3.0,
            grasp: GraspConfig::default(),
            randomization: DomainRandomization::default(),
            noise: NoiseConfig::default(),
            perturbation: PerturbationConfig::default(),
            observation: ObservationSet::Full,
        })
    }
}

fn round_steps(duration_s: f32, hz: f32) -> usize {
    (duration_s * hz).round().max(0.0) as usize
}

impl EnvConfig {
    /// Sets every joint's motor torque cap in proportion, so that the smallest cap (vge15:
    /// the four fingers' 0.3 N m; the thumb's 0.45 goes with it) becomes `cap_nm`: the cap
    /// sets the grip force.
    pub fn set_motor_torque_cap_nm(&mut self, cap_nm: f32) {
        let smallest = self.servos.iter().map(|s| s.torque_cap_nm).fold(f32::INFINITY, f32::min);
        for servo in &mut self.servos {
            // The smallest caps become `cap_nm` exactly, not through a ratio of 1.
            servo.torque_cap_nm = if servo.torque_cap_nm == smallest {
                cap_nm
            } else {
                servo.torque_cap_nm * (cap_nm / smallest)
            };
        }
    }

    /// Sets every joint's motor stiffness (N m/rad).
    pub fn set_motor_stiffness_nm_per_rad(&mut self, kp: f32) {
        for servo in &mut self.servos {
            servo.kp_nm_per_rad = kp;
        }
    }

    /// The layout of the env's own observation: the full set, sized by the hand.
    #[must_use]
    pub fn observation_layout(&self) -> ObservationLayout {
        ObservationLayout::new(ObservationSet::Full, self.hand.num_joints(), self.hand.num_fingers())
    }

    /// The layout of what a policy in this env observes ([`Self::observation`]).
    #[must_use]
    pub fn policy_layout(&self) -> ObservationLayout {
        ObservationLayout::new(self.observation, self.hand.num_joints(), self.hand.num_fingers())
    }

    /// Physics steps per control step (rounded: `(1/30)/(1/240)` in f32 is not 8).
    #[must_use]
    pub fn physics_steps_per_control(&self) -> usize {
        ((self.physics.physics_hz / self.control_hz).round() as usize).max(1)
    }

    /// Simulated time per control step (s).
    #[must_use]
    pub fn control_dt_s(&self) -> f32 {
        self.physics_steps_per_control() as f32 * self.physics.dt_s()
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), SimError> {
        self.physics.validate()?;
        self.object.validate()?;
        let joints = self.hand.joints();
        if self.servos.len() != joints.len() {
            return Err(SimError::InvalidConfig(format!(
                "{} servos for the {} joints of hand {}",
                self.servos.len(),
                joints.len(),
                self.hand.name()
            )));
        }
        for (servo, joint) in self.servos.iter().zip(joints) {
            servo.validate(&joint.name)?;
        }
        let bad = |what: &str, v: f32| Err(SimError::InvalidConfig(format!("{what} {v}")));
        if !(self.control_hz.is_finite()
            && self.control_hz > 0.0
            && self.control_hz <= self.physics.physics_hz)
        {
            return bad("control rate (Hz)", self.control_hz);
        }
        let ratio = self.physics.physics_hz / self.control_hz;
        if (ratio - ratio.round()).abs() > 1e-3 * ratio {
            return Err(SimError::InvalidConfig(format!(
                "physics rate {} Hz is not a whole multiple of control rate {} Hz",
                self.physics.physics_hz, self.control_hz
            )));
        }
        for (what, v) in [
            ("max action (rad)", self.max_action_rad),
            ("drop height (m)", self.drop_height_m),
            ("drop penalty", self.drop_penalty),
            ("max reward (rad/s)", self.max_reward_rad_per_s),
            ("squeeze (rad)", self.grasp.squeeze_rad),
            ("squeeze force (N/kg)", self.grasp.squeeze_force_n_per_kg),
            ("hold time (s)", self.grasp.hold_s),
            ("settle time (s)", self.grasp.settle_s),
            ("grasp pose noise (rad)", self.grasp.pose_noise_rad),
            ("q noise (rad)", self.noise.q_std_rad),
            ("normal noise", self.noise.normal_std_frac),
            ("position noise (m)", self.noise.position_std_m),
            ("perturbation force (N)", self.perturbation.force_std_n),
            ("perturbation force magnitude (N)", self.perturbation.force_magnitude_n),
        ] {
            if !v.is_finite() || v < 0.0 {
                return bad(what, v);
            }
        }
        if let Some(tilt) = self.upright_within_rad
            && !(tilt > 0.0 && tilt <= std::f32::consts::PI)
        {
            return bad("upright bound (rad, in (0, pi])", tilt);
        }
        let p = self.perturbation.change_probability;
        if !(0.0..=1.0).contains(&p) {
            return bad("perturbation change probability", p);
        }
        if self.perturbation.force_std_n > 0.0 && self.perturbation.force_magnitude_n > 0.0 {
            return Err(SimError::InvalidConfig(
                "perturbation: set either the force's std per component or its magnitude, not both"
                    .to_owned(),
            ));
        }
        for (what, [lo, hi]) in [
            ("mass scale", self.randomization.mass_scale),
            ("friction scale", self.randomization.friction_scale),
        ] {
            if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
                return Err(SimError::InvalidConfig(format!(
                    "{what} range [{lo}, {hi}]: needs 0 < lo <= hi"
                )));
            }
        }
        for (what, n) in
            [("min_contacts", self.min_contacts), ("reward_min_contacts", self.reward_min_contacts)]
        {
            let fingers = self.hand.num_fingers();
            if n > fingers {
                return Err(SimError::InvalidConfig(format!(
                    "{what} = {n} contacts: the hand {} has {fingers} fingertips",
                    self.hand.name()
                )));
            }
        }
        let steps = self.episode_length_steps;
        if steps == 0 || steps > MAX_EPISODE_STEPS {
            return Err(SimError::InvalidConfig(format!(
                "episode length {steps} control steps ({} s at {} Hz): needs 1 to {MAX_EPISODE_STEPS} steps",
                steps as f64 / f64::from(self.control_hz),
                self.control_hz
            )));
        }
        let latency = self.randomization.action_latency_steps;
        if latency >= steps {
            return Err(SimError::InvalidConfig(format!(
                "action latency {latency} control steps: needs fewer than the episode's {steps}"
            )));
        }
        Ok(())
    }
}

/// What `reset` reports besides the observation.
#[derive(Debug, Clone, PartialEq)]
pub struct ResetInfo {
    /// Which fingers were closed on the object, in finger order.
    pub grasping_fingers: Vec<bool>,
    /// Fingertips touching the object after settling.
    pub num_tip_contacts: usize,
    /// Object height after settling (m), its position against gravity (world z with the
    /// palm down): the reference for the drop test.
    pub object_height_m: f32,
}

/// What `step` reports besides observation and reward.
#[derive(Debug, Clone, PartialEq)]
pub struct StepInfo {
    /// Fingertips touching the object.
    pub num_tip_contacts: usize,
    /// Which fingertips touch the object, in finger order (contact switches are read off
    /// these).
    pub tip_contacts: Vec<bool>,
    /// Object angular velocity about world z (rad/s) at the end of the step, unclipped.
    pub object_angvel_z_rad_per_s: f32,
    /// Object rotation about world z during this step (rad; [`crate::rotation_about_z_rad`]).
    pub object_rotation_z_rad: f32,
    /// The object's rotation during this step as a world-frame rotation vector (rad;
    /// [`crate::angle::rotation_vector_rad`]; its z component is `object_rotation_z_rad`).
    pub object_rotation_rad: [f32; 3],
    /// Fingertip slip during this step (m): how far the contact points of the fingertips
    /// touching before and after it moved over the object, in the object's frame
    /// ([`crate::slip`]).
    pub tip_slip_m: f32,
    /// Object height (m): its position against gravity (world z with the palm down).
    pub object_height_m: f32,
    /// How far the object has tipped from its post-grasp orientation (rad;
    /// [`crate::angle::tilt_rad`]).
    pub object_tilt_rad: f32,
    /// Whether the object dropped below the termination height, or tipped past
    /// [`EnvConfig::upright_within_rad`].
    pub dropped: bool,
    /// Whether the object tipped past [`EnvConfig::upright_within_rad`] (a drop, by the bound).
    pub tipped_over: bool,
    /// Control steps since reset.
    pub step: usize,
}

/// The Gymnasium step tuple.
#[derive(Debug, Clone, PartialEq)]
pub struct StepResult {
    /// Observation after the step ([`EnvConfig::observation_layout`]).
    pub obs: Vec<f32>,
    /// Reward of the step.
    pub reward: f32,
    /// The episode ended (drop or lost grasp).
    pub terminated: bool,
    /// The episode hit its length.
    pub truncated: bool,
    /// Extra information.
    pub info: StepInfo,
}

/// Noise-free state for controllers and evaluation (the IGM/CS controllers build J_S and
/// G_S from `q` and `contacts` with the hand's kinematics).
#[derive(Debug, Clone, PartialEq)]
pub struct PrivilegedState {
    /// Object pose and velocity.
    pub object: ObjectState,
    /// Joint angles (rad), in the hand's joint order.
    pub q_rad: Vec<f32>,
    /// Joint targets (rad).
    pub q_target_rad: Vec<f32>,
    /// Fingertip contacts (point, normal, force), in finger order.
    pub contacts: Vec<Option<ContactReading>>,
}

impl PrivilegedState {
    /// Number of fingertips touching the object.
    #[must_use]
    pub fn num_tip_contacts(&self) -> usize {
        self.contacts.iter().filter(|c| c.is_some()).count()
    }

    /// Which fingertips touch the object, in finger order.
    #[must_use]
    pub fn tip_contacts(&self) -> Vec<bool> {
        self.contacts.iter().map(Option::is_some).collect()
    }
}

/// One environment: a hand world plus episode bookkeeping and its random generator.
#[derive(Debug)]
pub struct Env {
    config: EnvConfig,
    world: Option<HandWorld>,
    rng: ChaCha8Rng,
    state: Option<PrivilegedState>,
    external_force_n: Vector3<f32>,
    reference_height_m: f32,
    /// The object's post-grasp orientation: the reference its tilt is measured from.
    reference_orientation: UnitQuaternion<f32>,
    steps: usize,
    /// Actions waiting out `randomization.action_latency_steps`, oldest first.
    in_flight: std::collections::VecDeque<Vec<f32>>,
}

/// A standard normal draw (Box-Muller; deterministic given the generator).
fn gaussian(rng: &mut ChaCha8Rng) -> f32 {
    let u1: f32 = rng.random::<f32>().max(f32::MIN_POSITIVE);
    let u2: f32 = rng.random::<f32>();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

impl Env {
    /// A new environment; call [`Self::reset`] before stepping.
    pub fn new(config: EnvConfig) -> Result<Self, SimError> {
        config.validate()?;
        Ok(Self {
            config,
            world: None,
            rng: ChaCha8Rng::seed_from_u64(0),
            state: None,
            external_force_n: Vector3::zeros(),
            reference_height_m: 0.0,
            reference_orientation: UnitQuaternion::identity(),
            steps: 0,
            in_flight: std::collections::VecDeque::new(),
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// Replaces the observation noise and the forces on the object (a curriculum raises
    /// them over training). They apply from the next step; set them before a reset for a
    /// whole episode. Refused (and nothing changed) if the result is not a valid config.
    pub fn set_disturbances(
        &mut self,
        noise: NoiseConfig,
        perturbation: PerturbationConfig,
    ) -> Result<(), SimError> {
        EnvConfig { noise, perturbation, ..self.config.clone() }.validate()?;
        self.config.noise = noise;
        self.config.perturbation = perturbation;
        Ok(())
    }

    /// Replaces the drop penalty (a curriculum raises it with the forces on the object);
    /// it applies from the next step. Refused (and nothing changed) if not finite and >= 0.
    pub fn set_drop_penalty(&mut self, drop_penalty: f32) -> Result<(), SimError> {
        EnvConfig { drop_penalty, ..self.config.clone() }.validate()?;
        self.config.drop_penalty = drop_penalty;
        Ok(())
    }

    /// The physics world (after a reset).
    #[must_use]
    pub fn world(&self) -> Option<&HandWorld> {
        self.world.as_ref()
    }

    /// Mutable physics world, for tests and controllers that script the hand directly.
    pub fn world_mut(&mut self) -> Option<&mut HandWorld> {
        self.world.as_mut()
    }

    /// Noise-free state after the last reset or step.
    #[must_use]
    pub fn privileged(&self) -> Option<&PrivilegedState> {
        self.state.as_ref()
    }

    /// The external force currently applied to the object (N, world).
    #[must_use]
    pub fn external_force_n(&self) -> Vector3<f32> {
        self.external_force_n
    }

    /// Rebuilds the world, closes the fingers on the object and lets it settle.
    pub fn reset(&mut self, seed: u64) -> Result<(Vec<f32>, ResetInfo), SimError> {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
        let cfg = &self.config;
        let hand = Arc::clone(&cfg.hand);
        let grasp = cfg.grasp;
        let fingers = hand.fingers();
        let mut grasping = vec![true; fingers.len()];
        if grasp.randomize_fingers && self.rng.random::<f32>() < 0.5 {
            // One of the fingers that do not oppose the others may stay open (vge15: finger 0
            // is the thumb, so this draws 1 + r % 4 as it always has).
            let open_able: Vec<usize> = (0..fingers.len()).filter(|f| fingers[*f].name != "thumb").collect();
            if open_able.len() > 1 {
                let skip = open_able[(self.rng.random::<u32>() % open_able.len() as u32) as usize];
                grasping[skip] = false;
            }
        }
        let mut noise = vec![0.0f32; 2 * fingers.len()];
        if grasp.pose_noise_rad > 0.0 {
            for v in &mut noise {
                *v = self.rng.random_range(-grasp.pose_noise_rad..=grasp.pose_noise_rad);
            }
        }
        let mut object = cfg.object;
        object.mass_kg *= DomainRandomization::draw(&mut self.rng, cfg.randomization.mass_scale);
        object.friction *= DomainRandomization::draw(&mut self.rng, cfg.randomization.friction_scale);
        let q0 = vec![0.0f32; hand.num_joints()];
        let mut world =
            HandWorld::new(&hand, &cfg.servos, &cfg.physics, &object, &q0, &Isometry3::identity())?;
        world.set_object_fixed(true);
        let keyframe = hand.start_grasp_rad();
        let mut q = q0;
        for (f, finger) in fingers.iter().enumerate() {
            if !grasping[f] {
                continue;
            }
            let first = finger.joints.start;
            let closing = finger.joints.clone().skip(1);
            if let Some(start) = &keyframe {
                // The file's grasp, turned by the noise and opened (never closed) by it.
                q[first] = cfg.servos[first].limit.clamp(start[first] + noise[2 * f]);
                for j in closing {
                    q[j] = cfg.servos[j].limit.clamp(start[j] + noise[2 * f + 1].min(0.0));
                }
                continue;
            }
            let roll = cfg.servos[first].limit.clamp(noise[2 * f]);
            match close_finger(&world, &cfg.servos, f, finger.joints.len(), roll)? {
                Some(s) => {
                    let s = s + noise[2 * f + 1].min(0.0);
                    q[first] = roll;
                    for j in closing {
                        q[j] = s;
                    }
                }
                None => grasping[f] = false,
            }
        }
        if keyframe.is_some() {
            let pressed = crate::grasp::press_start_grasp(
                &hand,
                &cfg.servos,
                &object,
                &cfg.physics.gravity_m_per_s2_vector(),
                &q,
                &grasping,
                grasp.squeeze_force_n_per_kg * object.mass_kg,
            )?;
            world.set_joint_positions(&pressed.q_rad)?;
            world.set_joint_targets(&pressed.target_rad);
        } else {
            world.set_joint_positions(&q)?;
            let mut target = q;
            for (_, finger) in fingers.iter().enumerate().filter(|(f, _)| grasping[*f]) {
                for j in finger.joints.clone().skip(1) {
                    target[j] += grasp.squeeze_rad;
                }
            }
            world.set_joint_targets(&target);
        }
        let hz = cfg.physics.physics_hz;
        for _ in 0..round_steps(grasp.hold_s, hz) {
            world.step();
        }
        world.set_object_fixed(false);
        for _ in 0..round_steps(grasp.settle_s, hz) {
            world.step();
        }
        if !world.is_finite() {
            return Err(SimError::NonFiniteState("after the initial grasp".to_owned()));
        }
        let joints = hand.num_joints();
        self.world = Some(world);
        self.external_force_n = Vector3::zeros();
        self.steps = 0;
        self.in_flight.clear();
        self.in_flight
            .extend(std::iter::repeat_n(vec![0.0; joints], self.config.randomization.action_latency_steps));
        let state = self.read_state()?;
        self.reference_height_m = self.height_m(&state);
        self.reference_orientation = state.object.pose.rotation;
        let info = ResetInfo {
            grasping_fingers: grasping,
            num_tip_contacts: state.num_tip_contacts(),
            object_height_m: self.reference_height_m,
        };
        let obs = self.observe(&state);
        self.state = Some(state);
        Ok((obs, info))
    }

    /// The object's position along the up direction (against gravity). Palm down this is
    /// exactly its z: the other components are multiplied by 0.
    fn height_m(&self, state: &PrivilegedState) -> f32 {
        state.object.pose.translation.vector.dot(&self.config.physics.hand_orientation.up())
    }

    fn read_state(&self) -> Result<PrivilegedState, SimError> {
        let world = self.world.as_ref().ok_or(SimError::NotReset)?;
        Ok(PrivilegedState {
            object: world.object_state(),
            q_rad: world.joint_positions(),
            q_target_rad: world.joint_targets().to_vec(),
            contacts: world.fingertip_contacts(),
        })
    }

    fn observe(&mut self, state: &PrivilegedState) -> Vec<f32> {
        let noise = self.config.noise;
        let mut q = state.q_rad.clone();
        if noise.q_std_rad > 0.0 {
            for v in &mut q {
                *v += noise.q_std_rad * gaussian(&mut self.rng);
            }
        }
        let mut readings = vec![None; state.contacts.len()];
        for (slot, contact) in readings.iter_mut().zip(&state.contacts) {
            let Some(c) = contact else { continue };
            let mut p = c.position_m;
            let mut n = c.normal;
            if noise.position_std_m > 0.0 {
                for v in p.iter_mut() {
                    *v += noise.position_std_m * gaussian(&mut self.rng);
                }
            }
            if noise.normal_std_frac > 0.0 {
                for v in n.iter_mut() {
                    *v += noise.normal_std_frac * gaussian(&mut self.rng);
                }
                n = n.try_normalize(1e-6).unwrap_or(c.normal);
            }
            *slot = Some(FingertipReading {
                position_m: [p.x, p.y, p.z],
                normal: [n.x, n.y, n.z],
                force_n: c.normal_force_n,
            });
        }
        build_observation(&q, &state.q_target_rad, &readings)
    }

    /// Validates an action: one finite entry per joint of the hand.
    pub fn check_action(&self, action: &[f32]) -> Result<(), SimError> {
        check_action(&self.config.hand, action)
    }

    /// One control step: apply the clipped target deltas, advance the physics, observe.
    pub fn step(&mut self, action: &[f32]) -> Result<StepResult, SimError> {
        self.check_action(action)?;
        let mut action = action.to_vec();
        if self.config.randomization.action_latency_steps > 0 {
            self.in_flight.push_back(action);
            action = self.in_flight.pop_front().unwrap_or_else(|| vec![0.0; self.config.hand.num_joints()]);
        }
        let cfg = &self.config;
        let max = cfg.max_action_rad;
        let n_physics = cfg.physics_steps_per_control();
        let world = self.world.as_mut().ok_or(SimError::NotReset)?;
        let target: Vec<f32> = world
            .joint_targets()
            .iter()
            .zip(&action)
            .map(|(current, a)| current + a.clamp(-max, max))
            .collect();
        world.set_joint_targets(&target);
        let pert = cfg.perturbation;
        if pert.is_active() && self.rng.random::<f32>() < pert.change_probability {
            let f = Vector3::new(gaussian(&mut self.rng), gaussian(&mut self.rng), gaussian(&mut self.rng));
            self.external_force_n = if pert.force_magnitude_n > 0.0 {
                // An isotropic Gaussian's direction is uniform on the sphere; a draw of norm
                // ~0 (probability ~1e-20) has no direction and pushes along x.
                f.try_normalize(1e-12).unwrap_or_else(Vector3::x) * pert.force_magnitude_n
            } else {
                f * pert.force_std_n
            };
            world.set_object_external_force(&self.external_force_n);
        }
        // The reward is the object's angular velocity about z averaged over the control
        // period, i.e. its rotation about z over the period: the end-of-period velocity alone
        // under-reported IGM's rotation ~4x, and summed solver velocities miss the solver's
        // position corrections (~15% on an in-grasp roll).
        let orientation_before = world.object_state().pose.rotation;
        for _ in 0..n_physics {
            world.step();
        }
        let rotation_rad = rotation_vector_rad(&orientation_before, &world.object_state().pose.rotation);
        // The z component: `crate::rotation_about_z_rad`, what the reward pays.
        let rotation_z_rad = rotation_rad[2];
        let mean_angvel_z = rotation_z_rad / cfg.control_dt_s();
        if !world.is_finite() {
            return Err(SimError::NonFiniteState(format!("at control step {}", self.steps)));
        }
        self.steps += 1;
        let state = self.read_state()?;
        // Read off the state before the step (the reset's or the last step's) and after it:
        // no draw, no change to what the policy sees or earns.
        let tip_slip_m = self.state.as_ref().map_or(0.0, |before| tip_slip_m(before, &state));
        let cfg = &self.config;
        let n_contacts = state.num_tip_contacts();
        let wz = state.object.angvel_rad_per_s.z;
        let clipped = mean_angvel_z.clamp(-cfg.max_reward_rad_per_s, cfg.max_reward_rad_per_s);
        let reward = if n_contacts >= cfg.reward_min_contacts {
            clipped
        } else if cfg.charge_reverse_rotation {
            clipped.min(0.0)
        } else {
            0.0
        };
        let height = self.height_m(&state);
        let tilt_rad = crate::angle::tilt_rad(&self.reference_orientation, &state.object.pose.rotation);
        let tipped_over = cfg.upright_within_rad.is_some_and(|max| tilt_rad > max);
        // A tip past the bound ends the episode as a drop does, and costs what a drop costs.
        let dropped = height < self.reference_height_m - cfg.drop_height_m || tipped_over;
        let reward = if dropped { reward - cfg.drop_penalty } else { reward };
        let terminated = dropped || n_contacts < cfg.min_contacts;
        let truncated = !terminated && self.steps >= cfg.episode_length_steps;
        let info = StepInfo {
            num_tip_contacts: n_contacts,
            tip_contacts: state.tip_contacts(),
            object_angvel_z_rad_per_s: wz,
            object_rotation_z_rad: rotation_z_rad,
            object_rotation_rad: rotation_rad,
            tip_slip_m,
            object_height_m: height,
            object_tilt_rad: tilt_rad,
            dropped,
            tipped_over,
            step: self.steps,
        };
        let obs = self.observe(&state);
        self.state = Some(state);
        Ok(StepResult { obs, reward, terminated, truncated, info })
    }
}

/// The one episode loop (training accounts its parallel envs step by step with the same
/// [`EpisodeTracker`]; `vge eval`, the controller rollouts and the bridge's sim backend run
/// episodes through this).
impl Env {
    /// A tracker for the episode the last reset began.
    pub fn episode_tracker(&self) -> Result<EpisodeTracker, SimError> {
        let s = self.privileged().ok_or(SimError::NotReset)?;
        Ok(EpisodeTracker::start(&s.tip_contacts()))
    }

    /// Resets with `seed`, then steps with `act(env, obs)` until the env ends the episode (a
    /// drop or the time limit); `on_step(env, result, tracker)` sees each step once it is
    /// recorded.
    pub fn run_episode<E: From<SimError>>(
        &mut self,
        seed: u64,
        mut act: impl FnMut(&Self, &[f32]) -> Result<Vec<f32>, E>,
        mut on_step: impl FnMut(&Self, &StepResult, &EpisodeTracker),
    ) -> Result<EpisodeOutcome, E> {
        let (mut obs, _) = self.reset(seed)?;
        let mut tracker = self.episode_tracker()?;
        loop {
            let action = act(self, &obs)?;
            let r = self.step(&action)?;
            tracker.record(r.reward, r.info.object_rotation_rad, &r.info.tip_contacts, r.info.tip_slip_m);
            on_step(self, &r, &tracker);
            if r.terminated || r.truncated {
                return Ok(tracker.outcome(r.terminated));
            }
            obs = r.obs;
        }
    }
}

/// The fingertips' slip over the object from state `before` to state `after` (m,
/// [`crate::slip::step_slip_m`]).
fn tip_slip_m(before: &PrivilegedState, after: &PrivilegedState) -> f32 {
    let in_object_frame = |s: &PrivilegedState| {
        crate::slip::contact_points_in_object_frame(
            &s.object.pose,
            s.contacts.iter().map(|c| c.as_ref().map(|c| c.position_m)),
        )
    };
    crate::slip::step_slip_m(&in_object_frame(before), &in_object_frame(after))
}

/// Validates an action for `hand`: one finite entry per joint.
pub fn check_action(hand: &Hand, action: &[f32]) -> Result<(), SimError> {
    let expected = hand.num_joints();
    if action.len() != expected {
        return Err(SimError::ActionLength { got: action.len(), expected });
    }
    if let Some(index) = action.iter().position(|v| !v.is_finite()) {
        return Err(SimError::NonFiniteAction { index, value: action[index] });
    }
    Ok(())
}

/// Closing angle `s` (every joint after the first = s) at which finger `finger` of
/// `num_joints` joints, its first at `roll`, first touches the object; `None` when it never
/// does within its second joint's range.
fn close_finger(
    world: &HandWorld,
    servos: &[JointServo],
    finger: usize,
    num_joints: usize,
    roll: f32,
) -> Result<Option<f32>, SimError> {
    let first = world.hand().fingers()[finger].joints.start;
    let Some(limit) = servos.get(first + 1).map(|s| s.limit).filter(|_| num_joints >= 2) else {
        return Ok(None);
    };
    let dist = |s: f32| {
        let mut q = vec![s; num_joints];
        q[0] = roll;
        world.finger_object_distance_m(finger, &q)
    };
    let step = 0.02;
    let mut lo = 0.0f32.max(limit.lower_rad);
    if dist(lo)? <= 0.0 {
        return Ok(Some(lo));
    }
    let mut hi = lo;
    loop {
        hi += step;
        if hi > limit.upper_rad {
            return Ok(None);
        }
        if dist(hi)? <= 0.0 {
            break;
        }
        lo = hi;
    }
    for _ in 0..24 {
        let mid = 0.5 * (lo + hi);
        if dist(mid)? <= 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Ok(Some(lo))
}
