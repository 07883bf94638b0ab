//! `run --hand allegro` and `emulate --hand allegro`: the Allegro Hand v4 over its own CAN
//! protocol (docs/allegro-bridge.md).

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
#[cfg(feature = "sim")]
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
#[cfg(feature = "sim")]
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::Context;
use serde_json::{Value, json};
#[cfg(feature = "sim")]
use vge_bridge::allegro_emulator::{AllegroHandEmulator, AllegroPlant};
use vge_bridge::allegro_hand::{AllegroHand, DEFAULT_SQUEEZE_RAD};
use vge_bridge::allegro_link::{AllegroRole, AllegroSocketCan};
use vge_bridge::allegro_loop::{
    self, AllegroLoopConfig, AllegroReport, FromGrasp, HoldTargets, PERIOD, PolicyTargets, TargetSource,
};
#[cfg(feature = "sim")]
use vge_bridge::allegro_sim::{SimAllegro, SimAllegroConfig};
use vge_bridge::protocol::allegro::NUM_JOINTS;
#[cfg(feature = "sim")]
use vge_bridge::transport::BusCounts;

use vge_bridge::policy_runner::{RuntimePolicy, storage_for};
use vge_sim::action::DEFAULT_MAX_ACTION_RAD;

use super::run::read_policy;
use super::{Backend, LoopArgs, ObjectArg, positive_seconds, stop_on_signal};

/// What `run --hand allegro` was asked.
pub struct RunSettings {
    pub backend: Backend,
    pub iface: String,
    /// The policy that sets the targets; `None`: --hold.
    pub policy: Option<PathBuf>,
    /// --hold's flexion squeeze by angle; `None`: the start grasp pressed as the simulator
    /// presses it.
    pub squeeze_rad: Option<f32>,
    /// The PD damping on every joint instead of the simulator's (N m s / rad).
    pub kv_nms_per_rad: Option<f32>,
    /// The object and seed of the simulated Allegro's env (--backend sim --policy).
    pub object: ObjectArg,
    pub seed: u64,
    pub loop_args: LoopArgs,
}

/// The default position timeout and persistence, in 3 ms periods.
const DEFAULT_WATCHDOG_PERIODS: u32 = 10;

fn loop_config(
    hand: &AllegroHand,
    kv_nms_per_rad: Option<f32>,
    args: &LoopArgs,
) -> anyhow::Result<AllegroLoopConfig> {
    let mut config = AllegroLoopConfig::new(hand);
    if let Some(kv) = kv_nms_per_rad {
        anyhow::ensure!(
            kv.is_finite() && kv >= 0.0,
            "--kv-nms-per-rad must be a finite number >= 0, got {kv}"
        );
        config.kv_nms_per_rad = [kv; NUM_JOINTS];
    }
    if let Some(rate) = args.rate {
        config.target_rate_hz = rate;
    }
    config.max_delta_rad = args.max_delta_rad;
    config.duration = positive_seconds("duration", args.duration, true)?;
    config.max_cycles = args.steps;
    let periods = args.watchdog_periods.unwrap_or(DEFAULT_WATCHDOG_PERIODS).max(1);
    config.position_timeout = PERIOD * periods;
    config.persist_limit = periods;
    if let Some(s) = args.startup_timeout_s {
        config.startup_timeout =
            positive_seconds("startup-timeout-s", s, false)?.unwrap_or(config.startup_timeout);
    }
    Ok(config)
}

/// `vge-bridge run --hand allegro`.
pub fn run(settings: RunSettings) -> anyhow::Result<ExitCode> {
    let RunSettings { backend, iface, policy, squeeze_rad, kv_nms_per_rad, object, seed, loop_args } =
        settings;
    if let Some(path) = policy {
        return run_policy(backend, &iface, &path, &object, seed, kv_nms_per_rad, &loop_args);
    }
    let hand = AllegroHand::shipped()?;
    let config = loop_config(&hand, kv_nms_per_rad, &loop_args)?;
    let (grasp, held) = hold_targets(&hand, squeeze_rad)?;
    let mut targets = HoldTargets(held);
    let stop = stop_on_signal()?;
    loop_args.realtime.apply();
    let (report, extra) = match backend {
        Backend::Can => can_loop(&iface, &mut targets, &config, &stop)?,
        Backend::Sim => {
            let (report, sim) = run_against_sim(&mut targets, &config, &stop)?;
            (report, vec![("backend", json!("sim")), ("emulator", sim)])
        }
    };
    let mut extra = extra;
    extra.push(("mode", json!("hold")));
    extra.push(("grasp", grasp));
    finish(&report, &extra, loop_args.json)
}

