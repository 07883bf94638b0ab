//! One TOML file per experiment ([`Config`]), with `--set key.path=value` overrides applied
//! to the TOML value before deserialising ([`load_config`], [`apply_override`]) and
//! validation with clear messages ([`Config::validate`]).
//!
//! Every section has defaults, so a file names only what differs; unknown keys are errors
//! (a typo must not silently train the default).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;
use vge_sim::EnvConfig;
pub use vge_sim::env_keys::EnvSection;

use vge_controllers::{ControllerKind, CsConfig};

/// A configuration that cannot be read, overridden or used.
#[derive(Debug, Error)]
pub enum ConfigError {
    #[error("reading config {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("parsing config {path}: {message}")]
    Parse { path: String, message: String },
    #[error("override {0:?}: expected key.path=value")]
    OverrideSyntax(String),
    #[error("override {key}: {message}")]
    Override { key: String, message: String },
    #[error("invalid config: {0}")]
    Invalid(String),
}

/// The behaviour policy and loss (the paper's five methods).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Learner only.
    Rl,
    /// Learner only, plus the value-weighted BC loss.
    RlBc,
    /// Fixed guided exploration: follow the controller with a state-independent probability
    /// decaying with training steps.
    Fge,
    /// Value-guided exploration.
    Vge,
    /// VGE plus the value-weighted BC loss.
    VgeBc,
}

impl Method {
    pub const ALL: [Self; 5] = [Self::Rl, Self::RlBc, Self::Fge, Self::Vge, Self::VgeBc];

    pub fn name(self) -> &'static str {
        match self {
            Self::Rl => "rl",
            Self::RlBc => "rl-bc",
            Self::Fge => "fge",
            Self::Vge => "vge",
            Self::VgeBc => "vge-bc",
        }
    }

    /// Whether the behaviour policy ever follows a controller.
    pub fn uses_controller(self) -> bool {
        matches!(self, Self::Fge | Self::Vge | Self::VgeBc)
    }

    /// Whether the controller is queried during training: to be followed (FGE, VGE, VGE+BC)
    /// or only to label the learner's states with its action (RL+BC).
    pub fn queries_controller(self) -> bool {
        self.uses_controller() || self == Self::RlBc
    }

    /// Whether the actor gets the BC loss.
    pub fn uses_bc(self) -> bool {
        matches!(self, Self::RlBc | Self::VgeBc)
    }
}

/// SAC. `alpha = "auto"` tunes α to `target_entropy` (default -act_dim); a number fixes it
/// (the paper: 0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SacSection {
    /// Hidden widths of the actor and both critics. 128 x 128 by default: on the shipped cube
    /// task it reaches a gait in no more env steps than 256 x 256 (medians 500k and 700k in two
    /// sets of five seeds, against 700k), with held-out success in the same interval, at about
    /// twice the env steps/s (docs/results/time-to-gait/).
    pub hidden: Vec<i64>,
    pub actor_lr: f64,
    pub critic_lr: f64,
    pub batch: usize,
    pub gamma: f64,
    pub tau: f64,
    pub alpha: Alpha,
    pub initial_alpha: f64,
    pub target_entropy: Option<f64>,
    pub buffer_size: usize,
    /// Gradient updates per environment transition.
    pub utd: f64,
    /// Transitions collected with uniform random learner actions before updates start.
    pub warmup: u64,
    /// The most cores the training loop uses (0: libtorch's default thread count): libtorch's
    /// intra-op threads, and with two or more possibly one core stepping the envs beside the
    /// updates (`vge_trainer::learner::ThreadGovernor`).
    pub threads: i32,
    /// Normalise observations by the mean and std of the warm-up data (fixed after that,
    /// saved with the networks and exported in the policy file).
    pub normalize_obs: bool,
    /// Layer normalisation in the critics' hidden layers (against Q divergence).
    pub critic_layer_norm: bool,
    /// SAC only: floor of the policy's pre-tanh σ, as a fraction of the action range (0:
    /// CleanRL's exp(-5) = 0.007). With alpha = 0 nothing else keeps σ up; see
    /// `GaussianActor::with_min_std`.
    pub min_policy_std: f64,
    /// The first this-many updates train only the critics, the actor held (and SAC's α):
    /// for a run from trained networks ([`Config::init_from`]) under new conditions, whose
    /// critic must learn them before it steers the actor. Fine-tuned without a hold, a
    /// gait lost all its clean success within 20k updates.
    #[serde(skip_serializing_if = "is_zero")]
    pub actor_hold_updates: u64,
    /// The number format of the hidden layers' matmuls in updates: "f32" or "bf16" (f32
    /// master weights; a ~2x faster matmul on CPUs with AVX512_BF16). Acting, evaluation
    /// and the exported policy are f32 either way.
    #[serde(skip_serializing_if = "is_f32")]
    pub matmul: MatmulPrecision,
}

/// The number format of the hidden layers' matmuls in the learner's updates (the
/// `sac.matmul` key). Weights, optimiser state, biases' master copies, layer norm, the
/// heads and every loss stay f32; acting, evaluation and export are always f32, as the
/// runtime computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MatmulPrecision {
    #[default]
    F32,
    /// Inputs, weights and biases rounded to bfloat16 for the matmul (f32 accumulation, f32
    /// result): on a CPU with AVX512_BF16 a 256-wide layer runs ~2x as fast
    /// (`examples/matmul_dtypes` of vge-trainer); the 1- and 15-wide heads would run slower,
    /// so stay f32.
    Bf16,
}

