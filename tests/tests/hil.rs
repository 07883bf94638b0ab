//! Hardware-in-the-loop tests on a real SocketCAN interface (vcan0 by default).
//! They are `#[ignore]`d so that `cargo test --workspace` on a machine without CAN reports
//! them as ignored instead of failing; `scripts/hil.sh` runs them (`--ignored`) where vcan0
//! is up, booting a CAN-capable guest when this kernel has none.

use std::thread;
use std::time::{Duration, Instant};

use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Socket, StandardId};
use vge_bridge::emulator::{JointControllerEmulator, ServeLimits, serve};
use vge_bridge::protocol::fd::{FdMessage, FingerState, HandCommand};
use vge_bridge::protocol::*;
use vge_bridge::socketcan_io::{standard_id_and_data, to_can_frame};
use vge_bridge::transport::{Role, SocketCanTransport};
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
        let mut transport = SocketCanTransport::open(&server_iface, Role::Nodes)?;
        let limits =
            ServeLimits { max_commands: expected, idle_timeout: READ_TIMEOUT, command_timeout: READ_TIMEOUT };
        serve(&mut transport, &mut emulator, limits, &std::sync::atomic::AtomicBool::new(false))
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

// ---------------------------------------------------------------- bridge processes on vcan0

/// A workspace binary next to this test's executable (target/release/deps/..), built by
/// scripts/hil.sh before the tests.
fn workspace_bin(name: &str) -> std::path::PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let dir = exe.parent().and_then(|deps| deps.parent()).expect("target/<profile>/deps");
    let bin = dir.join(name);
    assert!(
        bin.exists(),
        "{} is missing: build it with `cargo build --release --workspace --bins`",
        bin.display()
    );
    bin
}

/// The value of `"key":value` in a flat one-line JSON object.
fn json_field(line: &str, key: &str) -> Option<String> {
    let start = line.find(&format!("\"{key}\":"))? + key.len() + 3;
    let rest = &line[start..];
    let end = rest.find([',', '}']).unwrap_or(rest.len());
    Some(rest[..end].trim_matches('"').to_owned())
}

fn json_f64(line: &str, key: &str) -> f64 {
    json_field(line, key)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no number `{key}` in {line}"))
}

/// An untrained but real policy file (format version 2, f32 weights), exported from a seeded
/// tch actor by `vge export`.
fn exported_policy(seed: u64) -> std::path::PathBuf {
    exported_policy_as(seed, "f32")
}

/// [`exported_policy`] with its weights stored as `weights` (`f32`, `f16` or `i8`).
fn exported_policy_as(seed: u64, weights: &str) -> std::path::PathBuf {
    let path =
        std::env::temp_dir().join(format!("vge-hil-policy-{seed}-{weights}-{}.vgep", std::process::id()));
    let out = std::process::Command::new(workspace_bin("vge"))
        .args(["export", "--init", "--weights", weights, "--seed", &seed.to_string(), "--out"])
        .arg(&path)
        .output()
        .expect("vge export runs");
    assert!(out.status.success(), "vge export failed: {}", String::from_utf8_lossy(&out.stderr));
    let bytes = std::fs::read(&path).expect("read the policy file");
    let info = vge_runtime::policy::inspect(&bytes).expect("a valid policy file");
    assert_eq!((info.format_version, info.weight_type.name()), (2, weights));
    path
}

/// A real policy file that always outputs zero change (its last layer zeroed): the hand
/// holds its grasp, so whether the object stays held says whether the link did.
fn hold_policy(seed: u64) -> std::path::PathBuf {
    let path = exported_policy(seed);
    let mut file = vge_export::PolicyFile::read(&path).expect("valid policy file");
    let last = file.layers.last_mut().expect("layers");
    last.weights.iter_mut().chain(last.bias.iter_mut()).for_each(|w| *w = 0.0);
    std::fs::write(&path, file.to_bytes().expect("encodes")).expect("write");
    path
}

fn spawn_emulator(iface: &str, seed: u64, idle_timeout_s: f64) -> std::process::Child {
    spawn_emulator_with(iface, seed, idle_timeout_s, &[])
}

