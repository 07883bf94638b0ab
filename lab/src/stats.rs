//! Aggregate statistics of groups of runs, as the field reports them (Agarwal et al. 2021,
//! "Deep RL at the Edge of the Statistical Precipice", and its `rliable` library, whose
//! definitions these follow and which `lab/tests/stats_vs_rliable.rs` checks them against):
//!
//! - a group's scores are a matrix of runs x tasks ([`Scores`]); here a task is usually one
//!   (the cube), a score a run's success rate on held-out episodes ([`vge_run::score`]);
//! - the **mean** is the mean over tasks of each task's mean over runs (rliable's
//!   `aggregate_mean`), the **IQM** the interquartile mean of all runs x tasks flattened:
//!   `scipy.stats.trim_mean(x, 0.25)`, which drops `floor(n / 4)` values from each end of the
//!   sorted scores and averages the rest (rliable's `aggregate_iqm`);
//! - **confidence intervals** are stratified bootstrap percentile intervals: each resample
//!   draws, for every task apart, as many runs as the task has, with replacement, from that
//!   task's runs; the interval's bounds are the (1 - c) / 2 and (1 + c) / 2 percentiles of the
//!   statistic over the resamples, interpolated linearly between order statistics as
//!   `numpy.percentile` does (rliable's `get_interval_estimates`, method `percentile`);
//! - the **probability of improvement** of X over Y is the mean over tasks of
//!   P(X > Y) + P(X = Y) / 2 for a run of X and a run of Y drawn at random, counted over all
//!   pairs (the Mann-Whitney U statistic over `runs_x * runs_y`); its interval resamples X and
//!   Y independently, each stratified by task (rliable's `probability_of_improvement` and
//!   `StratifiedIndependentBootstrap`);
//! - a **performance profile** is, for each threshold tau, the fraction of all runs x tasks
//!   whose score exceeds tau, with a bootstrap band (rliable's `create_performance_profile`
//!   with score distributions).
//!
//! Every random draw comes from the generator the caller passes in, so a figure is the same
//! for the same seed.

use rand::{Rng, RngExt};
use thiserror::Error;

/// Coverage of every interval: 95%.
pub const CONFIDENCE: f64 = 0.95;
/// Bootstrap resamples of every interval by default.
pub const RESAMPLES: usize = 10_000;
/// The fewest resamples an interval may be drawn from.
pub const MIN_RESAMPLES: usize = 2_000;
/// The most: 100 times the default, past which more resamples change no reported digit and
/// only hold memory (every statistic keeps each resample's value).
pub const MAX_RESAMPLES: usize = 1_000_000;

#[derive(Debug, Error, PartialEq)]
pub enum StatsError {
    #[error("a group with no runs or no tasks has no statistics")]
    Empty,
    #[error("task {task} has {runs} runs, task 0 has {expected}: scores must be runs x tasks")]
    Ragged { task: usize, runs: usize, expected: usize },
    #[error("score {value} of run {run}, task {task} is not a finite number")]
    NotFinite { run: usize, task: usize, value: f64 },
    #[error("{0} bootstrap resamples: at least {MIN_RESAMPLES} are needed")]
    TooFewResamples(usize),
    #[error("{0} bootstrap resamples: at most {MAX_RESAMPLES} are drawn")]
    TooManyResamples(usize),
}

/// One group's scores: for every task, the score of each run (the same runs in every task).
#[derive(Debug, Clone, PartialEq)]
pub struct Scores {
    /// `by_task[t][r]`: run r on task t.
    by_task: Vec<Vec<f64>>,
}

impl Scores {
    /// Scores of runs on one task.
    pub fn one_task(runs: &[f64]) -> Result<Self, StatsError> {
        Self::by_task(vec![runs.to_vec()])
    }

