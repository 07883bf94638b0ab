//! `vge-bridge`: the deployment side of vge.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Parser, Subcommand};
use vge_bridge::emulator::{JointControllerEmulator, serve};
use vge_bridge::transport::SocketCanTransport;

/// Runs exported vge policies against the simulator or a real hand over SocketCAN.
#[derive(Debug, Parser)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Emulate the hand's five joint-controller nodes on a CAN interface.
    ///
    /// Answers every joint command frame (id 0x100 + finger) with a joint position frame
    /// (id 0x180 + finger), moving each joint part of the way to its target. Use it to try
    /// the bridge without hardware: `ip link add dev vcan0 type vcan && ip link set up vcan0`
    /// (or scripts/canvm/run.sh on a kernel without CAN), then `vge-bridge emulate`.
    Emulate {
        /// CAN interface to serve on.
        #[arg(long, default_value = "vcan0")]
        iface: String,
        /// Stop after answering this many commands.
        #[arg(long, default_value_t = u64::MAX)]
        max_commands: u64,
        /// Stop after this many seconds without a frame.
        #[arg(long, default_value_t = 10.0)]
        idle_timeout_s: f64,
        /// Fraction of the position error each command removes, in [0, 1].
        #[arg(long, default_value_t = 0.2)]
        response: f32,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vge-bridge: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Emulate { iface, max_commands, idle_timeout_s, response } => {
            anyhow::ensure!(
                idle_timeout_s.is_finite() && idle_timeout_s > 0.0,
                "--idle-timeout-s must be a positive number of seconds, got {idle_timeout_s}"
            );
            anyhow::ensure!((0.0..=1.0).contains(&response), "--response must be in [0, 1], got {response}");
            let mut emulator = JointControllerEmulator::new(response);
            let mut transport =
                SocketCanTransport::open(&iface).with_context(|| format!("opening CAN interface {iface}"))?;
            let stats =
                serve(&mut transport, &mut emulator, max_commands, Duration::from_secs_f64(idle_timeout_s))
                    .with_context(|| format!("emulating joint controllers on {iface}"))?;
            eprintln!(
                "vge-bridge: answered {} commands, ignored {} other frames",
                stats.commands, stats.ignored
            );
            Ok(())
        }
    }
}
