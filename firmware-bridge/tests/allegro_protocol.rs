//! The Allegro Hand protocol from outside the crate: decoders total on arbitrary bytes,
//! round trips and clips as properties, and every frame kind the encoder makes decoded by
//! cantools with docs/allegro-v4.dbc to the values the Rust decoder reads.

#[path = "support/allegro_dbc.rs"]
mod allegro_dbc;

use allegro_dbc::{command_signals, line, report_signals};
use proptest::prelude::*;
use vge_bridge::protocol::allegro::*;

/// The shipped configuration and its variants: ids, device, set-period layout, torque scale.
fn configs() -> [AllegroConfig; 4] {
    let v4 = AllegroConfig::V4;
    [
        v4,
        AllegroConfig { ids: AllegroIds::V4_EARLY_WIKI, ..v4 },
        AllegroConfig { device: DeviceId::new(2).expect("in range"), torque: TorqueScale::V3_8V, ..v4 },
        AllegroConfig { period_layout: PeriodLayout::FourFields, ..v4 },
    ]
}

/// Mostly ids at or near the protocol's (each kind's first id plus 0..16 covers its fingers
/// and devices), and some anywhere in u16.
fn frame_id() -> impl Strategy<Value = u16> {
    let bases = vec![0x040u16, 0x080, 0x0E0, 0x100, 0x104, 0x140, 0x180, 0x200, 0x204, 0x220];
    prop_oneof![
        3 => (prop::sample::select(bases), 0u16..16).prop_map(|(base, k)| base + k),
        1 => any::<u16>(),
    ]
}

fn finger() -> impl Strategy<Value = Finger> {
    (0u8..4).prop_map(|i| Finger::new(i).expect("in range"))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    #[test]
    fn decoders_never_panic_and_name_what_is_wrong(
        id in frame_id(),
        data in prop::collection::vec(any::<u8>(), 0..=12),
        which in 0usize..4,
    ) {
        let cfg = configs()[which];
        match Report::decode(&cfg, id, &data) {
            Ok(report) => {
                // A decoded report encodes back to the same frame.
                let frame = AllegroFrame::data(id, &data).expect("at most 8 bytes");
                prop_assert_eq!(report.encode(&cfg), Ok(frame));
            }
            Err(AllegroError::BadLength { id: bad, len, expected }) => {
                prop_assert_eq!((bad, len), (id, data.len()));
                prop_assert_ne!(usize::from(expected), len);
            }
            Err(AllegroError::UnknownId(bad)) => prop_assert_eq!(bad, id),
            Err(AllegroError::OtherDevice { id: bad, device, expected }) => {
                prop_assert_eq!(bad, id);
                prop_assert_ne!(device, expected);
            }
            Err(AllegroError::WrongDirection { id: bad, .. }) => prop_assert_eq!(bad, id),
            Err(e) => prop_assert!(false, "unexpected error {}", e),
        }
        match Command::decode(&cfg, id, &data) {
            Ok(Command::SetTorque(t)) => {
                // Within the clip the frame comes back byte for byte; beyond it, clipped.
                let frame = Command::SetTorque(t).encode(&cfg).expect("finite");
                let back = Command::decode_frame(&cfg, &frame).expect("own frame");
                let Command::SetTorque(b) = back else { panic!("set torque") };
                for j in 0..4 {
                    let limit = cfg.torque.limit_nm(t.finger, j);
                    prop_assert!(b.tau_nm[j].abs() <= limit, "{} > {}", b.tau_nm[j], limit);
                    if t.tau_nm[j].abs() <= limit {
                        prop_assert_eq!(b.tau_nm[j], t.tau_nm[j]);
                    }
                }
            }
            Ok(Command::SetPeriod(p)) => {
                prop_assert!(data.len() == 6 || data.len() == 8);
                let again = Command::SetPeriod(p).encode(&cfg);
                if p.status_ms != 0 && cfg.period_layout == PeriodLayout::ThreeFields {
                    prop_assert_eq!(again, Err(AllegroError::NotInLayout("status_ms")));
                } else {
                    let frame = again.expect("encodes");
                    prop_assert_eq!(&frame.payload()[..6], &data[..6]);
                }
            }
            Ok(c) => {
                prop_assert!(data.is_empty(), "{:?} from {} bytes", c, data.len());
                let frame = c.encode(&cfg).expect("encodes");
                prop_assert_eq!(frame.id(), id);
            }
            Err(AllegroError::BadLength { id: bad, len, .. }) => prop_assert_eq!((bad, len), (id, data.len())),
            Err(AllegroError::UnknownId(bad)) => prop_assert_eq!(bad, id),
            Err(AllegroError::OtherDevice { id: bad, .. }) => prop_assert_eq!(bad, id),
            Err(AllegroError::WrongDirection { id: bad, .. }) => {
                prop_assert_eq!(bad, id);
                prop_assert!(!data.is_empty());
            }
            Err(e) => prop_assert!(false, "unexpected error {}", e),
        }
    }

    #[test]
    fn torques_come_back_clipped_to_within_half_a_count(
        f in finger(),
        tau in [-2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0],
        which in 0usize..4,
    ) {
        let cfg = configs()[which];
        let frame = Command::SetTorque(SetTorque { finger: f, tau_nm: tau }).encode(&cfg).expect("finite");
        let Ok(Command::SetTorque(back)) = Command::decode_frame(&cfg, &frame) else { panic!("set torque") };
        prop_assert_eq!(back.finger, f);
        let half_count = 0.5 / cfg.torque.pwm_per_nm;
        for (j, (&sent, &got)) in tau.iter().zip(&back.tau_nm).enumerate() {
            let limit = cfg.torque.limit_nm(f, j);
            prop_assert!(got.abs() <= limit);
            let clipped = sent.clamp(-limit, limit);
            prop_assert!((got - clipped).abs() <= half_count + 1e-6, "{} vs {}", got, clipped);
        }
    }

    #[test]
    fn only_non_finite_torques_are_refused(f in finger(), bits in any::<[u32; 4]>()) {
        let tau = bits.map(f32::from_bits);
        let result = Command::SetTorque(SetTorque { finger: f, tau_nm: tau }).encode(&AllegroConfig::V4);
        prop_assert_eq!(result.is_err(), tau.iter().any(|t| !t.is_finite()), "{:?}", tau);
    }

    #[test]
    fn positions_round_trip_to_within_half_a_count(
        f in finger(),
        q in [-2.9f32..2.9, -2.9f32..2.9, -2.9f32..2.9, -2.9f32..2.9],
    ) {
        let cfg = AllegroConfig::V4;
        let frame = Report::Position(FingerPosition { finger: f, q_rad: q }).encode(&cfg).expect("in range");
        let Ok(Report::Position(back)) = Report::decode_frame(&cfg, &frame) else { panic!("position") };
        prop_assert_eq!(back.finger, f);
        for (&sent, &got) in q.iter().zip(&back.q_rad) {
            let err = f64::from((got - sent).abs()) / POSITION_RAD_PER_COUNT;
            prop_assert!(err <= 0.5 + 1e-2, "{} -> {}: {} counts", sent, got, err);
        }
    }
}

