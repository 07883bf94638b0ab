//! `vge-bridge run`: a policy at a fixed rate against vge's hand (simulated, or over CAN), or
//! the Allegro Hand's PD loop (`--hand allegro`, [`super::allegro`]).

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use serde_json::{Value, json};
use vge_bridge::control_loop::{self, LoopConfig, LoopReport, PolicyRunner, StopReason};
use vge_bridge::hand_file;
use vge_bridge::policy_runner::{RuntimePolicy, storage_for};
use vge_bridge::protocol::fd::{FD_JOINTS, FD_NODES};
use vge_bridge::protocol_hand::{self, ProtocolHand};
use vge_bridge::report::{SimHandSummary, json_line};
#[cfg(feature = "sim")]
use vge_bridge::sim_hand::{self, SimHand};
use vge_bridge::transport::{FdSocketCanTransport, Role, SocketCanTransport};
use vge_hand::Hand;
use vge_runtime::AlignedBytes;
#[cfg(feature = "sim")]
use vge_sim::{EnvConfig, ObjectShape};

#[cfg(not(feature = "sim"))]
use super::ObjectArg;
use super::{Backend, HandArg, LoopArgs, SimHandArgs, no_sim, parse_hand, positive_seconds, stop_on_signal};

/// Run a policy file at a fixed rate, or hold the Allegro Hand's grasp.
///
/// vge's hand (--hand vge15, the default, a hand file, or a hand description whose fingers
/// are three joints each): the policy file is checked against the hand before its weights are
/// loaded (its joints, its observation slices); each period, read the hand's state, build the
/// observation exactly as the simulator does (the set the policy was trained with), run the
/// policy on vge-runtime, clamp the change and the joint limits, send the targets. Stops after
/// --duration, on Ctrl-C (hold, then disable), when the hand falls silent (watchdog) or when a
/// node reports a fault or restarts. Prints rate, jitter, deadline misses and frame counts, and the object's
/// rotation with the sim backend.
///
/// The Allegro Hand v4 (--hand allegro; docs/allegro-bridge.md): start-up as its drivers do
/// it (flush, servo off, info and serial requests, position period 3 ms, servo on; then the
/// info answer and all four position frames), then a joint PD loop at the hand's 333 Hz: each
/// set of four position frames is answered with four torque frames, tau = kp (target - q) -
/// kv dq, the gains from the hand's description. The targets move towards --hold's grasp at
/// --rate, at most --max-delta-rad a step, within the joint ranges; torques beyond a joint's
/// clip are clipped before they leave the host. On stop, fault or timeout: zero torques, servos
/// off, reports off. Halts when no complete position set came for --watchdog-periods periods
/// (3 ms each), on implausible positions (outside the ranges, or jumps), on a hand fault.
/// Prints the loop's rate, its jitter and late sets. With --policy the targets are the policy's
/// instead of --hold's: it runs at its own rate (the file's, 20 Hz) on the joint angles and
/// targets now and at its past steps (the Allegro has no fingertip sensors: only a policy of
/// the `proprio` observation set runs on it), each action a change of the targets clipped as
/// the simulator clips it, then held to --max-delta-rad and the ranges like --hold's. With
/// --backend sim: --hold runs the emulated Allegro (`emulate --hand allegro`'s) in process;
/// --policy runs the simulated Allegro's env (as it was trained) in process and prints how the
/// object turned, the contact switches and whether it dropped.
///
/// Exit status: 0 after --duration, --steps or Ctrl-C; after a safety halt one per stop
/// reason: 10 watchdog (Allegro: position timeout), 11 node_fault, 12 heartbeat_lost, 13
/// node_restarted, 14 implausible_state, 15 policy_failure, 16 bus_off, 17 bus_overload, 18
/// tx_failure; 1 when it could not run (a bad file, no answer from the hand at start-up, a
/// transport error); 2 for a bad command line.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Policy file written by `vge train`, `vge export` or `vge import`, for the hand driven:
    /// refused, before its weights are loaded, when its actions are not the hand's joints or
    /// it observes what the hand cannot give. Required unless --hold.
    #[arg(long, required_unless_present = "hold")]
    policy: Option<PathBuf>,
    /// The hand: `vge15` (vge's own, default), `allegro` (the Allegro Hand v4 over its own CAN
    /// protocol), a hand description (MJCF `.xml`, its TOML beside it) whose fingers are three
    /// joints each, on vge's protocol, or a hand file (TOML: `joint_limits_rad`, one [lower,
    /// upper] pair in rad per joint, 15 for vge15, finger-major; docs/can-protocol.md, Joint
    /// limits) with the joint limits of vge15 on vge's protocol, instead of those below. The
    /// safety filter clamps targets to them and the plausibility check holds positions
    /// against them; the simulated hand keeps its own.
    #[arg(long, value_name = "HAND|FILE", default_value = "vge15", value_parser = parse_hand)]
    hand: HandArg,
    /// The hand to drive: the simulated one in process, or one on CAN (`--iface`). `sim` needs
    /// a vge-bridge built with the `sim` cargo feature (the default build).
    #[arg(long, value_enum, default_value_t = Backend::Sim)]
    backend: Backend,
    /// CAN interface (backend can).
    #[arg(long, default_value = "vcan0")]
    iface: String,
    /// Use the CAN FD option (backend can, a hand of five nodes such as vge15): one frame per
    /// node per step and one command frame for the hand; the interface needs an FD MTU (72).
    #[arg(long)]
    fd: bool,
    #[command(flatten)]
    sim_hand: SimHandArgs,
    /// Record the simulated episode (backend sim, vge15) into this file (JSON Lines): each
    /// finger link's pose and the object's, the fingertip and link contact points with their
    /// normal forces, the joint-target changes sent and the reward, one line per control
    /// step. See it in the Rerun viewer with the Python package:
    /// `python -m vge.recording F.jsonl --spawn` (`pip install ./python rerun-sdk`).
    /// Refused with --backend can: a real hand does not report where the object is.
    #[arg(long, value_name = "F.jsonl")]
    record: Option<PathBuf>,
    /// Hold the start grasp instead of running a policy (--hand allegro): the targets are the
    /// hand description's start grasp pressed as the simulator's env presses it at a reset
    /// (each fingertip into its face with 5 N per kg of the cube, 0.1 kg, the thumb against the
    /// others' resultant, the weights carried; palm down), the targets the policies start from
    /// in training. Needs the `sim` feature (the default build) for the statics.
    #[arg(long, conflicts_with = "policy")]
    hold: bool,
    /// --hold squeezes instead: every joint but each finger's first this much further than the
    /// start grasp (rad; 0.05 as vge squeezes a hand without a keyframe). The thumb's flexion
    /// then presses mostly upwards and pushes the cube towards the thumb.
    #[arg(long, requires = "hold")]
    squeeze_rad: Option<f32>,
    /// The Allegro's PD damping on every joint (N m s / rad) instead of the simulator's (its
    /// servo's kv plus the joint's damping: 0.001 for hands/allegro.xml, what the policies are
    /// trained with). A real hand's geared joints may want more: HORA ran the real Allegro
    /// with D 0.1 (hands/allegro.xml, "Motor gains").
    #[arg(long, value_name = "NMS_PER_RAD")]
    kv_nms_per_rad: Option<f32>,
    #[command(flatten)]
    loop_args: LoopArgs,
}