/// Keeps a key that is off out of the serialised config, so that configs from before it
/// existed keep their hash.
fn is_zero(v: &u64) -> bool {
    *v == 0
}

/// Keeps the key out of serialised configs at its default, so their hashes stay those of
/// configs from before it.
fn is_f32(p: &MatmulPrecision) -> bool {
    *p == MatmulPrecision::F32
}

/// α: a fixed number or `"auto"`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Alpha {
    Fixed(f64),
    Named(AlphaName),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AlphaName {
    Auto,
}

impl Default for SacSection {
    fn default() -> Self {
        Self {
            hidden: vec![128, 128],
            actor_lr: 3e-4,
            critic_lr: 3e-4,
            batch: 256,
            gamma: 0.99,
            tau: 0.005,
            alpha: Alpha::Fixed(0.0),
            initial_alpha: 0.1,
            target_entropy: None,
            buffer_size: 1_000_000,
            utd: 0.25,
            warmup: 10_000,
            threads: 2,
            normalize_obs: true,
            critic_layer_norm: true,
            min_policy_std: 0.0,
            actor_hold_updates: 0,
            matmul: MatmulPrecision::F32,
        }
    }
}

/// The off-policy learner: SAC (the `[sac]` section) or TD3 (the `[sac]` section's sizes,
/// rates, γ, τ, batch, buffer, UTD and warm-up, plus `[td3]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AlgorithmName {
    Sac,
    Td3,
}

impl AlgorithmName {
    /// The name as configs spell it (`"sac"`, `"td3"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Sac => "sac",
            Self::Td3 => "td3",
        }
    }
}

/// TD3's noises (fractions of the action scale) and actor delay.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Td3Section {
    pub explore_std: f64,
    pub target_noise_std: f64,
    pub target_noise_clip: f64,
    pub policy_delay: u64,
}

/// CleanRL's TD3: the one place these defaults are written (the learner's
/// `Algorithm::td3()` reads them from here).
impl Default for Td3Section {
    fn default() -> Self {
        Self { explore_std: 0.1, target_noise_std: 0.2, target_noise_clip: 0.5, policy_delay: 2 }
    }
}

/// VGE's selection horizon and the hard stop (also used by FGE and RL+BC).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VgeSection {
    /// H (the paper's Algorithm 2): the source is chosen every `horizon` steps and followed
    /// for `horizon` steps, and it is also the length of the contact-switching trajectory
    /// `dq_switch(h), h = 1..H`, so that one controller pick runs one whole detach and
    /// re-attach.
    pub horizon: usize,
    /// Training step (env transitions) after which the controller is never queried again.
    pub hard_stop: u64,
}

impl Default for VgeSection {
    fn default() -> Self {
        // H is CS's switch length (`CsConfig::default`, 50 steps: the switch that broke and
        // remade the contact most reliably); the hard stop at a fifth of the default budget,
        // as the paper's 4M of 20M.
        Self { horizon: CsConfig::default().horizon_steps, hard_stop: 200_000 }
    }
}

/// FGE: the probability of following the controller, linear from `p_start` at step
/// `decay_start` to `p_end` at `decay_end`, constant outside.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FgeSection {
    pub p_start: f64,
    pub p_end: f64,
    pub decay_start: u64,
    pub decay_end: u64,
}

impl Default for FgeSection {
    fn default() -> Self {
        Self { p_start: 0.5, p_end: 0.0, decay_start: 0, decay_end: 4_000_000 }
    }
}

/// BC: β linear from `beta_start` at step 0 to 0 at `beta_zero_step`. What is cloned is
/// the controller's action at a replayed state: the executed one for VGE+BC (the paper's
/// `a != a_pi`), the one queried but not executed for RL+BC (the learner alone acts).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BcSection {
    pub beta_start: f64,
    pub beta_zero_step: u64,
}

impl Default for BcSection {
    fn default() -> Self {
        Self { beta_start: 0.1, beta_zero_step: 4_000_000 }
    }
}

/// Bookkeeping: logging, checkpoints, evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunSection {
    /// One metrics row every this many env steps.
    pub log_interval: u64,
    /// Checkpoint every this many env steps (0: only at the end / on stop).
    pub checkpoint_interval: u64,
    /// Save the replay buffer with checkpoints (needed for an exact resume).
    pub save_replay: bool,
    /// Evaluation of the exported actor on the runtime every this many env steps (0: never),
    /// with the success test of `vge eval` ([`crate::eval`]).
    pub eval_interval: u64,
    /// Episodes per evaluation (periodic and final).
    pub eval_episodes: usize,
    /// Length of an evaluation episode (s).
    pub eval_episode_s: f32,
    /// Uniform noise on the initial grasp pose of evaluation episodes (rad; 0 makes every
    /// deterministic episode the same).
    pub eval_grasp_noise_rad: f32,
    /// Held-out episodes training scores the run's policies on at its end (`score.json`,
    /// `vge score`'s record: the selected, final and last snapshots' policies, this many episodes
    /// each); 0 leaves the scoring to `vge score`. Left out of the canonical TOML at its
    /// default, so that stored configs keep their hashes.
    #[serde(skip_serializing_if = "is_default_score_episodes")]
    pub score_episodes: usize,
}

