//! The bridge's control loop: at a fixed rate with absolute deadlines, read the hand's state,
//! build the observation exactly as the simulator does (`vge_sim::observation`, the set the
//! policy was trained with), run the policy, pass its action through the safety filter and
//! send joint commands. Every size (nodes, joints, observation) is the hand's
//! ([`ProtocolHand`]).
//!
//! Deadlines, the end of a run and the policy's guard are [`crate::pacing`]'s, shared with
//! the simulator's in-process loop ([`crate::sim_policy`]). Each wait sleeps until `spin`
//! before the deadline and then spins.
//!
//! What the loop does not trust, and what it does then (docs/can-protocol.md, Semantics):
//! - no fresh joint state for `watchdog_periods`: halt (watchdog);
//! - a node fault (fault frame, status bit, heartbeat state): halt;
//! - a node that restarted (boot-up heartbeat, counter started again, enable state
//!   forgotten): halt, since a rebooted joint controller has lost what the host set up;
//! - a node heartbeat missing for `heartbeat_timeout`, or its counter stuck: halt;
//! - a stale frame (seq lagging the last command) or an implausible joint position: the
//!   frame is dropped and counted, the step holds the last safe targets, and the loop halts
//!   if that persists for `watchdog_periods`;
//! - a policy that errs (non-finite output, overflow inside the network): hold, halt if it
//!   persists;
//! - more than `rx_budget` frames in one period (a flood): the rest waits for the next
//!   period, and the loop halts if that persists;
//! - a SocketCAN bus-off error frame: halt; other error frames are counted by class;
//! - a full transmit queue (ENOBUFS): the frame is retried once, then dropped and counted;
//!   the loop halts if commands cannot be sent for `watchdog_periods`.
//!
//! Halting holds the last safe targets for `halt_hold_periods` (the grasp does not drop),
//! then disables every finger.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use thiserror::Error;
use vge_sim::action::DEFAULT_MAX_ACTION_RAD;
use vge_sim::observation::ObservationSet;

use crate::hand_state::{Applied, HandState, HeartbeatProblem, Plausibility};
use crate::heartbeat::HeartbeatClock;
pub use crate::pacing::MIN_RATE_HZ;
use crate::pacing::{GuardedPolicy, PaceFigures, Pacer, Persisting, RunLimits};
use crate::policy_runner::Observer;
pub use crate::policy_runner::PolicyRunner;
use crate::protocol::{
    HEARTBEAT_PERIOD_MS, HOST_NODE, Heartbeat, JOINTS_PER_NODE, JointCommand, Message, NodeLayout, NodeState,
};
use crate::protocol_hand::ProtocolHand;
use crate::safety::{SafetyCounts, SafetyFilter};
use crate::transport::{ErrorClass, Received, Transport, TransportError};

#[derive(Debug, Clone)]
pub struct LoopConfig {
    pub rate_hz: f64,
    /// Stop after this long; `None` runs until the stop flag is raised.
    pub duration: Option<Duration>,
    /// Stop after this many steps (command sets sent), if given.
    pub max_steps: Option<u64>,
    /// No fresh joint state for more than this many periods trips the watchdog; any other
    /// problem that persists this many periods halts the loop.
    pub watchdog_periods: u32,
    /// How long to wait for every node's first joint state and heartbeat.
    pub startup_timeout: Duration,
    /// Periods the halt sequence holds the last safe targets before disabling.
    pub halt_hold_periods: u32,
    /// Largest joint-target change per step (rad), enforced whatever the policy says.
    pub max_delta_rad: f32,
    /// The hand: its nodes, names and the joint limits targets are clamped to.
    pub hand: ProtocolHand,
    /// The observation the policy is fed (the set it was trained with).
    pub observation: ObservationSet,
    /// Spin this long before each deadline instead of sleeping.
    pub spin: Duration,
    /// A node heartbeat older than this is a lost node.
    pub heartbeat_timeout: Duration,
    /// How far outside its range a measured joint may read before it is implausible.
    pub plausibility_margin_rad: f32,
    /// Largest accepted lag of a node frame's seq behind the last command.
    pub max_seq_lag: u8,
    /// Frames taken from the bus per period at most.
    pub rx_budget: usize,
}

/// Commands a node frame may lag behind the last one sent and still be the finger's state
/// (0.15 s at 20 Hz): an older frame is stale.
pub const DEFAULT_MAX_SEQ_LAG: u8 = 3;

