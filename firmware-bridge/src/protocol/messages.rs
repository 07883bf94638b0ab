//! The protocol's messages and their encoding into 8-byte frames.

use super::fields::{
    ANGLE_RAD_PER_COUNT, EFFORT_NM_PER_COUNT, FORCE_N_PER_COUNT, NORMAL_PER_COUNT, POSITION_M_PER_COUNT,
    VELOCITY_RADPS_PER_COUNT, get_i16, get_i16x3, put_i16x3, scaled3, to_u16, unscaled3,
};
use super::{FingerId, HOST_NODE, MAX_FINGERS, ProtocolError, RawFrame, ids};

/// Joint command flag: motors powered. A command without it disables the finger.
pub const COMMAND_ENABLE: u8 = 0x01;
/// Joint position status: motors enabled.
pub const STATUS_ENABLED: u8 = 0x01;
/// Joint position status: a fault is latched (details in a fault frame).
pub const STATUS_FAULT: u8 = 0x02;
/// Tip normal flag: the fingertip touches something; contact fields are valid.
pub const TIP_IN_CONTACT: u8 = 0x01;

/// Target positions for one finger's three joints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointCommand {
    pub finger: FingerId,
    pub q_target_rad: [f32; 3],
    pub enable: bool,
    /// Wrapping sequence number, echoed by the node, to detect lost or stale frames.
    pub seq: u8,
}

/// Measured joint positions of one finger.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointPosition {
    pub finger: FingerId,
    pub q_rad: [f32; 3],
    /// `STATUS_ENABLED` | `STATUS_FAULT`.
    pub status: u8,
    pub seq: u8,
}

/// Measured joint velocities of one finger.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointVelocity {
    pub finger: FingerId,
    pub dq_radps: [f32; 3],
    pub seq: u8,
}

/// Measured joint torques of one finger.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointEffort {
    pub finger: FingerId,
    pub tau_nm: [f32; 3],
    pub seq: u8,
}

/// Fingertip contact point (hand frame) and normal-force magnitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipContact {
    pub finger: FingerId,
    pub position_m: [f32; 3],
    pub force_n: f32,
}

/// Fingertip contact normal (unit, hand frame, from the fingertip into the object) and flag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipNormal {
    pub finger: FingerId,
    pub normal: [f32; 3],
    pub in_contact: bool,
    pub seq: u8,
}

/// The targets a node is currently holding (reply to a query command).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointTarget {
    pub finger: FingerId,
    pub q_target_rad: [f32; 3],
    pub seq: u8,
}

/// Node states reported in heartbeats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeState {
    Booting,
    Ready,
    Enabled,
    Fault,
}

/// Liveness of a node (or of the host, node `HOST_NODE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Heartbeat {
    pub node: u8,
    pub state: NodeState,
    /// Increments with every heartbeat; a repeated value means a stuck sender.
    pub counter: u8,
}

/// Fault codes a node reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultCode {
    OverTemperature,
    OverCurrent,
    EncoderError,
    CommandTimeout,
    JointLimit,
    /// A code this version of the protocol does not know; kept, not dropped.
    Other(u16),
}

/// A fault raised by a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fault {
    pub finger: FingerId,
    pub code: FaultCode,
    /// Joint 0..=2, or `None` for the node as a whole.
    pub joint: Option<u8>,
    /// Code-specific detail (e.g. temperature in 0.1 °C, current in mA).
    pub value: i16,
    pub seq: u8,
}

/// Any frame of the protocol.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    Fault(Fault),
    JointCommand(JointCommand),
    JointPosition(JointPosition),
    JointVelocity(JointVelocity),
    JointEffort(JointEffort),
    TipContact(TipContact),
    TipNormal(TipNormal),
    JointTarget(JointTarget),
    Heartbeat(Heartbeat),
}

impl FaultCode {
    fn to_u16(self) -> u16 {
        match self {
            Self::OverTemperature => 1,
            Self::OverCurrent => 2,
            Self::EncoderError => 3,
            Self::CommandTimeout => 4,
            Self::JointLimit => 5,
            Self::Other(c) => c,
        }
    }

    fn from_u16(c: u16) -> Self {
        match c {
            1 => Self::OverTemperature,
            2 => Self::OverCurrent,
            3 => Self::EncoderError,
            4 => Self::CommandTimeout,
            5 => Self::JointLimit,
            c => Self::Other(c),
        }
    }
}

impl NodeState {
    fn to_u8(self) -> u8 {
        match self {
            Self::Booting => 0,
            Self::Ready => 1,
            Self::Enabled => 2,
            Self::Fault => 3,
        }
    }

