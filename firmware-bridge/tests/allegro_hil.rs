//! Hardware-in-the-loop tests of the bridge's Allegro mode on a real SocketCAN interface
//! (vcan0, `VGE_HIL_IFACE`): `vge-bridge run --hand allegro` and `vge-bridge emulate --hand
//! allegro` as separate processes, every frame between them captured from a third socket.
//! `#[ignore]`d like `tests/tests/hil.rs`: `scripts/hil.sh` runs them (`--ignored`) where vcan0
//! is up, in a CAN-capable guest where this kernel has none.
//!
//! They assert what the bridge guarantees on any host: the start-up and shut-down frames and
//! their order, every frame decoded by cantools with docs/allegro-v4.dbc, the grasp held, the
//! halt on silent position frames and its exit status, no torque beyond a clip on the bus. A
//! guest's speed depends on its host (a user-mode-linux guest on a loaded machine stalls for
//! hundreds of milliseconds), so the loop's timing (rate, jitter, late sets) is printed, not
//! asserted, and runs that test something else give the position timeout seconds
//! ([`TOLERANT`]).

#[path = "support/allegro_dbc.rs"]
mod allegro_dbc;
#[path = "../../tests/support/python.rs"]
mod python_env;

use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use socketcan::{CanSocket, Socket, SocketOptions};
use vge_bridge::protocol::allegro::{
    AllegroConfig, AllegroFrame, Command as AllegroCommand, Report, SetPeriod,
};
use vge_bridge::socketcan_io::{allegro_frame_of, allegro_to_can_frame};

fn iface() -> String {
    std::env::var("VGE_HIL_IFACE").unwrap_or_else(|_| "vcan0".to_owned())
}

/// The position timeout for runs that test something else: 1000 periods, 3 s, and 10 s for
/// start-up's answers, so that a guest stall does not halt them.
const TOLERANT: [&str; 4] = ["--watchdog-periods", "1000", "--startup-timeout-s", "10"];
/// How long the emulator waits without a frame before it ends (after the bridge has gone).
const EMULATOR_IDLE_S: &str = "3";
const CFG: AllegroConfig = AllegroConfig::V4;

fn open(iface: &str) -> CanSocket {
    let socket = CanSocket::open(iface).unwrap_or_else(|e| {
        panic!("cannot open CAN interface {iface}: {e}. HIL tests need it up: run scripts/hil.sh")
    });
    // Seconds of the bus (SO_RCVBUFFORCE: root in the guest), so that a reader the guest does
    // not schedule for a while loses no frame; the system's limit elsewhere.
    const SOL_SOCKET: i32 = 1;
    const SO_RCVBUF: i32 = 8;
    const SO_RCVBUFFORCE: i32 = 33;
    if socket.set_socket_option_int(SOL_SOCKET, SO_RCVBUFFORCE, 16 << 20).is_err() {
        socket.set_socket_option_int(SOL_SOCKET, SO_RCVBUF, 16 << 20).expect("SO_RCVBUF");
    }
    socket
}

/// Every frame on the bus while it runs, in bus order, with when the capture read it.
struct Capture {
    done: Arc<AtomicBool>,
    thread: thread::JoinHandle<Vec<(Instant, AllegroFrame)>>,
}

impl Capture {
    fn start(iface: &str) -> Self {
        let socket = open(iface);
        socket.set_read_timeout(Duration::from_millis(50)).expect("timeout");
        let done = Arc::new(AtomicBool::new(false));
        let stop = done.clone();
        let thread = thread::spawn(move || {
            let mut seen = Vec::new();
            while !stop.load(Ordering::Relaxed) {
                if let Ok(frame) = socket.read_frame()
                    && let Ok(f) = allegro_frame_of(&frame)
                {
                    seen.push((Instant::now(), f));
                }
            }
            // What is still queued.
            socket.set_nonblocking(true).expect("non-blocking");
            while let Ok(frame) = socket.read_frame() {
                if let Ok(f) = allegro_frame_of(&frame) {
                    seen.push((Instant::now(), f));
                }
            }
            seen
        });
        Self { done, thread }
    }

    fn stop(self) -> Vec<(Instant, AllegroFrame)> {
        self.done.store(true, Ordering::Relaxed);
        self.thread.join().expect("capture thread")
    }
}