impl LoopConfig {
    /// The defaults the `vge-bridge` command line uses, at `rate_hz` on `hand`, with the full
    /// observation.
    pub fn new(rate_hz: f64, hand: ProtocolHand) -> Self {
        Self {
            rate_hz,
            duration: None,
            max_steps: None,
            watchdog_periods: 5,
            startup_timeout: Duration::from_secs(5),
            halt_hold_periods: 3,
            max_delta_rad: DEFAULT_MAX_ACTION_RAD,
            hand,
            observation: ObservationSet::Full,
            spin: Duration::from_micros(200),
            // Five heartbeat periods: one late beat on a loaded host is not a lost node.
            heartbeat_timeout: Duration::from_millis(5 * u64::from(HEARTBEAT_PERIOD_MS)),
            plausibility_margin_rad: 0.1,
            max_seq_lag: DEFAULT_MAX_SEQ_LAG,
            // Ten times a period's traffic (25 frames + heartbeats) at any rate.
            rx_budget: 256,
        }
    }
}

/// A heartbeat counter that repeats this many times in a row is a stuck node.
pub const HEARTBEAT_MAX_REPEATS: u32 = 3;

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    DurationReached,
    /// The configured number of steps was sent.
    StepsReached,
    StopRequested,
    /// No fresh joint state for longer than the watchdog allows.
    Watchdog,
    /// A node reported a fault.
    NodeFault,
    /// A node restarted mid-run (its heartbeats said so).
    NodeRestarted,
    /// A node's heartbeat stopped or its counter stuck.
    HeartbeatLost,
    /// Stale or implausible joint state persisted.
    ImplausibleState,
    /// The policy failed (error or non-finite output) for too many periods in a row.
    PolicyFailure,
    /// The CAN controller reported bus-off.
    BusOff,
    /// More frames than the receive budget arrived, period after period.
    BusOverload,
    /// Commands could not be sent (transmit queue full) for too many periods.
    TxFailure,
}

impl StopReason {
    /// The name used in JSON summaries.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::DurationReached => "duration",
            Self::StepsReached => "steps",
            Self::StopRequested => "stop_requested",
            Self::Watchdog => "watchdog",
            Self::NodeFault => "node_fault",
            Self::NodeRestarted => "node_restarted",
            Self::HeartbeatLost => "heartbeat_lost",
            Self::ImplausibleState => "implausible_state",
            Self::PolicyFailure => "policy_failure",
            Self::BusOff => "bus_off",
            Self::BusOverload => "bus_overload",
            Self::TxFailure => "tx_failure",
        }
    }

    /// Every stop reason, in the order of their exit statuses.
    pub const ALL: [Self; 12] = [
        Self::DurationReached,
        Self::StepsReached,
        Self::StopRequested,
        Self::Watchdog,
        Self::NodeFault,
        Self::HeartbeatLost,
        Self::NodeRestarted,
        Self::ImplausibleState,
        Self::PolicyFailure,
        Self::BusOff,
        Self::BusOverload,
        Self::TxFailure,
    ];

    /// Whether the loop halted for safety (anything but the duration or a stop request).
    pub fn is_safety_halt(self) -> bool {
        !matches!(self, Self::DurationReached | Self::StepsReached | Self::StopRequested)
    }

    /// The exit status of `vge-bridge run` that ends this way: 0 for a normal end, one status
    /// per safety halt from 10 up, so a supervisor tells them apart without parsing output
    /// (1 and 2 stay with errors and usage; docs/can-protocol.md lists them).
    pub fn exit_code(self) -> u8 {
        match self {
            Self::DurationReached | Self::StepsReached | Self::StopRequested => 0,
            Self::Watchdog => 10,
            Self::NodeFault => 11,
            Self::HeartbeatLost => 12,
            Self::NodeRestarted => 13,
            Self::ImplausibleState => 14,
            Self::PolicyFailure => 15,
            Self::BusOff => 16,
            Self::BusOverload => 17,
            Self::TxFailure => 18,
        }
    }
}

/// SocketCAN error frames received, by class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ErrorFrameCounts {
    pub bus_off: u64,
    /// Controller problems (error-warning, error-passive, overflows).
    pub controller: u64,
    pub protocol: u64,
    pub no_ack: u64,
    /// Every other class (arbitration lost, transceiver, bus error, restarted, tx timeout).
    pub other: u64,
}

