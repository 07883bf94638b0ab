//! The `[env]` keys of a vge config and their mapping to [`vge_sim::EnvConfig`], as the
//! lab maps them (`vge_lab::config::EnvSection::env_config`).
//!
//! A copy, not a dependency: the lab brings plots, statistics, sweeps and ONNX that the
//! Python package does not need. Two tests keep the copy honest (python/tests/test_env.py):
//! every key the lab's `EnvSection` declares is a key here, and a config loaded here drives the controllers to
//! the same returns, to the bit, as `vge controller --config` on the same file.
//!
//! Keys are read from a TOML table (a config file's `[env]`, or Python keyword arguments
//! turned into one), so unknown keys and wrong types are refused with the key's name.

use serde::Deserialize;
use thiserror::Error;
use vge_sim::{
    DomainRandomization, EnvConfig, HandOrientation, NoiseConfig, ObjectConfig, ObjectShape,
    PerturbationConfig,
};

/// The TOML table of the config file at `path` with its `base` chain merged under it (tables
/// key by key, other values replaced), as `vge_lab::config::read_config_table` reads it.
fn read_with_bases(path: &std::path::Path, depth: usize) -> Result<toml::Table, EnvKeysError> {
    let shown = path.display().to_string();
    let text =
        std::fs::read_to_string(path).map_err(|source| EnvKeysError::Io { path: shown.clone(), source })?;
    let mut table: toml::Table = text.parse().map_err(|e: toml::de::Error| EnvKeysError::Parse {
        origin: shown.clone(),
        message: e.to_string(),
    })?;
    let Some(base) = table.remove("base") else {
        return Ok(table);
    };
    let invalid = |message: String| EnvKeysError::Invalid { origin: shown.clone(), message };
    let base = base.as_str().ok_or_else(|| invalid("`base` names a file, as a string".to_owned()))?;
    // The lab refuses loops by name; a depth bound is enough to refuse them here.
    if depth >= 8 {
        return Err(invalid("more than 8 bases in a chain (or a loop)".to_owned()));
    }
    let mut merged =
        read_with_bases(&path.parent().unwrap_or(std::path::Path::new(".")).join(base), depth + 1)?;
    merge_table(&mut merged, table);
    Ok(merged)
}