/// `vge-bridge run`.
pub fn run(args: RunArgs) -> anyhow::Result<ExitCode> {
    let RunArgs {
        policy,
        hand,
        backend,
        iface,
        fd,
        sim_hand: SimHandArgs { object, seed },
        record,
        hold: _,
        squeeze_rad,
        kv_nms_per_rad,
        loop_args,
    } = args;
    if hand == HandArg::Allegro {
        anyhow::ensure!(!fd, "--fd is vge's protocol's CAN FD option; the Allegro speaks classic CAN");
        anyhow::ensure!(
            record.is_none(),
            "--record records the simulated vge15 episode; the Allegro's is not recorded yet"
        );
        let run = super::allegro::RunSettings {
            backend,
            iface,
            policy,
            squeeze_rad,
            kv_nms_per_rad,
            object,
            seed,
            loop_args,
        };
        return super::allegro::run(run);
    }
    anyhow::ensure!(
        kv_nms_per_rad.is_none(),
        "--kv-nms-per-rad sets the Allegro's PD loop (--hand allegro); vge's joint controllers run their own"
    );
    let Some(policy) = policy else {
        anyhow::bail!("--hold holds the Allegro's grasp (--hand allegro); vge15 runs a --policy");
    };
    if backend == Backend::Sim && !cfg!(feature = "sim") {
        return Err(no_sim("--backend sim (the default)"));
    }
    if record.is_some() {
        anyhow::ensure!(
            backend == Backend::Sim,
            "--record needs --backend sim: over CAN the hand reports its joints and fingertip \
             sensors but not the object, whose pose the recording is about"
        );
        #[cfg(feature = "sim")]
        if let Some(path) = &record {
            vge_sim::recording::check_path(path)?;
        }
    }
    let (description, hand) = own_protocol_hand(&hand)?;
    anyhow::ensure!(
        !fd || hand.num_fingers() == FD_NODES,
        "--fd: the CAN FD hand command carries {FD_NODES} finger nodes ({FD_JOINTS} joint targets); the \
         hand {} has {}: run it on the classic frames (without --fd)",
        hand.name,
        hand.num_fingers()
    );
    let bytes = read_policy(&policy)?;
    // vge's protocol carries the fingertip sensors' frames, and the simulated hand fills them.
    let (feed, mut storage) =
        storage_for(&bytes, &description, true).with_context(|| format!("loading {}", policy.display()))?;
    let mut runner =
        RuntimePolicy::load(&bytes, &mut storage).with_context(|| format!("loading {}", policy.display()))?;
    let mut cfg = loop_config(&loop_args, runner.control_hz(), hand)?;
    cfg.observation = feed.set;
    let stop = stop_on_signal()?;
    loop_args.realtime.apply();
    match backend {
        Backend::Can => {
            let opening = || format!("opening CAN interface {iface}");
            let report = if fd {
                let mut transport = FdSocketCanTransport::open(&iface, Role::Host).with_context(opening)?;
                control_loop::run(&mut transport, &mut runner, &cfg, &stop)?
            } else {
                let mut transport = SocketCanTransport::open(&iface, Role::Host).with_context(opening)?;
                control_loop::run(&mut transport, &mut runner, &cfg, &stop)?
            };
            let backend = if fd { "can-fd" } else { "can" };
            let extra = [("hand", json!(cfg.hand.name)), ("backend", json!(backend))];
            print_report(loop_args.json, &extra, cfg.rate_hz, &report, None)?;
            Ok(exit_status(&report))
        }
        Backend::Sim => {
            let (report, summary) =
                run_against_sim(&mut runner, &cfg, description, &object, seed, record.as_deref(), &stop)?;
            let extra = [
                ("hand", json!(cfg.hand.name)),
                ("backend", json!("sim")),
                ("object", json!(object.to_string())),
            ];
            print_report(loop_args.json, &extra, cfg.rate_hz, &report, Some(&summary))?;
            Ok(exit_status(&report))
        }
    }
}