impl ErrorFrameCounts {
    pub(crate) fn count(&mut self, class: u32) {
        if class & ErrorClass::BUS_OFF != 0 {
            self.bus_off += 1;
        } else if class & ErrorClass::CONTROLLER != 0 {
            self.controller += 1;
        } else if class & ErrorClass::PROTOCOL != 0 {
            self.protocol += 1;
        } else if class & ErrorClass::NO_ACK != 0 {
            self.no_ack += 1;
        } else {
            self.other += 1;
        }
    }

    pub fn total(&self) -> u64 {
        self.bus_off + self.controller + self.protocol + self.no_ack + self.other
    }
}

/// What crossed the link, and what of it was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkCounts {
    /// Frames on the wire (with CAN FD one frame carries several messages).
    pub frames_in: u64,
    pub frames_out: u64,
    /// Protocol messages decoded and sent.
    pub messages_in: u64,
    pub messages_out: u64,
    /// Frames with a protocol id but a wrong length or payload, extended or remote frames,
    /// frames from a node id the hand does not have: counted, ignored. (Ids outside the protocol are dropped by the socket's filter.)
    pub bad_frames: u64,
    /// Node frames whose seq lagged the last command by more than `max_seq_lag`: dropped.
    pub stale_frames: u64,
    /// Joint positions outside their range plus the margin: dropped.
    pub implausible_frames: u64,
    /// Periods in which a finger sent no fresh joint position, summed over fingers.
    pub lost_frames: u64,
    pub error_frames: ErrorFrameCounts,
    /// Frames not sent because the transmit queue stayed full.
    pub tx_dropped: u64,
    /// Periods whose receive budget ran out.
    pub overload_periods: u64,
    pub heartbeats_out: u64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct LoopReport {
    pub stop_reason: StopReason,
    /// What exactly stopped the loop (which node, which error), empty for a normal end.
    pub stop_detail: String,
    /// The loop's pace: its steps (command sets sent, on time or late), the rate they
    /// achieved, wake jitter and loop time (waking to commands sent), deadline misses.
    pub pace: PaceFigures,
    pub link: LinkCounts,
    /// Steps that held the last safe targets instead of running the policy's action.
    pub holds: u64,
    pub policy_errors: u64,
    pub safety: SafetyCounts,
    /// Last targets sent while enabled.
    pub final_targets_rad: Vec<f32>,
}

impl LoopReport {
    /// The report of a run that ended for `stop_reason`: its pace, what crossed the link, the
    /// steps that held and failed, and the safety filter's counts and last targets.
    #[must_use]
    pub fn new(
        stop_reason: StopReason,
        stop_detail: String,
        pace: PaceFigures,
        link: LinkCounts,
        holds: u64,
        policy_errors: u64,
        safety: &SafetyFilter,
    ) -> Self {
        Self {
            stop_reason,
            stop_detail,
            pace,
            link,
            holds,
            policy_errors,
            safety: safety.counts,
            final_targets_rad: safety.last_safe_rad().to_vec(),
        }
    }
}

#[derive(Debug, Error)]
pub enum LoopError {
    #[error("transport: {0}")]
    Transport(#[from] TransportError),
    #[error("no {missing} within {timeout:?} of start (is the hand powered and on the bus?)")]
    StartupTimeout { timeout: Duration, missing: String },
    #[error("rate must be a finite number of Hz, at least {MIN_RATE_HZ}, got {0}")]
    BadRate(f64),
    #[error("inconsistent hand: {0}")]
    BadHand(String),
}

struct Io<'t, T: Transport> {
    transport: &'t mut T,
    nodes: NodeLayout,
    state: HandState,
    check: Plausibility,
    counts: LinkCounts,
    /// Seq of the last command set sent; `None` before the first.
    seq: Option<u8>,
    heartbeats: HeartbeatClock,
}