/// Every frame kind in both directions, beyond-the-clip torques and the start-up and
/// shut-down sequences included.
fn every_frame_kind() -> (Vec<Command>, Vec<Report>) {
    let mut commands = vec![Command::ServoOn, Command::ServoOff];
    commands.extend(STARTUP_COMMANDS);
    commands.extend(SHUTDOWN_COMMANDS);
    for f in Finger::ALL {
        let i = f32::from(f.index());
        commands
            .push(Command::SetTorque(SetTorque { finger: f, tau_nm: [0.1 * i, -0.05, 0.2, -0.0125 * i] }));
        // Beyond every clip: the frame carries the clips.
        commands.push(Command::SetTorque(SetTorque { finger: f, tau_nm: [5.0, -5.0, 1.0, -1.0] }));
        commands.push(Command::Request(Request::Position(f)));
        commands.push(Command::Request(Request::Temperature(f)));
    }
    commands.push(Command::Request(Request::Status));
    let mut reports = vec![];
    for f in Finger::ALL {
        let i = f32::from(f.index());
        reports.push(Report::Position(FingerPosition { finger: f, q_rad: [0.1 * i, -0.47, 1.61, 2.9 - i] }));
        reports.push(Report::Temperature(FingerTemperature { finger: f, temperature_c: [25, 40, -3, 127] }));
    }
    reports.push(Report::Info(Info {
        hardware_version: 0x0400,
        firmware_version: 0x0312,
        hand: Handedness::Right,
        palm_temperature_c: -12,
        status: Status { bits: Status::SERVO_ON | Status::JOINT_THROTTLED },
    }));
    reports.push(Report::Info(Info {
        hardware_version: 0x0301,
        firmware_version: 0xFFFF,
        hand: Handedness::Left,
        palm_temperature_c: 45,
        status: Status { bits: 0x1E },
    }));
    reports.push(Report::Serial(Serial { ascii: *b"AR011\0\0\0" }));
    for bits in [0, 0x01, 0x08, 0x10] {
        reports.push(Report::Status(Status { bits }));
    }
    (commands, reports)
}

#[test]
fn allegro_frames_decode_with_the_dbc() {
    let cfg = AllegroConfig::V4;
    let (commands, reports) = every_frame_kind();
    let mut lines = String::new();
    for c in &commands {
        let frame = c.encode(&cfg).expect("encodes");
        let decoded = Command::decode_frame(&cfg, &frame).expect("own frame decodes");
        let (name, signals) = command_signals(&decoded);
        lines.push_str(&line(&frame, &name, &signals));
    }
    for r in &reports {
        let frame = r.encode(&cfg).expect("encodes");
        let decoded = Report::decode_frame(&cfg, &frame).expect("own frame decodes");
        let (name, signals) = report_signals(&decoded);
        lines.push_str(&line(&frame, &name, &signals));
    }
    let stdout = allegro_dbc::check(&lines);
    let n = commands.len() + reports.len();
    assert!(stdout.contains(&format!("{n} frames")), "{stdout}");
    assert!(stdout.contains("18 of 18 DBC messages"), "{stdout}");
}
