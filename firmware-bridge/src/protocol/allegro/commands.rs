//! Host-to-hand frames: servo on/off, set torque, set period, and remote requests.

use super::config::Kind;
use super::frame::{le_bytes, le_words};
use super::{AllegroConfig, AllegroError, AllegroFrame, AllegroIds, Finger, JOINTS_PER_FINGER, PeriodLayout};

/// What the host asks for with a remote frame; the hand answers with the data frame of the
/// same id (a [`super::Report`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    Info,
    Serial,
    Position(Finger),
    Temperature(Finger),
    Status,
}

impl Request {
    /// The message id of the request and of its answer.
    pub fn message_id(self, ids: &AllegroIds) -> u16 {
        // Wrapping: an unvalidated id set must not panic; `can_id` keeps 9 bits.
        match self {
            Request::Info => ids.info,
            Request::Serial => ids.serial,
            Request::Position(f) => ids.position.wrapping_add(u16::from(f.index())),
            Request::Temperature(f) => ids.temperature.wrapping_add(u16::from(f.index())),
            Request::Status => ids.status,
        }
    }
}

/// Torque set-points of one finger's four joints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetTorque {
    pub finger: Finger,
    /// Joint torques (joints 0..=3). Encoding clips each to its joint's limit
    /// ([`super::TorqueScale`]) and refuses a non-finite one.
    pub tau_nm: [f32; JOINTS_PER_FINGER],
}

/// How often the hand sends each kind of report, in ms; 0 stops that report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SetPeriod {
    pub position_ms: u16,
    pub imu_ms: u16,
    pub temperature_ms: u16,
    /// Sent only in the user manual's 8-byte layout ([`PeriodLayout::FourFields`]); must be 0
    /// in the drivers' 6-byte layout.
    pub status_ms: u16,
}

impl SetPeriod {
    /// Every periodic report off.
    pub const OFF: Self = Self { position_ms: 0, imu_ms: 0, temperature_ms: 0, status_ms: 0 };
}

/// A frame from the host to the hand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Engage the joint motor drivers.
    ServoOn,
    /// Disable the joint motor drivers.
    ServoOff,
    SetTorque(SetTorque),
    SetPeriod(SetPeriod),
    /// A remote frame asking for a report.
    Request(Request),
}

impl Command {
    /// The frame carrying this command. Fails for a non-finite torque, and for a status
    /// period in the 6-byte set-period layout; a finite torque beyond its clip is clipped.
    pub fn encode(&self, cfg: &AllegroConfig) -> Result<AllegroFrame, AllegroError> {
        let ids = &cfg.ids;
        match *self {
            Command::ServoOn => AllegroFrame::data(cfg.can_id(ids.servo_on), &[]),
            Command::ServoOff => AllegroFrame::data(cfg.can_id(ids.servo_off), &[]),
            Command::SetTorque(t) => {
                let pwm = cfg.torque.to_pwm(t.finger, t.tau_nm)?;
                let id = cfg.can_id(ids.set_torque.wrapping_add(u16::from(t.finger.index())));
                AllegroFrame::data(id, &le_bytes(pwm.counts.map(|c| c as u16)))
            }
            Command::SetPeriod(p) => {
                let bytes = le_bytes([p.position_ms, p.imu_ms, p.temperature_ms, p.status_ms]);
                let id = cfg.can_id(ids.set_period);
                match cfg.period_layout {
                    PeriodLayout::ThreeFields if p.status_ms != 0 => {
                        Err(AllegroError::NotInLayout("status_ms"))
                    }
                    PeriodLayout::ThreeFields => AllegroFrame::data(id, &bytes[..6]),
                    PeriodLayout::FourFields => AllegroFrame::data(id, &bytes),
                }
            }
            Command::Request(r) => Ok(AllegroFrame::remote(cfg.can_id(r.message_id(ids)))),
        }
    }

