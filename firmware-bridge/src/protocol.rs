//! Frames between the bridge and the hand's per-finger joint controllers (classic CAN, 8 bytes).
//!
//! Each finger is one node (`FingerId` 0..=4) driving its three joints: roll, proximal flexion,
//! distal flexion. Angles travel as little-endian `i16` in units of 1e-4 rad (range ±3.2767 rad,
//! resolution well below the controllers' position noise); velocities in 1e-3 rad/s.
//! Identifiers follow a CANopen-like function-code layout so that lower ids (higher
//! priority) carry commands:
//!
//! | frame          | id            | payload                                              |
//! |----------------|---------------|------------------------------------------------------|
//! | joint command  | 0x100 + node  | q_target[3] i16 (1e-4 rad), flags u8, seq u8         |
//! | joint state    | 0x180 + node  | q[3] i16 (1e-4 rad), status u8, seq u8               |
//!
//! The full protocol (velocity/effort, fingertip contacts, heartbeat, faults) is in
//! `docs/can-protocol.md`.

use thiserror::Error;

/// Scale of joint angles on the wire: one count is 1e-4 rad.
pub const ANGLE_RAD_PER_COUNT: f32 = 1e-4;
/// Base identifier of joint command frames; the finger's node id is added.
pub const JOINT_COMMAND_BASE_ID: u16 = 0x100;
/// Base identifier of joint state frames; the finger's node id is added.
pub const JOINT_STATE_BASE_ID: u16 = 0x180;
/// Fingers on the hand, one CAN node each.
pub const NUM_FINGERS: u8 = 5;

/// Errors decoding or encoding frames. Frames come from a bus: nothing here panics on them.
#[derive(Debug, Error, PartialEq)]
pub enum ProtocolError {
    #[error("finger id {0} out of range (0..{NUM_FINGERS})")]
    BadFinger(u8),
    #[error("frame id {id:#05x} is not a {expected} frame")]
    UnexpectedId { id: u16, expected: &'static str },
    #[error("frame id {id:#05x} has {len} data bytes, expected {expected}")]
    BadLength { id: u16, len: usize, expected: usize },
    #[error("joint angle {value_rad} rad is not finite or outside ±{max_rad} rad")]
    AngleOutOfRange { value_rad: f32, max_rad: f32 },
}

/// A finger node on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FingerId(u8);

impl FingerId {
    pub fn new(index: u8) -> Result<Self, ProtocolError> {
        if index < NUM_FINGERS { Ok(Self(index)) } else { Err(ProtocolError::BadFinger(index)) }
    }

    pub fn index(self) -> u8 {
        self.0
    }
}

/// A classic CAN frame's identifier and payload, independent of the socket layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFrame {
    pub id: u16,
    pub data: [u8; 8],
}

/// Target positions for one finger's three joints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointCommand {
    pub finger: FingerId,
    pub q_target_rad: [f32; 3],
    /// Motors are powered only while this is set; a command without it disables the finger.
    pub enable: bool,
    /// Wrapping sequence number, echoed in the state reply, to detect lost frames.
    pub seq: u8,
}

/// Measured positions of one finger's three joints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointState {
    pub finger: FingerId,
    pub q_rad: [f32; 3],
    /// Bit 0: motors enabled; bit 1: fault latched (details in a fault frame).
    pub status: u8,
    /// Sequence number of the last command the node applied.
    pub seq: u8,
}

const FLAG_ENABLE: u8 = 0x01;

impl JointCommand {
    pub fn encode(&self) -> Result<RawFrame, ProtocolError> {
        let mut data = [0u8; 8];
        put_angles(&mut data, &self.q_target_rad)?;
        data[6] = if self.enable { FLAG_ENABLE } else { 0 };
        data[7] = self.seq;
        Ok(RawFrame { id: JOINT_COMMAND_BASE_ID + u16::from(self.finger.0), data })
    }

    pub fn decode(id: u16, payload: &[u8]) -> Result<Self, ProtocolError> {
        let (finger, data) = node_payload(id, payload, JOINT_COMMAND_BASE_ID, "joint command")?;
        Ok(Self { finger, q_target_rad: get_angles(&data), enable: data[6] & FLAG_ENABLE != 0, seq: data[7] })
    }
}

impl JointState {
    pub fn encode(&self) -> Result<RawFrame, ProtocolError> {
        let mut data = [0u8; 8];
        put_angles(&mut data, &self.q_rad)?;
        data[6] = self.status;
        data[7] = self.seq;
        Ok(RawFrame { id: JOINT_STATE_BASE_ID + u16::from(self.finger.0), data })
    }

