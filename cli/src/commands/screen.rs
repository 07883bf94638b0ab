//! `vge screen`: a finished run's passing snapshots and its final policy, tested again on
//! episodes the run never saw, to choose the one to ship.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use vge_lab::ship::{self, ScreenOptions};

/// Screen a run's snapshots for the policy to ship (`vge ship`).
///
/// Each snapshot whose periodic test passed (success >= --min-success in DIR/eval.csv), and the final policy, runs the
/// success test and the two pushes at the object's weight (the robustness test's
/// perturbation_magnitude_n and perturbation_force_n at their paper levels), all on episodes
/// from --seed, which training's tests never use. Everything runs on the run's own task (its
/// config.toml: object, hand, physics, reward; not its training disturbances), on each of its
/// objects for a run on several, pooled.
///
/// Writes DIR/screen.csv, one row per policy: step (`final` for the final policy), success,
/// drops, rotation_rad, and per push the return as a fraction of the clean return and the
/// success under it. The sensor-noise axes are left out (`vge ship` measures all five).
/// About 20 s per policy at 20 episodes on 2 cores.
///
/// Example: vge screen runs/robust/seed-0 && vge ship runs/robust/seed-0 --policy snapshots/policy-800000.vgep
#[derive(Debug, Args)]
pub struct ScreenArgs {
    /// The training run's folder.
    run: PathBuf,
    /// Episodes per test.
    #[arg(long, default_value_t = ScreenOptions::default().episodes)]
    episodes: usize,
    /// Seed of the first episode (episode k uses seed + k).
    #[arg(long, default_value_t = ScreenOptions::default().seed)]
    seed: u64,
    /// The periodic test's success a snapshot needs to be screened.
    #[arg(long, default_value_t = ScreenOptions::default().min_success)]
    min_success: f64,
}

pub fn run(args: ScreenArgs) -> anyhow::Result<()> {
    let ScreenArgs { run, episodes, seed, min_success } = args;
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    anyhow::ensure!((0.0..=1.0).contains(&min_success), "--min-success must be in [0, 1], got {min_success}");
    let candidates = ship::screen_candidates(&run, min_success)?;
    anyhow::ensure!(
        !candidates.is_empty(),
        "{}: no snapshot passed its periodic test (success >= {min_success}) and there is no final policy",
        run.display()
    );
    eprintln!("vge screen: {} policies, {episodes} episodes per test from seed {seed}", candidates.len());
    println!("step      success  drops  rotation_rad  push (size) return/success  push (std) return/success");
    let options = ScreenOptions { episodes, seed, min_success };
    let rows = ship::screen(&run, &candidates, &options, |r| {
        let step = r.step.map_or_else(|| "final".to_owned(), |s| s.to_string());
        println!(
            "{step:<9} {:>7.2} {:>6.2} {:>13.1} {:>14.2}/{:.2} {:>19.2}/{:.2}",
            r.success.success_rate,
            r.success.drop_rate,
            r.success.mean_rotation_rad,
            r.push_magnitude.return_fraction,
            r.push_magnitude.success_rate,
            r.push_std.return_fraction,
            r.push_std.success_rate,
        );
    })
    .with_context(|| format!("screening {}", run.display()))?;
    let csv = run.join(ship::SCREEN_CSV);
    vge_run::run_dir::atomic_file::write(&csv, ship::screen_csv(&rows).as_bytes())
        .with_context(|| format!("writing {}", csv.display()))?;
    println!("wrote {}", csv.display());
    Ok(())
}
