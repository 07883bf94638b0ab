//! The bridge's loop for the Allegro Hand (docs/allegro-protocol.md, docs/allegro-bridge.md):
//! start-up, a joint PD loop at the hand's 333 Hz driven by its position frames, and
//! shut-down.
//!
//! The hand sets the pace: once told to, it sends its four position frames every 3 ms, and the
//! loop answers each complete set with four torque frames, `tau = kp (target - q) - kv dq`
//! (the hand file's gains, `dq` estimated from successive positions). The PD targets come from
//! a [`TargetSource`] (a policy, or a fixed grasp) at its own, slower rate, each step limited
//! to `max_delta_rad` per joint and to the joints' ranges by the same [`SafetyFilter`] vge's
//! own loop uses. Torques beyond a joint's clip are clipped by the encoder, so no frame
//! carries more.
//!
//! What the loop does not trust, and what it does then:
//! - no complete set of position frames for `position_timeout`: halt (watchdog);
//! - a position outside its joint's range by more than `plausibility_margin_rad`, or a jump of
//!   more than `max_jump_rad` from the previous set: the set is dropped (no torques that
//!   period, the hand keeps the last ones) and counted; the loop halts if that persists for
//!   `persist_limit` sets (implausible_state);
//! - a target source that errs or proposes a non-finite target: the safe targets are held;
//!   the loop halts if that persists for `persist_limit` updates (policy_failure);
//! - the hand's status (its answer to the periodic status request, or the info at start-up)
//!   with a fault bit: halt (node_fault);
//! - a SocketCAN bus-off error frame: halt (bus_off); other error frames are counted;
//! - torque frames that cannot be sent (transmit queue full, after one retry) for
//!   `persist_limit` sets: halt (tx_failure).
//!
//! Every end, a halt's and a normal one's alike, sends the shut-down sequence: zero torque on
//! every finger, servos off, periodic reports off. A hand that goes limp drops what it holds,
//! but a hand that keeps pushing with torques nobody updates is worse.

use std::convert::Infallible;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use serde_json::{Map, Value, json};
use thiserror::Error;
use vge_hand::JointLimit;
use vge_sim::action::DEFAULT_MAX_ACTION_RAD;
use vge_sim::observation::ObservationSet;

use crate::allegro_hand::AllegroHand;
use crate::allegro_link::{AllegroLink, AllegroReceived};
use crate::control_loop::{ErrorFrameCounts, StopReason};
use crate::pacing::Persisting;
use crate::policy_runner::{Observer, PolicyRunner};
use crate::protocol::allegro::{
    AllegroConfig, AllegroFrame, CONTROL_PERIOD_MS, Command, Finger, Info, JOINTS_PER_FINGER, NUM_JOINTS,
    PositionCycle, Report, Request, SHUTDOWN_COMMANDS, STARTUP_COMMANDS, Status, TorqueScale,
};
use crate::safety::{SafetyCounts, SafetyFilter};
use crate::stats::Percentiles;
use crate::transport::{BusCounts, TransportError};

/// The hand's joint state as the loop estimates it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointState {
    pub q_rad: [f32; NUM_JOINTS],
    /// Finite differences of successive position sets, smoothed.
    pub dq_radps: [f32; NUM_JOINTS],
}

impl JointState {
    /// At rest at `q_rad`.
    #[must_use]
    pub fn at_rest(q_rad: [f32; NUM_JOINTS]) -> Self {
        Self { q_rad, dq_radps: [0.0; NUM_JOINTS] }
    }

    /// Takes in a trusted position set read `dt_s` after the last trusted one: the velocity
    /// estimate moves towards the finite difference by `smoothing` (0, 1].
    pub fn update(&mut self, q_rad: [f32; NUM_JOINTS], dt_s: f32, smoothing: f32) {
        for ((dq, q_new), q_old) in self.dq_radps.iter_mut().zip(&q_rad).zip(&self.q_rad) {
            *dq = smoothing * (q_new - q_old) / dt_s + (1.0 - smoothing) * *dq;
        }
        self.q_rad = q_rad;
    }
}

/// The loop's PD law on every joint: `tau = kp (target - q) - kv dq` (N m, before the clip).
#[must_use]
pub fn pd_torques_nm(
    config: &AllegroLoopConfig,
    targets_rad: &[f32; NUM_JOINTS],
    state: &JointState,
) -> [f32; NUM_JOINTS] {
    std::array::from_fn(|k| {
        config.kp_nm_per_rad[k] * (targets_rad[k] - state.q_rad[k])
            - config.kv_nms_per_rad[k] * state.dq_radps[k]
    })
}

