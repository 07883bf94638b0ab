//! The bridge's control loop: at a fixed rate with absolute deadlines, read the hand's state,
//! build the observation exactly as the simulator does (`vge_sim::observation`), run the
//! policy, pass its action through the safety filter and send joint commands.
//!
//! Deadlines are `start + k * period`, so a late step does not delay the ones after it. Each
//! wait sleeps until `spin` before the deadline and then spins: the OS timer alone overshoots
//! by 50-100 us, too coarse for a 1 kHz loop.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use thiserror::Error;
use vge_sim::kinematics::JointLimit;
use vge_sim::observation::{OBS_DIM, build_observation};

use crate::hand_state::HandState;
use crate::protocol::{FingerId, JointCommand, Message};
use crate::safety::{SafetyCounts, SafetyFilter};
use crate::stats::Percentiles;
use crate::transport::{Received, Transport, TransportError};

/// What turns an observation into a change of the joint targets.
pub trait PolicyRunner {
    type Error: std::error::Error + Send + Sync + 'static;
    fn act(&mut self, obs: &[f32; OBS_DIM]) -> Result<[f32; 15], Self::Error>;
}

#[derive(Debug, Clone)]
pub struct LoopConfig {
    pub rate_hz: f64,
    /// Stop after this long; `None` runs until the stop flag is raised.
    pub duration: Option<Duration>,
    /// No fresh joint state for more than this many periods trips the watchdog.
    pub watchdog_periods: u32,
    /// How long to wait for every node's first joint state before giving up.
    pub startup_timeout: Duration,
    /// Periods the halt sequence holds the last safe targets before disabling.
    pub halt_hold_periods: u32,
    /// Largest joint-target change per step (rad), enforced whatever the policy says.
    pub max_delta_rad: f32,
    pub limits: [JointLimit; 15],
    /// Spin this long before each deadline instead of sleeping.
    pub spin: Duration,
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    DurationReached,
    StopRequested,
    /// No fresh joint state for longer than the watchdog allows.
    Watchdog,
    /// A node reported a fault.
    NodeFault,
}

#[derive(Debug, Clone, PartialEq)]
pub struct LoopReport {
    pub stop_reason: StopReason,
    pub steps: u64,
    pub achieved_rate_hz: f64,
    /// How late the loop woke after each deadline.
    pub wake_jitter: Percentiles,
    /// Time from waking to commands sent.
    pub loop_time: Percentiles,
    /// Steps whose work ran past the next deadline.
    pub deadline_misses: u64,
    pub frames_in: u64,
    pub frames_out: u64,
    /// Frames that were not standard 8-byte data frames of the protocol: counted, ignored.
    pub bad_frames: u64,
    pub safety: SafetyCounts,
    /// Last targets sent while enabled.
    pub final_targets_rad: [f32; 15],
}

#[derive(Debug, Error)]
pub enum LoopError {
    #[error("transport: {0}")]
    Transport(#[from] TransportError),
    #[error("no joint state from every finger within {0:?} of start (is the hand powered and on the bus?)")]
    StartupTimeout(Duration),
    #[error("rate must be a positive finite number of Hz, got {0}")]
    BadRate(f64),
}

struct Io<'t, T: Transport> {
    transport: &'t mut T,
    state: HandState,
    frames_in: u64,
    frames_out: u64,
    bad_frames: u64,
    seq: u8,
}

impl<T: Transport> Io<'_, T> {
    fn drain(&mut self) -> Result<(), TransportError> {
        while let Some(received) = self.transport.recv(Duration::ZERO)? {
            self.frames_in += 1;
            let now = Instant::now();
            match received {
                Received::Frame(f) => match Message::decode_frame(&f) {
                    Ok(m) => self.state.apply(&m, now),
                    Err(_) => self.bad_frames += 1,
                },
                Received::Malformed { .. } => self.bad_frames += 1,
            }
        }
        Ok(())
    }

    fn send_targets(&mut self, targets: &[f32; 15], enable: bool) -> Result<(), TransportError> {
        self.seq = self.seq.wrapping_add(1);
        for finger in FingerId::all() {
            let i = usize::from(finger.index()) * 3;
            let q = [targets[i], targets[i + 1], targets[i + 2]];
            let cmd = Message::JointCommand(JointCommand { finger, q_target_rad: q, enable, seq: self.seq });
            // Safe targets are within joint limits (|q| < 3.2 rad), so encoding cannot fail;
            // if it ever did, sending nothing for that finger lets its node time out safely.
            if let Ok(frame) = cmd.encode() {
                self.transport.send(&frame)?;
                self.frames_out += 1;
            }
        }
        Ok(())
    }
}

