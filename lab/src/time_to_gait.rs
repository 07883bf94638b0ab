//! Time to a gait: the wall seconds from `vge train` to a run's first periodic test that
//! passes (success >= 0.5 in `eval.csv`), read from its folder, and over a group of runs the
//! median with the held-out scores of their policies beside it.
//!
//! A run logs `steps_per_s` in every `metrics.csv` row: the env steps of its session over the
//! session's wall time so far, logged before that step's test runs. At a test's step `S` the
//! session had run `S / steps_per_s` seconds, the tests before it included, when it was one
//! session from step 0. A resumed run's count starts again at its checkpoint's step, so its
//! figure is one session's only up to its first resume; its folder says it was resumed in
//! `train.log` (a lane's or a sweep's), in `tensorboard/` (an event file per session), or in
//! `metrics.csv` itself when that session clock goes back, or ends past `final-eval.json`'s
//! wall time (which adds up every session). A run without those files, resumed at a steady
//! rate, may leave no sign.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;
use thiserror::Error;
use vge_run::run_dir::{
    RunDir, RunFileError, Score, csv_columns, read_final_eval, read_json, read_train_log,
    tensorboard_sessions, whole_steps,
};

use crate::compare::{Judged, aggregates};
use crate::run_facts::{steps_label, thousands};
use crate::stats::{Aggregates, Bootstrap, StatsError};

#[derive(Debug, Error)]
pub enum TimeToGaitError {
    #[error(transparent)]
    RunFile(#[from] RunFileError),
    #[error("{path}: {why}")]
    Format { path: PathBuf, why: String },
    #[error("{0}")]
    Stats(#[from] StatsError),
}

/// A run's first passing test and the session clock at it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FirstPass {
    /// The env step of the test (`eval.csv`).
    pub step: u64,
    /// Its success on the validation episodes.
    pub success: f64,
    /// The session's wall seconds at that step: `step / steps_per_s`, the session having
    /// started at step 0.
    pub wall_s: f64,
    /// The session's env steps per second up to that step.
    pub steps_per_s: f64,
    /// The `metrics.csv` row read: the test's step, else the first row after it (the wall
    /// time is then that row's, later by at most one log interval).
    pub clock_step: u64,
}

/// One run's time to a gait.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunGait {
    pub run: PathBuf,
    pub seed: u64,
    /// The success a test must reach to count as a gait.
    pub threshold: f64,
    /// None: no test reached the threshold.
    pub first_pass: Option<FirstPass>,
    /// The last `metrics.csv` row: its step, the session's steps/s and clock there.
    pub last_step: u64,
    pub last_steps_per_s: f64,
    pub last_clock_s: f64,
    /// `final-eval.json`'s wall time, every session's summed (None: the run is unfinished).
    pub final_wall_s: Option<f64>,
    /// Whether the folder shows a resume, and where.
    pub resumed: bool,
    /// Each sign of a resume found, in words.
    pub resume_evidence: Vec<String>,
    /// The steps sessions resumed from, where `train.log` or `tensorboard/` name them.
    pub resume_steps: Vec<u64>,
    /// Whether the first pass's wall time is that of one session from step 0: the run was
    /// not resumed, or resumed only after its first pass.
    pub one_session: bool,
    /// `score.json`'s held-out success of the selected and final policies (None: not scored).
    pub selected_step: Option<u64>,
    pub selected_success: Option<f64>,
    pub final_success: Option<f64>,
}

/// The clock of a `metrics.csv` row, rounded as the file stores `steps_per_s` (one
/// decimal): how far it may be from the true one, plus half a second.
fn clock_tolerance_s(clock_s: f64, steps_per_s: f64) -> f64 {
    clock_s * 0.05 / steps_per_s.max(0.05) + 0.5
}