    fn from_u8(v: u8) -> Self {
        match v {
            0 => Self::Booting,
            1 => Self::Ready,
            2 => Self::Enabled,
            // Unknown states are treated as faults: the safe reading.
            _ => Self::Fault,
        }
    }
}

fn frame(code: u16, node: u8, data: [u8; 8]) -> RawFrame {
    RawFrame { id: code + u16::from(node), data }
}

impl Message {
    /// The frame carrying this message. Fails only for values outside a field's range.
    pub fn encode(&self) -> Result<RawFrame, ProtocolError> {
        let mut d = [0u8; 8];
        Ok(match *self {
            Message::Fault(f) => {
                d[0..2].copy_from_slice(&f.code.to_u16().to_le_bytes());
                d[2] = f.joint.unwrap_or(0xff);
                d[3..5].copy_from_slice(&f.value.to_le_bytes());
                d[7] = f.seq;
                frame(ids::FAULT, f.finger.index(), d)
            }
            Message::JointCommand(c) => {
                put_i16x3(&mut d, scaled3("q_target_rad", c.q_target_rad, ANGLE_RAD_PER_COUNT)?);
                d[6] = if c.enable { COMMAND_ENABLE } else { 0 };
                d[7] = c.seq;
                frame(ids::JOINT_COMMAND, c.finger.index(), d)
            }
            Message::JointPosition(s) => {
                put_i16x3(&mut d, scaled3("q_rad", s.q_rad, ANGLE_RAD_PER_COUNT)?);
                d[6] = s.status;
                d[7] = s.seq;
                frame(ids::JOINT_POSITION, s.finger.index(), d)
            }
            Message::JointVelocity(v) => {
                put_i16x3(&mut d, scaled3("dq_radps", v.dq_radps, VELOCITY_RADPS_PER_COUNT)?);
                d[7] = v.seq;
                frame(ids::JOINT_VELOCITY, v.finger.index(), d)
            }
            Message::JointEffort(e) => {
                put_i16x3(&mut d, scaled3("tau_nm", e.tau_nm, EFFORT_NM_PER_COUNT)?);
                d[7] = e.seq;
                frame(ids::JOINT_EFFORT, e.finger.index(), d)
            }
            Message::TipContact(t) => {
                put_i16x3(&mut d, scaled3("position_m", t.position_m, POSITION_M_PER_COUNT)?);
                d[6..8].copy_from_slice(&to_u16("force_n", t.force_n, FORCE_N_PER_COUNT)?.to_le_bytes());
                frame(ids::TIP_CONTACT, t.finger.index(), d)
            }
            Message::TipNormal(n) => {
                put_i16x3(&mut d, scaled3("normal", n.normal, NORMAL_PER_COUNT)?);
                d[6] = if n.in_contact { TIP_IN_CONTACT } else { 0 };
                d[7] = n.seq;
                frame(ids::TIP_NORMAL, n.finger.index(), d)
            }
            Message::JointTarget(t) => {
                put_i16x3(&mut d, scaled3("q_target_rad", t.q_target_rad, ANGLE_RAD_PER_COUNT)?);
                d[7] = t.seq;
                frame(ids::JOINT_TARGET, t.finger.index(), d)
            }
            Message::Heartbeat(h) => {
                if h.node >= MAX_FINGERS && h.node != HOST_NODE {
                    return Err(ProtocolError::BadFinger(h.node));
                }
                d[0] = h.state.to_u8();
                d[1] = h.counter;
                frame(ids::HEARTBEAT, h.node, d)
            }
        })
    }

