//! Which ids, which device and which torque scale: the settings both directions share.

use super::{AllegroError, DeviceId, Finger, TorqueScale};

/// Message ids: the upper 9 bits of the 11-bit frame id (`(message_id << 2) | device_id`).
/// Per-finger kinds use four consecutive ids, finger `f` at `base + f`.
///
/// The sources disagree on one of them: an early revision of Wonik's wiki page lists set
/// torque at 0x050..=0x053 (and config at 0x058), the page's later revisions, the v4 user
/// manual and every driver at 0x060..=0x063 (config 0x068). [`AllegroIds::V4`] follows the
/// drivers; [`AllegroIds::V4_EARLY_WIKI`] is the other reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AllegroIds {
    pub servo_on: u16,
    pub servo_off: u16,
    /// First of four: set torque of fingers 0..=3.
    pub set_torque: u16,
    pub set_period: u16,
    pub info: u16,
    pub serial: u16,
    /// First of four: positions of fingers 0..=3.
    pub position: u16,
    /// First of four: temperatures of fingers 0..=3.
    pub temperature: u16,
    pub status: u16,
}

impl AllegroIds {
    /// The ids of `candef.h` (allegro_hand_ros_v4, allegro_hand_linux_v4), `v4_spec.hpp`
    /// (allegro_hand_ros2) and the v4 user manual 1.1.
    pub const V4: Self = Self {
        servo_on: 0x40,
        servo_off: 0x41,
        set_torque: 0x60,
        set_period: 0x81,
        info: 0x80,
        serial: 0x88,
        position: 0x20,
        temperature: 0x38,
        status: 0x10,
    };

    /// [`Self::V4`] with set torque at 0x050..=0x053, as an early revision of the wiki page
    /// lists it.
    pub const V4_EARLY_WIKI: Self = Self { set_torque: 0x50, ..Self::V4 };

    /// Every kind's first message id and how many consecutive ids it takes.
    fn spans(&self) -> [(u16, u16); 9] {
        [
            (self.servo_on, 1),
            (self.servo_off, 1),
            (self.set_torque, 4),
            (self.set_period, 1),
            (self.info, 1),
            (self.serial, 1),
            (self.position, 4),
            (self.temperature, 4),
            (self.status, 1),
        ]
    }

    /// Whether these ids make an unambiguous protocol: every id fits its 9 bits, no two kinds
    /// share an id, and per-finger kinds start at a multiple of 4 (so one receive filter
    /// passes a kind's four fingers and nothing else).
    pub fn validate(&self) -> Result<(), AllegroError> {
        let spans = self.spans();
        for (i, &(base, n)) in spans.iter().enumerate() {
            let (base, n) = (u32::from(base), u32::from(n));
            if base + n - 1 > 0x1FF {
                return Err(AllegroError::BadConfig("a message id does not fit 9 bits"));
            }
            if n == 4 && base % 4 != 0 {
                return Err(AllegroError::BadConfig("a per-finger kind does not start at a multiple of 4"));
            }
            for &(other, m) in &spans[i + 1..] {
                let (other, m) = (u32::from(other), u32::from(m));
                if base < other + m && other < base + n {
                    return Err(AllegroError::BadConfig("two frame kinds share a message id"));
                }
            }
        }
        Ok(())
    }

    /// The kind of frame a message id names, if any.
    pub(super) fn kind_of(&self, msg: u16) -> Option<Kind> {
        let finger = |base: u16| {
            msg.checked_sub(base).and_then(|f| u8::try_from(f).ok()).and_then(|f| Finger::new(f).ok())
        };
        Some(match msg {
            m if m == self.servo_on => Kind::ServoOn,
            m if m == self.servo_off => Kind::ServoOff,
            m if m == self.set_period => Kind::SetPeriod,
            m if m == self.info => Kind::Info,
            m if m == self.serial => Kind::Serial,
            m if m == self.status => Kind::Status,
            _ => {
                if let Some(f) = finger(self.set_torque) {
                    Kind::SetTorque(f)
                } else if let Some(f) = finger(self.position) {
                    Kind::Position(f)
                } else {
                    Kind::Temperature(finger(self.temperature)?)
                }
            }
        })
    }
}