    /// `by_task[t][r]`: run r on task t; every task must have the same number of runs.
    pub fn by_task(by_task: Vec<Vec<f64>>) -> Result<Self, StatsError> {
        let expected = by_task.first().map_or(0, Vec::len);
        if expected == 0 {
            return Err(StatsError::Empty);
        }
        for (task, runs) in by_task.iter().enumerate() {
            if runs.len() != expected {
                return Err(StatsError::Ragged { task, runs: runs.len(), expected });
            }
            if let Some((run, &value)) = runs.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(StatsError::NotFinite { run, task, value });
            }
        }
        Ok(Self { by_task })
    }

    pub fn runs(&self) -> usize {
        self.by_task[0].len()
    }

    pub fn tasks(&self) -> usize {
        self.by_task.len()
    }

    /// Each task's scores, one per run.
    pub fn task_scores(&self) -> &[Vec<f64>] {
        &self.by_task
    }

    /// Every score, tasks after one another.
    fn flat(&self) -> Vec<f64> {
        self.by_task.iter().flatten().copied().collect()
    }

    /// Mean over tasks of the mean over runs.
    pub fn mean(&self) -> f64 {
        mean(&self.by_task.iter().map(|runs| mean(runs)).collect::<Vec<_>>())
    }

    /// Interquartile mean of all runs x tasks ([`iqm`]).
    pub fn iqm(&self) -> f64 {
        iqm(&self.flat())
    }

    /// Fraction of all runs x tasks whose score exceeds `tau`.
    pub fn fraction_above(&self, tau: f64) -> f64 {
        let flat = self.flat();
        flat.iter().filter(|&&v| v > tau).count() as f64 / flat.len() as f64
    }

    /// A stratified resample: every task's runs drawn with replacement from its own.
    fn resample<R: Rng + ?Sized>(&self, rng: &mut R) -> Self {
        let n = self.runs();
        let by_task =
            self.by_task.iter().map(|runs| (0..n).map(|_| runs[rng.random_range(0..n)]).collect()).collect();
        Self { by_task }
    }
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// `scipy.stats.trim_mean(values, 0.25)`: the mean of the sorted values without the lowest
/// and highest `floor(n / 4)` (NaN for no values).
#[must_use]
pub fn iqm(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let cut = values.len() / 4;
    mean(&sorted[cut..values.len() - cut])
}

/// `numpy.percentile(values, q)` (linear interpolation between order statistics) of sorted
/// values, q in [0, 100].
fn percentile_of_sorted(sorted: &[f64], q: f64) -> f64 {
    let position = q / 100.0 * (sorted.len() - 1) as f64;
    let below = position.floor() as usize;
    let above = (below + 1).min(sorted.len() - 1);
    let t = position - below as f64;
    sorted[below] + t * (sorted[above] - sorted[below])
}

/// A statistic and its confidence interval.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Estimate {
    pub point: f64,
    pub ci_low: f64,
    pub ci_high: f64,
}

/// How intervals are drawn: resamples and coverage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bootstrap {
    pub resamples: usize,
    pub confidence: f64,
}

impl Default for Bootstrap {
    fn default() -> Self {
        Self { resamples: RESAMPLES, confidence: CONFIDENCE }
    }
}

impl Bootstrap {
    fn check(&self) -> Result<(), StatsError> {
        if self.resamples < MIN_RESAMPLES {
            return Err(StatsError::TooFewResamples(self.resamples));
        }
        if self.resamples > MAX_RESAMPLES {
            return Err(StatsError::TooManyResamples(self.resamples));
        }
        Ok(())
    }

    /// The percentile interval of each of the `k` statistics that `draw` returns for one
    /// resample, over [`Bootstrap::resamples`] calls.
    fn intervals(&self, k: usize, mut draw: impl FnMut() -> Vec<f64>) -> Vec<(f64, f64)> {
        let mut per_stat = vec![Vec::with_capacity(self.resamples); k];
        for _ in 0..self.resamples {
            for (stat, v) in per_stat.iter_mut().zip(draw()) {
                stat.push(v);
            }
        }
        let tail = 100.0 * (1.0 - self.confidence) / 2.0;
        per_stat
            .into_iter()
            .map(|mut values| {
                values.sort_by(f64::total_cmp);
                (percentile_of_sorted(&values, tail), percentile_of_sorted(&values, 100.0 - tail))
            })
            .collect()
    }

