//! The Allegro bridge loop against the emulated hand over the in-process link: start-up and
//! shut-down frames, the PD law, the safety reactions. The hand is a set of simple inertias
//! ([`InertiaPlant`]) unless a test says otherwise, so these run in a second without the
//! physics engine; `allegro_hil.rs` runs the real processes on vcan0.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::Duration;

use vge_bridge::allegro_emulator::{AllegroHandEmulator, AllegroPlant, EmulatedHand, InertiaPlant, serve};
use vge_bridge::allegro_hand::{AllegroHand, DEFAULT_SQUEEZE_RAD};
use vge_bridge::allegro_link::{AllegroInProcess, AllegroLink, AllegroReceived};
use vge_bridge::allegro_loop::{
    self, AllegroLoopConfig, AllegroReport, HoldTargets, PolicyTargets, TargetSource,
};
use vge_bridge::control_loop::StopReason;
use vge_bridge::protocol::allegro::{AllegroConfig, AllegroFrame, Command, NUM_JOINTS};
use vge_bridge::transport::TransportError;

/// A link that records every frame sent through it, both ways.
struct Tap<L> {
    inner: L,
    sent: Arc<std::sync::Mutex<Vec<AllegroFrame>>>,
}

impl<L: AllegroLink> AllegroLink for Tap<L> {
    fn send(&mut self, frame: &AllegroFrame) -> Result<(), TransportError> {
        self.sent.lock().expect("tap").push(*frame);
        self.inner.send(frame)
    }
    fn recv(&mut self, timeout: Duration) -> Result<Option<AllegroReceived>, TransportError> {
        self.inner.recv(timeout)
    }
    fn bus_counts(&self) -> vge_bridge::transport::BusCounts {
        self.inner.bus_counts()
    }
}

struct Run<P: AllegroPlant = InertiaPlant> {
    report: Result<AllegroReport, allegro_loop::AllegroLoopError>,
    host_frames: Vec<AllegroFrame>,
    emulator: AllegroHandEmulator<P>,
}

/// The loop against an emulated hand of inertias starting at `q0`, with `config` changed by
/// `tweak`; the emulator runs until the loop is done.
fn run_against_inertias(
    targets: [f32; NUM_JOINTS],
    q0: [f32; NUM_JOINTS],
    tweak: impl FnOnce(&mut AllegroLoopConfig),
) -> Run {
    run_against(InertiaPlant::at(q0), targets, tweak)
}

/// The loop holding `targets` against an emulated hand of `plant`.
fn run_against<P: AllegroPlant + Send + 'static>(
    plant: P,
    targets: [f32; NUM_JOINTS],
    tweak: impl FnOnce(&mut AllegroLoopConfig),
) -> Run<P> {
    run_with(plant, &mut HoldTargets(targets), tweak)
}

/// The loop with the targets of `source` against an emulated hand of `plant`.
fn run_with<P: AllegroPlant + Send + 'static, S: TargetSource>(
    plant: P,
    source: &mut S,
    tweak: impl FnOnce(&mut AllegroLoopConfig),
) -> Run<P> {
    let hand = AllegroHand::shipped().expect("allegro");
    let mut config = AllegroLoopConfig::new(&hand);
    // Generous: a loaded test machine must not trip the watchdog in tests about other things.
    config.position_timeout = Duration::from_secs(2);
    tweak(&mut config);
    let (bridge_end, mut hand_end) = AllegroInProcess::pair();
    let done = Arc::new(AtomicBool::new(false));
    let hand_done = done.clone();
    let emulator = thread::spawn(move || {
        let mut e = AllegroHandEmulator::new(EmulatedHand::default(), plant);
        serve(&mut hand_end, &mut e, Duration::from_secs(5), &hand_done).expect("emulator link");
        e
    });
    let sent = Arc::new(std::sync::Mutex::new(Vec::new()));
    let mut tap = Tap { inner: bridge_end, sent: sent.clone() };
    let report = allegro_loop::run(&mut tap, source, &config, &AtomicBool::new(false));
    // Let the emulator take in the shut-down frames before it stops.
    thread::sleep(Duration::from_millis(50));
    done.store(true, Ordering::Relaxed);
    let emulator = emulator.join().expect("emulator thread");
    let host_frames = sent.lock().expect("tap").clone();
    Run { report, host_frames, emulator }
}