fn is_default_score_episodes(v: &usize) -> bool {
    *v == crate::episode_sets::HELD_OUT_EPISODES
}

impl Default for RunSection {
    fn default() -> Self {
        Self {
            log_interval: 10_000,
            checkpoint_interval: 100_000,
            save_replay: true,
            eval_interval: 100_000,
            eval_episodes: crate::eval::SUCCESS_TEST_EPISODES,
            eval_episode_s: crate::eval::SUCCESS_TEST_EPISODE_S,
            eval_grasp_noise_rad: crate::eval::SUCCESS_TEST_GRASP_NOISE_RAD,
            score_episodes: crate::episode_sets::HELD_OUT_EPISODES,
        }
    }
}

/// One experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub name: String,
    pub seed: u64,
    /// Env transitions to train for (all envs together).
    pub total_steps: u64,
    pub num_envs: usize,
    pub method: Method,
    /// Required for fge, vge, vge-bc; spelt as [`ControllerKind::name`] gives it (`"fg"`).
    pub controller: Option<ControllerKind>,
    pub algorithm: AlgorithmName,
    /// A run folder whose checkpoint's networks start this run: the actor, the critics,
    /// their targets and the observation normaliser they carry (a second curriculum stage,
    /// e.g. fine-tuning a gait under domain randomisation). The optimiser, the replay buffer
    /// and the counters start fresh; the warm-up acts with the loaded actor instead of
    /// uniform random actions, and the normaliser is kept rather than refitted. The
    /// algorithm and network sizes must match the folder's. A relative path is taken from
    /// the working directory; `{seed}` in it becomes the run's seed, so that a sweep
    /// fine-tunes each stage-1 seed into the same seed of stage 2. Only read when a run
    /// starts, not on `--resume`.
    pub init_from: Option<PathBuf>,
    pub env: EnvSection,
    pub sac: SacSection,
    pub td3: Td3Section,
    pub vge: VgeSection,
    pub fge: FgeSection,
    pub bc: BcSection,
    pub run: RunSection,
}

/// The shipped protocol (`configs/cube-base.toml`'s settings, with VGE and the FG controller):
/// TD3, 1M env steps, 0.25 updates per env step, the controllers stopped at 200k, randomised
/// initial grasps, a success test every 100k steps. A config states only what differs.
impl Default for Config {
    fn default() -> Self {
        Self {
            name: "run".to_owned(),
            seed: 0,
            total_steps: 1_000_000,
            num_envs: 8,
            method: Method::Vge,
            controller: Some(ControllerKind::Fg),
            algorithm: AlgorithmName::Td3,
            init_from: None,
            env: EnvSection::default(),
            sac: SacSection::default(),
            td3: Td3Section::default(),
            vge: VgeSection::default(),
            fge: FgeSection::default(),
            bc: BcSection::default(),
            run: RunSection::default(),
        }
    }
}

/// The most memory a run may hold by its estimate ([`Config::check_fits_memory`]), whatever the
/// machine: 1 TiB.
/// Beyond it a size is a typo (`sac.buffer_size = 1000000000000` asks for 656 TB).
pub use vge_config_file::memory::MAX_RUN_BYTES;
/// One env of the training vector with its controller, generator and bookkeeping, besides its
/// episode's records (shared with the Python package's vector env).
use vge_config_file::memory::{ENV_BYTES, bytes_text, machine_memory_bytes};

/// What a training env keeps per step of its episode: the reward (for the Monte-Carlo
/// returns), and the executed action and controller calls that replay an episode in progress
/// after a stop (`vge_trainer`'s checkpoint).
fn episode_step_bytes(joints: u64) -> u64 {
    4 + 4 * joints + 2 * 8
}

/// One evaluation episode's outcome as an evaluation keeps it.
const EVAL_EPISODE_BYTES: u64 = 256;

fn invalid(msg: impl Into<String>) -> ConfigError {
    ConfigError::Invalid(msg.into())
}

impl Config {
    /// The sim's configuration of env `index` ([`vge_sim::EnvSection::env_config`]): refused
    /// when the hand does not load (a hand file may change after the config was checked).
    pub fn env_config(&self, index: usize) -> Result<vge_sim::EnvConfig, vge_sim::SimError> {
        self.env.env_config(index).map_err(|e| vge_sim::SimError::Hand(e.to_string()))
    }

