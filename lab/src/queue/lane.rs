//! `vge queue run`: a queue's runs, one after another, each by its commit's `vge` in a child
//! process (one libtorch and one rayon thread by default, so two lanes side by side use two
//! cores). Run again, the same command continues the queue.
//!
//! The queue file is read afresh before each run, and its first line that is neither done,
//! nor held by another process, nor already tried by this lane is the next run: a queue file
//! replaced while a run trains (write a new file and rename it over the old one; an edit in
//! place could be read half-written) decides the next run. A run is done when
//! `docs/results/REL/score.json` or `runs/REL/score.json` exists (and its `--score-with`
//! marker, if the line has one). A run with a checkpoint resumes (`vge train --resume`, bit
//! for bit on the same binary, thread count and CPU model); a run folder without one
//! (stopped before its first checkpoint) is moved aside to `runs/REL.abandoned-TIME`, kept,
//! and the run starts again; a run that finished training without its score is scored.
//!
//! `runs/lanes/NAME.log` gets a line per start, end, skip and move, `TIME start REL with
//! vge-COMMIT` and `TIME end REL (exit N)` among them (`vge facts` reads these).

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, SystemTime};

use vge_run::run_dir::{LOCK, RunDir};

use super::{Checkout, QueueError, QueueLine, io_err, utc_compact, utc_timestamp};

/// How a lane ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaneEnd {
    /// No line is left to run.
    Done,
    /// A stop was asked for: the running child was sent SIGTERM (it checkpoints) and ended.
    Stopped,
    /// Less room than asked for under runs/ before a run: none started (a full disk fails a
    /// run at its next checkpoint, and the lane would go on failing the runs after it).
    NoRoom { free_bytes: u64 },
}

/// What a picked line needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// Trained and scored: only the scoring with `--score-with`'s binary is left.
    RescoreOnly,
    /// Trained (`final-eval.json`) without its score: `vge score`.
    Score,
    /// A checkpoint: `vge train --resume`.
    Resume,
    /// Nothing to resume: `vge train --config`, after moving a leftover folder aside.
    Train,
}

/// Whether the line's run is done (its score, and its `--score-with` marker if asked for).
pub fn is_done(checkout: &Checkout, line: &QueueLine) -> bool {
    checkout.results_dir(&line.rel).join(vge_run::run_dir::SCORE).is_file()
        || (checkout.run_dir(&line.rel).join(vge_run::run_dir::SCORE).is_file()
            && line.score_with.as_ref().is_none_or(|c| checkout.scored_with_marker(&line.rel, c).is_file()))
}

/// The step the run in `dir` needs next.
pub fn next_step(dir: &Path) -> Step {
    let run = RunDir::new(dir);
    if run.score().is_file() {
        Step::RescoreOnly
    } else if run.final_eval().is_file() {
        Step::Score
    } else if run.resume_checkpoint().is_some() {
        Step::Resume
    } else {
        Step::Train
    }
}

/// The pid in the run folder's lock when another process holds it (a lane, a `vge train` by
/// hand); None when the folder has no lock or nobody holds it.
pub fn held_by(dir: &Path) -> Option<String> {
    let mut file = File::open(dir.join(LOCK)).ok()?;
    match file.try_lock() {
        // Released when `file` drops, here.
        Ok(()) | Err(TryLockError::Error(_)) => None,
        Err(TryLockError::WouldBlock) => {
            let mut pid = String::new();
            let _ = file.read_to_string(&mut pid);
            Some(if pid.trim().is_empty() { "unknown".to_owned() } else { pid.trim().to_owned() })
        }
    }
}

/// The lock of a running lane, `runs/lanes/NAME.lock`, holding its pid (what `vge queue stop`
/// signals). Released when dropped or when the process ends.
#[derive(Debug)]
pub struct LaneLock {
    _file: File,
}

