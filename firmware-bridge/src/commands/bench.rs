//! `vge-bridge bench`: the control loop's own timing on this host.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::Duration;

use clap::Args;
use serde_json::json;
use vge_bridge::control_loop::{self, PolicyRunner};
use vge_bridge::emulator::{JointControllerEmulator, ServeLimits, serve};
use vge_bridge::hand_file;
use vge_bridge::policy_runner::{RuntimePolicy, storage_for};
use vge_bridge::transport::InProcessTransport;
use vge_sim::NUM_JOINTS;
use vge_sim::observation::OBS_DIM;

use super::run::{loop_config, print_report, read_policy};
use super::{LoopArgs, RealtimeArgs, stop_on_signal};

/// Loop timing on this host: the control loop against emulated nodes over the in-process
/// transport (no CAN, no simulator), so only the loop's own timing shows.
///
/// A measurement: it exits 0 however the loop stopped (the report names why).
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Policy file to run each period (default: hold, i.e. zero change).
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
    fn act(&mut self, _: &[f32; OBS_DIM]) -> Result<[f32; NUM_JOINTS], Self::Error> {
        Ok([0.0; NUM_JOINTS])
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
        max_seq_lag: control_loop::DEFAULT_MAX_SEQ_LAG,
        json,
        realtime,
    };
    anyhow::ensure!(duration > 0.0, "--duration must be positive");
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
        serve(&mut end, &mut JointControllerEmulator::new(0.5), limits, &nodes_flag)
    });
    let mut bridge_end = bridge_end;
    realtime.apply();
    let (report, cfg, name) = match &policy {
        Some(path) => {
            let bytes = read_policy(path)?;
            let mut storage = storage_for(&bytes)?;
            let mut runner = RuntimePolicy::load(&bytes, &mut storage)?;
            let cfg = loop_config(&loop_args, rate as f32, hand_file::default_joint_limits())?;
            (control_loop::run(&mut bridge_end, &mut runner, &cfg, &stop)?, cfg, path.display().to_string())
        }
        None => {
            let cfg = loop_config(&loop_args, rate as f32, hand_file::default_joint_limits())?;
            (control_loop::run(&mut bridge_end, &mut Hold, &cfg, &stop)?, cfg, "hold".to_owned())
        }
    };
    nodes_stop.store(true, Ordering::Relaxed);
    drop(bridge_end);
    let _ = nodes.join();
    print_report(
        json,
        &[("bench", json!("loop")), ("transport", json!("in-process")), ("policy", json!(name))],
        &cfg,
        &report,
        None,
    )?;
    Ok(ExitCode::SUCCESS)
}