/// What sets the PD targets: a policy ([`PolicyTargets`]), or a fixed pose.
pub trait TargetSource {
    type Error: std::error::Error + Send + Sync + 'static;
    /// The joint targets wanted now (rad, CAN joint order), given the joint state and the
    /// targets in force (`current_rad`, the safety filter's last safe ones).
    fn targets(
        &mut self,
        state: &JointState,
        current_rad: &[f32; NUM_JOINTS],
    ) -> Result<[f32; NUM_JOINTS], Self::Error>;
}

/// Fixed targets (`--hold`: the start grasp, squeezed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldTargets(pub [f32; NUM_JOINTS]);

impl TargetSource for HoldTargets {
    type Error = Infallible;
    fn targets(&mut self, _: &JointState, _: &[f32; NUM_JOINTS]) -> Result<[f32; NUM_JOINTS], Infallible> {
        Ok(self.0)
    }
}

/// A policy setting the PD targets at its own rate, as the simulator's env applies an action:
/// each update observes the joint angles and the targets in force (the Allegro has no
/// fingertip sensing, so the observation is the proprioceptive one, [`Observer`]) and moves
/// every target by the policy's action clipped to `max_action_rad` (the env's
/// `max_action_rad`). The loop's safety filter then holds the step and the ranges as for any
/// target source.
#[derive(Debug)]
pub struct PolicyTargets<P> {
    policy: P,
    observer: Observer,
    max_action_rad: f32,
    action: [f32; NUM_JOINTS],
    /// Updates the policy ran.
    pub updates: u64,
}

impl<P: PolicyRunner> PolicyTargets<P> {
    pub fn new(policy: P, set: ObservationSet, max_action_rad: f32) -> Self {
        Self { policy, observer: Observer::new(set), max_action_rad, action: [0.0; NUM_JOINTS], updates: 0 }
    }

    /// The policy.
    pub fn policy(&self) -> &P {
        &self.policy
    }
}

impl<P: PolicyRunner> TargetSource for PolicyTargets<P> {
    type Error = P::Error;
    fn targets(
        &mut self,
        state: &JointState,
        current_rad: &[f32; NUM_JOINTS],
    ) -> Result<[f32; NUM_JOINTS], P::Error> {
        let obs = self.observer.observe(&state.q_rad, current_rad, &[]);
        self.policy.act(&obs, &mut self.action)?;
        self.updates += 1;
        let max = self.max_action_rad;
        // A non-finite action stays non-finite: the filter holds the targets and counts it.
        Ok(std::array::from_fn(|k| {
            let a = self.action[k];
            if a.is_finite() { current_rad[k] + a.clamp(-max, max) } else { f32::NAN }
        }))
    }
}

/// A target source that first holds a grasp, as the simulator's reset grips the object before
/// an episode, and hands over to `then` once the safe targets have reached the grasp and stayed
/// there `settle_updates` updates: a policy then starts from the targets it was trained to
/// start from (the pressed grasp), not from the joints' measured angles at power-up, where
/// the fingertips only touch the object and it slips out.
#[derive(Debug)]
pub struct FromGrasp<S> {
    grasp_rad: [f32; NUM_JOINTS],
    settle_updates: u32,
    at_grasp: u32,
    then: S,
}

impl<S> FromGrasp<S> {
    pub fn new(grasp_rad: [f32; NUM_JOINTS], settle_updates: u32, then: S) -> Self {
        Self { grasp_rad, settle_updates, at_grasp: 0, then }
    }

    /// Whether the grasp has settled and `then` sets the targets.
    pub fn handed_over(&self) -> bool {
        self.at_grasp > self.settle_updates
    }

    /// The source that takes over.
    pub fn then(&self) -> &S {
        &self.then
    }
}

impl<S: TargetSource> TargetSource for FromGrasp<S> {
    type Error = S::Error;
    fn targets(
        &mut self,
        state: &JointState,
        current_rad: &[f32; NUM_JOINTS],
    ) -> Result<[f32; NUM_JOINTS], S::Error> {
        if !self.handed_over() {
            let reached = current_rad.iter().zip(&self.grasp_rad).all(|(c, g)| (c - g).abs() <= 1e-6);
            self.at_grasp = if reached { self.at_grasp + 1 } else { 0 };
            if !self.handed_over() {
                return Ok(self.grasp_rad);
            }
        }
        self.then.targets(state, current_rad)
    }
}