fn ids(frames: &[AllegroFrame]) -> Vec<(u16, bool, usize)> {
    frames.iter().map(|f| (f.id(), f.is_remote(), f.payload().len())).collect()
}

const SHUTDOWN_IDS: [(u16, bool, usize); 6] = [
    (0x180, false, 8),
    (0x184, false, 8),
    (0x188, false, 8),
    (0x18C, false, 8),
    (0x104, false, 0),
    (0x204, false, 6),
];

#[test]
fn the_loop_starts_up_holds_its_targets_and_shuts_down_in_the_drivers_order() {
    let hand = AllegroHand::shipped().expect("allegro");
    let targets = hand.squeezed_grasp_rad(DEFAULT_SQUEEZE_RAD);
    let run = run_against_inertias(targets, hand.start_grasp_rad, |c| c.max_cycles = Some(400));
    let report = run.report.expect("the loop ran");
    assert_eq!(report.stop_reason, StopReason::StepsReached, "{}", report.stop_detail);
    assert_eq!(report.cycles, 400);
    let frames = &run.host_frames;
    assert_eq!(
        ids(&frames[..5]),
        [(0x104, false, 0), (0x200, true, 0), (0x220, true, 0), (0x204, false, 6), (0x100, false, 0)],
        "start-up: servo off, info and serial requests, set period, servo on"
    );
    assert_eq!(frames[3].payload(), &[3, 0, 0, 0, 0xF4, 0x01]);
    assert_eq!(ids(&frames[frames.len() - 6..]), SHUTDOWN_IDS, "shut-down");
    for f in &frames[frames.len() - 6..frames.len() - 2] {
        assert_eq!(f.payload(), &[0; 8], "zero torque");
    }
    assert_eq!(frames[frames.len() - 1].payload(), &[0; 6], "reports off");
    let torque_frames = frames.iter().filter(|f| (0x180..=0x18C).contains(&f.id())).count() as u64;
    assert_eq!(torque_frames, 4 * 400 + 4);
    let info = report.info.expect("info");
    assert_eq!(info.hardware_major(), 4);
    assert_eq!(report.serial.as_deref(), Some("VGEEMU01"));
    assert_eq!(report.shutdown_frames, 6);
    // The emulator saw it all, applied torques, and was left limp and quiet.
    let e = &run.emulator;
    assert!(!e.servo_on());
    assert_eq!(e.period().position_ms, 0);
    assert_eq!(e.stats.torque_frames, 4 * 400 + 4);
    assert_eq!(e.stats.torques_beyond_clip, 0);
    // The joints went to the targets (the targets ramp at 1 rad/s; 400 sets are 1.2 s).
    for (k, target) in targets.iter().enumerate() {
        let err = (e.plant().q_rad()[k] - target).abs();
        assert!(err < 0.02, "{}: {err} rad from its target", hand.joint_name(k));
    }
    eprintln!("{}", report.json_line(&[]));
}