/// `vge-bridge emulate --hand allegro` on `iface`, once it answers an info request.
fn spawn_emulator(iface: &str) -> Child {
    let child = Command::new(env!("CARGO_BIN_EXE_vge-bridge"))
        .args([
            "emulate",
            "--hand",
            "allegro",
            "--iface",
            iface,
            "--json",
            "--idle-timeout-s",
            EMULATOR_IDLE_S,
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("vge-bridge emulate starts");
    // CAN does not queue for sockets opened later: ask until the emulator answers.
    let probe = open(iface);
    probe.set_read_timeout(Duration::from_millis(200)).expect("timeout");
    let info =
        AllegroCommand::Request(vge_bridge::protocol::allegro::Request::Info).encode(&CFG).expect("frame");
    let started = Instant::now();
    'asking: loop {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the emulator did not answer an info request in 60 s"
        );
        probe.write_frame(&allegro_to_can_frame(&info).expect("frame")).expect("write");
        let asked = Instant::now();
        while asked.elapsed() < Duration::from_millis(200) {
            if let Ok(frame) = probe.read_frame()
                && let Ok(f) = allegro_frame_of(&frame)
                && matches!(Report::decode_frame(&CFG, &f), Ok(Report::Info(_)))
            {
                break 'asking;
            }
        }
    }
    child
}

/// `vge-bridge run --hand allegro --backend can --iface IFACE --hold --json ARGS` in the
/// background.
fn spawn_bridge(iface: &str, args: &[&str]) -> Child {
    let mut hold = vec!["--hold"];
    hold.extend(args);
    spawn_run(iface, &hold)
}

/// `vge-bridge run --hand allegro --backend can --iface IFACE --json ARGS` in the background.
fn spawn_run(iface: &str, args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_vge-bridge"))
        .args(["run", "--hand", "allegro", "--backend", "can", "--iface", iface, "--json"])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("vge-bridge run starts")
}

/// What a finished process left: exit status, stdout (its JSON line), stderr.
fn finish(child: Child) -> (Option<i32>, String, String) {
    let out = child.wait_with_output().expect("process ends");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).trim().to_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn json(line: &str) -> serde_json::Value {
    serde_json::from_str(line).unwrap_or_else(|e| panic!("not one JSON line ({e}): {line}"))
}

/// The loop's timing, printed: it depends on the host, not on vge.
fn print_timing(what: &str, r: &serde_json::Value) {
    eprintln!(
        "allegro hil timing (measured, not asserted) {what}: {} Hz achieved of {} Hz over {} torque sets; \
         |set interval - 3 ms| p50 {} us, p99 {} us, max {} us; {} late position sets (> 4.5 ms apart); \
         {} sets skipped for a newer one; torques written p50 {} us, p99 {} us, max {} us after their \
         positions, {} late (> 1.5 ms)",
        r["achieved_rate_hz"],
        r["rate_hz"],
        r["cycles"],
        r["jitter_p50_us"],
        r["jitter_p99_us"],
        r["jitter_max_us"],
        r["late_position_sets"],
        r["superseded_sets"],
        r["response_p50_us"],
        r["response_p99_us"],
        r["response_max_us"],
        r["late_torque_sets"],
    );
}

fn is_host_frame(f: &AllegroFrame) -> bool {
    // Remote frames are the host's requests; data frames are commands when the command
    // decoder takes them.
    f.is_remote() || AllegroCommand::decode_frame(&CFG, f).is_ok()
}

fn shape(f: &AllegroFrame) -> (u16, bool, usize) {
    (f.id(), f.is_remote(), f.payload().len())
}

const STARTUP: [(u16, bool, usize); 5] =
    [(0x104, false, 0), (0x200, true, 0), (0x220, true, 0), (0x204, false, 6), (0x100, false, 0)];
const SHUTDOWN: [(u16, bool, usize); 6] = [
    (0x180, false, 8),
    (0x184, false, 8),
    (0x188, false, 8),
    (0x18C, false, 8),
    (0x104, false, 0),
    (0x204, false, 6),
];

