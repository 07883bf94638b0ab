//! The CAN FD option: one frame per node per step instead of five, and one command frame for
//! the whole hand, so that rates classic CAN cannot carry (above ~150 Hz) fit a bus.
//!
//! | frame       | id           | dir          | bytes | payload                                                         |
//! |-------------|--------------|--------------|-------|-----------------------------------------------------------------|
//! | hand command| 0x0F0        | host -> all  | 32    | q_target[15] i16 (1e-4 rad), flags u8 (bit 0 enable), seq u8    |
//! | node state  | 0x480 + node | node -> host | 48    | q[3], dq[3], tau[3], p[3] i16, force u16, n[3] i16, flags, seq  |
//!
//! The hand command's layout is fixed: it carries exactly [`FD_NODES`] nodes' targets (vge15's
//! five, 15 joints), so the FD option is for five-node hands only; another hand runs on the
//! classic frames (the bridge refuses `--fd` for it). Field scales are those of the classic frames. Node-state flags: bit 0 motors enabled,
//! bit 1 fault, bit 2 tip in contact; bytes 34..48 are reserved (zero). Each FD frame is
//! equivalent to classic messages ([`FdMessage::to_classic`], [`FdMessage::from_classic`]),
//! so the bridge's state handling and the emulators are the same for both.

use super::fields::{
    ANGLE_RAD_PER_COUNT, EFFORT_NM_PER_COUNT, FORCE_N_PER_COUNT, NORMAL_PER_COUNT, POSITION_M_PER_COUNT,
    VELOCITY_RADPS_PER_COUNT, scaled3, to_u16, unscaled3,
};
use super::messages::*;
use super::{FingerId, JOINTS_PER_NODE, Message, ProtocolError};

/// Identifier of the hand command FD frame.
pub const FD_HAND_COMMAND_ID: u16 = 0x0F0;
/// Base identifier of node-state FD frames; the node is added.
pub const FD_NODE_STATE_BASE_ID: u16 = 0x480;
/// Payload bytes of a hand command (a valid FD length).
pub const FD_HAND_COMMAND_LEN: usize = 32;
/// Payload bytes of a node state (a valid FD length; 34 used).
pub const FD_NODE_STATE_LEN: usize = 48;

const FLAG_ENABLED: u8 = 0x01;
const FLAG_FAULT: u8 = 0x02;
const FLAG_IN_CONTACT: u8 = 0x04;
/// Finger nodes the FD option carries: the hand command's 32 bytes hold their 15 targets.
pub const FD_NODES: usize = 5;
/// Joint targets in a hand command.
pub const FD_JOINTS: usize = FD_NODES * JOINTS_PER_NODE;
const FINGERS: usize = FD_NODES;

/// An FD frame's identifier, length and payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFdFrame {
    pub id: u16,
    pub len: usize,
    pub data: [u8; 64],
}

impl RawFdFrame {
    pub fn payload(&self) -> &[u8] {
        self.data.get(..self.len).unwrap_or(&self.data)
    }
}

/// Targets for all [`FD_JOINTS`] joints at once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandCommand {
    pub q_target_rad: [f32; FD_JOINTS],
    pub enable: bool,
    pub seq: u8,
}

/// Everything one node reports in a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FingerState {
    pub finger: FingerId,
    pub q_rad: [f32; 3],
    pub dq_radps: [f32; 3],
    pub tau_nm: [f32; 3],
    pub tip_position_m: [f32; 3],
    pub tip_force_n: f32,
    pub tip_normal: [f32; 3],
    pub enabled: bool,
    pub fault: bool,
    pub in_contact: bool,
    pub seq: u8,
}

/// A frame of the FD option.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FdMessage {
    HandCommand(HandCommand),
    NodeState(FingerState),
}

/// `bit` if `on`, else 0.
fn flag(on: bool, bit: u8) -> u8 {
    if on { bit } else { 0 }
}

fn put(data: &mut [u8], at: usize, counts: [i16; 3]) {
    for (k, c) in counts.iter().enumerate() {
        if let Some(slot) = data.get_mut(at + 2 * k..at + 2 * k + 2) {
            slot.copy_from_slice(&c.to_le_bytes());
        }
    }
}

fn get3(data: &[u8], at: usize, scale: f32) -> [f32; 3] {
    let c = |k: usize| {
        let b = [data.get(at + 2 * k).copied().unwrap_or(0), data.get(at + 2 * k + 1).copied().unwrap_or(0)];
        i16::from_le_bytes(b)
    };
    unscaled3([c(0), c(1), c(2)], scale)
}