/// What a frame id names, before its payload is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    ServoOn,
    ServoOff,
    SetTorque(Finger),
    SetPeriod,
    Info,
    Serial,
    Position(Finger),
    Temperature(Finger),
    Status,
}

impl Kind {
    /// The frame's name, for errors.
    pub(super) fn name(self) -> &'static str {
        match self {
            Kind::ServoOn => "servo on",
            Kind::ServoOff => "servo off",
            Kind::SetTorque(_) => "set torque",
            Kind::SetPeriod => "set period",
            Kind::Info => "info",
            Kind::Serial => "serial",
            Kind::Position(_) => "position",
            Kind::Temperature(_) => "temperature",
            Kind::Status => "status",
        }
    }
}

/// How many fields the set-period frame carries. The user manual gives it four u16 periods
/// (position, IMU, temperature, status; DLC 8); every driver sends the first three (DLC 6),
/// and that is what hands in the field have been driven with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeriodLayout {
    /// Position, IMU, temperature: DLC 6, as the drivers send it (the default).
    ThreeFields,
    /// Position, IMU, temperature, status: DLC 8, as the user manual gives it.
    FourFields,
}

impl PeriodLayout {
    /// The set-period frame's data length code.
    pub fn dlc(self) -> u8 {
        match self {
            PeriodLayout::ThreeFields => 6,
            PeriodLayout::FourFields => 8,
        }
    }
}

/// Everything both ends must agree on besides the frame layouts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AllegroConfig {
    pub ids: AllegroIds,
    /// The hand's device id; frames of other devices are refused.
    pub device: DeviceId,
    /// Torque to PWM counts and the per-joint clips.
    pub torque: TorqueScale,
    pub period_layout: PeriodLayout,
}

impl Default for AllegroConfig {
    fn default() -> Self {
        Self::V4
    }
}

/// `CAN_EFF_FLAG | CAN_RTR_FLAG`: in a filter's mask and not in its id, they reject extended
/// and remote frames.
const FILTER_FLAGS: u32 = 0x8000_0000 | 0x4000_0000;

impl AllegroConfig {
    /// An Allegro Hand v4 (12 V) at device 0, with the drivers' ids and set-period layout.
    pub const V4: Self = Self {
        ids: AllegroIds::V4,
        device: DeviceId(0),
        torque: TorqueScale::V4_12V,
        period_layout: PeriodLayout::ThreeFields,
    };

    /// Checks the ids and the torque scale (see [`AllegroIds::validate`],
    /// [`TorqueScale::validate`]). Encoding and decoding never panic either way; an invalid
    /// configuration can make frame kinds ambiguous.
    pub fn validate(&self) -> Result<(), AllegroError> {
        self.ids.validate()?;
        self.torque.validate()
    }

    /// The 11-bit frame id of message id `msg` on this device.
    pub fn can_id(&self, msg: u16) -> u16 {
        ((msg & 0x1FF) << 2) | u16::from(self.device.get())
    }

    /// The kind of frame `id` is, refusing ids of no kind and frames of other devices.
    pub(super) fn kind(&self, id: u16) -> Result<Kind, AllegroError> {
        if id > 0x7FF {
            return Err(AllegroError::UnknownId(id));
        }
        let kind = self.ids.kind_of(id >> 2).ok_or(AllegroError::UnknownId(id))?;
        let device = (id & 0x3) as u8;
        if device != self.device.get() {
            return Err(AllegroError::OtherDevice { id, device, expected: self.device.get() });
        }
        Ok(kind)
    }

