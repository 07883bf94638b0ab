//! A software stand-in for the hand's joint controllers, speaking the bridge's CAN protocol.
//!
//! It lets the bridge be exercised end to end on a virtual CAN bus (vcan) without hardware:
//! each finger node applies enabled commands as a first-order lag towards the target and
//! answers every command with a joint position frame that echoes its sequence number. The
//! node duties (heartbeats, enable state, command timeout) are [`NodeSupervisor`]'s.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use thiserror::Error;

use crate::node_supervisor::{NodeSupervisor, RestartPlan};
use crate::protocol::{JointCommand, JointPosition, Message, NodeLayout, ProtocolError};
use crate::transport::{Received, Transport, TransportError};

/// Joint positions of all fingers of a hand, moving towards their commanded targets.
#[derive(Debug, Clone)]
pub struct JointControllerEmulator {
    nodes: NodeLayout,
    q_rad: Vec<[f32; 3]>,
    /// Fraction of the remaining error removed per command (0 = frozen, 1 = instant).
    response: f32,
}

impl JointControllerEmulator {
    /// The nodes of `nodes`, every joint at 0; `response` is clamped to [0, 1].
    pub fn new(nodes: NodeLayout, response: f32) -> Self {
        Self { nodes, q_rad: vec![[0.0; 3]; nodes.num_fingers()], response: response.clamp(0.0, 1.0) }
    }

    /// The nodes emulated.
    pub fn nodes(&self) -> NodeLayout {
        self.nodes
    }

    /// Applies one command (moving only if it is enabled and `apply` is set: a faulted node
    /// holds) and returns the finger's state after it, with the given status byte; `None` for
    /// a node the hand does not have (nobody answers).
    pub fn apply(&mut self, cmd: &JointCommand, apply: bool, status: u8) -> Option<JointPosition> {
        let q = self.q_rad.get_mut(cmd.finger.slot())?;
        if cmd.enable && apply {
            for (q_i, target) in q.iter_mut().zip(cmd.q_target_rad) {
                *q_i += self.response * (target - *q_i);
            }
        }
        Some(JointPosition { finger: cmd.finger, q_rad: *q, status, seq: cmd.seq })
    }
}

#[derive(Debug, Error)]
pub enum EmulatorError {
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
}

/// What one emulator session on a bus did.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct EmulatorStats {
    pub commands: u64,
    /// Frames on the bus that were not joint commands (other nodes' traffic).
    pub ignored: u64,
    /// Command-timeout faults the nodes raised.
    pub command_timeouts: u64,
    pub heartbeats_sent: u64,
    /// Node restarts emulated ([`ServeLimits::restart`]).
    pub restarts: u64,
}

/// When [`serve`] stops, and the nodes' command timeout.
#[derive(Debug, Clone, Copy)]
pub struct ServeLimits {
    /// Stop after answering this many commands (the nodes then fall silent).
    pub max_commands: u64,
    /// Stop when no frame arrived for this long.
    pub idle_timeout: Duration,
    pub command_timeout: Duration,
    /// A node to restart mid-run, if any.
    pub restart: Option<RestartPlan>,
}

/// Serves joint commands on `transport` until `limits` or `stop` end it, sending the
/// nodes' heartbeats and command-timeout faults as they fall due.
pub fn serve<T: Transport>(
    transport: &mut T,
    emulator: &mut JointControllerEmulator,
    limits: ServeLimits,
    stop: &AtomicBool,
) -> Result<EmulatorStats, EmulatorError> {
    let mut stats = EmulatorStats::default();
    let mut nodes = NodeSupervisor::new(emulator.nodes(), limits.command_timeout, Instant::now());
    if let Some(plan) = limits.restart {
        nodes.plan_restart(plan);
    }
    let mut last_frame = Instant::now();
    while stats.commands < limits.max_commands && !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        for frame in nodes.poll(now)? {
            transport.send(&frame)?;
        }
        if now.saturating_duration_since(last_frame) >= limits.idle_timeout {
            break;
        }
        let Some(received) = transport.recv(nodes.until_due(now, Duration::from_millis(20)))? else {
            continue;
        };
        last_frame = Instant::now();
        let Received::Frame(frame) = received else {
            stats.ignored += 1;
            continue;
        };
        let Ok(Message::JointCommand(cmd)) = Message::decode_frame(&frame) else {
            stats.ignored += 1;
            continue;
        };
        let applied = nodes.on_command(&cmd, last_frame);
        let Some(state) = emulator.apply(&cmd, applied, nodes.status(cmd.finger)) else {
            stats.ignored += 1;
            continue;
        };
        transport.send(&Message::JointPosition(state).encode()?)?;
        stats.commands += 1;
    }
    stats.command_timeouts = nodes.command_timeouts;
    stats.heartbeats_sent = nodes.heartbeats_sent;
    stats.restarts = nodes.restarts;
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{FingerId, STATUS_ENABLED};

    #[test]
    fn enabled_commands_move_towards_target_and_disabled_ones_hold() {
        let mut emu = JointControllerEmulator::new(NodeLayout::VGE15, 0.5);
        let finger = FingerId::new(2).expect("valid");
        let cmd = JointCommand { finger, q_target_rad: [0.4, -0.2, 1.0], enable: true, seq: 9 };
        let s1 = emu.apply(&cmd, true, STATUS_ENABLED).expect("node 2");
        assert_eq!(s1.q_rad, [0.2, -0.1, 0.5]);
        assert_eq!((s1.status, s1.seq), (STATUS_ENABLED, 9));
        let s2 = emu.apply(&cmd, true, STATUS_ENABLED).expect("node 2");
        assert_eq!(s2.q_rad, [0.3, -0.15, 0.75]);
        let hold = emu.apply(&JointCommand { enable: false, seq: 10, ..cmd }, true, 0).expect("node 2");
        assert_eq!(hold.q_rad, s2.q_rad);
        assert_eq!(hold.status, 0);
        let faulted = emu.apply(&cmd, false, 0).expect("node 2");
        assert_eq!(faulted.q_rad, s2.q_rad, "a faulted node holds");
        let other = JointCommand { finger: FingerId::new(5).expect("node id"), ..cmd };
        assert_eq!(emu.apply(&other, true, 0), None, "vge15 has no node 5");
    }
}
