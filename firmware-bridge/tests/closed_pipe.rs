//! `vge-bridge` treats a closed stdout or stderr as the end of its output, not of the command:
//! no panic, and the exit status the run would have had (0 here).
//!
//! Each printing subcommand runs with its stdout (or stderr) a pipe whose reader was closed
//! before it started, so its first write meets EPIPE every time; the same command with the
//! pipe open shows it does print there. The runs are short: this is about the output. (`emulate`
//! needs a CAN interface: the HIL suite, tests/tests/hil.rs, covers it.)

use std::process::{Command, Stdio};

const POLICY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");
/// Runs per command with the reader gone (the loop's threads vary from run to run).
const TRIES: usize = 3;

fn bridge() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vge-bridge"))
}

#[path = "../../tests/support/closed_pipe.rs"]
mod pipes;
use pipes::Stream;

/// Runs `vge-bridge args` with `closed` a pipe without a reader ([`pipes::run_closed`]).
fn run_closed(args: &[&str], closed: Stream) -> (Option<i32>, String) {
    let mut cmd = bridge();
    cmd.args(args);
    pipes::run_closed(cmd, closed)
}

/// Asserts that `args` prints on `closed` when it is open, and exits 0 without a panic when
/// that stream's reader is gone; returns what the other stream got in the last run.
fn ends_quietly(args: &[&str], closed: Stream) -> String {
    let out = bridge().args(args).stdin(Stdio::null()).output().expect("vge-bridge runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "vge-bridge {args:?} fails with its output open: {stderr}");
    let printed = if closed == Stream::Stdout { &out.stdout } else { &out.stderr };
    assert!(
        !printed.is_empty(),
        "vge-bridge {args:?} prints nothing on {closed:?}: the test would be vacuous"
    );
    let mut other = String::new();
    for _ in 0..TRIES {
        let (code, got) = run_closed(args, closed);
        assert!(!got.contains("panicked"), "vge-bridge {args:?} with {closed:?} closed panicked: {got}");
        assert_eq!(code, Some(0), "vge-bridge {args:?} with {closed:?} closed: {got}");
        other = got;
    }
    other
}

#[test]
fn help_and_version_end_quietly_on_a_closed_stdout() {
    ends_quietly(&["--help"], Stream::Stdout);
    ends_quietly(&["--version"], Stream::Stdout);
    let help = bridge().arg("--help").output().expect("vge-bridge --help");
    let help = String::from_utf8_lossy(&help.stdout).into_owned();
    let commands: Vec<&str> = help
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter(|l| !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .collect();
    assert_eq!(commands, ["run", "emulate", "bench"], "{help}");
    for command in commands {
        ends_quietly(&[command, "--help"], Stream::Stdout);
    }
}

#[test]
fn run_and_bench_reports_end_quietly_on_a_closed_stdout() {
    let run = ["run", "--policy", POLICY, "--backend", "sim", "--duration", "0.3"];
    ends_quietly(&run, Stream::Stdout);
    ends_quietly(&[&run[..], &["--json"]].concat(), Stream::Stdout);
    let bench = ["bench", "--rate", "200", "--duration", "0.2"];
    ends_quietly(&bench, Stream::Stdout);
    ends_quietly(&[&bench[..], &["--json"]].concat(), Stream::Stdout);
}

#[test]
fn a_closed_stderr_ends_the_notes_and_the_run_goes_on() {
    // Off the policy's 20 Hz, the bridge notes that on stderr before it runs.
    let run = ["run", "--policy", POLICY, "--backend", "sim", "--duration", "0.3", "--rate", "25"];
    let stdout = ends_quietly(&run, Stream::Stderr);
    assert!(stdout.starts_with("stopped: duration"), "the report still comes: {stdout}");
    // An error whose message cannot be written is still an error.
    for _ in 0..TRIES {
        let (code, _) = run_closed(&["run", "--policy", "/nonexistent/policy.vgep"], Stream::Stderr);
        assert_eq!(code, Some(1), "a failure with stderr closed still exits 1");
    }
}
