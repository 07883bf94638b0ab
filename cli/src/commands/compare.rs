//! `vge compare`: groups of scored runs compared with rliable's statistics.

use std::path::PathBuf;

use clap::Args;

/// Compare groups of scored runs with rliable's statistics (IQM, intervals, P(improvement))
///
/// Per group the IQM and mean of the runs' held-out success (score.json) with 95%
/// stratified bootstrap intervals, the probability that a run of one group beats a run
/// of another with its interval, performance profiles and IQM learning curves.
///
/// Each group is NAME=DIR,DIR,... (run folders, or folders with runs below them). Every
/// run must have its score.json (`vge score`). Writes OUT/compare.csv (group, policy,
/// runs, iqm, iqm_ci_low, iqm_ci_high, mean, mean_ci_low, mean_ci_high; for the
/// selected, final and last-snapshot policies), OUT/compare.md, OUT/improvement.csv
/// (a, b, prob_improvement, ci_low, ci_high; selected policy), OUT/improvement-final.csv
/// (the same for the final policies), OUT/aggregates.png,
/// OUT/profiles.png and OUT/curves.png (IQM of the periodic success and return against
/// env steps, with 95% bands). compare.md ends with the critic at the end of each run:
/// mean Q minus the collected return over its last 3 metrics windows (as `vge facts`
/// prints it), per run and the group's mean; for runs that log `mc_return_early`, the
/// gap against their episodes' early steps' returns, which the time limit does not cut;
/// then the gap at each run's hard stop (`vge.hard_stop`, where the controllers stop
/// acting: the windows up to that step). Definitions: docs/scoring.md.
///
/// --metric ranks runs by another figure of the same held-out episodes: held (share
/// without a drop), rotation_rad (mean rotation about z per episode) or return. The
/// success test stays the verdict; these tell groups apart where every run fails it.
///
/// Runs trained and scored on several objects are compared with each object a task, and
/// OUT/per-object.csv (also a table in compare.md) lists each run on each object: the step
/// of its first periodic test at 50% success on that object, and the selected and final
/// policies' success, drops, rotation and contact switches there, with the run's wall time.
///
/// Example:
///   vge compare fge=docs/results/table1/cube-fg-fge vge=docs/results/cube-fg-vge-seeds
///       --out cmp/ --pairs vge:fge
///   vge compare rl=runs/rl vge=runs/vge --metric rotation_rad --out cmp-rotation/
#[derive(Debug, Args)]
#[command(verbatim_doc_comment)]
pub struct CompareArgs {
    /// Groups: NAME=DIR,DIR,...
    #[arg(required = true, value_parser = vge_lab::compare::parse_group)]
    groups: Vec<vge_lab::compare::GroupSpec>,
    /// Output folder (created).
    #[arg(long)]
    out: PathBuf,
    /// Pairs A:B whose probability of improvement P(A > B) to report (default: every
    /// ordered pair of groups).
    #[arg(long, value_delimiter = ',', value_parser = vge_lab::compare::parse_pair)]
    pairs: Vec<(String, String)>,
    /// The figure of each run's held-out episodes to compare: success, held, rotation_rad
    /// or return (larger is better for each).
    #[arg(long, default_value = "success", value_parser = clap::value_parser!(vge_lab::compare::Metric))]
    metric: vge_lab::compare::Metric,
    /// Seed of the bootstrap resampling.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Bootstrap resamples per interval (at least 2000).
    #[arg(long, default_value_t = vge_lab::stats::RESAMPLES)]
    resamples: usize,
}

/// `vge compare`.
pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    let CompareArgs { groups, out, pairs, metric, seed, resamples } = args;
    let bootstrap = vge_lab::stats::Bootstrap { resamples, ..Default::default() };
    let pairs = (!pairs.is_empty()).then_some(pairs.as_slice());
    let written = vge_lab::compare::write(&groups, pairs, metric, &out, seed, &bootstrap)?;
    let md = out.join("compare.md");
    let text = vge_run::read_limits::read_to_string_bounded(&md, vge_run::read_limits::MAX_RECORD_FILE_LEN);
    print!("{}", text.unwrap_or_default());
    for f in &written.files {
        eprintln!("wrote {}", f.display());
    }
    Ok(())
}
