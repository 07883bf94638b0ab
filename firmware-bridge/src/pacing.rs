//! What a loop that runs a policy at a fixed rate does whatever it drives (a hand over CAN,
//! [`crate::control_loop`], or the simulator's env in process, [`crate::sim_policy`]): keep
//! absolute deadlines, skip the periods already gone, end on the stop flag, the duration or
//! the step count, and run the policy with a guard that holds on a failure and halts once
//! failures persist.
//!
//! Deadlines are `start + k * period`. A loop that wakes a whole period late skips the
//! periods already gone (each a deadline miss) instead of running them back to back, so the
//! achieved rate and the misses tell the truth.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::control_loop::StopReason;
use crate::policy_runner::PolicyRunner;
use crate::stats::Percentiles;

/// The slowest loop accepted: one step in 1000 s. Its period and watchdog (up to `u32::MAX`
/// periods) then fit a [`Duration`], which panics on larger values.
pub const MIN_RATE_HZ: f64 = 1e-3;

/// Whether `rate_hz` is a rate a loop can keep: finite and at least [`MIN_RATE_HZ`].
#[must_use]
pub fn valid_rate(rate_hz: f64) -> bool {
    rate_hz.is_finite() && rate_hz >= MIN_RATE_HZ
}

/// When a run ends of itself: at the stop flag, after a duration, after a number of steps.
#[derive(Debug, Clone, Copy)]
pub struct RunLimits<'a> {
    pub stop: &'a AtomicBool,
    pub duration: Option<Duration>,
    pub max_steps: Option<u64>,
}

/// One period's wake-up: when the loop woke and the deadline it woke for.
#[derive(Debug, Clone, Copy)]
pub struct Tick {
    pub woke: Instant,
    pub deadline: Instant,
}

/// A fixed-rate loop's clock and its timing figures.
#[derive(Debug)]
pub struct Pacer {
    start: Instant,
    period: Duration,
    /// Spin this long before each deadline instead of sleeping (the OS timer alone overshoots
    /// by 50-100 us, too coarse for a 1 kHz loop).
    spin: Duration,
    period_index: u64,
    /// Steps the loop completed ([`Self::step_done`]).
    pub steps: u64,
    /// Periods whose step did not finish before the next deadline, skipped ones included.
    pub deadline_misses: u64,
    /// Periods skipped because the loop woke after they had passed.
    pub skipped_periods: u64,
    wake_jitter: Vec<Duration>,
    loop_times: Vec<Duration>,
}

/// What a paced run measured of itself.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaceFigures {
    /// Steps done, on time or late (skipped periods are not steps).
    pub steps: u64,
    pub achieved_rate_hz: f64,
    /// How late the loop woke after each deadline.
    pub wake_jitter: Percentiles,
    /// Time from waking to the step done.
    pub loop_time: Percentiles,
    /// Periods whose step did not finish before the next deadline, skipped ones included.
    pub deadline_misses: u64,
    /// Periods skipped because the loop woke after they had passed.
    pub skipped_periods: u64,
}

impl Pacer {
    /// A clock of `rate_hz` (checked by the caller with [`valid_rate`]) starting now.
    #[must_use]
    pub fn start(rate_hz: f64, spin: Duration) -> Self {
        Self {
            start: Instant::now(),
            period: Duration::from_secs_f64(1.0 / rate_hz),
            spin,
            period_index: 0,
            steps: 0,
            deadline_misses: 0,
            skipped_periods: 0,
            wake_jitter: Vec::new(),
            loop_times: Vec::new(),
        }
    }

    /// Waits for the next deadline; a loop that woke periods late skips them.
    pub fn wait(&mut self) -> Tick {
        let mut deadline = self.start + self.period.mul_f64(self.period_index as f64);
        let now = Instant::now();
        if deadline > now + self.spin {
            std::thread::sleep(deadline - now - self.spin);
        }
        while Instant::now() < deadline {
            std::hint::spin_loop();
        }
        let woke = Instant::now();
        let behind =
            (woke.saturating_duration_since(deadline).as_secs_f64() / self.period.as_secs_f64()) as u64;
        if behind > 0 {
            self.period_index += behind;
            self.skipped_periods += behind;
            self.deadline_misses += behind;
            deadline = self.start + self.period.mul_f64(self.period_index as f64);
        }
        self.wake_jitter.push(woke.saturating_duration_since(deadline));
        Tick { woke, deadline }
    }

    /// Why the run ends at `tick`, if it does: the stop flag, the duration, the steps.
    #[must_use]
    pub fn ends(&self, tick: &Tick, limits: &RunLimits<'_>) -> Option<StopReason> {
        if limits.stop.load(Ordering::Relaxed) {
            return Some(StopReason::StopRequested);
        }
        if limits.duration.is_some_and(|d| tick.woke.saturating_duration_since(self.start) >= d) {
            return Some(StopReason::DurationReached);
        }
        if limits.max_steps.is_some_and(|n| self.steps >= n) {
            return Some(StopReason::StepsReached);
        }
        None
    }

    /// The step of `tick` is done: its time and whether it missed the next deadline.
    pub fn step_done(&mut self, tick: &Tick) {
        self.steps += 1;
        let done = Instant::now();
        self.loop_times.push(done - tick.woke);
        if done > tick.deadline + self.period {
            self.deadline_misses += 1;
        }
        self.period_index += 1;
    }

    /// The loop's period.
    #[must_use]
    pub fn period(&self) -> Duration {
        self.period
    }

