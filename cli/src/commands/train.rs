//! `vge train`: one run, new or resumed, with a progress bar on a terminal (a line per metrics
//! row and per success test elsewhere); Ctrl-C, SIGTERM or SIGHUP saves a checkpoint, stops it
//! and exits with 128 + the signal's number ([`crate::stop`]). Progress is a view: where
//! stdout or stderr is gone (`vge train ... | head`), the lines are dropped and the run goes
//! on to its end; its folder's files hold every row.

use std::path::PathBuf;

#[cfg(feature = "train")]
use anyhow::{Context, bail};
use clap::Args;

/// Train a policy with TD3 (or SAC: `algorithm = "sac"`) and the configured behaviour
/// policy (RL, RL+BC, FGE, VGE, VGE+BC) from a TOML config (see configs/).
///
/// Writes DIR/config.toml, DIR/metrics.csv (step, return, rotation, contacts, controller
/// share, losses), the same curves for TensorBoard in DIR/tensorboard (`tensorboard
/// --logdir DIR`), DIR/eval.csv (the periodic success tests), DIR/snapshots/ (the policy at
/// each test), checkpoints in DIR/checkpoint and, when done, the actor as DIR/policy.vgep
/// with DIR/final-eval.json, the snapshot picked on validation grasps as
/// DIR/policy-best.vgep with DIR/best-eval.json, and DIR/score.json (`vge score`).
///
/// Stopping: Ctrl-C (SIGINT), SIGTERM (kill, Slurm's scancel, preemption and time limit) or
/// SIGHUP finish the step in progress, save a checkpoint there (the envs' episodes in
/// progress included), print `stopped at step N: ...` with the command that continues, and
/// exit with status 130 (SIGINT), 143 (SIGTERM) or 129 (SIGHUP), never 0. `vge train
/// --resume DIR` then continues exactly as if the run had not stopped: the same policy and
/// metrics, bit for bit, on the same binary, `sac.threads` and CPU model. After a kill -9 or
/// a crash it continues from the last periodic checkpoint (`run.checkpoint_interval`), also
/// bit for bit. Exit status 0: the run finished (DIR/policy.vgep written); 1: an error.
///
/// Output: a closed stdout or stderr (`vge train ... | head -1`) never stops training; the
/// lines are dropped and the run goes on to its end (DIR/metrics.csv and DIR/eval.csv hold
/// every row the progress lines show).
///
/// Progress: a bar on a terminal; where stderr is a file or a pipe (nohup, a batch job),
/// one line per metrics row (`step 20000/1000000 (2%), 151 steps/s, 1h48m left, return
/// ...`) and one per periodic success test (`test at step 100000: success 0.45, drops
/// ...`), so that a log shows how a run of hours goes.
///
/// A run can start from another run's networks (actor, critics, observation
/// normaliser) with the config key `init_from = "DIR"` or `--set init_from=DIR`: a
/// second curriculum stage, e.g. configs/cube-fg-fge-robust-finetune.toml, which
/// fine-tunes a trained gait under sensor noise and pushes.
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Experiment config (TOML), e.g. configs/cube-fg-vge.toml. Not needed with --resume.
    #[arg(long, required_unless_present = "resume")]
    config: Option<PathBuf>,
    /// Output directory of the run.
    #[arg(long, required_unless_present = "resume")]
    out: Option<PathBuf>,
    /// Continue the run in this directory from its last checkpoint (its config.toml). The
    /// checkpoint's files are checked against its manifest first: a damaged, truncated or
    /// older vge's checkpoint is refused, naming the file.
    #[arg(long, conflicts_with_all = ["config", "out"])]
    resume: Option<PathBuf>,
    /// Override the config's seed (refused with --resume unless it is the run's own).
    #[arg(long)]
    seed: Option<u64>,
    /// Override the config's total env steps; with --resume, continue the run to this many.
    #[arg(long)]
    steps: Option<u64>,
    /// Override any config field, e.g. `--set sac.batch=128 --set vge.horizon=20`. With
    /// --resume only `sac.threads` may change (another thread count can round differently, so
    /// the run need not continue bit for bit); any other change is refused, naming the key.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
}

/// `vge train`.
pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    #[cfg(feature = "train")]
    {
        let TrainArgs { config, out, resume, seed, steps, overrides } = args;
        let stop = crate::stop::on_signal_stop()?;
        if train(config, out, resume, seed, steps, &overrides, stop)? {
            return Err(stopped_error());
        }
        Ok(())
    }
    #[cfg(not(feature = "train"))]
    {
        let _ = args;
        Err(super::without_training("vge train"))
    }
}

