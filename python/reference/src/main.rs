//! Pure-Rust reference runs that python/tests compare the Python package with, so that
//! "the same as Rust" is checked against Rust that never passed through Python:
//!
//! - `vge-python-reference env-trace`: reads `{"object", "env", "seed", "actions"}` (JSON)
//!   from stdin, resets a `vge_sim::Env` with the seed and steps it with the actions, and
//!   prints every observation and reward as the bits of their `f32`s (JSON), with the
//!   terminated and truncated flags, until the episode ends (later actions are not used).
//! - `vge-python-reference policy-actions POLICY OBS OUT [HAND]`: the actions of the policy
//!   file for the `f32` little-endian observations in OBS (rows of the policy's input width),
//!   written to OUT the same way, loaded and run the way `vge eval` does
//!   (`vge_run::eval`'s `with_runtime_policy`: the file's hand, dimensions, observation layout
//!   and action names checked against the hand, its bytes copied to a 16-byte aligned buffer,
//!   a `Policy<8, 1024>`). HAND is a shipped hand's name or an MJCF path (default `vge15`);
//!   the layout is that of the observation set the file records, on that hand.
//! - `vge-python-reference write-mjcf FILE [TIMESTEP_S]`: the hand, cube and settled grasp
//!   as MJCF for MuJoCo, by the call `vge bench sim --write-mjcf` makes
//!   (`vge_sim::mjcf::settled_grasp_mjcf` of the default env, seed 0; default timestep
//!   1/240 s), for scripts/bench-python-vs-mujoco.sh without a libtorch build.
//! - `vge-python-reference bench-actions FILE STEPS`: the bench's action table, as
//!   `vge bench sim --write-actions` writes it (`vge_sim::bench::first_world_actions_f32_le`
//!   for the default env's hand, at its `max_action_rad`), for the same script.

use std::io::Read;
use std::process::ExitCode;

use serde::Deserialize;
use vge_config_file::EnvKeys;
use vge_runtime::{AlignedBytes, Policy};
use vge_sim::{Env, ObservationLayout, ObservationSet};

