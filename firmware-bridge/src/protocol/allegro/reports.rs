//! Hand-to-host frames: joint positions, joint temperatures, info, serial number, status.

use super::config::Kind;
use super::frame::{le_bytes, le_words};
use super::units::{counts_to_rad, rad_to_counts};
use super::{AllegroConfig, AllegroError, AllegroFrame, Finger, JOINTS_PER_FINGER, Request};

/// Joint angles of one finger (sent every position period, or on request).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FingerPosition {
    pub finger: Finger,
    /// Joints 0..=3; 333.3/65536 degrees per count on the wire.
    pub q_rad: [f32; JOINTS_PER_FINGER],
}

/// Motor temperatures of one finger's joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FingerTemperature {
    pub finger: Finger,
    /// Joints 0..=3, whole degrees Celsius (signed bytes).
    pub temperature_c: [i8; JOINTS_PER_FINGER],
}

/// Which hand: the info frame's L/R byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Handedness {
    Right,
    Left,
    /// A value the protocol does not define; kept, not dropped.
    Other(u8),
}

impl Handedness {
    fn from_u8(v: u8) -> Self {
        match v {
            0 => Handedness::Right,
            1 => Handedness::Left,
            v => Handedness::Other(v),
        }
    }

    fn to_u8(self) -> u8 {
        match self {
            Handedness::Right => 0,
            Handedness::Left => 1,
            Handedness::Other(v) => v,
        }
    }
}

/// The hand's status bits (the status frame, and the last byte of the info frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Status {
    pub bits: u8,
}

impl Status {
    /// Servos on.
    pub const SERVO_ON: u8 = 0x01;
    /// One or more joints in high-temperature fault.
    pub const JOINT_OVER_TEMPERATURE: u8 = 0x02;
    /// One or more joints throttled for temperature (the user manual; the drivers print
    /// this bit as "internal communication fault").
    pub const JOINT_THROTTLED: u8 = 0x04;
    /// One or more joints in communication timeout.
    pub const COMMUNICATION_TIMEOUT: u8 = 0x08;
    /// Palm in high-temperature fault.
    pub const PALM_OVER_TEMPERATURE: u8 = 0x10;

    /// Whether the servos are on.
    pub fn servo_on(self) -> bool {
        self.bits & Self::SERVO_ON != 0
    }

    /// Whether any fault or warning bit is set (bits 1 to 4). Bit 2 counts under either
    /// reading of it (throttling, or a communication fault).
    pub fn fault(self) -> bool {
        self.bits & 0x1E != 0
    }
}

/// Versions, handedness, palm temperature and status (answer to [`Request::Info`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Info {
    pub hardware_version: u16,
    pub firmware_version: u16,
    pub hand: Handedness,
    pub palm_temperature_c: i8,
    pub status: Status,
}

impl Info {
    /// The hardware version's high byte, the hand's generation (4 on a v4): the drivers pick
    /// the torque scale from it ([`super::TorqueScale::for_hardware`]).
    pub fn hardware_major(&self) -> u8 {
        self.hardware_version.to_be_bytes()[0]
    }
}

/// The serial number, 8 ASCII characters (answer to [`Request::Serial`]). The drivers print
/// it after a `SAH0x0` prefix that is not on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Serial {
    pub ascii: [u8; 8],
}

impl Serial {
    /// The characters without trailing NULs or spaces; `None` if they are not UTF-8.
    pub fn as_str(&self) -> Option<&str> {
        core::str::from_utf8(&self.ascii).ok().map(|s| s.trim_end_matches(['\0', ' ']))
    }
}

/// A frame from the hand to the host.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Report {
    Position(FingerPosition),
    Temperature(FingerTemperature),
    Info(Info),
    Serial(Serial),
    Status(Status),
}

impl Report {
    /// The request this report answers (and whose id it carries).
    pub fn request(&self) -> Request {
        match self {
            Report::Position(p) => Request::Position(p.finger),
            Report::Temperature(t) => Request::Temperature(t.finger),
            Report::Info(_) => Request::Info,
            Report::Serial(_) => Request::Serial,
            Report::Status(_) => Request::Status,
        }
    }