    /// Parses TOML text (no overrides).
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        parse_with_overrides(text, "<string>", &[])
    }

    /// The canonical TOML of this configuration (what a run directory stores).
    pub fn to_toml_string(&self) -> Result<String, ConfigError> {
        toml::to_string(self).map_err(|e| invalid(format!("cannot serialise: {e}")))
    }

    /// FNV-1a 64 of the canonical TOML, as 16 hex digits.
    pub fn hash_hex(&self) -> String {
        let text = self.to_toml_string().unwrap_or_default();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in text.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        format!("{h:016x}")
    }

    /// The run folder [`Self::init_from`] names, `{seed}` replaced by this run's seed.
    pub fn init_from_dir(&self) -> Option<PathBuf> {
        let path = self.init_from.as_ref()?;
        Some(PathBuf::from(path.to_string_lossy().replace("{seed}", &self.seed.to_string())))
    }

    /// CS's configuration on `env`: its trajectory is H = `vge.horizon` steps long, the
    /// paper's one H (see [`VgeSection::horizon`]).
    pub fn cs_config(&self, env: &EnvConfig) -> CsConfig {
        CsConfig { horizon_steps: self.vge.horizon, ..CsConfig::for_env(env) }
    }

    /// Checks every field; the message names the key. Every float first (finite, whatever the
    /// field), then the sections in file order (the top-level keys, then env, sac, td3, vge,
    /// fge, bc, run), each by its own validator, and last the memory the sizes add up to
    /// ([`Self::memory_estimate`], at most [`MAX_RUN_BYTES`]).
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.validate_finite()?;
        self.validate_top_level()?;
        self.env.validate().map_err(|e| invalid(e.to_string()))?;
        self.sac.validate()?;
        if self.algorithm == AlgorithmName::Td3 {
            self.td3.validate()?;
            if self.sac.alpha != Alpha::Fixed(0.0) {
                return Err(invalid(
                    "sac.alpha is SAC's entropy coefficient: leave it at 0 with algorithm = \"td3\"",
                ));
            }
        }
        if self.env.noise_ramp_steps > 0 && self.init_from.is_none() && self.sac.normalize_obs {
            return Err(invalid(
                "env.noise_ramp_steps ramps the sensor noise up from 0, but this run fits its observation \
                 normaliser to the warm-up's data, which would hold no noise (a policy normalised \
                 without normal noise kept 8% of its return at 50% error): use it with init_from, \
                 whose normaliser is kept, or ramp only the force (env.perturb_ramp_steps)",
            ));
        }
        self.vge.validate()?;
        self.fge.validate()?;
        self.bc.validate()?;
        self.run.validate()?;
        // Sizes first: an episode count no machine holds is that, whatever the seeds.
        self.validate_sizes()?;
        self.validate_episode_sets()
    }

    /// Refuses a seed whose validation and test episodes would share env seeds (both sets
    /// start at a fixed function of the seed, and a few seeds bring them within
    /// `run.eval_episodes` of each other): the selected snapshot's test score would then rest
    /// partly on episodes it was picked on.
    fn validate_episode_sets(&self) -> Result<(), ConfigError> {
        use crate::episode_sets::EpisodeSet;
        let n = self.run.eval_episodes as u64;
        let (validation, test) =
            (EpisodeSet::Validation.first_seed(self.seed), EpisodeSet::Test.first_seed(self.seed));
        if test.wrapping_sub(validation) < n || validation.wrapping_sub(test) < n {
            return Err(invalid(format!(
                "seed = {} with run.eval_episodes = {n}: the validation episodes (env seeds from \
                 {validation}) and the test episodes (from {test}) would share seeds, so the \
                 selected snapshot would be reported on episodes it was picked on; choose another \
                 seed or fewer episodes",
                self.seed
            )));
        }
        Ok(())
    }

    /// Refuses a NaN or infinite float anywhere in the config, naming its key. The floats are
    /// found in the config's TOML form, not listed here, so that every float field (one added
    /// later too) is covered.
    fn validate_finite(&self) -> Result<(), ConfigError> {
        fn first_non_finite(key: String, value: &toml::Value) -> Option<(String, f64)> {
            match value {
                toml::Value::Float(x) if !x.is_finite() => Some((key, *x)),
                toml::Value::Array(a) => {
                    a.iter().enumerate().find_map(|(i, v)| first_non_finite(format!("{key}[{i}]"), v))
                }
                _ => None,
            }
        }
        let value = toml::Value::try_from(self).map_err(|e| invalid(format!("cannot serialise: {e}")))?;
        match dotted_leaves(&value).into_iter().find_map(|(key, v)| first_non_finite(key, v)) {
            Some((key, x)) => Err(invalid(format!("{key} must be a finite number, got {x}"))),
            None => Ok(()),
        }
    }

    /// The largest allocations of a training run of this config outside the learner, each
    /// estimated from the sizes that set it: (the keys, bytes). The learner (vge-trainer)
    /// estimates its own, its replay buffer and networks, whose layouts only it knows, and
    /// [`Self::check_fits_memory`] bounds the two together before anything is allocated;
    /// [`Self::validate`] bounds these alone, wherever the config is read.
    pub fn memory_estimate(&self) -> Result<Vec<(&'static str, u64)>, ConfigError> {
        let env = self.env.env_config(0).map_err(|e| invalid(e.to_string()))?;
        // Each env, and its episode's records.
        let joints = env.hand.num_joints() as u64;
        let per_env = ENV_BYTES
            .saturating_add((self.env.episode_length as u64).saturating_mul(episode_step_bytes(joints)));
        let envs = (self.num_envs as u64).saturating_mul(per_env);
        let eval =
            (self.run.eval_episodes.max(self.run.score_episodes) as u64).saturating_mul(EVAL_EPISODE_BYTES);
        Ok(vec![("num_envs, env.episode_length", envs), ("run.eval_episodes, run.score_episodes", eval)])
    }

    /// `parts` as one sentence: the total and its parts.
    fn memory_text(parts: &[(&'static str, u64)]) -> (u64, String) {
        let total = parts.iter().fold(0u64, |sum, (_, b)| sum.saturating_add(*b));
        let shown: Vec<String> = parts.iter().map(|(k, b)| format!("{k}: {}", bytes_text(*b))).collect();
        (total, format!("about {} ({})", bytes_text(total), shown.join(", ")))
    }

    /// `parts` against [`MAX_RUN_BYTES`], independent of the machine the config is read on
    /// (a login node checks what a cluster's nodes will run).
    fn check_run_bound(parts: &[(&'static str, u64)]) -> Result<(), ConfigError> {
        let (total, text) = Self::memory_text(parts);
        if total > MAX_RUN_BYTES {
            return Err(invalid(format!(
                "this run would hold {text}, more than the {} vge allows a run: a size is wrong",
                bytes_text(MAX_RUN_BYTES)
            )));
        }
        Ok(())
    }

    /// [`Self::memory_estimate`] against [`MAX_RUN_BYTES`].
    fn validate_sizes(&self) -> Result<(), ConfigError> {
        Self::check_run_bound(&self.memory_estimate()?)
    }

    /// Refuses a run whose memory, `learner` (the learner's estimate of its own parts) and
    /// [`Self::memory_estimate`] together, exceeds [`MAX_RUN_BYTES`] or this machine's memory
    /// (`MemTotal` of `/proc/meminfo`), before anything is allocated: an allocation it cannot
    /// hold aborts the process. Where `/proc/meminfo` cannot be read, the fixed bound is all
    /// there is.
    pub fn check_fits_memory(&self, learner: &[(&'static str, u64)]) -> Result<(), ConfigError> {
        let parts: Vec<(&'static str, u64)> =
            learner.iter().copied().chain(self.memory_estimate()?).collect();
        Self::check_run_bound(&parts)?;
        let Some(machine) = machine_memory_bytes() else { return Ok(()) };
        let (total, text) = Self::memory_text(&parts);
        if total > machine {
            return Err(invalid(format!(
                "this run would hold {text}, more than this machine's {} of memory (MemTotal in \
                 /proc/meminfo): lower the sizes",
                bytes_text(machine)
            )));
        }
        Ok(())
    }

    /// The keys outside any section.
    fn validate_top_level(&self) -> Result<(), ConfigError> {
        if self.num_envs == 0 {
            return Err(invalid("num_envs must be at least 1"));
        }
        if self.total_steps == 0 {
            return Err(invalid("total_steps must be at least 1"));
        }
        if self.method.queries_controller() && self.controller.is_none() {
            return Err(invalid(format!(
                "method {:?} queries a controller: set controller = \"igm\" | \"cs\" | \"fg\"",
                self.method.name()
            )));
        }
        Ok(())
    }
}

impl SacSection {
    /// `[sac]` (also the sizes, rates and buffer of TD3).
    fn validate(&self) -> Result<(), ConfigError> {
        self.validate_hidden()?;
        for (key, v) in
            [("sac.actor_lr", self.actor_lr), ("sac.critic_lr", self.critic_lr), ("sac.utd", self.utd)]
        {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(format!("{key} must be a positive number, got {v}")));
            }
        }
        if !(self.gamma > 0.0 && self.gamma <= 1.0) {
            return Err(invalid(format!("sac.gamma must be in (0, 1], got {}", self.gamma)));
        }
        if !(self.tau > 0.0 && self.tau <= 1.0) {
            return Err(invalid(format!("sac.tau must be in (0, 1], got {}", self.tau)));
        }
        match self.alpha {
            Alpha::Fixed(a) if !(a.is_finite() && a >= 0.0) => {
                return Err(invalid(format!("sac.alpha must be >= 0 or \"auto\", got {a}")));
            }
            Alpha::Named(_) if !(self.initial_alpha.is_finite() && self.initial_alpha > 0.0) => {
                return Err(invalid("sac.initial_alpha must be > 0 with alpha = \"auto\""));
            }
            _ => {}
        }
        if self.batch == 0 {
            return Err(invalid("sac.batch must be at least 1"));
        }
        if self.buffer_size < self.batch {
            return Err(invalid(format!(
                "sac.buffer_size {} is smaller than sac.batch {}",
                self.buffer_size, self.batch
            )));
        }
        if self.threads < 0 {
            return Err(invalid("sac.threads must be >= 0"));
        }
        Ok(())
    }

    /// `sac.hidden`: positive widths, and an actor the deployment side can load (refused
    /// before hours of training).
    fn validate_hidden(&self) -> Result<(), ConfigError> {
        use vge_runtime::policy::{HAND_MAX_LAYERS, HAND_MAX_WIDTH};
        if self.hidden.is_empty() || self.hidden.iter().any(|&h| h <= 0) {
            return Err(invalid(format!(
                "sac.hidden must be non-empty positive widths, got {:?}",
                self.hidden
            )));
        }
        if self.hidden.len() + 1 > HAND_MAX_LAYERS || self.hidden.iter().any(|&h| h as usize > HAND_MAX_WIDTH)
        {
            return Err(invalid(format!(
                "sac.hidden = {:?}: vge-bridge and the firmware run actors of at most {} hidden layers of \
                 width <= {HAND_MAX_WIDTH} (vge_runtime::HandPolicy)",
                self.hidden,
                HAND_MAX_LAYERS - 1
            )));
        }
        Ok(())
    }
}

impl Td3Section {
    /// `[td3]` (checked only with `algorithm = "td3"`).
    fn validate(&self) -> Result<(), ConfigError> {
        for (key, v) in [
            ("td3.explore_std", self.explore_std),
            ("td3.target_noise_std", self.target_noise_std),
            ("td3.target_noise_clip", self.target_noise_clip),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(format!("{key} must be finite and >= 0, got {v}")));
            }
        }
        if self.policy_delay == 0 {
            return Err(invalid("td3.policy_delay must be at least 1"));
        }
        Ok(())
    }
}

impl VgeSection {
    /// `[vge]`.
    fn validate(&self) -> Result<(), ConfigError> {
        if self.horizon == 0 {
            return Err(invalid("vge.horizon (H) must be at least 1"));
        }
        Ok(())
    }
}

impl FgeSection {
    /// `[fge]`.
    fn validate(&self) -> Result<(), ConfigError> {
        for (key, p) in [("fge.p_start", self.p_start), ("fge.p_end", self.p_end)] {
            if !(0.0..=1.0).contains(&p) {
                return Err(invalid(format!("{key} must be a probability, got {p}")));
            }
        }
        if self.decay_end < self.decay_start {
            return Err(invalid("fge.decay_end must not be before fge.decay_start"));
        }
        Ok(())
    }
}

impl BcSection {
    /// `[bc]`.
    fn validate(&self) -> Result<(), ConfigError> {
        if !(self.beta_start.is_finite() && self.beta_start >= 0.0) {
            return Err(invalid(format!("bc.beta_start must be >= 0, got {}", self.beta_start)));
        }
        Ok(())
    }
}

impl RunSection {
    /// `[run]`.
    fn validate(&self) -> Result<(), ConfigError> {
        if self.log_interval == 0 {
            return Err(invalid("run.log_interval must be at least 1"));
        }
        if !(self.eval_episode_s.is_finite() && self.eval_episode_s > 0.0) {
            return Err(invalid(format!("run.eval_episode_s must be > 0, got {}", self.eval_episode_s)));
        }
        // Every success test (periodic, final, selection) is a rate over these episodes.
        if self.eval_episodes == 0 {
            return Err(invalid("run.eval_episodes must be at least 1 (the success test's episodes)"));
        }
        if !(self.eval_grasp_noise_rad.is_finite() && self.eval_grasp_noise_rad >= 0.0) {
            return Err(invalid(format!(
                "run.eval_grasp_noise_rad must be >= 0, got {}",
                self.eval_grasp_noise_rad
            )));
        }
        Ok(())
    }
}

/// Reads `path` (with its bases, [`read_config_table`]), applies `overrides`
/// (`"sac.batch=128"`), deserialises and validates.
pub fn load_config(path: &Path, overrides: &[String]) -> Result<Config, ConfigError> {
    let shown = path.display().to_string();
    let table = read_config_table(path)?;
    let config = config_from_table(table, &shown, overrides)?;
    config.validate()?;
    Ok(config)
}

/// The top-level key of a config file that names the file it builds on, relative to the
/// file's own folder: `base = "cube-base.toml"` (`vge_config_file::read_with_bases`: a config
/// is its base with the keys it sets replaced). A run folder stores the merged config.
pub use vge_config_file::BASE_KEY;

/// The TOML table of the config file at `path`, its `base` (and the base's base, ...)
/// merged under it; each file's `[learner]` is moved to its canonical place first.
pub fn read_config_table(path: &Path) -> Result<toml::Table, ConfigError> {
    vge_config_file::read_with_bases(path, &mut |table: &mut toml::Table, shown: &str| {
        fold_learner_section(table, shown, false)
    })
}

impl From<vge_config_file::BaseChainError> for ConfigError {
    fn from(e: vge_config_file::BaseChainError) -> Self {
        match e {
            vge_config_file::BaseChainError::Io { path, source } => Self::Io { path, source },
            vge_config_file::BaseChainError::Parse { path, message } => Self::Parse { path, message },
        }
    }
}

/// Keys whose default changed while runs were stored without them: resuming such a run
/// would switch it to the new default mid-run. (section, "" for the top level; key; what to
/// do). The other defaults that became the shipped protocol's (steps, utd, hard stop,
/// intervals, grasp noise) are in every run folder vge has written.
const CHANGED_DEFAULTS: [(&str, &str, &str); 2] = [
    (
        "env",
        "charge_reverse_rotation",
        "backward turns cost reward by default now, and this run was trained on the \
         paper's reward, which pays only while >= 3 fingertips touch: add \
         `charge_reverse_rotation = false` under [env] to continue it as it was",
    ),
    (
        "",
        "algorithm",
        "the learner is TD3 by default now, and this run predates the choice and trained \
         with SAC: add `algorithm = \"sac\"` at the top to continue it as it was",
    ),
];

/// Refuses a stored run's config (`text`, from `origin`) that lacks a key whose default
/// has changed since ([`CHANGED_DEFAULTS`]): resumed, the run would silently train on.
pub fn check_resumable(text: &str, origin: &str) -> Result<(), ConfigError> {
    let table: toml::Table = text.parse().map_err(|e: toml::de::Error| ConfigError::Parse {
        path: origin.to_owned(),
        message: e.to_string(),
    })?;
    for (section, key, advice) in CHANGED_DEFAULTS {
        let present = if section.is_empty() {
            table.contains_key(key)
        } else {
            table.get(section).and_then(|s| s.as_table()).is_some_and(|s| s.contains_key(key))
        };
        if !present {
            let name = if section.is_empty() { key.to_owned() } else { format!("{section}.{key}") };
            return Err(invalid(format!("{origin} predates {name}: {advice}")));
        }
    }
    Ok(())
}

/// The keys a resumed run may change: its budget (`--steps`), and libtorch's thread count,
/// which can change the rounding, so that the run no longer continues bit for bit
/// ([`check_resume`] says so). Any other change would make the folder claim a config that only
/// part of the run trained with.
pub const RESUME_MAY_CHANGE: [&str; 2] = ["total_steps", "sac.threads"];

/// One key whose value differs between two configs: dotted name, the value before and after
/// (as TOML; `-` where absent).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyChange {
    pub key: String,
    pub before: String,
    pub after: String,
}

impl std::fmt::Display for KeyChange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} = {} -> {}", self.key, self.before, self.after)
    }
}