/// Settings of one run.
#[derive(Debug, Clone)]
pub struct AllegroLoopConfig {
    /// Ids, device and set-period layout. The torque scale is replaced by the one the hand's
    /// hardware version calls for once its info has arrived.
    pub protocol: AllegroConfig,
    pub kp_nm_per_rad: [f32; NUM_JOINTS],
    pub kv_nms_per_rad: [f32; NUM_JOINTS],
    pub limits: [JointLimit; NUM_JOINTS],
    /// How often the target source is asked (a policy's control rate).
    pub target_rate_hz: f64,
    /// Largest change of a joint's target per update (rad).
    pub max_delta_rad: f32,
    /// Stop after this long; `None`: until the stop flag.
    pub duration: Option<Duration>,
    /// Stop after this many torque sets.
    pub max_cycles: Option<u64>,
    /// How long start-up waits for the info answer and the first four position frames.
    pub startup_timeout: Duration,
    /// No complete set of position frames for this long halts the loop.
    pub position_timeout: Duration,
    /// How far outside its range a measured joint may read before it is implausible.
    pub plausibility_margin_rad: f32,
    /// Largest change of a joint's position from one set to the next.
    pub max_jump_rad: f32,
    /// Implausible sets, failing target updates or unsent torque sets in a row that halt.
    pub persist_limit: u32,
    /// Weight of the newest finite difference in the velocity estimate (0, 1].
    pub velocity_smoothing: f32,
    /// How often to ask the hand for its status (fault bits); `None`: never.
    pub status_period: Option<Duration>,
}

/// Frames taken from the bus before the loop acts on what they said: ten periods' traffic.
const RX_BUDGET: usize = 100;

/// The control period the loop sets: the hand's position period.
pub const PERIOD: Duration = Duration::from_millis(CONTROL_PERIOD_MS as u64);

impl AllegroLoopConfig {
    /// The defaults of `vge-bridge run --hand allegro`: `hand`'s gains and ranges, thresholds
    /// for a 333 Hz loop.
    pub fn new(hand: &AllegroHand) -> Self {
        Self {
            protocol: AllegroConfig::V4,
            kp_nm_per_rad: hand.kp_nm_per_rad,
            kv_nms_per_rad: hand.kv_nms_per_rad,
            limits: hand.limits,
            target_rate_hz: 20.0,
            max_delta_rad: DEFAULT_MAX_ACTION_RAD,
            duration: None,
            max_cycles: None,
            startup_timeout: Duration::from_secs(2),
            // Ten periods: a hand that has missed ten sets in a row is not reporting, and a
            // finger under the last torques moves little in 30 ms.
            position_timeout: 10 * PERIOD,
            plausibility_margin_rad: 0.1,
            // 33 rad/s, five times what the motors reach unloaded.
            max_jump_rad: 0.1,
            persist_limit: 10,
            velocity_smoothing: 0.3,
            status_period: Some(Duration::from_millis(500)),
        }
    }
}

