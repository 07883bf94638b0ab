//! The control loop against the joint-controller emulator over the in-process transport.

use std::convert::Infallible;
use std::sync::atomic::AtomicBool;
use std::thread;
use std::time::{Duration, Instant};

use vge_bridge::control_loop::{LoopConfig, PolicyRunner, StopReason, run};
use vge_bridge::emulator::{JointControllerEmulator, ServeLimits, serve};
use vge_bridge::hand_file;
use vge_bridge::node_supervisor::RestartPlan;
use vge_bridge::protocol::{FingerId, Heartbeat, JointPosition, Message, NodeLayout, NodeState, RawFrame};
use vge_bridge::protocol_hand::ProtocolHand;
use vge_bridge::transport::{BusCounts, ErrorClass, InProcessTransport, Received, Transport, TransportError};
use vge_hand::JointLimit;
use vge_sim::observation::{ObservationLayout, ObservationSet};

/// vge15's full observation: 65 floats, the targets at 15..30.
const OBS_DIM: usize = 65;
const OBS_Q_TARGET_START: usize = 15;

/// Asks every joint to move by a fixed amount each step, and remembers what it saw.
struct ConstantDelta {
    delta_rad: f32,
    calls: u64,
    last_obs: Vec<f32>,
}

impl PolicyRunner for ConstantDelta {
    type Error = Infallible;
    fn act(&mut self, obs: &[f32], action: &mut [f32]) -> Result<(), Infallible> {
        self.calls += 1;
        self.last_obs = obs.to_vec();
        action.fill(self.delta_rad);
        Ok(())
    }
}

/// vge15 with every joint's range [-0.5, 0.5].
fn test_hand() -> ProtocolHand {
    let mut hand = ProtocolHand::vge15().expect("vge15");
    hand.limits = vec![JointLimit { lower_rad: -0.5, upper_rad: 0.5 }; 15];
    hand
}

fn config(rate_hz: f64, duration_s: f64) -> LoopConfig {
    LoopConfig {
        duration: Some(Duration::from_secs_f64(duration_s)),
        startup_timeout: Duration::from_secs(2),
        max_delta_rad: 0.01,
        ..LoopConfig::new(rate_hz, test_hand())
    }
}

fn spawn_emulator<T: Transport + 'static>(
    end: T,
    max_commands: u64,
) -> thread::JoinHandle<vge_bridge::emulator::EmulatorStats> {
    spawn_emulator_of(end, NodeLayout::VGE15, max_commands)
}

fn spawn_emulator_of<T: Transport + 'static>(
    mut end: T,
    nodes: NodeLayout,
    max_commands: u64,
) -> thread::JoinHandle<vge_bridge::emulator::EmulatorStats> {
    thread::spawn(move || {
        let mut emulator = JointControllerEmulator::new(nodes, 1.0);
        let limits = ServeLimits {
            max_commands,
            idle_timeout: Duration::from_millis(300),
            command_timeout: Duration::from_secs(1),
            restart: None,
        };
        serve(&mut end, &mut emulator, limits, &AtomicBool::new(false)).expect("emulator runs")
    })
}

/// The nodes' end of the link with a fault injected into what they send: `tamper` sees every
/// frame the nodes send (and when, since the first) and returns what goes on the wire instead.
struct Tampered<F> {
    inner: InProcessTransport,
    started: Instant,
    tamper: F,
}

impl<F: FnMut(Duration, RawFrame) -> Vec<Received> + Send> Transport for Tampered<F> {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError> {
        for r in (self.tamper)(self.started.elapsed(), *frame) {
            self.inner.send_received(r)?;
        }
        Ok(())
    }
    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
        self.inner.recv(timeout)
    }
    fn bus_counts(&self) -> BusCounts {
        self.inner.bus_counts()
    }
}

fn tampered<F>(nodes: InProcessTransport, tamper: F) -> Tampered<F> {
    Tampered { inner: nodes, started: Instant::now(), tamper }
}