/// The keys whose values differ between `a` and `b`, in key order.
pub fn changed_keys(a: &Config, b: &Config) -> Result<Vec<KeyChange>, ConfigError> {
    fn table(config: &Config) -> Result<toml::Value, ConfigError> {
        let table: toml::Table = config
            .to_toml_string()?
            .parse()
            .map_err(|e: toml::de::Error| invalid(format!("cannot re-read: {e}")))?;
        Ok(toml::Value::Table(table))
    }
    let (a, b) = (table(a)?, table(b)?);
    let (a, b) = (dotted_leaves(&a), dotted_leaves(&b));
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let text = |v: Option<&&toml::Value>| v.map_or_else(|| "-".to_owned(), ToString::to_string);
    Ok(keys
        .into_iter()
        .filter(|key| a.get(*key) != b.get(*key))
        .map(|key| KeyChange { key: key.clone(), before: text(a.get(key)), after: text(b.get(key)) })
        .collect())
}

/// Every value of a TOML document that is not a table, by its dotted key (`sac.hidden`,
/// `env.object_mass_kg`), in key order: the names a config's keys have on the command line
/// (`--set KEY=VALUE`) and in errors.
fn dotted_leaves(value: &toml::Value) -> std::collections::BTreeMap<String, &toml::Value> {
    fn walk<'a>(
        prefix: String,
        value: &'a toml::Value,
        out: &mut std::collections::BTreeMap<String, &'a toml::Value>,
    ) {
        match value {
            toml::Value::Table(table) => {
                for (key, v) in table {
                    walk(if prefix.is_empty() { key.clone() } else { format!("{prefix}.{key}") }, v, out);
                }
            }
            _ => {
                out.insert(prefix, value);
            }
        }
    }
    let mut out = std::collections::BTreeMap::new();
    walk(String::new(), value, &mut out);
    out
}