fn spawn_emulator_with(iface: &str, seed: u64, idle_timeout_s: f64, extra: &[&str]) -> std::process::Child {
    std::process::Command::new(workspace_bin("vge-bridge"))
        .args(["emulate", "--iface", iface, "--model", "sim", "--json", "--seed", &seed.to_string()])
        .args(["--idle-timeout-s", &idle_timeout_s.to_string()])
        .args(extra)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("vge-bridge emulate starts")
}

fn bridge_run(args: &[&str]) -> String {
    let out =
        std::process::Command::new(workspace_bin("vge-bridge")).arg("run").args(args).arg("--json").output();
    let out = out.expect("vge-bridge run starts");
    let stdout = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    assert!(
        out.status.success(),
        "vge-bridge run failed: {stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn wait_for_output(child: std::process::Child) -> String {
    let out = child.wait_with_output().expect("emulator exits");
    assert!(out.status.success(), "emulator failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).trim().to_owned()
}

/// Everything on the bus (classic and FD) while it runs, as protocol messages in bus order.
struct Capture {
    done: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: thread::JoinHandle<Vec<(Instant, Message)>>,
}

impl Capture {
    fn start(iface: &str) -> Self {
        let socket = socketcan::CanFdSocket::open(iface).expect("FD socket (vcan MTU 72)");
        socket.set_read_timeout(Duration::from_millis(100)).expect("timeout");
        let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let stop = done.clone();
        let thread = thread::spawn(move || {
            let mut seen = Vec::new();
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                match socket.read_frame() {
                    Ok(socketcan::CanAnyFrame::Normal(f)) => {
                        if let socketcan::Id::Standard(id) = f.id()
                            && let Ok(m) = Message::decode(id.as_raw(), f.data())
                        {
                            seen.push((Instant::now(), m));
                        }
                    }
                    Ok(socketcan::CanAnyFrame::Fd(f)) => {
                        if let socketcan::Id::Standard(id) = f.id()
                            && let Ok(fd) = FdMessage::decode(id.as_raw(), f.data())
                        {
                            seen.extend(fd.to_classic().into_iter().map(|m| (Instant::now(), m)));
                        }
                    }
                    _ => {}
                }
            }
            seen
        });
        Self { done, thread }
    }

    fn stop(self) -> Vec<(Instant, Message)> {
        self.done.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.join().expect("capture thread")
    }
}

/// The gait that ships with vge (policies/cube.vgep, what scripts/demo.sh runs) turns the
/// cube more than a full turn over CAN, switching contacts, without a drop: the emulated
/// hand's nodes on vcan0, the bridge driving them at 20 Hz for 30 s, the demo's run (the
/// shipped gait turns about 0.39 rad/s: 15 s are not a full turn).
#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn the_shipped_gait_turns_the_cube_a_full_turn_over_vcan() {
    let iface = hil_iface();
    let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");
    let emulator = spawn_emulator(&iface, 0, 2.0);
    thread::sleep(Duration::from_millis(500)); // the emulator grasps the cube first
    let over_can =
        bridge_run(&["--policy", policy, "--backend", "can", "--iface", &iface, "--duration", "30"]);
    let emulated = wait_for_output(emulator);
    eprintln!("{over_can}\n{emulated}");
    assert_eq!(json_field(&over_can, "stop_reason").as_deref(), Some("duration"), "{over_can}");
    assert_eq!(json_field(&emulated, "terminated").as_deref(), Some("false"), "dropped: {emulated}");
    assert!(json_f64(&emulated, "rotation_rad") >= std::f64::consts::TAU, "{emulated}");
    assert!(json_f64(&emulated, "contact_switches") >= 10.0, "{emulated}");
}