impl<T: Transport> Io<'_, T> {
    /// Takes in what is queued, at most `budget` frames; returns whether frames were left.
    fn drain(&mut self, budget: usize) -> Result<bool, TransportError> {
        for _ in 0..budget {
            let Some(received) = self.transport.recv(Duration::ZERO)? else { return Ok(false) };
            let now = Instant::now();
            match received {
                Received::Frame(f) => match Message::decode_frame(&f) {
                    Ok(m) => {
                        self.counts.messages_in += 1;
                        match self.state.apply(&m, now, &self.check, self.seq) {
                            Applied::Stale => self.counts.stale_frames += 1,
                            Applied::Implausible => self.counts.implausible_frames += 1,
                            // A node id the hand does not have: not its frame.
                            Applied::OtherNode => self.counts.bad_frames += 1,
                            Applied::Kept | Applied::Ignored => {}
                        }
                    }
                    Err(_) => self.counts.bad_frames += 1,
                },
                Received::Malformed { .. } => self.counts.bad_frames += 1,
                Received::Error { class } => self.counts.error_frames.count(class),
            }
        }
        Ok(true)
    }

    /// Sends `message`, retrying once on a full transmit queue; a frame that still cannot go
    /// is dropped and counted (`false`).
    fn send(&mut self, message: &Message) -> Result<bool, TransportError> {
        // Values come from the safety filter (within joint limits) or are constants, so
        // encoding cannot fail; if it ever did, sending nothing lets the node time out safely.
        let Ok(frame) = message.encode() else { return Ok(false) };
        for attempt in 0..2 {
            match self.transport.send(&frame) {
                Ok(()) => {
                    self.counts.messages_out += 1;
                    return Ok(true);
                }
                Err(TransportError::TxQueueFull { .. }) if attempt == 0 => {
                    std::thread::sleep(Duration::from_micros(100));
                }
                Err(TransportError::TxQueueFull { .. }) => break,
                Err(e) => return Err(e),
            }
        }
        self.counts.tx_dropped += 1;
        Ok(false)
    }

    /// One command set with a new seq; whether every frame went out.
    fn send_targets(&mut self, targets: &[f32], enable: bool) -> Result<bool, TransportError> {
        let seq = self.seq.map_or(1, |s| s.wrapping_add(1));
        self.seq = Some(seq);
        let mut all_sent = true;
        for finger in self.nodes.fingers() {
            let i = finger.slot() * JOINTS_PER_NODE;
            // The filter's targets are the hand's joints, three a node; a short slice (never
            // the filter's) sends nothing rather than another joint's target.
            let Some(q) = targets.get(i..i + JOINTS_PER_NODE).and_then(|t| <[f32; 3]>::try_from(t).ok())
            else {
                all_sent = false;
                continue;
            };
            all_sent &=
                self.send(&Message::JointCommand(JointCommand { finger, q_target_rad: q, enable, seq }))?;
        }
        Ok(all_sent)
    }

    /// The host's heartbeat, when one is due.
    fn heartbeat(&mut self, now: Instant, state: NodeState) -> Result<(), TransportError> {
        let Some(counter) = self.heartbeats.tick(now) else { return Ok(()) };
        let beat = Heartbeat { node: HOST_NODE, state, counter };
        if self.send(&Message::Heartbeat(beat))? {
            self.counts.heartbeats_out += 1;
        }
        Ok(())
    }
}

/// Startup: disabled commands ask every node for its state until all have answered with
/// positions, targets and a heartbeat. Returns the targets to start from: those the nodes
/// hold (they keep the current grasp), or, for a node that never reports targets, its
/// measured positions after a few more query rounds.
fn start_up<T: Transport>(
    io: &mut Io<'_, T>,
    config: &LoopConfig,
    stop: &AtomicBool,
) -> Result<Vec<f32>, LoopError> {
    let period = Duration::from_secs_f64(1.0 / config.rate_hz);
    let started = Instant::now();
    let mut rounds_with_positions = 0;
    loop {
        io.drain(config.rx_budget)?;
        let heartbeats =
            io.state.heartbeat_problem(Instant::now(), config.heartbeat_timeout, HEARTBEAT_MAX_REPEATS);
        let start = match (io.state.q_rad(), io.state.q_target_rad(), heartbeats) {
            (Some(_), Some(targets), None) => Some(targets),
            (Some(q), None, None) if rounds_with_positions >= 3 => Some(q),
            (Some(_), None, _) => {
                rounds_with_positions += 1;
                None
            }
            _ => None,
        };
        if let Some(start) = start {
            // Restarts before the nodes answered are part of the state taken over.
            io.state.clear_restarts();
            return Ok(start);
        }
        if started.elapsed() > config.startup_timeout || stop.load(Ordering::Relaxed) {
            let missing = match (io.state.q_rad(), heartbeats) {
                (None, _) => "joint state from every finger".to_owned(),
                (
                    Some(_),
                    Some(HeartbeatProblem::Missing { finger } | HeartbeatProblem::Stuck { finger, .. }),
                ) => {
                    format!("heartbeat from {}", config.hand.node_label(finger))
                }
                (Some(_), None) => "joint targets".to_owned(),
            };
            return Err(LoopError::StartupTimeout { timeout: config.startup_timeout, missing });
        }
        io.heartbeat(Instant::now(), NodeState::Ready)?;
        io.send_targets(&vec![0.0; config.hand.num_joints()], false)?;
        std::thread::sleep(period.min(Duration::from_millis(10)));
    }
}