#[test]
fn a_hand_that_stops_reporting_is_shut_down_after_the_position_timeout() {
    let hand = AllegroHand::shipped().expect("allegro");
    let (bridge_end, mut hand_end) = AllegroInProcess::pair();
    let hand_thread = thread::spawn(move || {
        let mut e = AllegroHandEmulator::new(EmulatedHand::default(), InertiaPlant::at(hand.start_grasp_rad));
        // Runs until 100 sets have gone out, then falls silent and listens only.
        let stop = AtomicBool::new(false);
        let mut out = Vec::new();
        let mut received = Vec::new();
        let start = std::time::Instant::now();
        while start.elapsed() < Duration::from_secs(10) {
            if let Some(AllegroReceived::Frame(f)) = hand_end.recv(Duration::from_millis(1)).expect("recv") {
                received.push(f);
                if e.stats.position_sets < 100 {
                    e.handle(&f, &mut out);
                }
            }
            if e.stats.position_sets < 100 && e.period().position_ms > 0 {
                e.advance(3, &mut out);
            }
            for f in out.drain(..) {
                hand_end.send(&f).expect("send");
            }
            if received.iter().any(|f| f.id() == 0x204 && f.payload() == [0; 6])
                || stop.load(Ordering::Relaxed)
            {
                break;
            }
        }
        received
    });
    let hand = AllegroHand::shipped().expect("allegro");
    let mut config = AllegroLoopConfig::new(&hand);
    config.position_timeout = Duration::from_millis(60);
    let mut tap = Tap { inner: bridge_end, sent: Arc::new(std::sync::Mutex::new(Vec::new())) };
    let report =
        allegro_loop::run(&mut tap, &mut HoldTargets(hand.start_grasp_rad), &config, &AtomicBool::new(false))
            .expect("the loop ran");
    let received = hand_thread.join().expect("hand thread");
    assert_eq!(report.stop_reason, StopReason::Watchdog);
    assert!(report.stop_detail.contains("no complete set of position frames"), "{}", report.stop_detail);
    assert_eq!(report.stop_reason.exit_code(), 10);
    assert!(report.cycles <= 100, "{} torque sets for 100 position sets", report.cycles);
    assert_eq!(ids(&received[received.len() - 6..]), SHUTDOWN_IDS);
}

