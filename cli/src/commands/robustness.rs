//! `vge robustness`: return, success and drops of a policy against the level of one
//! disturbance at a time (the paper's Fig. 4).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use super::eval::EpisodeArgs;

/// The paper's robustness test (Fig. 4): return, success and drops of a policy against the
/// level of one disturbance at a time.
///
/// Axes, each from 0 to the paper's level in --levels even steps, the others off: noise
/// on the observed joint positions (0..0.1 rad), error on the contact normals (0..50%),
/// error on the contact positions (0..3 mm), and a random force on the object redrawn with
/// probability 0.1 per step, two ways: Gaussian per component with std 0..its weight
/// (perturbation_force_n; its mean size is 1.6 times the std), and of magnitude 0..its
/// weight in a random direction (perturbation_magnitude_n, the paper's "forces
/// equivalent to the full weight of the object"). Every level runs the same --episodes episodes
/// (same grasps). Writes DIR/robustness.csv (one row per axis and level, with
/// return_fraction = return / undisturbed return), DIR/robustness.json and
/// DIR/robustness.png.
///
/// Example: vge robustness --policy runs/fg/seed-0/policy.vgep --episodes 10 --out rob/
#[derive(Debug, Args)]
pub struct RobustnessArgs {
    /// The policy file.
    #[arg(long)]
    policy: PathBuf,
    /// Episodes per level.
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Levels per axis, evenly from 0 to the paper's level (at least 2).
    #[arg(long, default_value_t = 5)]
    levels: usize,
    /// Only these axes, comma-separated (joint_noise_rad, normal_error_frac, position_error_m,
    /// perturbation_force_n, perturbation_magnitude_n), e.g. to screen snapshots on the pushes
    /// alone; all five when left out.
    #[arg(long, value_delimiter = ',', value_parser = parse_robustness_axis)]
    axes: Vec<vge_lab::robustness::Axis>,
    /// The same episodes (seeds, grasps) run at every level.
    #[command(flatten)]
    episode: EpisodeArgs,
    /// Output folder (created).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: RobustnessArgs) -> anyhow::Result<()> {
    let RobustnessArgs {
        policy,
        episodes,
        levels,
        axes,
        episode: EpisodeArgs { object, seed, episode_s, grasp_noise_rad },
        out,
    } = args;
    use vge_lab::robustness::{self, RobustnessOptions};
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    let max = vge_lab::robustness::MAX_LEVELS;
    anyhow::ensure!(
        (2..=max).contains(&levels),
        "--levels must be 2 (0 and the paper's level) to {max}, got {levels}"
    );
    anyhow::ensure!(episode_s.is_finite() && episode_s > 0.0, "--episode-s must be positive");
    anyhow::ensure!(grasp_noise_rad.is_finite() && grasp_noise_rad >= 0.0, "--grasp-noise-rad must be >= 0");
    let bytes = vge_run::eval::read_policy_file(&policy)?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    // The policy's own task: its hand, orientation and observation.
    let base = vge_run::eval::policy_task_env(&bytes, None, object)
        .with_context(|| format!("the task of {}", policy.display()))?;
    let axes = if axes.is_empty() { robustness::Axis::ALL.to_vec() } else { axes };
    for (i, axis) in axes.iter().enumerate() {
        anyhow::ensure!(!axes[..i].contains(axis), "--axes names {} twice", axis.name());
    }
    let total = 1 + axes.len() * (levels - 1);
    let options = RobustnessOptions { episodes, episode_s, grasp_noise_rad, seed, levels, axes };
    eprintln!("vge robustness: {total} evaluations of {episodes} episodes x {episode_s} s on the {object}");
    let report = robustness::run(&bytes, &base, &options, |r| {
        eprintln!(
            "  {:<22} {:>9.4}  return {:>8.3} ({:>5.1}% of clean)  success {:.2}  drops {:.2}",
            r.axis,
            r.level,
            r.mean_return,
            100.0 * r.return_fraction,
            r.success_rate,
            r.drop_rate
        );
    })
    .with_context(|| format!("evaluating {}", policy.display()))?;
    let csv = out.join("robustness.csv");
    std::fs::write(&csv, robustness::to_csv(&report))
        .with_context(|| format!("writing {}", csv.display()))?;
    let json = out.join("robustness.json");
    let text = serde_json::to_string_pretty(&report).context("serialising the report")?;
    std::fs::write(&json, text).with_context(|| format!("writing {}", json.display()))?;
    let png = out.join("robustness.png");
    robustness::plot(&report, &png).with_context(|| format!("drawing {}", png.display()))?;
    println!("wrote {}, {} and {}", csv.display(), json.display(), png.display());
    Ok(())
}

fn parse_robustness_axis(name: &str) -> Result<vge_lab::robustness::Axis, String> {
    use vge_lab::robustness::Axis;
    Axis::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = Axis::ALL.iter().map(|a| a.name()).collect();
        format!("unknown axis {name:?}; the axes are {}", names.join(", "))
    })
}