/// `vge eval`'s runtime capacity (`vge_run::eval::EVAL_MAX_LAYERS`, `EVAL_MAX_WIDTH`).
const EVAL_MAX_LAYERS: usize = 8;
const EVAL_MAX_WIDTH: usize = 1024;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TraceRequest {
    object: String,
    /// `[env]` keys.
    #[serde(default)]
    env: toml::Table,
    seed: u64,
    actions: Vec<Vec<f32>>,
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

fn env_trace() -> Result<(), String> {
    let mut text = String::new();
    std::io::stdin().read_to_string(&mut text).map_err(|e| format!("reading stdin: {e}"))?;
    let request: TraceRequest = serde_json::from_str(&text).map_err(|e| format!("request: {e}"))?;
    let mut table = request.env;
    table.insert("objects".to_owned(), toml::Value::Array(vec![toml::Value::String(request.object)]));
    let keys = EnvKeys::from_table(table, "request").map_err(|e| e.to_string())?;
    let mut env =
        Env::new(keys.env_config(0, "request").map_err(|e| e.to_string())?).map_err(|e| e.to_string())?;
    let (obs, _) = env.reset(request.seed).map_err(|e| e.to_string())?;
    let mut observations = vec![bits(&obs)];
    let (mut rewards, mut terminated, mut truncated) = (Vec::new(), Vec::new(), Vec::new());
    for (i, action) in request.actions.iter().enumerate() {
        if terminated.last() == Some(&true) || truncated.last() == Some(&true) {
            break;
        }
        let r = env.step(action).map_err(|e| format!("step {i}: {e}"))?;
        observations.push(bits(&r.obs));
        rewards.push(r.reward.to_bits());
        terminated.push(r.terminated);
        truncated.push(r.truncated);
    }
    let out = serde_json::json!({
        "obs_bits": observations,
        "reward_bits": rewards,
        "terminated": terminated,
        "truncated": truncated,
    });
    println!("{out}");
    Ok(())
}

fn policy_actions(policy: &str, obs_path: &str, out_path: &str, hand: &str) -> Result<(), String> {
    let hand = vge_sim::hands::load(hand).map_err(|e| e.to_string())?;
    let bytes = std::fs::read(policy).map_err(|e| format!("reading {policy}: {e}"))?;
    let info = vge_runtime::policy::inspect(&bytes).map_err(|e| format!("{policy}: {e}"))?;
    let set_name = info.task.map_or(vge_runtime::policy::UNRECORDED_OBSERVATION_SET, |t| t.observation_set);
    let set = ObservationSet::parse(set_name).map_err(|e| format!("{policy}: {e}"))?;
    let layout = ObservationLayout::new(set, hand.num_joints(), hand.num_fingers());
    vge_sim::check_policy_interface(&info, &hand, &layout).map_err(|e| format!("{policy}: {e}"))?;
    let aligned = AlignedBytes::new(&bytes);
    let mut storage = vec![0.0f32; info.storage_len];
    let runtime = Policy::<EVAL_MAX_LAYERS, EVAL_MAX_WIDTH>::load(&aligned, &mut storage)
        .map_err(|e| format!("{policy}: {e}"))?;
    let (obs_dim, joints) = (layout.dim(), hand.num_joints());
    let raw = std::fs::read(obs_path).map_err(|e| format!("reading {obs_path}: {e}"))?;
    if raw.len() % (4 * obs_dim) != 0 {
        return Err(format!("{obs_path}: {} bytes is not a whole number of {obs_dim}-float rows", raw.len()));
    }
    let obs: Vec<f32> = raw.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    let mut out = Vec::with_capacity(obs.len() / obs_dim * joints * 4);
    let mut action = vec![0.0f32; joints];
    for (i, row) in obs.chunks_exact(obs_dim).enumerate() {
        runtime.forward(row, &mut action).map_err(|e| format!("observation {i}: {e}"))?;
        out.extend(action.iter().flat_map(|a| a.to_le_bytes()));
    }
    std::fs::write(out_path, out).map_err(|e| format!("writing {out_path}: {e}"))
}

fn write_mjcf(path: &str, timestep_s: Option<&str>) -> Result<(), String> {
    let timestep_s: f32 = match timestep_s {
        None => 1.0 / 240.0,
        Some(t) => t.parse().map_err(|e| format!("timestep `{t}`: {e}"))?,
    };
    if !(timestep_s.is_finite() && timestep_s > 0.0) {
        return Err(format!("timestep {timestep_s} s: needs a positive number"));
    }
    let xml = vge_sim::mjcf::settled_grasp_mjcf(&vge_sim::EnvConfig::default(), 0, timestep_s)
        .map_err(|e| e.to_string())?;
    std::fs::write(path, xml).map_err(|e| format!("writing {path}: {e}"))
}

fn bench_actions(path: &str, steps: &str) -> Result<(), String> {
    let steps: usize = steps.parse().map_err(|e| format!("steps `{steps}`: {e}"))?;
    if steps == 0 {
        return Err("steps: needs at least 1".to_owned());
    }
    let env = vge_sim::EnvConfig::default();
    let bytes = vge_sim::bench::first_world_actions_f32_le(steps, env.hand.num_joints(), env.max_action_rad);
    std::fs::write(path, bytes).map_err(|e| format!("writing {path}: {e}"))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.iter().map(String::as_str).collect::<Vec<_>>().as_slice() {
        ["env-trace"] => env_trace(),
        ["policy-actions", policy, obs, out] => policy_actions(policy, obs, out, "vge15"),
        ["policy-actions", policy, obs, out, hand] => policy_actions(policy, obs, out, hand),
        ["write-mjcf", path] => write_mjcf(path, None),
        ["write-mjcf", path, timestep_s] => write_mjcf(path, Some(timestep_s)),
        ["bench-actions", path, steps] => bench_actions(path, steps),
        _ => Err("usage: vge-python-reference env-trace < REQUEST.json\n       \
                  vge-python-reference policy-actions POLICY OBS.f32 OUT.f32 [HAND]\n       \
                  vge-python-reference write-mjcf FILE [TIMESTEP_S]\n       \
                  vge-python-reference bench-actions FILE STEPS"
            .to_owned()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vge-python-reference: {e}");
            ExitCode::FAILURE
        }
    }
}
