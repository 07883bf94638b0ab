//! `vge facts`: what a results write-up quotes about a run, finished and scored or still
//! training.

use std::path::PathBuf;

use clap::Args;

/// Print a run's facts as the results write-ups report them
///
/// Reads RUN_DIR/score.json (held-out scores), final-eval.json (wall time), metrics.csv
/// (the critic's mean Q against the discounted return collected, from 100k steps on, and
/// their gap over the last three windows; the actor's last log-std where it was logged; the
/// BC term; the controller's share), eval.csv (the periodic tests), train.log (each training
/// segment: where it started, its wall time, how it ended) and the lanes' logs (when each
/// lane started and ended the run, named by its path after results/), and prints one table
/// row and the numbers a bullet quotes. A run still training (no final-eval.json) gets
/// everything but the row: where its metrics stand, its critic's gap so far, its periodic
/// tests; a finished run without score.json is told to run `vge score`.
///
/// Example:
///   vge facts docs/results/variants/sac-alpha0/table1/rl/seed-6
#[derive(Debug, Args)]
#[command(verbatim_doc_comment)]
pub struct FactsArgs {
    /// Run folders (each with its metrics.csv), finished or still training.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// The folder of the lanes' logs (`vge queue run` writes them).
    #[arg(long, default_value = "runs/lanes")]
    lanes: PathBuf,
}

/// `vge facts`.
pub fn run(args: FactsArgs) -> anyhow::Result<()> {
    for run in &args.runs {
        print!("{}", vge_lab::run_facts::facts(run, &args.lanes)?);
    }
    Ok(())
}
