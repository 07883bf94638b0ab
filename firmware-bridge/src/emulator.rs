//! A software stand-in for the hand's joint controllers, speaking the bridge's CAN protocol.
//!
//! It lets the bridge be exercised end to end on a virtual CAN bus (vcan) without hardware:
//! each finger node applies enabled commands as a first-order lag towards the target and
//! answers every command with a joint position frame that echoes its sequence number.

use std::time::Duration;

use thiserror::Error;

use crate::protocol::{JointCommand, JointPosition, Message, NUM_FINGERS, ProtocolError, STATUS_ENABLED};
use crate::transport::{Received, Transport, TransportError};

/// Joint positions of all fingers, moving towards their commanded targets.
#[derive(Debug, Clone)]
pub struct JointControllerEmulator {
    q_rad: [[f32; 3]; NUM_FINGERS as usize],
    /// Fraction of the remaining error removed per command (0 = frozen, 1 = instant).
    response: f32,
}

impl JointControllerEmulator {
    /// `response` is clamped to [0, 1].
    pub fn new(response: f32) -> Self {
        Self { q_rad: [[0.0; 3]; NUM_FINGERS as usize], response: response.clamp(0.0, 1.0) }
    }

    /// Applies one command and returns the finger's state after it.
    pub fn apply(&mut self, cmd: &JointCommand) -> JointPosition {
        let q = &mut self.q_rad[usize::from(cmd.finger.index())];
        if cmd.enable {
            for (q_i, target) in q.iter_mut().zip(cmd.q_target_rad) {
                *q_i += self.response * (target - *q_i);
            }
        }
        JointPosition {
            finger: cmd.finger,
            q_rad: *q,
            status: if cmd.enable { STATUS_ENABLED } else { 0 },
            seq: cmd.seq,
        }
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
}

/// Serves joint commands on `transport` until `max_commands` were answered or no frame
/// arrived for `idle_timeout`.
pub fn serve<T: Transport>(
    transport: &mut T,
    emulator: &mut JointControllerEmulator,
    max_commands: u64,
    idle_timeout: Duration,
) -> Result<EmulatorStats, EmulatorError> {
    let mut stats = EmulatorStats::default();
    while stats.commands < max_commands {
        let Some(received) = transport.recv(idle_timeout)? else { break };
        let Received::Frame(frame) = received else {
            stats.ignored += 1;
            continue;
        };
        let Ok(Message::JointCommand(cmd)) = Message::decode_frame(&frame) else {
            stats.ignored += 1;
            continue;
        };
        let state = Message::JointPosition(emulator.apply(&cmd));
        transport.send(&state.encode()?)?;
        stats.commands += 1;
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::FingerId;

    #[test]
    fn enabled_commands_move_towards_target_and_disabled_ones_hold() {
        let mut emu = JointControllerEmulator::new(0.5);
        let finger = FingerId::new(2).expect("valid");
        let cmd = JointCommand { finger, q_target_rad: [0.4, -0.2, 1.0], enable: true, seq: 9 };
        let s1 = emu.apply(&cmd);
        assert_eq!(s1.q_rad, [0.2, -0.1, 0.5]);
        assert_eq!((s1.status, s1.seq), (STATUS_ENABLED, 9));
        let s2 = emu.apply(&cmd);
        assert_eq!(s2.q_rad, [0.3, -0.15, 0.75]);
        let hold = emu.apply(&JointCommand { enable: false, seq: 10, ..cmd });
        assert_eq!(hold.q_rad, s2.q_rad);
        assert_eq!(hold.status, 0);
    }
}
