//! The CAN protocol between the bridge (host) and the hand's per-finger nodes.
//!
//! `no_std`: the same code runs in the bridge and can run in a joint controller's firmware.
//! Every frame is a classic CAN data frame with an 11-bit id and 8 data bytes; multi-byte
//! fields are little-endian. Each finger is one node driving its three joints (vge15: roll,
//! proximal flexion, distal flexion) and reading its fingertip sensor; node `f` is the hand
//! description's finger `f`, its joints the description's `3f..3f+3`. The hand decides how many
//! nodes there are ([`NodeLayout`]: vge15 has five, `FingerId` 0..=4), up to [`MAX_FINGERS`].
//! The id is a function code plus the node, CANopen-style, so that commands win arbitration:
//!
//! | frame            | id           | dir          | payload                                             |
//! |------------------|--------------|--------------|-----------------------------------------------------|
//! | fault            | 0x080 + node | node -> host | code u16, joint u8, value i16, reserved, seq u8    |
//! | joint command    | 0x100 + node | host -> node | q_target[3] i16 (1e-4 rad), flags u8, seq u8        |
//! | joint position   | 0x180 + node | node -> host | q[3] i16 (1e-4 rad), status u8, seq u8              |
//! | joint velocity   | 0x200 + node | node -> host | dq[3] i16 (1e-3 rad/s), reserved u8, seq u8         |
//! | joint effort     | 0x280 + node | node -> host | tau[3] i16 (1e-4 N·m), reserved u8, seq u8          |
//! | tip contact      | 0x300 + node | node -> host | p[3] i16 (1e-4 m, hand frame), force u16 (1e-3 N)   |
//! | tip normal       | 0x380 + node | node -> host | n[3] i16 (1/32767), flags u8, seq u8                |
//! | joint target     | 0x400 + node | node -> host | q_target[3] i16 (1e-4 rad), reserved u8, seq u8     |
//! | heartbeat        | 0x700 + node | both         | state u8, counter u8, reserved[6]                   |
//!
//! The host's heartbeat uses node 0x0F. `seq` in node frames is the sequence number of the
//! last joint command the node applied. `docs/can-protocol.md` is the full description
//! (with bus load) and `docs/vge-hand.dbc` describes the same frames for CAN tools.

pub mod allegro;
pub mod fd;
mod fields;
mod messages;

pub use fields::{
    ANGLE_RAD_PER_COUNT, EFFORT_NM_PER_COUNT, FORCE_N_PER_COUNT, NORMAL_PER_COUNT, POSITION_M_PER_COUNT,
    VELOCITY_RADPS_PER_COUNT,
};
pub use messages::*;

/// Period of every node's and the host's heartbeat (10 Hz).
pub const HEARTBEAT_PERIOD_MS: u32 = 100;

/// SocketCAN receive filters, `(id, mask)` as `struct can_filter` takes them: a frame passes
/// when `frame_id & mask == id & mask`. The masks include the extended-frame and remote-frame
/// flags, so only standard data frames pass. Each side's socket lets through only the ids it
/// reads: the kernel drops everything else (another protocol's traffic, a babbling node, a
/// flood) before it costs the control loop a system call.
pub mod filters {
    use super::fd::{FD_HAND_COMMAND_ID, FD_NODE_STATE_BASE_ID};
    use super::ids;

    /// `CAN_EFF_FLAG | CAN_RTR_FLAG`: a filter with these in its mask and not in its id
    /// rejects extended and remote frames.
    const FLAGS: u32 = 0x8000_0000 | 0x4000_0000;
    /// The function code's 8 ids (`code + 0..=7`): every node a hand may have
    /// ([`MAX_FINGERS`](super::MAX_FINGERS)); vge15 uses five.
    const CODE: u32 = FLAGS | 0x7F8;
    /// Exactly one id.
    const EXACT: u32 = FLAGS | 0x7FF;

    /// What the host (bridge) reads: every node frame, classic and FD, and node heartbeats.
    pub const HOST_RX: [(u32, u32); 9] = [
        (ids::FAULT as u32, CODE),
        (ids::JOINT_POSITION as u32, CODE),
        (ids::JOINT_VELOCITY as u32, CODE),
        (ids::JOINT_EFFORT as u32, CODE),
        (ids::TIP_CONTACT as u32, CODE),
        (ids::TIP_NORMAL as u32, CODE),
        (ids::JOINT_TARGET as u32, CODE),
        (FD_NODE_STATE_BASE_ID as u32, CODE),
        (ids::HEARTBEAT as u32, CODE),
    ];

    /// What the finger nodes read: joint commands, the FD hand command, the host heartbeat.
    pub const NODE_RX: [(u32, u32); 3] = [
        (ids::JOINT_COMMAND as u32, CODE),
        (FD_HAND_COMMAND_ID as u32, EXACT),
        ((ids::HEARTBEAT + super::HOST_NODE as u16) as u32, EXACT),
    ];