/// The time to a gait of the run in `dir`: its first test at `threshold` or more.
pub fn read_run(dir: &Path, threshold: f64) -> Result<RunGait, TimeToGaitError> {
    let run = RunDir::new(dir);
    let seed = run.read_config()?.seed;
    let metrics = run.metrics();
    let [steps, rates]: [Vec<f64>; 2] = csv_columns(&metrics, &["step", "steps_per_s"])?
        .try_into()
        .map_err(|_| TimeToGaitError::Format { path: metrics.clone(), why: "columns".into() })?;
    let steps = whole_steps(&metrics, &steps)?;
    let clock: Vec<(u64, f64, f64)> = steps
        .iter()
        .zip(&rates)
        .filter(|(_, rate)| rate.is_finite() && **rate > 0.0)
        .map(|(&step, &rate)| (step, rate, step as f64 / rate))
        .collect();
    let &(last_step, last_steps_per_s, last_clock_s) = clock.last().ok_or_else(|| {
        TimeToGaitError::Format { path: metrics.clone(), why: "no row with steps_per_s".into() }
    })?;
    let eval = run.eval_csv();
    let tests: Vec<(u64, f64)> = if eval.is_file() {
        let [test_steps, success]: [Vec<f64>; 2] = csv_columns(&eval, &["step", "success"])?
            .try_into()
            .map_err(|_| TimeToGaitError::Format { path: eval.clone(), why: "columns".into() })?;
        whole_steps(&eval, &test_steps)?.into_iter().zip(success).collect()
    } else {
        Vec::new()
    };
    let first_pass = tests.iter().find(|(_, s)| *s >= threshold).and_then(|&(step, success)| {
        let &(clock_step, steps_per_s, wall_s) = clock.iter().find(|(s, _, _)| *s >= step)?;
        Some(FirstPass { step, success, wall_s, steps_per_s, clock_step })
    });
    let final_wall_s = read_final_eval(dir)?.map(|f| f.wall_s);
    let signs = resume_signs(dir, &clock, final_wall_s)?;
    let resumed = !signs.evidence.is_empty();
    // Rows up to a resume's step are the session before it's.
    let one_session = !resumed
        || (signs.steps_named && first_pass.is_some_and(|p| signs.steps.iter().all(|r| p.clock_step <= *r)));
    let score: Option<Score> = read_json(&run.score())?;
    let selected = score.as_ref().and_then(|s| s.selected.as_ref());
    Ok(RunGait {
        run: dir.to_owned(),
        seed,
        threshold,
        first_pass,
        last_step,
        last_steps_per_s,
        last_clock_s,
        final_wall_s,
        resumed,
        resume_evidence: signs.evidence,
        resume_steps: signs.steps,
        one_session,
        selected_step: selected.map(|s| s.step),
        selected_success: selected.map(|s| s.success_rate),
        final_success: score.as_ref().map(|s| s.final_policy.success_rate),
    })
}

/// Every sign in the folder that the run trained in more than one session, and the steps
/// sessions resumed from where a file names them.
fn resume_signs(
    dir: &Path,
    clock: &[(u64, f64, f64)],
    final_wall_s: Option<f64>,
) -> Result<ResumeSigns, TimeToGaitError> {
    let mut evidence = Vec::new();
    let mut steps = Vec::new();
    let mut named = false;
    // A segment from step 0 started the run over (killed before its first checkpoint), so
    // only those from a later step are resumes.
    if let Some(segments) = read_train_log(dir)? {
        let from: Vec<u64> = segments.iter().map(|s| s.from_step).filter(|s| *s > 0).collect();
        if !from.is_empty() {
            let text: Vec<String> = from.iter().map(|s| thousands(*s as f64)).collect();
            evidence.push(format!(
                "train.log: {} sessions, resumed from {}",
                segments.len(),
                text.join(", ")
            ));
            steps.extend(from);
            named = true;
        }
    }
    if let Some(sessions) = tensorboard_sessions(dir)? {
        let from: Vec<u64> = sessions.iter().flatten().copied().filter(|s| *s > 0).collect();
        let unnamed = sessions.iter().filter(|s| s.is_none()).count();
        if !from.is_empty() || (unnamed > 0 && sessions.len() > 1) {
            let text: Vec<String> = from.iter().map(|s| thousands(*s as f64)).collect();
            evidence.push(format!(
                "tensorboard/: {} event files, one per session, resumed from {}",
                sessions.len(),
                if text.is_empty() { "steps their names do not say".to_owned() } else { text.join(", ") }
            ));
            named |= unnamed == 0;
            steps.extend(from);
        }
    }
    if let Some(pair) = clock.windows(2).find(|w| {
        let ((_, rate_a, clock_a), (_, rate_b, clock_b)) = (w[0], w[1]);
        clock_b + clock_tolerance_s(clock_b, rate_b) + clock_tolerance_s(clock_a, rate_a) < clock_a
    }) {
        evidence.push(format!(
            "metrics.csv: the session clock (step / steps_per_s) goes back from {} s at {} to {} s at {}",
            thousands(pair[0].2),
            thousands(pair[0].0 as f64),
            thousands(pair[1].2),
            thousands(pair[1].0 as f64)
        ));
    }
    if let (Some(wall_s), Some(&(step, rate, last))) = (final_wall_s, clock.last())
        && wall_s + clock_tolerance_s(last, rate) < last
    {
        evidence.push(format!(
            "final-eval.json: its wall time, {} s, is below the session clock at {}, {} s",
            thousands(wall_s),
            thousands(step as f64),
            thousands(last)
        ));
    }
    steps.sort_unstable();
    steps.dedup();
    Ok(ResumeSigns { evidence, steps, steps_named: named })
}

