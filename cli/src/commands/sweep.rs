//! `vge sweep`: one config for several seeds, in this process, as parallel processes or as a
//! Slurm array job.

use std::path::PathBuf;

#[cfg(feature = "train")]
use anyhow::{Context, bail};
use clap::Args;

#[cfg(feature = "train")]
use super::train::{stopped_error, train};

/// Train one config for several seeds, one run directory each (DIR/seed-N)
///
/// A finished seed (DIR/seed-N/policy.vgep) is skipped and an interrupted one resumed, so the same
/// command again continues a sweep.
///
/// Three ways to run the seeds: one after the other in this process (the default);
/// `--jobs N` side by side as N `vge train` processes, each logging to
/// DIR/seed-N/train.log, with a progress line per seed every 30 s and a summary; or
/// `--slurm`, a Slurm array job with one task per seed (docs/cluster.md).
///
/// Ctrl-C, SIGTERM or SIGHUP makes every running seed write a checkpoint and exit, and the
/// sweep exits with 130, 143 or 129 (128 + the signal's number). Exit status 0 means every
/// seed finished; 1 that a seed failed (its log is named); a seed stopped on its own (a
/// signal sent to its process alone) also makes the sweep exit with that seed's status. A
/// closed stdout or stderr never stops the seeds: the lines are dropped.
///
/// Examples:
///   vge sweep --config configs/cube-fg-vge.toml --seeds 0..4 --out runs/fg --jobs 2
///   vge sweep --config configs/cube-fg-vge.toml --seeds 0..10 --out runs/fg --slurm
///       --partition cpu --time 24:00:00 --cpus-per-task 4
///   vge plot runs/fg/seed-* --out fg.png
#[derive(Debug, Args)]
#[command(verbatim_doc_comment)]
pub struct SweepArgs {
    /// Experiment config (TOML), e.g. configs/cube-fg-vge.toml.
    #[arg(long)]
    config: PathBuf,
    /// Seeds as a range `A..B` (B excluded), e.g. `0..10`.
    #[arg(long, value_parser = parse_seed_range)]
    seeds: std::ops::Range<u64>,
    /// Folder of the sweep: one run directory per seed, DIR/seed-N.
    #[arg(long)]
    out: PathBuf,
    /// Override the config's total env steps (every seed).
    #[arg(long)]
    steps: Option<u64>,
    /// Override any config field for every seed, e.g. `--set sac.batch=128`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Train N seeds at once, each as its own `vge train` process (stdout and stderr in
    /// DIR/seed-N/train.log). Without it the seeds run one after the other in this process.
    /// Give each job its own cores: N x --threads-per-job should not exceed them.
    #[arg(long, value_name = "N", conflicts_with = "slurm", value_parser = clap::value_parser!(u32).range(1..))]
    jobs: Option<u32>,
    /// libtorch threads (sac.threads, unless --set gives it) and env-stepping threads of
    /// each --jobs process.
    #[arg(long, value_name = "K", default_value_t = 1, requires = "jobs", value_parser = clap::value_parser!(u32).range(1..))]
    threads_per_job: u32,
    /// Seconds between progress lines (one per running seed) with --jobs (1 to 86400).
    #[arg(long, value_name = "S", default_value_t = 30, requires = "jobs", value_parser = clap::value_parser!(u64).range(1..=86_400))]
    report_every_s: u64,
    /// Write DIR/sweep.sbatch, a Slurm array job with one task per unfinished seed (task id
    /// = seed), and submit it with sbatch. Each task resumes its seed when its folder holds a
    /// checkpoint, and checkpoints and exits on SIGTERM (scancel, preemption, and 120 s
    /// before --time runs out), so submitting again continues where the tasks stopped.
    /// See docs/cluster.md.
    #[arg(long)]
    slurm: bool,
    /// Slurm partition of the tasks (default: the cluster's default partition).
    #[arg(long, requires = "slurm")]
    partition: Option<String>,
    /// Wall-clock limit per task, e.g. 12:00:00 or 2-00:00:00 (default: the partition's).
    #[arg(long, value_name = "HH:MM:SS", requires = "slurm")]
    time: Option<String>,
    /// CPUs per task; also its libtorch threads (sac.threads, unless --set gives it).
    #[arg(long, value_name = "N", default_value_t = 1, requires = "slurm", value_parser = clap::value_parser!(u32).range(1..))]
    cpus_per_task: u32,
    /// Only write DIR/sweep.sbatch; do not submit it.
    #[arg(long, requires = "slurm")]
    dry_run: bool,
}

fn parse_seed_range(s: &str) -> Result<std::ops::Range<u64>, String> {
    let (a, b) = s.split_once("..").ok_or_else(|| format!("`{s}` is not a range like 0..10"))?;
    let a: u64 = a.trim().parse().map_err(|_| format!("`{a}` is not a seed"))?;
    let b: u64 = b.trim().parse().map_err(|_| format!("`{b}` is not a seed"))?;
    if a >= b {
        return Err(format!("empty seed range {s}"));
    }
    Ok(a..b)
}

/// `vge sweep`.
pub fn run(args: SweepArgs) -> anyhow::Result<()> {
    #[cfg(feature = "train")]
    {
        sweep(args)
    }
    #[cfg(not(feature = "train"))]
    {
        let _ = args;
        Err(super::without_training("vge sweep"))
    }
}

#[cfg(feature = "train")]
fn sweep(args: SweepArgs) -> anyhow::Result<()> {
    let sweep = vge_lab::sweep::Sweep {
        config: args.config.clone(),
        seeds: args.seeds.clone(),
        out: args.out.clone(),
        steps: args.steps,
        overrides: args.overrides.clone(),
    };
    if args.slurm {
        return sweep_slurm(&args, &sweep);
    }
    match args.jobs {
        Some(jobs) => sweep_parallel(&args, &sweep, jobs),
        None => sweep_in_process(&sweep),
    }
}

