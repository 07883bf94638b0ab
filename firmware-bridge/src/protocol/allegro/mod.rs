//! The Allegro Hand's own CAN protocol (Wonik Robotics, "CAN Protocol v4.0"), host side and
//! hand side, for a bridge that drives a real Allegro Hand v4 and for an emulator of one.
//!
//! `no_std`, no allocation, no panics on bus input. Classic CAN at 1 Mbit/s, 11-bit ids
//! `(message_id << 2) | device_id`, little-endian fields. Frames are plain data: host-to-hand
//! [`Command`]s and hand-to-host [`Report`]s, each encoded into an [`AllegroFrame`] and decoded
//! from `(id, data)` with an [`AllegroConfig`] (which ids, which device, which torque scale).
//! [`Command::decode`] reads a remote (RTR) frame as its id with empty data.
//!
//! | frame (default ids, device 0) | id            | dir          | DLC | payload                                        |
//! |-------------------------------|---------------|--------------|-----|------------------------------------------------|
//! | status                        | 0x040         | hand -> host | 1   | status bits                                    |
//! | position, finger f            | 0x080 + 4 f   | hand -> host | 8   | q[4] i16, 333.3/65536 deg per count            |
//! | temperature, finger f         | 0x0E0 + 4 f   | hand -> host | 4   | joint temperature[4] i8, deg C                 |
//! | servo on / servo off          | 0x100 / 0x104 | host -> hand | 0   | none                                           |
//! | set torque, finger f          | 0x180 + 4 f   | host -> hand | 8   | pwm[4] i16, 1200 counts per N·m, clipped       |
//! | info                          | 0x200         | hand -> host | 7   | hw u16, fw u16, L/R u8, palm temp i8, status   |
//! | set period                    | 0x204         | host -> hand | 6   | position, IMU, temperature periods u16 ms      |
//! | serial                        | 0x220         | hand -> host | 8   | ASCII[8]                                       |
//!
//! The host asks for info, serial, positions, temperatures and status with remote frames at
//! the id of the answer. `docs/allegro-protocol.md` is the full description with its sources
//! and the choices where they disagree; `docs/allegro-v4.dbc` describes the same frames for
//! CAN tools. Joint order everywhere: fingers index, middle, ring, thumb (the hand's fingers
//! 0..=3), joints 0..=3 within a finger, so a 16-vector is `4 * finger + joint`.
//!
//! The ids overlap vge's own protocol ([`super::ids`]): one bus carries one of the two.

mod commands;
mod config;
mod frame;
mod reports;
mod session;
mod units;

pub use commands::{Command, Request, SetPeriod, SetTorque};
pub use config::{AllegroConfig, AllegroIds, PeriodLayout};
pub use frame::AllegroFrame;
pub use reports::{FingerPosition, FingerTemperature, Handedness, Info, Report, Serial, Status};
pub use session::{
    CONTROL_PERIOD_MS, PositionCycle, SHUTDOWN_COMMANDS, STARTUP_COMMANDS, TEMPERATURE_PERIOD_MS,
    torque_commands,
};
pub use units::{
    POSITION_DEG_PER_COUNT, POSITION_RAD_PER_COUNT, PwmCounts, TorqueScale, counts_to_rad, rad_to_counts,
};

/// Fingers on the hand.
pub const NUM_FINGERS: usize = 4;
/// Joints per finger.
pub const JOINTS_PER_FINGER: usize = 4;
/// Joints on the hand: the length of a joint vector.
pub const NUM_JOINTS: usize = NUM_FINGERS * JOINTS_PER_FINGER;

/// A finger, in the hand's own order (its CAN frames' finger index 0..=3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Finger {
    Index,
    Middle,
    Ring,
    Thumb,
}

impl Finger {
    /// All fingers in frame order.
    pub const ALL: [Finger; NUM_FINGERS] = [Finger::Index, Finger::Middle, Finger::Ring, Finger::Thumb];

    /// The finger with frame index `index` (0..=3).
    pub fn new(index: u8) -> Result<Self, AllegroError> {
        Self::ALL.get(usize::from(index)).copied().ok_or(AllegroError::BadFinger(index))
    }

    /// The finger's index in frame ids and joint vectors (0..=3).
    pub fn index(self) -> u8 {
        self as u8
    }

    /// Position of `joint` (0..=3) of this finger in a 16-vector.
    pub fn joint_index(self, joint: usize) -> usize {
        usize::from(self.index()) * JOINTS_PER_FINGER + joint
    }
}

/// The device id in the low two bits of every frame id: up to four hands share a bus.
/// A hand leaves the factory as device 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct DeviceId(u8);

impl DeviceId {
    pub fn new(id: u8) -> Result<Self, AllegroError> {
        if id <= 3 { Ok(Self(id)) } else { Err(AllegroError::BadDevice(id)) }
    }

    pub fn get(self) -> u8 {
        self.0
    }
}

/// Errors encoding or decoding Allegro frames. Frames come from a bus: nothing here panics.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum AllegroError {
    #[error("frame id {0:#05x} is not a frame of the Allegro protocol")]
    UnknownId(u16),
    #[error("frame id {id:#05x} is a {kind} frame, which travels the other way")]
    WrongDirection { id: u16, kind: &'static str },
    #[error("frame id {id:#05x} is from device {device}; this hand is device {expected}")]
    OtherDevice { id: u16, device: u8, expected: u8 },
    #[error("frame id {id:#05x} has {len} data bytes, expected {expected}")]
    BadLength { id: u16, len: usize, expected: u8 },
    #[error("a classic CAN frame carries at most 8 data bytes, not {0}")]
    TooLong(usize),
    #[error("finger {0} out of range (0..=3)")]
    BadFinger(u8),
    #[error("device id {0} out of range (0..=3)")]
    BadDevice(u8),
    #[error("torque for finger {finger} joint {joint} is {value}, not a finite number")]
    NonFiniteTorque { finger: u8, joint: u8, value: f32 },
    #[error("{what} = {value} is not finite or outside {min}..={max} (the field's range)")]
    OutOfRange { what: &'static str, value: f32, min: f32, max: f32 },
    #[error("{0} is not sent in the configured set-period layout; it must be 0")]
    NotInLayout(&'static str),
    #[error("invalid configuration: {0}")]
    BadConfig(&'static str),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingers_and_devices_in_range_only() {
        assert_eq!(Finger::new(3), Ok(Finger::Thumb));
        assert_eq!(Finger::new(4), Err(AllegroError::BadFinger(4)));
        assert_eq!(Finger::Ring.joint_index(2), 10);
        assert_eq!(Finger::ALL.map(Finger::index), [0, 1, 2, 3]);
        assert_eq!(DeviceId::new(3).map(DeviceId::get), Ok(3));
        assert_eq!(DeviceId::new(4), Err(AllegroError::BadDevice(4)));
    }
}