#[derive(Debug, Error)]
pub enum AllegroLoopError {
    #[error("transport: {0}")]
    Transport(#[from] TransportError),
    #[error("no {missing} within {timeout:?} of start-up (is the hand powered, on the bus, at 1 Mbit/s?)")]
    StartupTimeout { timeout: Duration, missing: String },
    #[error("the hand reports a fault at start-up: {0}")]
    HandFault(String),
    #[error("invalid loop settings: {0}")]
    BadConfig(String),
}

/// What one run did: why it stopped, its timing, and what crossed the bus.
#[derive(Debug, Clone, PartialEq)]
pub struct AllegroReport {
    pub stop_reason: StopReason,
    pub stop_detail: String,
    /// Frames dropped from the receive queue before start-up.
    pub flushed: usize,
    pub info: Option<Info>,
    pub serial: Option<String>,
    /// Torque sets sent, one per complete set of position frames.
    pub cycles: u64,
    /// Complete position sets per second over the run.
    pub achieved_rate_hz: f64,
    /// |interval between complete position sets - period|.
    pub period_jitter: Percentiles,
    /// Position sets that completed more than 1.5 periods after the previous one.
    pub late_position_sets: u64,
    /// From reading the set's last position frame to its torque frames written.
    pub response: Percentiles,
    /// Torque sets written more than half a period after their positions.
    pub late_torque_sets: u64,
    pub bus: BusCounts,
    pub position_frames: u64,
    pub temperature_frames: u64,
    pub status_frames: u64,
    /// Frames the protocol refuses (another device, a wrong length), extended-id frames.
    pub bad_frames: u64,
    pub error_frames: ErrorFrameCounts,
    /// Position sets dropped as implausible.
    pub implausible_sets: u64,
    /// Complete position sets skipped because a newer one was already queued (the host had
    /// fallen behind the hand).
    pub superseded_sets: u64,
    /// Joint torques the encoder clipped, summed over joints and sets.
    pub torque_clips: u64,
    /// Largest torque the PD law asked for (N m), before the clip.
    pub max_torque_nm: f32,
    pub tx_dropped: u64,
    pub target_updates: u64,
    /// Target updates whose source erred (the safe targets were held).
    pub target_errors: u64,
    pub safety: SafetyCounts,
    /// Highest joint temperature reported (deg C).
    pub max_temperature_c: Option<i8>,
    /// Shut-down frames sent (of [`SHUTDOWN_COMMANDS`]'s six).
    pub shutdown_frames: usize,
    pub final_targets_rad: [f32; NUM_JOINTS],
    pub final_q_rad: [f32; NUM_JOINTS],
}

impl AllegroReport {
    fn new() -> Self {
        Self {
            stop_reason: StopReason::StopRequested,
            stop_detail: String::new(),
            flushed: 0,
            info: None,
            serial: None,
            cycles: 0,
            achieved_rate_hz: 0.0,
            period_jitter: Percentiles::default(),
            late_position_sets: 0,
            response: Percentiles::default(),
            late_torque_sets: 0,
            bus: BusCounts::default(),
            position_frames: 0,
            temperature_frames: 0,
            status_frames: 0,
            bad_frames: 0,
            error_frames: ErrorFrameCounts::default(),
            implausible_sets: 0,
            superseded_sets: 0,
            torque_clips: 0,
            max_torque_nm: 0.0,
            tx_dropped: 0,
            target_updates: 0,
            target_errors: 0,
            safety: SafetyCounts::default(),
            max_temperature_c: None,
            shutdown_frames: 0,
            final_targets_rad: [0.0; NUM_JOINTS],
            final_q_rad: [0.0; NUM_JOINTS],
        }
    }