/// Checks a resume's overrides: `resumed` (the stored config with them applied) may differ
/// from `stored` (`origin`) only in [`RESUME_MAY_CHANGE`]; any other change is refused,
/// naming each key with both values. Returns a note for each allowed change that costs the
/// bit-for-bit continuation (the thread count), for the caller to print.
pub fn check_resume(stored: &Config, resumed: &Config, origin: &str) -> Result<Vec<String>, ConfigError> {
    let changes = changed_keys(stored, resumed)?;
    let refused: Vec<String> = changes
        .iter()
        .filter(|c| !RESUME_MAY_CHANGE.contains(&c.key.as_str()))
        .map(ToString::to_string)
        .collect();
    if !refused.is_empty() {
        return Err(invalid(format!(
            "a resumed run keeps the config it started with ({origin}), but the command line changes {}; \
             only {} may change on --resume. To train with the change, start a new run from that \
             config (--config with --set) or from its networks (--set init_from=DIR)",
            refused.join(", "),
            RESUME_MAY_CHANGE.join(" and ")
        )));
    }
    Ok(changes
        .iter()
        .filter(|c| c.key == "sac.threads")
        .map(|c| {
            format!(
                "{c}: libtorch can round differently on another thread count, so the run need not \
                 continue bit for bit"
            )
        })
        .collect())
}

