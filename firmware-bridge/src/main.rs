//! `vge-bridge`: the deployment side of vge. Runs an exported policy file at a fixed control
//! rate against the simulator or a hand's joint controllers over SocketCAN. Built without the
//! `sim` feature it drives real hands only: asking it for the simulator is an error that says
//! so.

use std::fmt;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand, ValueEnum};
use serde_json::{Value, json};
use vge_bridge::control_loop::{self, LoopConfig, LoopReport, PolicyRunner, StopReason};
use vge_bridge::emulator::{JointControllerEmulator, ServeLimits, serve};
use vge_bridge::hand_file::{self, JointLimits};
use vge_bridge::node_supervisor::RestartPlan;
use vge_bridge::policy_runner::{RuntimePolicy, storage_for};
use vge_bridge::protocol::FingerId;
use vge_bridge::report::{SimHandSummary, json_line};
#[cfg(feature = "sim")]
use vge_bridge::sim_hand::{self, SimHand};
use vge_bridge::transport::{FdSocketCanTransport, InProcessTransport, Role, SocketCanTransport, Transport};
use vge_runtime::AlignedBytes;
use vge_sim::NUM_JOINTS;
use vge_sim::action::DEFAULT_MAX_ACTION_RAD;
use vge_sim::observation::OBS_DIM;
#[cfg(feature = "sim")]
use vge_sim::{EnvConfig, ObjectShape};

/// What `--object` parses into. Without the simulator the flag is still accepted, so that a
/// command line meant for it is refused by [`no_sim`] with the reason, not as a stray flag.
#[cfg(feature = "sim")]
type ObjectArg = ObjectShape;
#[cfg(not(feature = "sim"))]
type ObjectArg = String;