    /// One JSON line: `extra` pairs first, then every figure.
    pub fn json_line(&self, extra: &[(&str, Value)]) -> String {
        let round = |v: f64, digits: i32| {
            let scale = 10f64.powi(digits);
            json!((v * scale).round() / scale)
        };
        let mut m = Map::new();
        for (k, v) in extra {
            m.insert((*k).to_owned(), v.clone());
        }
        let info = self.info.map(|i| {
            json!({
                "hardware_version": i.hardware_version,
                "firmware_version": i.firmware_version,
                "status_bits": i.status.bits,
            })
        });
        let fields = [
            ("hand", json!("allegro")),
            ("rate_hz", round(1000.0 / f64::from(CONTROL_PERIOD_MS), 3)),
            ("achieved_rate_hz", round(self.achieved_rate_hz, 3)),
            ("cycles", json!(self.cycles)),
            ("jitter_p50_us", round(self.period_jitter.p50_us, 1)),
            ("jitter_p99_us", round(self.period_jitter.p99_us, 1)),
            ("jitter_max_us", round(self.period_jitter.max_us, 1)),
            ("late_position_sets", json!(self.late_position_sets)),
            ("response_p50_us", round(self.response.p50_us, 1)),
            ("response_p99_us", round(self.response.p99_us, 1)),
            ("response_max_us", round(self.response.max_us, 1)),
            ("late_torque_sets", json!(self.late_torque_sets)),
            ("flushed", json!(self.flushed)),
            ("info", info.unwrap_or(Value::Null)),
            ("serial", self.serial.as_ref().map_or(Value::Null, |s| json!(s))),
            ("frames_in", json!(self.bus.frames_in)),
            ("frames_out", json!(self.bus.frames_out)),
            ("position_frames", json!(self.position_frames)),
            ("temperature_frames", json!(self.temperature_frames)),
            ("status_frames", json!(self.status_frames)),
            ("bad_frames", json!(self.bad_frames)),
            ("error_frames", json!(self.error_frames.total())),
            ("error_frames_bus_off", json!(self.error_frames.bus_off)),
            ("implausible_sets", json!(self.implausible_sets)),
            ("superseded_sets", json!(self.superseded_sets)),
            ("torque_clips", json!(self.torque_clips)),
            ("max_torque_nm", round(f64::from(self.max_torque_nm), 4)),
            ("tx_dropped", json!(self.tx_dropped)),
            ("target_updates", json!(self.target_updates)),
            ("target_errors", json!(self.target_errors)),
            ("non_finite_holds", json!(self.safety.non_finite_holds)),
            ("delta_clamps", json!(self.safety.delta_clamps)),
            ("limit_clamps", json!(self.safety.limit_clamps)),
            ("max_temperature_c", self.max_temperature_c.map_or(Value::Null, |t| json!(t))),
            ("shutdown_frames", json!(self.shutdown_frames)),
            ("stop_reason", json!(self.stop_reason.as_str())),
            ("stop_detail", json!(self.stop_detail)),
        ];
        for (k, v) in fields {
            m.insert(k.to_owned(), v);
        }
        Value::Object(m).to_string()
    }
}

/// Runs start-up, the PD loop and shut-down on `link`. An error means the loop never ran (no
/// answer from the hand, a transport failure); the shut-down sequence has been sent all the
/// same wherever the link still worked.
pub fn run<L: AllegroLink, S: TargetSource>(
    link: &mut L,
    source: &mut S,
    config: &AllegroLoopConfig,
    stop: &AtomicBool,
) -> Result<AllegroReport, AllegroLoopError> {
    check(config)?;
    let mut report = AllegroReport::new();
    let mut io = Io { link, protocol: config.protocol, report: &mut report };
    let started = match start_up(&mut io, config, stop) {
        Ok(s) => s,
        Err(e) => {
            // The servos may be on already: leave the hand limp and quiet.
            let _ = io.shut_down();
            return Err(e);
        }
    };
    let outcome = pd_loop(&mut io, source, config, stop, started);
    // Shut down whatever happened, a transport error included (the send may still work).
    let shutdown = io.shut_down();
    let (reason, detail) = outcome?;
    shutdown?;
    report.stop_reason = reason;
    report.stop_detail = detail;
    Ok(report)
}

fn check(config: &AllegroLoopConfig) -> Result<(), AllegroLoopError> {
    let bad = |what: String| Err(AllegroLoopError::BadConfig(what));
    config.protocol.validate().map_err(|e| AllegroLoopError::BadConfig(e.to_string()))?;
    if !(config.target_rate_hz.is_finite() && config.target_rate_hz >= 1e-3) {
        return bad(format!("target rate {} Hz", config.target_rate_hz));
    }
    if !(config.max_delta_rad.is_finite() && config.max_delta_rad > 0.0) {
        return bad(format!("max delta {} rad", config.max_delta_rad));
    }
    if !(config.velocity_smoothing > 0.0 && config.velocity_smoothing <= 1.0) {
        return bad(format!("velocity smoothing {}", config.velocity_smoothing));
    }
    let gains = config.kp_nm_per_rad.iter().chain(&config.kv_nms_per_rad);
    if gains.clone().any(|g| !g.is_finite() || *g < 0.0) {
        return bad("gains must be finite and not negative".to_owned());
    }
    if config.position_timeout < PERIOD {
        return bad(format!("position timeout {:?} is shorter than a period", config.position_timeout));
    }
    Ok(())
}

struct Io<'a, L: AllegroLink> {
    link: &'a mut L,
    protocol: AllegroConfig,
    report: &'a mut AllegroReport,
}

