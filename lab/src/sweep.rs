//! `vge sweep`: one config trained for several seeds, one run directory each (`DIR/seed-N`).
//!
//! The seeds run in one of three ways: in the calling process one after the other (the
//! `vge` binary does that itself), as child processes of the `vge` binary side by side
//! ([`run_parallel`]), or as a Slurm array job with one task per seed ([`write_sbatch`],
//! [`submit`]). All three skip a seed whose run finished ([`check_finished`]: its
//! `policy.vgep` and `final-eval.json` read back whole) and resume one whose folder holds a
//! checkpoint, so running the same sweep again continues it. A folder with signs of a run
//! but neither is left alone: `vge train` refuses it with what it found.

use std::collections::VecDeque;
use std::ffi::OsString;
use std::fs::File;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use thiserror::Error;

#[derive(Debug, Error)]
pub enum SweepError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error(
        "`sbatch` is not on PATH: submit from a machine with Slurm's client commands, or pass \
         --dry-run to only write the job script"
    )]
    NoSbatch,
    #[error("sbatch failed ({status}): {stderr}")]
    Sbatch { status: String, stderr: String },
    #[error(
        "{0} holds a sweep of another config: choose another --out, or remove that file to \
         let new seeds use the new config"
    )]
    OtherConfig(String),
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Config(#[from] vge_run::config::ConfigError),
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> SweepError + '_ {
    move |source| SweepError::Io { path: path.display().to_string(), source }
}

/// What every way of running a sweep shares: the config, the seeds, the output directory
/// and the overrides given to each seed's `vge train`.
#[derive(Debug, Clone)]
pub struct Sweep {
    pub config: PathBuf,
    pub seeds: Range<u64>,
    pub out: PathBuf,
    pub steps: Option<u64>,
    pub overrides: Vec<String>,
}

/// Where a seed's run directory stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeedState {
    /// The run finished ([`check_finished`]): nothing to do.
    Done,
    /// A checkpoint and no finished run: continue with `--resume` (which, from the final
    /// checkpoint, writes the final files again).
    Interrupted,
    /// No checkpoint: start from the config (refused by `vge train`, naming what it found,
    /// where the folder holds signs of a run).
    New,
}

pub fn seed_state(dir: &Path) -> SeedState {
    if check_finished(dir).is_ok() {
        SeedState::Done
    } else if vge_run::run_dir::RunDir::new(dir).resume_checkpoint().is_some() {
        // checkpoint.old alone: killed between the two renames of a checkpoint save.
        SeedState::Interrupted
    } else {
        SeedState::New
    }
}

/// Whether a run finished and the step of its last checkpoint: the run folder's readers,
/// here under the names sweeps and queues know them by.
pub use vge_run::run_dir::{check_finished, checkpoint_step};

/// The exit status of a `vge train` or `vge sweep` that a signal stopped (its checkpoint
/// saved): 128 + the signal's number, as a shell reports a process that the signal ended
/// (SIGINT 130, SIGTERM 143, SIGHUP 129). Never 0: a stopped run is not a finished one.
pub fn stopped_exit_code(signal: i32) -> u8 {
    u8::try_from(128 + signal.clamp(1, 127)).unwrap_or(u8::MAX)
}

/// The signal whose stop `code` reports ([`stopped_exit_code`]) for the signals `vge train`
/// stops on: SIGHUP, SIGINT, SIGTERM.
pub fn stopped_by(code: i32) -> Option<i32> {
    [nix::libc::SIGHUP, nix::libc::SIGINT, nix::libc::SIGTERM]
        .into_iter()
        .find(|&signal| i32::from(stopped_exit_code(signal)) == code)
}

/// True when the overrides set `sac.threads` (the sweep then leaves the thread count alone).
pub fn sets_threads(overrides: &[String]) -> bool {
    overrides.iter().any(|o| o.split_once('=').is_some_and(|(k, _)| k.trim() == "sac.threads"))
}

impl Sweep {
    pub fn seed_dir(&self, seed: u64) -> PathBuf {
        self.out.join(format!("seed-{seed}"))
    }