#[test]
fn a_torque_beyond_the_clip_never_leaves_the_host() {
    let hand = AllegroHand::shipped().expect("allegro");
    // Targets 1 rad past the grasp against joints that barely move: kp 3 asks for 3 N m.
    let targets = hand.squeezed_grasp_rad(1.0);
    let run = run_against_inertias(targets, hand.start_grasp_rad, |c| {
        c.max_cycles = Some(100);
        c.max_delta_rad = 1.0;
    });
    let report = run.report.expect("the loop ran");
    assert!(report.max_torque_nm > 1.0, "the PD law asked for {} N m", report.max_torque_nm);
    assert!(report.torque_clips > 0);
    let scale = AllegroConfig::V4.torque;
    let mut checked = 0;
    for f in run.host_frames.iter().filter(|f| (0x180..=0x18C).contains(&f.id())) {
        let finger = usize::from((f.id() - 0x180) / 4);
        for (j, b) in f.payload().chunks_exact(2).enumerate() {
            let count = i16::from_le_bytes([b[0], b[1]]);
            assert!(
                count.unsigned_abs() <= scale.pwm_limit[finger][j].unsigned_abs(),
                "{count} on {finger}.{j}"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, (100 + 1) * 16);
    assert_eq!(run.emulator.stats.torques_beyond_clip, 0);
}

#[test]
fn implausible_positions_are_dropped_then_halt() {
    let hand = AllegroHand::shipped().expect("allegro");
    let mut q0 = hand.start_grasp_rad;
    // A joint reading far outside its range, as a broken sensor would.
    q0[5] = 2.8;
    let run = run_against_inertias(hand.start_grasp_rad, q0, |c| c.max_cycles = Some(100));
    let report = run.report.expect("the loop ran");
    assert_eq!(report.stop_reason, StopReason::ImplausibleState, "{}", report.stop_detail);
    assert!(report.stop_detail.contains("joint 5"), "{}", report.stop_detail);
    assert_eq!(report.cycles, 0, "no torque from an implausible reading");
    assert_eq!(report.implausible_sets, 11);
    assert_eq!(ids(&run.host_frames[run.host_frames.len() - 6..]), SHUTDOWN_IDS);
}

/// Inertias whose joint 6 reads 0.5 rad off for one position set, as a sensor glitch: the
/// set sent 31-33 ms after the servos went on (steps are 3 ms once the period is set, so one
/// step ends in that window).
struct Spike {
    plant: InertiaPlant,
    on_ms: u64,
}

impl AllegroPlant for Spike {
    fn step(&mut self, servo_on: bool, tau_nm: &[f32; NUM_JOINTS], ms: u32) {
        self.plant.step(servo_on, tau_nm, ms);
        if servo_on {
            self.on_ms += u64::from(ms);
        }
    }
    fn q_rad(&self) -> [f32; NUM_JOINTS] {
        let mut q = self.plant.q_rad();
        if (31..=33).contains(&self.on_ms) {
            q[6] += 0.5;
        }
        q
    }
}

#[test]
fn a_one_set_glitch_is_dropped_on_its_way_up_and_down_and_the_loop_runs_on() {
    let hand = AllegroHand::shipped().expect("allegro");
    let plant = Spike { plant: InertiaPlant::at(hand.start_grasp_rad), on_ms: 0 };
    let run = run_against(plant, hand.start_grasp_rad, |c| c.max_cycles = Some(100));
    let report = run.report.expect("the loop ran");
    assert_eq!(report.stop_reason, StopReason::StepsReached, "{}", report.stop_detail);
    assert_eq!(report.implausible_sets, 2, "the spike, and the set after it jumping back");
    assert_eq!(report.cycles, 100);
}

#[test]
fn a_silent_bus_fails_start_up_and_still_shuts_down() {
    let hand = AllegroHand::shipped().expect("allegro");
    let mut config = AllegroLoopConfig::new(&hand);
    config.startup_timeout = Duration::from_millis(100);
    let (bridge_end, _hand_end) = AllegroInProcess::pair();
    let sent = Arc::new(std::sync::Mutex::new(Vec::new()));
    let mut tap = Tap { inner: bridge_end, sent: sent.clone() };
    let err =
        allegro_loop::run(&mut tap, &mut HoldTargets(hand.start_grasp_rad), &config, &AtomicBool::new(false))
            .expect_err("nobody answers");
    assert!(err.to_string().contains("no info answer"), "{err}");
    let frames = sent.lock().expect("tap").clone();
    assert_eq!(ids(&frames[frames.len() - 6..]), SHUTDOWN_IDS);
}

#[test]
fn commands_decode_as_the_hand_reads_them() {
    // Every frame the loop sends is a command the hand's decoder takes.
    let hand = AllegroHand::shipped().expect("allegro");
    let run = run_against_inertias(hand.start_grasp_rad, hand.start_grasp_rad, |c| c.max_cycles = Some(20));
    for f in &run.host_frames {
        Command::decode_frame(&AllegroConfig::V4, f).expect("a command");
    }
    assert_eq!(run.emulator.stats.ignored_frames, 0);
}

/// The loop holding the simulated hand's start grasp in real time (ignored: it takes 3 s of
/// a core; the HIL test holds it for 10 s over vcan0).
#[cfg(feature = "sim")]
#[test]
#[ignore = "real-time physics for 3 s"]
fn the_simulated_allegro_holds_its_cube_under_the_pd_loop() {
    use vge_bridge::allegro_sim::{SimAllegro, SimAllegroConfig};
    let hand = AllegroHand::shipped().expect("allegro");
    let mut config = AllegroLoopConfig::new(&hand);
    config.position_timeout = Duration::from_secs(2);
    config.max_cycles = Some(1000);
    let (mut bridge_end, mut hand_end) = AllegroInProcess::pair();
    let done = Arc::new(AtomicBool::new(false));
    let hand_done = done.clone();
    let emulator = thread::spawn(move || {
        let plant = SimAllegro::new(SimAllegroConfig::default()).expect("sim");
        let mut e = AllegroHandEmulator::new(EmulatedHand::default(), plant);
        serve(&mut hand_end, &mut e, Duration::from_secs(5), &hand_done).expect("emulator link");
        (e.stats, e.plant().hold(), e.plant().released())
    });
    let report = allegro_loop::run(
        &mut bridge_end,
        &mut HoldTargets(hand.squeezed_grasp_rad(DEFAULT_SQUEEZE_RAD)),
        &config,
        &AtomicBool::new(false),
    )
    .expect("the loop ran");
    thread::sleep(Duration::from_millis(50));
    done.store(true, Ordering::Relaxed);
    let (stats, hold, released) = emulator.join().expect("emulator");
    eprintln!("{}", report.json_line(&[]));
    eprintln!("emulator: {stats:?}\nhold: {hold:?} released {released}");
    let hold = hold.expect("the stand was taken away");
    assert!(hold.fell_m < 0.01 && hold.tips_touching >= 3, "{hold:?}");
}

/// The loop's PD law (its gains, velocity estimate and torques) holding `targets` on the
/// simulated Allegro for `seconds` of the hand's time, in lockstep at the hand's 3 ms period:
/// how the cube fared. Lockstep, not the real-time loop, so that what is measured is the law
/// and its targets, whatever the host's load (the real-time loop holds it in the HIL test).
#[cfg(feature = "sim")]
fn hold_in_lockstep(
    targets: [f32; NUM_JOINTS],
    kv_nms_per_rad: Option<f32>,
    seconds: f32,
) -> vge_bridge::allegro_sim::HoldSummary {
    use vge_bridge::allegro_loop::{JointState, PERIOD, pd_torques_nm};
    use vge_bridge::allegro_sim::{SimAllegro, SimAllegroConfig};
    let hand = AllegroHand::shipped().expect("allegro");
    let mut config = AllegroLoopConfig::new(&hand);
    if let Some(kv) = kv_nms_per_rad {
        config.kv_nms_per_rad = [kv; NUM_JOINTS];
    }
    let mut plant = SimAllegro::new(SimAllegroConfig::default()).expect("the simulated Allegro");
    let mut state = JointState::at_rest(plant.q_rad());
    let period_ms = PERIOD.as_millis() as u32;
    for _ in 0..(seconds / PERIOD.as_secs_f32()).round() as usize {
        let tau = pd_torques_nm(&config, &targets, &state);
        plant.step(true, &tau, period_ms);
        state.update(plant.q_rad(), PERIOD.as_secs_f32(), config.velocity_smoothing);
    }
    assert!(plant.is_finite(), "the simulated hand blew up");
    plant.hold().expect("the hand gripped the cube and the stand went")
}

/// `--hold`'s targets, the start grasp pressed as the simulator presses it at a reset, hold the
/// cube under the loop's PD law (the simulator's servo gains) where it was released; the
/// flexion squeeze of a hand without a keyframe pushes it towards the thumb.
#[cfg(feature = "sim")]
#[test]
fn the_hold_presses_the_grasp_as_the_simulator_does_and_keeps_the_cube_where_it_was() {
    let pressed = AllegroHand::pressed_grasp_rad(vge_sim::HandOrientation::PalmDown).expect("press");
    let hand = AllegroHand::shipped().expect("allegro");
    let press = hold_in_lockstep(pressed, None, 3.0);
    let squeeze = hold_in_lockstep(hand.squeezed_grasp_rad(DEFAULT_SQUEEZE_RAD), None, 3.0);
    eprintln!("press:   {press:?}\nsqueeze: {squeeze:?}");
    for (name, h) in [("press", &press), ("squeeze", &squeeze)] {
        assert!(h.held_s > 2.5 && !h.dropped && h.tips_touching >= 3, "{name}: {h:?}");
    }
    assert!(press.moved_m < 0.003 && press.turned_rad < 0.05, "press: {press:?}");
    assert!(squeeze.moved_m > 2.0 * press.moved_m, "the squeeze pushes the cube: {squeeze:?} vs {press:?}");
}

/// Asks every joint to move by `delta_rad` at each update, and remembers what it observed.
struct Push {
    delta_rad: f32,
    observations: Vec<Vec<f32>>,
}

impl vge_bridge::policy_runner::PolicyRunner for Push {
    type Error = std::convert::Infallible;
    fn act(&mut self, obs: &[f32], action: &mut [f32]) -> Result<(), Self::Error> {
        self.observations.push(obs.to_vec());
        action.fill(self.delta_rad);
        Ok(())
    }
}

#[test]
fn a_policy_sets_the_targets_at_its_rate_clipped_as_the_env_clips_and_observes_its_history() {
    use vge_sim::observation::{ObservationLayout, ObservationSet};
    let hand = AllegroHand::shipped().expect("allegro");
    let set = ObservationSet::Proprio { history: 2 };
    // Asks for 1 rad a step: the env's clip makes it 0.05, the filter's 0.02 on top.
    let mut targets = PolicyTargets::new(Push { delta_rad: 1.0, observations: Vec::new() }, set, 0.05);
    let run = run_with(InertiaPlant::at(hand.start_grasp_rad), &mut targets, |c| {
        c.max_cycles = Some(200);
        c.target_rate_hz = 50.0;
        c.max_delta_rad = 0.02;
    });
    let report = run.report.expect("the loop ran");
    assert_eq!(report.stop_reason, StopReason::StepsReached, "{}", report.stop_detail);
    // The policy's rate is kept by the clock, so how many of the 200 sets carried an update
    // depends on the machine's load: at most one a set, and enough for the history below.
    assert!((3..=200).contains(&report.target_updates), "{} updates", report.target_updates);
    assert_eq!(report.target_errors, 0);
    assert_eq!(targets.updates, report.target_updates);
    assert_eq!(report.safety.delta_clamps, 16 * report.target_updates, "every joint held to 0.02 a step");
    let dim = ObservationLayout::new(set, NUM_JOINTS, 4).dim();
    let observations = &targets.policy().observations;
    assert!(observations.iter().all(|o| o.len() == dim), "{dim} floats each");
    // The targets observed rise 0.02 rad an update (until a range stops them), and the past
    // is the previous update's.
    let (second, third) = (&observations[1], &observations[2]);
    let (now, past) = (16..32, 64..80);
    for k in 0..NUM_JOINTS {
        let step = third[now.start + k] - second[now.start + k];
        assert!(step <= 0.02 + 1e-6, "joint {k} moved {step} in one update");
        assert_eq!(third[past.start + k], second[now.start + k], "joint {k}: the past is the last update");
    }
}

/// A policy over CAN starts as in training: the loop first moves the targets to the grasp the
/// env's reset presses (here the start grasp 0.1 rad further on every joint, so that the
/// filter needs several updates), holds it `settle_updates` more, and only then asks the
/// policy, whose first observation has the grasp's targets.
#[test]
fn a_policy_over_can_takes_over_from_the_settled_grasp() {
    use vge_bridge::allegro_loop::FromGrasp;
    use vge_sim::observation::ObservationSet;
    let hand = AllegroHand::shipped().expect("allegro");
    let grasp: [f32; NUM_JOINTS] =
        std::array::from_fn(|k| hand.limits[k].clamp(hand.start_grasp_rad[k] + 0.1));
    let set = ObservationSet::Proprio { history: 1 };
    let policy = PolicyTargets::new(Push { delta_rad: 0.0, observations: Vec::new() }, set, 0.05);
    let mut targets = FromGrasp::new(grasp, 3, policy);
    let run = run_with(InertiaPlant::at(hand.start_grasp_rad), &mut targets, |c| {
        c.max_cycles = Some(300);
        c.target_rate_hz = 100.0;
        c.max_delta_rad = 0.02;
    });
    let report = run.report.expect("the loop ran");
    assert!(targets.handed_over(), "{} updates", report.target_updates);
    let observations = &targets.then().policy().observations;
    let first = observations.first().expect("the policy ran once the grasp settled");
    // 0.1 rad at 0.02 an update: 5 updates to reach the grasp (6 where the start, measured
    // through the position frames' resolution, lies a little further), 3 at it, then the policy.
    let before_policy = report.target_updates as usize - observations.len();
    assert!((5 + 3..=6 + 3).contains(&before_policy), "{before_policy} updates before the policy");
    for k in 0..NUM_JOINTS {
        let observed = first[NUM_JOINTS + k];
        assert!(
            (observed - grasp[k]).abs() < 1e-6,
            "joint {k}: target {observed} observed, grasp {}",
            grasp[k]
        );
    }
}