fn wait_until(deadline: Instant, spin: Duration) {
    let now = Instant::now();
    if deadline > now + spin {
        std::thread::sleep(deadline - now - spin);
    }
    while Instant::now() < deadline {
        std::hint::spin_loop();
    }
}

/// Runs the loop until the duration, the stop flag, the watchdog or a node fault ends it,
/// then runs the halt sequence (hold, then disable).
pub fn run<T: Transport, P: PolicyRunner>(
    transport: &mut T,
    policy: &mut P,
    config: &LoopConfig,
    stop: &AtomicBool,
) -> Result<LoopReport, LoopError> {
    if !(config.rate_hz.is_finite() && config.rate_hz > 0.0) {
        return Err(LoopError::BadRate(config.rate_hz));
    }
    let period = Duration::from_secs_f64(1.0 / config.rate_hz);
    let mut io =
        Io { transport, state: HandState::default(), frames_in: 0, frames_out: 0, bad_frames: 0, seq: 0 };

    // Startup: disabled commands ask every node for its state, until all have answered.
    // Start from the targets the nodes hold (they keep the current grasp). Nodes answer a
    // query with positions then targets; a node that never reports targets gets its
    // measured positions after a few more query rounds.
    let started = Instant::now();
    let mut rounds_with_positions = 0;
    let q_start = loop {
        io.drain()?;
        match (io.state.q_rad(), io.state.q_target_rad()) {
            (Some(_), Some(targets)) => break targets,
            (Some(q), None) if rounds_with_positions >= 3 => break q,
            (Some(_), None) => rounds_with_positions += 1,
            _ => {}
        }
        if started.elapsed() > config.startup_timeout || stop.load(Ordering::Relaxed) {
            return Err(LoopError::StartupTimeout(config.startup_timeout));
        }
        io.send_targets(&[0.0; 15], false)?;
        std::thread::sleep(period.min(Duration::from_millis(10)));
    };
    let mut safety = SafetyFilter::new(config.max_delta_rad, config.limits, q_start);
    let watchdog = period * config.watchdog_periods.max(1);

    let mut wake_jitter = Vec::new();
    let mut loop_times = Vec::new();
    let mut deadline_misses = 0;
    let start = Instant::now();
    let mut step: u64 = 0;
    let stop_reason = loop {
        let deadline = start + period.mul_f64(step as f64);
        wait_until(deadline, config.spin);
        let woke = Instant::now();
        wake_jitter.push(woke.saturating_duration_since(deadline));

        if stop.load(Ordering::Relaxed) {
            break StopReason::StopRequested;
        }
        if config.duration.is_some_and(|d| woke.saturating_duration_since(start) >= d) {
            break StopReason::DurationReached;
        }
        io.drain()?;
        if io.state.any_fault() {
            break StopReason::NodeFault;
        }
        let fresh = io.state.oldest_position_age(woke).is_some_and(|age| age <= watchdog);
        if !fresh {
            break StopReason::Watchdog;
        }
        let q = io.state.q_rad().unwrap_or(q_start);
        let obs = build_observation(&q, &safety.last_safe_rad(), &io.state.contacts());
        // A policy error (e.g. NaN in the observation) holds the last safe targets.
        let delta = policy.act(&obs).unwrap_or([f32::NAN; 15]);
        let targets = safety.apply_delta(&delta);
        io.send_targets(&targets, true)?;

        let done = Instant::now();
        loop_times.push(done - woke);
        if done > deadline + period {
            deadline_misses += 1;
        }
        step += 1;
    };
    let elapsed = start.elapsed();
    let final_targets_rad = safety.last_safe_rad();

    // Halt: hold the last safe targets (motors on, so the grasp does not drop), then disable.
    for _ in 0..config.halt_hold_periods {
        std::thread::sleep(period);
        io.send_targets(&final_targets_rad, true)?;
    }
    io.send_targets(&final_targets_rad, false)?;
    io.drain()?;

    Ok(LoopReport {
        stop_reason,
        steps: step,
        achieved_rate_hz: if elapsed.is_zero() { 0.0 } else { step as f64 / elapsed.as_secs_f64() },
        wake_jitter: Percentiles::of(&mut wake_jitter),
        loop_time: Percentiles::of(&mut loop_times),
        deadline_misses,
        frames_in: io.frames_in,
        frames_out: io.frames_out,
        bad_frames: io.bad_frames,
        safety: safety.counts,
        final_targets_rad,
    })
}
