//! The `[env]` section of a run config file ([`EnvSection`]): the keys a user writes, flat
//! and in SI units, their defaults (the shipped training protocol), and the
//! [`EnvConfig`] of each env they build. One definition, read by the lab's configs and by
//! the Python package.
//!
//! The section is flat where [`EnvConfig`] is nested, and it holds the training curricula
//! (`*_ramp_*`) that an env alone does not apply; keys that are off by default are left out
//! of the serialised section, so that the hash of a config written before the key existed
//! does not change.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::{
    DomainRandomization, EnvConfig, HandOrientation, NoiseConfig, ObjectConfig, ObjectShape, ObservationSet,
    PerturbationConfig,
};

/// The uniform noise (rad) on the initial grasp pose of the shipped training protocol and of
/// the lab's success test: the policy meets, and is judged on, varied grasps.
pub const PROTOCOL_GRASP_POSE_NOISE_RAD: f32 = 0.02;

/// Why an [`EnvSection`] cannot build its envs; the message names the key (`env.KEY`).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{0}")]
pub struct InvalidEnvSection(pub String);

impl InvalidEnvSection {
    fn new(message: impl Into<String>) -> Self {
        Self(message.into())
    }
}

/// The environment. Env `i` of the vector gets `objects[i % objects.len()]`, each spelt as
/// [`ObjectShape::name`] gives it (`"cube"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnvSection {
    /// The hand: a shipped hand's name (`"vge15"`, the default, or `"allegro"`) or the path
    /// of an MJCF file (the TOML beside it is read too; see `docs/hands.md`). The object
    /// is sized as the hand's file says.
    #[serde(skip_serializing_if = "is_default_hand")]
    pub hand: String,
    /// What the policy (the actor) observes: `"full"` (the default: joints, targets and each
    /// fingertip's contact) or `"proprio"` / `"proprio:K"` (joints and targets now and at
    /// the last K control steps: what a hand without fingertip sensors, like a stock Allegro,
    /// measures). The critic and the controllers see the full state in training either way.
    #[serde(skip_serializing_if = "is_full_observation")]
    pub observation: String,
    pub objects: Vec<ObjectShape>,
    pub control_hz: f32,
    pub episode_length: usize,
    pub max_action_rad: f32,
    /// End an episode as soon as fewer than this many fingertips touch the object (0: never).
    /// The paper ends episodes only on a drop or at the time limit, which is the default;
    /// the reward is paid only while >= 3 fingertips touch the object either way.
    pub terminate_below_contacts: usize,
    /// Charge a backward turn about z even while fewer than 3 fingertips touch (default),
    /// so a back-and-forth earns nothing; `false` is the paper's reward, which one VGE seed
    /// gamed that way (see `vge_sim::EnvConfig::charge_reverse_rotation`).
    pub charge_reverse_rotation: bool,
    /// The rotation about z is paid only while at least this many fingertips touch the
    /// object (the paper's 3, the default). 4 asks for gaits that keep four fingertips on:
    /// under pushes of the cube's weight a frozen grasp on five fingertips holds for 30 s,
    /// one on three drops within seconds however hard it squeezes
    /// (`sim/examples/hold_under_push.rs`).
    #[serde(skip_serializing_if = "is_paper_reward_min_contacts")]
    pub reward_min_contacts: usize,
    /// Randomise the initial grasp (one non-thumb finger open with probability 0.5).
    pub randomize_fingers: bool,
    /// Uniform noise on the initial grasp pose (rad).
    pub grasp_pose_noise_rad: f32,
    pub noise_q_std_rad: f32,
    pub noise_normal_std_frac: f32,
    pub noise_position_std_m: f32,
    /// Random force on the object, Gaussian per component with this std (N).
    pub perturb_force_std_n: f32,
    /// Or a force of this magnitude (N) in a random direction, as the robustness test's
    /// `perturbation_magnitude_n` axis; at most one of the two is set.
    #[serde(skip_serializing_if = "is_zero_f32")]
    pub perturb_force_magnitude_n: f32,
    /// Probability per control step that a new force is drawn.
    pub perturb_change_probability: f32,
    /// Domain randomisation: the object's mass times a factor drawn per episode from
    /// `[lo, hi]` (`[1.0, 1.0]`: off).
    pub mass_scale: [f32; 2],
    /// Likewise the object's friction coefficient.
    pub friction_scale: [f32; 2],
    /// Control steps between an action and its effect (a real hand's bus and motor delay).
    pub action_latency_steps: usize,
    /// Subtracted from the reward of the step on which the object drops (reward units,
    /// rad/s; 0: the paper's reward, where a drop costs only the turn it ends). For gaits
    /// that must hold under pushes: at gamma 0.99 a gait turning 0.33 rad/s is worth about
    /// 33, which is all a drop costs without it. With the force's ramp on
    /// (`perturb_ramp_start`, `perturb_ramp_steps`) it ramps with the force. The success
    /// and robustness tests run without it.
    #[serde(skip_serializing_if = "is_zero_f32")]
    pub drop_penalty: f32,
    /// The upright task: end an episode, as a drop, once the object has tipped more than
    /// this (rad, in (0, π]) from its orientation after the grasp. It stays in the success
    /// test (it defines the task, as the object does). Absent: no bound, the paper's task,
    /// which a policy can pass by tumbling the object about a leaning axis.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub upright_within_rad: Option<f32>,
    /// Curriculum: the force on the object (`perturb_force_std_n`) grows linearly from 0
    /// to its level over the first this-many env steps, set at each episode's start (0:
    /// full from the start). Sensor noise is not ramped: the observation normaliser is
    /// fixed from the warm-up's data, which should hold the noise the policy will meet (at
    /// 50% normal error a policy trained without it kept 8% of its return, one trained
    /// with 25% from the start 85%).
    pub perturb_ramp_steps: u64,
    /// The step the force's ramp starts at: no force on the object before it, then
    /// `perturb_ramp_steps` of linear growth (0: from the first step). Lets the gait be
    /// learned undisturbed first: a run whose pushes grew from step 0 was at half force by
    /// 300k, before any gait (`docs/results/cube-fg-vge-robust/`).
    #[serde(skip_serializing_if = "is_zero")]
    pub perturb_ramp_start: u64,
    /// Curriculum for a run that starts from trained networks (the run config's
    /// `init_from`): the sensor noise (`noise_*`) grows linearly from 0 to its level over the
    /// first this-many env steps, set at each episode's start (0: full from the start).
    /// Refused for a run that fits its observation normaliser, whose warm-up data would then
    /// hold no noise.
    #[serde(skip_serializing_if = "is_zero")]
    pub noise_ramp_steps: u64,
    /// Task variant: the object's mass (kg), absolute, in place of the object's default
    /// (0.15 kg). It stays in the success test (it is the object, not a disturbance);
    /// `mass_scale` multiplies it per episode. Absent: the default.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub object_mass_kg: Option<f32>,
    /// Task variant: the object's Coulomb friction coefficient, absolute, in place of the
    /// default 0.8 (combined with the fingers' 0.8 by average); `friction_scale` multiplies
    /// it per episode. Absent: the default.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub object_friction: Option<f32>,
    /// Task variant: the finger motors' torque cap (N m) on the four fingers, the thumb's 1.5
    /// times it as by default (it opposes two fingers). The cap sets the grip force: by
    /// default (0.3 N m) the motors saturate about 0.015 rad past contact. Absent: 0.3.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor_torque_cap_nm: Option<f32>,
    /// Task variant: the finger motors' position stiffness (N m/rad, every joint). Absent:
    /// the default 20.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor_stiffness_nm_per_rad: Option<f32>,
    /// Task variant: the hand's orientation to gravity, `"palm_down"` (default: gravity along
    /// the rotation axis), `"palm_up"` (gravity along the hand's +z: the object rests on the
    /// fingers) or `"side_on"` (gravity along the hand's +x, from vge15's thumb towards its
    /// middle and ring fingers; see `vge_sim::HandOrientation`).
    #[serde(skip_serializing_if = "is_palm_down")]
    pub hand_orientation: HandOrientation,
    /// Task variant: whether the fingers collide with each other (default false: the hand
    /// touches the object only, and fingers can pass through each other).
    #[serde(skip_serializing_if = "is_false")]
    pub finger_collisions: bool,
}