    /// `--steps`, the `--set`s and, unless the user set it, `--set sac.threads=THREADS`.
    fn shared_args(&self, threads: usize) -> Vec<String> {
        let mut args = Vec::new();
        if let Some(steps) = self.steps {
            args.extend(["--steps".to_owned(), steps.to_string()]);
        }
        for o in &self.overrides {
            args.extend(["--set".to_owned(), o.clone()]);
        }
        if !sets_threads(&self.overrides) {
            args.extend(["--set".to_owned(), format!("sac.threads={threads}")]);
        }
        args
    }

    /// The `vge` arguments that train `seed` in its own process: `train --resume` when its
    /// folder holds a checkpoint, else `train --config`.
    pub fn train_args(&self, seed: u64, threads: usize) -> Vec<OsString> {
        let dir = self.seed_dir(seed);
        let mut args: Vec<OsString> = vec!["train".into()];
        if seed_state(&dir) == SeedState::Interrupted {
            args.extend(["--resume".into(), dir.into_os_string()]);
        } else {
            args.extend(["--config".into(), self.config.clone().into(), "--out".into(), dir.into()]);
        }
        args.extend(["--seed".into(), seed.to_string().into()]);
        args.extend(self.shared_args(threads).into_iter().map(OsString::from));
        args
    }
}

// ------------------------------------------------------------------ child processes

/// How [`run_parallel`] runs the seeds.
#[derive(Debug, Clone)]
pub struct Parallel {
    /// Seeds trained at once.
    pub jobs: usize,
    /// libtorch threads (`sac.threads`) and rayon threads of each job.
    pub threads_per_job: usize,
    /// How often a progress line per running seed is printed.
    pub report_every: Duration,
}

/// How one seed of a sweep ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// Its folder held `policy.vgep` before the sweep started.
    Skipped,
    /// Trained to the end: `policy.vgep` written.
    Done,
    /// Stopped by a signal at this step with a checkpoint, exiting with this status
    /// ([`stopped_exit_code`]); the next sweep resumes it.
    Stopped { step: Option<u64>, code: i32 },
    /// The child failed (or could not start): why, and its log.
    Failed { why: String, log: PathBuf },
    /// The sweep was stopped before this seed's turn.
    NotStarted,
}

#[derive(Debug)]
struct Job {
    seed: u64,
    child: Child,
}