impl FdMessage {
    pub fn encode(&self) -> Result<RawFdFrame, ProtocolError> {
        let mut data = [0u8; 64];
        Ok(match self {
            FdMessage::HandCommand(c) => {
                for f in 0..FINGERS {
                    let q = [c.q_target_rad[3 * f], c.q_target_rad[3 * f + 1], c.q_target_rad[3 * f + 2]];
                    put(&mut data, 6 * f, scaled3("q_target_rad", q, ANGLE_RAD_PER_COUNT)?);
                }
                data[30] = if c.enable { FLAG_ENABLED } else { 0 };
                data[31] = c.seq;
                RawFdFrame { id: FD_HAND_COMMAND_ID, len: FD_HAND_COMMAND_LEN, data }
            }
            FdMessage::NodeState(s) => {
                if s.finger.slot() >= FD_NODES {
                    return Err(ProtocolError::BadFinger(s.finger.index()));
                }
                put(&mut data, 0, scaled3("q_rad", s.q_rad, ANGLE_RAD_PER_COUNT)?);
                put(&mut data, 6, scaled3("dq_radps", s.dq_radps, VELOCITY_RADPS_PER_COUNT)?);
                put(&mut data, 12, scaled3("tau_nm", s.tau_nm, EFFORT_NM_PER_COUNT)?);
                put(&mut data, 18, scaled3("position_m", s.tip_position_m, POSITION_M_PER_COUNT)?);
                data[24..26]
                    .copy_from_slice(&to_u16("force_n", s.tip_force_n, FORCE_N_PER_COUNT)?.to_le_bytes());
                put(&mut data, 26, scaled3("normal", s.tip_normal, NORMAL_PER_COUNT)?);
                data[32] = flag(s.enabled, FLAG_ENABLED)
                    | flag(s.fault, FLAG_FAULT)
                    | flag(s.in_contact, FLAG_IN_CONTACT);
                data[33] = s.seq;
                let id = FD_NODE_STATE_BASE_ID + u16::from(s.finger.index());
                RawFdFrame { id, len: FD_NODE_STATE_LEN, data }
            }
        })
    }

    /// Decodes a received FD frame; unknown ids and wrong lengths are errors, never panics.
    pub fn decode(id: u16, payload: &[u8]) -> Result<Self, ProtocolError> {
        if id == FD_HAND_COMMAND_ID {
            if payload.len() != FD_HAND_COMMAND_LEN {
                return Err(ProtocolError::BadLength { id, len: payload.len() });
            }
            let mut q_target_rad = [0.0; FD_JOINTS];
            for f in 0..FINGERS {
                q_target_rad[3 * f..3 * f + 3].copy_from_slice(&get3(payload, 6 * f, ANGLE_RAD_PER_COUNT));
            }
            return Ok(FdMessage::HandCommand(HandCommand {
                q_target_rad,
                enable: payload[30] & FLAG_ENABLED != 0,
                seq: payload[31],
            }));
        }
        let node = id.checked_sub(FD_NODE_STATE_BASE_ID).filter(|n| usize::from(*n) < FD_NODES);
        let Some(node) = node else { return Err(ProtocolError::UnknownId(id)) };
        if payload.len() != FD_NODE_STATE_LEN {
            return Err(ProtocolError::BadLength { id, len: payload.len() });
        }
        let flags = payload[32];
        Ok(FdMessage::NodeState(FingerState {
            finger: FingerId::new(node as u8)?,
            q_rad: get3(payload, 0, ANGLE_RAD_PER_COUNT),
            dq_radps: get3(payload, 6, VELOCITY_RADPS_PER_COUNT),
            tau_nm: get3(payload, 12, EFFORT_NM_PER_COUNT),
            tip_position_m: get3(payload, 18, POSITION_M_PER_COUNT),
            tip_force_n: f32::from(u16::from_le_bytes([payload[24], payload[25]])) * FORCE_N_PER_COUNT,
            tip_normal: get3(payload, 26, NORMAL_PER_COUNT),
            enabled: flags & FLAG_ENABLED != 0,
            fault: flags & FLAG_FAULT != 0,
            in_contact: flags & FLAG_IN_CONTACT != 0,
            seq: payload[33],
        }))
    }