impl LaneLock {
    pub fn acquire(checkout: &Checkout, queue: &Path) -> Result<Self, QueueError> {
        let path = checkout.lane_lock(queue);
        std::fs::create_dir_all(checkout.lanes_dir()).map_err(io_err(&checkout.lanes_dir()))?;
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io_err(&path))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut pid = String::new();
                let _ = file.read_to_string(&mut pid);
                return Err(QueueError::Invalid(format!(
                    "{} is already running in another vge queue run (pid {}, holding {})",
                    queue.display(),
                    pid.trim(),
                    path.display()
                )));
            }
            Err(TryLockError::Error(e)) => return Err(io_err(&path)(e)),
        }
        file.set_len(0).map_err(io_err(&path))?;
        file.write_all(format!("{}\n", std::process::id()).as_bytes()).map_err(io_err(&path))?;
        Ok(Self { _file: file })
    }
}

/// The pid of the `vge queue run` holding the lane lock of `queue`, if one runs.
pub fn running_lane(checkout: &Checkout, queue: &Path) -> Option<i32> {
    let path = checkout.lane_lock(queue);
    let mut file = File::open(path).ok()?;
    match file.try_lock() {
        Ok(()) | Err(TryLockError::Error(_)) => None,
        Err(TryLockError::WouldBlock) => {
            let mut pid = String::new();
            file.read_to_string(&mut pid).ok()?;
            pid.trim().parse().ok()
        }
    }
}

/// The lane's log, `runs/lanes/NAME.log`: each line time-stamped, appended, and echoed.
struct LaneLog<'a> {
    path: PathBuf,
    say: &'a mut dyn FnMut(&str),
}

impl LaneLog<'_> {
    fn line(&mut self, what: &str) -> Result<(), QueueError> {
        let text = format!("{} {what}", utc_timestamp(SystemTime::now()));
        let mut file =
            OpenOptions::new().create(true).append(true).open(&self.path).map_err(io_err(&self.path))?;
        writeln!(file, "{text}").map_err(io_err(&self.path))?;
        (self.say)(&text);
        Ok(())
    }
}

/// Trains the runs of `queue` (checked first: nothing starts while a line is wrong), each
/// child's output appended to `runs/REL.log`, its rayon and scoring on `threads` threads.
/// `stop` raised ends the lane: the running child gets SIGTERM, checkpoints and exits, and
/// no further run starts. Before each run, the file system holding runs/ must have
/// `min_free_bytes` free, or the lane ends without starting it. Every line of the lane log is
/// also passed to `say`.
pub fn run(
    checkout: &Checkout,
    queue: &Path,
    threads: u32,
    min_free_bytes: u64,
    stop: &AtomicBool,
    say: &mut dyn FnMut(&str),
) -> Result<LaneEnd, QueueError> {
    super::check(checkout, queue, true)?;
    let _lock = LaneLock::acquire(checkout, queue)?;
    let mut log = LaneLog { path: checkout.lane_log(queue), say };
    let mut tried: Vec<String> = Vec::new();
    let mut noted: Vec<String> = Vec::new();
    loop {
        if stop.load(Ordering::SeqCst) {
            log.line("stopped: a signal asked the lane to stop")?;
            return Ok(LaneEnd::Stopped);
        }
        let Some(line) = pick(checkout, queue, &tried, &mut noted, &mut log)? else { break };
        let free_bytes = free_bytes_under(&checkout.root().join("runs"))?;
        if free_bytes < min_free_bytes {
            log.line(&format!(
                "stopped before {}: {:.1} GiB free under runs/, less than the {:.1} GiB asked for; \
                 free room and run the lane again",
                line.rel,
                gib(free_bytes),
                gib(min_free_bytes)
            ))?;
            return Ok(LaneEnd::NoRoom { free_bytes });
        }
        tried.push(line.rel.clone());
        if run_line(checkout, queue, &line, threads, stop, &mut log)? == LaneEnd::Stopped {
            log.line("stopped: a signal asked the lane to stop")?;
            return Ok(LaneEnd::Stopped);
        }
    }
    log.line("queue done")?;
    Ok(LaneEnd::Done)
}

