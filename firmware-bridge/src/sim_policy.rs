//! A policy against the simulated hand in process, without a CAN protocol between them: what
//! `vge-bridge run --hand allegro --backend sim --policy P` runs (the Allegro's protocol is
//! torque-level at 333 Hz, and the env the policy was trained in sets joint targets; vge15's
//! sim backend goes over its own protocol, [`crate::sim_hand`]).
//!
//! The loop is the control loop's in what it decides: at the policy's rate with absolute
//! deadlines, it builds the observation the policy was trained on from the env's readings
//! (noise included), runs the policy, passes its action through the same [`SafetyFilter`]
//! (largest step, joint ranges, a non-finite action holds), and steps the env with the change
//! of the safe targets. A policy that fails `watchdog_periods` steps in a row halts it
//! (policy_failure). The object's fate is the env's own accounting ([`vge_sim::EpisodeTracker`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use thiserror::Error;
use vge_sim::observation::ObservationSet;
use vge_sim::{Env, SimError};

use crate::control_loop::{LinkCounts, LoopReport, MIN_RATE_HZ, StopReason};
use crate::policy_runner::{Observer, PolicyRunner};
use crate::report::SimHandSummary;
use crate::safety::SafetyFilter;
use crate::stats::Percentiles;

#[derive(Debug, Error)]
pub enum SimPolicyError {
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("rate must be a finite number of Hz, at least {MIN_RATE_HZ}, got {0}")]
    BadRate(f64),
    #[error("the env's observation has no slice {0}")]
    Layout(&'static str),
}

/// Settings of one run.
#[derive(Debug, Clone)]
pub struct SimPolicyConfig {
    /// Control steps per second of wall time.
    pub rate_hz: f64,
    /// Stop after this long; `None` runs until the stop flag or `max_steps`.
    pub duration: Option<Duration>,
    pub max_steps: Option<u64>,
    /// Largest joint-target change per step (rad), enforced whatever the policy says.
    pub max_delta_rad: f32,
    /// A failing policy halts the run after this many steps in a row.
    pub watchdog_periods: u32,
    /// The observation the policy is fed.
    pub observation: ObservationSet,
    /// The env's episode seed.
    pub seed: u64,
}