/// Keeps the full observation (the default) out of the serialised section.
fn is_full_observation(observation: &String) -> bool {
    observation == "full"
}

/// The hand a config without `hand` means.
pub const DEFAULT_HAND: &str = "vge15";

/// Keeps the default hand out of the serialised section, so that configs from before the key
/// existed keep their hash.
fn is_default_hand(hand: &String) -> bool {
    hand == DEFAULT_HAND
}

/// Keeps the default orientation out of the serialised section, as [`is_zero`] does.
fn is_palm_down(o: &HandOrientation) -> bool {
    *o == HandOrientation::PalmDown
}

/// Keeps a switch that is off out of the serialised section, as [`is_zero`] does.
fn is_false(v: &bool) -> bool {
    !*v
}

/// Keeps a curriculum that is off out of the serialised section, as [`is_zero_f32`] does.
fn is_zero(v: &u64) -> bool {
    *v == 0
}

/// Keeps a level that is off out of the serialised section, so that configs from before it
/// existed keep their hash.
fn is_zero_f32(v: &f32) -> bool {
    *v == 0.0
}

/// Keeps the paper's reward threshold (the default) out of the serialised config, as
/// [`is_zero`] does.
fn is_paper_reward_min_contacts(v: &usize) -> bool {
    *v == EnvConfig::default().reward_min_contacts
}