/// Bytes an unprivileged process may still write on the file system holding `dir` (or the
/// nearest existing folder above it).
fn free_bytes_under(dir: &Path) -> Result<u64, QueueError> {
    let existing = dir.ancestors().find(|d| d.exists()).unwrap_or(dir);
    let stat = nix::sys::statvfs::statvfs(existing).map_err(|e| io_err(existing)(std::io::Error::from(e)))?;
    Ok(stat.blocks_available().saturating_mul(stat.fragment_size()))
}

fn gib(bytes: u64) -> f64 {
    bytes as f64 / f64::from(1u32 << 30)
}

/// The queue's first line not done, not held by another process and not tried yet; each
/// skip is logged once per lane.
fn pick(
    checkout: &Checkout,
    queue: &Path,
    tried: &[String],
    noted: &mut Vec<String>,
    log: &mut LaneLog<'_>,
) -> Result<Option<QueueLine>, QueueError> {
    let lines = match super::read(queue) {
        Ok(lines) => lines,
        Err(e) => {
            // A queue file replaced with a wrong line: the lane ends, saying why in its log.
            log.line(&format!("queue file has errors, lane ended: {}", e.to_string().replace('\n', "; ")))?;
            return Err(e);
        }
    };
    for line in lines.into_iter().filter(|l| !tried.contains(&l.rel)) {
        let skip = if is_done(checkout, &line) {
            format!("skip {} (done)", line.rel)
        } else if let Some(pid) = held_by(&checkout.run_dir(&line.rel)) {
            format!("skip {} (in use: pid {pid} holds its lock)", line.rel)
        } else {
            return Ok(Some(line));
        };
        if !noted.contains(&skip) {
            log.line(&skip)?;
            noted.push(skip);
        }
    }
    Ok(None)
}

/// Runs what `line` needs next, then its `--score-with` scoring.
fn run_line(
    checkout: &Checkout,
    queue: &Path,
    line: &QueueLine,
    threads: u32,
    stop: &AtomicBool,
    log: &mut LaneLog<'_>,
) -> Result<LaneEnd, QueueError> {
    let bin = checkout.binary(&line.commit);
    if !bin.is_file() {
        let why = format!("no {}: build it with `vge queue build {}`", bin.display(), queue.display());
        log.line(&format!("fail {} ({why})", line.rel))?;
        return Ok(LaneEnd::Done);
    }
    log.line(&format!("start {} with vge-{}", line.rel, line.commit))?;
    let dir = checkout.run_dir(&line.rel);
    // The child runs in the repository's root with the paths the queue names, so that its
    // messages ("continue with `vge train --resume runs/...`") hold there.
    let rel_dir = Path::new("runs").join(&line.rel);
    let threads_arg = threads.to_string();
    let args: Vec<String> = match next_step(&dir) {
        Step::RescoreOnly => Vec::new(),
        Step::Score => strings(&["score", "--threads", &threads_arg, &path_str(&rel_dir)]),
        Step::Resume => strings(&["train", "--resume", &path_str(&rel_dir)]),
        Step::Train => {
            if dir.exists() {
                // Stopped before its first checkpoint: nothing to resume, and vge refuses to
                // train into a folder holding a run. Kept beside it, not deleted.
                let aside =
                    PathBuf::from(format!("{}.abandoned-{}", dir.display(), utc_compact(SystemTime::now())));
                std::fs::rename(&dir, &aside).map_err(io_err(&dir))?;
                let aside_rel = aside.strip_prefix(checkout.root().join("runs")).unwrap_or(&aside);
                log.line(&format!(
                    "moved {} aside to {} (no checkpoint to resume); starting again",
                    line.rel,
                    aside_rel.display()
                ))?;
            }
            let config = Path::new("runs/src").join(&line.commit).join(&line.config);
            let mut args =
                strings(&["train", "--config", &path_str(&config), "--seed", &line.seed.to_string()]);
            args.extend(strings(&["--out", &path_str(&rel_dir)]));
            args.extend(line.sets.iter().flat_map(|s| ["--set".to_owned(), s.clone()]));
            args
        }
    };
    if !args.is_empty() {
        let code = run_child(checkout, &bin, &args, &line.rel, threads, stop)?;
        log.line(&format!("end {} (exit {code})", line.rel))?;
        if stop.load(Ordering::SeqCst) {
            return Ok(LaneEnd::Stopped);
        }
    } else {
        log.line(&format!("end {} (exit 0)", line.rel))?;
    }
    if let Some(other) = &line.score_with
        && dir.join(vge_run::run_dir::SCORE).is_file()
    {
        return score_with(checkout, queue, line, other, threads, stop, log);
    }
    Ok(LaneEnd::Done)
}