    pub fn decode(id: u16, payload: &[u8]) -> Result<Self, ProtocolError> {
        let (finger, data) = node_payload(id, payload, JOINT_STATE_BASE_ID, "joint state")?;
        Ok(Self { finger, q_rad: get_angles(&data), status: data[6], seq: data[7] })
    }
}

/// Checks that `id` is `base + node` for a valid node and the payload is 8 bytes.
fn node_payload(
    id: u16,
    payload: &[u8],
    base: u16,
    expected: &'static str,
) -> Result<(FingerId, [u8; 8]), ProtocolError> {
    let node = id
        .checked_sub(base)
        .filter(|n| *n < u16::from(NUM_FINGERS))
        .ok_or(ProtocolError::UnexpectedId { id, expected })?;
    let data: [u8; 8] =
        payload.try_into().map_err(|_| ProtocolError::BadLength { id, len: payload.len(), expected: 8 })?;
    // `node < NUM_FINGERS` was checked above, so the narrowing is exact.
    Ok((FingerId(node as u8), data))
}

fn put_angles(data: &mut [u8; 8], angles_rad: &[f32; 3]) -> Result<(), ProtocolError> {
    let max_rad = f32::from(i16::MAX) * ANGLE_RAD_PER_COUNT;
    for (chunk, &value_rad) in data.chunks_exact_mut(2).zip(angles_rad) {
        if !value_rad.is_finite() || value_rad.abs() > max_rad {
            return Err(ProtocolError::AngleOutOfRange { value_rad, max_rad });
        }
        let counts = (value_rad / ANGLE_RAD_PER_COUNT).round() as i16;
        chunk.copy_from_slice(&counts.to_le_bytes());
    }
    Ok(())
}

fn get_angles(data: &[u8; 8]) -> [f32; 3] {
    let angle =
        |i: usize| f32::from(i16::from_le_bytes([data[2 * i], data[2 * i + 1]])) * ANGLE_RAD_PER_COUNT;
    [angle(0), angle(1), angle(2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn finger(i: u8) -> FingerId {
        FingerId::new(i).expect("valid finger")
    }

    #[test]
    fn command_round_trips_within_one_count() {
        let cmd =
            JointCommand { finger: finger(3), q_target_rad: [0.31416, -1.2, 3.2], enable: true, seq: 250 };
        let frame = cmd.encode().expect("encodes");
        assert_eq!(frame.id, 0x103);
        let back = JointCommand::decode(frame.id, &frame.data).expect("decodes");
        assert_eq!(back.finger, cmd.finger);
        assert!(back.enable);
        assert_eq!(back.seq, 250);
        for (a, b) in back.q_target_rad.iter().zip(cmd.q_target_rad) {
            assert!((a - b).abs() <= ANGLE_RAD_PER_COUNT / 2.0 + 1e-7, "{a} vs {b}");
        }
    }

    #[test]
    fn angles_are_little_endian_counts() {
        let state = JointState { finger: finger(0), q_rad: [0.0001, -0.0001, 0.0256], status: 1, seq: 7 };
        let frame = state.encode().expect("encodes");
        assert_eq!(frame.id, 0x180);
        assert_eq!(frame.data, [1, 0, 0xff, 0xff, 0, 1, 1, 7]);
    }

    #[test]
    fn rejects_bad_frames_without_panicking() {
        assert_eq!(FingerId::new(5), Err(ProtocolError::BadFinger(5)));
        assert!(matches!(JointCommand::decode(0x105, &[0; 8]), Err(ProtocolError::UnexpectedId { .. })));
        assert!(matches!(JointCommand::decode(0x180, &[0; 8]), Err(ProtocolError::UnexpectedId { .. })));
        assert!(matches!(JointState::decode(0x17f, &[0; 8]), Err(ProtocolError::UnexpectedId { .. })));
        assert!(matches!(JointState::decode(0x181, &[0; 7]), Err(ProtocolError::BadLength { len: 7, .. })));
        let nan =
            JointCommand { finger: finger(1), q_target_rad: [f32::NAN, 0.0, 0.0], enable: false, seq: 0 };
        assert!(matches!(nan.encode(), Err(ProtocolError::AngleOutOfRange { .. })));
        let far = JointCommand { finger: finger(1), q_target_rad: [0.0, 3.3, 0.0], enable: false, seq: 0 };
        assert!(matches!(far.encode(), Err(ProtocolError::AngleOutOfRange { .. })));
    }
}