    /// The figures of the run so far.
    pub fn figures(&mut self) -> PaceFigures {
        let elapsed = self.start.elapsed();
        PaceFigures {
            steps: self.steps,
            achieved_rate_hz: if elapsed.is_zero() { 0.0 } else { self.steps as f64 / elapsed.as_secs_f64() },
            wake_jitter: Percentiles::of(&mut self.wake_jitter),
            loop_time: Percentiles::of(&mut self.loop_times),
            deadline_misses: self.deadline_misses,
            skipped_periods: self.skipped_periods,
        }
    }
}

/// A problem that halts a loop once it has lasted more than `limit` times in a row.
#[derive(Debug, Default)]
pub struct Persisting {
    pub run: u32,
}

impl Persisting {
    /// Records one time with (`true`) or without the problem; whether it now halts.
    pub fn record(&mut self, present: bool, limit: u32) -> bool {
        self.run = if present { self.run + 1 } else { 0 };
        self.run > limit
    }
}

/// A policy run once a step: an error or a non-finite action is a failure, the action is
/// then all NaN (the safety filter holds the last safe targets on it), and failures for more
/// than `limit` steps in a row halt the loop.
#[derive(Debug)]
pub struct GuardedPolicy {
    limit: u32,
    failing: Persisting,
    /// Steps whose policy failed.
    pub errors: u64,
}

impl GuardedPolicy {
    /// Halts after `limit` failing steps in a row (at least 1).
    #[must_use]
    pub fn new(limit: u32) -> Self {
        Self { limit: limit.max(1), failing: Persisting::default(), errors: 0 }
    }

    /// Runs `policy` on `obs` into `action`: `Ok(true)` when it failed this step (the action
    /// is NaN), `Ok(false)` when it acted, `Err(detail)` when failures have persisted past the
    /// limit (`unit` names the steps in the detail: "periods", "steps").
    pub fn act<P: PolicyRunner>(
        &mut self,
        policy: &mut P,
        obs: &[f32],
        action: &mut [f32],
        unit: &str,
    ) -> Result<bool, String> {
        let acted = policy.act(obs, action);
        let failed = acted.is_err() || !action.iter().all(|v| v.is_finite());
        if failed {
            self.errors += 1;
        }
        if self.failing.record(failed, self.limit) {
            let limit = self.limit;
            return Err(match acted {
                Err(e) => format!("the policy failed for {limit} {unit}: {e}"),
                Ok(()) => format!("the policy's action was not finite for {limit} {unit}"),
            });
        }
        if failed {
            action.fill(f32::NAN);
        }
        Ok(failed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_problem_halts_only_once_it_outlasts_the_limit() {
        let mut p = Persisting::default();
        assert!(!p.record(true, 2) && !p.record(true, 2));
        assert!(!p.record(false, 2), "a good period resets the count");
        assert!(!p.record(true, 2) && !p.record(true, 2) && p.record(true, 2));
    }

    /// Fails on the steps it is told to, else acts with 1.0.
    struct Failing(Vec<bool>);

    impl PolicyRunner for Failing {
        type Error = std::fmt::Error;
        fn act(&mut self, _: &[f32], action: &mut [f32]) -> Result<(), std::fmt::Error> {
            action.fill(1.0);
            if self.0.remove(0) { Err(std::fmt::Error) } else { Ok(()) }
        }
    }

    #[test]
    fn a_failing_policy_gives_nan_and_halts_once_it_fails_past_the_limit() {
        let mut guard = GuardedPolicy::new(2);
        let mut policy = Failing(vec![false, true, true, false, true, true, true]);
        let mut action = [0.0f32; 2];
        let mut outcomes = Vec::new();
        for _ in 0..7 {
            outcomes
                .push(guard.act(&mut policy, &[], &mut action, "steps").map(|failed| (failed, action[0])));
        }
        let nan = |o: &Result<(bool, f32), String>| matches!(o, Ok((true, a)) if a.is_nan());
        assert_eq!(outcomes[0], Ok((false, 1.0)));
        assert!(nan(&outcomes[1]) && nan(&outcomes[2]), "{outcomes:?}");
        assert_eq!(outcomes[3], Ok((false, 1.0)), "a good step resets the count");
        assert!(nan(&outcomes[4]) && nan(&outcomes[5]));
        let halt = outcomes[6].clone().expect_err("three failures in a row halt at a limit of 2");
        assert!(halt.contains("failed for 2 steps"), "{halt}");
        assert_eq!(guard.errors, 5);
    }

    #[test]
    fn the_run_ends_at_the_stop_flag_the_duration_or_the_steps() {
        let stop = AtomicBool::new(false);
        let mut pacer = Pacer::start(1000.0, Duration::ZERO);
        let tick = pacer.wait();
        let limits = RunLimits { stop: &stop, duration: None, max_steps: Some(1) };
        assert_eq!(pacer.ends(&tick, &limits), None);
        pacer.step_done(&tick);
        let tick = pacer.wait();
        assert_eq!(pacer.ends(&tick, &limits), Some(StopReason::StepsReached));
        let timed = RunLimits { stop: &stop, duration: Some(Duration::ZERO), max_steps: None };
        assert_eq!(pacer.ends(&tick, &timed), Some(StopReason::DurationReached));
        stop.store(true, Ordering::Relaxed);
        assert_eq!(pacer.ends(&tick, &timed), Some(StopReason::StopRequested));
        assert_eq!(pacer.figures().steps, 1);
    }
}
