//! A run folder survives a kill at any write, a full disk in any writer, and a second writer:
//! `vge train` is killed (SIGKILL) or handed `ENOSPC` at chosen system calls on chosen files
//! by `strace`'s fault injection (the real program, the real kernel interface), then resumed
//! to the policy of an uninterrupted run, byte for byte, and `vge plot` reads the folder.
//! One test trains into a real, small tmpfs.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

const TOTAL_STEPS: u64 = 800;

/// TINY, with a checkpoint and an evaluation every 400 steps: a periodic checkpoint at 400
/// and the final one at 800; snapshots, `eval.csv` and model selection.
fn config_file(dir: &Path) -> PathBuf {
    let own =
        ["name=\"crash-test\"", "sac.threads=1", "run.checkpoint_interval=400", "run.eval_interval=400"];
    common::tiny_config_file(dir, &own, TOTAL_STEPS)
}

fn vge(args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vge"));
    cmd.args(args).stdin(Stdio::null()).env("RAYON_NUM_THREADS", "1");
    cmd
}

fn text(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// `vge train --config CONFIG --out DIR`, under `strace` with `inject` on the syscalls of
/// `paths` (`-P`): the fault lands on those files only. An injected error runs under
/// `--seccomp-bpf`, which stops the tracee only at the traced syscalls (a traced run took
/// 1.7 times as long without it); an injected signal does not, as strace 6.1 then let the
/// killing call pass.
fn train_under_strace(config: &Path, dir: &Path, extra: &[&str], paths: &[PathBuf], inject: &str) -> Output {
    let mut cmd = Command::new("strace");
    cmd.args(["-f", "-qq", "-o", "/dev/null"]);
    if inject.contains(":error=") {
        cmd.arg("--seccomp-bpf");
    }
    for p in paths {
        cmd.arg("-P").arg(p);
    }
    let trace = inject.split(':').next().expect("syscalls");
    cmd.args(["-e", &format!("trace={trace}"), "-e", &format!("inject={inject}")]);
    cmd.arg(env!("CARGO_BIN_EXE_vge")).env("RAYON_NUM_THREADS", "1").stdin(Stdio::null());
    if extra.first() == Some(&"--resume") {
        cmd.args(["train"]).args(extra);
    } else {
        cmd.args(["train", "--config", s(config), "--out", s(dir)]).args(extra);
    }
    cmd.output().expect("strace runs (apt-get install strace)")
}

/// The uninterrupted run every test compares with (trained once per test binary).
fn reference() -> &'static PathBuf {
    static REFERENCE: OnceLock<PathBuf> = OnceLock::new();
    REFERENCE.get_or_init(|| {
        let root = common::temp_dir("crash-reference");
        let config = config_file(&root);
        let dir = root.join("run");
        let out = vge(&["train", "--config", s(&config), "--out", s(&dir)]).output().expect("vge");
        assert!(out.status.success(), "reference run: {}", text(&out));
        dir
    })
}

fn policy(dir: &Path) -> Vec<u8> {
    std::fs::read(dir.join("policy.vgep")).expect("policy.vgep")
}

/// `vge train --resume DIR` to the end; the policy is the uninterrupted run's, and `vge plot`
/// reads the folder.
fn resume_to_the_reference_policy(dir: &Path, what: &str) {
    let out = vge(&["train", "--resume", s(dir)]).output().expect("vge");
    assert!(out.status.success(), "{what}: resume: {}", text(&out));
    assert!(
        policy(dir) == policy(reference()),
        "{what}: the resumed policy differs from the uninterrupted run's"
    );
    let png = dir.with_extension("png");
    let out = vge(&["plot", s(dir), "--out", s(&png)]).output().expect("vge plot");
    assert!(out.status.success(), "{what}: vge plot: {}", text(&out));
}

fn killed(out: &Output) -> bool {
    use std::os::unix::process::ExitStatusExt;
    out.status.signal() == Some(9) || out.status.code() == Some(137)
}