/// The simulated hand's episode, for `run --backend sim` and `emulate --model sim`.
#[derive(Debug, Args)]
struct SimHandArgs {
    /// Object in the simulated hand (`run --backend sim`, `emulate --model sim`): cube,
    /// sphere, cylinder, dodecahedron, icosahedron or hexagonal-prism.
    #[arg(long, default_value = "cube")]
    object: ObjectArg,
    /// Seed of the simulated hand's episode.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// Exit status of `emulate` when a node faulted (e.g. the bridge stopped sending commands
/// while the fingers were enabled): the summary is printed, and scripts see the fault.
const EXIT_NODE_FAULT: u8 = 3;

/// A line to stdout. A reader that has gone (EPIPE: `vge-bridge ... | head -1`) ends the
/// output, not the command, which runs on and exits with its own status (a safety halt's
/// included); any other write error (a full disk) is an error.
macro_rules! out {
    ($($arg:tt)*) => { stdout_line(format_args!($($arg)*))? };
}

/// A line to stderr. Diagnostics that cannot be written (stderr closed) are dropped: there is
/// nowhere left to report that, and the exit status still tells.
macro_rules! note {
    ($($arg:tt)*) => {{ let _ = writeln!(io::stderr(), $($arg)*); }};
}

fn stdout_line(line: fmt::Arguments<'_>) -> anyhow::Result<()> {
    match writeln!(io::stdout(), "{line}") {
        Err(e) if e.kind() != io::ErrorKind::BrokenPipe => Err(e).context("writing to stdout"),
        _ => Ok(()),
    }
}

/// Runs exported vge policies against the simulator or a real hand over SocketCAN.
///
/// The hand protocol (frames, units, bus load) is in docs/can-protocol.md. On a kernel
/// without CAN, run any of these inside a guest that has vcan0 with
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

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Backend {
    /// The simulated hand, in lockstep over the protocol (in-process).
    Sim,
    /// Joint controllers on a SocketCAN interface (`--iface`).
    Can,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum NodeModel {
    /// The rapier simulation of the hand and object.
    Sim,
    /// Joints that move a fixed fraction towards their targets per command; no object.
    Lag,
}

#[derive(Debug, Args)]
struct LoopArgs {
    /// Control rate in Hz (default: the rate the policy was trained at).
    #[arg(long)]
    rate: Option<f64>,
    /// Seconds to run; 0 runs until Ctrl-C.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Stop after this many control steps (stop reason `steps`), or at --duration if that
    /// comes first: a run of a fixed length whatever the host's speed.
    #[arg(long)]
    steps: Option<u64>,
    /// Largest joint-target change per step (rad), enforced whatever the policy says.
    #[arg(long, default_value_t = DEFAULT_MAX_ACTION_RAD)]
    max_delta_rad: f32,
    /// Periods without fresh joint state before the watchdog holds and stops; any other
    /// problem that persists this many periods (stale or implausible state, a failing policy,
    /// an overloaded bus, unsent commands) halts too.
    #[arg(long, default_value_t = 5)]
    watchdog_periods: u32,
    /// Seconds without a node's heartbeat before the loop halts (heartbeat_lost).
    #[arg(long, default_value_t = 0.5)]
    heartbeat_timeout_s: f64,
    /// Commands a node's frame may lag behind the latest one (its seq) and still count as the
    /// finger's state; an older frame is dropped and counted as stale (1-127). The default 3
    /// is 0.15 s at 20 Hz; a slow link to the nodes may need more.
    #[arg(long, default_value_t = control_loop::DEFAULT_MAX_SEQ_LAG, value_parser = clap::value_parser!(u8).range(1..=127))]
    max_seq_lag: u8,
    /// Print one JSON line of statistics instead of a summary.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    realtime: RealtimeArgs,
}

#[derive(Debug, Clone, Copy, Args)]
struct RealtimeArgs {
    /// Run the loop under SCHED_FIFO at this priority (1-99) where permitted (root or
    /// CAP_SYS_NICE); without permission a warning is printed and the loop runs as usual.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    realtime_priority: Option<i32>,
    /// Pin the loop thread to this CPU.
    #[arg(long)]
    cpu: Option<usize>,
}

impl RealtimeArgs {
    fn apply(self) {
        if self.realtime_priority.is_none() && self.cpu.is_none() {
            return;
        }
        let outcome =
            vge_bridge::realtime::make_current_thread_realtime(self.realtime_priority.unwrap_or(1), self.cpu);
        if self.realtime_priority.is_some() {
            match outcome.fifo {
                Ok(p) => note!("vge-bridge: SCHED_FIFO priority {p}"),
                Err(e) => {
                    note!("vge-bridge: warning: SCHED_FIFO refused ({e}); running with normal scheduling")
                }
            }
        }
        match outcome.pinned {
            Some(Ok(cpu)) => note!("vge-bridge: pinned to CPU {cpu}"),
            Some(Err(e)) => note!("vge-bridge: warning: pinning refused ({e})"),
            None => {}
        }
    }
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a policy file at a fixed rate.
    ///
    /// Each period: read the hand's state, build the observation exactly as the simulator
    /// does, run the policy on vge-runtime, clamp the change and the joint limits, send the
    /// targets. Stops after --duration, on Ctrl-C (hold, then disable), when the hand falls
    /// silent (watchdog) or when a node reports a fault or restarts. Prints rate, jitter,
    /// deadline misses and frame counts, and the object's rotation with the sim backend.
    ///
    /// Exit status: 0 after --duration, --steps or Ctrl-C; after a safety halt (hold, then disable) one
    /// per stop reason: 10 watchdog, 11 node_fault, 12 heartbeat_lost, 13 node_restarted, 14
    /// implausible_state, 15 policy_failure, 16 bus_off, 17 bus_overload, 18 tx_failure; 1 when
    /// it could not run (a bad file, no answer from the hand at start-up, a transport error);
    /// 2 for a bad command line.
    Run {
        /// Policy file written by `vge train`, `vge export` or `vge import`.
        #[arg(long)]
        policy: PathBuf,
        /// The hand to drive. `sim` needs a vge-bridge built with the `sim` cargo feature (the
        /// default build).
        #[arg(long, value_enum, default_value_t = Backend::Sim)]
        backend: Backend,
        /// Hand file with the joint limits of the hand driven (TOML: `joint_limits_rad`, 15
        /// [lower, upper] pairs in rad, finger-major; docs/can-protocol.md, Joint limits),
        /// instead of the default hand's below. The safety filter clamps targets to them and
        /// the plausibility check holds positions against them; the simulated hand keeps its
        /// own.
        #[arg(long, value_name = "FILE")]
        hand: Option<PathBuf>,
        /// CAN interface (backend can).
        #[arg(long, default_value = "vcan0")]
        iface: String,
        /// Use the CAN FD option (backend can): one frame per node per step and one command
        /// frame for the hand; the interface needs an FD MTU (72).
        #[arg(long)]
        fd: bool,
        #[command(flatten)]
        sim_hand: SimHandArgs,
        /// Record the simulated episode (backend sim) into this file (JSON Lines): each finger
        /// link's pose and the object's, the fingertip and link contact points with their
        /// normal forces, the joint-target changes sent and the reward, one line per control
        /// step. See it in the Rerun viewer with the Python package:
        /// `python -m vge.recording F.jsonl --spawn` (`pip install ./python rerun-sdk`).
        /// Refused with --backend can: a real hand does not report where the object is.
        #[arg(long, value_name = "F.jsonl")]
        record: Option<PathBuf>,
        #[command(flatten)]
        loop_args: LoopArgs,
    },
    /// Emulate the hand's five finger nodes (joint controllers and fingertip sensors) on a
    /// CAN interface, in real time, speaking the protocol.
    ///
    /// With --model sim (default) the nodes are the simulated hand holding --object: every
    /// full set of enabled joint commands advances the simulation one control period. The
    /// nodes send heartbeats at 10 Hz and report their enable state; an enabled finger that
    /// gets no command for --command-timeout-s holds and reports fault command_timeout.
    /// Stops when no frame arrived for --idle-timeout-s or on Ctrl-C, printing a summary.
    /// Exit status 0, 3 when a node faulted during the run, 1 when it could not run, 2 for a
    /// bad command line. --restart-node reboots one
    /// node mid-run, as a joint controller that resets: it sends its boot-up heartbeat and
    /// counts its heartbeats from 0 again, disabled (the bridge halts: node_restarted).
    Emulate {
        /// CAN interface the nodes speak on.
        #[arg(long, default_value = "vcan0")]
        iface: String,
        /// What the nodes are. `sim` needs a vge-bridge built with the `sim` cargo feature (the
        /// default build).
        #[arg(long, value_enum, default_value_t = NodeModel::Sim)]
        model: NodeModel,
        /// Speak the CAN FD option (model sim): node states and hand commands as FD frames.
        #[arg(long)]
        fd: bool,
        #[command(flatten)]
        sim_hand: SimHandArgs,
        /// Stop after this many seconds without a frame.
        #[arg(long, default_value_t = 10.0)]
        idle_timeout_s: f64,
        /// An enabled finger that receives no command for this long holds and reports fault
        /// command_timeout (cleared by a disabled command).
        #[arg(long, default_value_t = 0.5)]
        command_timeout_s: f64,
        /// Reboot this node (0 thumb .. 4 little) once it has applied
        /// --restart-after-commands enabled commands.
        #[arg(long, value_parser = clap::value_parser!(u8).range(0..5))]
        restart_node: Option<u8>,
        /// The enabled commands the --restart-node node applies before it reboots.
        #[arg(long, default_value_t = 20, requires = "restart_node")]
        restart_after_commands: u64,
        /// Print one JSON line when done.
        #[arg(long)]
        json: bool,
    },
    /// Loop timing on this host: the control loop against emulated nodes over the
    /// in-process transport (no CAN, no simulator), so only the loop's own timing shows.
    /// A measurement: it exits 0 however the loop stopped (the report names why).
    Bench {
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
    },
}

fn main() -> ExitCode {
    // `run --help` lists the joint limits of the hand, read from the one hand description.
    let mut command = Cli::command().mut_subcommand("run", |c| c.after_long_help(joint_limits_help()));
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
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            note!("vge-bridge: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The joint limits every target is clamped to (and positions are checked against).
fn joint_limits_help() -> String {
    let limits = hand_file::default_joint_limits();
    let mut text = String::from(
        "Joint limits (rad) of the default hand (--hand FILE replaces them): the safety filter clamps\n\
         every target to them, and a measured position more than 0.1 rad outside them is implausible\n\
         (dropped and counted; the loop holds, and halts if it persists).\n  \
         finger   roll              proximal flexion  distal flexion\n",
    );
    for (f, name) in vge_sim::kinematics::FINGER_NAMES.iter().enumerate() {
        text.push_str(&format!("  {name:<8}"));
        for l in &limits[3 * f..3 * f + 3] {
            text.push_str(&format!(" [{:+.3}, {:+.3}]", l.lower_rad, l.upper_rad));
        }
        text.push('\n');
    }
    text
}

/// A flag raised by Ctrl-C or SIGTERM, so loops stop cleanly (hold, then disable).
fn stop_on_signal() -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    Ok(stop)
}

fn positive_seconds(name: &str, s: f64, zero_ok: bool) -> anyhow::Result<Option<Duration>> {
    if !s.is_finite() || s < 0.0 || (s == 0.0 && !zero_ok) {
        bail!("--{name} must be a positive number of seconds, got {s}");
    }
    if s == 0.0 {
        return Ok(None);
    }
    Duration::try_from_secs_f64(s).map(Some).map_err(|_| anyhow::anyhow!("--{name} = {s} s is too long"))
}

fn loop_config(args: &LoopArgs, policy_hz: f32, limits: JointLimits) -> anyhow::Result<LoopConfig> {
    let rate_hz = args.rate.unwrap_or(f64::from(policy_hz));
    anyhow::ensure!(
        rate_hz.is_finite() && rate_hz >= control_loop::MIN_RATE_HZ,
        "--rate must be a number of Hz, at least {}, got {rate_hz}",
        control_loop::MIN_RATE_HZ
    );
    if (rate_hz - f64::from(policy_hz)).abs() > 1e-3 {
        note!("vge-bridge: note: the policy was trained at {policy_hz} Hz, running it at {rate_hz} Hz");
    }
    anyhow::ensure!(
        args.max_delta_rad.is_finite() && args.max_delta_rad > 0.0,
        "--max-delta-rad must be positive"
    );
    let heartbeat_timeout =
        positive_seconds("heartbeat-timeout-s", args.heartbeat_timeout_s, false)?.unwrap_or(Duration::MAX);
    Ok(LoopConfig {
        duration: positive_seconds("duration", args.duration, true)?,
        max_steps: args.steps,
        watchdog_periods: args.watchdog_periods.max(1),
        max_delta_rad: args.max_delta_rad,
        heartbeat_timeout,
        max_seq_lag: args.max_seq_lag,
        ..LoopConfig::new(rate_hz, limits)
    })
}

/// The file's bytes at an aligned address, so that a version-2 policy is used in place. A file
/// longer than any hand policy (its length from its metadata) is refused unread.
fn read_policy(path: &Path) -> anyhow::Result<AlignedBytes> {
    use std::io::Read;
    use vge_runtime::policy::HAND_MAX_FILE_LEN;
    let context = || format!("reading policy file {}", path.display());
    let file = std::fs::File::open(path).with_context(context)?;
    let len = file.metadata().with_context(context)?.len();
    let too_long = |len: u64| {
        anyhow::anyhow!(
            "policy file {}: {len} bytes, longer than any hand policy (at most {HAND_MAX_FILE_LEN} \
             bytes); not read",
            path.display()
        )
    };
    if len > HAND_MAX_FILE_LEN as u64 {
        return Err(too_long(len));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(HAND_MAX_FILE_LEN as u64 + 1).read_to_end(&mut bytes).with_context(context)?;
    if bytes.len() > HAND_MAX_FILE_LEN {
        return Err(too_long(bytes.len() as u64));
    }
    Ok(AlignedBytes::new(&bytes))
}

fn print_report(
    json: bool,
    extra: &[(&str, Value)],
    cfg: &LoopConfig,
    r: &LoopReport,
    sim: Option<&SimHandSummary>,
) -> anyhow::Result<()> {
    if json {
        out!("{}", json_line(extra, cfg.rate_hz, r, sim));
        return Ok(());
    }
    let detail = if r.stop_detail.is_empty() { String::new() } else { format!(": {}", r.stop_detail) };
    out!("stopped: {} after {} steps{detail}", r.stop_reason.as_str(), r.steps);
    out!("rate:    {:.2} Hz achieved of {:.2} Hz", r.achieved_rate_hz, cfg.rate_hz);
    out!(
        "jitter:  p50 {:.1} us, p99 {:.1} us, max {:.1} us; deadline misses {} ({} periods skipped)",
        r.wake_jitter.p50_us,
        r.wake_jitter.p99_us,
        r.wake_jitter.max_us,
        r.deadline_misses,
        r.skipped_periods
    );
    out!(
        "loop:    p50 {:.1} us, p99 {:.1} us, max {:.1} us",
        r.loop_time.p50_us,
        r.loop_time.p99_us,
        r.loop_time.max_us
    );
    let l = &r.link;
    out!(
        "frames:  {} in, {} out on the bus ({} / {} messages); {} bad, {} stale, {} implausible, {} lost",
        l.frames_in,
        l.frames_out,
        l.messages_in,
        l.messages_out,
        l.bad_frames,
        l.stale_frames,
        l.implausible_frames,
        l.lost_frames
    );
    out!(
        "bus:     {} error frames ({} bus-off), {} frames not sent, {} overloaded periods",
        l.error_frames.total(),
        l.error_frames.bus_off,
        l.tx_dropped,
        l.overload_periods
    );
    out!(
        "safety:  {} holds ({} policy errors), {} NaN holds, {} delta clamps, {} limit clamps",
        r.holds,
        r.policy_errors,
        r.safety.non_finite_holds,
        r.safety.delta_clamps,
        r.safety.limit_clamps
    );
    if let Some(s) = sim {
        out!(
            "object:  turned {:.3} rad about z in {} sim steps; return {:.3}; {:.2} fingertip contacts on average, {} contact switches{}",
            s.rotation_rad,
            s.steps,
            s.total_reward,
            s.mean_tip_contacts,
            s.contact_switches,
            if s.terminated { "; the episode terminated (drop or lost contacts)" } else { "" }
        );
    }
    Ok(())
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Run {
            policy,
            backend,
            hand,
            iface,
            fd,
            sim_hand: SimHandArgs { object, seed },
            record,
            loop_args,
        } => {
            if backend == Backend::Sim && !cfg!(feature = "sim") {
                return Err(no_sim("--backend sim (the default)"));
            }
            if record.is_some() {
                anyhow::ensure!(
                    backend == Backend::Sim,
                    "--record needs --backend sim: over CAN the hand reports its joints and fingertip \
                     sensors but not the object, whose pose the recording is about"
                );
                #[cfg(feature = "sim")]
                if let Some(path) = &record {
                    vge_sim::recording::check_path(path)?;
                }
            }
            let limits = match &hand {
                Some(path) => hand_file::load_joint_limits(path)
                    .with_context(|| format!("hand file {}", path.display()))?,
                None => hand_file::default_joint_limits(),
            };
            let bytes = read_policy(&policy)?;
            let mut storage = storage_for(&bytes).with_context(|| format!("loading {}", policy.display()))?;
            let mut runner = RuntimePolicy::load(&bytes, &mut storage)
                .with_context(|| format!("loading {}", policy.display()))?;
            let cfg = loop_config(&loop_args, runner.control_hz(), limits)?;
            let stop = stop_on_signal()?;
            loop_args.realtime.apply();
            match backend {
                Backend::Can => {
                    let opening = || format!("opening CAN interface {iface}");
                    let report = if fd {
                        let mut transport =
                            FdSocketCanTransport::open(&iface, Role::Host).with_context(opening)?;
                        control_loop::run(&mut transport, &mut runner, &cfg, &stop)?
                    } else {
                        let mut transport =
                            SocketCanTransport::open(&iface, Role::Host).with_context(opening)?;
                        control_loop::run(&mut transport, &mut runner, &cfg, &stop)?
                    };
                    let backend = if fd { "can-fd" } else { "can" };
                    print_report(loop_args.json, &[("backend", json!(backend))], &cfg, &report, None)?;
                    Ok(exit_status(&report))
                }
                Backend::Sim => {
                    let (report, summary) =
                        run_against_sim(&mut runner, &cfg, &object, seed, record.as_deref(), &stop)?;
                    let extra = [("backend", json!("sim")), ("object", json!(object.to_string()))];
                    print_report(loop_args.json, &extra, &cfg, &report, Some(&summary))?;
                    Ok(exit_status(&report))
                }
            }
        }
        Command::Emulate {
            iface,
            model,
            fd,
            sim_hand: SimHandArgs { object, seed },
            idle_timeout_s,
            command_timeout_s,
            restart_node,
            restart_after_commands,
            json,
        } => {
            let restart = match restart_node {
                Some(node) => {
                    anyhow::ensure!(
                        restart_after_commands > 0,
                        "--restart-after-commands must be at least 1"
                    );
                    let node = FingerId::new(node).with_context(|| format!("--restart-node {node}"))?;
                    Some(RestartPlan { node, after_enabled_commands: restart_after_commands })
                }
                None => None,
            };
            let idle = positive_seconds("idle-timeout-s", idle_timeout_s, false)?.unwrap_or(Duration::MAX);
            let command_timeout =
                positive_seconds("command-timeout-s", command_timeout_s, false)?.unwrap_or(Duration::MAX);
            if model == NodeModel::Sim && !cfg!(feature = "sim") {
                return Err(no_sim("--model sim (the default)"));
            }
            let stop = stop_on_signal()?;
            anyhow::ensure!(!(fd && model == NodeModel::Lag), "--fd needs --model sim");
            let opening = || format!("opening CAN interface {iface}");
            let limits = ServeLimits { max_commands: u64::MAX, idle_timeout: idle, command_timeout, restart };
            let summary = match model {
                NodeModel::Lag => {
                    let mut transport =
                        SocketCanTransport::open(&iface, Role::Nodes).with_context(opening)?;
                    let stats = serve(&mut transport, &mut JointControllerEmulator::new(0.2), limits, &stop)?;
                    let bus = transport.bus_counts();
                    json!({
                        "model": "lag",
                        "commands": stats.commands,
                        "frames_in": bus.frames_in,
                        "frames_out": bus.frames_out,
                        "ignored": stats.ignored,
                        "heartbeats_sent": stats.heartbeats_sent,
                        "command_timeouts": stats.command_timeouts,
                        "restarts": stats.restarts,
                    })
                }
                NodeModel::Sim => emulate_sim(&iface, fd, &object, seed, limits, &stop)?,
            };
            let timeouts = summary["command_timeouts"].as_u64().unwrap_or(0);
            if timeouts > 0 {
                note!(
                    "vge-bridge: {timeouts} finger node(s) faulted with command_timeout: the bridge stopped sending \
                     commands while they were enabled; they held their positions"
                );
            }
            if json {
                out!("{summary}");
            } else {
                note!("vge-bridge: emulator summary: {summary}");
            }
            Ok(if timeouts > 0 { ExitCode::from(EXIT_NODE_FAULT) } else { ExitCode::SUCCESS })
        }
        Command::Bench { policy, rate, duration, json, realtime } => {
            let loop_args = LoopArgs {
                rate: Some(rate),
                duration,
                steps: None,
                max_delta_rad: 0.05,
                watchdog_periods: 50,
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
                    (
                        control_loop::run(&mut bridge_end, &mut runner, &cfg, &stop)?,
                        cfg,
                        path.display().to_string(),
                    )
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
    }
}

/// `run`'s exit status: 0 for a normal end, the stop reason's own status for a safety halt
/// (named on stderr too, whatever --json says).
fn exit_status(report: &LoopReport) -> ExitCode {
    let reason: StopReason = report.stop_reason;
    if reason.is_safety_halt() {
        note!(
            "vge-bridge: safety halt ({}): {}; held, then disabled the fingers; exit status {}",
            reason.as_str(),
            report.stop_detail,
            reason.exit_code()
        );
    }
    ExitCode::from(reason.exit_code())
}

/// The bench's default policy: no change.
struct Hold;

impl PolicyRunner for Hold {
    type Error = std::convert::Infallible;
    fn act(&mut self, _: &[f32; OBS_DIM]) -> Result<[f32; NUM_JOINTS], Self::Error> {
        Ok([0.0; NUM_JOINTS])
    }
}

/// Why a command that needs the simulator cannot run in this build (`run` asks before it
/// loads anything; the stand-ins below, compiled in its place, refuse too).
fn no_sim(what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{what} needs the simulator, and this vge-bridge was built without it (cargo feature `sim`, on \
         by default): it drives real hands only, with `run --backend can` and `emulate --model lag`. \
         Rebuild with the default features for the simulated hand"
    )
}

/// Emulates the hand's nodes on `iface` with the simulated hand holding `object`; the summary.
#[cfg(feature = "sim")]
fn emulate_sim(
    iface: &str,
    fd: bool,
    object: &ObjectShape,
    seed: u64,
    limits: ServeLimits,
    stop: &AtomicBool,
) -> anyhow::Result<Value> {
    let mut config = EnvConfig::default();
    config.object.shape = *object;
    let mut hand = SimHand::new(config, seed, limits.command_timeout)?;
    let idle = limits.idle_timeout;
    if let Some(plan) = limits.restart {
        hand.nodes.plan_restart(plan);
    }
    note!(
        "vge-bridge: emulating the hand holding a {object} on {iface}{}",
        if fd { " (CAN FD)" } else { "" }
    );
    let opening = || format!("opening CAN interface {iface}");
    let (stats, bus) = if fd {
        let mut t = FdSocketCanTransport::open(iface, Role::Nodes).with_context(opening)?;
        (sim_hand::serve(&mut t, &mut hand, idle, stop)?, t.bus_counts())
    } else {
        let mut t = SocketCanTransport::open(iface, Role::Nodes).with_context(opening)?;
        (sim_hand::serve(&mut t, &mut hand, idle, stop)?, t.bus_counts())
    };
    let s = hand.summary();
    Ok(json!({
        "model": "sim",
        "frames_in": bus.frames_in,
        "frames_out": bus.frames_out,
        "messages_in": stats.frames_in,
        "messages_out": stats.frames_out,
        "bad_frames": stats.bad_frames,
        "heartbeats_sent": stats.heartbeats_sent,
        "command_timeouts": stats.command_timeouts,
        "restarts": stats.restarts,
        "sim_steps": s.steps,
        "rotation_rad": (f64::from(s.rotation_rad) * 1e4).round() / 1e4,
        "contact_switches": s.contact_switches,
        "terminated": s.terminated,
    }))
}

/// Stand-in without the simulator: refuses.
#[cfg(not(feature = "sim"))]
fn emulate_sim(
    _: &str,
    _: bool,
    _: &ObjectArg,
    _: u64,
    _: ServeLimits,
    _: &AtomicBool,
) -> anyhow::Result<Value> {
    Err(no_sim("--model sim (the default)"))
}

/// Stand-in without the simulator: refuses.
#[cfg(not(feature = "sim"))]
fn run_against_sim<P: PolicyRunner>(
    _: &mut P,
    _: &LoopConfig,
    _: &ObjectArg,
    _: u64,
    _: Option<&Path>,
    _: &Arc<AtomicBool>,
) -> anyhow::Result<(LoopReport, SimHandSummary)> {
    Err(no_sim("--backend sim (the default)"))
}

/// Runs the loop against the simulated hand on a thread of its own, over the protocol.
#[cfg(feature = "sim")]
fn run_against_sim<P: PolicyRunner>(
    runner: &mut P,
    cfg: &LoopConfig,
    object: &ObjectShape,
    seed: u64,
    record: Option<&Path>,
    stop: &Arc<AtomicBool>,
) -> anyhow::Result<(LoopReport, SimHandSummary)> {
    let mut env = EnvConfig::default();
    env.object.shape = *object;
    let (mut bridge_end, mut nodes_end) = InProcessTransport::pair();
    let nodes_stop = Arc::new(AtomicBool::new(false));
    let nodes_flag = nodes_stop.clone();
    // In-process the link cannot lose commands; the timeout only guards a stalled loop.
    let mut hand = SimHand::new(env, seed, Duration::from_secs(1)).context("building the simulated hand")?;
    if let Some(path) = record {
        hand.record_to(path).with_context(|| format!("recording into {}", path.display()))?;
    }
    let nodes = thread::spawn(move || {
        let mut hand = hand;
        sim_hand::serve(&mut nodes_end, &mut hand, Duration::from_secs(5), &nodes_flag)?;
        let recorded = hand.finish_recording()?;
        Ok::<_, sim_hand::SimHandError>((hand.summary(), recorded))
    });
    let report = control_loop::run(&mut bridge_end, runner, cfg, stop);
    nodes_stop.store(true, Ordering::Relaxed);
    let (summary, recorded) =
        nodes.join().map_err(|_| anyhow::anyhow!("the simulated hand's thread panicked"))??;
    if let (Some(path), Some(steps)) = (record, recorded) {
        note!(
            "vge-bridge: {steps} sim steps recorded in {}; see it in Rerun with `python -m vge.recording {} --spawn`",
            path.display(),
            path.display()
        );
    }
    Ok((report?, summary))
}