    /// SocketCAN receive filters for the host, `(id, mask)` as `struct can_filter` takes them:
    /// the data frames of this device's positions, temperatures, info, serial and status, and
    /// nothing else (no remote frames, no other device, no other protocol).
    pub fn host_filters(&self) -> [(u32, u32); 5] {
        // Bits 2-3 of a per-finger id are the finger.
        let fingers = FILTER_FLAGS | 0x7F3;
        let exact = FILTER_FLAGS | 0x7FF;
        let id = |msg| u32::from(self.can_id(msg));
        [
            (id(self.ids.position), fingers),
            (id(self.ids.temperature), fingers),
            (id(self.ids.info), exact),
            (id(self.ids.serial), exact),
            (id(self.ids.status), exact),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_id_sets_are_valid_and_others_are_refused() {
        assert_eq!(AllegroIds::V4.validate(), Ok(()));
        assert_eq!(AllegroIds::V4_EARLY_WIKI.validate(), Ok(()));
        assert_eq!(AllegroConfig::V4.validate(), Ok(()));
        let clash = AllegroIds { status: 0x62, ..AllegroIds::V4 };
        assert!(matches!(clash.validate(), Err(AllegroError::BadConfig(_))));
        let unaligned = AllegroIds { position: 0x21, ..AllegroIds::V4 };
        assert!(matches!(unaligned.validate(), Err(AllegroError::BadConfig(_))));
        let too_big = AllegroIds { set_torque: 0x1FE, ..AllegroIds::V4 };
        assert!(matches!(too_big.validate(), Err(AllegroError::BadConfig(_))));
        let huge = AllegroIds { servo_on: u16::MAX, ..AllegroIds::V4 };
        assert!(matches!(huge.validate(), Err(AllegroError::BadConfig(_))));
    }

    #[test]
    fn ids_name_their_kind_and_device() {
        let cfg = AllegroConfig::V4;
        assert_eq!(cfg.kind(0x100), Ok(Kind::ServoOn));
        assert_eq!(cfg.kind(0x08C), Ok(Kind::Position(Finger::Thumb)));
        assert_eq!(cfg.kind(0x184), Ok(Kind::SetTorque(Finger::Middle)));
        assert_eq!(cfg.kind(0x0E8), Ok(Kind::Temperature(Finger::Ring)));
        assert_eq!(cfg.kind(0x101), Err(AllegroError::OtherDevice { id: 0x101, device: 1, expected: 0 }));
        assert_eq!(cfg.kind(0x190), Err(AllegroError::UnknownId(0x190)));
        assert_eq!(cfg.kind(0x800), Err(AllegroError::UnknownId(0x800)));
        let early = AllegroConfig { ids: AllegroIds::V4_EARLY_WIKI, ..cfg };
        assert_eq!(early.kind(0x140), Ok(Kind::SetTorque(Finger::Index)));
        assert_eq!(early.kind(0x180), Err(AllegroError::UnknownId(0x180)));
        let device2 = AllegroConfig { device: DeviceId(2), ..cfg };
        assert_eq!(device2.can_id(0x20), 0x082);
        assert_eq!(device2.kind(0x082), Ok(Kind::Position(Finger::Index)));
    }

    #[test]
    fn host_filters_pass_exactly_this_devices_reports() {
        fn passes(filters: &[(u32, u32)], raw: u32) -> bool {
            filters.iter().any(|&(f, mask)| raw & mask == f & mask)
        }
        const RTR: u32 = 0x4000_0000;
        for device in 0..=3 {
            let cfg = AllegroConfig { device: DeviceId(device), ..AllegroConfig::V4 };
            let filters = cfg.host_filters();
            for id in 0..0x800u16 {
                let report = matches!(
                    cfg.kind(id),
                    Ok(Kind::Position(_) | Kind::Temperature(_) | Kind::Info | Kind::Serial | Kind::Status)
                );
                assert_eq!(passes(&filters, u32::from(id)), report, "device {device} id {id:#05x}");
                assert!(!passes(&filters, u32::from(id) | RTR), "remote frame {id:#05x} passes");
            }
        }
    }
}
