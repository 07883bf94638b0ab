//! Evaluation: an exported policy file on the `no_std` runtime (deterministic) in the sim,
//! for N episodes with the env's optional noise and perturbations.
//!
//! Success: the object turned at least 2π about z (unwrapped rotation at the end of the
//! episode) and the episode was not terminated (no drop, never fewer than the env's minimum
//! contacts), the same notion of drop as `vge controller`.

use std::path::Path;

use thiserror::Error;
use vge_runtime::Policy;
use vge_sim::{Env, EnvConfig, NUM_JOINTS, OBS_DIM, SimError};

/// Largest network the evaluator loads: layers and width.
pub const EVAL_MAX_LAYERS: usize = 8;
pub const EVAL_MAX_WIDTH: usize = 1024;

#[derive(Debug, Error)]
pub enum EvalError {
    #[error("reading policy {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("policy: {0}")]
    Policy(String),
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("episodes must be at least 1")]
    NoEpisodes,
}

/// Figures over the evaluated episodes.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalReport {
    pub episodes: usize,
    pub mean_return: f64,
    /// Mean object rotation about world z (rad, unwrapped; positive = the rewarded sense).
    pub mean_rotation_rad: f64,
    /// Share of episodes turned >= 2π without a drop.
    pub success_rate: f64,
    /// Share of episodes the env terminated (drop or too few contacts).
    pub drop_rate: f64,
    pub mean_contacts: f64,
    pub mean_length: f64,
}

impl EvalReport {
    /// One JSON object on one line.
    pub fn to_json_line(&self) -> String {
        format!(
            "{{\"episodes\":{},\"mean_return\":{:.6},\"mean_rotation_rad\":{:.6},\"success_rate\":{:.4},\"drop_rate\":{:.4},\"mean_contacts\":{:.4},\"mean_length\":{:.2}}}",
            self.episodes,
            self.mean_return,
            self.mean_rotation_rad,
            self.success_rate,
            self.drop_rate,
            self.mean_contacts,
            self.mean_length
        )
    }
}

fn wrap_pi(a: f32) -> f32 {
    let tau = std::f32::consts::TAU;
    a - tau * ((a + std::f32::consts::PI) / tau).floor()
}

/// One episode's figures.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EpisodeOutcome {
    pub episode_return: f64,
    pub rotation_rad: f64,
    pub terminated: bool,
    pub mean_contacts: f64,
    pub length: usize,
}

impl EpisodeOutcome {
    pub fn success(&self) -> bool {
        !self.terminated && self.rotation_rad >= std::f64::consts::TAU
    }
}

/// A policy: fills the action for an observation.
pub type PolicyFn<'a> = dyn FnMut(&[f32; OBS_DIM], &mut [f32; NUM_JOINTS]) -> Result<(), String> + 'a;

/// Runs `episodes` episodes (env seeds `seed`, `seed + 1`, ...) with `policy(obs, action)`.
pub fn run_episodes(
    env_config: &EnvConfig,
    episodes: usize,
    seed: u64,
    policy: &mut PolicyFn<'_>,
) -> Result<EvalReport, EvalError> {
    if episodes == 0 {
        return Err(EvalError::NoEpisodes);
    }
    let mut env = Env::new(env_config.clone())?;
    let mut outcomes = Vec::with_capacity(episodes);
    for e in 0..episodes {
        let (mut obs, _) = env.reset(seed.wrapping_add(e as u64))?;
        let mut yaw = env.privileged().ok_or(SimError::NotReset)?.object.yaw_rad();
        let mut out = EpisodeOutcome::default();
        let mut contacts = 0usize;
        let mut action = [0.0f32; NUM_JOINTS];
        loop {
            policy(&obs, &mut action).map_err(EvalError::Policy)?;
            let r = env.step(&action)?;
            out.episode_return += f64::from(r.reward);
            out.rotation_rad += f64::from(wrap_pi(r.info.object_yaw_rad - yaw));
            yaw = r.info.object_yaw_rad;
            contacts += r.info.num_tip_contacts;
            out.length += 1;
            obs = r.obs;
            if r.terminated || r.truncated {
                out.terminated = r.terminated;
                break;
            }
        }
        out.mean_contacts = contacts as f64 / out.length.max(1) as f64;
        outcomes.push(out);
    }
    Ok(summarise(&outcomes))
}

/// Means over episode outcomes.
pub fn summarise(outcomes: &[EpisodeOutcome]) -> EvalReport {
    let n = outcomes.len().max(1) as f64;
    let mean = |f: &dyn Fn(&EpisodeOutcome) -> f64| outcomes.iter().map(f).sum::<f64>() / n;
    EvalReport {
        episodes: outcomes.len(),
        mean_return: mean(&|o| o.episode_return),
        mean_rotation_rad: mean(&|o| o.rotation_rad),
        success_rate: mean(&|o| f64::from(u8::from(o.success()))),
        drop_rate: mean(&|o| f64::from(u8::from(o.terminated))),
        mean_contacts: mean(&|o| o.mean_contacts),
        mean_length: mean(&|o| o.length as f64),
    }
}

/// Evaluates an encoded policy file on the runtime. The env runs at the policy's control
/// rate (`env.control_hz` is replaced by the file's).
pub fn eval_policy_bytes(
    bytes: &[u8],
    env: &EnvConfig,
    episodes: usize,
    seed: u64,
) -> Result<EvalReport, EvalError> {
    let info = vge_runtime::policy::inspect(bytes).map_err(|e| EvalError::Policy(format!("{e:?}")))?;
    if info.obs_dim != OBS_DIM || info.act_dim != NUM_JOINTS {
        return Err(EvalError::Policy(format!(
            "policy maps {} observations to {} actions, the hand needs {OBS_DIM} -> {NUM_JOINTS}",
            info.obs_dim, info.act_dim
        )));
    }
    let mut env = env.clone();
    env.control_hz = info.control_hz;
    let mut storage = vec![0.0f32; info.storage_len];
    let policy = Policy::<EVAL_MAX_LAYERS, EVAL_MAX_WIDTH>::load(bytes, &mut storage)
        .map_err(|e| EvalError::Policy(format!("{e:?}")))?;
    run_episodes(&env, episodes, seed, &mut |obs, action| {
        policy.forward(obs, action).map_err(|e| format!("{e:?}"))
    })
}

/// [`eval_policy_bytes`] of the file at `path`.
pub fn eval_policy_file(
    path: &Path,
    env: &EnvConfig,
    episodes: usize,
    seed: u64,
) -> Result<EvalReport, EvalError> {
    let bytes =
        std::fs::read(path).map_err(|source| EvalError::Io { path: path.display().to_string(), source })?;
    eval_policy_bytes(&bytes, env, episodes, seed)
}