fn merge_table(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_table(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Why a set of `[env]` keys cannot become an environment.
#[derive(Debug, Error)]
pub enum EnvKeysError {
    /// A file that cannot be read.
    #[error("reading {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// Not TOML, an unknown key or a value of the wrong type.
    #[error("{origin}: {message}")]
    Parse {
        /// The file, or "keyword arguments".
        origin: String,
        /// The TOML reader's message (it names the key).
        message: String,
    },
    /// Keys that parse but do not make a valid environment.
    #[error("{origin}: {message}")]
    Invalid {
        /// The file, or "keyword arguments".
        origin: String,
        /// What is wrong, naming the key.
        message: String,
    },
}

/// The `[env]` section of a vge config: the trainer's `EnvSection`, key for key, with its
/// defaults (those of [`EnvConfig::default`]).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnvKeys {
    /// Env `i` of a vector gets `objects[i % objects.len()]`.
    pub objects: Vec<ObjectShape>,
    pub control_hz: f32,
    /// Control steps per episode (truncation).
    pub episode_length: usize,
    pub max_action_rad: f32,
    pub terminate_below_contacts: usize,
    pub charge_reverse_rotation: bool,
    pub reward_min_contacts: usize,
    pub randomize_fingers: bool,
    pub grasp_pose_noise_rad: f32,
    pub noise_q_std_rad: f32,
    pub noise_normal_std_frac: f32,
    pub noise_position_std_m: f32,
    pub perturb_force_std_n: f32,
    pub perturb_force_magnitude_n: f32,
    pub perturb_change_probability: f32,
    pub mass_scale: [f32; 2],
    pub friction_scale: [f32; 2],
    pub action_latency_steps: usize,
    pub drop_penalty: f32,
    /// Training curricula of `vge train` (they ramp levels over a run's env steps); an env
    /// outside training runs at the full levels, so these are accepted and reported
    /// ([`Self::training_only_keys`]), not applied.
    pub perturb_ramp_steps: u64,
    pub perturb_ramp_start: u64,
    pub noise_ramp_steps: u64,
    pub object_mass_kg: Option<f32>,
    pub object_friction: Option<f32>,
    pub motor_torque_cap_nm: Option<f32>,
    pub motor_stiffness_nm_per_rad: Option<f32>,
    pub hand_orientation: HandOrientation,
    pub finger_collisions: bool,
}

impl Default for EnvKeys {
    fn default() -> Self {
        let env = EnvConfig::default();
        Self {
            objects: vec![ObjectShape::Cube],
            control_hz: env.control_hz,
            episode_length: env.episode_length_steps,
            max_action_rad: env.max_action_rad,
            terminate_below_contacts: env.min_contacts,
            charge_reverse_rotation: env.charge_reverse_rotation,
            reward_min_contacts: env.reward_min_contacts,
            randomize_fingers: env.grasp.randomize_fingers,
            grasp_pose_noise_rad: env.grasp.pose_noise_rad,
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

/// Every key [`EnvKeys`] reads, in declaration order (for error messages and the test that
/// compares them with the trainer's).
pub const KEYS: [&str; 28] = [
    "objects",
    "control_hz",
    "episode_length",
    "max_action_rad",
    "terminate_below_contacts",
    "charge_reverse_rotation",
    "reward_min_contacts",
    "randomize_fingers",
    "grasp_pose_noise_rad",
    "noise_q_std_rad",
    "noise_normal_std_frac",
    "noise_position_std_m",
    "perturb_force_std_n",
    "perturb_force_magnitude_n",
    "perturb_change_probability",
    "mass_scale",
    "friction_scale",
    "action_latency_steps",
    "drop_penalty",
    "perturb_ramp_steps",
    "perturb_ramp_start",
    "noise_ramp_steps",
    "object_mass_kg",
    "object_friction",
    "motor_torque_cap_nm",
    "motor_stiffness_nm_per_rad",
    "hand_orientation",
    "finger_collisions",
];

impl EnvKeys {
    /// The keys of `table` over the defaults; `origin` names where they came from.
    pub fn from_table(table: toml::Table, origin: &str) -> Result<Self, EnvKeysError> {
        // Through TOML text, whose reader names the offending key in its messages.
        let text = toml::to_string(&table)
            .map_err(|e| EnvKeysError::Parse { origin: origin.to_owned(), message: e.to_string() })?;
        let keys: Self = toml::from_str(&text)
            .map_err(|e| EnvKeysError::Parse { origin: origin.to_owned(), message: e.to_string() })?;
        if keys.objects.is_empty() {
            return Err(EnvKeysError::Invalid {
                origin: origin.to_owned(),
                message: "`objects` is empty: name at least one object".to_owned(),
            });
        }
        Ok(keys)
    }

    /// The `[env]` table of the config file at `path` (empty when it has none) over its
    /// base's (a config's `base = "FILE"`, as the lab reads it: `vge_lab::config::BASE_KEY`),
    /// with `overrides` replacing its keys.
    pub fn config_file_table(
        path: &std::path::Path,
        overrides: toml::Table,
    ) -> Result<toml::Table, EnvKeysError> {
        let shown = path.display().to_string();
        let mut doc = read_with_bases(path, 0)?;
        let mut env = match doc.remove("env") {
            None => toml::Table::new(),
            Some(toml::Value::Table(t)) => t,
            Some(other) => {
                return Err(EnvKeysError::Invalid {
                    origin: shown,
                    message: format!("`env` is a {}, expected a table", other.type_str()),
                });
            }
        };
        env.extend(overrides);
        Ok(env)
    }

    /// The training curricula set to a non-zero value (accepted, not applied: see the field).
    #[must_use]
    pub fn training_only_keys(&self) -> Vec<&'static str> {
        [
            ("perturb_ramp_steps", self.perturb_ramp_steps),
            ("perturb_ramp_start", self.perturb_ramp_start),
            ("noise_ramp_steps", self.noise_ramp_steps),
        ]
        .into_iter()
        .filter(|(_, v)| *v != 0)
        .map(|(k, _)| k)
        .collect()
    }

    /// The sim's configuration for env `index` (object `objects[index % len]`), mapped as the
    /// trainer's `EnvSection::env_config` maps it, and validated.
    pub fn env_config(&self, index: usize, origin: &str) -> Result<EnvConfig, EnvKeysError> {
        let mut env = EnvConfig::default();
        let object =
            self.objects.get(index % self.objects.len().max(1)).copied().unwrap_or(ObjectShape::Cube);
        env.object = ObjectConfig::of(object);
        env.control_hz = self.control_hz;
        env.episode_length_steps = self.episode_length;
        env.max_action_rad = self.max_action_rad;
        env.min_contacts = self.terminate_below_contacts;
        env.charge_reverse_rotation = self.charge_reverse_rotation;
        env.reward_min_contacts = self.reward_min_contacts;
        env.drop_penalty = self.drop_penalty;
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
            env.hand.set_finger_torque_cap_nm(cap_nm);
        }
        if let Some(kp) = self.motor_stiffness_nm_per_rad {
            env.physics.motor_stiffness_nm_per_rad = kp;
        }
        env.physics.hand_orientation = self.hand_orientation;
        env.physics.finger_collisions = self.finger_collisions;
        env.validate()
            .map_err(|e| EnvKeysError::Invalid { origin: origin.to_owned(), message: e.to_string() })?;
        Ok(env)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> toml::Table {
        text.parse().expect("toml")
    }

    #[test]
    fn defaults_are_the_sims() {
        let keys = EnvKeys::from_table(toml::Table::new(), "test").expect("keys");
        assert_eq!(keys.env_config(0, "test").expect("config"), EnvConfig::default());
    }

    #[test]
    fn unknown_keys_and_wrong_types_name_the_key() {
        let e = EnvKeys::from_table(table("control_hzz = 20.0"), "kw").expect_err("unknown");
        assert!(e.to_string().contains("control_hzz"), "{e}");
        let e = EnvKeys::from_table(table("control_hz = \"fast\""), "kw").expect_err("type");
        assert!(e.to_string().contains("control_hz"), "{e}");
    }

    #[test]
    fn objects_cycle_over_the_index() {
        let keys = EnvKeys::from_table(table("objects = [\"cube\", \"sphere\"]"), "kw").expect("keys");
        assert_eq!(keys.env_config(3, "kw").expect("config").object.shape, ObjectShape::Sphere);
        let e = EnvKeys::from_table(table("objects = []"), "kw").expect_err("empty");
        assert!(e.to_string().contains("objects"), "{e}");
    }

    #[test]
    fn invalid_values_are_refused_by_the_sims_check() {
        let keys = EnvKeys::from_table(table("control_hz = -1.0"), "kw").expect("keys");
        let e = keys.env_config(0, "kw").expect_err("invalid");
        assert!(e.to_string().contains("control rate"), "{e}");
    }
}