    /// `statistic` of `scores` with its stratified bootstrap interval.
    pub fn estimate<R: Rng + ?Sized>(
        &self,
        scores: &Scores,
        statistic: fn(&Scores) -> f64,
        rng: &mut R,
    ) -> Result<Estimate, StatsError> {
        self.check()?;
        let bounds = self.intervals(1, || vec![statistic(&scores.resample(rng))]);
        let (ci_low, ci_high) = bounds[0];
        Ok(Estimate { point: statistic(scores), ci_low, ci_high })
    }

    /// IQM and mean of `scores` with their intervals (IQM's resamples drawn first).
    pub fn aggregates<R: Rng + ?Sized>(
        &self,
        scores: &Scores,
        rng: &mut R,
    ) -> Result<Aggregates, StatsError> {
        Ok(Aggregates {
            runs: scores.runs(),
            iqm: self.estimate(scores, Scores::iqm, rng)?,
            mean: self.estimate(scores, Scores::mean, rng)?,
        })
    }

    /// [`probability_of_improvement`] of `x` over `y`, with an interval from resampling `x`
    /// and `y` independently (each stratified by task).
    pub fn probability_of_improvement<R: Rng + ?Sized>(
        &self,
        x: &Scores,
        y: &Scores,
        rng: &mut R,
    ) -> Result<Estimate, StatsError> {
        self.check()?;
        // Checks that x and y have the same tasks, which their resamples keep.
        let point = probability_of_improvement(x, y)?;
        let bounds = self.intervals(1, || {
            let (rx, ry) = (x.resample(rng), y.resample(rng));
            vec![probability_of_improvement(&rx, &ry).unwrap_or(f64::NAN)]
        });
        let (ci_low, ci_high) = bounds[0];
        Ok(Estimate { point, ci_low, ci_high })
    }

    /// The performance profile of `scores` at every threshold of `taus`, with bands.
    pub fn performance_profile<R: Rng + ?Sized>(
        &self,
        scores: &Scores,
        taus: &[f64],
        rng: &mut R,
    ) -> Result<Vec<Estimate>, StatsError> {
        self.check()?;
        let profile = |s: &Scores| taus.iter().map(|&tau| s.fraction_above(tau)).collect::<Vec<_>>();
        let bands = self.intervals(taus.len(), || profile(&scores.resample(rng)));
        Ok(profile(scores)
            .into_iter()
            .zip(bands)
            .map(|(point, (ci_low, ci_high))| Estimate { point, ci_low, ci_high })
            .collect())
    }
}

/// A group's IQM and mean with their intervals.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Aggregates {
    pub runs: usize,
    pub iqm: Estimate,
    pub mean: Estimate,
}

/// The probability that a run of `x` scores above a run of `y` (ties count half), averaged
/// over tasks; `x` and `y` must have the same tasks.
pub fn probability_of_improvement(x: &Scores, y: &Scores) -> Result<f64, StatsError> {
    if x.tasks() != y.tasks() {
        return Err(StatsError::Ragged { task: x.tasks(), runs: y.tasks(), expected: x.tasks() });
    }
    let per_task: Vec<f64> = x
        .by_task
        .iter()
        .zip(&y.by_task)
        .map(|(xs, ys)| {
            let u: f64 = xs
                .iter()
                .flat_map(|a| {
                    ys.iter().map(move |b| match a.total_cmp(b) {
                        std::cmp::Ordering::Greater => 1.0,
                        std::cmp::Ordering::Equal => 0.5,
                        std::cmp::Ordering::Less => 0.0,
                    })
                })
                .sum();
            u / (xs.len() * ys.len()) as f64
        })
        .collect();
    Ok(mean(&per_task))
}