    /// Decodes a frame the host sent (the hand's, or an emulator's, side). A remote frame
    /// decodes as its id with empty `data`. A report's id with data is
    /// [`AllegroError::WrongDirection`]; a set-period frame may have either layout's length.
    pub fn decode(cfg: &AllegroConfig, id: u16, data: &[u8]) -> Result<Self, AllegroError> {
        let kind = cfg.kind(id)?;
        let expect = |expected: u8| {
            if data.len() == usize::from(expected) {
                Ok(())
            } else {
                Err(AllegroError::BadLength { id, len: data.len(), expected })
            }
        };
        let request = |r: Request| {
            if data.is_empty() {
                Ok(Command::Request(r))
            } else {
                Err(AllegroError::WrongDirection { id, kind: kind.name() })
            }
        };
        match kind {
            Kind::ServoOn => expect(0).map(|()| Command::ServoOn),
            Kind::ServoOff => expect(0).map(|()| Command::ServoOff),
            Kind::SetTorque(finger) => {
                expect(8)?;
                let counts = le_words(data).map(|w| w as i16);
                Ok(Command::SetTorque(SetTorque { finger, tau_nm: cfg.torque.to_nm(counts) }))
            }
            Kind::SetPeriod => {
                if data.len() != 6 && data.len() != 8 {
                    return Err(AllegroError::BadLength {
                        id,
                        len: data.len(),
                        expected: cfg.period_layout.dlc(),
                    });
                }
                let [position_ms, imu_ms, temperature_ms, status_ms] = le_words(data);
                Ok(Command::SetPeriod(SetPeriod { position_ms, imu_ms, temperature_ms, status_ms }))
            }
            Kind::Info => request(Request::Info),
            Kind::Serial => request(Request::Serial),
            Kind::Position(f) => request(Request::Position(f)),
            Kind::Temperature(f) => request(Request::Temperature(f)),
            Kind::Status => request(Request::Status),
        }
    }

    /// Decodes an [`AllegroFrame`] (remote frames as requests).
    pub fn decode_frame(cfg: &AllegroConfig, frame: &AllegroFrame) -> Result<Self, AllegroError> {
        Self::decode(cfg, frame.id(), frame.payload())
    }
}

#[cfg(test)]
mod tests {
    use super::super::{DeviceId, TorqueScale};
    use super::*;

    const CFG: AllegroConfig = AllegroConfig::V4;

    fn encode(c: Command) -> AllegroFrame {
        c.encode(&CFG).expect("encodes")
    }

    #[test]
    fn known_bytes_of_every_command() {
        assert_eq!(encode(Command::ServoOn), AllegroFrame::data(0x100, &[]).expect("frame"));
        assert_eq!(encode(Command::ServoOff), AllegroFrame::data(0x104, &[]).expect("frame"));
        let t = encode(Command::SetTorque(SetTorque { finger: Finger::Ring, tau_nm: [0.1, -0.1, 1.0, 0.0] }));
        // 0.1 N·m = 120 counts; 1.0 N·m on the ring's middle joint clips to 450.
        assert_eq!((t.id(), t.is_remote()), (0x188, false));
        assert_eq!(t.payload(), &[120, 0, 0x88, 0xFF, 0xC2, 0x01, 0, 0]);
        let p =
            encode(Command::SetPeriod(SetPeriod { position_ms: 3, temperature_ms: 500, ..SetPeriod::OFF }));
        assert_eq!((p.id(), p.payload()), (0x204, &[3, 0, 0, 0, 0xF4, 0x01][..]));
        let r = encode(Command::Request(Request::Temperature(Finger::Thumb)));
        assert_eq!((r.id(), r.is_remote(), r.payload().len()), (0x0EC, true, 0));
        assert_eq!(encode(Command::Request(Request::Info)).id(), 0x200);
        assert_eq!(encode(Command::Request(Request::Serial)).id(), 0x220);
        assert_eq!(encode(Command::Request(Request::Position(Finger::Index))).id(), 0x080);
        assert_eq!(encode(Command::Request(Request::Status)).id(), 0x040);
    }

