//! What a host sends around the control loop: start-up and shut-down commands, the torque
//! frames of a 16-joint vector, and the four position frames gathered into one.

use super::{
    AllegroConfig, AllegroError, AllegroFrame, Command, Finger, FingerPosition, JOINTS_PER_FINGER,
    NUM_JOINTS, Request, SetPeriod, SetTorque,
};

/// The position report period, and so the control period: 3 ms (333 Hz), as
/// allegro_hand_ros_v4 and allegro_hand_ros2 set it for a v4 hand.
pub const CONTROL_PERIOD_MS: u16 = 3;
/// The temperature report period: 500 ms, as allegro_hand_ros2 sets it (8 frames/s on the
/// bus, so the host sees a motor heating up).
pub const TEMPERATURE_PERIOD_MS: u16 = 500;

/// Start-up, in order, after the host has flushed its receive queue: servos off (a hand
/// left on by a crashed host holds its last torques), info (hardware version: the torque
/// scale) and serial requests, the report periods, servos on. allegro_hand_ros_v4's order.
/// Then the host waits for the info answer and for all four position frames before it sends
/// a torque.
pub const STARTUP_COMMANDS: [Command; 5] = [
    Command::ServoOff,
    Command::Request(Request::Info),
    Command::Request(Request::Serial),
    Command::SetPeriod(SetPeriod {
        position_ms: CONTROL_PERIOD_MS,
        imu_ms: 0,
        temperature_ms: TEMPERATURE_PERIOD_MS,
        status_ms: 0,
    }),
    Command::ServoOn,
];

/// Shut-down, in order: zero torque on every finger, servos off, periodic reports off.
pub const SHUTDOWN_COMMANDS: [Command; 6] = [
    zero_torque(Finger::Index),
    zero_torque(Finger::Middle),
    zero_torque(Finger::Ring),
    zero_torque(Finger::Thumb),
    Command::ServoOff,
    Command::SetPeriod(SetPeriod::OFF),
];

const fn zero_torque(finger: Finger) -> Command {
    Command::SetTorque(SetTorque { finger, tau_nm: [0.0; JOINTS_PER_FINGER] })
}

/// The four set-torque commands of a hand's joint torques (16-vector, finger-major).
pub fn torque_commands(tau_nm: &[f32; NUM_JOINTS]) -> [Command; 4] {
    Finger::ALL.map(|finger| {
        let mut t = [0.0; JOINTS_PER_FINGER];
        for (joint, tau) in t.iter_mut().enumerate() {
            *tau = tau_nm[finger.joint_index(joint)];
        }
        Command::SetTorque(SetTorque { finger, tau_nm: t })
    })
}

impl AllegroConfig {
    /// The four set-torque frames of a hand's joint torques, all or none: a non-finite torque
    /// anywhere is an error and no frame is made (the caller sends nothing rather than three
    /// fingers' torques). Torques beyond a joint's clip are clipped.
    pub fn encode_torques(&self, tau_nm: &[f32; NUM_JOINTS]) -> Result<[AllegroFrame; 4], AllegroError> {
        let [a, b, c, d] = torque_commands(tau_nm);
        Ok([a.encode(self)?, b.encode(self)?, c.encode(self)?, d.encode(self)?])
    }
}

/// Gathers the four fingers' position frames into one 16-joint reading: the hand sends them
/// one after another each period, and the drivers act once all four have arrived (their
/// `_curr_position_get` mask), then wait for the next four.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PositionCycle {
    q_rad: [f32; NUM_JOINTS],
    seen: u8,
}

impl PositionCycle {
    pub fn new() -> Self {
        Self::default()
    }

    /// Records one finger's angles (a repeated finger overwrites its earlier frame). Returns
    /// the 16 angles when this frame completes the set of four, and starts the next set.
    pub fn push(&mut self, p: &FingerPosition) -> Option<[f32; NUM_JOINTS]> {
        for (joint, &q) in p.q_rad.iter().enumerate() {
            self.q_rad[p.finger.joint_index(joint)] = q;
        }
        self.seen |= 1 << p.finger.index();
        (self.seen == 0x0F).then(|| {
            self.seen = 0;
            self.q_rad
        })
    }