/// Runs `policy` on `env` (reset with `config.seed`) until the duration, the steps, the stop
/// flag or a failing policy ends it: the loop's report (no bus: its link counts are zero) and
/// the object's summary.
pub fn run<P: PolicyRunner>(
    env: &mut Env,
    policy: &mut P,
    config: &SimPolicyConfig,
    stop: &AtomicBool,
) -> Result<(LoopReport, SimHandSummary), SimPolicyError> {
    if !(config.rate_hz.is_finite() && config.rate_hz >= MIN_RATE_HZ) {
        return Err(SimPolicyError::BadRate(config.rate_hz));
    }
    let layout = env.config().observation_layout();
    let slice = |name: &'static str| layout.range(name).ok_or(SimPolicyError::Layout(name));
    let (q_slice, target_slice) = (slice("q_rad")?, slice("q_target_rad")?);
    let limits = env.config().servos.iter().map(|s| s.limit).collect();
    let num_joints = env.config().hand.num_joints();
    let (mut obs, _) = env.reset(config.seed)?;
    let read = |obs: &[f32], range: &std::ops::Range<usize>| obs.get(range.clone()).map(<[f32]>::to_vec);
    // The targets the grasp left, the filter's first safe ones.
    let start_targets = read(&obs, &target_slice).unwrap_or_default();
    let mut safety = SafetyFilter::new(config.max_delta_rad, limits, &start_targets);
    let mut tracker = env.episode_tracker()?;
    let mut observer = Observer::new(config.observation);
    let mut action = vec![0.0; num_joints];
    let limit = config.watchdog_periods.max(1);
    let period = Duration::from_secs_f64(1.0 / config.rate_hz);
    let (mut wake_jitter, mut loop_times) = (Vec::new(), Vec::new());
    let (mut steps, mut period_index, mut holds, mut policy_errors) = (0u64, 0u64, 0u64, 0u64);
    let (mut deadline_misses, mut skipped_periods, mut failing) = (0u64, 0u64, 0u32);
    let (mut terminated, mut dropped) = (false, false);
    let start = Instant::now();
    let (stop_reason, stop_detail) = loop {
        let mut deadline = start + period.mul_f64(period_index as f64);
        let now = Instant::now();
        if deadline > now {
            std::thread::sleep(deadline - now);
        }
        let woke = Instant::now();
        let behind = (woke.saturating_duration_since(deadline).as_secs_f64() / period.as_secs_f64()) as u64;
        if behind > 0 {
            period_index += behind;
            skipped_periods += behind;
            deadline_misses += behind;
            deadline = start + period.mul_f64(period_index as f64);
        }
        wake_jitter.push(woke.saturating_duration_since(deadline));
        if stop.load(Ordering::Relaxed) {
            break (StopReason::StopRequested, String::new());
        }
        if config.duration.is_some_and(|d| woke.saturating_duration_since(start) >= d) {
            break (StopReason::DurationReached, String::new());
        }
        if config.max_steps.is_some_and(|n| steps >= n) {
            break (StopReason::StepsReached, String::new());
        }
        // The env's observation is the full one, noise included; the proprioceptive one is
        // built from its joint angles and targets as the env's readings.
        let (q, targets) =
            (read(&obs, &q_slice).unwrap_or_default(), read(&obs, &target_slice).unwrap_or_default());
        let observed = match config.observation {
            ObservationSet::Full => obs.clone(),
            ObservationSet::Proprio { .. } => observer.observe(&q, &targets, &[]),
        };
        let acted = policy.act(&observed, &mut action);
        let failed = acted.is_err() || !action.iter().all(|v| v.is_finite());
        failing = if failed { failing + 1 } else { 0 };
        if failed {
            policy_errors += 1;
            holds += 1;
            action.fill(f32::NAN);
        }
        if failing > limit {
            let detail = match acted {
                Err(e) => format!("the policy failed for {limit} steps: {e}"),
                Ok(()) => format!("the policy's action was not finite for {limit} steps"),
            };
            break (StopReason::PolicyFailure, detail);
        }
        // The env moves its targets by the change from the ones it holds to the safe ones.
        let change: Vec<f32> = safety.apply_delta(&action).iter().zip(&targets).map(|(t, b)| t - b).collect();
        let result = env.step(&change)?;
        tracker.record(result.reward, result.info.object_rotation_z_rad, &result.info.tip_contacts);
        terminated |= result.terminated;
        dropped |= result.info.dropped;
        obs = result.obs;
        steps += 1;
        let done = Instant::now();
        loop_times.push(done - woke);
        if done > deadline + period {
            deadline_misses += 1;
        }
        period_index += 1;
    };
    let elapsed = start.elapsed();
    let outcome = tracker.outcome(terminated);
    let summary = SimHandSummary {
        steps: outcome.length as u64,
        rotation_rad: outcome.rotation_rad as f32,
        total_reward: outcome.episode_return as f32,
        terminated: outcome.terminated,
        dropped,
        mean_tip_contacts: outcome.mean_contacts as f32,
        contact_switches: outcome.contact_switches,
    };
    let report = LoopReport {
        stop_reason,
        stop_detail,
        steps,
        achieved_rate_hz: if elapsed.is_zero() { 0.0 } else { steps as f64 / elapsed.as_secs_f64() },
        wake_jitter: Percentiles::of(&mut wake_jitter),
        loop_time: Percentiles::of(&mut loop_times),
        deadline_misses,
        skipped_periods,
        link: LinkCounts::default(),
        holds,
        policy_errors,
        safety: safety.counts,
        final_targets_rad: safety.last_safe_rad().to_vec(),
    };
    Ok((report, summary))
}
