//! `vge queue` on a real git repository and real tiny runs, trained by the `vge` under test
//! standing in as the queue's built binary: what a lane trains, skips, moves aside, resumes
//! and scores, what it logs, how it is stopped and continued, the checks that keep a bad
//! queue from starting, and `collect` with the facts it prints.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A tiny run's env steps: a few seconds of training.
const STEPS: u64 = 400;

fn vge(root: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge")).args(args).current_dir(root).output().expect("vge runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn git(root: &Path, args: &[&str]) -> String {
    let out = Command::new("git")
        .args(["-c", "user.name=vge test", "-c", "user.email=test@vge.invalid"])
        .args(args)
        .current_dir(root)
        .output()
        .expect("git runs");
    assert!(out.status.success(), "git {args:?}: {}", text(&out.stderr));
    text(&out.stdout).trim().to_owned()
}

/// A git repository at a temp folder whose one commit holds `configs/tiny.toml` (the
/// defaults with `common::TINY`, `STEPS` long on one libtorch thread, a periodic test every
/// 200 steps, scored on 2 episodes at its end), with that
/// commit's worktree at `runs/src/COMMIT` and the vge under test as `runs/bin/vge-COMMIT`,
/// as `vge queue build` leaves them. Returns the root and the commit.
fn repository(name: &str) -> (PathBuf, String) {
    let root = common::temp_dir(name);
    git(&root, &["init", "-q"]);
    std::fs::create_dir_all(root.join("configs")).expect("configs");
    let written = common::tiny_config_file(
        &root.join("configs"),
        &["run.score_episodes=2", "run.eval_interval=200", "sac.threads=1"],
        STEPS,
    );
    std::fs::rename(written, root.join("configs/tiny.toml")).expect("rename");
    git(&root, &["add", "configs/tiny.toml"]);
    git(&root, &["commit", "-q", "-m", "a tiny config"]);
    let commit = git(&root, &["rev-parse", "--short=7", "HEAD"]);
    git(&root, &["worktree", "add", "-q", "--detach", &format!("runs/src/{commit}"), &commit]);
    std::fs::create_dir_all(root.join("runs/bin")).expect("runs/bin");
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_vge"), root.join(format!("runs/bin/vge-{commit}")))
        .expect("the binary");
    (root, commit)
}

/// A second commit on `root` (adding `later.toml`), with no vge built for it: its short hash.
fn second_commit(root: &Path) -> String {
    std::fs::write(root.join("later.toml"), "name = \"later\"\n").expect("file");
    git(root, &["add", "later.toml"]);
    git(root, &["commit", "-q", "-m", "a second commit"]);
    git(root, &["rev-parse", "--short=7", "HEAD"])
}

fn lane_log(root: &Path) -> String {
    std::fs::read_to_string(root.join("runs/lanes/queue.log")).unwrap_or_default()
}

fn config_of(run: &Path) -> toml::Table {
    std::fs::read_to_string(run.join("config.toml")).expect("config.toml").parse().expect("TOML")
}

/// One lane over a queue that holds each case: a run to train, one with an override, one
/// already collected, a leftover folder without a checkpoint, and a folder another process
/// holds. Run again, the lane starts nothing; `collect` copies a run's record and its facts.
#[test]
fn a_lane_trains_skips_moves_aside_and_continues() {
    let (root, c) = repository("queue-lane");
    let queue = format!(
        "# runs of a tiny config\n\
         a/seed-0 {c} configs/tiny.toml 0\n\
         \n\
         b/seed-1 {c} configs/tiny.toml 1 --set total_steps=200 --set sac.threads=1\n\
         c/seed-2 {c} configs/tiny.toml 2\n\
         d/seed-3 {c} configs/tiny.toml 3\n\
         f/seed-5 {c} configs/tiny.toml 5\n"
    );
    std::fs::write(root.join("queue.txt"), queue).expect("queue");
    // c: already collected.
    std::fs::create_dir_all(root.join("docs/results/c/seed-2")).expect("results");
    std::fs::write(root.join("docs/results/c/seed-2/score.json"), "{}").expect("score");
    // d: stopped before its first checkpoint.
    std::fs::create_dir_all(root.join("runs/d/seed-3")).expect("d");
    std::fs::write(root.join("runs/d/seed-3/metrics.csv"), "step\n").expect("d's file");
    // f: held by another process (this test, through the run folder's lock).
    std::fs::create_dir_all(root.join("runs/f/seed-5")).expect("f");
    let held = std::fs::File::create(root.join("runs/f/seed-5/vge.lock")).expect("lock file");
    held.try_lock().expect("the lock");
    std::fs::write(root.join("runs/f/seed-5/vge.lock"), format!("{}\n", std::process::id())).expect("pid");

    let out = vge(&root, &["queue", "run", "queue.txt"]);
    assert!(out.status.success(), "{}{}", text(&out.stdout), text(&out.stderr));
    let log = lane_log(&root);
    for want in [
        format!("start a/seed-0 with vge-{c}"),
        "end a/seed-0 (exit 0)".to_owned(),
        "end b/seed-1 (exit 0)".to_owned(),
        "skip c/seed-2 (done)".to_owned(),
        "moved d/seed-3 aside to d/seed-3.abandoned-".to_owned(),
        "end d/seed-3 (exit 0)".to_owned(),
        format!("skip f/seed-5 (in use: pid {} holds its lock)", std::process::id()),
        "queue done".to_owned(),
    ] {
        assert!(log.contains(&want), "no `{want}` in the lane log:\n{log}");
    }
    // The lane's log lines are time-stamped to the second, in UTC.
    let first = log.lines().next().expect("a line");
    assert!(first.len() > 21 && first.as_bytes()[10] == b'T' && &first[19..21] == "Z ", "{first}");
    assert_eq!(text(&out.stdout).lines().filter(|l| l.contains(" start ")).count(), 3, "echoed");

    // Each run trained from the commit's config with its own seed and overrides, into runs/REL.
    for (rel, seed, steps) in [("a/seed-0", 0, STEPS), ("b/seed-1", 1, 200), ("d/seed-3", 3, STEPS)] {
        let run = root.join("runs").join(rel);
        assert!(run.join("score.json").is_file(), "{rel} scored");
        let config = config_of(&run);
        assert_eq!(config["total_steps"].as_integer(), Some(i64::try_from(steps).expect("steps")), "{rel}");
        assert_eq!(config["seed"].as_integer(), Some(seed), "{rel}");
        let run_log = std::fs::read_to_string(root.join(format!("runs/{rel}.log"))).expect("the run's log");
        assert!(run_log.contains(&format!("into runs/{rel}")), "{run_log}");
    }
    // d's leftover is kept beside it; c and f were not touched.
    let aside: Vec<PathBuf> = std::fs::read_dir(root.join("runs/d"))
        .expect("runs/d")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.to_string_lossy().contains("seed-3.abandoned-"))
        .collect();
    assert_eq!(aside.len(), 1, "{aside:?}");
    assert!(aside[0].join("metrics.csv").is_file());
    assert!(!root.join("runs/c").exists());
    assert!(!root.join("runs/f/seed-5/config.toml").exists());

    // Again: every run is done or held, so nothing starts.
    let starts = log.matches(" start ").count();
    let out = vge(&root, &["queue", "run", "queue.txt"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let log = lane_log(&root);
    assert_eq!(log.matches(" start ").count(), starts, "{log}");
    assert!(log.contains("skip a/seed-0 (done)"), "{log}");

    // The status of each line, and collect with the run's facts.
    let status = text(&vge(&root, &["queue", "status", "queue.txt"]).stdout);
    assert!(
        status.lines().any(|l| l.starts_with("a/seed-0") && l.ends_with("finished, not collected")),
        "{status}"
    );
    assert!(status.lines().any(|l| l.starts_with("c/seed-2") && l.ends_with(" collected")), "{status}");
    assert!(status.lines().any(|l| l.starts_with("f/seed-5") && l.contains("training now")), "{status}");
    let out = vge(&root, &["queue", "collect", "a/seed-0"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let collected = root.join("docs/results/a/seed-0");
    for file in [
        "config.toml",
        "metrics.csv",
        "eval.csv",
        "final-eval.json",
        "score.json",
        "policy.vgep",
        "train.log",
    ] {
        assert!(collected.join(file).is_file(), "{file} collected");
    }
    assert!(!collected.join("checkpoint").exists(), "no checkpoint collected");
    let facts = text(&out.stdout);
    assert!(facts.contains("== ") && facts.contains("\nrow: selected"), "{facts}");
    assert!(facts.contains("start (queue)") && facts.contains("end (queue)"), "the lane's lines: {facts}");
    drop(held);
    let _ = std::fs::remove_dir_all(&root);
}

/// `vge queue stop` ends a lane mid-run: its vge checkpoints and the lane exits 143 (SIGTERM);
/// the same `vge queue run` then resumes the run from that checkpoint to its end.
#[test]
fn a_stopped_lane_resumes_its_run_from_the_checkpoint() {
    let (root, c) = repository("queue-stop");
    // Long enough that the stop comes well before the end, with a checkpoint every 200.
    std::fs::write(
        root.join("queue.txt"),
        format!("s/seed-0 {c} configs/tiny.toml 0 --set total_steps=1200\n"),
    )
    .expect("queue");
    let lane = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["queue", "run", "queue.txt"])
        .current_dir(&root)
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("the lane");
    let run = root.join("runs/s/seed-0");
    while !run.join("checkpoint/state.toml").is_file() {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let stop = vge(&root, &["queue", "stop", "queue.txt"]);
    assert!(stop.status.success(), "{}", text(&stop.stderr));
    let lane = lane.wait_with_output().expect("the lane ends");
    assert_eq!(lane.status.code(), Some(143), "stopped by SIGTERM");
    let log = lane_log(&root);
    assert!(log.contains("end s/seed-0 (exit 143)") && log.contains("stopped"), "{log}");
    assert!(!run.join("score.json").exists(), "stopped before its end");

    let out = vge(&root, &["queue", "run", "queue.txt"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let run_log = std::fs::read_to_string(root.join("runs/s/seed-0.log")).expect("the run's log");
    assert!(run_log.contains("resuming from step"), "{run_log}");
    assert!(run.join("score.json").is_file());
    assert!(lane_log(&root).contains("end s/seed-0 (exit 0)"));
    let _ = std::fs::remove_dir_all(&root);
}

/// A queue with wrong lines starts nothing and names each: the form, a commit the repository
/// lacks, a config missing at its commit, a run twice, and a commit whose vge is not built
/// (with the command that builds it).
#[test]
fn a_bad_queue_is_refused_naming_every_problem() {
    let (root, c) = repository("queue-check");
    let unbuilt = second_commit(&root);
    let queue = format!(
        "a/seed-0 {c} configs/tiny.toml zero\n\
         b/seed-0 0000000 configs/tiny.toml 0\n\
         c/seed-0 {c} configs/missing.toml 0\n\
         d/seed-0 {c} configs/tiny.toml 0 --set total_steps\n\
         e/seed-0 {c} configs/tiny.toml 0\n\
         e/seed-0 {c} configs/tiny.toml 1\n\
         g/seed-0 {unbuilt} later.toml 0\n"
    );
    std::fs::write(root.join("queue.txt"), queue).expect("queue");
    let out = vge(&root, &["queue", "check", "queue.txt"]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    for want in [
        "queue.txt:1: seed 'zero' is not a whole number",
        "queue.txt:2: no commit 0000000 in this repository",
        "queue.txt:3: configs/missing.toml does not exist at commit",
        "queue.txt:4: after the seed only --set KEY=VALUE",
        "queue.txt:6: e/seed-0 is also on line 5",
        &format!("(the vge of commit {unbuilt}): build it with `vge queue build queue.txt`"),
    ] {
        assert!(stderr.contains(want), "no `{want}` in:\n{stderr}");
    }
    let out = vge(&root, &["queue", "run", "queue.txt"]);
    assert!(!out.status.success());
    assert!(!root.join("runs/e").exists() && !lane_log(&root).contains("start"), "nothing started");

    // Outside a repository's root, vge queue says where to run it.
    let out = vge(&root.join("configs"), &["queue", "check", "../queue.txt"]);
    assert!(text(&out.stderr).contains("is not a repository's root"), "{}", text(&out.stderr));
    let _ = std::fs::remove_dir_all(&root);
}

/// A finished run's commit needs no binary: a new checkout, whose `runs/bin` is empty, checks
/// a queue whose unbuilt commit only finished runs name, and `build` does not build it; once
/// a run to do names it, the check asks for it.
#[test]
fn only_the_runs_still_to_do_need_their_binaries() {
    let (root, c) = repository("queue-done-binaries");
    let unbuilt = second_commit(&root);
    std::fs::create_dir_all(root.join("docs/results/old/seed-0")).expect("results");
    std::fs::write(root.join("docs/results/old/seed-0/score.json"), "{}").expect("score");
    let done_only = format!("old/seed-0 {unbuilt} configs/tiny.toml 0\na/seed-0 {c} configs/tiny.toml 0\n");
    std::fs::write(root.join("queue.txt"), done_only).expect("queue");
    let out = vge(&root, &["queue", "check", "queue.txt"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = vge(&root, &["queue", "build", "queue.txt"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let built = text(&out.stdout);
    assert!(
        built.lines().count() == 1 && built.trim_end().ends_with(&format!("runs/bin/vge-{c}")),
        "{built}"
    );
    assert!(!root.join(format!("runs/src/{unbuilt}")).exists(), "no worktree for a finished run's commit");

    std::fs::remove_file(root.join("docs/results/old/seed-0/score.json")).expect("remove");
    let out = vge(&root, &["queue", "check", "queue.txt"]);
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert!(stderr.contains(&format!("(the vge of commit {unbuilt}): build it with")), "{stderr}");
    let _ = std::fs::remove_dir_all(&root);
}

/// A lane asked for more free room under runs/ than the disk has starts no run, ends with an
/// error naming the flag, and logs which run it stopped before; with room it trains that run.
#[test]
fn a_lane_without_room_under_runs_starts_nothing_and_says_so() {
    let (root, c) = repository("queue-room");
    std::fs::write(root.join("queue.txt"), format!("a/seed-0 {c} configs/tiny.toml 0\n")).expect("queue");
    // 2^40 GiB: more than any file system holds.
    let out = vge(&root, &["queue", "run", "queue.txt", "--min-free-gib", "1099511627776"]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("less than --min-free-gib 1099511627776"), "{stderr}");
    let log = lane_log(&root);
    assert!(log.contains("stopped before a/seed-0:") && log.contains("GiB free under runs/"), "{log}");
    assert!(!log.contains(" start ") && !root.join("runs/a").exists(), "nothing started: {log}");

    let out = vge(&root, &["queue", "run", "queue.txt", "--min-free-gib=-1"]);
    assert!(text(&out.stderr).contains("expected a number of GiB, 0 or more"), "{}", text(&out.stderr));

    let out = vge(&root, &["queue", "run", "queue.txt", "--min-free-gib", "0"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(lane_log(&root).contains("end a/seed-0 (exit 0)"));
    let _ = std::fs::remove_dir_all(&root);
}