/// --hold's targets and how they were made: the start grasp pressed as the simulator's env
/// presses it (`"press"`), or squeezed by `squeeze_rad` on the flexion joints when given.
fn hold_targets(hand: &AllegroHand, squeeze_rad: Option<f32>) -> anyhow::Result<(Value, [f32; NUM_JOINTS])> {
    if let Some(squeeze_rad) = squeeze_rad {
        anyhow::ensure!(
            squeeze_rad.is_finite() && squeeze_rad.abs() <= 1.0,
            "--squeeze-rad must be a number of rad within [-1, 1], got {squeeze_rad}"
        );
        return Ok((json!(format!("squeeze {squeeze_rad} rad")), hand.squeezed_grasp_rad(squeeze_rad)));
    }
    pressed_grasp().map(|targets| (json!("press"), targets))
}

/// How long a policy over CAN holds its start grasp before it acts (s): the env's reset holds
/// the object 0.05 s while the press builds and lets it settle 0.25 s (`GraspConfig`).
const GRIP_S: f64 = 0.3;

/// The grasp a policy over CAN starts from: the env's, pressed as its reset presses it; without
/// the simulator's statics, the flexion squeeze, saying so.
fn policy_start_grasp(hand: &AllegroHand) -> anyhow::Result<(Value, [f32; NUM_JOINTS])> {
    if cfg!(feature = "sim") {
        return pressed_grasp().map(|targets| (json!("press"), targets));
    }
    note!(
        "vge-bridge: note: without the simulator (cargo feature `sim`) the policy starts from the start \
         grasp squeezed {DEFAULT_SQUEEZE_RAD} rad, not pressed as in training"
    );
    Ok((json!(format!("squeeze {DEFAULT_SQUEEZE_RAD} rad")), hand.squeezed_grasp_rad(DEFAULT_SQUEEZE_RAD)))
}

#[cfg(feature = "sim")]
fn pressed_grasp() -> anyhow::Result<[f32; NUM_JOINTS]> {
    Ok(AllegroHand::pressed_grasp_rad(vge_sim::HandOrientation::PalmDown)?)
}

/// Without the simulator there are no statics to press with: refuses, naming the fallback.
#[cfg(not(feature = "sim"))]
fn pressed_grasp() -> anyhow::Result<[f32; NUM_JOINTS]> {
    Err(super::no_sim(
        "--hold's press (the start grasp pressed as the simulator's reset presses it; --squeeze-rad R \
         squeezes the flexion joints by angle instead)",
    ))
}