fn header_of(path: &Path) -> String {
    std::fs::read_to_string(path).expect("csv").lines().next().unwrap_or_default().to_owned()
}

#[test]
fn a_kill_at_each_write_of_metrics_csv_during_a_resume_leaves_a_folder_that_resumes_and_plots() {
    let root = common::temp_dir("crash-metrics");
    let config = config_file(&root);
    let dir = root.join("run");
    let metrics = dir.join("metrics.csv");
    // Killed at its 10th row (step 500): a checkpoint at 400, rows up to 450 past it.
    let out =
        train_under_strace(&config, &dir, &[], std::slice::from_ref(&metrics), "write:signal=KILL:when=10");
    assert!(killed(&out), "the run was not killed at its 10th row: {}", text(&out));
    let header = header_of(&reference().join("metrics.csv"));
    // Each resume killed at one system call on metrics.csv or its temporary: the rows past the
    // checkpoint are dropped by a rewrite (read, create, write, sync, rename), then the file is
    // opened for rows and a row written.
    let tmp = dir.join("metrics.csv.tmp");
    for (syscalls, when) in [
        ("openat", 1),
        ("openat", 2),
        ("write", 1),
        ("fsync", 1),
        ("rename,renameat,renameat2", 1),
        ("openat", 3),
        ("write", 2),
    ] {
        let inject = format!("{syscalls}:signal=KILL:when={when}");
        let out = train_under_strace(
            &config,
            &dir,
            &["--resume", s(&dir)],
            &[metrics.clone(), tmp.clone()],
            &inject,
        );
        assert!(killed(&out), "{inject}: not killed: {}", text(&out));
        assert_eq!(header_of(&metrics), header, "{inject}: metrics.csv lost its header");
    }
    resume_to_the_reference_policy(&dir, "after the kills");
    let rows = |d: &Path| {
        let text = std::fs::read_to_string(d.join("metrics.csv")).expect("metrics");
        text.lines().map(|l| l.split(',').next().unwrap_or_default().to_owned()).collect::<Vec<_>>()
    };
    assert_eq!(rows(&dir), rows(reference()), "the metrics rows' steps differ from the uninterrupted run's");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn a_kill_at_either_rename_of_a_checkpoint_swap_is_never_started_over_and_resumes() {
    let root = common::temp_dir("crash-swap");
    let config = config_file(&root);
    // The renames involving checkpoint/: the first save's checkpoint.tmp -> checkpoint (1),
    // then the final save's checkpoint -> checkpoint.old (2) and checkpoint.tmp -> checkpoint (3).
    for when in [2, 3] {
        let dir = root.join(format!("run-{when}"));
        let inject = format!("rename,renameat,renameat2:signal=KILL:when={when}");
        // strace matches a rename by its first path.
        let paths = [dir.join("checkpoint"), dir.join("checkpoint.tmp")];
        let out = train_under_strace(&config, &dir, &[], &paths, &inject);
        assert!(killed(&out), "{inject}: not killed: {}", text(&out));
        let alone = !dir.join("checkpoint").exists();
        assert_eq!(alone, when == 3, "between the renames only checkpoint.old is whole");
        // A new run there is refused, naming what it found, and the folder is left alone.
        let state = |d: &Path| {
            std::fs::read(vge_trainer::checkpoint::resume_dir(d).expect("ckpt").join("state.toml"))
        };
        let before = state(&dir).expect("state");
        let out = vge(&["train", "--config", s(&config), "--out", s(&dir)]).output().expect("vge");
        let err = text(&out);
        assert!(!out.status.success(), "{inject}: a new run started over the folder");
        let found = if alone { "checkpoint.old" } else { "checkpoint" };
        assert!(
            err.contains("already holds a run") && err.contains(found) && err.contains("--resume"),
            "{err}"
        );
        assert_eq!(state(&dir).expect("state"), before, "the refused run touched the checkpoint");
        resume_to_the_reference_policy(&dir, &inject);
    }
    let _ = std::fs::remove_dir_all(&root);
}

// ENOSPC in each writer gives a named error and a folder that resumes to the same policy (or,
// before the first checkpoint at 400, a folder emptied of run files that starts again). Three
// tests of the run's phases, so that they run side by side.

#[test]
fn enospc_before_the_first_checkpoint_gives_a_named_error_and_an_emptied_folder_that_starts_again() {
    enospc_in_each_writer(
        "crash-enospc-start",
        Left::NoCheckpoint,
        &[
            ("config.toml.tmp", 1),
            ("metrics.csv.tmp", 1),
            ("metrics.csv", 1),
            ("eval.csv", 1),
            ("snapshots/policy-400.vgep.tmp", 1),
            ("checkpoint.tmp/actor.ot", 1),
        ],
    );
}

#[test]
fn enospc_in_a_periodic_writer_gives_a_named_error_and_a_folder_that_resumes_to_the_same_policy() {
    enospc_in_each_writer(
        "crash-enospc-periodic",
        Left::Checkpoint,
        &[
            ("metrics.csv", 9),
            ("eval.csv", 2),
            ("snapshots/policy-800.vgep.tmp", 1),
            ("checkpoint.tmp/critic.ot", 2),
            ("checkpoint.tmp/target.ot", 2),
            ("checkpoint.tmp/optim.ot", 2),
            ("checkpoint.tmp/replay.bin", 2),
            ("checkpoint.tmp/state.toml", 2),
            ("checkpoint.tmp/manifest.json", 2),
        ],
    );
}

#[test]
fn enospc_in_a_final_writer_gives_a_named_error_and_a_folder_that_resumes_to_the_same_policy() {
    enospc_in_each_writer(
        "crash-enospc-final",
        Left::Checkpoint,
        &[
            ("policy-best.vgep.tmp", 1),
            ("best-eval.json.tmp", 1),
            ("policy.vgep.tmp", 1),
            ("final-eval.json.tmp", 1),
        ],
    );
}

/// What a failed write must leave: a checkpoint to resume from once the first one is saved,
/// before it a folder emptied of run files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Left {
    Checkpoint,
    NoCheckpoint,
}