/// The run `vge train` works on: a new one (`--config`, `--out`, refused where a run already
/// is) or the one in `--resume DIR`, with the overrides applied.
#[cfg(feature = "train")]
fn train_target(
    resume: Option<PathBuf>,
    config: Option<PathBuf>,
    out: Option<PathBuf>,
    overrides: &[String],
) -> anyhow::Result<(vge_run::config::Config, PathBuf, bool)> {
    use vge_run::config as cfg;
    Ok(match (resume, config, out) {
        (Some(dir), _, _) => {
            let run = vge_run::run_dir::RunDir::new(&dir);
            let text = run
                .read_config_text()
                .with_context(|| format!("{} is not a vge run directory (no config.toml)", dir.display()))?;
            let (config, notes) = cfg::resume_config(&text, &run.config().display().to_string(), overrides)?;
            for note in notes {
                errln!("vge train: {note}");
            }
            (config, dir, true)
        }
        // A folder holding a run, or being written, is refused by `train` (naming what it found).
        (None, Some(path), Some(out)) => (cfg::load_config(&path, overrides)?, out, false),
        _ => bail!("give --config and --out, or --resume DIR"),
    })
}

#[cfg(feature = "train")]
fn progress_bar(total_steps: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(total_steps);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} steps ({eta} left) {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar
}

/// One line of progress where no bar is drawn: `step 20000/1000000 (2%), 151 steps/s, 1h48m
/// left, return 15.78, rotation 0.99 rad, controller 31%, 96 episodes`.
#[cfg(feature = "train")]
fn progress_line(p: &vge_trainer::train::Progress<'_>) -> String {
    let left_s =
        if p.steps_per_s > 0.0 { p.total_steps.saturating_sub(p.step) as f64 / p.steps_per_s } else { 0.0 };
    format!(
        "step {}/{} ({:.0}%), {:.0} steps/s, {} left, return {:.2}, rotation {:.2} rad, controller {:.0}%, {} episodes",
        p.step,
        p.total_steps,
        100.0 * p.step as f64 / p.total_steps.max(1) as f64,
        p.steps_per_s,
        duration_text(left_s),
        p.mean_return,
        p.mean_rotation_rad,
        100.0 * p.controller_share,
        p.episodes
    )
}

/// `1h48m`, `4m05s`, `12s`.
#[cfg(feature = "train")]
fn duration_text(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    match (s / 3600, s % 3600 / 60, s % 60) {
        (0, 0, s) => format!("{s}s"),
        (0, m, s) => format!("{m}m{s:02}s"),
        (h, m, _) => format!("{h}h{m:02}m"),
    }
}

/// The periodic success test's result, as `eval.csv` records it: `test at step 100000:
/// success 0.00, drops 1.00, return 15.78, rotation 0.99 rad (20 episodes)`, and for a run on
/// several objects its worst object.
#[cfg(feature = "train")]
fn evaluation_line(step: u64, report: &vge_run::eval::ObjectsReport) -> String {
    let r = &report.overall;
    let mut line = format!(
        "test at step {step}: success {:.2}, drops {:.2}, return {:.2}, rotation {:.2} rad ({} episodes)",
        r.success_rate, r.drop_rate, r.mean_return, r.mean_rotation_rad, r.episodes
    );
    if report.per_object.len() > 1
        && let Some((object, success)) = report.worst_object()
    {
        line.push_str(&format!("; worst object: {object} {success:.2}"));
    }
    line
}