/// Runs the loop with `policy` on `bridge` against the lag emulator on `nodes` until `cfg`
/// or a fault ends it, then lets the emulator finish.
fn run_against_emulator<B: Transport, N: Transport + 'static, P: PolicyRunner>(
    mut bridge: B,
    nodes: N,
    policy: &mut P,
    cfg: &LoopConfig,
) -> vge_bridge::control_loop::LoopReport {
    let emulator = spawn_emulator(nodes, u64::MAX);
    let report = run(&mut bridge, policy, cfg, &AtomicBool::new(false)).expect("loop runs");
    drop(bridge);
    emulator.join().expect("emulator thread");
    report
}

fn decode(frame: &RawFrame) -> Message {
    Message::decode_frame(frame).expect("the emulator sends valid frames")
}

fn hold_policy() -> ConstantDelta {
    ConstantDelta { delta_rad: 0.0, calls: 0, last_obs: Vec::new() }
}

#[test]
fn loop_drives_the_emulated_hand_and_clamps_large_actions() {
    let (mut bridge, nodes) = InProcessTransport::pair();
    let emulator = spawn_emulator(nodes, u64::MAX);
    // Asks for 0.05 rad per step; the safety filter allows 0.01.
    let mut policy = ConstantDelta { delta_rad: 0.05, calls: 0, last_obs: Vec::new() };
    let report =
        run(&mut bridge, &mut policy, &config(200.0, 0.25), &AtomicBool::new(false)).expect("loop runs");
    drop(bridge);
    let served = emulator.join().expect("emulator thread");

    assert_eq!(report.stop_reason, StopReason::DurationReached);
    assert!((45..=51).contains(&report.pace.steps), "steps {}", report.pace.steps);
    assert_eq!(policy.calls, report.pace.steps);
    assert!((report.pace.achieved_rate_hz - 200.0).abs() < 20.0, "rate {}", report.pace.achieved_rate_hz);
    // 0.01 rad per step from 0 reaches the 0.5 rad limit after 50 steps.
    let expected = (report.pace.steps as f32 * 0.01).min(0.5);
    assert!((report.final_targets_rad[0] - expected).abs() < 1e-4, "{:?}", report.final_targets_rad);
    assert_eq!(report.safety.delta_clamps, report.pace.steps * 15);
    // The observation carried the targets the bridge had sent.
    assert_eq!(policy.last_obs.len(), OBS_DIM);
    assert!(policy.last_obs[OBS_Q_TARGET_START] > 0.0);
    // Every command frame arrived and was answered; nothing was malformed or refused; the
    // bridge and the nodes sent heartbeats (10 Hz over 0.25 s plus start-up and halt).
    assert_eq!(served.commands, report.link.messages_out - report.link.heartbeats_out);
    assert_eq!(report.link.bad_frames + report.link.stale_frames + report.link.implausible_frames, 0);
    assert!(report.link.heartbeats_out >= 2 && served.heartbeats_sent >= 10, "{report:?} {served:?}");
    assert_eq!((report.holds, report.policy_errors), (0, 0));
}

struct NanPolicy;

impl PolicyRunner for NanPolicy {
    type Error = Infallible;
    fn act(&mut self, _: &[f32], action: &mut [f32]) -> Result<(), Infallible> {
        action.fill(f32::NAN);
        Ok(())
    }
}

#[test]
fn nan_actions_hold_the_last_safe_targets_then_halt() {
    let (bridge, nodes) = InProcessTransport::pair();
    let report = run_against_emulator(bridge, nodes, &mut NanPolicy, &config(200.0, 1.0));
    // Five failing periods are held; the sixth halts.
    assert_eq!(report.stop_reason, StopReason::PolicyFailure, "{report:?}");
    assert_eq!((report.pace.steps, report.policy_errors, report.holds), (5, 6, 6));
    assert_eq!(report.safety.non_finite_holds, report.pace.steps);
    assert!(report.stop_detail.contains("not finite"), "{}", report.stop_detail);
    assert!(report.final_targets_rad.iter().all(|q| q.abs() < 1e-6), "{:?}", report.final_targets_rad);
}