    /// The classic messages this frame stands for: five joint commands, or a node's
    /// position, velocity, effort, tip contact and tip normal.
    pub fn to_classic(&self) -> heapless::Vec<Message, FINGERS> {
        let mut out = heapless::Vec::new();
        match *self {
            FdMessage::HandCommand(c) => {
                for finger in (0..FD_NODES as u8).filter_map(|n| FingerId::new(n).ok()) {
                    let f = 3 * usize::from(finger.index());
                    let q_target_rad = [c.q_target_rad[f], c.q_target_rad[f + 1], c.q_target_rad[f + 2]];
                    let _ = out.push(Message::JointCommand(JointCommand {
                        finger,
                        q_target_rad,
                        enable: c.enable,
                        seq: c.seq,
                    }));
                }
            }
            FdMessage::NodeState(s) => {
                let status = flag(s.enabled, STATUS_ENABLED) | flag(s.fault, STATUS_FAULT);
                let finger = s.finger;
                for m in [
                    Message::JointPosition(JointPosition { finger, q_rad: s.q_rad, status, seq: s.seq }),
                    Message::JointVelocity(JointVelocity { finger, dq_radps: s.dq_radps, seq: s.seq }),
                    Message::JointEffort(JointEffort { finger, tau_nm: s.tau_nm, seq: s.seq }),
                    Message::TipContact(TipContact {
                        finger,
                        position_m: s.tip_position_m,
                        force_n: s.tip_force_n,
                    }),
                    Message::TipNormal(TipNormal {
                        finger,
                        normal: s.tip_normal,
                        in_contact: s.in_contact,
                        seq: s.seq,
                    }),
                ] {
                    let _ = out.push(m);
                }
            }
        }
        out
    }
}

/// Collects classic messages into FD frames: five joint commands with one sequence number
/// become a hand command; a node's five state messages become its node state.
#[derive(Debug, Default, Clone)]
pub struct FdPacker {
    commands: [Option<JointCommand>; FINGERS],
    states: [PartialState; FINGERS],
}

#[derive(Debug, Default, Clone, Copy)]
struct PartialState {
    position: Option<JointPosition>,
    velocity: Option<JointVelocity>,
    effort: Option<JointEffort>,
    contact: Option<TipContact>,
    normal: Option<TipNormal>,
}

impl FdPacker {
    /// Whether `message` travels inside an FD frame (else it stays a classic frame).
    pub fn carries(message: &Message) -> bool {
        matches!(
            message,
            Message::JointCommand(_)
                | Message::JointPosition(_)
                | Message::JointVelocity(_)
                | Message::JointEffort(_)
                | Message::TipContact(_)
                | Message::TipNormal(_)
        )
    }

    /// Takes one classic message; returns an FD message when one is complete. Messages with
    /// no FD form (heartbeats, faults, targets) return `None` and go out as classic frames.
    pub fn push(&mut self, message: &Message) -> Option<FdMessage> {
        match *message {
            Message::JointCommand(c) => {
                // A node the FD option does not carry has no place in a hand command.
                let slot = self.commands.get_mut(c.finger.slot())?;
                *slot = Some(c);
                let all =
                    self.commands.iter().all(|p| p.is_some_and(|p| p.seq == c.seq && p.enable == c.enable));
                if !all {
                    return None;
                }
                let mut q_target_rad = [0.0; FD_JOINTS];
                for p in self.commands.iter().flatten() {
                    let f = 3 * usize::from(p.finger.index());
                    q_target_rad[f..f + 3].copy_from_slice(&p.q_target_rad);
                }
                self.commands = [None; FINGERS];
                Some(FdMessage::HandCommand(HandCommand { q_target_rad, enable: c.enable, seq: c.seq }))
            }
            Message::JointPosition(p) => self.state(p.finger, |s| s.position = Some(p)),
            Message::JointVelocity(v) => self.state(v.finger, |s| s.velocity = Some(v)),
            Message::JointEffort(e) => self.state(e.finger, |s| s.effort = Some(e)),
            Message::TipContact(t) => self.state(t.finger, |s| s.contact = Some(t)),
            Message::TipNormal(n) => self.state(n.finger, |s| s.normal = Some(n)),
            Message::Fault(_) | Message::Heartbeat(_) | Message::JointTarget(_) => None,
        }
    }

    fn state(&mut self, finger: FingerId, set: impl FnOnce(&mut PartialState)) -> Option<FdMessage> {
        let slot = self.states.get_mut(finger.slot())?;
        set(slot);
        let (Some(p), Some(v), Some(e), Some(c), Some(n)) =
            (slot.position, slot.velocity, slot.effort, slot.contact, slot.normal)
        else {
            return None;
        };
        *slot = PartialState::default();
        Some(FdMessage::NodeState(FingerState {
            finger,
            q_rad: p.q_rad,
            dq_radps: v.dq_radps,
            tau_nm: e.tau_nm,
            tip_position_m: c.position_m,
            tip_force_n: c.force_n,
            tip_normal: n.normal,
            enabled: p.status & STATUS_ENABLED != 0,
            fault: p.status & STATUS_FAULT != 0,
            in_contact: n.in_contact,
            seq: p.seq,
        }))
    }
}

/// Frames per control step with the FD option: one hand command, one state per node.
pub const FD_FRAMES_PER_STEP: u32 = 1 + FD_NODES as u32;