/// The PD loop on `iface` with `targets`: its report and what names the run.
fn can_loop<S: TargetSource>(
    iface: &str,
    targets: &mut S,
    config: &AllegroLoopConfig,
    stop: &AtomicBool,
) -> anyhow::Result<(AllegroReport, Vec<(&'static str, Value)>)> {
    let mut link = AllegroSocketCan::open(iface, AllegroRole::Host(config.protocol))
        .with_context(|| format!("opening CAN interface {iface}"))?;
    let report = allegro_loop::run(&mut link, targets, config, stop)?;
    Ok((report, vec![("backend", json!("can")), ("iface", json!(iface))]))
}

/// `run --hand allegro --policy P`: over CAN the PD loop with the policy's targets; with the
/// simulator, the Allegro's env.
fn run_policy(
    backend: Backend,
    iface: &str,
    path: &Path,
    object: &ObjectArg,
    seed: u64,
    kv_nms_per_rad: Option<f32>,
    loop_args: &LoopArgs,
) -> anyhow::Result<ExitCode> {
    if backend == Backend::Sim && !cfg!(feature = "sim") {
        return Err(super::no_sim("--backend sim (the default)"));
    }
    anyhow::ensure!(
        backend == Backend::Can || kv_nms_per_rad.is_none(),
        "--kv-nms-per-rad sets the PD loop over CAN (or --hold's emulated hand); a policy with --backend sim \
         runs in the simulator's env, whose servos are the hand file's"
    );
    let description = vge_sim::hands::load("allegro").context("the Allegro's description")?;
    let bytes = read_policy(path)?;
    // The simulated hand senses its fingertips; the Allegro on CAN has no fingertip sensors.
    let tip_sensing = backend == Backend::Sim;
    let loading = || format!("loading {}", path.display());
    let (feed, mut storage) = storage_for(&bytes, &description, tip_sensing).with_context(loading)?;
    let runner = RuntimePolicy::load(&bytes, &mut storage).with_context(loading)?;
    let policy_hz = f64::from(runner.control_hz());
    let rate_hz = loop_args.rate.unwrap_or(policy_hz);
    if (rate_hz - policy_hz).abs() > 1e-3 {
        note!("vge-bridge: note: the policy was trained at {policy_hz} Hz, running it at {rate_hz} Hz");
    }
    let about = [
        ("mode", json!("policy")),
        ("policy", json!(path.display().to_string())),
        ("observation", json!(feed.set.name())),
    ];
    match backend {
        Backend::Can => {
            let hand = AllegroHand::shipped()?;
            let mut config = loop_config(&hand, kv_nms_per_rad, loop_args)?;
            config.target_rate_hz = rate_hz;
            // The action is clipped as the env clips it when training; --max-delta-rad is the
            // safety filter's bound on top.
            let policy = PolicyTargets::new(runner, feed.set, DEFAULT_MAX_ACTION_RAD);
            // As the env's reset: the grasp pressed and settled first, then the policy from it.
            let (grasp, start) = policy_start_grasp(&hand)?;
            let settle_updates = (GRIP_S * rate_hz).round().max(1.0) as u32;
            let mut targets = FromGrasp::new(start, settle_updates, policy);
            let stop = stop_on_signal()?;
            loop_args.realtime.apply();
            let (report, mut extra) = can_loop(iface, &mut targets, &config, &stop)?;
            extra.extend(about);
            extra.push(("grasp", grasp));
            extra.push(("policy_updates", json!(targets.then().updates)));
            finish(&report, &extra, loop_args.json)
        }
        Backend::Sim => {
            run_policy_sim(runner, feed.set, description, object, seed, rate_hz, loop_args, &about)
        }
    }
}

/// The policy against the simulated Allegro's env, in process.
#[cfg(feature = "sim")]
#[allow(clippy::too_many_arguments)]
fn run_policy_sim(
    mut runner: RuntimePolicy<'_>,
    set: vge_sim::ObservationSet,
    description: Arc<vge_hand::Hand>,
    object: &ObjectArg,
    seed: u64,
    rate_hz: f64,
    loop_args: &LoopArgs,
    about: &[(&str, Value)],
) -> anyhow::Result<ExitCode> {
    use vge_bridge::sim_policy::{self, SimPolicyConfig};
    let mut env = vge_sim::EnvConfig::for_hand(description).context("the simulated Allegro")?;
    env.object.shape = *object;
    let mut env = vge_sim::Env::new(env).context("the simulated Allegro")?;
    let config = SimPolicyConfig {
        rate_hz,
        duration: positive_seconds("duration", loop_args.duration, true)?,
        max_steps: loop_args.steps,
        max_delta_rad: loop_args.max_delta_rad,
        watchdog_periods: loop_args.watchdog_periods.unwrap_or(5),
        observation: set,
        seed,
    };
    anyhow::ensure!(
        config.max_delta_rad.is_finite() && config.max_delta_rad > 0.0,
        "--max-delta-rad must be positive"
    );
    let stop = stop_on_signal()?;
    loop_args.realtime.apply();
    let (report, summary) = sim_policy::run(&mut env, &mut runner, &config, &stop)?;
    let mut extra =
        vec![("hand", json!("allegro")), ("backend", json!("sim")), ("object", json!(object.to_string()))];
    extra.extend(about.iter().cloned());
    super::run::print_report(loop_args.json, &extra, rate_hz, &report, Some(&summary))?;
    Ok(super::run::exit_status(&report))
}

/// Stand-in without the simulator: refuses.
#[cfg(not(feature = "sim"))]
#[allow(clippy::too_many_arguments)]
fn run_policy_sim(
    _: RuntimePolicy<'_>,
    _: vge_sim::ObservationSet,
    _: std::sync::Arc<vge_hand::Hand>,
    _: &ObjectArg,
    _: u64,
    _: f64,
    _: &LoopArgs,
    _: &[(&str, Value)],
) -> anyhow::Result<ExitCode> {
    Err(super::no_sim("--backend sim (the default)"))
}

/// Prints the report (one JSON line with --json) and returns the exit status, naming a safety
/// halt on stderr.
fn finish(report: &AllegroReport, extra: &[(&str, Value)], json: bool) -> anyhow::Result<ExitCode> {
    if json {
        out!("{}", report.json_line(extra));
    } else {
        print_report(report, extra)?;
    }
    let reason = report.stop_reason;
    if reason.is_safety_halt() {
        note!(
            "vge-bridge: safety halt ({}): {}; zeroed the torques and turned the servos off; exit status {}",
            reason.as_str(),
            report.stop_detail,
            reason.exit_code()
        );
    }
    Ok(ExitCode::from(reason.exit_code()))
}

fn print_report(r: &AllegroReport, extra: &[(&str, Value)]) -> anyhow::Result<()> {
    let detail = if r.stop_detail.is_empty() { String::new() } else { format!(": {}", r.stop_detail) };
    out!("stopped: {} after {} torque sets{detail}", r.stop_reason.as_str(), r.cycles);
    if let Some(i) = r.info {
        out!(
            "hand:    Allegro hardware {:#06x}, firmware {:#06x}, serial {}",
            i.hardware_version,
            i.firmware_version,
            r.serial.as_deref().unwrap_or("(no answer)")
        );
    }
    out!(
        "rate:    {:.2} Hz achieved of {:.2} Hz; {} late position sets (> 1.5 periods apart), {} skipped \
         for a newer one",
        r.achieved_rate_hz,
        1.0 / PERIOD.as_secs_f64(),
        r.late_position_sets,
        r.superseded_sets
    );
    out!(
        "jitter:  |set interval - 3 ms| p50 {:.1} us, p99 {:.1} us, max {:.1} us",
        r.period_jitter.p50_us,
        r.period_jitter.p99_us,
        r.period_jitter.max_us
    );
    out!(
        "torques: written p50 {:.1} us, p99 {:.1} us, max {:.1} us after their positions; {} late (> 1.5 ms)",
        r.response.p50_us,
        r.response.p99_us,
        r.response.max_us,
        r.late_torque_sets
    );
    out!(
        "frames:  {} in, {} out; {} position, {} temperature, {} status; {} bad, {} error frames, {} not sent",
        r.bus.frames_in,
        r.bus.frames_out,
        r.position_frames,
        r.temperature_frames,
        r.status_frames,
        r.bad_frames,
        r.error_frames.total(),
        r.tx_dropped
    );
    out!(
        "safety:  {} implausible sets, {} joint torques clipped (largest asked {:.3} N m), {} target errors, \
         {} delta clamps, {} limit clamps; {} of 6 shut-down frames sent",
        r.implausible_sets,
        r.torque_clips,
        r.max_torque_nm,
        r.target_errors,
        r.safety.delta_clamps,
        r.safety.limit_clamps,
        r.shutdown_frames
    );
    out!("targets: {} updates, {} failed", r.target_updates, r.target_errors);
    for (k, v) in extra {
        match *k {
            "emulator" => out!("sim:     {v}"),
            "policy" => out!("policy:  {}", v.as_str().unwrap_or_default()),
            "observation" => out!("observed: {}", v.as_str().unwrap_or_default()),
            _ => {}
        }
    }
    Ok(())
}

/// The emulator's summary: its counts and, for the simulated hand, how the cube fared.
#[cfg(feature = "sim")]
fn summary<P: AllegroPlant>(e: &AllegroHandEmulator<P>, bus: BusCounts, hold: Option<Value>) -> Value {
    let s = &e.stats;
    json!({
        "hand": "allegro",
        "model": "sim",
        "frames_in": bus.frames_in,
        "frames_out": bus.frames_out,
        "commands": s.commands,
        "requests_answered": s.requests_answered,
        "torque_frames": s.torque_frames,
        "torques_beyond_clip": s.torques_beyond_clip,
        "servo_ons": s.servo_ons,
        "servo_offs": s.servo_offs,
        "period_sets": s.period_sets,
        "position_sets": s.position_sets,
        "temperature_frames": s.temperature_frames,
        "ignored_frames": s.ignored_frames,
        "late_steps": s.late_steps,
        "sim_s": s.sim_ms as f64 / 1000.0,
        "servo_on_at_end": e.servo_on(),
        "position_period_ms_at_end": e.period().position_ms,
        "hold": hold.unwrap_or(Value::Null),
    })
}

#[cfg(feature = "sim")]
fn hold_json(plant: &SimAllegro) -> Option<Value> {
    let round = |v: f64, digits: i32| {
        let scale = 10f64.powi(digits);
        (v * scale).round() / scale
    };
    plant.hold().map(|h| {
        json!({
            "held_s": round(h.held_s, 3),
            "fell_m": round(f64::from(h.fell_m), 5),
            "moved_m": round(f64::from(h.moved_m), 5),
            "turned_rad": round(f64::from(h.turned_rad), 4),
            "tips_touching": h.tips_touching,
            "rotation_rad": round(f64::from(h.rotation_z_rad), 4),
            "rotation_axis_tilt_rad": round(f64::from(h.rotation_axis_tilt_rad), 4),
            "contact_switches": h.contact_switches,
            "dropped": h.dropped,
        })
    })
}

/// The loop against the simulated Allegro on a thread of its own, over the in-process link.
#[cfg(feature = "sim")]
fn run_against_sim(
    targets: &mut HoldTargets,
    config: &AllegroLoopConfig,
    stop: &AtomicBool,
) -> anyhow::Result<(AllegroReport, Value)> {
    use vge_bridge::allegro_emulator::{EmulatedHand, serve};
    use vge_bridge::allegro_link::{AllegroInProcess, AllegroLink};
    let (mut bridge_end, mut hand_end) = AllegroInProcess::pair();
    let plant = SimAllegro::new(SimAllegroConfig::default())?;
    let done = Arc::new(AtomicBool::new(false));
    let hand_done = done.clone();
    let hand = std::thread::spawn(move || {
        let mut e = AllegroHandEmulator::new(EmulatedHand::default(), plant);
        let served = serve(&mut hand_end, &mut e, Duration::from_secs(5), &hand_done);
        served.map(|()| summary(&e, hand_end.bus_counts(), hold_json(e.plant())))
    });
    let report = allegro_loop::run(&mut bridge_end, targets, config, stop);
    // The emulator takes in the shut-down frames before it stops.
    std::thread::sleep(Duration::from_millis(20));
    done.store(true, Ordering::Relaxed);
    let sim = hand.join().map_err(|_| anyhow::anyhow!("the simulated Allegro's thread panicked"))??;
    Ok((report?, sim))
}

/// Stand-in without the simulator: refuses.
#[cfg(not(feature = "sim"))]
fn run_against_sim(
    _: &mut HoldTargets,
    _: &AllegroLoopConfig,
    _: &AtomicBool,
) -> anyhow::Result<(AllegroReport, Value)> {
    Err(super::no_sim("--backend sim (the default)"))
}

/// `vge-bridge emulate --hand allegro`.
#[cfg(feature = "sim")]
pub fn emulate(iface: &str, idle: Duration, json: bool) -> anyhow::Result<ExitCode> {
    use vge_bridge::allegro_emulator::{EmulatedHand, serve};
    use vge_bridge::allegro_link::AllegroLink;
    let stop = stop_on_signal()?;
    let plant = SimAllegro::new(SimAllegroConfig::default())?;
    let mut link = AllegroSocketCan::open(iface, AllegroRole::Hand)
        .with_context(|| format!("opening CAN interface {iface}"))?;
    let mut e = AllegroHandEmulator::new(EmulatedHand::default(), plant);
    note!("vge-bridge: emulating an Allegro Hand v4 holding a 65 mm cube on {iface}");
    serve(&mut link, &mut e, idle, &stop)?;
    let summary = summary(&e, link.bus_counts(), hold_json(e.plant()));
    if json {
        out!("{summary}");
    } else {
        note!("vge-bridge: emulator summary: {summary}");
    }
    Ok(ExitCode::SUCCESS)
}

/// Stand-in without the simulator: refuses.
#[cfg(not(feature = "sim"))]
pub fn emulate(_: &str, _: Duration, _: bool) -> anyhow::Result<ExitCode> {
    Err(super::no_sim("the emulated Allegro (--model sim)"))
}