    /// Whether a standard data frame with `id` passes `filters` (the kernel's rule).
    pub fn passes(filters: &[(u32, u32)], id: u16) -> bool {
        filters.iter().any(|&(f, mask)| u32::from(id) & mask == f & mask)
    }
}

/// The most finger nodes a hand on this protocol may have: each function code has eight node
/// ids (`code + 0..=7`, the receive filters' mask), and the host's node (0x0F) lies outside
/// them. A hand's own count is its [`NodeLayout`]; fixed-capacity tables (`no_std`) hold this
/// many.
pub const MAX_FINGERS: u8 = 8;
/// Joints each finger node drives: a joint command or state frame carries three.
pub const JOINTS_PER_NODE: usize = 3;
/// Node id of the host (the bridge) in heartbeat frames.
pub const HOST_NODE: u8 = 0x0F;

/// Function codes: the id of a frame is `code + node`.
pub mod ids {
    pub const FAULT: u16 = 0x080;
    pub const JOINT_COMMAND: u16 = 0x100;
    pub const JOINT_POSITION: u16 = 0x180;
    pub const JOINT_VELOCITY: u16 = 0x200;
    pub const JOINT_EFFORT: u16 = 0x280;
    pub const TIP_CONTACT: u16 = 0x300;
    pub const TIP_NORMAL: u16 = 0x380;
    /// A node's active targets, sent in reply to a disabled (query) command, so the bridge
    /// starts from the targets that hold the current grasp instead of releasing it.
    pub const JOINT_TARGET: u16 = 0x400;
    pub const HEARTBEAT: u16 = 0x700;
}

/// Errors decoding or encoding frames. Frames come from a bus: nothing here panics on them.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ProtocolError {
    #[error("finger id {0} out of range (0..{MAX_FINGERS})")]
    BadFinger(u8),
    /// A hand this protocol cannot carry (fingers that are not three joints each, or more
    /// fingers than node ids).
    #[error("{fingers} finger nodes: the protocol carries 1 to {MAX_FINGERS}")]
    BadNodeCount { fingers: usize },
    #[error("frame id {0:#05x} is not part of the hand protocol")]
    UnknownId(u16),
    #[error("frame id {id:#05x} has {len} data bytes, expected 8")]
    BadLength { id: u16, len: usize },
    #[error("{what} = {value} is not finite or outside {min}..={max} (the field's range)")]
    OutOfRange { what: &'static str, value: f32, min: f32, max: f32 },
}

/// A finger node on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FingerId(u8);

impl FingerId {
    /// Node `index`, any of the protocol's [`MAX_FINGERS`]; whether the hand has it is the
    /// hand's [`NodeLayout`]'s to say.
    pub fn new(index: u8) -> Result<Self, ProtocolError> {
        if index < MAX_FINGERS { Ok(Self(index)) } else { Err(ProtocolError::BadFinger(index)) }
    }

    pub fn index(self) -> u8 {
        self.0
    }

    /// The node's index as a table index.
    pub fn slot(self) -> usize {
        usize::from(self.0)
    }
}

/// The finger nodes of one hand on this protocol: how many (each [`JOINTS_PER_NODE`] joints),
/// from the hand's description. vge15's is [`NodeLayout::VGE15`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct NodeLayout {
    fingers: u8,
}

impl NodeLayout {
    /// vge's own hand: five fingers of three joints.
    pub const VGE15: Self = Self { fingers: 5 };

    /// A hand of `fingers` nodes, 1 to [`MAX_FINGERS`].
    pub fn new(fingers: usize) -> Result<Self, ProtocolError> {
        match u8::try_from(fingers) {
            Ok(n) if (1..=MAX_FINGERS).contains(&n) => Ok(Self { fingers: n }),
            _ => Err(ProtocolError::BadNodeCount { fingers }),
        }
    }

    pub fn num_fingers(self) -> usize {
        usize::from(self.fingers)
    }

    pub fn num_joints(self) -> usize {
        self.num_fingers() * JOINTS_PER_NODE
    }

    /// Whether `finger` is one of this hand's nodes.
    pub fn has(self, finger: FingerId) -> bool {
        finger.0 < self.fingers
    }

    /// The hand's fingers, in node order.
    pub fn fingers(self) -> impl Iterator<Item = FingerId> {
        (0..self.fingers).map(FingerId)
    }

    /// Frames per control step with every node reporting: one command per finger, and
    /// position, velocity, effort, tip contact and tip normal from each.
    pub fn frames_per_step(self) -> u32 {
        u32::from(self.fingers) * 6
    }