/// What a folder says of a run's sessions.
struct ResumeSigns {
    /// Each sign of a resume, in words; empty: none found.
    evidence: Vec<String>,
    /// The steps sessions resumed from, ascending.
    steps: Vec<u64>,
    /// Whether `steps` are every resume's (named by `train.log` or by every event file).
    steps_named: bool,
}

/// A group's time to a gait and held-out scores.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroupGait {
    pub name: String,
    pub runs: usize,
    /// Runs whose figure counts: one session up to their first pass, or finished without one.
    pub counted: usize,
    /// The median over the counted runs, a run that never passed counting as slower than
    /// any that did; None when the median falls on such runs (or none counts).
    pub median_wall_s: Option<f64>,
    /// The same in env steps.
    pub median_step: Option<f64>,
    /// Finished runs with no passing test.
    pub never: Vec<PathBuf>,
    /// Runs still training (no `final-eval.json`) without a passing test yet: left out.
    pub in_progress: Vec<PathBuf>,
    /// Runs whose first pass came after a resume: their wall time is not one session's, so
    /// it is left out of the median.
    pub not_one_session: Vec<PathBuf>,
    /// IQM and mean of the held-out success of the scored runs' selected and final policies,
    /// with the intervals `vge compare NAME=...` draws (the same seed and label).
    pub selected: Option<Aggregates>,
    pub final_policy: Option<Aggregates>,
}

/// The median of values where None is slower than any value; None when it falls on one.
fn median_never_last(values: &[Option<f64>]) -> Option<f64> {
    let mut finite: Vec<f64> = values.iter().flatten().copied().collect();
    finite.sort_by(f64::total_cmp);
    let n = values.len();
    if n == 0 {
        return None;
    }
    let at = |i: usize| finite.get(i).copied();
    if n % 2 == 1 { at(n / 2) } else { Some((at(n / 2 - 1)? + at(n / 2)?) / 2.0) }
}

/// The group `name` of `runs`: its median time to a gait and the held-out scores; the
/// intervals are drawn with `vge compare`'s seed 0 under `name`.
pub fn summarise(name: &str, runs: &[RunGait]) -> Result<GroupGait, TimeToGaitError> {
    let finished = |r: &RunGait| r.final_wall_s.is_some();
    let counted: Vec<&RunGait> =
        runs.iter().filter(|r| if r.first_pass.is_some() { r.one_session } else { finished(r) }).collect();
    let without_pass = |done: bool| -> Vec<PathBuf> {
        runs.iter().filter(|r| r.first_pass.is_none() && finished(r) == done).map(|r| r.run.clone()).collect()
    };
    let wall: Vec<Option<f64>> = counted.iter().map(|r| r.first_pass.map(|p| p.wall_s)).collect();
    let step: Vec<Option<f64>> = counted.iter().map(|r| r.first_pass.map(|p| p.step as f64)).collect();
    let bootstrap = Bootstrap::default();
    let scores = |judged: Judged, of: fn(&RunGait) -> Option<f64>| {
        let values: Vec<f64> = runs.iter().filter_map(of).collect();
        aggregates(&values, &bootstrap, 0, &format!("{name} {}", judged.name()))
    };
    Ok(GroupGait {
        name: name.to_owned(),
        runs: runs.len(),
        counted: counted.len(),
        median_wall_s: median_never_last(&wall),
        median_step: median_never_last(&step),
        never: without_pass(true),
        in_progress: without_pass(false),
        not_one_session: runs
            .iter()
            .filter(|r| r.first_pass.is_some() && !r.one_session)
            .map(|r| r.run.clone())
            .collect(),
        selected: scores(Judged::Selected, |r| r.selected_success)?,
        final_policy: scores(Judged::Final, |r| r.final_success)?,
    })
}

