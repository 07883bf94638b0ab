//! `vge queue`: a queue file of runs trained one after another by fixed binaries.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use vge_lab::queue::{self, Checkout, lane};

/// Train a queue of runs, one after another, each by the vge of a named commit
///
/// A queue file holds one run a line (blank lines and lines starting with # are skipped):
///
///   REL COMMIT CONFIG SEED [--set KEY=VALUE ...] [--score-with COMMIT2]
///
/// The run trains into runs/REL (its output appended to runs/REL.log) with
/// runs/bin/vge-COMMIT, built once by `vge queue build` from a git worktree of COMMIT at
/// runs/src/COMMIT, where CONFIG is read from: a queue keeps training the same program on the
/// same config whatever the checkout has become since. --score-with scores the finished run
/// again with runs/bin/vge-COMMIT2 (vge score --force), for scores the training binary
/// lacks; runs/REL.scored-with-COMMIT2 marks that done. Every path is relative to the
/// repository's root: run vge queue there.
///
/// `run` checks every line first, then takes the queue's first line neither done
/// (docs/results/REL/score.json or runs/REL/score.json), nor held by another process (its
/// vge.lock), nor tried already; the file is read again before each run, so a queue file
/// replaced while a run trains (write a new file, rename it over the old one) decides the
/// next run. A run with a checkpoint resumes (vge train --resume); a run folder without one
/// is moved aside to runs/REL.abandoned-TIME and the run starts again; a run trained
/// without its score is scored. Each run gets --threads rayon threads (its config's
/// sac.threads sets libtorch's). runs/lanes/NAME.log records each start, end and skip. Run
/// again, the same command continues the queue. SIGTERM, SIGINT or `vge queue stop` ends
/// the lane: the running vge checkpoints, and no further run starts. With less than
/// --min-free-gib free under runs/ before a run, the lane ends with an error and starts none.
///
/// Examples:
///   vge queue build scripts/queues/lane-a.txt
///   nohup vge queue run scripts/queues/lane-a.txt >runs/lanes/a.out 2>&1 &
///   vge queue status scripts/queues/lane-a.txt
///   vge queue collect allegro/rl/seed-0
#[derive(Debug, Args)]
#[command(verbatim_doc_comment)]
pub struct QueueArgs {
    #[command(subcommand)]
    command: QueueCommand,
}

#[derive(Debug, Subcommand)]
enum QueueCommand {
    /// Train the queue's runs, one after another (log: runs/lanes/NAME.log).
    Run {
        queue: PathBuf,
        /// Rayon threads of each run and of its scoring.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        threads: u32,
        /// Free space (GiB) the file system holding runs/ must have before each run starts,
        /// or the lane ends with an error instead (a run's checkpoint is written beside the
        /// last one, so it needs about twice its replay buffer: 1.4 GiB for the Allegro's 1M
        /// transitions).
        #[arg(long, default_value_t = 4.0, value_parser = non_negative_gib)]
        min_free_gib: f64,
    },
    /// Check every line: its form, its commit, its config at that commit, no run twice, the
    /// binaries of the runs still to do built (`run` does this first).
    Check { queue: PathBuf },
    /// Build runs/bin/vge-COMMIT for every commit the queue's runs still to do name (minutes
    /// each; once; a finished run's commit is not built).
    Build { queue: PathBuf },
    /// Each run's state, latest step and training time left, and the queue's env steps and
    /// hours to go.
    Status { queue: PathBuf },
    /// End the lane running the queue: its running vge checkpoints; `run` resumes it.
    Stop { queue: PathBuf },
    /// Copy finished runs from runs/REL to docs/results/REL (config, metrics, tests, scores,
    /// plots, final and selected policies, training log; no checkpoints) and print their facts.
    Collect {
        #[arg(required = true)]
        rels: Vec<String>,
    },
}

