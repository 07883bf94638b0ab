//! `vge-bridge`: the deployment side of vge. Runs an exported policy file at a fixed control
//! rate against the simulator or a hand's joint controllers over SocketCAN, and emulates
//! hands on a CAN interface. Built without the `sim` feature it drives real hands only:
//! asking it for the simulator is an error that says so.
//!
//! This file parses the command line and dispatches; each subcommand is a module of
//! `commands`, the Allegro Hand's paths in `commands::allegro`.

use std::fmt;
use std::io::{self, Write};
use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

/// A line to stdout. A reader that has gone (EPIPE: `vge-bridge ... | head -1`) ends the
/// output, not the command, which runs on and exits with its own status (a safety halt's
/// included); any other write error (a full disk) is an error.
macro_rules! out {
    ($($arg:tt)*) => { $crate::stdout_line(format_args!($($arg)*))? };
}

/// A line to stderr. Diagnostics that cannot be written (stderr closed) are dropped: there is
/// nowhere left to report that, and the exit status still tells.
macro_rules! note {
    ($($arg:tt)*) => {{ let _ = writeln!(std::io::stderr(), $($arg)*); }};
}

mod commands;

use commands::{bench, emulate, run};

fn stdout_line(line: fmt::Arguments<'_>) -> anyhow::Result<()> {
    match writeln!(io::stdout(), "{line}") {
        Err(e) if e.kind() != io::ErrorKind::BrokenPipe => {
            Err(anyhow::Error::new(e).context("writing to stdout"))
        }
        _ => Ok(()),
    }
}

/// Runs exported vge policies against the simulator or a real hand over SocketCAN.
///
/// Two hands: vge's own 15-joint hand (`--hand vge15`, the default; its protocol in
/// docs/can-protocol.md) and the Allegro Hand v4 over its own CAN protocol (`--hand allegro`;
/// docs/allegro-protocol.md, docs/allegro-bridge.md). The two protocols cannot share a bus.
/// On a kernel without CAN, run any of these inside a guest that has vcan0 with
/// `scripts/canvm/run.sh target/release/vge-bridge ...`.
///
/// A closed stdout or stderr (`vge-bridge ... | head -1`) ends the output, not the command:
/// it runs on and exits with its own status.
#[derive(Debug, Parser)]
#[command(version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    Run(run::RunArgs),
    Emulate(emulate::EmulateArgs),
    Bench(bench::BenchArgs),
}

fn main() -> ExitCode {
    // `run --help` lists the joint limits of the hand, read from the one hand description.
    let mut command = Cli::command().mut_subcommand("run", |c| c.after_long_help(run::joint_limits_help()));
    if !cfg!(feature = "sim") {
        command = command.after_help(
            "This vge-bridge was built without the simulator (cargo feature `sim`): it drives real hands \
             over CAN only and refuses `run --backend sim` and `emulate --model sim`.",
        );
    }
    let cli = match Cli::from_arg_matches(&command.get_matches()) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    let result = match cli.command {
        Command::Run(args) => run::run(args),
        Command::Emulate(args) => emulate::run(args),
        Command::Bench(args) => bench::run(args),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            note!("vge-bridge: {e:#}");
            ExitCode::FAILURE
        }
    }
}