/// The seeds one after the other in this process.
#[cfg(feature = "train")]
fn sweep_in_process(sweep: &vge_lab::sweep::Sweep) -> anyhow::Result<()> {
    use vge_lab::sweep::{SeedState, seed_state};
    let stop = crate::stop::on_signal_stop()?;
    for seed in sweep.seeds.clone() {
        if stop.load(std::sync::atomic::Ordering::SeqCst) {
            // Between two seeds: the next one is not started (its folder stays as it is).
            errln!("sweep stopped before seed {seed}: the same `vge sweep` again trains it");
            return Err(stopped_error());
        }
        let dir = sweep.seed_dir(seed);
        let (steps, overrides) = (sweep.steps, &sweep.overrides);
        let stopped = match seed_state(&dir) {
            SeedState::Done => {
                errln!("seed {seed}: done already ({})", dir.display());
                continue;
            }
            SeedState::Interrupted => train(None, None, Some(dir), Some(seed), steps, overrides, stop)?,
            SeedState::New => {
                train(Some(sweep.config.clone()), Some(dir), None, Some(seed), steps, overrides, stop)?
            }
        };
        if stopped {
            errln!(
                "sweep stopped at seed {seed} of {}..{}: the same `vge sweep` again resumes it and \
                 trains the seeds after it",
                sweep.seeds.start,
                sweep.seeds.end
            );
            return Err(stopped_error());
        }
    }
    Ok(())
}

/// The seeds as child processes, `jobs` at a time.
#[cfg(feature = "train")]
fn sweep_parallel(args: &SweepArgs, sweep: &vge_lab::sweep::Sweep, jobs: u32) -> anyhow::Result<()> {
    use vge_lab::sweep::{Outcome, Parallel, run_parallel, summary_line};
    let exe = std::env::current_exe().context("finding the vge binary to start the jobs")?;
    // Checked here so that a typo fails once, not once per seed in each log.
    vge_run::config::load_config(&sweep.config, &sweep.overrides)?;
    let opts = Parallel {
        jobs: jobs as usize,
        threads_per_job: args.threads_per_job as usize,
        report_every: std::time::Duration::from_secs(args.report_every_s),
    };
    let stop = crate::stop::on_signal_stop()?;
    errln!(
        "sweep: seeds {}..{}, {jobs} at a time, logs in {}/seed-N/train.log",
        sweep.seeds.start,
        sweep.seeds.end,
        sweep.out.display()
    );
    let outcomes = run_parallel(&exe, sweep, &opts, stop, &mut |line| errln!("{line}"));
    for (seed, outcome) in &outcomes {
        outln!("{}", summary_line(sweep, *seed, outcome));
    }
    let failed: Vec<String> = outcomes
        .iter()
        .filter_map(|(seed, o)| match o {
            Outcome::Failed { log, .. } => Some(format!("seed {seed} (log {})", log.display())),
            _ => None,
        })
        .collect();
    if !failed.is_empty() {
        bail!("{} of {} seeds failed: {}", failed.len(), outcomes.len(), failed.join(", "));
    }
    if crate::stop::received().is_some() {
        return Err(stopped_error());
    }
    // A seed stopped by a signal to its own process: unfinished, so the sweep is too.
    let stopped = outcomes.iter().find_map(|(_, o)| match o {
        Outcome::Stopped { code, .. } => vge_lab::sweep::stopped_by(*code),
        _ => None,
    });
    if let Some(signal) = stopped {
        return Err(anyhow::Error::new(crate::stop::Stopped { signal }));
    }
    Ok(())
}

/// Writes DIR/sweep.sbatch and, unless --dry-run, submits it.
#[cfg(feature = "train")]
fn sweep_slurm(args: &SweepArgs, sweep: &vge_lab::sweep::Sweep) -> anyhow::Result<()> {
    use vge_lab::sweep::{Slurm, array_spec, on_path, submit, write_sbatch};
    // Before any file is written: a login node without Slurm is the likely mistake.
    if !args.dry_run && !on_path("sbatch") {
        bail!(vge_lab::sweep::SweepError::NoSbatch);
    }
    vge_run::config::load_config(&sweep.config, &sweep.overrides)?;
    let slurm = Slurm {
        partition: args.partition.clone(),
        time: args.time.clone(),
        cpus_per_task: args.cpus_per_task as usize,
    };
    let exe = std::env::current_exe()
        .and_then(|p| p.canonicalize())
        .context("finding the vge binary the tasks run")?;
    let (script, seeds) = write_sbatch(&exe, sweep, &slurm)?;
    if seeds.is_empty() {
        outln!("every seed is done already (DIR/seed-N/policy.vgep): nothing to submit");
        return Ok(());
    }
    let dir = script.parent().unwrap_or(&sweep.out).display().to_string();
    if args.dry_run {
        outln!("wrote {} (seeds {}); submit it with: sbatch {0}", script.display(), array_spec(&seeds));
        return Ok(());
    }
    let job = submit(&script)?;
    outln!("submitted array job {job}: seeds {} from {}", array_spec(&seeds), script.display());
    outln!("follow it:    squeue -j {job}    (task id = seed)");
    outln!("logs:         {dir}/seed-N/train.log");
    outln!("curves:       vge plot {dir}/seed-* --out {dir}/curves.png");
    outln!("interrupted?  the same `vge sweep --slurm` again resumes unfinished seeds");
    Ok(())
}