/// `vge queue`.
pub fn run(args: QueueArgs) -> anyhow::Result<()> {
    let root = std::env::current_dir().context("the current folder")?;
    let checkout = Checkout::open(&root)?;
    match args.command {
        QueueCommand::Run { queue, threads, min_free_gib } => {
            run_lane(&checkout, &queue, threads, min_free_gib)
        }
        QueueCommand::Check { queue } => {
            let lines = queue::check(&checkout, &queue, true)?;
            println!("{}: every line checks ({} runs)", queue.display(), lines.len());
            Ok(())
        }
        QueueCommand::Build { queue } => {
            let lines = queue::check(&checkout, &queue, false)?;
            for commit in queue::commits_to_do(&checkout, &lines) {
                let bin = queue::build::build(&checkout, &commit, &mut |s| errln!("vge queue: {s}"))?;
                println!("{}", bin.display());
            }
            Ok(())
        }
        QueueCommand::Status { queue } => {
            let status = queue::status::status(&checkout, &queue)?;
            for (rel, state) in &status.runs {
                println!("{rel:<50} {state}");
            }
            println!("{}", status.summary());
            Ok(())
        }
        QueueCommand::Stop { queue } => stop_lane(&checkout, &queue),
        QueueCommand::Collect { rels } => {
            for rel in rels {
                let (out, copied) = queue::collect::collect(&checkout, &rel)?;
                println!("collected {}: {}", out.display(), copied.join(" "));
                print!("{}", vge_lab::run_facts::facts(&out, &checkout.lanes_dir())?);
            }
            Ok(())
        }
    }
}

fn non_negative_gib(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(gib) if gib.is_finite() && gib >= 0.0 => Ok(gib),
        _ => Err(format!("expected a number of GiB, 0 or more, got {text:?}")),
    }
}

fn run_lane(
    checkout: &Checkout,
    queue: &std::path::Path,
    threads: u32,
    min_free_gib: f64,
) -> anyhow::Result<()> {
    let stop = stop_flag()?;
    println!("vge queue: {}, log {}", queue.display(), checkout.lane_log(queue).display());
    // f64 to u64 saturates: a huge request asks for more than any disk has.
    let min_free_bytes = (min_free_gib * f64::from(1u32 << 30)) as u64;
    let end = lane::run(checkout, queue, threads, min_free_bytes, stop, &mut |line| println!("{line}"))?;
    if let lane::LaneEnd::NoRoom { free_bytes } = end {
        bail!(
            "{:.1} GiB free under runs/, less than --min-free-gib {min_free_gib}: the lane ended before its next run",
            free_bytes as f64 / f64::from(1u32 << 30)
        );
    }
    if end == lane::LaneEnd::Stopped {
        #[cfg(feature = "train")]
        if let Some(stopped) = crate::stop::received() {
            return Err(stopped.into());
        }
    }
    Ok(())
}

/// Raised by SIGINT, SIGTERM and SIGHUP.
#[cfg(feature = "train")]
fn stop_flag() -> anyhow::Result<&'static AtomicBool> {
    crate::stop::on_signal_stop()
}

/// Never raised: without the handler a signal ends vge queue at once, and its running vge,
/// in the same process group when the signal came from the terminal, checkpoints on its own.
#[cfg(not(feature = "train"))]
fn stop_flag() -> anyhow::Result<&'static AtomicBool> {
    static NEVER: AtomicBool = AtomicBool::new(false);
    Ok(&NEVER)
}

/// SIGTERM to the `vge queue run` holding the queue's lane lock; returns once it has ended.
fn stop_lane(checkout: &Checkout, queue: &std::path::Path) -> anyhow::Result<()> {
    let Some(pid) = lane::running_lane(checkout, queue) else {
        bail!("no vge queue run is running {}", queue.display());
    };
    // SAFETY: kill(2) with a pid read from the lane's lock and a valid signal number.
    #[allow(unsafe_code)]
    let sent = unsafe { libc::kill(pid, libc::SIGTERM) };
    if sent != 0 {
        bail!("signalling pid {pid}: {}", std::io::Error::last_os_error());
    }
    while lane::running_lane(checkout, queue).is_some() {
        std::thread::sleep(std::time::Duration::from_millis(500));
    }
    println!("vge queue: stopped {} (pid {pid}); `vge queue run` resumes it", queue.display());
    Ok(())
}