/// The config a resumed run trains on: its stored config (`text`, from `origin`) with the
/// command line's `overrides`, validated; refused when the stored config predates a changed
/// default ([`check_resumable`]) or the overrides change more than [`RESUME_MAY_CHANGE`]
/// ([`check_resume`], whose notes come back for the caller to print).
pub fn resume_config(
    text: &str,
    origin: &str,
    overrides: &[String],
) -> Result<(Config, Vec<String>), ConfigError> {
    check_resumable(text, origin)?;
    let stored = parse_with_overrides(text, origin, &[])?;
    let config = parse_with_overrides(text, origin, overrides)?;
    config.validate()?;
    let notes = check_resume(&stored, &config, origin)?;
    Ok((config, notes))
}

/// Parses `text`, applies the overrides to its TOML table, deserialises (not validated).
/// Text has no folder to find a base in: a `base` key is refused ([`load_config`] reads one).
pub fn parse_with_overrides(text: &str, origin: &str, overrides: &[String]) -> Result<Config, ConfigError> {
    let table: toml::Table = text.parse().map_err(|e: toml::de::Error| ConfigError::Parse {
        path: origin.to_owned(),
        message: e.to_string(),
    })?;
    if table.contains_key(BASE_KEY) {
        return Err(ConfigError::Parse {
            path: origin.to_owned(),
            message: format!("`{BASE_KEY}` is read only from a config file (vge train --config FILE)"),
        });
    }
    let mut table = table;
    fold_learner_section(&mut table, origin, false)?;
    config_from_table(table, origin, overrides)
}

