//! The `[env]` keys of a vge config for the Python package: the sim's [`EnvSection`] (the
//! one definition the lab's configs read too) read from a config file, with its `base`
//! chain, or from Python keyword arguments, and validated into [`vge_sim::EnvConfig`]s.
//!
//! The lab's config reader builds the rest of a config (learner, run, plots) that the Python
//! package does not need; both read the file through [`crate::read_with_bases`]. A test
//! (python/tests/test_against_rust.py) checks the outcome end to end: a config loaded here
//! drives the controllers to the same returns, to the bit, as `vge controller --config` on
//! the same file.
//!
//! Keys are read from a TOML table (a config file's `[env]`, or Python keyword arguments
//! turned into one), so unknown keys and wrong types are refused with the key's name.

use serde::Deserialize;
use thiserror::Error;
use vge_sim::{EnvConfig, EnvSection};

use crate::BaseChainError;

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

impl From<BaseChainError> for EnvKeysError {
    fn from(e: BaseChainError) -> Self {
        match e {
            BaseChainError::Io { path, source } => Self::Io { path, source },
            BaseChainError::Parse { path, message } => Self::Parse { origin: path, message },
        }
    }
}

/// The `[env]` section of a vge config, as the Python package reads it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(transparent)]
pub struct EnvKeys(pub EnvSection);

impl EnvKeys {
    /// The keys of `table` over the defaults; `origin` names where they came from.
    pub fn from_table(table: toml::Table, origin: &str) -> Result<Self, EnvKeysError> {
        // Through TOML text, whose reader names the offending key in its messages.
        let text = toml::to_string(&table)
            .map_err(|e| EnvKeysError::Parse { origin: origin.to_owned(), message: e.to_string() })?;
        let keys: Self = toml::from_str(&text)
            .map_err(|e| EnvKeysError::Parse { origin: origin.to_owned(), message: e.to_string() })?;
        // The lab's checks of the section, naming the key (`env.KEY`).
        keys.0
            .validate()
            .map_err(|e| EnvKeysError::Invalid { origin: origin.to_owned(), message: e.to_string() })?;
        Ok(keys)
    }

    /// The `[env]` table of the config file at `path` (empty when it has none) over its
    /// bases' ([`crate::read_with_bases`]), with `overrides` replacing its keys.
    pub fn config_file_table(
        path: &std::path::Path,
        overrides: toml::Table,
    ) -> Result<toml::Table, EnvKeysError> {
        let shown = path.display().to_string();
        let mut doc = crate::read_with_bases(path, &mut |_, _| Ok::<(), EnvKeysError>(()))?;
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

    /// The training curricula set to a non-zero value: `vge train` ramps levels over a run's
    /// env steps; an env outside training runs at the full levels, so these are accepted and
    /// reported, not applied.
    #[must_use]
    pub fn training_only_keys(&self) -> Vec<&'static str> {
        let s = &self.0;
        [
            ("perturb_ramp_steps", s.perturb_ramp_steps),
            ("perturb_ramp_start", s.perturb_ramp_start),
            ("noise_ramp_steps", s.noise_ramp_steps),
        ]
        .into_iter()
        .filter(|(_, v)| *v != 0)
        .map(|(k, _)| k)
        .collect()
    }

    /// The sim's configuration for env `index` (object `objects[index % len]`), as the lab
    /// builds it, and validated.
    pub fn env_config(&self, index: usize, origin: &str) -> Result<EnvConfig, EnvKeysError> {
        let invalid = |message: String| EnvKeysError::Invalid { origin: origin.to_owned(), message };
        let env = self.0.env_config(index).map_err(|e| invalid(e.to_string()))?;
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
    fn defaults_are_the_sections() {
        let keys = EnvKeys::from_table(toml::Table::new(), "test").expect("keys");
        assert_eq!(
            keys.env_config(0, "test").expect("config"),
            EnvSection::default().env_config(0).expect("default")
        );
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
        assert_eq!(keys.env_config(3, "kw").expect("config").object.shape, vge_sim::ObjectShape::Sphere);
        let e = EnvKeys::from_table(table("objects = []"), "kw").expect_err("empty");
        assert!(e.to_string().contains("objects"), "{e}");
    }

    #[test]
    fn invalid_values_are_refused_by_the_sections_and_the_sims_checks() {
        let e = EnvKeys::from_table(table("control_hz = -1.0"), "kw").expect_err("invalid");
        assert!(e.to_string().contains("control rate"), "{e}");
        let e = EnvKeys::from_table(table("object_mass_kg = 0.0"), "kw").expect_err("invalid");
        assert!(e.to_string().contains("env.object_mass_kg"), "{e}");
    }
}