    /// Decodes a received frame. Unknown ids and short frames are errors, never panics.
    pub fn decode(id: u16, payload: &[u8]) -> Result<Self, ProtocolError> {
        let d: [u8; 8] =
            payload.try_into().map_err(|_| ProtocolError::BadLength { id, len: payload.len() })?;
        let (code, node) = (id & !0x7f, (id & 0x7f) as u8);
        if code == ids::HEARTBEAT && node == HOST_NODE {
            return Ok(Message::Heartbeat(Heartbeat {
                node,
                state: NodeState::from_u8(d[0]),
                counter: d[1],
            }));
        }
        let finger = FingerId::new(node).map_err(|_| ProtocolError::UnknownId(id))?;
        Ok(match code {
            ids::FAULT => Message::Fault(Fault {
                finger,
                code: FaultCode::from_u16(u16::from_le_bytes([d[0], d[1]])),
                joint: (d[2] < 3).then_some(d[2]),
                value: get_i16(&d, 3),
                seq: d[7],
            }),
            ids::JOINT_COMMAND => Message::JointCommand(JointCommand {
                finger,
                q_target_rad: unscaled3(get_i16x3(&d), ANGLE_RAD_PER_COUNT),
                enable: d[6] & COMMAND_ENABLE != 0,
                seq: d[7],
            }),
            ids::JOINT_POSITION => Message::JointPosition(JointPosition {
                finger,
                q_rad: unscaled3(get_i16x3(&d), ANGLE_RAD_PER_COUNT),
                status: d[6],
                seq: d[7],
            }),
            ids::JOINT_VELOCITY => Message::JointVelocity(JointVelocity {
                finger,
                dq_radps: unscaled3(get_i16x3(&d), VELOCITY_RADPS_PER_COUNT),
                seq: d[7],
            }),
            ids::JOINT_EFFORT => Message::JointEffort(JointEffort {
                finger,
                tau_nm: unscaled3(get_i16x3(&d), EFFORT_NM_PER_COUNT),
                seq: d[7],
            }),
            ids::TIP_CONTACT => Message::TipContact(TipContact {
                finger,
                position_m: unscaled3(get_i16x3(&d), POSITION_M_PER_COUNT),
                force_n: f32::from(u16::from_le_bytes([d[6], d[7]])) * FORCE_N_PER_COUNT,
            }),
            ids::TIP_NORMAL => Message::TipNormal(TipNormal {
                finger,
                normal: unscaled3(get_i16x3(&d), NORMAL_PER_COUNT),
                in_contact: d[6] & TIP_IN_CONTACT != 0,
                seq: d[7],
            }),
            ids::JOINT_TARGET => Message::JointTarget(JointTarget {
                finger,
                q_target_rad: unscaled3(get_i16x3(&d), ANGLE_RAD_PER_COUNT),
                seq: d[7],
            }),
            ids::HEARTBEAT => {
                Message::Heartbeat(Heartbeat { node, state: NodeState::from_u8(d[0]), counter: d[1] })
            }
            _ => return Err(ProtocolError::UnknownId(id)),
        })
    }

    /// Decodes a [`RawFrame`].
    pub fn decode_frame(frame: &RawFrame) -> Result<Self, ProtocolError> {
        Self::decode(frame.id, &frame.data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn finger(i: u8) -> FingerId {
        FingerId::new(i).expect("valid finger")
    }

    #[test]
    fn known_bytes_of_a_joint_position_frame() {
        let m = Message::JointPosition(JointPosition {
            finger: finger(0),
            q_rad: [0.0001, -0.0001, 0.0256],
            status: STATUS_ENABLED,
            seq: 7,
        });
        let f = m.encode().expect("encodes");
        assert_eq!(f.id, 0x180);
        assert_eq!(f.data, [1, 0, 0xff, 0xff, 0, 1, 1, 7]);
    }

    #[test]
    fn rejects_unknown_ids_and_short_frames_without_panicking() {
        // Node 8 is past every hand's nodes (`MAX_FINGERS`); nodes 5 to 7 are a larger hand's.
        assert_eq!(Message::decode(0x108, &[0; 8]), Err(ProtocolError::UnknownId(0x108)));
        assert!(Message::decode(0x107, &[0; 8]).is_ok());
        assert_eq!(Message::decode(0x7ff, &[0; 8]), Err(ProtocolError::UnknownId(0x7ff)));
        assert_eq!(Message::decode(0x000, &[0; 8]), Err(ProtocolError::UnknownId(0x000)));
        assert_eq!(Message::decode(0x181, &[0; 7]), Err(ProtocolError::BadLength { id: 0x181, len: 7 }));
        let nan = Message::JointCommand(JointCommand {
            finger: finger(1),
            q_target_rad: [f32::NAN, 0.0, 0.0],
            enable: false,
            seq: 0,
        });
        assert!(matches!(nan.encode(), Err(ProtocolError::OutOfRange { .. })));
        let bad_node = Message::Heartbeat(Heartbeat { node: 9, state: NodeState::Ready, counter: 0 });
        assert_eq!(bad_node.encode(), Err(ProtocolError::BadFinger(9)));
    }

    #[test]
    fn host_heartbeat_and_unknown_fault_codes_survive() {
        let hb = Message::Heartbeat(Heartbeat { node: HOST_NODE, state: NodeState::Enabled, counter: 200 });
        let f = hb.encode().expect("encodes");
        assert_eq!(f.id, 0x70f);
        assert_eq!(Message::decode_frame(&f), Ok(hb));
        let fault = Message::Fault(Fault {
            finger: finger(4),
            code: FaultCode::Other(999),
            joint: None,
            value: -5,
            seq: 3,
        });
        assert_eq!(Message::decode_frame(&fault.encode().expect("encodes")), Ok(fault));
    }
}
