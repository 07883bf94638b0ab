//! `vge ship`: a finished run's policy copied to a policies folder and measured, as the gait
//! that comes with vge.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use vge_lab::ship::{self, ShipOptions, ShippedFiles};

/// Ship a run's policy as a measured gait that comes with vge (policies/NAME.*).
///
/// Takes the run's final policy unless told, copies it and the run's config.toml to the
/// --policies folder (DIR, default policies/) as NAME.vgep and NAME.toml, then measures the
/// copy with the success test (20 randomised 30 s episodes) and the robustness test (10
/// episodes per level, 5 levels per axis up to the paper's), and writes both, the run it
/// came from and the goals with whether each holds to DIR/NAME.json, the robustness figure
/// to DIR/NAME-robustness.png and the gait diagram of the success test's first episode to
/// DIR/NAME-gait.png.
///
/// Measured on the run's own task (its config.toml: object, hand, physics, reward; not its
/// training disturbances). The goals: success >= 0.8, and >= 0.75 of the clean return at each
/// axis's paper level, the push at the object's weight read as the paper's (a force of its
/// size in a random direction). The Gaussian push with the weight as each component's std
/// (1.6 times the weight on average) is measured beside them.
///
/// A run on several objects (configs/multi-object-*.toml) is measured on each: the success
/// test per object (--episodes each; the goals: >= 0.8 on the first object, >= 0.5 on every
/// other), the robustness test on the first object (all levels; its goals as above) and on
/// the others at the paper's levels (beside the goals); NAME.json gains `per_object`, and the
/// gait diagrams are NAME-gait-OBJECT.png, with all of them in NAME-gait.png. Nothing is
/// written if the policy cannot be read or measured. About 5 min on 2 cores per object.
/// `vge screen` chooses among a run's snapshots. A name already shipped in DIR is refused
/// before anything is measured, unless --force replaces it.
///
/// Example: vge ship runs/robust/seed-0 --policy policy-best.vgep --name cube
#[derive(Debug, Args)]
pub struct ShipArgs {
    /// The finished training run's folder.
    run: PathBuf,
    /// The policy file to ship, relative to the run's folder: policy.vgep (the final policy),
    /// policy-best.vgep (the snapshot the run's selection picked on its validation grasps) or
    /// snapshots/policy-STEP.vgep.
    #[arg(long, default_value = vge_run::run_dir::POLICY)]
    policy: String,
    /// The shipped gait's name: its files are NAME.vgep, NAME.toml, NAME.json,
    /// NAME-robustness.png and NAME-gait.png (for several objects: all of them, and
    /// NAME-gait-OBJECT.png for each).
    #[arg(long, default_value = "cube")]
    name: String,
    /// The folder the files go to.
    #[arg(long, default_value = "policies")]
    policies: PathBuf,
    /// Episodes of the success test.
    #[arg(long, default_value_t = ShipOptions::default().success_episodes)]
    episodes: usize,
    /// Episodes per level of the robustness test.
    #[arg(long, default_value_t = ShipOptions::default().robustness_episodes)]
    robustness_episodes: usize,
    /// Replace a gait already shipped under NAME (its files are overwritten once the new
    /// policy has been measured).
    #[arg(long)]
    force: bool,
}

pub fn run(args: ShipArgs) -> anyhow::Result<()> {
    let ShipArgs { run, policy, name, policies, episodes, robustness_episodes, force } = args;
    anyhow::ensure!(
        episodes > 0 && robustness_episodes > 0,
        "--episodes and --robustness-episodes must be at least 1"
    );
    anyhow::ensure!(
        !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_'),
        "--name {name:?}: letters, digits, '-' and '_' only (it names files)"
    );
    let files = ShippedFiles::new(&policies, &name);
    if let (Some(existing), false) = (files.already_shipped(), force) {
        anyhow::bail!(
            "{} exists: a gait is already shipped as {name:?}; choose another --name, or --force to replace it",
            existing.display()
        );
    }
    let options =
        ShipOptions { policy, success_episodes: episodes, robustness_episodes, ..ShipOptions::default() };
    eprintln!("vge ship: measuring {} (success test, then robustness)", run.join(&options.policy).display());
    let (record, gait_pngs) = ship::ship(&run, &files, &options, |r| {
        eprintln!(
            "  {:<24} {:>9.4}  return {:>5.1}% of clean  success {:.2}",
            r.axis,
            r.level,
            100.0 * r.return_fraction,
            r.success_rate
        );
    })
    .with_context(|| format!("shipping from {}", run.display()))?;
    println!(
        "success test: {:.2} success, {:.2} drops, {:.1} rad per episode",
        record.success_test.success_rate,
        record.success_test.drop_rate,
        record.success_test.mean_rotation_rad
    );
    for o in &record.per_object {
        println!(
            "  {:<16} {:.2} success, {:.2} drops, {:.1} rad per episode",
            o.object, o.success_test.success_rate, o.success_test.drop_rate, o.success_test.mean_rotation_rad
        );
    }
    for (goal, ok) in &record.goals {
        println!("  {}  {goal}", if *ok { "holds" } else { "FAILS" });
    }
    for (goal, ok) in &record.beside_goals {
        println!("  ({}, beside the goals)  {goal}", if *ok { "holds" } else { "fails" });
    }
    let gaits: Vec<String> = gait_pngs.iter().map(|p| p.display().to_string()).collect();
    println!(
        "wrote {}, {}, {}, {} and {}",
        files.policy.display(),
        files.config.display(),
        files.record.display(),
        files.robustness_png.display(),
        gaits.join(", ")
    );
    Ok(())
}