/// The hand `--hand` names on vge's own protocol: its description (what the policy is checked
/// against and the simulated hand is built from) and its nodes and limits (a hand file's
/// limits in place of vge15's).
pub fn own_protocol_hand(arg: &HandArg) -> anyhow::Result<(Arc<Hand>, ProtocolHand)> {
    let spec = match arg {
        HandArg::Own(spec) => spec.as_str(),
        HandArg::Vge15File(_) | HandArg::Allegro => "vge15",
    };
    let description = protocol_hand::load(spec).with_context(|| format!("--hand {spec}"))?;
    let mut hand = ProtocolHand::of(&description)?;
    if let HandArg::Vge15File(path) = arg {
        hand.limits = hand_file::load_joint_limits(path, &hand)
            .with_context(|| format!("hand file {}", path.display()))?;
    }
    Ok((description, hand))
}

/// The joint limits every target is clamped to (and positions are checked against).
pub fn joint_limits_help() -> String {
    let hand = match ProtocolHand::vge15() {
        Ok(hand) => hand,
        Err(e) => return format!("Joint limits: vge15's description could not be read: {e}\n"),
    };
    let mut text = String::from(
        "Joint limits (rad) of vge15, the default hand (--hand FILE replaces them): the safety filter clamps\n\
         every target to them, and a measured position more than 0.1 rad outside them is implausible\n\
         (dropped and counted; the loop holds, and halts if it persists). Another hand's are those of\n\
         its description (the Allegro's hands/allegro.xml: `vge hand inspect allegro`).\n  \
         finger   ",
    );
    // The joints of a finger by their names after the finger's (vge15: roll, flex_prox, flex_dist).
    let per_node = hand.num_joints() / hand.num_fingers().max(1);
    for k in 0..per_node {
        let name = hand.joint_name(k);
        let short = name.rsplit('.').next().unwrap_or(&name);
        text.push_str(&format!("{short:<18}"));
    }
    text = text.trim_end().to_owned();
    text.push('\n');
    for (f, name) in hand.finger_names.iter().enumerate() {
        text.push_str(&format!("  {name:<8}"));
        for l in hand.limits.iter().skip(per_node * f).take(per_node) {
            text.push_str(&format!(" [{:+.3}, {:+.3}]", l.lower_rad, l.upper_rad));
        }
        text.push('\n');
    }
    text
}

