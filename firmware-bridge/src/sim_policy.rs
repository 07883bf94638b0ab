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
//! (policy_failure). The pace, the end of a run and the policy's guard are the control
//! loop's ([`crate::pacing`]). The object's fate is the env's own accounting ([`vge_sim::EpisodeTracker`]).

use std::sync::atomic::AtomicBool;
use std::time::Duration;

use thiserror::Error;
use vge_sim::observation::ObservationSet;
use vge_sim::{Env, SimError};

use crate::control_loop::{LinkCounts, LoopReport, MIN_RATE_HZ, StopReason};
use crate::pacing::{GuardedPolicy, Pacer, RunLimits};
use crate::policy_runner::{Observer, PolicyRunner};
use crate::report::SimHandSummary;
use crate::safety::SafetyFilter;

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
    if !crate::pacing::valid_rate(config.rate_hz) {
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
    let mut guard = GuardedPolicy::new(config.watchdog_periods);
    let mut holds = 0u64;
    let (mut terminated, mut dropped) = (false, false);
    let limits = RunLimits { stop, duration: config.duration, max_steps: config.max_steps };
    let mut pacer = Pacer::start(config.rate_hz, Duration::ZERO);
    let (stop_reason, stop_detail) = loop {
        let tick = pacer.wait();
        if let Some(end) = pacer.ends(&tick, &limits) {
            break (end, String::new());
        }
        // The env's observation is the full one, noise included; the proprioceptive one is
        // built from its joint angles and targets as the env's readings.
        let (q, targets) =
            (read(&obs, &q_slice).unwrap_or_default(), read(&obs, &target_slice).unwrap_or_default());
        let observed = match config.observation {
            ObservationSet::Full => obs.clone(),
            ObservationSet::Proprio { .. } => observer.observe(&q, &targets, &[]),
        };
        // A failed action goes to the filter as NaN: it holds the last safe targets.
        match guard.act(policy, &observed, &mut action, "steps") {
            Ok(failed) => holds += u64::from(failed),
            Err(detail) => {
                holds += 1;
                break (StopReason::PolicyFailure, detail);
            }
        }
        // The env moves its targets by the change from the ones it holds to the safe ones.
        let change: Vec<f32> = safety.apply_delta(&action).iter().zip(&targets).map(|(t, b)| t - b).collect();
        let result = env.step(&change)?;
        tracker.record(
            result.reward,
            result.info.object_rotation_rad,
            &result.info.tip_contacts,
            result.info.tip_slip_m,
        );
        terminated |= result.terminated;
        dropped |= result.info.dropped;
        obs = result.obs;
        pacer.step_done(&tick);
    };
    let outcome = tracker.outcome(terminated);
    let summary = SimHandSummary::new(&outcome, dropped);
    // No bus: the link counts are zero.
    let pace = pacer.figures();
    let report =
        LoopReport::new(stop_reason, stop_detail, pace, LinkCounts::default(), holds, guard.errors, &safety);
    Ok((report, summary))
}