/// Worst-case duration (s) of an FD data frame with an 11-bit id and `len` data bytes, bit
/// rate switched: ~50 bits at the nominal rate (arbitration, ack, end of frame, interframe,
/// with stuffing) and, at the data rate, control, data and CRC bits plus one stuff bit in
/// five (a bound; FD's fixed stuff bits in the CRC are counted as data).
pub fn fd_frame_s(len: usize, nominal_bps: f64, data_bps: f64) -> f64 {
    let crc_bits = if len <= 16 { 17.0 } else { 21.0 };
    let data_phase_bits = (4.0 + 8.0 * len as f64 + crc_bits + 5.0) * 1.2;
    50.0 / nominal_bps + data_phase_bits / data_bps
}

/// Bus load of the FD option at `rate_hz` steps per second.
pub fn fd_bus_load(rate_hz: f64, nominal_bps: f64, data_bps: f64) -> f64 {
    let step_s = fd_frame_s(FD_HAND_COMMAND_LEN, nominal_bps, data_bps)
        + FD_NODES as f64 * fd_frame_s(FD_NODE_STATE_LEN, nominal_bps, data_bps);
    let heartbeats_s = 10.0 * (FD_NODES + 1) as f64 * 135.0 / nominal_bps;
    rate_hz * step_s + heartbeats_s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn five_commands_pack_into_one_hand_command_and_back() {
        let mut packer = FdPacker::default();
        let mut packed = None;
        for finger in (0..5).map(|n| FingerId::new(n).expect("node")) {
            let q = f32::from(finger.index()) * 0.1;
            let cmd = Message::JointCommand(JointCommand {
                finger,
                q_target_rad: [q, -q, 0.5],
                enable: true,
                seq: 9,
            });
            packed = packer.push(&cmd);
        }
        let Some(fd) = packed else { panic!("five commands make a hand command") };
        let frame = fd.encode().expect("encodes");
        assert_eq!((frame.id, frame.len), (FD_HAND_COMMAND_ID, 32));
        let back = FdMessage::decode(frame.id, frame.payload()).expect("decodes");
        let classic = back.to_classic();
        assert_eq!(classic.len(), 5);
        let Message::JointCommand(c3) = classic[3] else { panic!("a command") };
        assert!((c3.q_target_rad[0] - 0.3).abs() < 1e-4 && c3.enable && c3.seq == 9);
    }

    #[test]
    fn every_classic_message_of_a_received_frame_encodes_even_at_the_fields_extremes() {
        // Each i16 field at i16::MIN (bytes 00 80), each u16 at its maximum: the FD transport
        // hands these on as classic frames, so none may fail to encode and vanish.
        for fill in [[0x00, 0x80], [0xff, 0x7f], [0xff, 0xff]] {
            let mut state = [0u8; FD_NODE_STATE_LEN];
            for pair in state[..32].chunks_exact_mut(2) {
                pair.copy_from_slice(&fill);
            }
            let mut command = [0u8; FD_HAND_COMMAND_LEN];
            for pair in command[..30].chunks_exact_mut(2) {
                pair.copy_from_slice(&fill);
            }
            for (id, payload) in [(FD_NODE_STATE_BASE_ID + 2, &state[..]), (FD_HAND_COMMAND_ID, &command[..])]
            {
                let message = FdMessage::decode(id, payload).expect("decodes");
                let classic = message.to_classic();
                assert!(!classic.is_empty());
                for m in classic {
                    let raw = m.encode().unwrap_or_else(|e| panic!("{fill:?} {id:#x}: {m:?}: {e}"));
                    assert_eq!(Message::decode_frame(&raw), Ok(m), "{fill:?} {id:#x}: the same message back");
                }
            }
        }
    }

    #[test]
    fn fd_decoding_rejects_wrong_lengths_and_ids() {
        assert_eq!(FdMessage::decode(0x0F0, &[0; 31]), Err(ProtocolError::BadLength { id: 0x0F0, len: 31 }));
        assert_eq!(FdMessage::decode(0x485, &[0; 48]), Err(ProtocolError::UnknownId(0x485)));
        assert_eq!(FdMessage::decode(0x481, &[0; 8]), Err(ProtocolError::BadLength { id: 0x481, len: 8 }));
    }

    #[test]
    fn fd_bus_load_fits_a_kilohertz_loop_at_8_mbit_data_phase() {
        // 1 kHz: 6 frames per step; at 1 / 8 Mbit/s about 65% of the bus.
        let load = fd_bus_load(1000.0, 1e6, 8e6);
        assert!(load < 0.70, "{load}");
        assert!(fd_bus_load(1000.0, 1e6, 2e6) > 1.0);
    }
}
