//! `vge`: train, evaluate, export and inspect finger-gaiting policies. This file parses the
//! command line and dispatches; each subcommand is a module of `commands`.

#[macro_use]
mod closed_output;
mod commands;
mod stop;

use std::io::Write as _;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use commands::{
    bench, compare, config, controller, eval, export, facts, hand, import, inspect, plot, queue, robustness,
    score, screen, ship, sweep, table1, time_to_gait, train,
};

/// Value-guided exploration for dexterous finger-gaiting: an off-policy learner (TD3, or SAC)
/// whose behaviour policy follows sub-skill controllers where the critic values them, on a
/// simulated hand read from its MJCF file.
#[derive(Debug, Parser)]
#[command(version, about, long_about = None)]
#[command(after_help = "A closed stdout or stderr (`vge ... | head -1`) ends vge quietly with status 0, \
but for `vge train`, `vge sweep`, `vge queue`, `vge table1` and `vge score`, which drop the lines and go on to the end of their \
runs. Exit status: 0 done, 1 an error, 128 + a signal's number (130 SIGINT, 143 SIGTERM, 129 SIGHUP) \
when a signal stopped training with its checkpoint saved.")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    Train(train::TrainArgs),
    Sweep(sweep::SweepArgs),
    Queue(queue::QueueArgs),
    Table1(table1::Table1Args),
    Plot(plot::PlotArgs),
    Score(score::ScoreArgs),
    Compare(compare::CompareArgs),
    Facts(facts::FactsArgs),
    TimeToGait(time_to_gait::TimeToGaitArgs),
    Config(config::ConfigArgs),
    Eval(eval::EvalArgs),
    Robustness(robustness::RobustnessArgs),
    Screen(screen::ScreenArgs),
    Ship(ship::ShipArgs),
    Export(export::ExportArgs),
    Import(import::ImportArgs),
    Inspect(inspect::InspectArgs),
    Hand(hand::HandArgs),
    Controller(controller::ControllerArgs),
    /// Measure vge's hot paths on this machine.
    #[command(subcommand)]
    Bench(bench::Bench),
}

/// MKL's vendor check, answered by `vge` so that MKL runs its AVX-512 kernels on AMD CPUs
/// that have them (`vge_trainer::mkl` says why and what it measured). build.rs exports it
/// from the executable, where it takes precedence over libtorch's own copy.
#[cfg(feature = "train")]
#[unsafe(no_mangle)]
#[allow(unsafe_code)]
pub extern "C" fn mkl_serv_intel_cpu_true() -> std::ffi::c_int {
    vge_trainer::mkl::intel_cpu_answer()
}

fn main() -> ExitCode {
    closed_output::end_quietly_when_closed();
    let command = Cli::parse().command;
    if matches!(
        command,
        Command::Train(_) | Command::Sweep(_) | Command::Queue(_) | Command::Table1(_) | Command::Score(_)
    ) {
        // Runs that take hours finish whether or not anyone still reads their output.
        closed_output::keep_going();
    }
    // Before libtorch allocates anything; a refusal only costs speed (vge_trainer::heap).
    #[cfg(feature = "train")]
    if !vge_trainer::heap::keep_freed_memory() {
        errln!("vge: note: glibc heap settings not applied; updates may run slower");
    }
    let result = match command {
        Command::Train(args) => train::run(args),
        Command::Sweep(args) => sweep::run(args),
        Command::Queue(args) => queue::run(args),
        Command::Table1(args) => table1::run(args),
        Command::Plot(args) => plot::run(args),
        Command::Score(args) => score::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Facts(args) => facts::run(args),
        Command::TimeToGait(args) => time_to_gait::run(args),
        Command::Config(args) => config::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Robustness(args) => robustness::run(args),
        Command::Screen(args) => screen::run(args),
        Command::Ship(args) => ship::run(args),
        Command::Export(args) => export::run(args),
        Command::Import(args) => import::run(args),
        Command::Inspect(args) => inspect::run(args),
        Command::Hand(args) => hand::run(args),
        Command::Controller(args) => controller::run(args),
        Command::Bench(bench) => bench::run(bench),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if let Some(stopped) = e.downcast_ref::<stop::Stopped>() {
                // The command said where it stopped and how to go on.
                return ExitCode::from(stopped.exit_code());
            }
            // Not eprintln!: with stderr closed the failure must still exit 1, not 0.
            let _ = writeln!(std::io::stderr(), "vge: {}", error_text(&e));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes, `: `-joined as anyhow's `{:#}`, without the repeats: the
/// libraries' errors name their source in their own message (`PATH: No such file ...`), so a
/// cause that the message before it already ends with is left out.
fn error_text(e: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if !parts.last().is_some_and(|previous| previous.ends_with(&text)) {
            parts.push(text);
        }
    }
    parts.join(": ")
}