/// Why the hand's state cannot be trusted this period, if it cannot: the halting reason and
/// its detail.
fn distrust<T: Transport>(io: &Io<'_, T>, config: &LoopConfig, now: Instant) -> Option<(StopReason, String)> {
    if io.counts.error_frames.bus_off > 0 {
        return Some((StopReason::BusOff, "the CAN controller reported bus-off".to_owned()));
    }
    if let Some((f, sign)) = io.state.restart() {
        let detail = format!("{} restarted: {sign}", config.hand.node_label(f));
        return Some((StopReason::NodeRestarted, detail));
    }
    if let Some(f) = io.state.fault.iter().position(|&f| f) {
        return Some((StopReason::NodeFault, format!("{} reported a fault", config.hand.node_label(f))));
    }
    match io.state.heartbeat_problem(now, config.heartbeat_timeout, HEARTBEAT_MAX_REPEATS) {
        Some(HeartbeatProblem::Missing { finger }) => {
            let detail = format!(
                "no heartbeat from {} for {:?}",
                config.hand.node_label(finger),
                config.heartbeat_timeout
            );
            return Some((StopReason::HeartbeatLost, detail));
        }
        Some(HeartbeatProblem::Stuck { finger, counter }) => {
            let detail =
                format!("heartbeat counter of {} stuck at {counter}", config.hand.node_label(finger));
            return Some((StopReason::HeartbeatLost, detail));
        }
        None => {}
    }
    let watchdog = Duration::from_secs_f64(f64::from(config.watchdog_periods.max(1)) / config.rate_hz);
    if io.state.oldest_position_age(now).is_none_or(|age| age > watchdog) {
        return Some((StopReason::Watchdog, format!("no fresh joint state for {watchdog:?}")));
    }
    None
}