#[test]
fn a_silent_hand_trips_the_watchdog_and_bad_frames_are_counted() {
    let (mut bridge, mut nodes) = InProcessTransport::pair();
    // Garbage on the bus before anything else: an unknown id, an extended frame, a short one.
    nodes.send(&RawFrame { id: 0x555, data: [0; 8] }).expect("send");
    nodes.send_received(Received::Malformed { id: 0x1abc_def0, len: 8 }).expect("send");
    nodes.send_received(Received::Malformed { id: 0x181, len: 3 }).expect("send");
    // The emulated nodes answer 100 commands, then fall silent.
    let emulator = spawn_emulator(nodes, 100);
    let mut policy = ConstantDelta { delta_rad: 0.0, calls: 0, last_obs: Vec::new() };
    let report = run(&mut bridge, &mut policy, &config(200.0, 5.0), &AtomicBool::new(false)).expect("runs");
    drop(bridge);
    emulator.join().expect("emulator thread");

    assert_eq!(report.stop_reason, StopReason::Watchdog);
    assert_eq!(report.link.bad_frames, 3);
    // 100 answered commands are 20 steps (5 fingers each, startup included); the watchdog
    // allows 5 silent periods, so the loop stops well before its 5 s duration.
    assert!(report.pace.steps < 40, "steps {}", report.pace.steps);
}

#[test]
fn no_hand_at_all_is_a_startup_error() {
    let (mut bridge, _nodes) = InProcessTransport::pair();
    let mut cfg = config(100.0, 1.0);
    cfg.startup_timeout = Duration::from_millis(100);
    let mut policy = ConstantDelta { delta_rad: 0.0, calls: 0, last_obs: Vec::new() };
    let err = run(&mut bridge, &mut policy, &cfg, &AtomicBool::new(false)).expect_err("nobody answers");
    assert!(err.to_string().contains("no joint state"), "{err}");
}

/// Rolls every finger by a fixed step: in grasp, that turns the object about +z.
#[cfg(feature = "sim")]
struct RollRamp;

#[cfg(feature = "sim")]
impl PolicyRunner for RollRamp {
    type Error = Infallible;
    fn act(&mut self, _: &[f32], action: &mut [f32]) -> Result<(), Infallible> {
        for (k, a) in action.iter_mut().enumerate() {
            *a = if k % 3 == 0 { 0.01 } else { 0.0 };
        }
        Ok(())
    }
}

#[cfg(feature = "sim")]
#[test]
fn loop_turns_the_simulated_cube_through_the_protocol() {
    use std::sync::atomic::Ordering;
    use vge_bridge::sim_hand::{SimHand, serve as serve_sim};
    use vge_sim::EnvConfig;

    let env_config = EnvConfig::default();
    let rate_hz = f64::from(env_config.control_hz);
    let hand = ProtocolHand::of(&env_config.hand).expect("vge15");
    let (mut bridge, mut nodes) = InProcessTransport::pair();
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    let stop_nodes = stop.clone();
    let sim = thread::spawn(move || {
        let mut hand = SimHand::new(env_config, 3, Duration::from_secs(1)).expect("sim hand");
        let stats = serve_sim(&mut nodes, &mut hand, Duration::from_secs(2), &stop_nodes).expect("serves");
        (hand.summary(), stats)
    });
    // 30 steps of 0.01 rad of roll: the in-grasp ramp the sim's own test uses.
    let cfg = LoopConfig { hand, max_delta_rad: 0.05, ..config(rate_hz, 30.0 / rate_hz) };
    let report = run(&mut bridge, &mut RollRamp, &cfg, &AtomicBool::new(false)).expect("loop runs");
    stop.store(true, Ordering::Relaxed);
    let (summary, stats) = sim.join().expect("sim thread");

    assert_eq!(report.stop_reason, StopReason::DurationReached);
    assert_eq!(stats.bad_frames, 0);
    // The sim advanced once per enabled step (plus the halt's holds).
    assert!(
        summary.steps >= report.pace.steps,
        "{} sim steps for {} loop steps",
        summary.steps,
        report.pace.steps
    );
    assert!(!summary.terminated, "object dropped: {summary:?}");
    assert!(summary.rotation_rad > 0.1, "the cube turned only {} rad", summary.rotation_rad);
    assert!(summary.mean_tip_contacts >= 3.0, "{summary:?}");
    eprintln!("bridge -> sim over the protocol: {report:?}\n{summary:?}");
}