impl<L: AllegroLink> Io<'_, L> {
    /// Sends `frame`, retrying once on a full transmit queue; `false` when it still could not go.
    fn send(&mut self, frame: &AllegroFrame) -> Result<bool, TransportError> {
        for attempt in 0..2 {
            match self.link.send(frame) {
                Ok(()) => return Ok(true),
                Err(TransportError::TxQueueFull { .. }) if attempt == 0 => {
                    std::thread::sleep(Duration::from_micros(100));
                }
                Err(TransportError::TxQueueFull { .. }) => break,
                Err(e) => return Err(e),
            }
        }
        self.report.tx_dropped += 1;
        Ok(false)
    }

    fn command(&mut self, command: &Command) -> Result<bool, TransportError> {
        // The loop's commands are constants or finite torques: encoding cannot fail; were it to,
        // sending nothing is what a halt does anyway.
        match command.encode(&self.protocol) {
            Ok(frame) => self.send(&frame),
            Err(_) => Ok(false),
        }
    }

    /// The next report within `timeout`, with the bus's noise counted on the way.
    fn recv(&mut self, timeout: Duration) -> Result<Option<Report>, TransportError> {
        let Some(received) = self.link.recv(timeout)? else { return Ok(None) };
        match received {
            AllegroReceived::Frame(f) if !f.is_remote() => match Report::decode_frame(&self.protocol, &f) {
                Ok(r) => {
                    match r {
                        Report::Position(_) => self.report.position_frames += 1,
                        Report::Temperature(t) => {
                            self.report.temperature_frames += 1;
                            let hottest = t.temperature_c.iter().copied().max();
                            self.report.max_temperature_c = self.report.max_temperature_c.max(hottest);
                        }
                        Report::Status(_) => self.report.status_frames += 1,
                        Report::Info(_) | Report::Serial(_) => {}
                    }
                    return Ok(Some(r));
                }
                Err(_) => self.report.bad_frames += 1,
            },
            AllegroReceived::Frame(_) | AllegroReceived::Malformed { .. } => self.report.bad_frames += 1,
            AllegroReceived::Error { class } => self.report.error_frames.count(class),
        }
        Ok(None)
    }

    /// Zero torques, servos off, reports off; every frame tried even when one fails.
    fn shut_down(&mut self) -> Result<(), TransportError> {
        let mut first_error = None;
        for command in &SHUTDOWN_COMMANDS {
            match self.command(command) {
                Ok(true) => self.report.shutdown_frames += 1,
                Ok(false) => {}
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
        self.report.bus = self.link.bus_counts();
        first_error.map_or(Ok(()), Err)
    }
}

/// What start-up ends with: the first complete reading.
struct Started {
    q_rad: [f32; NUM_JOINTS],
    at: Instant,
}

/// Flush, the start-up commands, then wait for the info answer (its hardware version picks the
/// torque scale) and a complete set of position frames. Info and serial requests are repeated
/// every half second while unanswered: a request lost on a busy bus is not a dead hand.
fn start_up<L: AllegroLink>(
    io: &mut Io<'_, L>,
    config: &AllegroLoopConfig,
    stop: &AtomicBool,
) -> Result<Started, AllegroLoopError> {
    io.report.flushed = io.link.flush(10_000)?;
    for command in &STARTUP_COMMANDS {
        io.command(command)?;
    }
    let began = Instant::now();
    let mut asked = began;
    let mut cycle = PositionCycle::new();
    let mut first = None;
    loop {
        if let (Some(_), Some(q)) = (io.report.info, first) {
            return Ok(Started { q_rad: q, at: Instant::now() });
        }
        let now = Instant::now();
        if now.duration_since(began) > config.startup_timeout || stop.load(Ordering::Relaxed) {
            let missing = if io.report.info.is_none() {
                "info answer".to_owned()
            } else {
                let seen = cycle.seen();
                let missing: Vec<&str> = Finger::ALL
                    .iter()
                    .filter(|f| seen & (1 << f.index()) == 0)
                    .map(|f| finger_name(*f))
                    .collect();
                format!("position frames (none complete; missing this set: {})", missing.join(", "))
            };
            return Err(AllegroLoopError::StartupTimeout { timeout: config.startup_timeout, missing });
        }
        if now.duration_since(asked) > Duration::from_millis(500) {
            asked = now;
            if io.report.info.is_none() {
                io.command(&Command::Request(Request::Info))?;
            }
            if io.report.serial.is_none() {
                io.command(&Command::Request(Request::Serial))?;
            }
        }
        match io.recv(Duration::from_millis(10))? {
            Some(Report::Info(info)) => {
                if info.status.fault() {
                    return Err(AllegroLoopError::HandFault(status_text(info.status)));
                }
                io.protocol.torque = TorqueScale::for_hardware(info.hardware_major());
                io.report.info = Some(info);
            }
            Some(Report::Serial(s)) => {
                io.report.serial =
                    Some(s.as_str().map_or_else(|| format!("{:02x?}", s.ascii), str::to_owned));
            }
            Some(Report::Position(p)) => {
                if let Some(q) = cycle.push(&p) {
                    first = Some(q);
                }
            }
            Some(Report::Temperature(_) | Report::Status(_)) | None => {}
        }
    }
}

fn finger_name(f: Finger) -> &'static str {
    match f {
        Finger::Index => "index",
        Finger::Middle => "middle",
        Finger::Ring => "ring",
        Finger::Thumb => "thumb",
    }
}

