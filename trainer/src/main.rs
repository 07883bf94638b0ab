//! `vge`: train, evaluate, export and inspect finger-gaiting policies.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use vge_trainer::bench_update;

/// Value-guided exploration for dexterous finger-gaiting: SAC whose behaviour policy follows
/// sub-skill controllers where the critic values them, on a simulated 15-DOF hand.
#[derive(Debug, Parser)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Measure vge's hot paths on this machine.
    #[command(subcommand)]
    Bench(Bench),
}

#[derive(Debug, Subcommand)]
enum Bench {
    /// Full SAC updates per second: batch 256, 256x256 actor and twin critics, obs 65,
    /// action 15; also the achieved GFLOP/s and this CPU's matmul GFLOP/s for comparison.
    Update {
        /// Print one JSON line instead of a table.
        #[arg(long)]
        json: bool,
        /// Timed updates (after 20 warm-up updates).
        #[arg(long, default_value_t = 300)]
        updates: usize,
        /// Minibatch size.
        #[arg(long, default_value_t = 256)]
        batch: i64,
        /// Seed of the network initialisation and random batches.
        #[arg(long, default_value_t = 0)]
        seed: i64,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vge: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Bench(Bench::Update { json, updates, batch, seed }) => {
            anyhow::ensure!(updates > 0, "--updates must be at least 1");
            anyhow::ensure!(batch > 0, "--batch must be at least 1");
            let r = bench_update::run(batch, 20, updates, seed)?;
            if json {
                println!(
                    "{{\"bench\":\"update\",\"updates_per_s\":{:.1},\"gflops\":{:.2},\"matmul_gflops\":{:.2},\"ratio_to_matmul\":{:.3},\"batch\":{},\"updates\":{},\"threads\":{}}}",
                    r.updates_per_s,
                    r.gflops,
                    r.matmul_gflops,
                    r.gflops / r.matmul_gflops,
                    r.batch,
                    r.updates,
                    r.threads
                );
            } else {
                println!("SAC update, batch {}, {} threads, {} updates", r.batch, r.threads, r.updates);
                println!("  updates/s        {:>8.1}", r.updates_per_s);
                println!("  achieved GFLOP/s {:>8.2}", r.gflops);
                println!("  matmul GFLOP/s   {:>8.2}  (1024^3 f32 matmul, same run)", r.matmul_gflops);
            }
            Ok(())
        }
    }
}