impl Default for EnvSection {
    fn default() -> Self {
        let env = EnvConfig::default();
        Self {
            hand: DEFAULT_HAND.to_owned(),
            observation: "full".to_owned(),
            objects: vec![ObjectShape::Cube],
            control_hz: env.control_hz,
            episode_length: env.episode_length_steps,
            max_action_rad: env.max_action_rad,
            terminate_below_contacts: env.min_contacts,
            charge_reverse_rotation: env.charge_reverse_rotation,
            reward_min_contacts: env.reward_min_contacts,
            randomize_fingers: env.grasp.randomize_fingers,
            // Training starts from grasps randomised as the success test's are (the shipped
            // protocol), not from the sim's one exact grasp.
            grasp_pose_noise_rad: PROTOCOL_GRASP_POSE_NOISE_RAD,
            noise_q_std_rad: 0.0,
            noise_normal_std_frac: 0.0,
            noise_position_std_m: 0.0,
            perturb_force_std_n: 0.0,
            perturb_force_magnitude_n: 0.0,
            perturb_change_probability: 0.0,
            mass_scale: env.randomization.mass_scale,
            friction_scale: env.randomization.friction_scale,
            action_latency_steps: env.randomization.action_latency_steps,
            drop_penalty: env.drop_penalty,
            upright_within_rad: env.upright_within_rad,
            perturb_ramp_steps: 0,
            perturb_ramp_start: 0,
            noise_ramp_steps: 0,
            object_mass_kg: None,
            object_friction: None,
            motor_torque_cap_nm: None,
            motor_stiffness_nm_per_rad: None,
            hand_orientation: env.physics.hand_orientation,
            finger_collisions: env.physics.finger_collisions,
        }
    }
}

impl EnvSection {
    /// The sim's configuration for object `index` of [`Self::objects`] (modulo its length);
    /// refused when the hand does not load.
    pub fn env_config(&self, index: usize) -> Result<EnvConfig, InvalidEnvSection> {
        let hand =
            crate::hands::load(&self.hand).map_err(|e| InvalidEnvSection::new(format!("env.hand: {e}")))?;
        let mut env =
            EnvConfig::for_hand(hand).map_err(|e| InvalidEnvSection::new(format!("env.hand: {e}")))?;
        let object =
            self.objects.get(index % self.objects.len().max(1)).copied().unwrap_or(ObjectShape::Cube);
        // The shape the key names, at the width and mass the hand is sized for.
        env.object = ObjectConfig { shape: object, ..env.object };
        env.control_hz = self.control_hz;
        env.episode_length_steps = self.episode_length;
        env.max_action_rad = self.max_action_rad;
        env.min_contacts = self.terminate_below_contacts;
        env.charge_reverse_rotation = self.charge_reverse_rotation;
        env.reward_min_contacts = self.reward_min_contacts;
        env.drop_penalty = self.drop_penalty;
        env.upright_within_rad = self.upright_within_rad;
        env.grasp.randomize_fingers = self.randomize_fingers;
        env.grasp.pose_noise_rad = self.grasp_pose_noise_rad;
        env.noise = NoiseConfig {
            q_std_rad: self.noise_q_std_rad,
            normal_std_frac: self.noise_normal_std_frac,
            position_std_m: self.noise_position_std_m,
        };
        env.perturbation = PerturbationConfig {
            force_std_n: self.perturb_force_std_n,
            force_magnitude_n: self.perturb_force_magnitude_n,
            change_probability: self.perturb_change_probability,
        };
        env.randomization = DomainRandomization {
            mass_scale: self.mass_scale,
            friction_scale: self.friction_scale,
            action_latency_steps: self.action_latency_steps,
        };
        if let Some(mass_kg) = self.object_mass_kg {
            env.object.mass_kg = mass_kg;
        }
        if let Some(friction) = self.object_friction {
            env.object.friction = friction;
        }
        if let Some(cap_nm) = self.motor_torque_cap_nm {
            env.set_motor_torque_cap_nm(cap_nm);
        }
        if let Some(kp) = self.motor_stiffness_nm_per_rad {
            env.set_motor_stiffness_nm_per_rad(kp);
        }
        env.physics.hand_orientation = self.hand_orientation;
        env.physics.finger_collisions = self.finger_collisions;
        env.observation = self.observation_set()?;
        Ok(env)
    }
}

