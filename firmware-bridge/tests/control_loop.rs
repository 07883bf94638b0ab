//! The control loop against the joint-controller emulator over the in-process transport.

use std::convert::Infallible;
use std::sync::atomic::AtomicBool;
use std::thread;
use std::time::Duration;

use vge_bridge::control_loop::{LoopConfig, PolicyRunner, StopReason, run};
use vge_bridge::emulator::{JointControllerEmulator, serve};
use vge_bridge::protocol::RawFrame;
use vge_bridge::transport::{InProcessTransport, Transport};
use vge_sim::kinematics::JointLimit;
use vge_sim::observation::{OBS_DIM, OBS_Q_TARGET};

/// Asks every joint to move by a fixed amount each step, and remembers what it saw.
struct ConstantDelta {
    delta_rad: f32,
    calls: u64,
    last_obs: [f32; OBS_DIM],
}

impl PolicyRunner for ConstantDelta {
    type Error = Infallible;
    fn act(&mut self, obs: &[f32; OBS_DIM]) -> Result<[f32; 15], Infallible> {
        self.calls += 1;
        self.last_obs = *obs;
        Ok([self.delta_rad; 15])
    }
}

fn config(rate_hz: f64, duration_s: f64) -> LoopConfig {
    LoopConfig {
        rate_hz,
        duration: Some(Duration::from_secs_f64(duration_s)),
        watchdog_periods: 5,
        startup_timeout: Duration::from_secs(2),
        halt_hold_periods: 3,
        max_delta_rad: 0.01,
        limits: [JointLimit { lower_rad: -0.5, upper_rad: 0.5 }; 15],
        spin: Duration::from_micros(200),
    }
}

fn spawn_emulator(
    mut end: InProcessTransport,
    max_commands: u64,
) -> thread::JoinHandle<vge_bridge::emulator::EmulatorStats> {
    thread::spawn(move || {
        let mut emulator = JointControllerEmulator::new(1.0);
        serve(&mut end, &mut emulator, max_commands, Duration::from_millis(300)).expect("emulator runs")
    })
}

#[test]
fn loop_drives_the_emulated_hand_and_clamps_large_actions() {
    let (mut bridge, nodes) = InProcessTransport::pair();
    let emulator = spawn_emulator(nodes, u64::MAX);
    // Asks for 0.05 rad per step; the safety filter allows 0.01.
    let mut policy = ConstantDelta { delta_rad: 0.05, calls: 0, last_obs: [0.0; OBS_DIM] };
    let report =
        run(&mut bridge, &mut policy, &config(200.0, 0.25), &AtomicBool::new(false)).expect("loop runs");
    drop(bridge);
    let served = emulator.join().expect("emulator thread");

    assert_eq!(report.stop_reason, StopReason::DurationReached);
    assert!((45..=51).contains(&report.steps), "steps {}", report.steps);
    assert_eq!(policy.calls, report.steps);
    assert!((report.achieved_rate_hz - 200.0).abs() < 20.0, "rate {}", report.achieved_rate_hz);
    // 0.01 rad per step from 0 reaches the 0.5 rad limit after 50 steps.
    let expected = (report.steps as f32 * 0.01).min(0.5);
    assert!((report.final_targets_rad[0] - expected).abs() < 1e-4, "{:?}", report.final_targets_rad);
    assert_eq!(report.safety.delta_clamps, report.steps * 15);
    // The observation carried the targets the bridge had sent.
    assert!(policy.last_obs[OBS_Q_TARGET.start] > 0.0);
    // Every command frame arrived and was answered; nothing was malformed.
    assert_eq!(served.commands, report.frames_out);
    assert_eq!(report.bad_frames, 0);
}

struct NanPolicy;

impl PolicyRunner for NanPolicy {
    type Error = Infallible;
    fn act(&mut self, _: &[f32; OBS_DIM]) -> Result<[f32; 15], Infallible> {
        Ok([f32::NAN; 15])
    }
}

#[test]
fn nan_actions_hold_the_last_safe_targets() {
    let (mut bridge, nodes) = InProcessTransport::pair();
    let emulator = spawn_emulator(nodes, u64::MAX);
    let report =
        run(&mut bridge, &mut NanPolicy, &config(200.0, 0.1), &AtomicBool::new(false)).expect("runs");
    drop(bridge);
    emulator.join().expect("emulator thread");
    assert_eq!(report.safety.non_finite_holds, report.steps);
    assert!(report.final_targets_rad.iter().all(|q| q.abs() < 1e-6), "{:?}", report.final_targets_rad);
}