/// Runs the loop until the duration, the stop flag or a problem it does not trust ends it,
/// then runs the halt sequence (hold, then disable).
pub fn run<T: Transport, P: PolicyRunner>(
    transport: &mut T,
    policy: &mut P,
    config: &LoopConfig,
    stop: &AtomicBool,
) -> Result<LoopReport, LoopError> {
    if !crate::pacing::valid_rate(config.rate_hz) {
        return Err(LoopError::BadRate(config.rate_hz));
    }
    let hand = &config.hand;
    if hand.limits.len() != hand.num_joints() || hand.finger_names.len() != hand.num_fingers() {
        return Err(LoopError::BadHand(format!(
            "{} joint limits and {} finger names for {} nodes of {JOINTS_PER_NODE} joints",
            hand.limits.len(),
            hand.finger_names.len(),
            hand.num_fingers()
        )));
    }
    let check = Plausibility {
        limits: hand.limits.clone(),
        margin_rad: config.plausibility_margin_rad,
        max_seq_lag: config.max_seq_lag,
    };
    let mut io = Io {
        transport,
        nodes: hand.nodes,
        state: HandState::new(hand.nodes),
        check,
        counts: LinkCounts::default(),
        seq: None,
        heartbeats: HeartbeatClock::new(Instant::now()),
    };
    let q_start = start_up(&mut io, config, stop)?;
    let mut safety = SafetyFilter::new(config.max_delta_rad, hand.limits.clone(), &q_start);
    let mut observer = Observer::new(config.observation);
    let mut action = vec![0.0; hand.num_joints()];
    let limit = config.watchdog_periods.max(1);

    let mut holds = 0;
    let mut guard = GuardedPolicy::new(limit);
    let (mut suspect, mut overload, mut unsent) =
        (Persisting::default(), Persisting::default(), Persisting::default());
    let mut last_positions = io.state.position_times();
    let limits = RunLimits { stop, duration: config.duration, max_steps: config.max_steps };
    let mut pacer = Pacer::start(config.rate_hz, config.spin);
    let (stop_reason, stop_detail) = loop {
        let tick = pacer.wait();
        let woke = tick.woke;
        if let Some(end) = pacer.ends(&tick, &limits) {
            break (end, String::new());
        }
        let flooded = io.drain(config.rx_budget)?;
        if flooded {
            io.counts.overload_periods += 1;
        }
        if overload.record(flooded, limit) {
            break (StopReason::BusOverload, format!("more than {} frames per period", config.rx_budget));
        }
        // Stale or implausible frames this period: hold rather than act on a state the
        // policy never saw in training. Checked before the watchdog, which the dropped frames
        // trip too, so that the stop names the cause.
        let suspects = io.state.take_suspects();
        let hold = suspects.iter().any(|&s| s);
        if suspect.record(hold, limit) {
            let f = suspects.iter().position(|&s| s).unwrap_or(0);
            let detail =
                format!("{} sent stale or implausible state for {limit} periods", hand.node_label(f));
            break (StopReason::ImplausibleState, detail);
        }
        if let Some((reason, detail)) = distrust(&io, config, woke) {
            // Joint state goes stale when its frames are refused: name the cause.
            if reason == StopReason::Watchdog && suspect.run > 0 {
                let f = suspects.iter().position(|&s| s).unwrap_or(0);
                let why = format!("{} sent stale or implausible state; {detail}", hand.node_label(f));
                break (StopReason::ImplausibleState, why);
            }
            break (reason, detail);
        }
        // From the second step on: the first drains what start-up's queries left queued.
        let positions = io.state.position_times();
        if pacer.steps > 0 {
            io.counts.lost_frames +=
                positions.iter().zip(&last_positions).filter(|(now, before)| now == before).count() as u64;
        }
        last_positions = positions;

        if hold {
            holds += 1;
        } else {
            let q = io.state.q_rad().unwrap_or_else(|| q_start.clone());
            let obs = observer.observe(&q, safety.last_safe_rad(), &io.state.contacts());
            // A failed action goes to the filter as NaN: it holds the last safe targets.
            match guard.act(policy, &obs, &mut action, "periods") {
                Ok(failed) => holds += u64::from(failed),
                Err(detail) => {
                    holds += 1;
                    break (StopReason::PolicyFailure, detail);
                }
            }
            safety.apply_delta(&action);
        }
        io.heartbeat(woke, NodeState::Enabled)?;
        let sent = io.send_targets(safety.last_safe_rad(), true)?;
        if unsent.record(!sent, limit) {
            break (
                StopReason::TxFailure,
                format!("commands could not be sent for {limit} periods (transmit queue full)"),
            );
        }
        pacer.step_done(&tick);
    };
    let pace = pacer.figures();
    let period = pacer.period();
    let final_targets_rad = safety.last_safe_rad().to_vec();

    // Halt: hold the last safe targets (motors on, so the grasp does not drop), then disable.
    // Best effort: a bus that refuses frames now leaves the nodes to their command timeout.
    let halting = if stop_reason.is_safety_halt() { NodeState::Fault } else { NodeState::Ready };
    for _ in 0..config.halt_hold_periods {
        std::thread::sleep(period);
        let _ = io.drain(config.rx_budget);
        let _ = io.heartbeat(Instant::now(), halting);
        let _ = io.send_targets(&final_targets_rad, true);
    }
    let _ = io.send_targets(&final_targets_rad, false);
    let _ = io.drain(config.rx_budget);

    let bus = io.transport.bus_counts();
    io.counts.frames_in = bus.frames_in;
    io.counts.frames_out = bus.frames_out;
    Ok(LoopReport::new(stop_reason, stop_detail, pace, io.counts, holds, guard.errors, &safety))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_safety_halt_exits_with_a_status_of_its_own_and_a_normal_end_with_0() {
        let codes: Vec<u8> = StopReason::ALL.iter().map(|r| r.exit_code()).collect();
        assert_eq!(codes, [0, 0, 0, 10, 11, 12, 13, 14, 15, 16, 17, 18]);
        for r in StopReason::ALL {
            assert_eq!(r.is_safety_halt(), r.exit_code() != 0, "{}", r.as_str());
        }
    }

    #[test]
    fn error_frames_are_counted_by_class() {
        let mut c = ErrorFrameCounts::default();
        for class in [
            ErrorClass::BUS_OFF,
            ErrorClass::CONTROLLER,
            ErrorClass::CONTROLLER | ErrorClass::PROTOCOL,
            ErrorClass::NO_ACK,
            ErrorClass::LOST_ARBITRATION,
        ] {
            c.count(class);
        }
        assert_eq!(c, ErrorFrameCounts { bus_off: 1, controller: 2, protocol: 0, no_ack: 1, other: 1 });
        assert_eq!(c.total(), 5);
    }
}