#[cfg(feature = "train")]
pub(crate) fn train(
    config: Option<PathBuf>,
    out: Option<PathBuf>,
    resume: Option<PathBuf>,
    seed: Option<u64>,
    steps: Option<u64>,
    overrides: &[String],
    stop: &std::sync::atomic::AtomicBool,
) -> anyhow::Result<bool> {
    use std::io::IsTerminal;
    use vge_trainer::train as tr;
    let mut overrides = overrides.to_vec();
    if let Some(seed) = seed {
        overrides.push(format!("seed={seed}"));
    }
    if let Some(steps) = steps {
        overrides.push(format!("total_steps={steps}"));
    }
    let (config, out_dir, resuming) = train_target(resume, config, out, &overrides)?;
    warn_if_threads_exceed_idle_cores(config.sac.threads);
    let bar = progress_bar(config.total_steps);
    let resumed_from = if resuming { vge_lab::sweep::checkpoint_step(&out_dir) } else { None };
    // The controller only where the method queries it (rl runs ignore `controller`).
    let controller = config.controller.filter(|_| config.method.queries_controller());
    errln!(
        "training {} ({}{}, {}, seed {}){} into {}{}",
        config.name,
        config.method.name(),
        controller.map_or(String::new(), |c| format!(" + {}", c.name())),
        config.algorithm.name(),
        config.seed,
        config.init_from_dir().map_or(String::new(), |d| format!(" from the networks of {}", d.display())),
        out_dir.display(),
        match (resuming, resumed_from) {
            (true, Some(step)) => format!(", resuming from step {step}"),
            (true, None) => ", resuming".to_owned(),
            _ => String::new(),
        }
    );
    // On a terminal a bar; elsewhere (a log file, a batch job) a line per metrics row, since
    // a bar is not drawn there and a run of hours would otherwise print nothing.
    let terminal = std::io::stderr().is_terminal();
    let summary = tr::train(&config, &out_dir, resuming, stop, &mut |p: &tr::Progress<'_>| {
        if let Some(report) = p.evaluation {
            let line = evaluation_line(p.step, report);
            if terminal { bar.println(line) } else { errln!("{line}") }
        }
        if terminal {
            bar.set_position(p.step);
            bar.set_message(format!(
                "{:.0} steps/s, return {:.2}, rotation {:.2} rad, controller {:.0}%, {} episodes",
                p.steps_per_s,
                p.mean_return,
                p.mean_rotation_rad,
                100.0 * p.controller_share,
                p.episodes
            ));
        } else if p.logged {
            errln!("{}", progress_line(p));
        }
    })?;
    bar.finish();
    outln!("time this session: {}", summary.times);
    if summary.stopped {
        // One line that a log keeps and a scheduler's script can parse: the step, the
        // signal, and how to go on.
        let by = crate::stop::received().map_or_else(String::new, |s| format!(" ({s})"));
        errln!(
            "stopped at step {}: checkpoint saved{by}; continue with `vge train --resume {}`",
            summary.steps,
            out_dir.display()
        );
    } else if let Some(policy) = summary.policy {
        outln!(
            "done: {} steps, {} updates; policy written to {}",
            summary.steps,
            summary.updates,
            policy.display()
        );
    }
    Ok(summary.stopped)
}

/// Says so when other processes leave fewer idle cores than the run has libtorch threads:
/// its parallel regions then wait for descheduled workers and training stalls
/// (docs/libtorch.md). Only a warning: the thread count is the config's.
#[cfg(feature = "train")]
fn warn_if_threads_exceed_idle_cores(config_threads: i32) {
    let threads = match usize::try_from(config_threads) {
        Ok(0) | Err(_) => std::thread::available_parallelism().map_or(1, |n| n.get()),
        Ok(n) => n,
    };
    if threads < 2 {
        return;
    }
    match vge_run::cpu_use::measure(std::time::Duration::from_millis(250)) {
        Ok(used) if threads > used.threads_that_fit() => errln!(
            "vge train: other processes keep {:.1} of the {} cores this run may use busy, leaving \
             {:.1} idle for sac.threads = {threads}; libtorch's workers wait for each other, so \
             training can run several times slower than at one thread. Beside other work, train \
             with --set sac.threads=1 (or OMP_WAIT_POLICY=passive); see docs/libtorch.md",
            used.busy_cores,
            used.cores,
            used.idle_cores()
        ),
        Ok(_) => {}
        // No /proc/stat (not Linux): nothing measured, nothing to advise.
        Err(vge_run::cpu_use::CpuUseError::Unsupported) => {}
        Err(e) => errln!("vge train: could not measure how busy the cores are ({e}); training goes on"),
    }
}

/// The error a command returns after a signal stopped its training: `main` exits with
/// 128 + the signal's number ([`crate::stop`]).
#[cfg(feature = "train")]
pub(crate) fn stopped_error() -> anyhow::Error {
    // The flag is only raised by the handler, which records the signal first.
    anyhow::Error::new(crate::stop::received().unwrap_or(crate::stop::Stopped { signal: libc::SIGTERM }))
}