    /// Fraction of a bus of `bitrate_bps` that the protocol uses at `rate_hz` control steps
    /// per second (heartbeats at 10 Hz per node and the host's included), with worst-case bit
    /// stuffing.
    pub fn bus_load(self, rate_hz: f64, bitrate_bps: f64) -> f64 {
        let heartbeats_per_s = 10.0 * f64::from(self.fingers + 1);
        let frames_per_s = rate_hz * f64::from(self.frames_per_step()) + heartbeats_per_s;
        frames_per_s * f64::from(WORST_CASE_FRAME_BITS) / bitrate_bps
    }
}

/// A classic CAN frame's identifier and payload, independent of the socket layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFrame {
    pub id: u16,
    pub data: [u8; 8],
}

/// Worst-case bits on the wire of a classic data frame with an 11-bit id and 8 data bytes:
/// 44 bits of framing + 64 data bits + 3 bits interframe space, plus one stuff bit per four
/// bits over the 98 stuffable bits (SOF to CRC).
pub const WORST_CASE_FRAME_BITS: u32 = 44 + 64 + 3 + (34 + 64 - 1) / 4;

/// [`NodeLayout::bus_load`] of vge15's five nodes.
pub fn bus_load(rate_hz: f64, bitrate_bps: f64) -> f64 {
    NodeLayout::VGE15.bus_load(rate_hz, bitrate_bps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filters_pass_each_side_exactly_the_frames_it_reads() {
        use filters::{HOST_RX, NODE_RX, passes};
        for f in (0..MAX_FINGERS).map(FingerId) {
            let n = u16::from(f.index());
            for code in [ids::FAULT, ids::JOINT_POSITION, ids::JOINT_VELOCITY, ids::JOINT_EFFORT] {
                assert!(passes(&HOST_RX, code + n) && !passes(&NODE_RX, code + n));
            }
            for code in [ids::TIP_CONTACT, ids::TIP_NORMAL, ids::JOINT_TARGET, ids::HEARTBEAT, 0x480] {
                assert!(passes(&HOST_RX, code + n) && !passes(&NODE_RX, code + n));
            }
            assert!(passes(&NODE_RX, ids::JOINT_COMMAND + n) && !passes(&HOST_RX, ids::JOINT_COMMAND + n));
        }
        assert!(passes(&NODE_RX, 0x70F) && passes(&NODE_RX, 0x0F0));
        assert!(!passes(&HOST_RX, 0x70F), "the host does not read its own heartbeat");
        for junk in [0x000, 0x001, 0x555, 0x7FF, 0x0F1, 0x700 + 0x0E] {
            assert!(!passes(&HOST_RX, junk) && !passes(&NODE_RX, junk), "{junk:#x}");
        }
    }

    #[test]
    fn bus_load_at_the_default_rate_is_far_below_the_limit() {
        assert_eq!(WORST_CASE_FRAME_BITS, 135);
        // 20 Hz (the default control rate): (20 * 30 + 60) frames/s * 135 bits = 8.9%.
        assert!((bus_load(20.0, 1e6) - 0.0891).abs() < 1e-9);
        // 30 Hz: (30 * 30 + 60) frames/s * 135 bits = 129,600 bit/s = 13% of 1 Mbit/s.
        let load = bus_load(30.0, 1e6);
        assert!((load - 0.1296).abs() < 1e-9, "{load}");
        // 1 kHz does not fit a classic bus: that is what the CAN FD option is for.
        assert!(bus_load(1000.0, 1e6) > 1.0);
        // Eight nodes: (20 * 48 + 90) frames/s * 135 bits = 14.2%.
        let eight = NodeLayout::new(8).expect("eight nodes");
        assert!((eight.bus_load(20.0, 1e6) - 0.14175).abs() < 1e-9);
    }

    #[test]
    fn a_hand_has_one_to_eight_nodes_and_fingers_past_its_count_are_not_its_own() {
        assert_eq!(NodeLayout::new(5), Ok(NodeLayout::VGE15));
        assert_eq!(NodeLayout::VGE15.num_joints(), 15);
        assert_eq!(NodeLayout::VGE15.frames_per_step(), 30);
        for bad in [0, 9, 300] {
            assert_eq!(NodeLayout::new(bad), Err(ProtocolError::BadNodeCount { fingers: bad }));
        }
        let four = NodeLayout::new(4).expect("four");
        let f4 = FingerId::new(4).expect("node 4 exists on the bus");
        assert!(!four.has(f4) && NodeLayout::VGE15.has(f4));
        assert_eq!(four.fingers().map(FingerId::index).collect::<heapless::Vec<u8, 8>>(), [0, 1, 2, 3]);
        assert_eq!(FingerId::new(MAX_FINGERS), Err(ProtocolError::BadFinger(MAX_FINGERS)));
    }
}
