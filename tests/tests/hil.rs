//! Hardware-in-the-loop tests on a real SocketCAN interface (vcan0 by default).
//! They are `#[ignore]`d so that `cargo test --workspace` on a machine without CAN reports
//! them as ignored instead of failing; `scripts/hil.sh` runs them (`--ignored`) where vcan0
//! is up, booting a CAN-capable guest when this kernel has none.

use std::thread;
use std::time::{Duration, Instant};

use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Socket, StandardId};
use vge_bridge::emulator::{JointControllerEmulator, serve};
use vge_bridge::protocol::*;
use vge_bridge::socketcan_io::{standard_id_and_data, to_can_frame};
use vge_bridge::transport::SocketCanTransport;
use vge_tests::hil_iface;

const READ_TIMEOUT: Duration = Duration::from_secs(2);

fn open(iface: &str) -> CanSocket {
    CanSocket::open(iface).unwrap_or_else(|e| {
        panic!("cannot open CAN interface {iface}: {e}. HIL tests need it up: run scripts/hil.sh")
    })
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn two_sockets_exchange_frames_on_vcan() {
    let iface = hil_iface();
    let a = open(&iface);
    let b = open(&iface);
    b.set_read_timeout(READ_TIMEOUT).expect("read timeout");

    for i in 0..100u8 {
        let id = StandardId::new(0x300 + u16::from(i)).expect("11-bit id");
        let data = [i, i.wrapping_mul(3), 0xa5, 0x5a, 0, 1, 2, i];
        let sent = CanFrame::new(id, &data[..usize::from(i % 9)]).expect("classic frame");
        a.write_frame(&sent).expect("write");
        let got = b.read_frame().expect("the other socket receives the frame");
        assert_eq!(got.id(), sent.id());
        assert_eq!(got.data(), sent.data());
    }
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn joint_controller_emulator_answers_commands_over_vcan() {
    let iface = hil_iface();
    // Filter-free sockets see every frame on the bus, including other tests' traffic: use a
    // dedicated finger-range check and sequence numbers to pick out our replies.
    let client = open(&iface);
    client.set_read_timeout(READ_TIMEOUT).expect("read timeout");

    let rounds: u8 = 20;
    let expected = u64::from(rounds) * u64::from(NUM_FINGERS);
    let server_iface = iface.clone();
    let server = thread::spawn(move || {
        let mut emulator = JointControllerEmulator::new(0.5);
        let mut transport = SocketCanTransport::open(&server_iface)?;
        serve(&mut transport, &mut emulator, expected, READ_TIMEOUT)
    });
    // The server must be listening before the first command: CAN does not queue for sockets
    // opened later. Give it a moment, then check it answered every command.
    thread::sleep(Duration::from_millis(200));

    let target_rad = [0.3, 0.8, -0.4];
    let mut last = [None::<JointPosition>; NUM_FINGERS as usize];
    let start = Instant::now();
    for seq in 0..rounds {
        for f in 0..NUM_FINGERS {
            let cmd = Message::JointCommand(JointCommand {
                finger: FingerId::new(f).expect("finger"),
                q_target_rad: target_rad,
                enable: true,
                seq,
            });
            client.write_frame(&to_can_frame(&cmd.encode().expect("encode")).expect("frame")).expect("write");
            let state = loop {
                let frame = client.read_frame().expect("a joint state reply before the timeout");
                let (id, data) = standard_id_and_data(&frame).expect("data frame");
                if let Ok(Message::JointPosition(state)) = Message::decode(id, data) {
                    break state;
                }
            };
            assert_eq!(state.finger.index(), f);
            assert_eq!(state.seq, seq, "reply echoes the command's sequence number");
            last[usize::from(f)] = Some(state);
        }
    }
    let elapsed = start.elapsed();
    let stats = server.join().expect("server thread").expect("server ran");
    assert_eq!(stats.commands, expected);

    // After 20 halvings of the error the joints sit on the target (to the wire's resolution).
    for state in last.iter().flatten() {
        for (q, t) in state.q_rad.iter().zip(target_rad) {
            assert!((q - t).abs() < 2e-4, "finger {} joint at {q} rad, target {t}", state.finger.index());
        }
        assert_eq!(state.status & 1, 1, "enabled");
    }
    eprintln!(
        "hil: {expected} command/state round trips on {iface} in {:.1} ms ({:.0} us each)",
        elapsed.as_secs_f64() * 1e3,
        elapsed.as_secs_f64() * 1e6 / expected as f64
    );
}

/// The signals of a message as the DBC names them, with the physical values the Rust side
/// encoded (the DBC must decode the same bytes to the same values).
fn dbc_signals(m: &Message) -> Vec<(&'static str, f64)> {
    const JOINTS: [&str; 3] = ["roll", "prox", "dist"];
    let mut out = Vec::new();
    let mut triple = |names: [&'static str; 3], v: [f32; 3]| {
        out.extend(names.into_iter().zip(v.map(f64::from)));
    };
    match *m {
        Message::JointCommand(c) => {
            triple(
                JOINTS.map(|j| match j {
                    "roll" => "q_target_roll",
                    "prox" => "q_target_prox",
                    _ => "q_target_dist",
                }),
                c.q_target_rad,
            );
            out.push(("enable", f64::from(u8::from(c.enable))));
            out.push(("seq", f64::from(c.seq)));
        }
        Message::JointPosition(p) => {
            triple(["q_roll", "q_prox", "q_dist"], p.q_rad);
            out.push(("enabled", f64::from(p.status & STATUS_ENABLED)));
            out.push(("seq", f64::from(p.seq)));
        }
        Message::JointVelocity(v) => triple(["dq_roll", "dq_prox", "dq_dist"], v.dq_radps),
        Message::JointEffort(e) => triple(["tau_roll", "tau_prox", "tau_dist"], e.tau_nm),
        Message::TipContact(t) => {
            triple(["p_x", "p_y", "p_z"], t.position_m);
            out.push(("force", f64::from(t.force_n)));
        }
        Message::TipNormal(n) => {
            triple(["n_x", "n_y", "n_z"], n.normal);
            out.push(("in_contact", f64::from(u8::from(n.in_contact))));
        }
        Message::JointTarget(t) => {
            triple(["q_target_roll", "q_target_prox", "q_target_dist"], t.q_target_rad);
            out.push(("seq", f64::from(t.seq)));
        }
        Message::Heartbeat(h) => out.push(("counter", f64::from(h.counter))),
        Message::Fault(f) => {
            out.push(("joint", f64::from(f.joint.unwrap_or(0xff))));
            out.push(("value", f64::from(f.value)));
        }
    }
    out
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn frames_captured_on_vcan_decode_with_the_dbc() {
    let iface = hil_iface();
    let sender = open(&iface);
    let capture = open(&iface);
    capture.set_read_timeout(READ_TIMEOUT).expect("read timeout");

    let mut messages = Vec::new();
    for finger in FingerId::all() {
        let k = f32::from(finger.index());
        messages.extend([
            Message::JointCommand(JointCommand {
                finger,
                q_target_rad: [0.1 * k - 0.2, 1.2345, -0.5],
                enable: true,
                seq: 10 + finger.index(),
            }),
            Message::JointPosition(JointPosition {
                finger,
                q_rad: [-0.3, 0.25 * k, 1.5],
                status: STATUS_ENABLED,
                seq: 3,
            }),
            Message::JointVelocity(JointVelocity { finger, dq_radps: [0.4, -2.5, 5.0 * k], seq: 4 }),
            Message::JointEffort(JointEffort { finger, tau_nm: [0.3, -0.45, 0.01 * k], seq: 5 }),
            Message::TipContact(TipContact {
                finger,
                position_m: [0.062, -0.01 * k, 0.003],
                force_n: 3.1 + k,
            }),
            Message::TipNormal(TipNormal { finger, normal: [0.6, -0.8, 0.0], in_contact: true, seq: 6 }),
            Message::JointTarget(JointTarget { finger, q_target_rad: [0.05 * k, 0.3, 0.31], seq: 8 }),
            Message::Heartbeat(Heartbeat { node: finger.index(), state: NodeState::Enabled, counter: 42 }),
            Message::Fault(Fault {
                finger,
                code: FaultCode::OverTemperature,
                joint: Some(2),
                value: 655,
                seq: 7,
            }),
        ]);
    }
    messages.push(Message::Heartbeat(Heartbeat { node: HOST_NODE, state: NodeState::Ready, counter: 1 }));

    // Send everything, then read back what the bus carried: the capture is of real frames.
    for m in &messages {
        sender.write_frame(&to_can_frame(&m.encode().expect("encode")).expect("frame")).expect("write");
    }
    let mut lines = String::new();
    for m in &messages {
        let frame = capture.read_frame().expect("captured frame");
        let (id, data) = standard_id_and_data(&frame).expect("data frame");
        assert_eq!(Message::decode(id, data).map(|d| d.encode().expect("re-encode").id), Ok(id));
        let hex: String = data.iter().map(|b| format!("{b:02x}")).collect();
        let signals: Vec<String> = dbc_signals(m).iter().map(|(n, v)| format!("{n}={v}")).collect();
        lines.push_str(&format!("{id:03x} {hex} {}\n", signals.join(" ")));
    }
    let capture_file = std::env::temp_dir().join(format!("vge-hil-capture-{}.txt", std::process::id()));
    std::fs::write(&capture_file, &lines).expect("write capture");

    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/dbc_check.py");
    let python = std::env::var("VGE_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let out = std::process::Command::new(python)
        .arg(script)
        .arg(&capture_file)
        .output()
        .expect("python runs (VGE_PYTHON; scripts/test.sh makes .deps/py with cantools)");
    let _ = std::fs::remove_file(&capture_file);
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "cantools decoding with docs/vge-hand.dbc disagrees:\n{stdout}");
    assert!(stdout.contains(&format!("{} frames", messages.len())), "{stdout}");
}