#[test]
fn implausible_joint_positions_are_dropped_held_and_halt_when_they_persist() {
    let (bridge, nodes) = InProcessTransport::pair();
    // After 0.2 s, finger 2 reports its roll at 3.2 rad (0x7FFF counts: far outside its range).
    let nodes = tampered(nodes, |t, frame| match decode(&frame) {
        Message::JointPosition(p) if p.finger.index() == 2 && t > Duration::from_millis(200) => {
            let bad = JointPosition { q_rad: [3.2767, 0.0, 0.0], ..p };
            vec![Received::Frame(Message::JointPosition(bad).encode().expect("in range of the field"))]
        }
        _ => vec![Received::Frame(frame)],
    });
    let mut policy = ConstantDelta { delta_rad: 0.001, ..hold_policy() };
    let report = run_against_emulator(bridge, nodes, &mut policy, &config(100.0, 3.0));
    assert_eq!(report.stop_reason, StopReason::ImplausibleState, "{report:?}");
    assert!(report.stop_detail.contains("node 2 (middle)"), "{}", report.stop_detail);
    assert!(report.link.implausible_frames >= 4, "{:?}", report.link);
    // The held steps did not move the targets: the policy ran only before the fault.
    assert_eq!(policy.calls, report.pace.steps - (report.holds - report.policy_errors));
    assert!(report.holds >= 4 && report.pace.steps < 60, "{report:?}");
}

#[test]
fn a_hand_files_joint_limits_are_the_ones_positions_are_checked_against() {
    // After start-up, finger 1 reports its proximal flexion at 0.4 rad: inside the default
    // hand's range, outside a real hand whose index finger flexes to 0.2 rad (+0.1 margin).
    let report_with = |limits: Vec<JointLimit>| {
        let (bridge, nodes) = InProcessTransport::pair();
        let nodes = tampered(nodes, |t, frame| match decode(&frame) {
            Message::JointPosition(p) if p.finger.index() == 1 && t > Duration::from_millis(200) => {
                let moved = JointPosition { q_rad: [0.0, 0.4, 0.0], ..p };
                vec![Received::Frame(Message::JointPosition(moved).encode().expect("in range"))]
            }
            _ => vec![Received::Frame(frame)],
        });
        let cfg = LoopConfig { hand: ProtocolHand { limits, ..test_hand() }, ..config(100.0, 1.0) };
        run_against_emulator(bridge, nodes, &mut hold_policy(), &cfg)
    };
    let default = report_with(ProtocolHand::vge15().expect("vge15").limits);
    assert_eq!(default.stop_reason, StopReason::DurationReached, "{default:?}");
    assert_eq!(default.link.implausible_frames, 0);

    // The default hand's limits, but joint 4 (index.flex_prox) flexes to 0.2 rad only.
    let row = |j: usize| match (j, j % 3) {
        (4, _) => "[-0.3, 0.2]",
        (_, 0) => "[-0.5, 0.5]",
        _ => "[-0.3, 1.6]",
    };
    let text = format!("joint_limits_rad = [{}]\n", (0..15).map(row).collect::<Vec<_>>().join(", "));
    let path = std::env::temp_dir().join(format!("vge-bridge-hand-{}.toml", std::process::id()));
    std::fs::write(&path, text).expect("writes the hand file");
    let limits = hand_file::load_joint_limits(&path, &test_hand()).expect("a valid hand file");
    let _ = std::fs::remove_file(&path);
    assert_eq!(limits[4], JointLimit { lower_rad: -0.3, upper_rad: 0.2 });
    let real = report_with(limits);
    assert_eq!(real.stop_reason, StopReason::ImplausibleState, "{real:?}");
    assert!(real.stop_detail.contains("node 1 (index)"), "{}", real.stop_detail);
    assert!(real.link.implausible_frames > 0, "{:?}", real.link);
}