impl EnvSection {
    /// The observation set `observation` names.
    pub fn observation_set(&self) -> Result<ObservationSet, InvalidEnvSection> {
        ObservationSet::parse(&self.observation)
            .map_err(|e| InvalidEnvSection::new(format!("env.observation: {e}")))
    }

    /// Checks every key; the message names the key (`env.KEY`). Last, every object's sim
    /// configuration must pass the sim's own check.
    pub fn validate(&self) -> Result<(), InvalidEnvSection> {
        if self.objects.is_empty() {
            return Err(InvalidEnvSection::new("env.objects must name at least one object"));
        }
        let hand =
            crate::hands::load(&self.hand).map_err(|e| InvalidEnvSection::new(format!("env.hand: {e}")))?;
        self.observation_set()?;
        let fingers = hand.num_fingers();
        // Checked here, before the sim's own check, so the message names the key the user wrote.
        for (key, n) in [
            ("env.terminate_below_contacts", self.terminate_below_contacts),
            ("env.reward_min_contacts", self.reward_min_contacts),
        ] {
            if n > fingers {
                return Err(InvalidEnvSection::new(format!(
                    "{key} = {n}: the hand {} has {fingers} fingertips",
                    hand.name()
                )));
            }
        }
        if self.perturb_force_std_n > 0.0 && self.perturb_force_magnitude_n > 0.0 {
            return Err(InvalidEnvSection::new(
                "env.perturb_force_std_n and env.perturb_force_magnitude_n are two ways to draw the \
                 force on the object: set one",
            ));
        }
        // The task variants, named here before the sim's own check sees them unnamed.
        for (key, value, zero_ok) in [
            ("env.object_mass_kg", self.object_mass_kg, false),
            ("env.object_friction", self.object_friction, true),
            ("env.motor_torque_cap_nm", self.motor_torque_cap_nm, false),
            ("env.motor_stiffness_nm_per_rad", self.motor_stiffness_nm_per_rad, false),
        ] {
            if let Some(v) = value
                && !(v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0)))
            {
                let need = if zero_ok { ">= 0" } else { "> 0" };
                return Err(InvalidEnvSection::new(format!("{key} must be a finite number {need}, got {v}")));
            }
        }
        if let Some(tilt) = self.upright_within_rad
            && !(tilt > 0.0 && tilt <= std::f32::consts::PI)
        {
            return Err(InvalidEnvSection::new(format!(
                "env.upright_within_rad = {tilt}: needs an angle in (0, pi] rad (0.35 is 20 degrees)"
            )));
        }
        if !(1..=crate::env::MAX_EPISODE_STEPS).contains(&self.episode_length) {
            return Err(InvalidEnvSection::new(format!(
                "env.episode_length = {}: needs 1 to {} control steps",
                self.episode_length,
                crate::env::MAX_EPISODE_STEPS
            )));
        }
        if self.action_latency_steps >= self.episode_length {
            return Err(InvalidEnvSection::new(format!(
                "env.action_latency_steps = {}: needs fewer than env.episode_length ({})",
                self.action_latency_steps, self.episode_length
            )));
        }
        for i in 0..self.objects.len() {
            self.env_config(i)?.validate().map_err(|e| InvalidEnvSection::new(format!("env: {e}")))?;
        }
        if self.max_action_rad.is_nan() || self.max_action_rad <= 0.0 {
            return Err(InvalidEnvSection::new("env.max_action_rad must be > 0"));
        }
        if (self.perturb_ramp_steps > 0 || self.perturb_ramp_start > 0)
            && self.perturb_force_std_n == 0.0
            && self.perturb_force_magnitude_n == 0.0
        {
            return Err(InvalidEnvSection::new(
                "env.perturb_ramp_steps / env.perturb_ramp_start ramp the force on the object, but \
                 env.perturb_force_std_n and env.perturb_force_magnitude_n are 0: set the force to ramp to",
            ));
        }
        Ok(())
    }

    /// Every key of the section, in declaration order (what serde reads: the error messages'
    /// list and the Python package's `ENV_KEYS`).
    #[must_use]
    pub fn keys() -> &'static [&'static str] {
        struct_fields::<Self>()
    }
}