/// Trains the sweep's seeds as child processes of `exe` (the `vge` binary), `jobs` at a time,
/// each writing stdout and stderr to `DIR/seed-N/train.log`. Every `report_every` it passes
/// one progress line per running seed to `say`. When `stop` is raised it sends SIGTERM to the
/// children (which checkpoint and exit), starts no more and waits for them. Returns one
/// outcome per seed, in seed order.
pub fn run_parallel(
    exe: &Path,
    sweep: &Sweep,
    opts: &Parallel,
    stop: &AtomicBool,
    say: &mut dyn FnMut(String),
) -> Vec<(u64, Outcome)> {
    let mut outcomes = Vec::new();
    let mut queue = VecDeque::new();
    for seed in sweep.seeds.clone() {
        match seed_state(&sweep.seed_dir(seed)) {
            SeedState::Done => outcomes.push((seed, Outcome::Skipped)),
            _ => queue.push_back(seed),
        }
    }
    let mut running: Vec<Job> = Vec::new();
    let mut forwarded = false;
    let mut next_report = Instant::now() + opts.report_every;
    // The last line printed per seed: a seed whose metrics did not move is not repeated.
    let mut last_said: std::collections::HashMap<u64, String> = std::collections::HashMap::new();
    loop {
        if stop.load(Ordering::Relaxed) {
            if !forwarded {
                running.iter().for_each(terminate);
                forwarded = true;
            }
            outcomes.extend(queue.drain(..).map(|seed| (seed, Outcome::NotStarted)));
        }
        while running.len() < opts.jobs
            && let Some(seed) = queue.pop_front()
        {
            match spawn(exe, sweep, seed, opts) {
                Ok(job) => running.push(job),
                Err(e) => {
                    outcomes.push((seed, Outcome::Failed { why: e.to_string(), log: log_path(sweep, seed) }))
                }
            }
        }
        if running.is_empty() {
            break;
        }
        outcomes.extend(reap(&mut running, sweep));
        if Instant::now() >= next_report {
            for j in &running {
                let line = progress_line(&sweep.seed_dir(j.seed), j.seed, sweep.steps);
                if last_said.get(&j.seed) != Some(&line) {
                    say(line.clone());
                    last_said.insert(j.seed, line);
                }
            }
            next_report = Instant::now() + opts.report_every;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    outcomes.sort_by_key(|(seed, _)| *seed);
    outcomes
}

fn log_path(sweep: &Sweep, seed: u64) -> PathBuf {
    sweep.seed_dir(seed).join("train.log")
}

fn spawn(exe: &Path, sweep: &Sweep, seed: u64, opts: &Parallel) -> Result<Job, SweepError> {
    let dir = sweep.seed_dir(seed);
    std::fs::create_dir_all(&dir).map_err(io_err(&dir))?;
    let log_path = log_path(sweep, seed);
    // Appended: a resumed seed's log keeps its earlier sessions.
    let log = File::options().create(true).append(true).open(&log_path).map_err(io_err(&log_path))?;
    let log2 = log.try_clone().map_err(io_err(&log_path))?;
    let mut cmd = Command::new(exe);
    cmd.args(sweep.train_args(seed, opts.threads_per_job)).stdin(Stdio::null()).stdout(log).stderr(log2);
    // rayon steps the envs on all cores by default: N jobs would each take them all.
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        cmd.env("RAYON_NUM_THREADS", opts.threads_per_job.to_string());
    }
    let child = cmd.spawn().map_err(io_err(exe))?;
    Ok(Job { seed, child })
}

/// SIGTERM: what `vge train` takes as "checkpoint and exit", like Ctrl-C (it then exits
/// with [`stopped_exit_code`]).
fn terminate(job: &Job) {
    use nix::sys::signal::{Signal, kill};
    use nix::unistd::Pid;
    if let Ok(pid) = i32::try_from(job.child.id()) {
        // An error means the child exited already: nothing to tell it.
        let _ = kill(Pid::from_raw(pid), Signal::SIGTERM);
    }
}

/// Removes the finished jobs from `running` and says how each ended.
fn reap(running: &mut Vec<Job>, sweep: &Sweep) -> Vec<(u64, Outcome)> {
    let mut ended = Vec::new();
    running.retain_mut(|job| {
        let outcome = match job.child.try_wait() {
            Ok(None) => return true,
            Ok(Some(status)) => how_it_ended(&sweep.seed_dir(job.seed), status, &log_path(sweep, job.seed)),
            Err(e) => Outcome::Failed { why: format!("waiting for it: {e}"), log: log_path(sweep, job.seed) },
        };
        ended.push((job.seed, outcome));
        false
    });
    ended
}

/// How a child that exited with `status` ended: finished (0, and its run reads back whole),
/// stopped by a signal with its checkpoint ([`stopped_exit_code`]), or failed.
fn how_it_ended(dir: &Path, status: std::process::ExitStatus, log: &Path) -> Outcome {
    let failed = |why: String| Outcome::Failed { why, log: log.to_owned() };
    match status.code() {
        Some(0) => match check_finished(dir) {
            Ok(()) => Outcome::Done,
            Err(e) => failed(format!("it exited 0 but its run is not finished: {e}")),
        },
        Some(code) if stopped_by(code).is_some() && checkpoint_step(dir).is_some() => {
            Outcome::Stopped { step: checkpoint_step(dir), code }
        }
        _ => failed(status.to_string()),
    }
}

/// `seed 3: 120000/1000000 steps, 85 steps/s, return 12.3, success 30% at 100000`, from the
/// run's metrics.csv and eval.csv (their last complete rows) and `steps` or else
/// config.toml (a resumed run's config.toml keeps its first session's total); the child's
/// stderr holds a progress bar only on a terminal, so the files are what every run has.
pub fn progress_line(dir: &Path, seed: u64, steps: Option<u64>) -> String {
    let from_config = || {
        let text = vge_run::run_dir::RunDir::new(dir).read_config_text().ok()?;
        u64::try_from(text.parse::<toml::Table>().ok()?.get("total_steps")?.as_integer()?).ok()
    };
    let total_steps = steps.or_else(from_config);
    let total = total_steps.map_or_else(|| "?".to_owned(), |t| t.to_string());
    let success = last_success(dir)
        .map_or_else(String::new, |(step, rate)| format!(", success {:.0}% at {step}", 100.0 * rate));
    match last_metrics(dir) {
        Some(m) => {
            let left =
                total_steps.filter(|t| *t > m.step && m.steps_per_s > 0.0).map_or_else(String::new, |t| {
                    format!(" ({} left)", duration_text((t - m.step) as f64 / m.steps_per_s))
                });
            format!(
                "seed {seed}: {}/{total} steps, {:.0} steps/s{left}, return {:.2}{success}",
                m.step, m.steps_per_s, m.mean_return
            )
        }
        None => format!("seed {seed}: starting (no metrics row yet)"),
    }
}

/// A remaining time at the precision a user plans with: `40 s`, `25 min`, `1 h 05 min`.
fn duration_text(seconds: f64) -> String {
    let s = seconds.round() as u64;
    match s {
        0..90 => format!("{s} s"),
        90..5400 => format!("{} min", (s + 30) / 60),
        _ => {
            let minutes = (s + 30) / 60;
            format!("{} h {:02} min", minutes / 60, minutes % 60)
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct MetricsRow {
    step: u64,
    mean_return: f64,
    steps_per_s: f64,
}

/// The named columns of the last complete row of the CSV file `path` (a row being written
/// has no newline yet).
fn last_row(path: &Path, names: &[&str]) -> Option<Vec<String>> {
    let text =
        vge_run::read_limits::read_to_string_bounded(path, vge_run::read_limits::MAX_TABLE_FILE_LEN).ok()?;
    let complete = &text[..text.rfind('\n')?];
    let mut lines = complete.lines();
    let header: Vec<&str> = lines.next()?.split(',').collect();
    let row: Vec<&str> = lines.next_back()?.split(',').collect();
    names
        .iter()
        .map(|name| header.iter().position(|h| h == name).and_then(|i| row.get(i)).map(|v| (*v).to_owned()))
        .collect()
}

fn last_metrics(dir: &Path) -> Option<MetricsRow> {
    let row = last_row(&dir.join(vge_run::run_dir::METRICS), &["step", "return", "steps_per_s"])?;
    Some(MetricsRow {
        step: row[0].parse().ok()?,
        mean_return: row[1].parse().ok()?,
        steps_per_s: row[2].parse().ok()?,
    })
}

/// The step and success rate of the run's last periodic success test (`eval.csv`).
fn last_success(dir: &Path) -> Option<(u64, f64)> {
    let row = last_row(&dir.join(vge_run::run_dir::EVAL), &["step", "success"])?;
    Some((row[0].parse().ok()?, row[1].parse().ok()?))
}

/// The final policy's success rate and whether the seed learned (`final-eval.json`).
fn final_success(dir: &Path) -> Option<(f64, bool)> {
    let path = vge_run::run_dir::RunDir::new(dir).final_eval();
    let doc: serde_json::Value = vge_run::run_dir::read_json(&path).ok()??;
    Some((doc.get("success_rate")?.as_f64()?, doc.get("learned")?.as_bool()?))
}

/// One line per seed for the end of a sweep.
pub fn summary_line(sweep: &Sweep, seed: u64, outcome: &Outcome) -> String {
    let dir = sweep.seed_dir(seed);
    match outcome {
        Outcome::Skipped => {
            format!("seed {seed}: done already ({})", dir.join(vge_run::run_dir::POLICY).display())
        }
        Outcome::Done => match last_metrics(&dir) {
            Some(m) => format!(
                "seed {seed}: done, {} steps, return {:.2}{}; {}",
                m.step,
                m.mean_return,
                final_success(&dir).map_or_else(String::new, |(rate, learned)| format!(
                    ", success {:.0}% ({})",
                    100.0 * rate,
                    if learned { "learned" } else { "did not learn" }
                )),
                dir.join(vge_run::run_dir::POLICY).display()
            ),
            None => format!("seed {seed}: done; {}", dir.join(vge_run::run_dir::POLICY).display()),
        },
        Outcome::Stopped { step, code } => format!(
            "seed {seed}: stopped at step {} (exit {code}), checkpoint saved; the same sweep again resumes it",
            step.map_or_else(|| "?".to_owned(), |s| s.to_string())
        ),
        Outcome::Failed { why, log } => format!("seed {seed}: FAILED ({why}); log {}", log.display()),
        Outcome::NotStarted => format!("seed {seed}: not started (sweep stopped)"),
    }
}

// ------------------------------------------------------------------ Slurm

/// `vge sweep --slurm`'s job settings.
#[derive(Debug, Clone)]
pub struct Slurm {
    pub partition: Option<String>,
    /// Wall-clock limit per task, in Slurm's format (e.g. `HH:MM:SS`, `D-HH:MM:SS`).
    pub time: Option<String>,
    /// CPUs per task; also the task's `sac.threads` (unless set) and rayon threads.
    pub cpus_per_task: usize,
}

/// The file name the sweep's config is copied to, merged with its bases, so the job depends
/// neither on the caller's working directory nor on later edits of the original or its bases.
pub const SWEEP_CONFIG: &str = "sweep-config.toml";
/// The job script's file name in the sweep's directory.
pub const SBATCH_FILE: &str = "sweep.sbatch";

/// Seconds before the time limit at which Slurm sends SIGTERM to the task (`--signal`): the
/// time vge has to write its checkpoint, replay buffer included.
const SIGNAL_LEAD_S: u32 = 120;

impl Slurm {
    /// Rejects values that would break the job script (they are written into it).
    pub fn validate(&self) -> Result<(), SweepError> {
        if let Some(p) = &self.partition
            && (p.is_empty() || !p.chars().all(|c| c.is_ascii_alphanumeric() || "-_.,".contains(c)))
        {
            return Err(SweepError::Invalid(format!("--partition `{p}` is not a partition name")));
        }
        if let Some(t) = &self.time
            && (t.is_empty() || !t.chars().all(|c| c.is_ascii_digit() || c == ':' || c == '-'))
        {
            return Err(SweepError::Invalid(format!(
                "--time `{t}` is not a Slurm time such as 12:00:00 or 1-00:00:00"
            )));
        }
        if self.cpus_per_task == 0 {
            return Err(SweepError::Invalid("--cpus-per-task must be at least 1".to_owned()));
        }
        Ok(())
    }
}

/// Quotes `s` for bash (single quotes; a `'` becomes `'\''`).
pub fn shell_quote(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@".contains(c)) {
        return s.to_owned();
    }
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// Seeds as Slurm's `--array` list: runs of consecutive seeds as `A-B`, e.g. `0-3,7,9-10`.
pub fn array_spec(seeds: &[u64]) -> String {
    let mut spec = String::new();
    let mut i = 0;
    while i < seeds.len() {
        let mut j = i;
        while j + 1 < seeds.len() && seeds[j + 1] == seeds[j] + 1 {
            j += 1;
        }
        if !spec.is_empty() {
            spec.push(',');
        }
        if j > i {
            spec.push_str(&format!("{}-{}", seeds[i], seeds[j]));
        } else {
            spec.push_str(&seeds[i].to_string());
        }
        i = j + 1;
    }
    spec
}

/// The array job script. `vge` and `dir` must be absolute; `seeds` are the array's task ids.
pub fn sbatch_script(
    vge: &Path,
    dir: &Path,
    name: &str,
    seeds: &[u64],
    sweep: &Sweep,
    slurm: &Slurm,
) -> String {
    let q = |p: &Path| shell_quote(&p.display().to_string());
    let (vge, d) = (q(vge), q(dir));
    let config = q(&dir.join(SWEEP_CONFIG));
    let args: Vec<String> = sweep.shared_args(slurm.cpus_per_task).iter().map(|a| shell_quote(a)).collect();
    let args = args.join(" ");
    let mut s = String::new();
    let mut line = |l: String| {
        s.push_str(&l);
        s.push('\n');
    };
    line("#!/bin/bash".into());
    line(format!("# `vge sweep --slurm` of {name}: one array task per seed (task id = seed)."));
    line("# Submitting it again skips finished seeds and resumes interrupted ones.".into());
    // #SBATCH lines are not shell: no quoting there, so the name keeps safe characters only.
    let job_name: String = name.chars().filter(|c| c.is_ascii_alphanumeric() || "-_.".contains(*c)).collect();
    line(format!("#SBATCH --job-name=vge-{job_name}"));
    line(format!("#SBATCH --array={}", array_spec(seeds)));
    line(format!("#SBATCH --cpus-per-task={}", slurm.cpus_per_task));
    if let Some(p) = &slurm.partition {
        line(format!("#SBATCH --partition={p}"));
    }
    if let Some(t) = &slurm.time {
        line(format!("#SBATCH --time={t}"));
    }
    line(format!("#SBATCH --output={}/slurm/%A_%a.out", dir.display()));
    line("#SBATCH --open-mode=append".into());
    // A requeued task (preemption, node failure) runs this script again and resumes.
    line("#SBATCH --requeue".into());
    // vge runs as a job step (srun) so that every way Slurm stops a task reaches it as
    // SIGTERM: scancel (with or without --signal=TERM), preemption, and this warning.
    line(format!(
        "# SIGTERM to vge {SIGNAL_LEAD_S} s before the time limit: it writes a checkpoint and exits."
    ));
    line(format!("#SBATCH --signal=TERM@{SIGNAL_LEAD_S}"));
    // The task's exit status is vge's (exec): never 0 for a seed that is not finished.
    line(format!(
        "# Exit status: 0 the seed finished; {} stopped by SIGTERM with its checkpoint (resubmit, or",
        stopped_exit_code(nix::libc::SIGTERM)
    ));
    line("# RequeueExit in slurm.conf, to resume it); 1 an error (see the log).".into());
    line("set -euo pipefail".into());
    line("seed=$SLURM_ARRAY_TASK_ID".into());
    line(format!("run={d}/seed-$seed"));
    line("mkdir -p \"$run\"".into());
    line("exec >>\"$run/train.log\" 2>&1".into());
    line("echo \"== slurm job ${SLURM_ARRAY_JOB_ID}_${seed} on $(hostname) at $(date -u +%FT%TZ), restart ${SLURM_RESTART_COUNT:-0}\"".into());
    line("# rayon (env stepping) would start one thread per core of the node, not of the task.".into());
    line("export RAYON_NUM_THREADS=${SLURM_CPUS_PER_TASK:-1}".into());
    // srun's own --cpus-per-task: a step does not inherit the batch's (Slurm >= 22.05).
    let srun = "srun --ntasks=1 --cpus-per-task=\"${SLURM_CPUS_PER_TASK:-1}\"";
    // Finished: final-eval.json is written last and whole (renamed into place), and the
    // policy reads back whole ([`check_finished`]).
    line(format!(
        "if [[ -s $run/final-eval.json ]] && {vge} inspect \"$run/policy.vgep\" >/dev/null 2>&1; then"
    ));
    line("  echo \"seed $seed: done already\"".into());
    line("elif [[ -d $run/checkpoint || -d $run/checkpoint.old ]]; then".into());
    line(format!("  exec {srun} {vge} train --resume \"$run\" --seed \"$seed\" {args}"));
    line("else".into());
    line(format!("  exec {srun} {vge} train --config {config} --out \"$run\" --seed \"$seed\" {args}"));
    line("fi".into());
    s
}

/// Copies the config, merged with its bases, into the sweep's directory (or checks that the
/// copy there is the same),
/// writes `DIR/sweep.sbatch` for the seeds not yet done (none: no file) and returns its path
/// and those seeds.
/// `vge` is the absolute path of the binary the tasks run.
pub fn write_sbatch(vge: &Path, sweep: &Sweep, slurm: &Slurm) -> Result<(PathBuf, Vec<u64>), SweepError> {
    slurm.validate()?;
    let slurm_dir = sweep.out.join("slurm");
    std::fs::create_dir_all(&slurm_dir).map_err(io_err(&slurm_dir))?;
    let dir = sweep.out.canonicalize().map_err(io_err(&sweep.out))?;
    if dir.to_string_lossy().chars().any(char::is_whitespace) {
        // #SBATCH --output takes the path unquoted.
        return Err(SweepError::Invalid(format!(
            "{}: a Slurm sweep's folder needs a path without spaces",
            dir.display()
        )));
    }
    copy_config(&sweep.config, &dir.join(SWEEP_CONFIG))?;
    let seeds: Vec<u64> =
        sweep.seeds.clone().filter(|&s| seed_state(&sweep.seed_dir(s)) != SeedState::Done).collect();
    let name = sweep.config.file_stem().map_or_else(|| "sweep".into(), |s| s.to_string_lossy());
    let path = dir.join(SBATCH_FILE);
    // Every seed done: an array of no tasks is no job, and the last script stays as it was.
    if !seeds.is_empty() {
        let text = sbatch_script(vge, &dir, &name, &seeds, sweep, slurm);
        vge_run::run_dir::atomic_file::write(&path, text.as_bytes()).map_err(io_err(&path))?;
    }
    Ok((path, seeds))
}

fn copy_config(from: &Path, to: &Path) -> Result<(), SweepError> {
    // A copy that kept `base = "..."` would look for the base beside the copy.
    let merged = vge_run::config::read_config_table(from)?;
    let text = toml::to_string(&merged)
        .map_err(|e| SweepError::Invalid(format!("{}: {e}", from.display())))?
        .into_bytes();
    match vge_run::read_limits::read_bounded(to, vge_run::read_limits::MAX_CONFIG_FILE_LEN) {
        Ok(existing) if existing == text => Ok(()),
        Ok(_) => Err(SweepError::OtherConfig(to.display().to_string())),
        Err(_) => vge_run::run_dir::atomic_file::write(to, &text).map_err(io_err(to)),
    }
}

/// True when `program` is an executable file in a `PATH` directory.
pub fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|d| d.join(program).is_file()))
}

/// Submits the job script with `sbatch --parsable` and returns the job id.
pub fn submit(script: &Path) -> Result<String, SweepError> {
    if !on_path("sbatch") {
        return Err(SweepError::NoSbatch);
    }
    let out =
        Command::new("sbatch").arg("--parsable").arg(script).output().map_err(io_err(Path::new("sbatch")))?;
    if !out.status.success() {
        return Err(SweepError::Sbatch {
            status: out.status.to_string(),
            stderr: String::from_utf8_lossy(&out.stderr).trim().to_owned(),
        });
    }
    // --parsable prints `jobid` or `jobid;cluster`.
    let text = String::from_utf8_lossy(&out.stdout);
    Ok(text.trim().split(';').next().unwrap_or_default().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_lines_read_the_last_complete_rows_of_metrics_and_eval() {
        let dir = std::env::temp_dir().join(format!("vge-sweep-progress-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        assert_eq!(progress_line(&dir, 3, Some(1000)), "seed 3: starting (no metrics row yet)");
        let metrics = "step,episodes,return,steps_per_s\n100,1,2.5,80.4\n200,2,3.25,90.6\n300,3,9";
        std::fs::write(dir.join(vge_run::run_dir::METRICS), metrics).expect("metrics");
        // 800 steps left at 90.6 steps/s.
        assert_eq!(
            progress_line(&dir, 3, Some(1000)),
            "seed 3: 200/1000 steps, 91 steps/s (9 s left), return 3.25"
        );
        assert_eq!(progress_line(&dir, 3, Some(200)), "seed 3: 200/200 steps, 91 steps/s, return 3.25");
        std::fs::write(
            dir.join(vge_run::run_dir::EVAL),
            "step,episodes,return,rotation,success\n200,20,5.0,1.0,0.3500\n",
        )
        .expect("eval");
        assert_eq!(
            progress_line(&dir, 3, Some(1000)),
            "seed 3: 200/1000 steps, 91 steps/s (9 s left), return 3.25, success 35% at 200"
        );
        assert_eq!(final_success(&dir), None);
        std::fs::write(dir.join(vge_run::run_dir::FINAL_EVAL), r#"{"learned": true, "success_rate": 0.55}"#)
            .expect("json");
        assert_eq!(final_success(&dir), Some((0.55, true)));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_sweeps_copy_of_a_config_holds_its_bases_merged_in() {
        let dir = std::env::temp_dir().join(format!("vge-sweep-copy-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("configs")).expect("dir");
        let base = dir.join("configs/base.toml");
        let child = dir.join("configs/child.toml");
        std::fs::write(&base, "name = \"base\"\ntotal_steps = 1000\nnum_envs = 2\n").expect("base");
        std::fs::write(&child, "base = \"base.toml\"\nname = \"child\"\n").expect("child");
        let copy = dir.join(SWEEP_CONFIG);
        copy_config(&child, &copy).expect("copy");
        let text = std::fs::read_to_string(&copy).expect("copy");
        assert!(!text.contains("base.toml"), "{text}");
        let original = vge_run::config::load_config(&child, &[]).expect("original");
        let copied = vge_run::config::load_config(&copy, &[]).expect("copy loads alone");
        assert_eq!(copied, original);
        assert_eq!((copied.total_steps, copied.num_envs, copied.name.as_str()), (1000, 2, "child"));
        // The same config again is fine; an edited base makes it another sweep's config.
        copy_config(&child, &copy).expect("same config");
        std::fs::write(&base, "name = \"base\"\ntotal_steps = 2000\n").expect("edit");
        assert!(matches!(copy_config(&child, &copy), Err(SweepError::OtherConfig(_))));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn time_left_reads_in_seconds_minutes_or_hours() {
        assert_eq!(duration_text(0.4), "0 s");
        assert_eq!(duration_text(89.0), "89 s");
        assert_eq!(duration_text(90.0), "2 min");
        assert_eq!(duration_text(1_500.0), "25 min");
        assert_eq!(duration_text(5_400.0), "1 h 30 min");
        assert_eq!(duration_text(3_900.0 + 3_600.0), "2 h 05 min");
    }

    #[test]
    fn array_spec_joins_runs_of_seeds() {
        assert_eq!(array_spec(&[0, 1, 2, 3]), "0-3");
        assert_eq!(array_spec(&[2, 5, 6, 7, 9]), "2,5-7,9");
        assert_eq!(array_spec(&[4]), "4");
    }

    #[test]
    fn shell_quote_keeps_plain_words_and_quotes_the_rest() {
        assert_eq!(shell_quote("sac.batch=128"), "sac.batch=128");
        assert_eq!(shell_quote("name=\"a b\""), "'name=\"a b\"'");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
    }

    #[test]
    fn threads_are_added_unless_the_user_set_them() {
        let mut sweep = Sweep {
            config: "c.toml".into(),
            seeds: 0..2,
            out: "/nonexistent/sweep".into(),
            steps: Some(500),
            overrides: vec!["sac.batch=64".into()],
        };
        let args: Vec<String> =
            sweep.train_args(1, 3).iter().map(|a| a.to_string_lossy().into_owned()).collect();
        assert_eq!(
            args,
            [
                "train",
                "--config",
                "c.toml",
                "--out",
                "/nonexistent/sweep/seed-1",
                "--seed",
                "1",
                "--steps",
                "500",
                "--set",
                "sac.batch=64",
                "--set",
                "sac.threads=3"
            ]
        );
        sweep.overrides.push(" sac.threads = 2".into());
        assert!(!sweep.shared_args(3).iter().any(|a| a == "sac.threads=3"));
    }
}