#[test]
fn stale_frames_are_dropped_and_counted_and_a_short_burst_only_holds() {
    let (bridge, nodes) = InProcessTransport::pair();
    // Three times, between 0.1 and 0.13 s, finger 4 also sends a position with a seq ten
    // commands old (as a node replaying its buffer would).
    let mut replays = 0;
    let nodes = tampered(nodes, move |t, frame| match decode(&frame) {
        Message::JointPosition(p)
            if p.finger.index() == 4 && t > Duration::from_millis(100) && replays < 3 =>
        {
            replays += 1;
            let old = JointPosition { seq: p.seq.wrapping_sub(10), q_rad: [0.4; 3], ..p };
            vec![
                Received::Frame(frame),
                Received::Frame(Message::JointPosition(old).encode().expect("valid")),
            ]
        }
        _ => vec![Received::Frame(frame)],
    });
    let report = run_against_emulator(bridge, nodes, &mut hold_policy(), &config(100.0, 0.5));
    assert_eq!(report.stop_reason, StopReason::DurationReached, "{report:?}");
    assert_eq!(report.link.stale_frames, 3, "{:?}", report.link);
    assert!((1..=3).contains(&report.holds), "one hold per period with a stale frame: {report:?}");
    assert!(
        report.final_targets_rad.iter().all(|q| q.abs() < 1e-6),
        "the stale 0.4 rad never entered the state"
    );
}

#[test]
fn a_node_that_restarts_mid_run_halts_the_loop_with_node_restarted() {
    // Node 3 reboots after its 10th enabled command: its boot-up heartbeat (state booting,
    // counter 0) goes out, then it counts from 1. The second time the boot-up is lost on the
    // way, and its counter starting again gives it away.
    for (boot_up_lost, sign) in
        [(false, "boot-up heartbeat (state booting)"), (true, "heartbeat counter went from")]
    {
        let (mut bridge, nodes) = InProcessTransport::pair();
        let mut boot_ups = 0;
        let nodes = tampered(nodes, move |_, frame| match decode(&frame) {
            Message::Heartbeat(h) if h.node == 3 && h.state == NodeState::Booting => {
                boot_ups += 1;
                // The first boot-up is the node's power-up, before the bridge took over.
                if boot_up_lost && boot_ups > 1 { vec![] } else { vec![Received::Frame(frame)] }
            }
            _ => vec![Received::Frame(frame)],
        });
        let emulator = thread::spawn(move || {
            let mut end = nodes;
            let node = FingerId::new(3).expect("finger");
            let limits = ServeLimits {
                max_commands: u64::MAX,
                idle_timeout: Duration::from_millis(300),
                command_timeout: Duration::from_secs(1),
                restart: Some(RestartPlan { node, after_enabled_commands: 10 }),
            };
            serve(
                &mut end,
                &mut JointControllerEmulator::new(NodeLayout::VGE15, 1.0),
                limits,
                &AtomicBool::new(false),
            )
            .expect("emulator runs")
        });
        let cfg = config(20.0, 5.0);
        let report = run(&mut bridge, &mut hold_policy(), &cfg, &AtomicBool::new(false)).expect("loop runs");
        drop(bridge);
        let stats = emulator.join().expect("emulator thread");
        assert_eq!(stats.restarts, 1);
        assert_eq!(report.stop_reason, StopReason::NodeRestarted, "{report:?}");
        assert!(report.stop_detail.starts_with("node 3 (ring) restarted: "), "{}", report.stop_detail);
        assert!(report.stop_detail.contains(sign), "{}", report.stop_detail);
        // It halted once the restart was on the link: before the watchdog could have.
        let limit = u64::from(cfg.watchdog_periods);
        assert!((10..=10 + limit).contains(&report.pace.steps), "{} steps", report.pace.steps);
    }
}

#[test]
fn a_node_whose_heartbeat_stops_or_sticks_halts_the_loop() {
    for stuck in [false, true] {
        let (bridge, nodes) = InProcessTransport::pair();
        // Node 1's heartbeat: after 0.3 s it stops, or its counter is frozen from the start.
        let nodes = tampered(nodes, move |t, frame| match decode(&frame) {
            Message::Heartbeat(h) if h.node == 1 && stuck => {
                let frozen = Heartbeat { counter: 7, ..h };
                vec![Received::Frame(Message::Heartbeat(frozen).encode().expect("valid"))]
            }
            Message::Heartbeat(h) if h.node == 1 && t > Duration::from_millis(300) => vec![],
            _ => vec![Received::Frame(frame)],
        });
        let report = run_against_emulator(bridge, nodes, &mut hold_policy(), &config(50.0, 3.0));
        assert_eq!(report.stop_reason, StopReason::HeartbeatLost, "stuck {stuck}: {report:?}");
        let want = if stuck {
            "heartbeat counter of node 1 (index) stuck at 7"
        } else {
            "no heartbeat from node 1 (index)"
        };
        assert!(report.stop_detail.contains(want), "{}", report.stop_detail);
        // Stopped: a missing beat after 0.3 s + 0.5 s timeout; a stuck one after 4 beats.
        assert!(report.pace.steps < 50, "{} steps", report.pace.steps);
    }
}

