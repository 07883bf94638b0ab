//! Diagnostic for the robustness goal under pushes: what a policy's grasp looks like when a push drops
//! the object. Runs a policy file on the runtime under the robustness test's force (std per
//! axis, redrawn with probability 0.1 per step) and, for each drop, finds its onset: the
//! last step at which the object was still within `ONSET_M` of its starting height. It
//! prints which fingertips touched and what force acted at the onsets, beside the same
//! figures over every step of the episodes, so a drop can be told apart from bad luck:
//!
//!   cargo run --release -p vge-lab --example drops_under_push -- policies/cube.vgep 1.4715 20 2000
//!
//! Arguments: POLICY FORCE_STD_N [EPISODES=20] [SEED=2000].
use anyhow::Context;
use vge_lab::robustness::Axis;
use vge_run::eval::{
    EVAL_MAX_LAYERS, EVAL_MAX_WIDTH, SUCCESS_TEST_EPISODE_S, SUCCESS_TEST_GRASP_NOISE_RAD,
    run_episode_observed, success_test_env,
};
use vge_runtime::{AlignedBytes, Policy};
use vge_sim::EnvConfig;

/// How far the object may sink below its starting height before a drop counts as begun (m).
const ONSET_M: f32 = 0.005;

/// One control step: which fingertips touch, the object's height, the force on it.
#[derive(Clone)]
struct Step {
    tips: Vec<bool>,
    height_m: f32,
    force_n: [f32; 3],
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(args.len() >= 3, "usage: drops_under_push POLICY FORCE_STD_N [EPISODES] [SEED]");
    let bytes = std::fs::read(&args[1]).with_context(|| format!("reading {}", args[1]))?;
    let force_std_n: f32 = args[2].parse().context("FORCE_STD_N")?;
    let episodes: u64 = args.get(3).map_or(Ok(20), |s| s.parse()).context("EPISODES")?;
    let seed: u64 = args.get(4).map_or(Ok(2000), |s| s.parse()).context("SEED")?;

    let info = vge_runtime::policy::inspect(&bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
    let aligned = AlignedBytes::new(&bytes);
    let mut storage = vec![0.0f32; info.storage_len];
    let policy = Policy::<EVAL_MAX_LAYERS, EVAL_MAX_WIDTH>::load(&aligned, &mut storage)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut env =
        success_test_env(&EnvConfig::default(), SUCCESS_TEST_EPISODE_S, SUCCESS_TEST_GRASP_NOISE_RAD);
    env.control_hz = info.control_hz;
    env.episode_length_steps = (SUCCESS_TEST_EPISODE_S * env.control_hz).round() as usize;
    // The robustness test's own force axis, so both apply the same force process.
    Axis::Perturbation.apply(&mut env, force_std_n);

    let fingers: Vec<String> = env.hand.fingers().iter().map(|f| f.name.clone()).collect();
    let act = |obs: &[f32], a: &mut [f32]| policy.forward(obs, a).map_err(|e| e.to_string());
    let mut all: Vec<Step> = Vec::new();
    let mut onsets: Vec<Step> = Vec::new();
    let mut drops = 0;
    for e in 0..episodes {
        let mut steps: Vec<Step> = Vec::new();
        let outcome = run_episode_observed(&env, seed + e, &act, |env, _, r, _| {
            steps.push(Step {
                tips: r.info.tip_contacts.clone(),
                height_m: r.info.object_height_m,
                force_n: env.external_force_n().into(),
            });
        })?;
        if outcome.terminated {
            drops += 1;
            // The first step's height stands for the held height: the grasp has settled by reset.
            let start = steps.first().map_or(0.0, |s| s.height_m);
            if let Some(i) = steps.iter().rposition(|s| s.height_m >= start - ONSET_M) {
                onsets.push(steps[i].clone());
            }
        }
        all.extend(steps);
    }

    println!("{episodes} episodes at {force_std_n} N per axis: {drops} drops, {} onsets found", onsets.len());
    println!("{:<26} {:>10} {:>10}", "", "all steps", "onsets");
    // A figure over the steps of `v`, or none where `v` is empty (no drops: no onsets).
    type Figure<'a> = &'a dyn Fn(&[Step]) -> f64;
    let row = |label: &str, figure: Figure<'_>| {
        let onset = if onsets.is_empty() { "-".to_owned() } else { format!("{:.2}", figure(&onsets)) };
        println!("{label:<26} {:>10.2} {onset:>10}", figure(&all));
    };
    let share = |f: &dyn Fn(&Step) -> bool, v: &[Step]| {
        100.0 * v.iter().filter(|s| f(s)).count() as f64 / v.len().max(1) as f64
    };
    let mean = |f: &dyn Fn(&Step) -> f32, v: &[Step]| {
        v.iter().map(|s| f64::from(f(s))).sum::<f64>() / v.len().max(1) as f64
    };
    for (k, name) in fingers.iter().enumerate() {
        row(&format!("{name} off (%)"), &|v| share(&|s| !s.tips[k], v));
    }
    let tips = |s: &Step| s.tips.iter().filter(|t| **t).count();
    row("fingertips on, mean", &|v| mean(&|s| tips(s) as f32, v));
    for n in 2..=fingers.len() {
        row(&format!("{n} fingertips on (%)"), &|v| share(&|s| tips(s) == n, v));
    }
    let norm = |s: &Step| s.force_n.iter().map(|f| f * f).sum::<f32>().sqrt();
    row("force magnitude, mean (N)", &|v| mean(&norm, v));
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        row(&format!("force {axis}, mean (N)"), &|v| mean(&|s| s.force_n[k], v));
    }
    Ok(())
}