/// `vge score --force` with `--score-with`'s binary; `runs/REL.scored-with-COMMIT2` on success.
fn score_with(
    checkout: &Checkout,
    queue: &Path,
    line: &QueueLine,
    other: &str,
    threads: u32,
    stop: &AtomicBool,
    log: &mut LaneLog<'_>,
) -> Result<LaneEnd, QueueError> {
    let bin = checkout.binary(other);
    if !bin.is_file() {
        let why = format!("no {}: build it with `vge queue build {}`", bin.display(), queue.display());
        log.line(&format!("fail {} ({why})", line.rel))?;
        return Ok(LaneEnd::Done);
    }
    log.line(&format!("score {} again with vge-{other}", line.rel))?;
    let rel_dir = path_str(&Path::new("runs").join(&line.rel));
    let args = strings(&["score", "--force", "--threads", &threads.to_string(), &rel_dir]);
    let code = run_child(checkout, &bin, &args, &line.rel, threads, stop)?;
    if code == 0 {
        let marker = checkout.scored_with_marker(&line.rel, other);
        std::fs::write(&marker, format!("vge-{other}\n")).map_err(io_err(&marker))?;
    }
    log.line(&format!("scored {} (exit {code})", line.rel))?;
    Ok(if stop.load(Ordering::SeqCst) { LaneEnd::Stopped } else { LaneEnd::Done })
}

/// Runs `bin args` in the repository's root, its output appended to `runs/REL.log`, and
/// returns its exit status (128 + the signal's number when a signal ended it). When `stop`
/// is raised the child is sent SIGTERM once and waited for.
fn run_child(
    checkout: &Checkout,
    bin: &Path,
    args: &[String],
    rel: &str,
    threads: u32,
    stop: &AtomicBool,
) -> Result<i32, QueueError> {
    let log_path = checkout.run_log(rel);
    if let Some(parent) = log_path.parent() {
        std::fs::create_dir_all(parent).map_err(io_err(parent))?;
    }
    let out = OpenOptions::new().create(true).append(true).open(&log_path).map_err(io_err(&log_path))?;
    let err = out.try_clone().map_err(io_err(&log_path))?;
    let mut child = Command::new(bin)
        .args(args)
        .current_dir(checkout.root())
        .env("RAYON_NUM_THREADS", threads.to_string())
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(err)
        .spawn()
        .map_err(io_err(bin))?;
    let mut forwarded = false;
    let status = loop {
        if let Some(status) = child.try_wait().map_err(io_err(bin))? {
            break status;
        }
        if !forwarded && stop.load(Ordering::SeqCst) {
            if let Ok(pid) = i32::try_from(child.id()) {
                let _ = nix::sys::signal::kill(
                    nix::unistd::Pid::from_raw(pid),
                    nix::sys::signal::Signal::SIGTERM,
                );
            }
            forwarded = true;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    Ok(exit_code(status))
}

fn exit_code(status: ExitStatus) -> i32 {
    use std::os::unix::process::ExitStatusExt;
    status.code().or_else(|| status.signal().map(|s| 128 + s)).unwrap_or(-1)
}

fn strings(words: &[&str]) -> Vec<String> {
    words.iter().map(|w| (*w).to_owned()).collect()
}

fn path_str(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}
