//! `vge sweep --slurm` on a real Slurm: a 2-seed sweep of a tiny config runs as an array job
//! to the end, and a 3rd seed cancelled with `scancel` mid-run writes a checkpoint, exits,
//! and resumes from it when the sweep is submitted again.
//!
//! Ignored under `cargo test`: it needs a running Slurm (`SLURM_CONF`). scripts/slurm/test.sh
//! starts a throw-away one-node cluster on localhost and runs it; scripts/test.sh calls that.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn slurm(program: &str, args: &[&str]) -> Output {
    Command::new(program).args(args).output().unwrap_or_else(|e| panic!("running {program}: {e}"))
}

/// Fails with what to do when no Slurm answers, instead of passing without testing anything.
fn require_slurm() {
    let hint = "start one with `dir=$(scripts/slurm/start.sh) && export SLURM_CONF=$dir/slurm.conf` \
                (scripts/slurm/test.sh does both)";
    let out = Command::new("sinfo")
        .args(["-h", "-o", "%t"])
        .output()
        .unwrap_or_else(|e| panic!("Slurm's sinfo did not run ({e}): {hint}"));
    assert!(out.status.success(), "sinfo failed: {}; {hint}", text(&out.stderr).trim());
    let states = text(&out.stdout);
    assert!(states.lines().any(|s| s == "idle" || s == "mix"), "no usable Slurm node ({states}); {hint}");
}

/// `vge sweep --slurm` of seeds `seeds` into `dir`; returns the array job's id.
fn submit(dir: &Path, seeds: &str, steps: u64) -> String {
    let config = common::config("cube-fg-vge.toml");
    let steps = steps.to_string();
    let args = [
        "sweep",
        "--config",
        config.to_str().expect("utf-8"),
        "--seeds",
        seeds,
        "--out",
        dir.to_str().expect("utf-8"),
        "--slurm",
        "--steps",
        &steps,
    ];
    let out = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(args)
        .args(common::tiny_args())
        .output()
        .expect("vge sweep runs");
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "vge sweep --slurm: {}{stdout}", text(&out.stderr));
    let job = stdout
        .lines()
        .find_map(|l| l.strip_prefix("submitted array job "))
        .and_then(|rest| rest.split(':').next())
        .unwrap_or_else(|| panic!("no job id in:\n{stdout}"));
    assert!(stdout.contains("squeue -j") && stdout.contains("vge plot"), "{stdout}");
    job.to_owned()
}

/// Task states of the job's tasks still in the queue (pending, running, completing).
fn queued(job: &str) -> Vec<String> {
    let out = slurm("squeue", &["-h", "-j", job, "-o", "%i %T"]);
    // An unknown id (purged after MinJobAge) is an error: nothing queued either way.
    text(&out.stdout).lines().map(str::to_owned).collect()
}

fn wait_until(what: &str, limit: Duration, mut done: impl FnMut() -> bool) -> Duration {
    let start = Instant::now();
    while !done() {
        assert!(start.elapsed() < limit, "{what}: not after {limit:?}");
        std::thread::sleep(Duration::from_millis(250));
    }
    start.elapsed()
}

fn checkpoint_step(run: &Path) -> Option<u64> {
    vge_lab::sweep::checkpoint_step(run)
}

fn log(run: &Path) -> String {
    std::fs::read_to_string(run.join("train.log")).unwrap_or_default()
}

struct Cleanup(PathBuf, Vec<String>);
impl Drop for Cleanup {
    fn drop(&mut self) {
        // A failed assertion must not leave tasks training on the test cluster.
        for job in &self.1 {
            let _ = Command::new("scancel").arg(job).status();
        }
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

#[test]
#[ignore = "needs a running Slurm: scripts/slurm/test.sh"]
fn sweep_runs_as_an_array_job_and_a_cancelled_task_resumes_from_its_checkpoint() {
    require_slurm();
    let root = std::env::temp_dir().join(format!("vge-slurm-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).expect("temp dir");
    let mut cleanup = Cleanup(root.clone(), Vec::new());
    let dir = root.join("sweep");
    let limit = Duration::from_secs(300);

    // Two seeds to the end, side by side on the node's CPUs.
    let job = submit(&dir, "0..2", 400);
    cleanup.1.push(job.clone());
    let t = wait_until("the 2-seed array job to finish", limit, || queued(&job).is_empty());
    eprintln!("2-seed sweep (400 steps each) finished in {:.1} s", t.as_secs_f64());
    for seed in 0..2 {
        let run = dir.join(format!("seed-{seed}"));
        assert!(run.join("policy.vgep").exists(), "seed {seed} has no policy.vgep; its log:\n{}", log(&run));
        assert!(log(&run).contains("done: 400 steps"), "{}", log(&run));
    }
    let inspect = Command::new(env!("CARGO_BIN_EXE_vge"))
        .arg("inspect")
        .arg(dir.join("seed-1/policy.vgep"))
        .output()
        .expect("vge inspect");
    assert!(inspect.status.success(), "{}", text(&inspect.stdout));

    // A 3rd seed long enough to still run when cancelled after its first periodic checkpoint.
    let run = dir.join("seed-2");
    let job = submit(&dir, "2..3", 1_000_000);
    cleanup.1.push(job.clone());
    wait_until("a periodic checkpoint of seed 2", limit, || checkpoint_step(&run).is_some_and(|s| s >= 400));
    assert!(queued(&job).iter().any(|l| l.ends_with("RUNNING")), "seed 2's task is not running");
    // Plain scancel: SIGTERM to the task, SIGKILL only after KillWait (120 s in the test config).
    let t0 = Instant::now();
    let out = slurm("scancel", &[&job]);
    assert!(out.status.success(), "scancel: {}", text(&out.stderr));
    wait_until("the cancelled task to leave the queue", limit, || queued(&job).is_empty());
    eprintln!("scancel to exit: {:.1} s", t0.elapsed().as_secs_f64());
    let stopped = log(&run)
        .lines()
        .find_map(|l| l.strip_prefix("stopped at step ")?.split(':').next()?.parse::<u64>().ok())
        .unwrap_or_else(|| panic!("seed 2 did not checkpoint and exit on SIGTERM; its log:\n{}", log(&run)));
    assert_eq!(checkpoint_step(&run), Some(stopped), "the checkpoint on disk is the one written on SIGTERM");
    assert!(!run.join("checkpoint.tmp").exists(), "a checkpoint was cut off mid-write");
    assert!(!run.join("policy.vgep").exists(), "seed 2 finished instead of being cancelled");

    // Submitted again (a few hundred steps more so that the test ends soon), it resumes there.
    let total = stopped + 300;
    let job = submit(&dir, "2..3", total);
    cleanup.1.push(job.clone());
    wait_until("the resubmitted task to finish", limit, || queued(&job).is_empty());
    let text = log(&run);
    assert!(text.contains(&format!("resuming from step {stopped}")), "seed 2 did not resume:\n{text}");
    assert!(text.contains(&format!("done: {total} steps")), "{text}");
    assert!(run.join("policy.vgep").exists(), "seed 2 has no policy.vgep:\n{text}");
    cleanup.1.clear();
}
