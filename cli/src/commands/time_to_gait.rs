//! `vge time-to-gait`: how long runs took to their first passing periodic test.

use std::path::PathBuf;

use clap::Args;

/// Time to a gait: wall seconds from `vge train` to each run's first passing test
///
/// Per run: the first periodic test (eval.csv) whose success reaches --success, the wall
/// seconds the session had run at it (that step over metrics.csv's steps_per_s there,
/// which counts from the session's start and is logged before the test runs), the env
/// steps/s up to it, whether the run was resumed, and the held-out success of its
/// selected and final policies (score.json; `-` before `vge score`). A resumed run's
/// count restarts at its checkpoint: its wall time is one session's only if its first
/// pass came before the first resume. Signs of a resume: train.log's segments (a lane's
/// or a sweep's), tensorboard/'s event files (one per session), metrics.csv's session
/// clock going back, or passing final-eval.json's wall time (which sums every session).
///
/// Over the runs given, one group: the median time to a gait (a finished run that never
/// passed counts as slower than any that did; runs whose pass came after a resume, and
/// runs still training without a pass, are left out and named), the runs that never
/// passed, and the IQM and mean of the held-out success with 95% intervals, drawn as
/// `vge compare NAME=...` draws them for the same --name (Table I's cells are named
/// `fg/vge` and so on).
///
/// Example:
///   vge time-to-gait docs/results/cube-fg-vge-seeds --name fg/vge
///   vge time-to-gait runs/time-to-gait/default/seed-{0,1,2,3,4} --json
#[derive(Debug, Args)]
#[command(verbatim_doc_comment)]
pub struct TimeToGaitArgs {
    /// Run folders, or folders with runs below them.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// The success a periodic test must reach to count as a gait.
    #[arg(long, default_value_t = vge_run::eval::LEARNED_SUCCESS_RATE)]
    success: f64,
    /// The group's name: the label its intervals are drawn under.
    #[arg(long, default_value = "runs")]
    name: String,
    /// Print one JSON object (`runs`, `group`) instead of the table.
    #[arg(long)]
    json: bool,
}

/// `vge time-to-gait`.
pub fn run(args: TimeToGaitArgs) -> anyhow::Result<()> {
    use vge_lab::time_to_gait::{read_run, summarise, to_text};
    anyhow::ensure!(
        args.success.is_finite() && (0.0..=1.0).contains(&args.success),
        "--success {}: a share of episodes, from 0 to 1",
        args.success
    );
    let dirs = vge_run::run_dir::find_runs(&args.runs)?;
    anyhow::ensure!(
        !dirs.is_empty(),
        "no run folder (config.toml and metrics.csv) at or below the paths given"
    );
    let runs = dirs.iter().map(|d| read_run(d, args.success)).collect::<Result<Vec<_>, _>>()?;
    let group = summarise(&args.name, &runs)?;
    if args.json {
        println!("{}", serde_json::json!({ "runs": runs, "group": group }));
    } else {
        print!("{}", to_text(&runs, &group));
    }
    Ok(())
}