/// The capture from the bridge's first frame (its servo off) on: what came before is the
/// emulator's readiness probe.
fn from_bridge_start(seen: &[(Instant, AllegroFrame)]) -> &[(Instant, AllegroFrame)] {
    let first = seen.iter().position(|(_, f)| f.id() == 0x104).expect("the bridge's servo off on the bus");
    &seen[first..]
}

fn torque_counts(f: &AllegroFrame) -> [i16; 4] {
    let p = f.payload();
    std::array::from_fn(|j| i16::from_le_bytes([p[2 * j], p[2 * j + 1]]))
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn allegro_start_up_and_shut_down_on_vcan_frame_by_frame_and_every_frame_decodes_with_the_dbc() {
    let iface = iface();
    let emulator = spawn_emulator(&iface);
    let capture = Capture::start(&iface);
    let mut args = vec!["--steps", "400"];
    args.extend(TOLERANT);
    let (code, out, err) = finish(spawn_bridge(&iface, &args));
    assert_eq!(code, Some(0), "bridge: {out}\n{err}");
    let (emu_code, emu_out, emu_err) = finish(emulator);
    let seen = capture.stop();
    assert_eq!(emu_code, Some(0), "emulator: {emu_err}");
    let report = json(&out);
    assert_eq!(report["stop_reason"], "steps", "{out}");
    assert_eq!(report["cycles"], 400);
    assert_eq!(report["serial"], "VGEEMU01");
    assert_eq!(report["info"]["hardware_version"], 0x0400);
    print_timing("start-up run", &report);

    let run = from_bridge_start(&seen);
    let host: Vec<&AllegroFrame> = run.iter().map(|(_, f)| f).filter(|f| is_host_frame(f)).collect();
    let hand: Vec<&AllegroFrame> = run.iter().map(|(_, f)| f).filter(|f| !is_host_frame(f)).collect();
    // Start-up: servo off, info and serial requests, set period {3 ms, IMU off, 500 ms}, servo on.
    let first: Vec<_> = host[..5].iter().map(|f| shape(f)).collect();
    assert_eq!(first, STARTUP, "the bridge's first five frames");
    assert_eq!(host[3].payload(), &[3, 0, 0, 0, 0xF4, 0x01]);
    // The hand answers info, then serial, then reports positions.
    let answers: Vec<u16> = hand.iter().take(3).map(|f| f.id()).collect();
    assert_eq!(&answers[..2], &[0x200, 0x220], "the emulator's first answers");
    assert_eq!((hand[0].payload().len(), hand[1].payload().len()), (7, 8));
    // No torque before the hand's info and a complete set of positions.
    let first_torque = run.iter().position(|(_, f)| f.id() == 0x180).expect("torques");
    let before: Vec<u16> = run[..first_torque].iter().map(|(_, f)| f.id()).collect();
    assert!(before.contains(&0x200) && !before.iter().any(|id| (0x181..=0x18F).contains(id)));
    for id in [0x080, 0x084, 0x088, 0x08C] {
        assert!(before.contains(&id), "position {id:#05x} before the first torque: {before:03x?}");
    }
    // Torques go out a finger at a time, in sets of four, one set per position set.
    let torques: Vec<u16> = host.iter().map(|f| f.id()).filter(|id| (0x180..=0x18C).contains(id)).collect();
    assert_eq!(torques.len(), 4 * 400 + 4);
    for set in torques.chunks(4) {
        assert_eq!(set, [0x180, 0x184, 0x188, 0x18C]);
    }
    // Shut-down: zero torques, servo off, reports off; the hand's positions stop.
    let last: Vec<_> = host[host.len() - 6..].iter().map(|f| shape(f)).collect();
    assert_eq!(last, SHUTDOWN, "the bridge's last six frames");
    for f in &host[host.len() - 6..host.len() - 2] {
        assert_eq!(f.payload(), &[0; 8], "zero torque");
    }
    assert_eq!(host[host.len() - 1].payload(), &[0; 6], "reports off");
    let off_at = run.iter().rposition(|(_, f)| f.id() == 0x204).expect("set period 0");
    let after = run[off_at..].iter().filter(|(_, f)| (0x080..=0x08C).contains(&f.id())).count();
    assert!(after <= 4, "{after} position frames after the reports went off (one set may be on its way)");
    let emu = json(&emu_out);
    assert_eq!(emu["servo_on_at_end"], false, "{emu_out}");
    assert_eq!(emu["position_period_ms_at_end"], 0);
    assert_eq!(emu["torques_beyond_clip"], 0);
    assert_eq!(emu["ignored_frames"], 0, "every frame the bridge sent is a command the hand takes");

    // Every frame of both sides: decoded by the Rust decoders and by cantools with the DBC to
    // the same values, every DBC message among them.
    let mut lines = String::new();
    for (_, f) in &seen {
        lines
            .push_str(&allegro_dbc::frame_line(&CFG, f).unwrap_or_else(|| panic!("undecodable frame {f:?}")));
    }
    let stdout = allegro_dbc::check(&lines);
    eprint!("{stdout}");
    assert!(stdout.contains(&format!("{} frames", seen.len())), "{stdout}");
    assert!(stdout.contains("18 of 18 DBC messages"), "{stdout}");
    eprintln!(
        "allegro hil: start-up as captured: {}",
        run.iter()
            .take(12)
            .map(|(_, f)| format!(
                "{:03x}{}[{}]",
                f.id(),
                if f.is_remote() { "R" } else { "" },
                f.payload().iter().map(|b| format!("{b:02x}")).collect::<String>()
            ))
            .collect::<Vec<_>>()
            .join(" ")
    );
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn allegro_pd_loop_holds_the_start_grasp_for_10_s_over_vcan() {
    let iface = iface();
    let emulator = spawn_emulator(&iface);
    // 4000 sets are 12 s of the hand's time: the grip before the stand goes, then 10 s held.
    // Sets, not seconds: a slow guest slows the emulated hand's clock with it.
    let mut args = vec!["--steps", "4000", "--duration", "600"];
    args.extend(TOLERANT);
    let (code, out, err) = finish(spawn_bridge(&iface, &args));
    assert_eq!(code, Some(0), "bridge: {out}\n{err}");
    let (emu_code, emu_out, emu_err) = finish(emulator);
    assert_eq!(emu_code, Some(0), "emulator: {emu_err}");
    let report = json(&out);
    assert_eq!(report["stop_reason"], "steps", "{out}");
    assert_eq!(report["implausible_sets"], 0);
    print_timing("10 s hold", &report);
    let emu = json(&emu_out);
    eprintln!("allegro hil: emulator {emu_out}");
    let hold = &emu["hold"];
    assert!(hold.is_object(), "the stand was never taken away (the hand never gripped): {emu_out}");
    let f = |k: &str| hold[k].as_f64().unwrap_or_else(|| panic!("{k} in {hold}"));
    assert!(f("held_s") >= 10.0, "held {} s of the hand's time", f("held_s"));
    assert!(f("fell_m") < 0.01, "the cube sank {} m", f("fell_m"));
    assert!(
        f("moved_m") < 0.015 && f("turned_rad") < 0.3,
        "the cube moved {} m, turned {} rad",
        f("moved_m"),
        f("turned_rad")
    );
    assert!(f("tips_touching") >= 3.0, "{} fingertips touch the cube", f("tips_touching"));
    assert_eq!(emu["torques_beyond_clip"], 0);
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn allegro_position_frames_stopping_zero_the_torques_and_turn_the_servos_off() {
    let iface = iface();
    let emulator = spawn_emulator(&iface);
    let capture = Capture::start(&iface);
    // The tolerant timeout (3 s): a guest stall must not halt the loop before the test stops
    // the positions.
    let mut args = vec!["--duration", "600"];
    args.extend(TOLERANT);
    let bridge = spawn_bridge(&iface, &args);
    // Once the loop runs (torque frames on the bus), a third party silences the hand's position
    // reports with a set period of zero, as a hand whose reports stop.
    let watcher = open(&iface);
    watcher.set_read_timeout(Duration::from_millis(100)).expect("timeout");
    let started = Instant::now();
    let mut torque_sets = 0;
    while torque_sets < 200 {
        assert!(started.elapsed() < Duration::from_secs(120), "only {torque_sets} torque sets in 120 s");
        if let Ok(frame) = watcher.read_frame()
            && let Ok(f) = allegro_frame_of(&frame)
            && f.id() == 0x18C
        {
            torque_sets += 1;
        }
    }
    let silence = AllegroCommand::SetPeriod(SetPeriod::OFF).encode(&CFG).expect("frame");
    watcher.write_frame(&allegro_to_can_frame(&silence).expect("frame")).expect("write");
    let (code, out, err) = finish(bridge);
    let (_, emu_out, _) = finish(emulator);
    let seen = capture.stop();
    let report = json(&out);
    assert_eq!(code, Some(10), "watchdog's exit status: {out}\n{err}");
    assert_eq!(report["stop_reason"], "watchdog");
    let detail = report["stop_detail"].as_str().expect("detail");
    assert!(
        detail.contains("no complete set of position frames") && detail.contains("timeout 3000.0 ms"),
        "{detail}"
    );
    assert!(err.contains("zeroed the torques and turned the servos off"), "{err}");
    print_timing("until the positions stopped", &report);

    // On the bus: the bridge's last frames are the shut-down sequence, and between the hand's
    // last position frame and them the bridge sent at most two torque sets (the one it was
    // computing when that frame came, and the answer to the newest set), none computed
    // without fresh positions: a bridge that answered a backlog would send many.
    let run = from_bridge_start(&seen);
    let host: Vec<usize> =
        (0..run.len()).filter(|&i| is_host_frame(&run[i].1) && !run[i].1.is_remote()).collect();
    let shutdown = &host[host.len() - 6..];
    let shapes: Vec<_> = shutdown.iter().map(|&i| shape(&run[i].1)).collect();
    assert_eq!(shapes, SHUTDOWN, "the bridge's last six frames");
    for &i in &shutdown[..4] {
        assert_eq!(run[i].1.payload(), &[0; 8], "zero torque");
    }
    let last_position = run.iter().rposition(|(_, f)| (0x080..=0x08C).contains(&f.id())).expect("positions");
    assert!(last_position < shutdown[0], "positions after the shut-down began");
    let late_torques =
        run[last_position + 1..shutdown[0]].iter().filter(|(_, f)| (0x180..=0x18C).contains(&f.id())).count();
    assert!(late_torques <= 8, "{late_torques} torque frames after the last position frame");
    let reaction = run[shutdown[0]].0.duration_since(run[last_position].0);
    eprintln!(
        "allegro hil timing (measured, not asserted): zero torques {:.1} ms after the last position frame \
         (timeout 3000 ms)",
        reaction.as_secs_f64() * 1e3
    );
    let emu = json(&emu_out);
    assert_eq!(emu["servo_on_at_end"], false, "{emu_out}");
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn allegro_torque_beyond_the_clip_never_leaves_the_host() {
    let iface = iface();
    let emulator = spawn_emulator(&iface);
    let capture = Capture::start(&iface);
    // Targets 1 rad past the grasp, reached at once: kp 3 asks for up to 3 N m, five times the
    // largest clip.
    let mut args = vec!["--steps", "300", "--squeeze-rad", "1.0", "--max-delta-rad", "1.0"];
    args.extend(TOLERANT);
    let (code, out, err) = finish(spawn_bridge(&iface, &args));
    assert_eq!(code, Some(0), "bridge: {out}\n{err}");
    let (_, emu_out, _) = finish(emulator);
    let seen = capture.stop();
    let report = json(&out);
    let asked = report["max_torque_nm"].as_f64().expect("max torque");
    assert!(asked > 0.5625, "the PD law asked for at most {asked} N m, within the largest clip");
    assert!(report["torque_clips"].as_u64() > Some(0), "{out}");
    let limits = CFG.torque.pwm_limit;
    let mut frames = 0;
    let mut at_clip = 0;
    for (_, f) in from_bridge_start(&seen).iter().filter(|(_, f)| (0x180..=0x18C).contains(&f.id())) {
        let finger = usize::from((f.id() - 0x180) / 4);
        for (j, count) in torque_counts(f).into_iter().enumerate() {
            let limit = limits[finger][j].unsigned_abs();
            assert!(
                count.unsigned_abs() <= limit,
                "{count} counts on finger {finger} joint {j} (clip {limit})"
            );
            at_clip += usize::from(count.unsigned_abs() == limit);
        }
        frames += 1;
    }
    assert_eq!(frames, 4 * 300 + 4);
    assert!(at_clip > 0, "no joint reached its clip");
    assert_eq!(json(&emu_out)["torques_beyond_clip"], 0, "{emu_out}");
    eprintln!(
        "allegro hil: {frames} torque frames, {at_clip} joint torques at their clip, none beyond; PD asked up to {asked} N m"
    );
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn allegro_policy_sets_the_pd_targets_over_vcan_at_its_own_rate() {
    let iface = iface();
    // A stored untrained proprio:2 Allegro policy (`vge export --init --hand allegro
    // --observation proprio:2 --hidden 64,64 --seed 7`): the guest runs no libtorch, and a
    // test binary that wrote one with vge-export would link it under the workspace's features.
    let policy = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/fixtures/policies/allegro-proprio2-init.vgep");
    let emulator = spawn_emulator(&iface);
    let capture = Capture::start(&iface);
    // 2000 sets are 6 s of the hand's time; the policy runs at its file's 20 Hz meanwhile.
    let mut args =
        vec!["--policy", policy.to_str().expect("utf-8 path"), "--steps", "2000", "--duration", "600"];
    args.extend(TOLERANT);
    let (code, out, err) = finish(spawn_run(&iface, &args));
    assert_eq!(code, Some(0), "bridge: {out}\n{err}");
    let (emu_code, emu_out, emu_err) = finish(emulator);
    let seen = capture.stop();
    assert_eq!(emu_code, Some(0), "emulator: {emu_err}");
    let report = json(&out);
    assert_eq!(report["stop_reason"], "steps", "{out}");
    assert_eq!(
        (report["mode"].as_str(), report["observation"].as_str()),
        (Some("policy"), Some("proprio:2")),
        "{out}"
    );
    assert_eq!(report["cycles"], 2000);
    print_timing("policy-driven run", &report);
    // The policy ran at its rate, on every update once the start grasp had settled (0.3 s
    // held, 6 updates, after the few that reach it: as the env's reset), without an error or a
    // non-finite target.
    let updates = report["target_updates"].as_u64().expect("target_updates");
    let policy_updates = report["policy_updates"].as_u64().expect("policy_updates");
    assert_eq!(report["grasp"], "press", "{out}");
    assert!(
        (7..=7 + 10).contains(&(updates - policy_updates)),
        "{updates} updates, {policy_updates} the policy's: {out}"
    );
    assert_eq!(
        (report["target_errors"].as_u64(), report["non_finite_holds"].as_u64()),
        (Some(0), Some(0)),
        "{out}"
    );
    let achieved = report["achieved_rate_hz"].as_f64().expect("rate");
    // 2000 sets at the achieved rate, 20 updates a second of wall time.
    let expected = 2000.0 / achieved * 20.0;
    assert!(
        (updates as f64 - expected).abs() <= 0.25 * expected + 3.0,
        "{updates} updates, about {expected:.0} expected"
    );
    eprintln!(
        "allegro hil: policy {} updates at 20 Hz over {} torque sets; {} delta clamps, {} limit clamps, {} \
         torques clipped; {} position frames, {} frames out",
        updates,
        report["cycles"],
        report["delta_clamps"],
        report["limit_clamps"],
        report["torque_clips"],
        report["position_frames"],
        report["frames_out"]
    );
    // On the bus: torques a set per position set, then the shut-down; the hand never saw a
    // torque beyond a clip, and it ends limp and quiet.
    let run = from_bridge_start(&seen);
    let host: Vec<&AllegroFrame> = run.iter().map(|(_, f)| f).filter(|f| is_host_frame(f)).collect();
    let last: Vec<_> = host[host.len() - 6..].iter().map(|f| shape(f)).collect();
    assert_eq!(last, SHUTDOWN, "the bridge's last six frames");
    let torques = host.iter().filter(|f| (0x180..=0x18C).contains(&f.id())).count();
    assert_eq!(torques, 4 * 2000 + 4);
    let emu = json(&emu_out);
    eprintln!("allegro hil: emulator {emu_out}");
    assert_eq!(emu["torques_beyond_clip"], 0, "{emu_out}");
    assert_eq!(emu["servo_on_at_end"], false, "{emu_out}");
}