    /// Bit `f` is set when finger `f` has reported in the current set.
    pub fn seen(&self) -> u8 {
        self.seen
    }

    /// The latest angle of every joint (0 for a finger that never reported).
    pub fn latest(&self) -> [f32; NUM_JOINTS] {
        self.q_rad
    }
}

#[cfg(test)]
mod tests {
    use super::super::{PeriodLayout, Report};
    use super::*;

    #[test]
    fn startup_and_shutdown_encode_in_the_drivers_order() {
        let cfg = AllegroConfig::V4;
        let frames = STARTUP_COMMANDS.map(|c| c.encode(&cfg).expect("encodes"));
        let ids = frames.map(|f| (f.id(), f.is_remote()));
        assert_eq!(ids, [(0x104, false), (0x200, true), (0x220, true), (0x204, false), (0x100, false)]);
        assert_eq!(frames[3].payload(), &[3, 0, 0, 0, 0xF4, 0x01]);
        let four = AllegroConfig { period_layout: PeriodLayout::FourFields, ..cfg };
        assert!(STARTUP_COMMANDS.iter().all(|c| c.encode(&four).is_ok()));
        let frames = SHUTDOWN_COMMANDS.map(|c| c.encode(&cfg).expect("encodes"));
        for (f, id) in frames[..4].iter().zip([0x180, 0x184, 0x188, 0x18C]) {
            assert_eq!((f.id(), f.payload()), (id, &[0u8; 8][..]));
        }
        assert_eq!(frames[4].id(), 0x104);
        assert_eq!((frames[5].id(), frames[5].payload()), (0x204, &[0u8; 6][..]));
    }

    #[test]
    fn a_joint_vector_maps_finger_major() {
        let tau: [f32; NUM_JOINTS] = core::array::from_fn(|i| i as f32 * 0.01);
        let commands = torque_commands(&tau);
        let Command::SetTorque(thumb) = commands[3] else { panic!("set torque") };
        assert_eq!((thumb.finger, thumb.tau_nm), (Finger::Thumb, [tau[12], tau[13], tau[14], tau[15]]));
        let cfg = AllegroConfig::V4;
        let frames = cfg.encode_torques(&tau).expect("finite");
        assert_eq!(frames.map(|f| f.id()), [0x180, 0x184, 0x188, 0x18C]);
        // Index joint 1: 0.01 N·m = 12 counts.
        assert_eq!(&frames[0].payload()[2..4], &12i16.to_le_bytes());
        let mut bad = tau;
        bad[9] = f32::NAN;
        assert!(matches!(
            cfg.encode_torques(&bad),
            Err(AllegroError::NonFiniteTorque { finger: 2, joint: 1, .. })
        ));
    }

    #[test]
    fn positions_complete_once_all_four_fingers_report() {
        let cfg = AllegroConfig::V4;
        let mut cycle = PositionCycle::new();
        let mut done = None;
        for (n, finger) in
            [Finger::Thumb, Finger::Index, Finger::Index, Finger::Ring, Finger::Middle].iter().enumerate()
        {
            let q = [n as f32 * 0.1; 4];
            let frame = Report::Position(FingerPosition { finger: *finger, q_rad: q })
                .encode(&cfg)
                .expect("in range");
            let Ok(Report::Position(p)) = Report::decode_frame(&cfg, &frame) else { panic!("position") };
            assert!(done.is_none(), "complete before the fourth finger");
            done = cycle.push(&p);
        }
        let q = done.expect("complete after the fourth finger");
        // Thumb from the first frame, index from its second (the repeat overwrote the first).
        assert!((q[12] - 0.0).abs() < 1e-4 && (q[0] - 0.2).abs() < 1e-4);
        assert!((q[8] - 0.3).abs() < 1e-4 && (q[4] - 0.4).abs() < 1e-4);
        assert_eq!(cycle.seen(), 0, "the next set starts empty");
        assert_eq!(cycle.latest(), q);
        let again = FingerPosition { finger: Finger::Ring, q_rad: [0.0; 4] };
        assert_eq!(cycle.push(&again), None);
        assert_eq!(cycle.seen(), 0b0100);
    }
}