fn status_text(s: Status) -> String {
    let mut faults = Vec::new();
    for (bit, what) in [
        (Status::JOINT_OVER_TEMPERATURE, "joint over temperature"),
        (Status::JOINT_THROTTLED, "joint throttled for temperature"),
        (Status::COMMUNICATION_TIMEOUT, "joint communication timeout"),
        (Status::PALM_OVER_TEMPERATURE, "palm over temperature"),
    ] {
        if s.bits & bit != 0 {
            faults.push(what);
        }
    }
    format!("status {:#04x} ({})", s.bits, faults.join(", "))
}

/// Why a complete position set is not trusted, if it is not.
fn implausible(
    q: &[f32; NUM_JOINTS],
    last: &[f32; NUM_JOINTS],
    config: &AllegroLoopConfig,
) -> Option<String> {
    for k in 0..NUM_JOINTS {
        let l = config.limits[k];
        let margin = config.plausibility_margin_rad;
        if !(l.lower_rad - margin..=l.upper_rad + margin).contains(&q[k]) {
            return Some(format!(
                "joint {k} at {:.3} rad, outside [{:.3}, {:.3}] by more than {margin} rad",
                q[k], l.lower_rad, l.upper_rad
            ));
        }
        if (q[k] - last[k]).abs() > config.max_jump_rad {
            return Some(format!(
                "joint {k} jumped {:.3} rad in one set (at most {} rad)",
                q[k] - last[k],
                config.max_jump_rad
            ));
        }
    }
    None
}

