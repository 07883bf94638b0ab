//! `vge-bridge emulate`: a hand on a CAN interface, in real time: vge's five finger nodes, or
//! the Allegro Hand ([`super::allegro`]).

use std::io::Write as _;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use serde_json::{Value, json};
use vge_bridge::emulator::{JointControllerEmulator, ServeLimits, serve};
use vge_bridge::node_supervisor::RestartPlan;
use vge_bridge::protocol::{FingerId, MAX_FINGERS};
use vge_bridge::protocol_hand::ProtocolHand;
#[cfg(feature = "sim")]
use vge_bridge::sim_hand::{self, SimHand};
#[cfg(feature = "sim")]
use vge_bridge::transport::FdSocketCanTransport;
use vge_bridge::transport::{Role, SocketCanTransport, Transport};
#[cfg(feature = "sim")]
use vge_sim::{EnvConfig, ObjectShape};

#[cfg(not(feature = "sim"))]
use super::ObjectArg;
use super::{HandName, SimHandArgs, no_sim, positive_seconds, stop_on_signal};

/// Exit status of `emulate` when a node faulted (e.g. the bridge stopped sending commands
/// while the fingers were enabled): the summary is printed, and scripts see the fault.
const EXIT_NODE_FAULT: u8 = 3;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum NodeModel {
    /// The rapier simulation of the hand and object.
    Sim,
    /// Joints that move a fixed fraction towards their targets per command; no object
    /// (vge15 only).
    Lag,
}

/// Emulate a hand on a CAN interface, in real time, speaking its protocol.
///
/// vge's hand (--hand vge15, the default): its finger nodes (joint controllers and fingertip
/// sensors), as many as its description has fingers (five). With --model sim (default) the nodes are the simulated hand holding
/// --object: every full set of enabled joint commands advances the simulation one control
/// period. The nodes send heartbeats at 10 Hz and report their enable state; an enabled
/// finger that gets no command for --command-timeout-s holds and reports fault
/// command_timeout. --restart-node reboots one node mid-run, as a joint controller that
/// resets: it sends its boot-up heartbeat and counts its heartbeats from 0 again, disabled
/// (the bridge halts: node_restarted).
///
/// The Allegro Hand v4 (--hand allegro; docs/allegro-bridge.md): the simulated Allegro
/// holding its 65 mm cube, answering as the real hand does: info, serial, position,
/// temperature and status requests at once; once a period is set, its four position frames
/// every period (3 ms) and temperatures every temperature period; torques applied to the
/// joints while the servos are on; servos off leave the joints limp. The hand powers up limp
/// at its start grasp with the cube on a stand, which is taken away once three fingertips
/// have gripped it for 0.2 s with the servos on. The summary says how the cube fared from
/// then until the servos went off (`hold`: seconds held, how far it fell, moved and turned).
///
/// Stops when no frame arrived for --idle-timeout-s or on Ctrl-C, printing a summary.
/// Exit status 0, 3 when a vge15 node faulted during the run, 1 when it could not run, 2 for
/// a bad command line.
#[derive(Debug, Args)]
pub struct EmulateArgs {
    /// The hand to emulate.
    #[arg(long, value_enum, default_value_t = HandName::Vge15)]
    hand: HandName,
    /// CAN interface the hand speaks on.
    #[arg(long, default_value = "vcan0")]
    iface: String,
    /// What the hand is. `sim` needs a vge-bridge built with the `sim` cargo feature (the
    /// default build).
    #[arg(long, value_enum, default_value_t = NodeModel::Sim)]
    model: NodeModel,
    /// Speak the CAN FD option (vge15, model sim): node states and hand commands as FD frames.
    #[arg(long)]
    fd: bool,
    #[command(flatten)]
    sim_hand: SimHandArgs,
    /// Stop after this many seconds without a frame.
    #[arg(long, default_value_t = 10.0)]
    idle_timeout_s: f64,
    /// An enabled finger that receives no command for this long holds and reports fault
    /// command_timeout, cleared by a disabled command (vge15).
    #[arg(long, default_value_t = 0.5)]
    command_timeout_s: f64,
    /// Reboot this node (vge15: 0 thumb .. 4 little) once it has applied
    /// --restart-after-commands enabled commands (vge15).
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..i64::from(MAX_FINGERS)))]
    restart_node: Option<u8>,
    /// The enabled commands the --restart-node node applies before it reboots.
    #[arg(long, default_value_t = 20, requires = "restart_node")]
    restart_after_commands: u64,
    /// Print one JSON line when done.
    #[arg(long)]
    json: bool,
}

/// `vge-bridge emulate`.
pub fn run(args: EmulateArgs) -> anyhow::Result<ExitCode> {
    let EmulateArgs {
        hand,
        iface,
        model,
        fd,
        sim_hand: SimHandArgs { object, seed },
        idle_timeout_s,
        command_timeout_s,
        restart_node,
        restart_after_commands,
        json,
    } = args;
    let idle = positive_seconds("idle-timeout-s", idle_timeout_s, false)?.unwrap_or(Duration::MAX);
    if hand == HandName::Allegro {
        anyhow::ensure!(!fd, "--fd is vge's protocol's CAN FD option; the Allegro speaks classic CAN");
        anyhow::ensure!(
            restart_node.is_none(),
            "--restart-node reboots a vge15 finger node; the Allegro has none"
        );
        anyhow::ensure!(
            model == NodeModel::Sim,
            "--model lag is vge15's position-controlled nodes; the Allegro is torque-driven: --model sim"
        );
        return super::allegro::emulate(&iface, idle, json);
    }
    let hand = ProtocolHand::vge15()?;
    let restart = match restart_node {
        Some(node) => {
            anyhow::ensure!(restart_after_commands > 0, "--restart-after-commands must be at least 1");
            let finger = FingerId::new(node).with_context(|| format!("--restart-node {node}"))?;
            anyhow::ensure!(
                hand.nodes.has(finger),
                "--restart-node {node}: the hand {} has nodes 0 to {}",
                hand.name,
                hand.num_fingers() - 1
            );
            Some(RestartPlan { node: finger, after_enabled_commands: restart_after_commands })
        }
        None => None,
    };
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
            let mut transport = SocketCanTransport::open(&iface, Role::Nodes).with_context(opening)?;
            let stats =
                serve(&mut transport, &mut JointControllerEmulator::new(hand.nodes, 0.2), limits, &stop)?;
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
        "rotation_axis_tilt_rad": (f64::from(s.rotation_axis_tilt_rad) * 1e4).round() / 1e4,
        "tip_slip_m": (f64::from(s.tip_slip_m) * 1e4).round() / 1e4,
        "terminated": s.terminated,
        "dropped": s.dropped,
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
