//! `vge train` stopped mid-run and resumed with `--resume` ends where an uninterrupted run
//! ends: same metrics (every column but `steps_per_s`, the wall-clock rate, which differs
//! between any two runs), same TensorBoard curves (an interrupted session's points past its
//! checkpoint dropped), same exported policy, byte for byte. Stopped by SIGKILL (from the
//! last periodic checkpoint), and by SIGTERM and SIGINT at steps between checkpoints (from
//! the checkpoint the stop writes, the envs' episodes in progress included), which exit with
//! 143 and 130 and say where they stopped.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use nix::sys::signal::Signal;

const TOTAL_STEPS: u64 = 3000;

fn config_file(dir: &Path) -> PathBuf {
    // TINY, then this test's own: VGE + BC with its hard stop and BC decay inside the run,
    // one thread, and a checkpoint every 400 steps (after TINY's 200, so it wins).
    let own = [
        "name=\"kill-test\"",
        "method=vge-bc",
        "sac.threads=1",
        "vge.hard_stop=1000",
        "bc.beta_zero_step=2000",
        "run.checkpoint_interval=400",
    ];
    common::tiny_config_file(dir, &own, TOTAL_STEPS)
}

fn vge(args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vge"));
    cmd.args(args).stdout(Stdio::null()).stderr(Stdio::piped());
    cmd
}

fn checkpoint_step(run: &Path) -> Option<u64> {
    let text = std::fs::read_to_string(run.join("checkpoint/state.toml")).ok()?;
    let line = text.lines().find(|l| l.starts_with("step = "))?;
    line.trim_start_matches("step = ").parse().ok()
}

fn last_logged_step(run: &Path) -> u64 {
    let text = std::fs::read_to_string(run.join("metrics.csv")).unwrap_or_default();
    text.lines().filter_map(|l| l.split(',').next()?.parse().ok()).max().unwrap_or(0)
}

