//! `vge-bridge bench`: the control loop's own timing on this host.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use serde_json::json;
use vge_bridge::control_loop::{self, PolicyRunner};
use vge_bridge::emulator::{JointControllerEmulator, ServeLimits, serve};
use vge_bridge::policy_runner::{RuntimePolicy, storage_for};
use vge_bridge::protocol_hand::{self, ProtocolHand};
use vge_bridge::transport::InProcessTransport;

use super::run::{loop_config, print_report, read_policy};
use super::{LoopArgs, RealtimeArgs, stop_on_signal};

/// Loop timing on this host: the control loop against vge15's emulated nodes over the
/// in-process transport (no CAN, no simulator), so only the loop's own timing shows.
///
/// A measurement: it exits 0 however the loop stopped (the report names why).
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Policy file to run each period, a vge15 policy (default: hold, i.e. zero change).
    #[arg(long)]
    policy: Option<PathBuf>,
    /// Control rate in Hz.
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// Seconds to run.
    #[arg(long, default_value_t = 60.0)]
    duration: f64,
    /// Print one JSON line of statistics instead of a summary.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    realtime: RealtimeArgs,
}

/// The bench's default policy: no change.
struct Hold;

impl PolicyRunner for Hold {
    type Error = std::convert::Infallible;
    fn act(&mut self, _: &[f32], action: &mut [f32]) -> Result<(), Self::Error> {
        action.fill(0.0);
        Ok(())
    }
}

/// `vge-bridge bench`.
pub fn run(args: BenchArgs) -> anyhow::Result<ExitCode> {
    let BenchArgs { policy, rate, duration, json, realtime } = args;
    let loop_args = LoopArgs {
        rate: Some(rate),
        duration,
        steps: None,
        max_delta_rad: 0.05,
        watchdog_periods: Some(50),
        heartbeat_timeout_s: 0.5,
        startup_timeout_s: None,
        max_seq_lag: control_loop::DEFAULT_MAX_SEQ_LAG,
        json,
        realtime,
    };
    anyhow::ensure!(duration > 0.0, "--duration must be positive");
    let description = protocol_hand::load("vge15").context("vge15's description")?;
    let hand = ProtocolHand::of(&description)?;
    let nodes = hand.nodes;
    let stop = stop_on_signal()?;
    let (bridge_end, nodes_end) = InProcessTransport::pair();
    let nodes_stop = Arc::new(AtomicBool::new(false));
    let nodes_flag = nodes_stop.clone();
    let nodes = thread::spawn(move || {
        let mut end = nodes_end;
        let limits = ServeLimits {
            max_commands: u64::MAX,
            idle_timeout: Duration::from_secs(1),
            command_timeout: Duration::from_secs(1),
            restart: None,
        };
        serve(&mut end, &mut JointControllerEmulator::new(nodes, 0.5), limits, &nodes_flag)
    });
    let mut bridge_end = bridge_end;
    realtime.apply();
    let (report, cfg, name) = match &policy {
        Some(path) => {
            let bytes = read_policy(path)?;
            let loading = || format!("loading {}", path.display());
            let (feed, mut storage) = storage_for(&bytes, &description, true).with_context(loading)?;
            let mut runner = RuntimePolicy::load(&bytes, &mut storage).with_context(loading)?;
            let mut cfg = loop_config(&loop_args, rate as f32, hand)?;
            cfg.observation = feed.set;
            (control_loop::run(&mut bridge_end, &mut runner, &cfg, &stop)?, cfg, path.display().to_string())
        }
        None => {
            let cfg = loop_config(&loop_args, rate as f32, hand)?;
            (control_loop::run(&mut bridge_end, &mut Hold, &cfg, &stop)?, cfg, "hold".to_owned())
        }
    };
    nodes_stop.store(true, Ordering::Relaxed);
    drop(bridge_end);
    let _ = nodes.join();
    print_report(
        json,
        &[("bench", json!("loop")), ("transport", json!("in-process")), ("policy", json!(name))],
        cfg.rate_hz,
        &report,
        None,
    )?;
    Ok(ExitCode::SUCCESS)
}