/// The PD loop proper, from the first complete reading to a stop; the stop reason and detail.
fn pd_loop<L: AllegroLink, S: TargetSource>(
    io: &mut Io<'_, L>,
    source: &mut S,
    config: &AllegroLoopConfig,
    stop: &AtomicBool,
    started: Started,
) -> Result<(StopReason, String), AllegroLoopError> {
    let period_s = PERIOD.as_secs_f32();
    let target_period = Duration::from_secs_f64(1.0 / config.target_rate_hz);
    let end = config.duration.and_then(|d| started.at.checked_add(d));
    let mut filter = SafetyFilter::new(config.max_delta_rad, config.limits.to_vec(), &started.q_rad);
    let mut state = JointState::at_rest(started.q_rad);
    let mut targets = started.q_rad;
    targets.copy_from_slice(filter.last_safe_rad());
    let mut cycle = PositionCycle::new();
    let mut last_set_at = started.at;
    // The previous complete set as read, and sets read since the last trusted one.
    let mut last_read = started.q_rad;
    let mut sets_since_trusted = 0u32;
    let mut first_set_at = None;
    let mut next_update = started.at;
    let mut next_status = config.status_period.map(|p| started.at + p);
    let (mut implausible_run, mut target_run, mut tx_run) =
        (Persisting::default(), Persisting::default(), Persisting::default());
    let mut intervals = Vec::new();
    let mut responses = Vec::new();

    let outcome = loop {
        let now = Instant::now();
        if stop.load(Ordering::Relaxed) {
            break (StopReason::StopRequested, String::new());
        }
        if end.is_some_and(|e| now >= e) {
            break (StopReason::DurationReached, String::new());
        }
        if io.report.error_frames.bus_off > 0 {
            break (StopReason::BusOff, "the CAN controller reported bus-off".to_owned());
        }
        let silent = now.duration_since(last_set_at);
        if silent > config.position_timeout {
            let seen = cycle.seen();
            let missing: Vec<&str> = Finger::ALL
                .iter()
                .filter(|f| seen & (1 << f.index()) == 0)
                .map(|f| finger_name(*f))
                .collect();
            break (
                StopReason::Watchdog,
                format!(
                    "no complete set of position frames for {:.1} ms (timeout {:.1} ms; missing: {})",
                    silent.as_secs_f64() * 1e3,
                    config.position_timeout.as_secs_f64() * 1e3,
                    missing.join(", ")
                ),
            );
        }
        if now >= next_update {
            io.report.target_updates += 1;
            let failed = match source.targets(&state, &targets) {
                Ok(proposal) => {
                    let holds = filter.counts.non_finite_holds;
                    targets.copy_from_slice(filter.apply_target(&proposal));
                    filter.counts.non_finite_holds > holds
                }
                Err(_) => {
                    io.report.target_errors += 1;
                    true
                }
            };
            if target_run.record(failed, config.persist_limit) {
                break (
                    StopReason::PolicyFailure,
                    format!("the targets failed {} updates in a row", config.persist_limit + 1),
                );
            }
            next_update += target_period;
            if next_update <= now {
                next_update = now + target_period;
            }
        }
        if let Some(due) = next_status
            && now >= due
        {
            io.command(&Command::Request(Request::Status))?;
            next_status = config.status_period.map(|p| now + p);
        }

        let mut wake = next_update.min(last_set_at + config.position_timeout + Duration::from_micros(100));
        if let Some(e) = end {
            wake = wake.min(e);
        }
        // Short waits, so a stop request is seen within 10 ms whatever the bus does.
        let wait = wake.saturating_duration_since(Instant::now()).min(Duration::from_millis(10));
        // Everything queued, not just the next frame: a host that fell behind acts on the
        // newest complete set and skips the older ones, rather than answering each in turn
        // with torques ever further behind the hand.
        let mut received = io.recv(wait)?;
        let mut newest = None;
        let mut before_newest = last_read;
        let mut fault = None;
        let mut taken = 0;
        while let Some(report) = received {
            match report {
                Report::Position(p) => {
                    if let Some(q) = cycle.push(&p) {
                        if newest.is_some() {
                            io.report.superseded_sets += 1;
                        }
                        newest = Some(q);
                        before_newest = std::mem::replace(&mut last_read, q);
                        sets_since_trusted += 1;
                    }
                }
                Report::Status(s) | Report::Info(Info { status: s, .. }) if s.fault() => {
                    fault = Some(s);
                    break;
                }
                _ => {}
            }
            taken += 1;
            if taken >= RX_BUDGET {
                break;
            }
            received = io.recv(Duration::ZERO)?;
        }
        if let Some(s) = fault {
            break (StopReason::NodeFault, format!("the hand reports {}", status_text(s)));
        }
        let Some(q) = newest else { continue };
        let read_at = Instant::now();
        let interval = read_at.duration_since(last_set_at);
        last_set_at = read_at;
        if first_set_at.is_some() {
            intervals.push(interval);
            if interval > PERIOD * 3 / 2 {
                io.report.late_position_sets += 1;
            }
        }
        first_set_at.get_or_insert(read_at);
        io.report.final_q_rad = q;

        // Jumps are measured from the previous set as read, trusted or not: a one-set spike is
        // dropped on its way up and down, and a joint that really moved while sets were lost
        // is trusted again from its second set, instead of every later set looking like a
        // jump from a stale reading.
        if let Some(why) = implausible(&q, &before_newest, config) {
            io.report.implausible_sets += 1;
            if implausible_run.record(true, config.persist_limit) {
                break (StopReason::ImplausibleState, why);
            }
            continue;
        }
        implausible_run.record(false, config.persist_limit);
        state.update(q, period_s * sets_since_trusted as f32, config.velocity_smoothing);
        sets_since_trusted = 0;

        let tau = pd_torques_nm(config, &targets, &state);
        for finger in Finger::ALL {
            for joint in 0..JOINTS_PER_FINGER {
                let t = tau[finger.joint_index(joint)].abs();
                io.report.max_torque_nm = io.report.max_torque_nm.max(t);
                if t > io.protocol.torque.limit_nm(finger, joint) {
                    io.report.torque_clips += 1;
                }
            }
        }
        let Ok(frames) = io.protocol.encode_torques(&tau) else {
            // Finite positions and targets give finite torques; should they not, no frame
            // goes out and the hand keeps the last torques until the halt.
            if target_run.record(true, config.persist_limit) {
                break (StopReason::PolicyFailure, "the PD law gave a non-finite torque".to_owned());
            }
            continue;
        };
        let mut all_sent = true;
        for frame in &frames {
            all_sent &= io.send(frame)?;
        }
        let response = read_at.elapsed();
        responses.push(response);
        if response > PERIOD / 2 {
            io.report.late_torque_sets += 1;
        }
        if tx_run.record(!all_sent, config.persist_limit) {
            break (
                StopReason::TxFailure,
                format!("torque frames could not be sent for {} sets in a row", config.persist_limit + 1),
            );
        }
        io.report.cycles += 1;
        if config.max_cycles.is_some_and(|n| io.report.cycles >= n) {
            break (StopReason::StepsReached, String::new());
        }
    };

    if let Some(first) = first_set_at {
        let span = last_set_at.duration_since(first).as_secs_f64();
        if span > 0.0 {
            io.report.achieved_rate_hz = intervals.len() as f64 / span;
        }
    }
    let mut jitter: Vec<Duration> = intervals.iter().map(|i| i.abs_diff(PERIOD)).collect();
    io.report.period_jitter = Percentiles::of(&mut jitter);
    io.report.response = Percentiles::of(&mut responses);
    io.report.safety = filter.counts;
    io.report.final_targets_rad = targets;
    Ok(outcome)
}