pub fn loop_config(args: &LoopArgs, policy_hz: f32, hand: ProtocolHand) -> anyhow::Result<LoopConfig> {
    let rate_hz = args.rate.unwrap_or(f64::from(policy_hz));
    anyhow::ensure!(
        rate_hz.is_finite() && rate_hz >= control_loop::MIN_RATE_HZ,
        "--rate must be a number of Hz, at least {}, got {rate_hz}",
        control_loop::MIN_RATE_HZ
    );
    if (rate_hz - f64::from(policy_hz)).abs() > 1e-3 {
        note!("vge-bridge: note: the policy was trained at {policy_hz} Hz, running it at {rate_hz} Hz");
    }
    anyhow::ensure!(
        args.max_delta_rad.is_finite() && args.max_delta_rad > 0.0,
        "--max-delta-rad must be positive"
    );
    let heartbeat_timeout =
        positive_seconds("heartbeat-timeout-s", args.heartbeat_timeout_s, false)?.unwrap_or(Duration::MAX);
    let defaults = LoopConfig::new(rate_hz, hand);
    let startup_timeout = match args.startup_timeout_s {
        Some(s) => positive_seconds("startup-timeout-s", s, false)?.unwrap_or(defaults.startup_timeout),
        None => defaults.startup_timeout,
    };
    Ok(LoopConfig {
        duration: positive_seconds("duration", args.duration, true)?,
        startup_timeout,
        max_steps: args.steps,
        watchdog_periods: args.watchdog_periods.unwrap_or(5).max(1),
        max_delta_rad: args.max_delta_rad,
        heartbeat_timeout,
        max_seq_lag: args.max_seq_lag,
        ..defaults
    })
}