    /// The data frame carrying this report (the hand's, or an emulator's, side). Fails only
    /// for a joint angle that is not finite or outside the i16 range (±2.9086 rad).
    pub fn encode(&self, cfg: &AllegroConfig) -> Result<AllegroFrame, AllegroError> {
        let id = cfg.can_id(self.request().message_id(&cfg.ids));
        match self {
            Report::Position(p) => {
                let mut counts = [0u16; JOINTS_PER_FINGER];
                for (c, &q) in counts.iter_mut().zip(&p.q_rad) {
                    *c = rad_to_counts(q)? as u16;
                }
                AllegroFrame::data(id, &le_bytes(counts))
            }
            Report::Temperature(t) => AllegroFrame::data(id, &t.temperature_c.map(|c| c as u8)),
            Report::Info(i) => {
                let [hw_lo, hw_hi] = i.hardware_version.to_le_bytes();
                let [fw_lo, fw_hi] = i.firmware_version.to_le_bytes();
                let data =
                    [hw_lo, hw_hi, fw_lo, fw_hi, i.hand.to_u8(), i.palm_temperature_c as u8, i.status.bits];
                AllegroFrame::data(id, &data)
            }
            Report::Serial(s) => AllegroFrame::data(id, &s.ascii),
            Report::Status(s) => AllegroFrame::data(id, &[s.bits]),
        }
    }

    /// Decodes a data frame the hand sent. Unknown ids, other devices, wrong lengths and
    /// command ids are typed errors, never panics.
    pub fn decode(cfg: &AllegroConfig, id: u16, data: &[u8]) -> Result<Self, AllegroError> {
        let kind = cfg.kind(id)?;
        let expected: u8 = match kind {
            Kind::Position(_) | Kind::Serial => 8,
            Kind::Info => 7,
            Kind::Temperature(_) => 4,
            Kind::Status => 1,
            Kind::ServoOn | Kind::ServoOff | Kind::SetTorque(_) | Kind::SetPeriod => {
                return Err(AllegroError::WrongDirection { id, kind: kind.name() });
            }
        };
        if data.len() != usize::from(expected) {
            return Err(AllegroError::BadLength { id, len: data.len(), expected });
        }
        let mut d = [0u8; 8];
        for (b, x) in d.iter_mut().zip(data) {
            *b = *x;
        }
        Ok(match kind {
            Kind::Position(finger) => {
                let q_rad = le_words(&d).map(|w| counts_to_rad(w as i16));
                Report::Position(FingerPosition { finger, q_rad })
            }
            Kind::Temperature(finger) => Report::Temperature(FingerTemperature {
                finger,
                temperature_c: [d[0] as i8, d[1] as i8, d[2] as i8, d[3] as i8],
            }),
            Kind::Info => Report::Info(Info {
                hardware_version: u16::from_le_bytes([d[0], d[1]]),
                firmware_version: u16::from_le_bytes([d[2], d[3]]),
                hand: Handedness::from_u8(d[4]),
                palm_temperature_c: d[5] as i8,
                status: Status { bits: d[6] },
            }),
            Kind::Serial => Report::Serial(Serial { ascii: d }),
            _ => Report::Status(Status { bits: d[0] }),
        })
    }

    /// Decodes an [`AllegroFrame`]; a remote frame is a request, not a report.
    pub fn decode_frame(cfg: &AllegroConfig, frame: &AllegroFrame) -> Result<Self, AllegroError> {
        if frame.is_remote() {
            let kind = cfg.kind(frame.id())?;
            return Err(AllegroError::WrongDirection { id: frame.id(), kind: kind.name() });
        }
        Self::decode(cfg, frame.id(), frame.payload())
    }
}

#[cfg(test)]
mod tests {
    use super::super::POSITION_RAD_PER_COUNT;
    use super::*;

    const CFG: AllegroConfig = AllegroConfig::V4;

    #[test]
    fn known_bytes_of_a_position_frame() {
        // Index finger: counts 1000, -1000, 0, 32767.
        let data = [0xE8, 0x03, 0x18, 0xFC, 0, 0, 0xFF, 0x7F];
        let Ok(Report::Position(p)) = Report::decode(&CFG, 0x080, &data) else {
            panic!("a position frame");
        };
        assert_eq!(p.finger, Finger::Index);
        let expected = [1000.0, -1000.0, 0.0, 32767.0].map(|c: f64| (c * POSITION_RAD_PER_COUNT) as f32);
        assert_eq!(p.q_rad, expected);
        assert!((p.q_rad[0] - 0.088_763_16).abs() < 1e-7);
        let frame = Report::Position(p).encode(&CFG).expect("in range");
        assert_eq!((frame.id(), frame.payload()), (0x080, &data[..]));
    }

