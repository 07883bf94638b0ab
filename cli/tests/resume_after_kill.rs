//! `vge train` killed with SIGKILL mid-run and resumed with `--resume` ends where an
//! uninterrupted run ends: same metrics, same TensorBoard curves (the killed session's
//! points past the checkpoint dropped), same exported policy, byte for byte.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

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

/// The metrics CSV without its last column (steps/s differs between runs).
fn metrics_without_speed(run: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(run.join("metrics.csv")).expect("metrics");
    text.lines().map(|l| l.rsplit_once(',').map_or(l, |(a, _)| a).to_owned()).collect()
}

fn curves(run: &Path) -> Vec<(String, u64, f64)> {
    let mut s = common::tensorboard_scalars(&run.join("tensorboard"));
    s.retain(|(tag, _, _)| tag != "train/steps_per_s");
    s
}

#[test]
fn sigkill_then_resume_equals_an_uninterrupted_run() {
    let root = std::env::temp_dir().join(format!("vge-kill-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).expect("temp dir");
    let config = config_file(&root);
    let config = config.to_str().expect("utf-8 path");
    let (full, killed) = (root.join("full"), root.join("killed"));

    let out =
        vge(&["train", "--config", config, "--out", full.to_str().expect("path")]).output().expect("vge");
    assert!(out.status.success(), "uninterrupted run: {}", String::from_utf8_lossy(&out.stderr));

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
    assert_eq!(metrics_without_speed(&killed), metrics_without_speed(&full));
    assert_eq!(curves(&killed), curves(&full), "TensorBoard curves differ after resume");
    let a = std::fs::read(full.join("policy.vgep")).expect("policy");
    let b = std::fs::read(killed.join("policy.vgep")).expect("policy");
    assert!(a == b, "the resumed run's policy differs from the uninterrupted run's");
    let _ = std::fs::remove_dir_all(&root);
}