/// Emulator and bridge as processes on vcan0 (classic frames, or the FD option), against the
/// same policy and seed run in-process; returns how many FD frames a third socket saw.
fn closed_loop_matches_in_process(fd: bool) -> usize {
    let iface = hil_iface();
    let policy = exported_policy(3);
    let policy_arg = policy.to_str().expect("utf-8 temp path");
    let duration = "2.0";

    // A third socket counts FD frames on the bus while the loop runs.
    let capture = socketcan::CanFdSocket::open(&iface).expect("FD socket (vcan MTU 72)");
    capture.set_read_timeout(Duration::from_millis(200)).expect("timeout");
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let counting = done.clone();
    let counter = thread::spawn(move || {
        let mut fd_frames = 0;
        while !counting.load(std::sync::atomic::Ordering::Relaxed) {
            if let Ok(socketcan::CanAnyFrame::Fd(_)) = capture.read_frame() {
                fd_frames += 1;
            }
        }
        fd_frames
    });

    let mut emulator_args = vec![];
    let mut run_args =
        vec!["--policy", policy_arg, "--backend", "can", "--iface", &iface, "--duration", duration];
    if fd {
        emulator_args.push("--fd");
        run_args.push("--fd");
    }
    let emulator = spawn_emulator_with(&iface, 5, 2.0, &emulator_args);
    thread::sleep(Duration::from_millis(500)); // the emulator resets the sim (grasp) first
    let over_can = bridge_run(&run_args);
    let emulated = wait_for_output(emulator);
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let fd_frames = counter.join().expect("counter");
    let in_process =
        bridge_run(&["--policy", policy_arg, "--backend", "sim", "--seed", "5", "--duration", duration]);
    let _ = std::fs::remove_file(&policy);
    eprintln!(
        "over CAN (fd {fd}): {over_can}\nemulator: {emulated}\nin-process: {in_process}\nFD frames {fd_frames}"
    );

    assert_eq!(json_field(&over_can, "stop_reason").as_deref(), Some("duration"));
    assert_eq!(json_f64(&over_can, "bad_frames"), 0.0);
    assert_eq!(json_f64(&emulated, "bad_frames"), 0.0);
    // Both runs are the same lockstep exchange of the same frames; they may differ by a step
    // or two at the ends (start-up and halt timing), so compare per-step rotation.
    let (rot_can, steps_can) = (json_f64(&emulated, "rotation_rad"), json_f64(&emulated, "sim_steps"));
    let (rot_sim, steps_sim) = (json_f64(&in_process, "rotation_rad"), json_f64(&in_process, "sim_steps"));
    assert!((steps_can - steps_sim).abs() <= 3.0, "{steps_can} vs {steps_sim} sim steps");
    assert!(rot_sim.abs() > 1e-3, "the policy should move the object at all: {rot_sim}");
    // Tolerance: both are the same lockstep exchange of the same quantised frames, so the
    // trajectories agree step for step; they differ only in the up-to-3 extra periods at the
    // ends (start-up queries, halt holds), in which the targets do not change and the object
    // only settles: far below 0.01 rad. 10% of the rotation covers timing of the last step.
    let tolerance = 0.01 + 0.1 * rot_sim.abs();
    assert!((rot_can - rot_sim).abs() <= tolerance, "over CAN {rot_can} rad vs in-process {rot_sim} rad");
    fd_frames
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn closed_loop_over_can_turns_the_object_as_the_in_process_sim_does() {
    assert_eq!(closed_loop_matches_in_process(false), 0, "classic mode sends no FD frames");
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn closed_loop_over_can_fd_turns_the_object_as_the_in_process_sim_does() {
    // 40 steps at 20 Hz: one hand command and five node states per step (plus start-up).
    let fd_frames = closed_loop_matches_in_process(true);
    assert!(fd_frames >= 6 * 38, "only {fd_frames} FD frames on the bus");
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn stopping_the_emulator_fires_the_bridge_watchdog() {
    let iface = hil_iface();
    // i8 weights: the bridge runs every weight type (f16 below).
    let policy = exported_policy_as(4, "i8");
    let mut emulator = spawn_emulator(&iface, 1, 30.0);
    thread::sleep(Duration::from_millis(500));
    let killer = thread::spawn(move || {
        thread::sleep(Duration::from_millis(1500));
        emulator.kill().expect("kill the emulator");
        emulator.wait().expect("reaped")
    });
    let policy_arg = policy.to_str().expect("utf-8 temp path");
    let report =
        bridge_run(&["--policy", policy_arg, "--backend", "can", "--iface", &iface, "--duration", "20"]);
    killer.join().expect("killer thread");
    let _ = std::fs::remove_file(&policy);
    eprintln!("{report}");
    assert_eq!(json_field(&report, "stop_reason").as_deref(), Some("watchdog"), "{report}");
    // It stopped within the watchdog's 5 periods (20 Hz) of the emulator's death, not at 20 s.
    let steps = json_f64(&report, "steps");
    assert!(steps < 20.0 * 4.0, "{steps} steps");
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn bad_frames_from_a_third_socket_are_counted_and_ignored() {
    let iface = hil_iface();
    let policy = exported_policy_as(5, "f16");
    let emulator = spawn_emulator(&iface, 2, 2.0);
    thread::sleep(Duration::from_millis(500));
    let injector_iface = iface.clone();
    let injected = 30;
    let injector = thread::spawn(move || {
        let socket = open(&injector_iface);
        // Inject only once the bridge is on the bus (its first joint command): a fixed
        // 300 ms head start lost the first frame when a loaded machine started it later.
        socket.set_read_timeout(READ_TIMEOUT).expect("read timeout");
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            assert!(Instant::now() < deadline, "the bridge sent no joint command within 20 s");
            let Ok(frame) = socket.read_frame() else { continue };
            let Ok((id, data)) = standard_id_and_data(&frame) else { continue };
            if let Ok(Message::JointCommand(_)) = Message::decode(id, data) {
                break;
            }
        }
        for i in 0..injected {
            let frame = match i % 3 {
                // An id no node uses.
                0 => CanFrame::new(StandardId::new(0x555).expect("id"), &[0xff; 8]),
                // A joint-state id with a short payload.
                1 => CanFrame::new(StandardId::new(0x181).expect("id"), &[1, 2, 3]),
                // An extended id.
                _ => CanFrame::new(socketcan::ExtendedId::new(0x1abc_def0).expect("id"), &[0; 8]),
            };
            socket.write_frame(&frame.expect("frame")).expect("inject");
            thread::sleep(Duration::from_millis(20));
        }
    });
    let policy_arg = policy.to_str().expect("utf-8 temp path");
    let report =
        bridge_run(&["--policy", policy_arg, "--backend", "can", "--iface", &iface, "--duration", "2.0"]);
    injector.join().expect("injector");
    let emulated = wait_for_output(emulator);
    let _ = std::fs::remove_file(&policy);
    eprintln!("{report}\n{emulated}");
    assert_eq!(json_field(&report, "stop_reason").as_deref(), Some("duration"), "{report}");
    // The unknown and the extended ids never reach the bridge (its socket's filter drops
    // them); the short joint-state frames pass the filter and are counted.
    assert_eq!(json_f64(&report, "bad_frames"), f64::from(injected / 3), "{report}");
    // The nodes' filter passes only commands and the host heartbeat: none of these.
    assert_eq!(json_f64(&emulated, "bad_frames"), 0.0, "{emulated}");
}

// ---------------------------------------------------------------- issue 13: faults on the wire

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn fd_frames_captured_on_vcan_decode_with_the_dbc() {
    let iface = hil_iface();
    let sender = socketcan::CanFdSocket::open(&iface).expect("FD socket");
    let capture = socketcan::CanFdSocket::open(&iface).expect("FD socket");
    capture.set_read_timeout(READ_TIMEOUT).expect("read timeout");
    let mut q_target = [0.0f32; 15];
    for (i, q) in q_target.iter_mut().enumerate() {
        *q = 0.1 * i as f32 - 0.7;
    }
    let mut messages =
        vec![FdMessage::HandCommand(HandCommand { q_target_rad: q_target, enable: true, seq: 77 })];
    for finger in FingerId::all() {
        let k = f32::from(finger.index());
        messages.push(FdMessage::NodeState(FingerState {
            finger,
            q_rad: [0.1 * k, -0.2, 1.1],
            dq_radps: [0.5, -1.5 * k, 3.0],
            tau_nm: [0.3, -0.1, 0.02 * k],
            tip_position_m: [0.05, -0.01 * k, 0.002],
            tip_force_n: 2.5 + k,
            tip_normal: [0.0, 0.6, -0.8],
            enabled: true,
            fault: finger.index() == 3,
            in_contact: finger.index() != 1,
            seq: 40 + finger.index(),
        }));
    }
    let mut lines = String::new();
    for m in &messages {
        let raw = m.encode().expect("encode");
        let id = StandardId::new(raw.id).expect("11-bit id");
        let frame = socketcan::CanFdFrame::new(id, raw.payload()).expect("FD frame");
        sender.write_frame(&frame).expect("write FD frame");
        let got = match capture.read_frame().expect("captured") {
            socketcan::CanAnyFrame::Fd(f) => f,
            other => panic!("expected an FD frame, got {other:?}"),
        };
        assert!(FdMessage::decode(raw.id, got.data()).is_ok(), "vge decodes its own FD frame");
        let hex: String = got.data().iter().map(|b| format!("{b:02x}")).collect();
        let mut signals = Vec::new();
        match m {
            FdMessage::HandCommand(c) => {
                for (i, q) in c.q_target_rad.iter().enumerate() {
                    let joint = ["roll", "prox", "dist"][i % 3];
                    signals.push(format!("q_target_f{}_{joint}={q}", i / 3));
                }
                signals.push(format!("enable={}", u8::from(c.enable)));
                signals.push(format!("seq={}", c.seq));
            }
            FdMessage::NodeState(s) => {
                for (name, v) in [("q", s.q_rad), ("dq", s.dq_radps), ("tau", s.tau_nm)] {
                    for (joint, x) in ["roll", "prox", "dist"].iter().zip(v) {
                        signals.push(format!("{name}_{joint}={x}"));
                    }
                }
                for (axis, (p, n)) in ["x", "y", "z"].iter().zip(s.tip_position_m.iter().zip(s.tip_normal)) {
                    signals.push(format!("p_{axis}={p}"));
                    signals.push(format!("n_{axis}={n}"));
                }
                signals.push(format!("force={}", s.tip_force_n));
                signals.push(format!("enabled={}", u8::from(s.enabled)));
                signals.push(format!("fault={}", u8::from(s.fault)));
                signals.push(format!("in_contact={}", u8::from(s.in_contact)));
                signals.push(format!("seq={}", s.seq));
            }
        }
        lines.push_str(&format!("{:03x} {hex} {}\n", raw.id, signals.join(" ")));
    }
    let stdout = run_dbc_check(&lines);
    assert!(stdout.contains(&format!("{} frames", messages.len())), "{stdout}");
}

/// Runs tests/dbc_check.py on capture lines; panics with its output unless every signal
/// decodes to the value given.
fn run_dbc_check(lines: &str) -> String {
    let capture_file = std::env::temp_dir().join(format!("vge-hil-capture-fd-{}.txt", std::process::id()));
    std::fs::write(&capture_file, lines).expect("write capture");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/dbc_check.py");
    let python = std::env::var("VGE_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let out =
        std::process::Command::new(python).arg(script).arg(&capture_file).output().expect("python runs");
    let _ = std::fs::remove_file(&capture_file);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    eprintln!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "cantools decoding with docs/vge-hand.dbc disagrees:\n{stdout}");
    stdout
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn heartbeats_both_ways_and_enable_states_follow_the_commands() {
    let iface = hil_iface();
    let policy = exported_policy(6);
    let capture = Capture::start(&iface);
    let emulator = spawn_emulator(&iface, 3, 1.5);
    thread::sleep(Duration::from_millis(500));
    let policy_arg = policy.to_str().expect("utf-8 temp path");
    let report =
        bridge_run(&["--policy", policy_arg, "--backend", "can", "--iface", &iface, "--duration", "3.0"]);
    let emulated = wait_for_output(emulator);
    let seen = capture.stop();
    let _ = std::fs::remove_file(&policy);
    eprintln!("{report}\n{emulated}");

    // Heartbeats at 10 Hz: the host's over the bridge's ~3.2 s, each node's over the
    // emulator's whole life (~5 s), counters incrementing by one.
    let beats = |node: u8| -> Vec<(Instant, u8, NodeState)> {
        seen.iter()
            .filter_map(|(t, m)| match m {
                Message::Heartbeat(h) if h.node == node => Some((*t, h.counter, h.state)),
                _ => None,
            })
            .collect()
    };
    for node in (0..NUM_FINGERS).chain([HOST_NODE]) {
        let b = beats(node);
        let span = b.last().map(|l| l.0.duration_since(b[0].0).as_secs_f64()).unwrap_or(0.0);
        let rate = (b.len() as f64 - 1.0) / span.max(1e-9);
        assert!(
            b.len() >= 25 && (8.0..=12.0).contains(&rate),
            "node {node:#x}: {} beats, {rate:.1} Hz",
            b.len()
        );
        assert!(b.windows(2).all(|w| w[1].1 == w[0].1.wrapping_add(1)), "node {node:#x} counter skips");
    }
    assert!(
        beats(HOST_NODE).iter().any(|b| b.2 == NodeState::Enabled),
        "host heartbeat says enabled while running"
    );
    assert!(
        beats(2).iter().any(|b| b.2 == NodeState::Enabled)
            && beats(2).iter().any(|b| b.2 == NodeState::Ready)
    );
    assert_eq!(json_f64(&report, "heartbeats_out"), beats(HOST_NODE).len() as f64, "{report}");

    // Every joint position reports the enable flag of the command it answers (same finger,
    // same seq): disabled during the start-up queries and after the final disable.
    let mut commands = std::collections::HashMap::new();
    let (mut checked, mut disabled_replies) = (0, 0);
    for (_, m) in &seen {
        match m {
            Message::JointCommand(c) => {
                commands.insert((c.finger.index(), c.seq), c.enable);
            }
            Message::JointPosition(p) => {
                let Some(&enable) = commands.get(&(p.finger.index(), p.seq)) else { continue };
                assert_eq!(
                    p.status & STATUS_ENABLED != 0,
                    enable,
                    "finger {} seq {}",
                    p.finger.index(),
                    p.seq
                );
                checked += 1;
                disabled_replies += usize::from(!enable);
            }
            _ => {}
        }
    }
    assert!(
        checked >= 5 * 55 && disabled_replies >= 10,
        "{checked} positions checked, {disabled_replies} disabled"
    );
    assert_eq!(json_f64(&report, "stale_frames") + json_f64(&report, "implausible_frames"), 0.0, "{report}");
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn a_killed_bridge_leaves_the_nodes_holding_with_fault_command_timeout() {
    let iface = hil_iface();
    let policy = exported_policy(7);
    let capture = Capture::start(&iface);
    let emulator = spawn_emulator_with(&iface, 4, 2.0, &["--command-timeout-s", "0.3"]);
    thread::sleep(Duration::from_millis(500));
    let mut bridge = std::process::Command::new(workspace_bin("vge-bridge"))
        .args(["run", "--policy", policy.to_str().expect("utf-8"), "--backend", "can", "--iface", &iface])
        .args(["--duration", "30", "--json"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("bridge starts");
    thread::sleep(Duration::from_millis(1500));
    bridge.kill().expect("SIGKILL the bridge");
    let killed_at = Instant::now();
    bridge.wait().expect("reaped");
    let out = emulator.wait_with_output().expect("emulator exits");
    let seen = capture.stop();
    let _ = std::fs::remove_file(&policy);
    let summary = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("{summary}\n{stderr}");

    assert_eq!(out.status.code(), Some(2), "the emulator says a node faulted: {stderr}");
    assert!(stderr.contains("command_timeout"), "{stderr}");
    assert_eq!(json_f64(&summary, "command_timeouts"), 5.0, "{summary}");
    let faults: Vec<_> = seen
        .iter()
        .filter_map(|(t, m)| match m {
            Message::Fault(f) if f.code == FaultCode::CommandTimeout => Some((*t, f.finger.index())),
            _ => None,
        })
        .collect();
    let mut fingers: Vec<u8> = faults.iter().map(|f| f.1).collect();
    fingers.sort_unstable();
    assert_eq!(fingers, [0, 1, 2, 3, 4], "one command_timeout fault per finger on the bus");
    let latency = faults[0].0.duration_since(killed_at);
    assert!(latency < Duration::from_millis(800), "faults {latency:?} after the kill");
    // After the fault the nodes report it: heartbeat state fault, and no further sim step
    // (nothing moves: the positions stay what they were).
    assert!(
        seen.iter()
            .any(|(t, m)| *t > faults[0].0
                && matches!(m, Message::Heartbeat(h) if h.state == NodeState::Fault))
    );
    eprintln!(
        "hil: command_timeout raised {:.0} ms after the bridge was killed",
        latency.as_secs_f64() * 1e3
    );
}

/// Injects from a third socket, for every enabled command of `finger` seen on the bus,
/// the frame `forge` makes of that command; returns how many it sent.
fn spawn_injector(
    iface: &str,
    finger: u8,
    run_for: Duration,
    mut forge: impl FnMut(&JointCommand) -> Option<RawFrame> + Send + 'static,
) -> thread::JoinHandle<usize> {
    let socket = open(iface);
    socket.set_read_timeout(Duration::from_millis(50)).expect("timeout");
    thread::spawn(move || {
        let start = Instant::now();
        let mut sent = 0;
        while start.elapsed() < run_for {
            let Ok(frame) = socket.read_frame() else { continue };
            let Ok((id, data)) = standard_id_and_data(&frame) else { continue };
            if let Ok(Message::JointCommand(c)) = Message::decode(id, data)
                && c.finger.index() == finger
                && c.enable
                && let Some(frame) = forge(&c)
            {
                socket.write_frame(&to_can_frame(&frame).expect("frame")).expect("inject");
                sent += 1;
            }
        }
        sent
    })
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn implausible_positions_from_the_wire_hold_then_halt_and_stale_ones_are_dropped() {
    let iface = hil_iface();
    let policy = exported_policy(8);
    let policy_arg = policy.to_str().expect("utf-8 temp path");

    // 1. After 1 s, finger 2 also "reports" +3.2767 / -3.2768 rad (0x7FFF / 0x8000) with the
    //    current seq, answering every command.
    let emulator = spawn_emulator(&iface, 6, 1.5);
    thread::sleep(Duration::from_millis(500));
    let started = Instant::now();
    let mut n = 0u32;
    let injector = spawn_injector(&iface, 2, Duration::from_secs(6), move |c| {
        n += 1;
        (started.elapsed() > Duration::from_secs(1)).then(|| {
            let p = JointPosition {
                finger: c.finger,
                q_rad: [3.2767, 0.0, 0.0],
                status: STATUS_ENABLED,
                seq: c.seq,
            };
            let mut frame = Message::JointPosition(p).encode().expect("+3.2767 rad is the field's maximum");
            if n % 2 == 1 {
                // 0x8000 = -3.2768 rad, a raw count the encoder itself never writes.
                frame.data[0..2].copy_from_slice(&[0x00, 0x80]);
            }
            frame
        })
    });
    let report =
        bridge_run(&["--policy", policy_arg, "--backend", "can", "--iface", &iface, "--duration", "5.0"]);
    let emulated = wait_for_output(emulator);
    let injected = injector.join().expect("injector");
    eprintln!("{report}\n{emulated}\ninjected {injected}");
    assert_eq!(json_field(&report, "stop_reason").as_deref(), Some("implausible_state"), "{report}");
    assert!(json_field(&report, "stop_detail").is_some_and(|d| d.contains("node 2")), "{report}");
    assert!(json_f64(&report, "implausible_frames") >= 4.0 && json_f64(&report, "holds") >= 4.0, "{report}");
    assert!(json_f64(&report, "steps") < 40.0, "halted within a few periods of the first: {report}");
    assert_eq!(
        json_field(&emulated, "terminated").as_deref(),
        Some("false"),
        "the bridge held the grasp: {emulated}"
    );

    // 2. Three position frames of finger 4 replayed with a seq 20 commands old: dropped and
    //    counted, the run goes on.
    let emulator = spawn_emulator(&iface, 6, 1.5);
    thread::sleep(Duration::from_millis(500));
    let mut replays = 0;
    let injector = spawn_injector(&iface, 4, Duration::from_secs(3), move |c| {
        replays += 1;
        (10..13).contains(&replays).then(|| {
            let old = JointPosition {
                finger: c.finger,
                q_rad: [0.3; 3],
                status: STATUS_ENABLED,
                seq: c.seq.wrapping_sub(20),
            };
            Message::JointPosition(old).encode().expect("in range")
        })
    });
    let report =
        bridge_run(&["--policy", policy_arg, "--backend", "can", "--iface", &iface, "--duration", "2.0"]);
    let emulated = wait_for_output(emulator);
    assert_eq!(injector.join().expect("injector"), 3);
    let _ = std::fs::remove_file(&policy);
    eprintln!("{report}\n{emulated}");
    assert_eq!(json_field(&report, "stop_reason").as_deref(), Some("duration"), "{report}");
    assert_eq!(json_f64(&report, "stale_frames"), 3.0, "{report}");
    assert!((1.0..=3.0).contains(&json_f64(&report, "holds")), "{report}");
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn a_flood_of_id_0x000_does_not_disturb_the_loop() {
    let iface = hil_iface();
    let policy = hold_policy(9);
    let emulator = spawn_emulator(&iface, 7, 1.5);
    thread::sleep(Duration::from_millis(500));
    // 5,000 frames of id 0x000 at 800/s (6.25 s), from 0.5 s into the run.
    let flood_iface = iface.clone();
    let flood = thread::spawn(move || {
        let socket = open(&flood_iface);
        let frame = CanFrame::new(StandardId::new(0x000).expect("id"), &[0xff; 8]).expect("frame");
        thread::sleep(Duration::from_millis(500));
        let start = Instant::now();
        let mut sent = 0u32;
        for k in 0..5000u32 {
            let due = start + Duration::from_secs_f64(f64::from(k) / 800.0);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                thread::sleep(wait);
            }
            if socket.write_frame(&frame).is_ok() {
                sent += 1;
            }
        }
        (sent, start.elapsed())
    });
    let policy_arg = policy.to_str().expect("utf-8 temp path");
    let report =
        bridge_run(&["--policy", policy_arg, "--backend", "can", "--iface", &iface, "--duration", "7.5"]);
    let emulated = wait_for_output(emulator);
    let (sent, took) = flood.join().expect("flood");
    let _ = std::fs::remove_file(&policy);
    eprintln!("{report}\n{emulated}\nflood: {sent} frames in {took:?}");
    assert_eq!(sent, 5000);
    assert_eq!(json_field(&report, "stop_reason").as_deref(), Some("duration"), "{report}");
    assert_eq!(json_f64(&report, "deadline_misses"), 0.0, "{report}");
    assert_eq!(json_f64(&report, "bad_frames"), 0.0, "the kernel filter drops the flood: {report}");
    assert!((json_f64(&report, "achieved_rate_hz") - 20.0).abs() < 0.5, "{report}");
    assert_eq!(json_field(&emulated, "terminated").as_deref(), Some("false"), "object held: {emulated}");
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn error_frames_are_counted_and_bus_off_halts_the_bridge() {
    let iface = hil_iface();
    let policy = exported_policy(10);
    let emulator = spawn_emulator(&iface, 8, 1.5);
    thread::sleep(Duration::from_millis(500));
    let inject_iface = iface.clone();
    let injector = thread::spawn(move || {
        let socket = open(&inject_iface);
        thread::sleep(Duration::from_millis(700));
        // Error-passive (controller problem, data[1] = 0x10 rx/0x20 tx passive) three times,
        // then bus-off.
        for class in [0x004, 0x004, 0x004, 0x040] {
            let frame = socketcan::CanErrorFrame::new_error(class, &[0, 0x20, 0, 0, 0, 0, 0, 0])
                .expect("error frame");
            socket.write_frame(&frame).expect("vcan carries error frames written by a raw socket");
            thread::sleep(Duration::from_millis(200));
        }
    });
    let policy_arg = policy.to_str().expect("utf-8 temp path");
    let report =
        bridge_run(&["--policy", policy_arg, "--backend", "can", "--iface", &iface, "--duration", "5.0"]);
    injector.join().expect("injector");
    let emulated = wait_for_output(emulator);
    let _ = std::fs::remove_file(&policy);
    eprintln!("{report}\n{emulated}");
    assert_eq!(json_field(&report, "stop_reason").as_deref(), Some("bus_off"), "{report}");
    assert_eq!(json_f64(&report, "error_frames_controller"), 3.0, "{report}");
    assert_eq!(json_f64(&report, "error_frames_bus_off"), 1.0, "{report}");
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn the_emulator_prints_its_summary_on_ctrl_c() {
    let iface = hil_iface();
    let emulator = spawn_emulator(&iface, 9, 30.0);
    thread::sleep(Duration::from_millis(1500));
    let status = std::process::Command::new("kill")
        .args(["-INT", &emulator.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let started = Instant::now();
    let out = emulator.wait_with_output().expect("emulator exits");
    let stdout = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    eprintln!("{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "Ctrl-C is a normal stop: {}", String::from_utf8_lossy(&out.stderr));
    assert!(started.elapsed() < Duration::from_secs(2), "stopped promptly");
    assert!(json_f64(&stdout, "heartbeats_sent") >= 50.0, "{stdout}");
    assert_eq!(json_f64(&stdout, "sim_steps"), 0.0, "{stdout}");
}