/// One line per run and the group's summary, as text.
pub fn to_text(runs: &[RunGait], group: &GroupGait) -> String {
    let mut out = String::new();
    let threshold = runs.first().map_or(0.5, |r| r.threshold);
    let _ = writeln!(
        out,
        "run | seed | first test >= {threshold} (success) | wall s to it | env steps/s to it | \
         sessions | held-out success: selected (at), final"
    );
    for r in runs {
        let opt = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.2}"));
        let (pass, wall, rate) = match r.first_pass {
            None if r.final_wall_s.is_none() => (
                format!("not yet (training, at {})", steps_label(r.last_step)),
                "-".to_owned(),
                format!("{:.1} (so far)", r.last_steps_per_s),
            ),
            None => ("never".to_owned(), "-".to_owned(), format!("{:.1} (to the end)", r.last_steps_per_s)),
            Some(p) => {
                let clock = if p.clock_step == p.step {
                    String::new()
                } else {
                    format!(", clock at {}", p.clock_step)
                };
                let mark = if r.one_session { "" } else { " (not one session's)" };
                (
                    format!("{} ({:.2}{clock})", steps_label(p.step), p.success),
                    format!("{}{mark}", thousands(p.wall_s)),
                    format!("{:.1}", p.steps_per_s),
                )
            }
        };
        let sessions = if r.resumed { "resumed" } else { "one" };
        let selected_at = r.selected_step.map_or(String::new(), |s| format!(" ({})", steps_label(s)));
        let _ = writeln!(
            out,
            "{} | {} | {pass} | {wall} | {rate} | {sessions} | {}{selected_at}, {}",
            r.run.display(),
            r.seed,
            opt(r.selected_success),
            opt(r.final_success)
        );
        for sign in &r.resume_evidence {
            let _ = writeln!(out, "  resumed: {sign}");
        }
    }
    summary_text(&mut out, group);
    out
}

fn summary_text(out: &mut String, g: &GroupGait) {
    let median = match (g.median_wall_s, g.median_step) {
        (Some(wall_s), Some(step)) => {
            format!("{} s, at {} env steps", thousands(wall_s), steps_label(step as u64))
        }
        _ if g.counted == 0 => "none (no run counted)".to_owned(),
        _ => "never (half the runs counted or more never passed)".to_owned(),
    };
    let _ = writeln!(
        out,
        "{}: median time to a gait {median} ({} of {} runs counted)",
        g.name, g.counted, g.runs
    );
    let list = |runs: &[PathBuf]| runs.iter().map(|r| r.display().to_string()).collect::<Vec<_>>().join(", ");
    if !g.never.is_empty() {
        let _ = writeln!(out, "never passed: {}", list(&g.never));
    }
    if !g.in_progress.is_empty() {
        let _ = writeln!(out, "left out (still training, no pass yet): {}", list(&g.in_progress));
    }
    if !g.not_one_session.is_empty() {
        let _ = writeln!(out, "left out (first pass after a resume): {}", list(&g.not_one_session));
    }
    for (what, a) in [("selected", &g.selected), ("final", &g.final_policy)] {
        if let Some(a) = a {
            let _ = writeln!(
                out,
                "{what} policies' held-out success ({} scored runs): IQM {:.2} [{:.2}, {:.2}], mean {:.2} [{:.2}, {:.2}]",
                a.runs, a.iqm.point, a.iqm.ci_low, a.iqm.ci_high, a.mean.point, a.mean.ci_low, a.mean.ci_high
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_median_that_falls_on_runs_that_never_passed_is_never() {
        assert_eq!(median_never_last(&[Some(3.0), None, Some(1.0)]), Some(3.0));
        assert_eq!(median_never_last(&[Some(3.0), None, None]), None);
        assert_eq!(median_never_last(&[Some(4.0), Some(2.0), None, Some(1.0)]), Some(3.0));
        assert_eq!(median_never_last(&[Some(4.0), None, None, Some(1.0)]), None);
        assert_eq!(median_never_last(&[]), None);
    }
}