    #[test]
    fn every_command_round_trips() {
        let commands = [
            Command::ServoOn,
            Command::ServoOff,
            Command::SetTorque(SetTorque { finger: Finger::Thumb, tau_nm: [0.4375, -0.3375, 0.1, -0.225] }),
            Command::SetPeriod(SetPeriod { position_ms: 3, imu_ms: 0, temperature_ms: 500, status_ms: 0 }),
            Command::Request(Request::Info),
            Command::Request(Request::Serial),
            Command::Request(Request::Position(Finger::Middle)),
            Command::Request(Request::Temperature(Finger::Index)),
            Command::Request(Request::Status),
        ];
        for c in commands {
            let frame = encode(c);
            assert_eq!(Command::decode_frame(&CFG, &frame), Ok(c), "{frame:?}");
        }
        let four = AllegroConfig { period_layout: PeriodLayout::FourFields, ..CFG };
        let all =
            Command::SetPeriod(SetPeriod { position_ms: 3, imu_ms: 10, temperature_ms: 500, status_ms: 100 });
        let frame = all.encode(&four).expect("8-byte layout");
        assert_eq!(frame.payload().len(), 8);
        assert_eq!(Command::decode_frame(&four, &frame), Ok(all));
        // Either layout decodes whichever is configured.
        assert_eq!(Command::decode_frame(&CFG, &frame), Ok(all));
        assert_eq!(all.encode(&CFG), Err(AllegroError::NotInLayout("status_ms")));
    }

    #[test]
    fn torques_beyond_the_clip_never_reach_a_frame() {
        let t = Command::SetTorque(SetTorque { finger: Finger::Index, tau_nm: [9.0, -9.0, 9.0, -9.0] });
        let back = Command::decode_frame(&CFG, &encode(t));
        assert_eq!(
            back,
            Ok(Command::SetTorque(SetTorque {
                finger: Finger::Index,
                tau_nm: [0.3125, -0.5625, 0.375, -0.2375]
            }))
        );
        let nan = Command::SetTorque(SetTorque { finger: Finger::Thumb, tau_nm: [0.0, 0.0, f32::NAN, 0.0] });
        assert!(matches!(nan.encode(&CFG), Err(AllegroError::NonFiniteTorque { finger: 3, joint: 2, .. })));
        // The scale is the configuration's: a v3 hand clips the same counts at more N·m.
        let v3 = AllegroConfig { torque: TorqueScale::V3_8V, ..CFG };
        let frame = t.encode(&v3).expect("finite");
        assert_eq!(&frame.payload()[..2], &375i16.to_le_bytes());
    }

    #[test]
    fn bad_frames_are_refused_with_their_reason() {
        assert_eq!(
            Command::decode(&CFG, 0x100, &[0]),
            Err(AllegroError::BadLength { id: 0x100, len: 1, expected: 0 })
        );
        assert_eq!(
            Command::decode(&CFG, 0x180, &[0; 7]),
            Err(AllegroError::BadLength { id: 0x180, len: 7, expected: 8 })
        );
        assert_eq!(
            Command::decode(&CFG, 0x204, &[0; 4]),
            Err(AllegroError::BadLength { id: 0x204, len: 4, expected: 6 })
        );
        assert_eq!(
            Command::decode(&CFG, 0x080, &[0; 8]),
            Err(AllegroError::WrongDirection { id: 0x080, kind: "position" })
        );
        assert_eq!(Command::decode(&CFG, 0x7FF, &[]), Err(AllegroError::UnknownId(0x7FF)));
        assert_eq!(
            Command::decode(&CFG, 0x103, &[]),
            Err(AllegroError::OtherDevice { id: 0x103, device: 3, expected: 0 })
        );
        let device3 = AllegroConfig { device: DeviceId::new(3).expect("in range"), ..CFG };
        assert_eq!(Command::decode(&device3, 0x103, &[]), Ok(Command::ServoOn));
        assert_eq!(Command::ServoOff.encode(&device3).map(|f| f.id()), Ok(0x107));
    }
}
