//! `vge` treats a closed stdout or stderr as the end of its output: no panic, exit status 0,
//! as `vge inspect policies/cube.vgep | head -1` needs under `set -o pipefail`.
//!
//! Each printing subcommand runs with its stdout (or stderr) a pipe whose reader was closed
//! before it started, so its first write meets EPIPE every time; the same command with the
//! pipe open shows it does print there (a command that printed nothing would pass vacuously).
//! The episode counts are tiny: this is about the output, not the work. The commands that
//! train or score are the exception: they drop their output and finish their work.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const POLICY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");
/// Runs per command with the reader gone: a race between the reader's exit and the writes
/// cannot hide (the reader is closed before the start), and runs that spawn threads vary.
const TRIES: usize = 2;

fn vge() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vge"))
}

#[path = "../../tests/support/closed_pipe.rs"]
mod pipes;
use pipes::Stream;

/// Runs `vge args` with `closed` a pipe without a reader ([`pipes::run_closed`]).
fn run_closed(args: &[String], closed: Stream) -> (Option<i32>, String) {
    let mut cmd = vge();
    cmd.args(args);
    pipes::run_closed(cmd, closed)
}

/// `vge args` with both streams open: its status and (stdout, stderr).
fn run_open(args: &[String]) -> (Option<i32>, String, String) {
    let out = vge().args(args).stdin(Stdio::null()).output().expect("vge runs");
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    (out.status.code(), text(&out.stdout), text(&out.stderr))
}

/// Asserts that `args` prints on `closed` when it is open, and exits 0 without a panic when
/// that stream's reader is gone.
fn ends_quietly(args: &[&str], closed: Stream) {
    let args: Vec<String> = args.iter().map(|s| (*s).to_owned()).collect();
    let (code, stdout, stderr) = run_open(&args);
    assert_eq!(code, Some(0), "vge {args:?} fails with its output open: {stderr}");
    let printed = if closed == Stream::Stdout { &stdout } else { &stderr };
    assert!(!printed.is_empty(), "vge {args:?} prints nothing on {closed:?}: the test would be vacuous");
    for _ in 0..TRIES {
        closed_ends_quietly(&args, closed);
    }
}

/// One run of `args` with `closed`'s reader gone: exit 0, no panic.
fn closed_ends_quietly(args: &[String], closed: Stream) {
    let (code, other) = run_closed(args, closed);
    assert!(!other.contains("panicked"), "vge {args:?} with {closed:?} closed panicked: {other}");
    assert_eq!(code, Some(0), "vge {args:?} with {closed:?} closed: {other}");
}

struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("vge-closed-pipe-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        Self(dir)
    }
    fn path(&self, file: &str) -> String {
        self.0.join(file).to_str().expect("utf-8 temp path").to_owned()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The subcommands `vge help` lists (and, for `bench`, its own), so that a new one is covered
/// at least for its --help.
fn subcommands(prefix: &[&str]) -> Vec<String> {
    let mut args: Vec<&str> = prefix.to_vec();
    args.push("--help");
    let out = vge().args(&args).output().expect("vge --help");
    let help = String::from_utf8_lossy(&out.stdout).into_owned();
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        // A command's line; a wrapped description would be indented further.
        .filter(|l| !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_owned)
        .collect()
}

#[test]
fn help_and_version_of_every_subcommand_end_quietly_on_a_closed_stdout() {
    ends_quietly(&["--help"], Stream::Stdout);
    ends_quietly(&["--version"], Stream::Stdout);
    let top = subcommands(&[]);
    assert!(top.iter().any(|c| c == "inspect") && top.iter().any(|c| c == "bench"), "{top:?}");
    // Help is printed by clap before anything runs (and `subcommands` read it): one closed run
    // each.
    for command in &top {
        closed_ends_quietly(&[command.clone(), "--help".to_owned()], Stream::Stdout);
    }
    let bench = subcommands(&["bench"]);
    assert!(bench.iter().any(|c| c == "runtime"), "{bench:?}");
    for command in &bench {
        closed_ends_quietly(&["bench".to_owned(), command.clone(), "--help".to_owned()], Stream::Stdout);
    }
}

#[test]
fn inspect_piped_into_head_succeeds_under_pipefail() {
    ends_quietly(&["inspect", POLICY], Stream::Stdout);
    // The demo's own pipeline, as a shell runs it: `head` exits after its line, whenever the
    // writer gets to its next one.
    let script = format!("set -o pipefail; '{}' inspect '{POLICY}' | head -1", env!("CARGO_BIN_EXE_vge"));
    for _ in 0..10 {
        let out = Command::new("bash").args(["-c", &script]).output().expect("bash runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success() && !stderr.contains("panicked"), "{:?}: {stderr}", out.status);
        assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 1);
    }
}

#[test]
fn reports_of_eval_controller_and_export_end_quietly_on_a_closed_stdout() {
    let tiny_eval = ["eval", "--policy", POLICY, "--episodes", "1", "--episode-s", "0.1"];
    ends_quietly(&tiny_eval, Stream::Stdout);
    ends_quietly(&[&tiny_eval[..], &["--json"]].concat(), Stream::Stdout);
    let tiny_controller = ["controller", "--kind", "fg", "--episodes", "1", "--episode-s", "0.1"];
    ends_quietly(&tiny_controller, Stream::Stdout);
    ends_quietly(&[&tiny_controller[..], &["--json"]].concat(), Stream::Stdout);
    let dir = TempDir::new("export");
    ends_quietly(&["export", "--init", "--out", &dir.path("init.vgep")], Stream::Stdout);
}

#[test]
fn benches_end_quietly_on_a_closed_stdout() {
    for args in [
        &["bench", "runtime", "--iters", "10"][..],
        &["bench", "runtime", "--iters", "10", "--json"],
        &["bench", "sim", "--steps", "5", "--worlds", "1", "--threads", "1"],
        &["bench", "update", "--updates", "1", "--batch", "8", "--json"],
    ] {
        ends_quietly(args, Stream::Stdout);
    }
}

#[test]
fn notes_on_a_closed_stderr_end_quietly_and_an_error_still_fails() {
    let dir = TempDir::new("stderr");
    // `--plot` names the gait diagram it wrote on stderr.
    let png = dir.path("gait.png");
    ends_quietly(
        &["eval", "--policy", POLICY, "--episodes", "1", "--episode-s", "0.1", "--plot", &png],
        Stream::Stderr,
    );
    assert!(Path::new(&png).exists(), "the diagram was written before the note");
    // An error whose message cannot be written is still an error.
    let missing = dir.path("missing.vgep");
    for _ in 0..TRIES {
        let (code, _) = run_closed(&["inspect".to_owned(), missing.clone()], Stream::Stderr);
        assert_eq!(code, Some(1), "a failure with stderr closed still exits 1");
    }
}

/// `configs/cube-fg-vge.toml` made a run of seconds (`common::TINY`), `steps` long.
fn tiny_train_args(out: &str, steps: u64) -> Vec<String> {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/cube-fg-vge.toml");
    let mut args: Vec<String> = ["train", "--config", config.to_str().expect("utf-8"), "--out", out]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
    args.extend(["--steps".to_owned(), steps.to_string()]);
    args.extend(common::tiny_args());
    args.extend(["--set".to_owned(), "sac.threads=1".to_owned()]);
    args
}

fn finished(run: &Path) -> bool {
    vge_lab::sweep::check_finished(run).is_ok()
}

/// Training outlives its output: with the reader of its output gone (`| head -1`, or closed
/// before it started) `vge train` prints nothing more, trains to its end and writes its
/// policy, and exits 0; so do `vge sweep` for every seed and `vge score`.
#[test]
fn train_sweep_and_score_finish_their_runs_when_their_reader_is_gone() {
    let dir = TempDir::new("train");
    let vge_bin = env!("CARGO_BIN_EXE_vge");
    // As a user types it: the first line, then head exits and the pipe has no reader.
    let run = dir.path("head");
    let quoted: Vec<String> = tiny_train_args(&run, 300).iter().map(|a| format!("'{a}'")).collect();
    let script = format!("set -o pipefail; '{vge_bin}' {} 2>&1 | head -1", quoted.join(" "));
    let out = Command::new("bash").args(["-c", &script]).output().expect("bash runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{:?}: {stdout}{}", out.status, String::from_utf8_lossy(&out.stderr));
    assert_eq!(stdout.lines().count(), 1, "{stdout}");
    assert!(finished(Path::new(&run)), "`vge train | head -1` did not finish its run");

    for closed in [Stream::Stdout, Stream::Stderr] {
        let run = dir.path(&format!("closed-{closed:?}"));
        let (code, other) = run_closed(&tiny_train_args(&run, 200), closed);
        assert_eq!(code, Some(0), "train with {closed:?} closed: {other}");
        assert!(!other.contains("panicked"), "{other}");
        assert!(finished(Path::new(&run)), "train with {closed:?} closed did not finish its run");
    }

    // Seeds one after the other in this process, as `vge sweep ... | head -1` once stopped at
    // the first seed: both finish.
    let sweep = dir.path("sweep");
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/cube-fg-vge.toml");
    let mut args: Vec<String> = ["sweep", "--config", config.to_str().expect("utf-8"), "--seeds", "0..2"]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
    args.extend(["--out".to_owned(), sweep.clone(), "--steps".to_owned(), "200".to_owned()]);
    args.extend(common::tiny_args());
    let (code, other) = run_closed(&args, Stream::Stdout);
    assert_eq!(code, Some(0), "sweep with stdout closed: {other}");
    for seed in 0..2 {
        assert!(finished(&Path::new(&sweep).join(format!("seed-{seed}"))), "seed {seed} did not finish");
    }

    // Scoring a finished run writes its score.json with nobody reading.
    let head_run = Path::new(&run);
    let score = ["score".to_owned(), run.clone(), "--episodes".to_owned(), "2".to_owned()];
    let (code, other) = run_closed(&score, Stream::Stdout);
    assert_eq!(code, Some(0), "score with stdout closed: {other}");
    assert!(head_run.join("score.json").exists(), "vge score wrote no score.json");
}
