//! `vge score`: finished runs scored on many held-out episodes (`score.json`).

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;

/// Score finished runs on held-out episodes into DIR/score.json
///
/// Training writes it at its end too. Scored: the run's selected policy (its own model selection on
/// validation grasps, policy-best.vgep), its final policy (policy.vgep) and, where the
/// last 3 periodic snapshots are kept, their mean, all on the same episodes.
///
/// The episodes: --episodes (default 100) of the run's success test (30 s, grasps
/// randomised by 0.02 rad in every stored config; no training disturbances) from env
/// seeds --seed + k, the same for every run and apart from the validation and test
/// episodes training drew. An episode succeeds when the object turns >= 2 pi about z
/// without a drop. score.json: {"episodes", "seed", "selected", "final",
/// "last_snapshots"}, each policy's success_rate, mean_return, drop_rate,
/// mean_rotation_rad, mean_contact_switches, mean_tip_slip_m (m of fingertip travel over
/// the object per episode), its file, step and CRC-32 (docs/scoring.md). A run on several
/// objects is scored on those episodes for each object: the figures pool them, and
/// "per_object" gives each object's.
///
/// A run already scored with the same episodes, seed, definition and policy files is
/// skipped (--force scores it again). An unfinished run (no final-eval.json) is refused
/// and nothing is written; a missing, damaged or other-layout policy file fails naming
/// the file. Runs are scored one after another, their episodes side by side on
/// --threads threads (default: RAYON_NUM_THREADS, else all cores).
///
/// Examples:
///   vge score docs/results/table1/cube-fg-fge/seed-*
///   vge score --threads 1 --episodes 200 runs/fg/seed-0
#[derive(Debug, Args)]
#[command(verbatim_doc_comment)]
pub struct ScoreArgs {
    /// Finished run folders (each with config.toml, final-eval.json, policy.vgep).
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// Held-out episodes per policy.
    #[arg(long, default_value_t = vge_run::score::DEFAULT_EPISODES)]
    episodes: usize,
    /// Env seed of the first held-out episode (episode k: seed + k).
    #[arg(long, default_value_t = vge_run::score::HELD_OUT_SEED)]
    seed: u64,
    /// Score again runs whose score.json already holds this score.
    #[arg(long)]
    force: bool,
    /// Threads the episodes run on (default: RAYON_NUM_THREADS, else all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    threads: Option<u32>,
}

/// `vge score`.
pub fn run(args: ScoreArgs) -> anyhow::Result<()> {
    let ScoreArgs { runs, episodes, seed, force, threads } = args;
    score(&runs, episodes, seed, force, threads)
}

/// `vge score`: every run in turn, its episodes on `threads` threads, a progress line per
/// batch of episodes.
fn score(
    runs: &[PathBuf],
    episodes: usize,
    seed: u64,
    force: bool,
    threads: Option<u32>,
) -> anyhow::Result<()> {
    use vge_run::score::{ScoreOptions, ScoreOutcome, score_run};
    let options = ScoreOptions { episodes, seed, force };
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        pool = pool.num_threads(n as usize);
    }
    let pool = pool.build().context("starting the scoring threads")?;
    let mut failed = Vec::new();
    for (i, dir) in runs.iter().enumerate() {
        let started = std::time::Instant::now();
        let mut last_shown = std::time::Instant::now();
        let mut show = |p: &vge_run::score::ScoreProgress| {
            if p.done == p.total || last_shown.elapsed().as_secs_f64() >= 10.0 {
                errln!(
                    "vge score: run {}/{} {}: {} episodes of {} ({}), {:.0} s",
                    i + 1,
                    runs.len(),
                    p.dir.display(),
                    p.done,
                    p.total,
                    p.file,
                    started.elapsed().as_secs_f64()
                );
                last_shown = std::time::Instant::now();
            }
        };
        match pool.install(|| score_run(dir, &options, &mut show)) {
            Ok((outcome, notes)) => {
                for note in notes {
                    errln!("vge score: {}: {note}", dir.display());
                }
                let (verb, s) = match &outcome {
                    ScoreOutcome::Scored(s) => ("scored", s),
                    ScoreOutcome::Skipped(s) => ("already scored, skipped", s),
                };
                let selected =
                    s.selected.as_ref().map_or("-".to_owned(), |p| format!("{:.2}", p.success_rate));
                let last =
                    s.last_snapshots.as_ref().map_or("-".to_owned(), |p| format!("{:.2}", p.success_rate));
                outln!(
                    "{}: {verb}: success on {} held-out episodes: selected {selected}, final {:.2}, last snapshots {last} ({:.0} s)",
                    dir.display(),
                    s.episodes,
                    s.final_policy.success_rate,
                    started.elapsed().as_secs_f64()
                );
                let switches_and_slip = |p: &vge_run::run_dir::PolicyScore| {
                    let slip = p.mean_tip_slip_m.map_or("-".to_owned(), |m| format!("{m:.3} m"));
                    format!("{:.1} switches, {slip} fingertip slip", p.mean_contact_switches)
                };
                outln!(
                    "  per episode: selected {}, final {}",
                    s.selected.as_ref().map_or("-".to_owned(), switches_and_slip),
                    switches_and_slip(&s.final_policy)
                );
                // A run on several objects: each object's success, selected and final.
                if let Some(per_object) = &s.final_policy.per_object {
                    let selected = s.selected.as_ref().and_then(|p| p.per_object.as_ref());
                    for (k, (object, f)) in per_object.0.iter().enumerate() {
                        let sel = selected
                            .and_then(|p| p.0.get(k))
                            .map_or("-".to_owned(), |(_, f)| format!("{:.2}", f.success_rate));
                        outln!("  {object}: selected {sel}, final {:.2}", f.success_rate);
                    }
                }
            }
            Err(e) => {
                errln!("vge score: {e}");
                failed.push(dir.display().to_string());
            }
        }
    }
    if !failed.is_empty() {
        bail!("{} of {} runs not scored: {}", failed.len(), runs.len(), failed.join(", "));
    }
    Ok(())
}