/// The section of the learner's settings as configs may spell it, `[learner]` with
/// `kind = "td3"` or `"sac"`; the canonical TOML (and so every stored config and its hash)
/// keeps the older spelling, `[sac]` and the top-level `algorithm`.
pub const LEARNER_KEY: &str = "learner";

/// Moves `[learner]` (`kind` and the learner's settings) to its canonical place: `kind` to the
/// top-level `algorithm`, the rest to `[sac]`. In a file the two spellings of one setting are
/// refused (`overridable` false); `--set learner.KEY=...` overrides either (`overridable` true).
fn fold_learner_section(table: &mut toml::Table, origin: &str, overridable: bool) -> Result<(), ConfigError> {
    let Some(learner) = table.remove(LEARNER_KEY) else {
        return Ok(());
    };
    let refuse = |message: String| ConfigError::Parse { path: origin.to_owned(), message };
    let toml::Value::Table(mut learner) = learner else {
        return Err(refuse(format!(
            "[{LEARNER_KEY}] is the table of the learner's settings; got a {}",
            learner.type_str()
        )));
    };
    if let Some(kind) = learner.remove("kind") {
        if !overridable && table.contains_key("algorithm") {
            return Err(refuse(format!(
                "`algorithm` is the older name of `{LEARNER_KEY}.kind`: set only `{LEARNER_KEY}.kind`"
            )));
        }
        table.insert("algorithm".to_owned(), kind);
    }
    match table.entry("sac").or_insert_with(|| toml::Value::Table(toml::Table::new())) {
        toml::Value::Table(sac) if overridable || sac.is_empty() => sac.extend(learner),
        _ => {
            return Err(refuse(format!(
                "[sac] is the older name of [{LEARNER_KEY}]: put the learner's settings in [{LEARNER_KEY}] only"
            )));
        }
    }
    Ok(())
}

/// The overrides applied to `table`, deserialised (not validated).
fn config_from_table(
    mut table: toml::Table,
    origin: &str,
    overrides: &[String],
) -> Result<Config, ConfigError> {
    for o in overrides {
        apply_override_table(&mut table, o)?;
    }
    fold_learner_section(&mut table, origin, true)?;
    Config::deserialize(toml::Value::Table(table))
        .map_err(|e| ConfigError::Parse { path: origin.to_owned(), message: e.to_string() })
}

/// Applies one `key.path=value` override to a config (through its TOML form, so that the
/// value is parsed exactly as in a file), then re-validates the field types.
pub fn apply_override(config: &mut Config, assignment: &str) -> Result<(), ConfigError> {
    let value = toml::Value::try_from(&*config).map_err(|e| invalid(format!("cannot serialise: {e}")))?;
    let toml::Value::Table(mut table) = value else {
        return Err(invalid("config is not a table"));
    };
    apply_override_table(&mut table, assignment)?;
    fold_learner_section(&mut table, "--set", true)?;
    *config = Config::deserialize(toml::Value::Table(table))
        .map_err(|e| ConfigError::Override { key: assignment.to_owned(), message: e.to_string() })?;
    Ok(())
}

/// The value text as TOML (`128`, `"fg"`, `[256, 256]`, `true`); a bare word that is not
/// valid TOML is taken as a string (`method=vge`).
fn parse_value(text: &str) -> toml::Value {
    let doc = format!("v = {text}");
    match doc.parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(text.to_owned())),
        Err(_) => toml::Value::String(text.to_owned()),
    }
}

fn apply_override_table(table: &mut toml::Table, assignment: &str) -> Result<(), ConfigError> {
    let (key, value) =
        assignment.split_once('=').ok_or_else(|| ConfigError::OverrideSyntax(assignment.to_owned()))?;
    let key = key.trim();
    let parts: Vec<&str> = key.split('.').collect();
    if key.is_empty() || parts.iter().any(|p| p.is_empty()) {
        return Err(ConfigError::OverrideSyntax(assignment.to_owned()));
    }
    let err = |message: String| ConfigError::Override { key: key.to_owned(), message };
    let mut node = table;
    for part in &parts[..parts.len() - 1] {
        let entry = node.entry((*part).to_owned()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        node = entry.as_table_mut().ok_or_else(|| err(format!("{part:?} is not a table")))?;
    }
    let last = parts[parts.len() - 1];
    node.insert(last.to_owned(), parse_value(value.trim()));
    Ok(())
}