/// The file's bytes at an aligned address, so that a version-2 policy is used in place. A file
/// longer than any hand policy (its length from its metadata) is refused unread.
pub fn read_policy(path: &Path) -> anyhow::Result<AlignedBytes> {
    use std::io::Read;
    use vge_runtime::policy::HAND_MAX_FILE_LEN;
    let context = || format!("reading policy file {}", path.display());
    let file = std::fs::File::open(path).with_context(context)?;
    let len = file.metadata().with_context(context)?.len();
    let too_long = |len: u64| {
        anyhow::anyhow!(
            "policy file {}: {len} bytes, longer than any hand policy (at most {HAND_MAX_FILE_LEN} \
             bytes); not read",
            path.display()
        )
    };
    if len > HAND_MAX_FILE_LEN as u64 {
        return Err(too_long(len));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(HAND_MAX_FILE_LEN as u64 + 1).read_to_end(&mut bytes).with_context(context)?;
    if bytes.len() > HAND_MAX_FILE_LEN {
        return Err(too_long(bytes.len() as u64));
    }
    Ok(AlignedBytes::new(&bytes))
}

pub fn print_report(
    json: bool,
    extra: &[(&str, Value)],
    rate_hz: f64,
    r: &LoopReport,
    sim: Option<&SimHandSummary>,
) -> anyhow::Result<()> {
    if json {
        out!("{}", json_line(extra, rate_hz, r, sim));
        return Ok(());
    }
    let detail = if r.stop_detail.is_empty() { String::new() } else { format!(": {}", r.stop_detail) };
    out!("stopped: {} after {} steps{detail}", r.stop_reason.as_str(), r.pace.steps);
    out!("rate:    {:.2} Hz achieved of {:.2} Hz", r.pace.achieved_rate_hz, rate_hz);
    out!(
        "jitter:  p50 {:.1} us, p99 {:.1} us, max {:.1} us; deadline misses {} ({} periods skipped)",
        r.pace.wake_jitter.p50_us,
        r.pace.wake_jitter.p99_us,
        r.pace.wake_jitter.max_us,
        r.pace.deadline_misses,
        r.pace.skipped_periods
    );
    out!(
        "loop:    p50 {:.1} us, p99 {:.1} us, max {:.1} us",
        r.pace.loop_time.p50_us,
        r.pace.loop_time.p99_us,
        r.pace.loop_time.max_us
    );
    let l = &r.link;
    out!(
        "frames:  {} in, {} out on the bus ({} / {} messages); {} bad, {} stale, {} implausible, {} lost",
        l.frames_in,
        l.frames_out,
        l.messages_in,
        l.messages_out,
        l.bad_frames,
        l.stale_frames,
        l.implausible_frames,
        l.lost_frames
    );
    out!(
        "bus:     {} error frames ({} bus-off), {} frames not sent, {} overloaded periods",
        l.error_frames.total(),
        l.error_frames.bus_off,
        l.tx_dropped,
        l.overload_periods
    );
    out!(
        "safety:  {} holds ({} policy errors), {} NaN holds, {} delta clamps, {} limit clamps",
        r.holds,
        r.policy_errors,
        r.safety.non_finite_holds,
        r.safety.delta_clamps,
        r.safety.limit_clamps
    );
    if let Some(s) = sim {
        out!(
            "object:  turned {:.3} rad about z in {} sim steps, about an axis {:.0} deg from z; return {:.3}; {:.2} fingertip contacts on average, {} contact switches, {:.3} m fingertip slip{}",
            s.rotation_rad,
            s.steps,
            s.rotation_axis_tilt_rad.to_degrees(),
            s.total_reward,
            s.mean_tip_contacts,
            s.contact_switches,
            s.tip_slip_m,
            match (s.dropped, s.terminated) {
                (true, _) => "; the object dropped",
                (false, true) => "; the episode terminated (lost contacts)",
                (false, false) => "",
            }
        );
    }
    Ok(())
}

/// `run`'s exit status: 0 for a normal end, the stop reason's own status for a safety halt
/// (named on stderr too, whatever --json says).
pub fn exit_status(report: &LoopReport) -> ExitCode {
    let reason: StopReason = report.stop_reason;
    if reason.is_safety_halt() {
        note!(
            "vge-bridge: safety halt ({}): {}; held, then disabled the fingers; exit status {}",
            reason.as_str(),
            report.stop_detail,
            reason.exit_code()
        );
    }
    ExitCode::from(reason.exit_code())
}

/// Stand-in without the simulator: refuses.
#[cfg(not(feature = "sim"))]
fn run_against_sim<P: PolicyRunner>(
    _: &mut P,
    _: &LoopConfig,
    _: Arc<Hand>,
    _: &ObjectArg,
    _: u64,
    _: Option<&Path>,
    _: &Arc<AtomicBool>,
) -> anyhow::Result<(LoopReport, SimHandSummary)> {
    Err(no_sim("--backend sim (the default)"))
}

/// Runs the loop against the simulated hand on a thread of its own, over the protocol.
#[cfg(feature = "sim")]
fn run_against_sim<P: PolicyRunner>(
    runner: &mut P,
    cfg: &LoopConfig,
    hand: Arc<Hand>,
    object: &ObjectShape,
    seed: u64,
    record: Option<&Path>,
    stop: &Arc<AtomicBool>,
) -> anyhow::Result<(LoopReport, SimHandSummary)> {
    use std::sync::atomic::Ordering;
    use std::thread;
    use vge_bridge::transport::InProcessTransport;
    let name = hand.name().to_owned();
    let mut env = EnvConfig::for_hand(hand).with_context(|| format!("the simulated hand {name}"))?;
    env.object.shape = *object;
    let (mut bridge_end, mut nodes_end) = InProcessTransport::pair();
    let nodes_stop = Arc::new(AtomicBool::new(false));
    let nodes_flag = nodes_stop.clone();
    // In-process the link cannot lose commands; the timeout only guards a stalled loop.
    let mut hand = SimHand::new(env, seed, Duration::from_secs(1)).context("building the simulated hand")?;
    if let Some(path) = record {
        hand.record_to(path).with_context(|| format!("recording into {}", path.display()))?;
    }
    let nodes = thread::spawn(move || {
        let mut hand = hand;
        sim_hand::serve(&mut nodes_end, &mut hand, Duration::from_secs(5), &nodes_flag)?;
        let recorded = hand.finish_recording()?;
        Ok::<_, sim_hand::SimHandError>((hand.summary(), recorded))
    });
    let report = control_loop::run(&mut bridge_end, runner, cfg, stop);
    nodes_stop.store(true, Ordering::Relaxed);
    let (summary, recorded) =
        nodes.join().map_err(|_| anyhow::anyhow!("the simulated hand's thread panicked"))??;
    if let (Some(path), Some(steps)) = (record, recorded) {
        note!(
            "vge-bridge: {steps} sim steps recorded in {}; see it in Rerun with `python -m vge.recording {} --spawn`",
            path.display(),
            path.display()
        );
    }
    Ok((report?, summary))
}
