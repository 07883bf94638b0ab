//! `run --hand allegro` and `emulate --hand allegro`: the Allegro Hand v4 over its own CAN
//! protocol (docs/allegro-bridge.md).

use std::io::Write as _;
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
use vge_bridge::allegro_hand::AllegroHand;
use vge_bridge::allegro_link::{AllegroRole, AllegroSocketCan};
use vge_bridge::allegro_loop::{self, AllegroLoopConfig, AllegroReport, HoldTargets, PERIOD};
#[cfg(feature = "sim")]
use vge_bridge::allegro_sim::{SimAllegro, SimAllegroConfig};
#[cfg(feature = "sim")]
use vge_bridge::transport::BusCounts;

use super::{Backend, LoopArgs, positive_seconds, stop_on_signal};

/// What `run --hand allegro` was asked.
pub struct RunSettings {
    pub backend: Backend,
    pub iface: String,
    pub squeeze_rad: f32,
    pub loop_args: LoopArgs,
}

/// The default position timeout and persistence, in 3 ms periods.
const DEFAULT_WATCHDOG_PERIODS: u32 = 10;

fn loop_config(hand: &AllegroHand, args: &LoopArgs) -> anyhow::Result<AllegroLoopConfig> {
    let mut config = AllegroLoopConfig::new(hand);
    if let Some(rate) = args.rate {
        config.target_rate_hz = rate;
    }
    config.max_delta_rad = args.max_delta_rad;
    config.duration = positive_seconds("duration", args.duration, true)?;
    config.max_cycles = args.steps;
    let periods = args.watchdog_periods.unwrap_or(DEFAULT_WATCHDOG_PERIODS).max(1);
    config.position_timeout = PERIOD * periods;
    config.persist_limit = periods;
    Ok(config)
}

/// `vge-bridge run --hand allegro`.
pub fn run(settings: RunSettings) -> anyhow::Result<ExitCode> {
    let RunSettings { backend, iface, squeeze_rad, loop_args } = settings;
    anyhow::ensure!(
        squeeze_rad.is_finite() && squeeze_rad.abs() <= 1.0,
        "--squeeze-rad must be a number of rad within [-1, 1], got {squeeze_rad}"
    );
    let hand = AllegroHand::shipped()?;
    let config = loop_config(&hand, &loop_args)?;
    let mut targets = HoldTargets(hand.squeezed_grasp_rad(squeeze_rad));
    let stop = stop_on_signal()?;
    loop_args.realtime.apply();
    let (report, extra) = match backend {
        Backend::Can => {
            let mut link = AllegroSocketCan::open(&iface, AllegroRole::Host(config.protocol))
                .with_context(|| format!("opening CAN interface {iface}"))?;
            let report = allegro_loop::run(&mut link, &mut targets, &config, &stop)?;
            (report, vec![("backend", json!("can")), ("iface", json!(iface))])
        }
        Backend::Sim => {
            let (report, sim) = run_against_sim(&mut targets, &config, &stop)?;
            (report, vec![("backend", json!("sim")), ("emulator", sim)])
        }
    };
    let mut extra = extra;
    extra.push(("mode", json!("hold")));
    if loop_args.json {
        out!("{}", report.json_line(&extra));
    } else {
        print_report(&report, &extra)?;
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
    for (k, v) in extra {
        if *k == "emulator" {
            out!("sim:     {v}");
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