/// `count` thresholds evenly from `low` to `high`, both included (the profiles' tau axis).
#[must_use]
pub fn thresholds(low: f64, high: f64, count: usize) -> Vec<f64> {
    let steps = count.saturating_sub(1).max(1) as f64;
    (0..count).map(|i| low + (high - low) * i as f64 / steps).collect()
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;

    #[test]
    fn iqm_is_scipys_trim_mean_at_a_quarter() {
        // n = 8: two cut from each end.
        assert_eq!(iqm(&[8.0, 1.0, 7.0, 2.0, 6.0, 3.0, 5.0, 100.0]), (3.0 + 5.0 + 6.0 + 7.0) / 4.0);
        // n = 5: floor(1.25) = 1 from each end.
        assert_eq!(iqm(&[0.0, 10.0, 1.0, 2.0, 3.0]), 2.0);
        // n < 4: nothing cut.
        assert_eq!(iqm(&[1.0, 2.0, 6.0]), 3.0);
    }

    #[test]
    fn percentiles_interpolate_as_numpy() {
        let v = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(percentile_of_sorted(&v, 50.0), 2.5);
        assert_eq!(percentile_of_sorted(&v, 2.5), 1.075);
        assert_eq!(percentile_of_sorted(&v, 100.0), 4.0);
        assert_eq!(percentile_of_sorted(&[7.0], 97.5), 7.0);
    }

    #[test]
    fn probability_of_improvement_counts_pairs_and_ties_half() {
        let x = Scores::one_task(&[0.5, 1.0]).expect("x");
        let y = Scores::one_task(&[0.0, 0.5, 1.0]).expect("y");
        // Pairs won by x: 0.5 > 0 (1), 0.5 = 0.5 (1/2), 1 > 0, 1 > 0.5 (2), 1 = 1 (1/2): 4 of 6.
        assert_eq!(probability_of_improvement(&x, &y), Ok(4.0 / 6.0));
        assert_eq!(probability_of_improvement(&x, &x), Ok(0.5));
    }

    #[test]
    fn intervals_hold_the_point_and_are_the_same_for_the_same_seed() {
        let s = Scores::one_task(&[0.1, 0.9, 0.5, 0.7, 0.0, 1.0]).expect("scores");
        let b = Bootstrap::default();
        let a = b.aggregates(&s, &mut ChaCha8Rng::seed_from_u64(3)).expect("aggregates");
        assert_eq!(a, b.aggregates(&s, &mut ChaCha8Rng::seed_from_u64(3)).expect("again"));
        for e in [a.iqm, a.mean] {
            assert!(e.ci_low <= e.point && e.point <= e.ci_high, "{e:?}");
            assert!(e.ci_low < e.ci_high, "six different scores: a wide interval {e:?}");
        }
        let one = Scores::one_task(&[0.5; 5]).expect("constant");
        let e = b.estimate(&one, Scores::iqm, &mut ChaCha8Rng::seed_from_u64(0)).expect("iqm");
        assert_eq!((e.point, e.ci_low, e.ci_high), (0.5, 0.5, 0.5));
    }

    #[test]
    fn refuses_what_has_no_statistics() {
        assert_eq!(Scores::one_task(&[]), Err(StatsError::Empty));
        assert!(matches!(Scores::one_task(&[0.1, f64::NAN]), Err(StatsError::NotFinite { run: 1, .. })));
        assert!(matches!(
            Scores::by_task(vec![vec![0.1, 0.2], vec![0.3]]),
            Err(StatsError::Ragged { task: 1, runs: 1, expected: 2 })
        ));
        let s = Scores::one_task(&[0.1]).expect("one run");
        let few = Bootstrap { resamples: 100, ..Bootstrap::default() };
        assert_eq!(
            few.aggregates(&s, &mut ChaCha8Rng::seed_from_u64(0)),
            Err(StatsError::TooFewResamples(100))
        );
        // Every resample's value is kept: an absurd count is refused before it is allocated.
        let many = Bootstrap { resamples: usize::MAX, ..Bootstrap::default() };
        assert_eq!(
            many.aggregates(&s, &mut ChaCha8Rng::seed_from_u64(0)),
            Err(StatsError::TooManyResamples(usize::MAX))
        );
    }

    #[test]
    fn a_profile_is_the_fraction_above_each_threshold() {
        let s = Scores::one_task(&[0.0, 0.25, 0.5, 1.0]).expect("scores");
        let p = Bootstrap::default()
            .performance_profile(&s, &[-0.1, 0.25, 0.9, 1.0], &mut ChaCha8Rng::seed_from_u64(1))
            .expect("profile");
        let points: Vec<f64> = p.iter().map(|e| e.point).collect();
        assert_eq!(points, vec![1.0, 0.5, 0.25, 0.0]);
        assert_eq!(thresholds(0.0, 1.0, 5), vec![0.0, 0.25, 0.5, 0.75, 1.0]);
    }
}