#[test]
fn bus_off_halts_and_other_error_frames_are_counted() {
    let (bridge, nodes) = InProcessTransport::pair();
    // Every node position answer comes with an error-passive report; after 0.2 s a bus-off.
    let nodes = tampered(nodes, |t, frame| match decode(&frame) {
        Message::JointPosition(p) if p.finger.index() == 0 => {
            let class =
                if t > Duration::from_millis(200) { ErrorClass::BUS_OFF } else { ErrorClass::CONTROLLER };
            vec![Received::Frame(frame), Received::Error { class }]
        }
        _ => vec![Received::Frame(frame)],
    });
    let report = run_against_emulator(bridge, nodes, &mut hold_policy(), &config(100.0, 3.0));
    assert_eq!(report.stop_reason, StopReason::BusOff, "{report:?}");
    assert!(report.link.error_frames.bus_off >= 1, "{:?}", report.link);
    assert!(report.link.error_frames.controller >= 10, "{:?}", report.link);
}

#[test]
fn a_flood_beyond_the_receive_budget_halts_and_below_it_is_only_counted() {
    for (junk_per_frame, halts) in [(2usize, false), (80, true)] {
        let (bridge, nodes) = InProcessTransport::pair();
        let nodes = tampered(nodes, move |_, frame| {
            let mut out = vec![Received::Frame(frame)];
            out.extend((0..junk_per_frame).map(|_| Received::Frame(RawFrame { id: 0x000, data: [0; 8] })));
            out
        });
        // The flood halts within a few periods; its run may last seconds so that a host too
        // loaded to keep the emulator's pace (a stall of several periods) cannot end it first.
        let duration_s = if halts { 5.0 } else { 0.6 };
        let cfg = LoopConfig { rx_budget: 256, ..config(50.0, duration_s) };
        let report = run_against_emulator(bridge, nodes, &mut hold_policy(), &cfg);
        if halts {
            // 5 answers x 81 frames = 405 per command set (and 5 sets per query round): far
            // more than 256 per period, period after period.
            assert_eq!(report.stop_reason, StopReason::BusOverload, "{report:?}");
            assert!(report.link.overload_periods >= 6, "{:?}", report.link);
        } else {
            assert_eq!(report.stop_reason, StopReason::DurationReached, "{report:?}");
            assert!(report.link.bad_frames >= 2 * 5 * report.pace.steps, "{:?}", report.link);
            assert_eq!(report.pace.deadline_misses, 0, "{report:?}");
        }
    }
}

/// The bridge's end of the link with a transmit queue that is full from `after` on. With
/// `deliver`, the frames still reach the nodes (as if a retry below the bridge got them
/// out), so the nodes keep answering and only the refused sends can halt the loop.
struct FullQueue {
    inner: InProcessTransport,
    sent: u64,
    after: u64,
    deliver: bool,
}

impl Transport for FullQueue {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError> {
        self.sent += 1;
        if self.sent > self.after {
            if self.deliver {
                self.inner.send(frame)?;
            }
            return Err(TransportError::TxQueueFull { id: frame.id });
        }
        self.inner.send(frame)
    }
    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
        self.inner.recv(timeout)
    }
    fn bus_counts(&self) -> BusCounts {
        self.inner.bus_counts()
    }
}