/// The metrics CSV without its `steps_per_s` column: a wall-clock rate, which differs between
/// any two runs; every other column must be equal.
fn metrics_without_speed(run: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(run.join("metrics.csv")).expect("metrics");
    let header: Vec<&str> = text.lines().next().expect("header").split(',').collect();
    let speed = header.iter().position(|h| *h == "steps_per_s").expect("a steps_per_s column");
    text.lines()
        .map(|l| {
            l.split(',')
                .enumerate()
                .filter(|(i, _)| *i != speed)
                .map(|(_, f)| f)
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect()
}

fn curves(run: &Path) -> Vec<(String, u64, f64)> {
    let mut s = common::tensorboard_scalars(&run.join("tensorboard"));
    s.retain(|(tag, _, _)| tag != "train/steps_per_s");
    s
}

/// The folder of this test binary's runs, and its config file.
fn root() -> &'static (PathBuf, String) {
    static ROOT: OnceLock<(PathBuf, String)> = OnceLock::new();
    ROOT.get_or_init(|| {
        let root = std::env::temp_dir().join(format!("vge-kill-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(&root).expect("temp dir");
        let config = config_file(&root).to_str().expect("utf-8 path").to_owned();
        (root, config)
    })
}

/// The uninterrupted run, trained once for every test here.
fn full_run() -> &'static Path {
    static FULL: OnceLock<PathBuf> = OnceLock::new();
    FULL.get_or_init(|| {
        let (root, config) = root();
        let full = root.join("full");
        let out =
            vge(&["train", "--config", config, "--out", full.to_str().expect("path")]).output().expect("vge");
        assert!(out.status.success(), "uninterrupted run: {}", String::from_utf8_lossy(&out.stderr));
        full
    })
}

/// `run` against the uninterrupted run: metrics (all but steps/s), curves, policy bytes.
fn assert_same_as_uninterrupted(run: &Path) {
    let full = full_run();
    assert_eq!(metrics_without_speed(run), metrics_without_speed(full), "metrics.csv differs");
    assert_eq!(curves(run), curves(full), "TensorBoard curves differ after resume");
    let a = std::fs::read(full.join("policy.vgep")).expect("policy");
    let b = std::fs::read(run.join("policy.vgep")).expect("policy");
    assert!(a == b, "the resumed run's policy differs from the uninterrupted run's");
}

#[test]
fn sigkill_then_resume_equals_an_uninterrupted_run() {
    let (root, config) = root();
    let config = config.as_str();
    full_run();
    let killed = root.join("killed");

    // Kill once a periodic checkpoint exists and the log has moved past it, so the kill
    // loses work that the resumed run must redo identically.
    let mut child = vge(&["train", "--config", config, "--out", killed.to_str().expect("path")])
        .spawn()
        .expect("spawn vge");
    let deadline = Instant::now() + Duration::from_secs(300);
    let killed_at = loop {
        if let Some(ck) = checkpoint_step(&killed)
            && ck >= 800
            && last_logged_step(&killed) > ck
        {
            child.kill().expect("SIGKILL");
            break ck;
        }
        if let Some(status) = child.try_wait().expect("wait") {
            panic!("the run ended ({status}) before it could be killed; raise TOTAL_STEPS");
        }
        assert!(Instant::now() < deadline, "no checkpoint at step >= 800 after 300 s");
        std::thread::sleep(Duration::from_millis(2));
    };
    let _ = child.wait();
    assert!(killed_at < TOTAL_STEPS);
    assert!(!killed.join("policy.vgep").exists(), "the killed run must not have finished");
    let logged_before_resume = last_logged_step(&killed);

    let out = vge(&["train", "--resume", killed.to_str().expect("path")]).output().expect("vge resume");
    assert!(out.status.success(), "resume: {}", String::from_utf8_lossy(&out.stderr));
    assert!(logged_before_resume > killed_at, "the kill lost no logged work; the test proves less");
    assert_same_as_uninterrupted(&killed);
    let _ = std::fs::remove_dir_all(&killed);
}

/// One session of `vge train` (`args`) stopped by `signal` once `metrics.csv` has a row past
/// `after`: its exit status, the step its stop line names, and that line.
fn stop_session(args: &[&str], run: &Path, signal: Signal, after: u64) -> (Option<i32>, u64, String) {
    let log_path = run.with_extension(format!("session-{after}.log"));
    let log = std::fs::File::create(&log_path).expect("log");
    let mut child = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("spawn vge");
    let deadline = Instant::now() + Duration::from_secs(300);
    while last_logged_step(run) <= after {
        if let Some(status) = child.try_wait().expect("wait") {
            panic!("the run ended ({status}) before step {after}; raise TOTAL_STEPS");
        }
        assert!(Instant::now() < deadline, "no metrics row past step {after} after 300 s");
        std::thread::sleep(Duration::from_millis(2));
    }
    let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).expect("pid"));
    nix::sys::signal::kill(pid, signal).expect("signal");
    let status = child.wait().expect("vge ends");
    let text = std::fs::read_to_string(&log_path).expect("log");
    let line = text
        .lines()
        .find(|l| l.starts_with("stopped at step "))
        .unwrap_or_else(|| panic!("no stop line after {signal}:\n{text}"))
        .to_owned();
    let step = line["stopped at step ".len()..].split(':').next().and_then(|s| s.parse().ok()).expect("step");
    (status.code(), step, line)
}

#[test]
fn sigterm_and_sigint_at_any_step_then_resume_equal_an_uninterrupted_run() {
    let (root, config) = root();
    let run = root.join("signalled");
    let dir = run.to_str().expect("path");
    let new = ["train", "--config", config.as_str(), "--out", dir];
    let resume = ["train", "--resume", dir];
    let mut stops = Vec::new();
    // Between the periodic checkpoints (every 400 steps) and the log rows (every 50): the stop
    // lands wherever the loop is when the signal comes.
    for (k, (signal, after, code)) in
        [(Signal::SIGTERM, 650, 143), (Signal::SIGINT, 1510, 130), (Signal::SIGTERM, 2420, 143)]
            .into_iter()
            .enumerate()
    {
        let args: &[&str] = if k == 0 { &new } else { &resume };
        let (status, step, line) = stop_session(args, &run, signal, after);
        assert_eq!(status, Some(code), "{signal} must exit {code}: {line}");
        assert!(
            line.contains(&format!("vge train --resume {dir}")) && line.contains(signal.as_str()),
            "{line}"
        );
        assert_eq!(checkpoint_step(&run), Some(step), "the checkpoint is the one the stop wrote");
        assert!(!run.join("policy.vgep").exists(), "a stopped run wrote its policy");
        stops.push(step);
    }
    eprintln!("stopped at steps {stops:?}");
    assert!(stops.iter().any(|s| s % 400 != 0), "every stop fell on a periodic checkpoint: {stops:?}");
    let out = vge(&["train", "--resume", dir]).output().expect("vge resume");
    assert!(out.status.success(), "resume: {}", String::from_utf8_lossy(&out.stderr));
    assert_same_as_uninterrupted(&run);
    let _ = std::fs::remove_dir_all(&run);
}