/// The field names serde reads for the struct `T`, as its derived `Deserialize` passes them
/// to [`serde::Deserializer::deserialize_struct`], so that no list of keys is kept by hand.
fn struct_fields<T: serde::de::DeserializeOwned>() -> &'static [&'static str] {
    use serde::de::{self, Visitor};

    struct Probe<'a>(&'a mut &'static [&'static str]);

    impl<'de> serde::Deserializer<'de> for Probe<'_> {
        type Error = de::value::Error;

        fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, Self::Error> {
            Err(de::Error::custom("not a struct"))
        }

        fn deserialize_struct<V: Visitor<'de>>(
            self,
            _name: &'static str,
            fields: &'static [&'static str],
            _visitor: V,
        ) -> Result<V::Value, Self::Error> {
            *self.0 = fields;
            Err(de::Error::custom("fields read"))
        }

        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
            option unit unit_struct newtype_struct seq tuple tuple_struct map enum identifier
            ignored_any
        }
    }

    let mut fields: &'static [&'static str] = &[];
    // The probe always fails, once it has the fields.
    let _ = T::deserialize(Probe(&mut fields));
    fields
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_keys_are_the_fields_in_order() {
        let keys = EnvSection::keys();
        assert_eq!(keys.len(), 31, "{keys:?}");
        assert_eq!((keys[0], keys[30]), ("hand", "finger_collisions"));
        // Every key the default section writes is one of them, and an unknown one is refused.
        let written = serde_json::to_value(EnvSection::default()).expect("json");
        let written = written.as_object().expect("an object");
        assert!(written.len() >= 15, "{written:?}");
        assert!(written.keys().all(|k| keys.contains(&k.as_str())), "{written:?}");
        let unknown = serde_json::from_str::<EnvSection>(r#"{"control_hzz": 20.0}"#).expect_err("unknown");
        assert!(unknown.to_string().contains("control_hzz"), "{unknown}");
    }

    #[test]
    fn the_default_section_builds_the_sims_env_with_the_protocols_grasp_noise() {
        let mut expected = EnvConfig::default();
        expected.grasp.pose_noise_rad = PROTOCOL_GRASP_POSE_NOISE_RAD;
        assert_eq!(EnvSection::default().env_config(0), Ok(expected));
    }

    #[test]
    fn a_hand_is_named_or_a_path_and_sizes_the_object_and_an_unknown_one_is_refused() {
        let allegro = EnvSection { hand: "allegro".to_owned(), ..EnvSection::default() };
        let env = allegro.env_config(0).expect("allegro");
        assert_eq!((env.hand.num_joints(), env.servos.len()), (16, 16));
        assert_eq!((env.object.width_m, env.object.mass_kg), (0.065, 0.1));
        assert!(allegro.validate().is_ok());
        let err =
            EnvSection { hand: "alegro".to_owned(), ..EnvSection::default() }.validate().expect_err("typo");
        assert!(err.0.contains("env.hand") && err.0.contains("allegro"), "{err}");
        let proprio = EnvSection { observation: "proprio:3".to_owned(), ..allegro.clone() };
        assert_eq!(proprio.observation_set(), Ok(ObservationSet::Proprio { history: 3 }));
        let err =
            EnvSection { observation: "touch".to_owned(), ..allegro.clone() }.validate().expect_err("bad");
        assert!(err.0.contains("env.observation"), "{err}");
        let too_many = EnvSection { reward_min_contacts: 5, ..allegro };
        let err = too_many.validate().expect_err("4 fingertips");
        assert!(err.0.contains("4 fingertips"), "{err}");
    }

    #[test]
    fn the_tilt_bound_is_off_unless_written_and_an_angle_out_of_range_is_refused() {
        let written = serde_json::to_value(EnvSection::default()).expect("json");
        assert!(written.get("upright_within_rad").is_none(), "off: not written, old configs keep their hash");
        assert_eq!(EnvSection::default().env_config(0).expect("env").upright_within_rad, None);
        let upright = EnvSection { upright_within_rad: Some(0.35), ..EnvSection::default() };
        assert!(upright.validate().is_ok());
        assert_eq!(upright.env_config(0).expect("env").upright_within_rad, Some(0.35));
        for bad in [0.0, -0.1, 3.2, f32::NAN, f32::INFINITY] {
            let err = EnvSection { upright_within_rad: Some(bad), ..EnvSection::default() }
                .validate()
                .expect_err("bad");
            assert!(err.0.contains("env.upright_within_rad") && err.0.contains("(0, pi]"), "{bad}: {err}");
        }
    }
}