#[test]
fn a_transmit_queue_that_stays_full_halts_the_loop() {
    let (bridge, nodes) = InProcessTransport::pair();
    let bridge = FullQueue { inner: bridge, sent: 0, after: 200, deliver: false };
    let report = run_against_emulator(bridge, nodes, &mut hold_policy(), &config(100.0, 3.0));
    // The nodes fall silent without commands, so the watchdog may see it first: both are
    // the loop refusing to go on blind.
    assert!(matches!(report.stop_reason, StopReason::TxFailure | StopReason::Watchdog), "{report:?}");
    assert!(report.link.tx_dropped >= 5, "{:?}", report.link);

    // Nodes that keep answering: the watchdog stays quiet, so the refused sends alone halt it.
    let (bridge, nodes) = InProcessTransport::pair();
    let bridge = FullQueue { inner: bridge, sent: 0, after: 200, deliver: true };
    let report = run_against_emulator(bridge, nodes, &mut hold_policy(), &config(100.0, 3.0));
    assert_eq!(report.stop_reason, StopReason::TxFailure, "{report:?}");
    assert!(report.stop_detail.contains("could not be sent for 5 periods"), "{report:?}");
}

/// Sleeps through three periods once, as a loaded host would.
struct Stall {
    calls: u32,
}

impl PolicyRunner for Stall {
    type Error = Infallible;
    fn act(&mut self, _: &[f32], action: &mut [f32]) -> Result<(), Infallible> {
        self.calls += 1;
        if self.calls == 10 {
            thread::sleep(Duration::from_millis(35));
        }
        action.fill(0.0);
        Ok(())
    }
}

#[test]
fn a_late_loop_skips_the_periods_it_missed_instead_of_bursting() {
    let (bridge, nodes) = InProcessTransport::pair();
    let report = run_against_emulator(bridge, nodes, &mut Stall { calls: 0 }, &config(100.0, 0.5));
    // 35 ms late at 100 Hz: the stalled step misses, and the 3 periods that passed meanwhile
    // are skipped (not run late back to back); 50 periods, 46 or 47 steps.
    assert!(report.pace.skipped_periods >= 2 && report.pace.deadline_misses >= 3, "{report:?}");
    assert!(report.pace.steps <= 48, "{report:?}");
    assert!(
        report.pace.achieved_rate_hz < 97.0,
        "the rate must show the gap: {}",
        report.pace.achieved_rate_hz
    );
    let _ = FingerId::new(0);
}

/// A hand of two three-joint fingers on vge's protocol: the loop, the nodes and the
/// observation take their sizes from it, and a proprioceptive policy gets its history.
#[test]
fn a_hand_of_another_size_runs_with_its_own_sizes_and_observation() {
    let (mut bridge, nodes) = InProcessTransport::pair();
    let two = NodeLayout::new(2).expect("two nodes");
    let emulator = spawn_emulator_of(nodes, two, u64::MAX);
    let hand = ProtocolHand {
        name: "two".to_owned(),
        nodes: two,
        finger_names: vec!["left".to_owned(), "right".to_owned()],
        joint_names: (0..6).map(|k| format!("j{k}")).collect(),
        limits: vec![JointLimit { lower_rad: -0.5, upper_rad: 0.5 }; 6],
    };
    let set = ObservationSet::Proprio { history: 2 };
    let cfg = LoopConfig { hand, observation: set, ..config(200.0, 0.1) };
    let mut policy = ConstantDelta { delta_rad: 0.01, ..hold_policy() };
    let report = run(&mut bridge, &mut policy, &cfg, &AtomicBool::new(false)).expect("loop runs");
    drop(bridge);
    let served = emulator.join().expect("emulator thread");
    assert_eq!(report.stop_reason, StopReason::DurationReached, "{report:?}");
    assert_eq!(report.final_targets_rad.len(), 6);
    assert_eq!(policy.last_obs.len(), ObservationLayout::new(set, 6, 2).dim());
    // Now, then the targets of the last two steps: 0.01 rad a step.
    let targets = &policy.last_obs[6..12];
    let past_targets = &policy.last_obs[24..30];
    assert!(
        targets.iter().zip(past_targets).all(|(now, then)| (now - then - 0.01).abs() < 1e-4),
        "{:?}",
        policy.last_obs
    );
    assert_eq!(served.commands, report.link.messages_out - report.link.heartbeats_out);
    assert_eq!(report.link.bad_frames, 0);
}