#[test]
fn a_silent_hand_trips_the_watchdog_and_bad_frames_are_counted() {
    let (mut bridge, mut nodes) = InProcessTransport::pair();
    // Garbage on the bus before anything else: an unknown id, an extended frame, a short one.
    nodes.send(&RawFrame { id: 0x555, data: [0; 8] }).expect("send");
    nodes.send_malformed(0x1abc_def0, 8).expect("send");
    nodes.send_malformed(0x181, 3).expect("send");
    // The emulated nodes answer 100 commands, then fall silent.
    let emulator = spawn_emulator(nodes, 100);
    let mut policy = ConstantDelta { delta_rad: 0.0, calls: 0, last_obs: [0.0; OBS_DIM] };
    let report = run(&mut bridge, &mut policy, &config(200.0, 5.0), &AtomicBool::new(false)).expect("runs");
    drop(bridge);
    emulator.join().expect("emulator thread");

    assert_eq!(report.stop_reason, StopReason::Watchdog);
    assert_eq!(report.bad_frames, 3);
    // 100 answered commands are 20 steps (5 fingers each, startup included); the watchdog
    // allows 5 silent periods, so the loop stops well before its 5 s duration.
    assert!(report.steps < 40, "steps {}", report.steps);
}

#[test]
fn no_hand_at_all_is_a_startup_error() {
    let (mut bridge, _nodes) = InProcessTransport::pair();
    let mut cfg = config(100.0, 1.0);
    cfg.startup_timeout = Duration::from_millis(100);
    let mut policy = ConstantDelta { delta_rad: 0.0, calls: 0, last_obs: [0.0; OBS_DIM] };
    let err = run(&mut bridge, &mut policy, &cfg, &AtomicBool::new(false)).expect_err("nobody answers");
    assert!(err.to_string().contains("no joint state"), "{err}");
}

/// Rolls every finger by a fixed step: in grasp, that turns the object about +z.
struct RollRamp;

impl PolicyRunner for RollRamp {
    type Error = Infallible;
    fn act(&mut self, _: &[f32; OBS_DIM]) -> Result<[f32; 15], Infallible> {
        let mut delta = [0.0; 15];
        for f in 0..5 {
            delta[3 * f] = 0.01;
        }
        Ok(delta)
    }
}

#[test]
fn loop_turns_the_simulated_cube_through_the_protocol() {
    use std::sync::atomic::Ordering;
    use vge_bridge::sim_hand::{SimHand, serve as serve_sim};
    use vge_sim::EnvConfig;

    let env_config = EnvConfig::default();
    let rate_hz = f64::from(env_config.control_hz);
    let limits = env_config.hand.joint_limits();
    let (mut bridge, mut nodes) = InProcessTransport::pair();
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    let stop_nodes = stop.clone();
    let sim = thread::spawn(move || {
        let mut hand = SimHand::new(env_config, 3).expect("sim hand");
        let stats = serve_sim(&mut nodes, &mut hand, Duration::from_secs(2), &stop_nodes).expect("serves");
        (hand.summary(), stats)
    });
    // 30 steps of 0.01 rad of roll: the in-grasp ramp the sim's own test uses.
    let cfg = LoopConfig { limits, max_delta_rad: 0.05, ..config(rate_hz, 30.0 / rate_hz) };
    let report = run(&mut bridge, &mut RollRamp, &cfg, &AtomicBool::new(false)).expect("loop runs");
    stop.store(true, Ordering::Relaxed);
    let (summary, stats) = sim.join().expect("sim thread");

    assert_eq!(report.stop_reason, StopReason::DurationReached);
    assert_eq!(stats.bad_frames, 0);
    // The sim advanced once per enabled step (plus the halt's holds).
    assert!(summary.steps >= report.steps, "{} sim steps for {} loop steps", summary.steps, report.steps);
    assert!(!summary.terminated, "object dropped: {summary:?}");
    assert!(summary.rotation_rad > 0.1, "the cube turned only {} rad", summary.rotation_rad);
    assert!(summary.mean_tip_contacts >= 3.0, "{summary:?}");
    eprintln!("bridge -> sim over the protocol: {report:?}\n{summary:?}");
}
