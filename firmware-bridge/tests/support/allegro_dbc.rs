//! The Allegro frames as `allegro_dbc_check.py` reads them: each frame's DBC message name and
//! signal values as the Rust decoder reads them, checked by cantools with docs/allegro-v4.dbc.
//! Included by path from the tests that check frames against the DBC; each declares
//! `python_env` (tests/support/python.rs) at its root.

#![allow(dead_code)] // not every including test uses every helper

use crate::python_env;

use vge_bridge::protocol::allegro::{
    AllegroConfig, AllegroFrame, Command, Handedness, Report, Request, Status,
};

const FINGER_NAMES: [&str; 4] = ["Index", "Middle", "Ring", "Thumb"];
const STATUS_SIGNALS: [(&str, u8); 5] = [
    ("servo_on", Status::SERVO_ON),
    ("joint_over_temperature", Status::JOINT_OVER_TEMPERATURE),
    ("joint_throttled", Status::JOINT_THROTTLED),
    ("communication_timeout", Status::COMMUNICATION_TIMEOUT),
    ("palm_over_temperature", Status::PALM_OVER_TEMPERATURE),
];

/// The DBC message name and signal values of a decoded command.
pub fn command_signals(c: &Command) -> (String, Vec<(String, f32)>) {
    match c {
        Command::ServoOn => ("ServoOn".into(), vec![]),
        Command::ServoOff => ("ServoOff".into(), vec![]),
        Command::SetTorque(t) => (
            format!("SetTorque_{}", FINGER_NAMES[usize::from(t.finger.index())]),
            (0..4).map(|j| (format!("tau_j{j}"), t.tau_nm[j])).collect(),
        ),
        Command::SetPeriod(p) => (
            "SetPeriod".into(),
            vec![
                ("position_period".into(), f32::from(p.position_ms)),
                ("imu_period".into(), f32::from(p.imu_ms)),
                ("temperature_period".into(), f32::from(p.temperature_ms)),
            ],
        ),
        Command::Request(r) => (request_name(*r), vec![]),
    }
}

fn request_name(r: Request) -> String {
    match r {
        Request::Info => "Info".into(),
        Request::Serial => "Serial".into(),
        Request::Position(f) => format!("Position_{}", FINGER_NAMES[usize::from(f.index())]),
        Request::Temperature(f) => format!("Temperature_{}", FINGER_NAMES[usize::from(f.index())]),
        Request::Status => "Status".into(),
    }
}

fn status_signals(signals: &mut Vec<(String, f32)>, s: Status) {
    for (name, bit) in STATUS_SIGNALS {
        signals.push((name.into(), f32::from(u8::from(s.bits & bit != 0))));
    }
}

/// The DBC message name and signal values of a decoded report.
pub fn report_signals(r: &Report) -> (String, Vec<(String, f32)>) {
    let name = request_name(r.request());
    let mut signals = Vec::new();
    match r {
        Report::Position(p) => {
            signals.extend((0..4).map(|j| (format!("q_j{j}"), p.q_rad[j])));
        }
        Report::Temperature(t) => {
            signals.extend((0..4).map(|j| (format!("temperature_j{j}"), f32::from(t.temperature_c[j]))));
        }
        Report::Info(i) => {
            let hand = match i.hand {
                Handedness::Right => 0,
                Handedness::Left => 1,
                Handedness::Other(v) => v,
            };
            signals.push(("hardware_version".into(), f32::from(i.hardware_version)));
            signals.push(("firmware_version".into(), f32::from(i.firmware_version)));
            signals.push(("hand".into(), f32::from(hand)));
            signals.push(("palm_temperature".into(), f32::from(i.palm_temperature_c)));
            status_signals(&mut signals, i.status);
        }
        Report::Serial(s) => signals.extend((0..8).map(|k| (format!("char{k}"), f32::from(s.ascii[k])))),
        Report::Status(s) => status_signals(&mut signals, *s),
    }
    (name, signals)
}

/// One line of the checker's input. Values print as f32 (shortest round-trip form), the
/// precision the decoder gives them, so a torque at its clip reads as the DBC's limit.
pub fn line(frame: &AllegroFrame, name: &str, signals: &[(String, f32)]) -> String {
    let hex: String = frame.payload().iter().map(|b| format!("{b:02x}")).collect();
    let hex = if hex.is_empty() { "-".to_owned() } else { hex };
    let kind = if frame.is_remote() { "R" } else { "D" };
    let values: Vec<String> = signals.iter().map(|(n, v)| format!("{n}={v}")).collect();
    format!("{:03x} {kind} {hex} {name} {}\n", frame.id(), values.join(" "))
}

/// The checker's line for a frame seen on the bus, decoded as the report or command it is;
/// `None` when neither decoder takes it.
pub fn frame_line(cfg: &AllegroConfig, frame: &AllegroFrame) -> Option<String> {
    if !frame.is_remote()
        && let Ok(r) = Report::decode_frame(cfg, frame)
    {
        let (name, signals) = report_signals(&r);
        return Some(line(frame, &name, &signals));
    }
    let c = Command::decode_frame(cfg, frame).ok()?;
    let (name, signals) = command_signals(&c);
    Some(line(frame, &name, &signals))
}

/// Runs the checker on `lines`; its output, after asserting that it passed.
pub fn check(lines: &str) -> String {
    let capture = std::env::temp_dir().join(format!(
        "vge-allegro-dbc-{}-{}.txt",
        std::process::id(),
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos())
    ));
    std::fs::write(&capture, lines).expect("write frames");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/allegro_dbc_check.py");
    let out = std::process::Command::new(python_env::python())
        .arg(script)
        .arg(&capture)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with cantools)");
    let _ = std::fs::remove_file(&capture);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "cantools decoding with docs/allegro-v4.dbc disagrees:\n{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}