    #[test]
    fn known_bytes_of_info_serial_temperature_status() {
        let info = [0x00, 0x04, 0x12, 0x03, 0x01, 0x1F, 0x03];
        assert_eq!(
            Report::decode(&CFG, 0x200, &info),
            Ok(Report::Info(Info {
                hardware_version: 0x0400,
                firmware_version: 0x0312,
                hand: Handedness::Left,
                palm_temperature_c: 31,
                status: Status { bits: Status::SERVO_ON | Status::JOINT_OVER_TEMPERATURE },
            }))
        );
        let Ok(Report::Info(i)) = Report::decode(&CFG, 0x200, &info) else { panic!("info") };
        assert_eq!(i.hardware_major(), 4);
        assert!(i.status.servo_on() && i.status.fault());
        let Ok(Report::Serial(s)) = Report::decode(&CFG, 0x220, b"AR011\0\0\0") else { panic!("serial") };
        assert_eq!(s.as_str(), Some("AR011"));
        assert_eq!(Serial { ascii: [0xFF; 8] }.as_str(), None);
        assert_eq!(
            Report::decode(&CFG, 0x0EC, &[40, 41, 0xFF, 0]),
            Ok(Report::Temperature(FingerTemperature {
                finger: Finger::Thumb,
                temperature_c: [40, 41, -1, 0]
            }))
        );
        assert_eq!(Report::decode(&CFG, 0x040, &[0x01]), Ok(Report::Status(Status { bits: 1 })));
        assert!(!Status { bits: Status::SERVO_ON }.fault());
    }

    #[test]
    fn every_report_round_trips() {
        let reports = [
            Report::Position(FingerPosition { finger: Finger::Ring, q_rad: [0.1, -0.2, 1.5, 2.9] }),
            Report::Temperature(FingerTemperature {
                finger: Finger::Middle,
                temperature_c: [25, 26, -3, 127],
            }),
            Report::Info(Info {
                hardware_version: 0x0401,
                firmware_version: 0x0100,
                hand: Handedness::Other(7),
                palm_temperature_c: -5,
                status: Status { bits: 0x1F },
            }),
            Report::Serial(Serial { ascii: *b"BR012345" }),
            Report::Status(Status { bits: 0x08 }),
        ];
        for r in reports {
            let frame = r.encode(&CFG).expect("encodes");
            let back = Report::decode_frame(&CFG, &frame).expect("decodes");
            assert_eq!(back.encode(&CFG), Ok(frame), "{r:?}");
            match (r, back) {
                (Report::Position(a), Report::Position(b)) => {
                    assert_eq!(a.finger, b.finger);
                    for (x, y) in a.q_rad.iter().zip(b.q_rad) {
                        assert!(((x - y) as f64).abs() <= 0.5 * POSITION_RAD_PER_COUNT + 1e-7, "{x} {y}");
                    }
                }
                (a, b) => assert_eq!(a, b),
            }
        }
        let too_far = Report::Position(FingerPosition { finger: Finger::Index, q_rad: [3.0, 0.0, 0.0, 0.0] });
        assert!(matches!(too_far.encode(&CFG), Err(AllegroError::OutOfRange { what: "q_rad", .. })));
    }

    #[test]
    fn bad_frames_are_refused_with_their_reason() {
        assert_eq!(
            Report::decode(&CFG, 0x080, &[0; 7]),
            Err(AllegroError::BadLength { id: 0x080, len: 7, expected: 8 })
        );
        assert_eq!(
            Report::decode(&CFG, 0x200, &[0; 8]),
            Err(AllegroError::BadLength { id: 0x200, len: 8, expected: 7 })
        );
        assert_eq!(
            Report::decode(&CFG, 0x0E0, &[0; 8]),
            Err(AllegroError::BadLength { id: 0x0E0, len: 8, expected: 4 })
        );
        assert_eq!(
            Report::decode(&CFG, 0x040, &[]),
            Err(AllegroError::BadLength { id: 0x040, len: 0, expected: 1 })
        );
        assert_eq!(
            Report::decode(&CFG, 0x180, &[0; 8]),
            Err(AllegroError::WrongDirection { id: 0x180, kind: "set torque" })
        );
        assert_eq!(Report::decode(&CFG, 0x090, &[0; 8]), Err(AllegroError::UnknownId(0x090)));
        assert_eq!(
            Report::decode(&CFG, 0x081, &[0; 8]),
            Err(AllegroError::OtherDevice { id: 0x081, device: 1, expected: 0 })
        );
        let rtr = AllegroFrame::remote(0x200);
        assert_eq!(
            Report::decode_frame(&CFG, &rtr),
            Err(AllegroError::WrongDirection { id: 0x200, kind: "info" })
        );
    }
}