/// Each case `(file, which write of it fails)` in a run folder of its own under `name`.
fn enospc_in_each_writer(name: &str, left: Left, cases: &[(&str, u32)]) {
    let root = common::temp_dir(name);
    let config = config_file(&root);
    for (k, &(file, when)) in cases.iter().enumerate() {
        let dir = root.join(format!("run-{k}"));
        let what = format!("ENOSPC at write {when} of {file}");
        let inject = format!("write:error=ENOSPC:when={when}");
        let out = train_under_strace(&config, &dir, &[], &[dir.join(file)], &inject);
        let err = text(&out);
        assert_eq!(out.status.code(), Some(1), "{what}: exit {:?} (not an abort): {err}", out.status);
        let named = file.trim_end_matches(".tmp");
        assert!(err.contains(named) && err.contains("No space left on device"), "{what}: {err}");
        let checkpoint = vge_trainer::checkpoint::resume_dir(&dir);
        assert_eq!(
            checkpoint.is_some(),
            left == Left::Checkpoint,
            "{what}: expected {left:?}, found {checkpoint:?}"
        );
        if let Some(ckpt) = checkpoint {
            vge_trainer::checkpoint::verify(&ckpt).unwrap_or_else(|e| panic!("{what}: {e}"));
            resume_to_the_reference_policy(&dir, &what);
        } else {
            let left: Vec<&str> =
                vge_trainer::train::RUN_FILES.iter().copied().filter(|f| dir.join(f).exists()).collect();
            assert!(left.is_empty(), "{what}: a run without a checkpoint left {left:?}");
            let out = vge(&["train", "--config", s(&config), "--out", s(&dir)]).output().expect("vge");
            assert!(out.status.success(), "{what}: starting again: {}", text(&out));
            assert!(policy(&dir) == policy(reference()), "{what}: the policy differs");
        }
    }
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn training_into_a_full_tmpfs_fails_with_a_named_error_and_leaves_a_resumable_checkpoint() {
    let root = common::temp_dir("crash-tmpfs");
    let config = config_file(&root);
    let mount = root.join("small");
    std::fs::create_dir_all(&mount).expect("dir");
    // Room for the first checkpoint, not for the second beside it.
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=640k", "tmpfs", s(&mount)])
        .output()
        .expect("mount runs");
    if !mounted.status.success() {
        // Mounting needs root (CAP_SYS_ADMIN); the strace test injects ENOSPC without it.
        eprintln!("skipped: cannot mount a tmpfs here: {}", text(&mounted));
        return;
    }
    let dir = mount.join("run");
    let out = vge(&["train", "--config", s(&config), "--out", s(&dir)]).output().expect("vge");
    let err = text(&out);
    let copy = root.join("copy");
    let copied = Command::new("cp").args(["-a", s(&dir), s(&copy)]).status().expect("cp");
    let _ = Command::new("umount").arg(&mount).status();
    assert_eq!(out.status.code(), Some(1), "exit {:?} (not an abort): {err}", out.status);
    assert!(err.contains("No space left on device") && err.contains(s(&dir)), "{err}");
    assert!(copied.success());
    let ckpt = vge_trainer::checkpoint::resume_dir(&copy).expect("the first checkpoint is there");
    vge_trainer::checkpoint::verify(&ckpt).expect("and whole");
    resume_to_the_reference_policy(&copy, "after a full tmpfs");
    let _ = std::fs::remove_dir_all(&root);
}

/// The pid in `DIR/vge.lock`, once a process wrote one.
fn lock_pid(dir: &Path) -> Option<u32> {
    std::fs::read_to_string(dir.join("vge.lock")).ok()?.trim().parse().ok()
}

#[test]
fn a_second_writer_is_refused_naming_the_holders_pid_and_a_dead_holders_lock_is_taken_over() {
    let root = common::temp_dir("crash-lock");
    let config = config_file(&root);
    let sweep = root.join("sweep");
    let dir = sweep.join("seed-0");
    // A long run (seed 0, as the sweep's seed-0 would be), checkpointing every 400 steps.
    let mut holder =
        vge(&["train", "--config", s(&config), "--out", s(&dir), "--seed", "0", "--steps", "1000000"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn vge");
    let deadline = Instant::now() + Duration::from_secs(300);
    while !(lock_pid(&dir) == Some(holder.id()) && vge_trainer::checkpoint::resume_dir(&dir).is_some()) {
        assert!(holder.try_wait().expect("wait").is_none(), "the holder ended early");
        assert!(Instant::now() < deadline, "no checkpoint after 300 s");
        std::thread::sleep(Duration::from_millis(20));
    }
    let pid = format!("pid {}", holder.id());
    for args in [
        vec!["train", "--resume", s(&dir)],
        vec!["train", "--config", s(&config), "--out", s(&dir)],
        vec!["sweep", "--config", s(&config), "--seeds", "0..1", "--out", s(&sweep)],
    ] {
        let out = vge(&args).output().expect("vge");
        let err = text(&out);
        assert!(!out.status.success(), "{args:?} ran beside the holder");
        assert!(err.contains(&pid) && err.contains("vge.lock"), "{args:?}: {err}");
    }
    holder.kill().expect("SIGKILL");
    let _ = holder.wait();
    assert!(lock_pid(&dir).is_some(), "the dead holder's pid stays in the file");
    // The kernel released the dead process's lock: the next writer takes it over.
    let step = vge_lab::sweep::checkpoint_step(&dir).expect("checkpoint step").to_string();
    let out = vge(&["train", "--resume", s(&dir), "--steps", &step]).output().expect("vge");
    assert!(out.status.success(), "taking over a dead holder's lock: {}", text(&out));
    let _ = std::fs::remove_dir_all(&root);
}
