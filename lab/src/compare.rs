//! `vge compare GROUP=DIR,DIR... --out DIR`: groups of scored runs side by side, reported
//! the way the field trusts ([`crate::stats`]): per group the IQM and mean of one figure of
//! the runs' held-out episodes (`score.json`, [`vge_run::score`]; the success rate unless a
//! [`Metric`] says otherwise) with 95% stratified bootstrap intervals, the probability of
//! improvement between groups with its interval, performance profiles with bands, and the
//! IQM of the periodic success and return against env steps with bands. `vge plot --table1`
//! reports its cells with the same functions.
//!
//! Every interval draws from a generator seeded by the command's seed and the group's (or
//! pair's) label, so that one group's interval does not change when another group is added.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use thiserror::Error;

use crate::plot::{Groups, PlotError, Series, XAxis};
use crate::stats::{Aggregates, Bootstrap, Estimate, Scores, StatsError};
use vge_run::eval::ObjectFigures;
use vge_run::run_dir::RunCurves;
use vge_run::score::{PolicyScore, Score};

#[derive(Debug, Error)]
pub enum CompareError {
    #[error(transparent)]
    Plot(#[from] PlotError),
    #[error(transparent)]
    RunFile(#[from] vge_run::run_dir::RunFileError),
    #[error(transparent)]
    Stats(#[from] StatsError),
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("group {group}: {what}")]
    Group { group: String, what: String },
    #[error("not scored (no score.json; `vge score DIR...` scores them): {}", list(.0))]
    NotScored(Vec<PathBuf>),
    #[error("scores of different definitions cannot be compared: {0}")]
    Mixed(String),
}

fn list(dirs: &[PathBuf]) -> String {
    dirs.iter().map(|d| d.display().to_string()).collect::<Vec<_>>().join(", ")
}

/// A group on the command line: `NAME=DIR,DIR,...` (each DIR a run folder or a folder with
/// runs below it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroupSpec {
    pub name: String,
    pub dirs: Vec<PathBuf>,
}

/// Parses `NAME=DIR,DIR,...`.
pub fn parse_group(s: &str) -> Result<GroupSpec, String> {
    let (name, dirs) = s.split_once('=').ok_or_else(|| format!("`{s}` is not NAME=DIR,DIR,..."))?;
    let name = name.trim();
    if name.is_empty() || name.contains(':') {
        return Err(format!("`{s}`: a group needs a name without `:`"));
    }
    let dirs: Vec<PathBuf> = dirs.split(',').filter(|d| !d.is_empty()).map(PathBuf::from).collect();
    if dirs.is_empty() {
        return Err(format!("`{s}`: group {name} names no folder"));
    }
    Ok(GroupSpec { name: name.to_owned(), dirs })
}

/// Parses `A:B` (the probability that a run of A beats a run of B).
pub fn parse_pair(s: &str) -> Result<(String, String), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("`{s}` is not A:B"))?;
    Ok((a.trim().to_owned(), b.trim().to_owned()))
}

/// Which of a run's scored policies a statistic is of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Judged {
    /// The run's own model selection (`score.json`'s `selected`).
    Selected,
    /// The final policy (the paper's rule).
    Final,
    /// The mean of the last periodic snapshots.
    LastSnapshots,
}

impl Judged {
    pub const ALL: [Self; 3] = [Self::Selected, Self::Final, Self::LastSnapshots];

    /// Its name in `score.json` and in the reports.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Selected => "selected",
            Self::Final => "final",
            Self::LastSnapshots => "last_snapshots",
        }
    }

    /// Its success rate in `score`, where the score has it.
    #[must_use]
    pub fn success(self, score: &Score) -> Option<f64> {
        self.value(score, Metric::Success)
    }

    /// Its `metric` in `score`, where the score has it.
    #[must_use]
    pub fn value(self, score: &Score, metric: Metric) -> Option<f64> {
        match self {
            Self::Selected => score.selected.as_ref().map(|s| metric.of_policy(s)),
            Self::Final => Some(metric.of_policy(&score.final_policy)),
            Self::LastSnapshots => score
                .last_snapshots
                .as_ref()
                .map(|s| metric.of(s.success_rate, s.drop_rate, s.mean_rotation_rad, s.mean_return)),
        }
    }
}

/// The figure of a scored policy that a comparison ranks runs by, larger being better. The
/// success rate is the task's verdict and the default; the others tell groups apart where
/// every run fails the success test, and are read as such (docs/scoring.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Metric {
    /// Share of episodes turned >= 2 pi about z without a drop.
    #[default]
    Success,
    /// Share of episodes that end with the object in hand (1 - drop rate).
    Held,
    /// Mean rotation about z per episode (rad), whether or not the episode succeeded.
    RotationRad,
    /// Mean return per episode.
    Return,
}

impl Metric {
    pub const ALL: [Self; 4] = [Self::Success, Self::Held, Self::RotationRad, Self::Return];

    /// Its name on the command line and in the reports.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Success => "success",
            Self::Held => "held",
            Self::RotationRad => "rotation_rad",
            Self::Return => "return",
        }
    }

    /// What a run's score of this metric is, in words.
    #[must_use]
    pub fn describe(self) -> &'static str {
        match self {
            Self::Success => "success rate",
            Self::Held => "share of episodes held (no drop)",
            Self::RotationRad => "mean rotation about z per episode (rad)",
            Self::Return => "mean return per episode",
        }
    }

    /// Its name on a figure's axis.
    #[must_use]
    pub fn short(self) -> &'static str {
        match self {
            Self::Success => "success rate",
            Self::Held => "share held",
            Self::RotationRad => "rotation (rad)",
            Self::Return => "return",
        }
    }

    /// Whether its scores lie in [0, 1] (shares of episodes).
    #[must_use]
    pub fn is_share(self) -> bool {
        matches!(self, Self::Success | Self::Held)
    }

    fn of(self, success_rate: f64, drop_rate: f64, mean_rotation_rad: f64, mean_return: f64) -> f64 {
        match self {
            Self::Success => success_rate,
            Self::Held => 1.0 - drop_rate,
            Self::RotationRad => mean_rotation_rad,
            Self::Return => mean_return,
        }
    }

    /// Its value for a scored policy (pooled over objects).
    #[must_use]
    pub fn of_policy(self, s: &PolicyScore) -> f64 {
        self.of(s.success_rate, s.drop_rate, s.mean_rotation_rad, s.mean_return)
    }

    /// Its value on one object.
    #[must_use]
    pub fn of_object(self, f: &ObjectFigures) -> f64 {
        self.of(f.success_rate, f.drop_rate, f.mean_rotation_rad, f.mean_return)
    }
}

impl std::str::FromStr for Metric {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|m| m.name()).collect();
            format!("unknown metric `{s}`; one of {}", names.join(", "))
        })
    }
}

/// One figure of each run: which of its scored policies, and which of that policy's figures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Figure {
    pub judged: Judged,
    pub metric: Metric,
}

impl Figure {
    /// The success rate of `judged`'s policy.
    #[must_use]
    pub fn success(judged: Judged) -> Self {
        Self { judged, metric: Metric::Success }
    }

    fn of(self, score: &Score) -> Option<f64> {
        self.judged.value(score, self.metric)
    }
}

/// The success rates of the scored runs among `runs` whose score has `judged`'s policy.
#[must_use]
pub fn success_rates(runs: &[&RunCurves], judged: Judged) -> Vec<f64> {
    runs.iter().filter_map(|r| r.score.as_ref().and_then(|s| judged.success(s))).collect()
}

/// The objects of a run on several, as its score names them for `judged`'s policy (the
/// last snapshots are pooled only, so they have none).
fn judged_objects(score: &Score, judged: Judged) -> Option<&vge_run::eval::PerObjectFigures> {
    match judged {
        Judged::Selected => score.selected.as_ref().and_then(|s| s.per_object.as_ref()),
        Judged::Final => score.final_policy.per_object.as_ref(),
        Judged::LastSnapshots => None,
    }
}

/// The statistics' tasks: for runs on several objects, every object is a task (rliable's
/// runs x tasks, resampled within each object), when every run of every group was scored on
/// the same objects in the same order; otherwise None and the runs' pooled success is one task.
fn object_tasks(groups: &[(&str, Vec<&RunCurves>)], judged: Judged) -> Option<Vec<vge_sim::ObjectShape>> {
    let mut scores = groups.iter().flat_map(|(_, runs)| runs.iter().filter_map(|r| r.score.as_ref()));
    let objects = judged_objects(scores.next()?, judged)?.objects();
    let same = scores.all(|s| judged_objects(s, judged).is_some_and(|p| p.objects() == objects));
    (same && objects.len() > 1).then_some(objects)
}

/// The scores of `runs` for `figure`: runs x objects where `objects` are the tasks, else
/// one task of their pooled figure. None for no scored run.
fn judged_scores(
    runs: &[&RunCurves],
    figure: Figure,
    objects: Option<&[vge_sim::ObjectShape]>,
) -> Result<Option<Scores>, StatsError> {
    let scored: Vec<&Score> =
        runs.iter().filter_map(|r| r.score.as_ref()).filter(|s| figure.of(s).is_some()).collect();
    if scored.is_empty() {
        return Ok(None);
    }
    let Some(objects) = objects else {
        return Scores::one_task(&scored.iter().filter_map(|s| figure.of(s)).collect::<Vec<_>>()).map(Some);
    };
    let by_task = objects
        .iter()
        .map(|object| {
            scored
                .iter()
                .filter_map(|s| judged_objects(s, figure.judged))
                .filter_map(|p| p.of(*object).map(|f| figure.metric.of_object(f)))
                .collect()
        })
        .collect();
    Scores::by_task(by_task).map(Some)
}

/// The generator of the intervals of `label` (a group, or a pair `a > b`) under `seed`.
#[must_use]
pub fn rng_for(seed: u64, label: &str) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed ^ u64::from(crc32fast::hash(label.as_bytes())))
}

/// IQM and mean of `values` (one task) with their intervals; None for no values.
pub fn aggregates(
    values: &[f64],
    bootstrap: &Bootstrap,
    seed: u64,
    label: &str,
) -> Result<Option<Aggregates>, StatsError> {
    if values.is_empty() {
        return Ok(None);
    }
    bootstrap.aggregates(&Scores::one_task(values)?, &mut rng_for(seed, label)).map(Some)
}

/// The probability of improvement of `x` over `y` with its interval; None if either is empty.
pub fn improvement(
    x: &[f64],
    y: &[f64],
    bootstrap: &Bootstrap,
    seed: u64,
    label: &str,
) -> Result<Option<Estimate>, StatsError> {
    if x.is_empty() || y.is_empty() {
        return Ok(None);
    }
    let (x, y) = (Scores::one_task(x)?, Scores::one_task(y)?);
    bootstrap.probability_of_improvement(&x, &y, &mut rng_for(seed, label)).map(Some)
}

/// Thresholds of the performance profiles of shares: tau from 0 to 1 in steps of 0.01.
#[must_use]
pub fn profile_thresholds() -> Vec<f64> {
    crate::stats::thresholds(0.0, 1.0, 101)
}

/// The performance profile of `scores` at `taus` with its band, as points for
/// [`crate::plot::draw_panels`].
pub(crate) fn profile(
    scores: &Scores,
    taus: &[f64],
    bootstrap: &Bootstrap,
    seed: u64,
    label: &str,
) -> Result<Vec<crate::plot::SpreadPoint>, StatsError> {
    let estimates = bootstrap.performance_profile(scores, taus, &mut rng_for(seed, label))?;
    Ok(taus
        .iter()
        .zip(estimates)
        .map(|(&tau, e)| crate::plot::SpreadPoint { step: tau, mean: e.point, min: e.ci_low, max: e.ci_high })
        .collect())
}

/// One row of `improvement.csv`: P(a run of `a` beats a run of `b`).
#[derive(Debug, Clone, PartialEq)]
pub struct Improvement {
    pub a: String,
    pub b: String,
    pub estimate: Estimate,
}

/// `improvement.csv`: `a,b,prob_improvement,ci_low,ci_high`.
#[must_use]
pub fn improvement_csv(rows: &[Improvement]) -> String {
    let mut text = String::from("a,b,prob_improvement,ci_low,ci_high\n");
    for r in rows {
        let e = r.estimate;
        text.push_str(&format!("{},{},{:.4},{:.4},{:.4}\n", r.a, r.b, e.point, e.ci_low, e.ci_high));
    }
    text
}

/// What an interval of P(a > b) says, in words.
#[must_use]
pub fn improvement_verdict(e: &Estimate) -> &'static str {
    if e.ci_low > 0.5 {
        "supported: the interval lies above 0.5"
    } else if e.ci_high < 0.5 {
        "reversed: the interval lies below 0.5"
    } else {
        "not supported: the interval holds 0.5"
    }
}

/// The markdown table of improvements.
#[must_use]
pub fn improvement_markdown(rows: &[Improvement]) -> String {
    let mut text = String::from(
        "| A | B | P(A > B) | 95% interval | what the interval supports |\n|---|---|---|---|---|\n",
    );
    for r in rows {
        let e = r.estimate;
        text.push_str(&format!(
            "| {} | {} | {:.2} | [{:.2}, {:.2}] | {} |\n",
            r.a,
            r.b,
            e.point,
            e.ci_low,
            e.ci_high,
            improvement_verdict(&e)
        ));
    }
    text
}

/// A cell or group's statistic as `value [low, high]`.
#[must_use]
pub fn with_interval(e: &Estimate) -> String {
    format!("{:.2} [{:.2}, {:.2}]", e.point, e.ci_low, e.ci_high)
}

/// The critic at the end of each group's runs: every run's gap
/// ([`RunCurves::critic_gap_at_end`]: mean Q minus the collected return over its last metrics
/// windows) and the group's mean; empty where no run logged both figures. A comparison of
/// off-policy learners is read with it: a critic far above the returns its behaviour collects
/// has not converged, and a run's failure then says little about its method.
#[must_use]
pub fn critic_gap_markdown<S: AsRef<str>>(groups: &[(S, Vec<&RunCurves>)]) -> String {
    let intro = format!(
        "The critic at the end of each run: mean Q minus the collected discounted return \
         (`metrics.csv`'s `mean_q` - `mc_return`), the mean over its last {} metrics windows; above 0 \
         the critic overestimates what its behaviour collected.",
        vge_run::run_dir::CRITIC_GAP_WINDOWS
    );
    critic_gap_table(&intro, &critic_gap_rows(groups, RunCurves::critic_gap_at_end))
}

/// A critic-gap table after its paragraph, or nothing where it has no rows.
fn critic_gap_table(intro: &str, rows: &str) -> String {
    if rows.is_empty() {
        return String::new();
    }
    format!("\n{intro}\n\n| group | runs | per run (seed: gap) | mean |\n|---|---|---|---|\n{rows}")
}

/// The critic at the end of each run against the returns of its episodes' early steps
/// ([`RunCurves::critic_gap_early_at_end`]), which the time limit cuts by at most 5%, while
/// the collected return of a step near the limit lacks most of what the critic bootstraps
/// past it. Empty where no run logged them (binaries from before `mc_return_early`).
#[must_use]
pub fn critic_gap_early_markdown<S: AsRef<str>>(groups: &[(S, Vec<&RunCurves>)]) -> String {
    let intro = format!(
        "The same gap against the returns of the episodes' early steps (`mean_q` - \
         `mc_return_early`: the steps whose return the time limit cuts by at most 5%), the mean over \
         the last {} metrics windows; the collected return of a step near the limit lacks what the \
         critic counts past it, so this is the gap without that bias.",
        vge_run::run_dir::CRITIC_GAP_WINDOWS
    );
    critic_gap_table(&intro, &critic_gap_rows(groups, RunCurves::critic_gap_early_at_end))
}

/// One table row per group with a gap for any of its runs: the runs with one (`gap` of the
/// run), as `seed: gap` in seed order, and their mean.
fn critic_gap_rows<S: AsRef<str>>(
    groups: &[(S, Vec<&RunCurves>)],
    gap: impl Fn(&RunCurves) -> Option<f64>,
) -> String {
    let mut rows = String::new();
    for (name, runs) in groups {
        let mut gaps: Vec<(u64, f64)> = runs.iter().filter_map(|r| gap(r).map(|g| (r.seed, g))).collect();
        gaps.sort_by_key(|&(seed, _)| seed);
        if gaps.is_empty() {
            continue;
        }
        let mean = gaps.iter().map(|(_, gap)| gap).sum::<f64>() / gaps.len() as f64;
        let per_run: Vec<String> = gaps.iter().map(|(seed, gap)| format!("{seed}: {gap:.1}")).collect();
        rows.push_str(&format!(
            "| {} | {} | {} | {mean:.1} |\n",
            name.as_ref(),
            gaps.len(),
            per_run.join(", ")
        ));
    }
    rows
}

/// The critic where the guided methods' controllers stop acting: every run's gap at its hard
/// stop ([`RunCurves::critic_gap_at_step`] at `vge.hard_stop`: mean Q minus the collected
/// return over its last metrics windows up to that step) and the group's mean. Plain RL's
/// configs carry the same hard stop, so every group is read at one step; a run that has not
/// reached it, or logged neither figure, is left out. Empty where no run has a gap there.
#[must_use]
pub fn critic_gap_at_hard_stop_markdown<S: AsRef<str>>(groups: &[(S, Vec<&RunCurves>)]) -> String {
    let at_hard_stop = |r: &RunCurves| r.critic_gap_at_step(r.hard_stop_step);
    let hard_stops: std::collections::BTreeSet<u64> = groups
        .iter()
        .flat_map(|(_, runs)| runs.iter().filter(|r| at_hard_stop(r).is_some()).map(|r| r.hard_stop_step))
        .collect();
    let steps: Vec<String> = hard_stops.iter().map(|s| s.to_string()).collect();
    let intro = format!(
        "The critic at the hard stop (`vge.hard_stop`, env step {}): the same gap over the last {} \
         metrics windows up to that step, where the controllers stop acting.",
        steps.join(", "),
        vge_run::run_dir::CRITIC_GAP_WINDOWS
    );
    critic_gap_table(&intro, &critic_gap_rows(groups, at_hard_stop))
}

/// The panels of the IQM curves: periodic success and return against env steps.
pub const CURVE_SPECS: [(&str, Series); 2] = [
    ("success rate (periodic tests), IQM", |r| (&r.eval_step, &r.eval_success)),
    ("evaluation return, IQM", |r| (&r.eval_step, &r.eval_return)),
];

/// Draws the IQM curves of `groups` (each panel of [`CURVE_SPECS`]) with bootstrap bands.
pub fn draw_iqm_curves(
    groups: &Groups,
    bootstrap: &Bootstrap,
    seed: u64,
    caption: &str,
    palette: &[&str],
    out: &Path,
) -> Result<(), PlotError> {
    let mut panels = Vec::new();
    for (title, series) in CURVE_SPECS {
        let mut curves = Vec::new();
        for (name, runs) in groups {
            let mut rng = rng_for(seed, &format!("{name} {title}"));
            curves.push((*name, crate::plot::iqm_curve(runs, series, bootstrap, &mut rng)?, false));
        }
        panels.push((title, XAxis::EnvSteps, curves));
    }
    crate::plot::draw_panels(&panels, groups, caption, palette, out)
}

/// Draws the performance profiles of `figure` over `groups` (scored runs only): thresholds
/// from 0 to 1 for a share, else from 0 (or the lowest score) to the highest.
pub fn draw_profiles(
    groups: &Groups,
    figure: Figure,
    bootstrap: &Bootstrap,
    seed: u64,
    caption: &str,
    palette: &[&str],
    out: &Path,
) -> Result<(), CompareError> {
    let mut scored: Groups = BTreeMap::new();
    let listed: Vec<(&str, Vec<&RunCurves>)> = groups.iter().map(|(n, rs)| (*n, rs.clone())).collect();
    let objects = object_tasks(&listed, figure.judged);
    let mut all = Vec::new();
    for (name, runs) in groups {
        let with: Vec<&RunCurves> =
            runs.iter().copied().filter(|r| r.score.as_ref().and_then(|s| figure.of(s)).is_some()).collect();
        if with.is_empty() {
            continue;
        }
        let Some(scores) = judged_scores(&with, figure, objects.as_deref())? else { continue };
        all.push((*name, scores));
        scored.insert(*name, with);
    }
    let taus = if figure.metric.is_share() {
        profile_thresholds()
    } else {
        let values = all.iter().flat_map(|(_, s)| s.task_scores().iter().flatten().copied());
        // From 0 (or the lowest score, if below), where every run is still counted.
        let (low, high) = values.fold((0.0f64, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
        // Every score at or below 0: a unit's range, so that the profile still has an axis.
        let high = if high > low { high } else { low + 1.0 };
        crate::stats::thresholds(low, high, 101)
    };
    let mut curves = Vec::new();
    for (name, scores) in &all {
        curves.push((*name, profile(scores, &taus, bootstrap, seed, name)?, false));
    }
    let title = format!(
        "fraction of runs with {} > tau ({} policy)",
        figure.metric.name(),
        match figure.judged {
            Judged::Selected => "selected",
            Judged::Final => "final",
            Judged::LastSnapshots => "last snapshots'",
        }
    );
    Ok(crate::plot::draw_panels(
        &[(title.as_str(), XAxis::Threshold(figure.metric.short()), curves)],
        &scored,
        caption,
        palette,
        out,
    )?)
}

/// One row of `compare.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareRow {
    pub group: String,
    pub judged: Judged,
    pub aggregates: Aggregates,
}

/// `compare.csv`: `group,policy,runs,iqm,iqm_ci_low,iqm_ci_high,mean,mean_ci_low,mean_ci_high`.
#[must_use]
pub fn compare_csv(rows: &[CompareRow]) -> String {
    let mut text =
        String::from("group,policy,runs,iqm,iqm_ci_low,iqm_ci_high,mean,mean_ci_low,mean_ci_high\n");
    for r in rows {
        let (i, m) = (r.aggregates.iqm, r.aggregates.mean);
        text.push_str(&format!(
            "{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}\n",
            r.group,
            r.judged.name(),
            r.aggregates.runs,
            i.point,
            i.ci_low,
            i.ci_high,
            m.point,
            m.ci_low,
            m.ci_high
        ));
    }
    text
}

/// What [`write`] produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    pub rows: Vec<CompareRow>,
    /// P(A > B) of the selected policies (`improvement.csv`).
    pub improvements: Vec<Improvement>,
    /// P(A > B) of the final policies (`improvement-final.csv`).
    pub improvements_final: Vec<Improvement>,
    pub files: Vec<PathBuf>,
}

/// The runs of each group, read, every one scored with one definition.
fn read_groups(specs: &[GroupSpec]) -> Result<Vec<(String, Vec<RunCurves>)>, CompareError> {
    let mut groups = Vec::new();
    let mut unscored = Vec::new();
    for spec in specs {
        if groups.iter().any(|(name, _): &(String, _)| *name == spec.name) {
            return Err(CompareError::Group { group: spec.name.clone(), what: "named twice".to_owned() });
        }
        let dirs = vge_run::run_dir::find_runs(&spec.dirs)?;
        if dirs.is_empty() {
            return Err(CompareError::Group {
                group: spec.name.clone(),
                what: "no run folder found".to_owned(),
            });
        }
        let runs = dirs.iter().map(|d| vge_run::run_dir::read_run(d)).collect::<Result<Vec<_>, _>>()?;
        unscored.extend(runs.iter().filter(|r| r.score.is_none()).map(|r| r.dir.clone()));
        groups.push((spec.name.clone(), runs));
    }
    if !unscored.is_empty() {
        return Err(CompareError::NotScored(unscored));
    }
    let scores: Vec<&Score> =
        groups.iter().flat_map(|(_, rs)| rs.iter().filter_map(|r| r.score.as_ref())).collect();
    let definition = |s: &Score| {
        format!("{}, {} s episodes, grasp noise {} rad", s.definition, s.episode_s, s.grasp_noise_rad)
    };
    if let Some(first) = scores.first()
        && let Some(other) = scores.iter().find(|s| definition(s) != definition(first))
    {
        return Err(CompareError::Mixed(format!("{} against {}", definition(first), definition(other))));
    }
    Ok(groups)
}

/// Writes `out/compare.csv`, `compare.md`, `improvement.csv`, `aggregates.png`,
/// `profiles.png` and `curves.png` for `specs` by `metric`, with P(A > B) for `pairs` (every
/// ordered pair when None); for runs scored object by object also `per-object.csv`
/// ([`crate::object_rows`]).
pub fn write(
    specs: &[GroupSpec],
    pairs: Option<&[(String, String)]>,
    metric: Metric,
    out: &Path,
    seed: u64,
    bootstrap: &Bootstrap,
) -> Result<Written, CompareError> {
    let groups = read_groups(specs)?;
    let names: Vec<&str> = groups.iter().map(|(n, _)| n.as_str()).collect();
    let refs: Vec<(&str, Vec<&RunCurves>)> =
        groups.iter().map(|(n, rs)| (n.as_str(), rs.iter().collect())).collect();
    let pairs = checked_pairs(pairs, &names)?;
    let mut rows = Vec::new();
    for judged in Judged::ALL {
        let objects = object_tasks(&refs, judged);
        for (name, runs) in &refs {
            let label = format!("{name} {}", judged.name());
            if let Some(scores) = judged_scores(runs, Figure { judged, metric }, objects.as_deref())? {
                let aggregates = bootstrap.aggregates(&scores, &mut rng_for(seed, &label))?;
                rows.push(CompareRow { group: (*name).to_owned(), judged, aggregates });
            }
        }
    }
    rows.sort_by_key(|r| {
        (names.iter().position(|n| *n == r.group), Judged::ALL.iter().position(|j| *j == r.judged))
    });
    let selected_objects = object_tasks(&refs, Judged::Selected);
    let selected = Figure { judged: Judged::Selected, metric };
    let improvements = improvements_between(&refs, &pairs, Judged::Selected, metric, bootstrap, seed)?;
    let improvements_final = improvements_between(&refs, &pairs, Judged::Final, metric, bootstrap, seed)?;
    std::fs::create_dir_all(out).map_err(|source| CompareError::Io { path: out.to_owned(), source })?;
    let mut files = Vec::new();
    let mut md = markdown(
        &refs,
        &rows,
        [&improvements, &improvements_final],
        bootstrap,
        selected_objects.as_deref(),
        metric,
        seed,
    )?;
    let mut texts = vec![
        ("compare.csv", compare_csv(&rows)),
        ("improvement.csv", improvement_csv(&improvements)),
        ("improvement-final.csv", improvement_csv(&improvements_final)),
    ];
    if let Some(objects) = selected_objects.as_deref() {
        let object_rows = crate::object_rows::rows(&refs, objects)?;
        md.push_str(&format!(
            "\nEach run on each object (per-object.csv): the first periodic test at which the object's \
             success reached {:.0}%, and the held-out figures of the selected and final policies.\n\n",
            100.0 * vge_run::eval::LEARNED_SUCCESS_RATE
        ));
        md.push_str(&crate::object_rows::to_markdown(&object_rows));
        texts.push(("per-object.csv", crate::object_rows::to_csv(&object_rows)));
    }
    texts.insert(1, ("compare.md", md));
    for (name, text) in texts {
        let path = out.join(name);
        std::fs::write(&path, text).map_err(|source| CompareError::Io { path: path.clone(), source })?;
        files.push(path);
    }
    let group_map: Groups = refs.iter().map(|(n, rs)| (*n, rs.clone())).collect();
    let path = out.join("aggregates.png");
    draw_aggregates(&rows, metric, &names, &path)?;
    files.push(path);
    let path = out.join("profiles.png");
    draw_profiles(&group_map, selected, bootstrap, seed, "", &names, &path)?;
    files.push(path);
    let path = out.join("curves.png");
    draw_iqm_curves(&group_map, bootstrap, seed, "IQM over runs, 95% bootstrap band", &names, &path)?;
    files.push(path);
    Ok(Written { rows, improvements, improvements_final, files })
}

/// The label P(A > B)'s bootstrap draws are seeded by ([`rng_for`]): `A > B` for the selected
/// policies (the label they had before other policies were compared), `A > B final` for the
/// final ones, so that each interval is the same whichever others are computed beside it.
#[must_use]
pub fn improvement_label(a: &str, b: &str, judged: Judged) -> String {
    match judged {
        Judged::Selected => format!("{a} > {b}"),
        _ => format!("{a} > {b} {}", judged.name()),
    }
}

/// P(A > B) of `judged` policies for each pair whose groups both have scores
/// ([`improvement_label`]).
fn improvements_between(
    groups: &[(&str, Vec<&RunCurves>)],
    pairs: &[(String, String)],
    judged: Judged,
    metric: Metric,
    bootstrap: &Bootstrap,
    seed: u64,
) -> Result<Vec<Improvement>, CompareError> {
    let by_name: BTreeMap<&str, &Vec<&RunCurves>> = groups.iter().map(|(n, rs)| (*n, rs)).collect();
    let objects = object_tasks(groups, judged);
    let figure = Figure { judged, metric };
    let mut found = Vec::new();
    for (a, b) in pairs {
        let x = judged_scores(by_name[a.as_str()], figure, objects.as_deref())?;
        let y = judged_scores(by_name[b.as_str()], figure, objects.as_deref())?;
        if let (Some(x), Some(y)) = (x, y) {
            let label = improvement_label(a, b, judged);
            let estimate = bootstrap.probability_of_improvement(&x, &y, &mut rng_for(seed, &label))?;
            found.push(Improvement { a: a.clone(), b: b.clone(), estimate });
        }
    }
    Ok(found)
}

/// `aggregates.png`: each group's IQM and mean of the selected policies' `metric` with their
/// intervals, on [0, 1] for a share.
fn draw_aggregates(
    rows: &[CompareRow],
    metric: Metric,
    names: &[&str],
    path: &Path,
) -> Result<(), PlotError> {
    let interval_rows: Vec<crate::plot::IntervalRow> = rows
        .iter()
        .filter(|r| r.judged == Judged::Selected)
        .map(|r| (r.group.as_str(), r.aggregates.runs, vec![r.aggregates.iqm, r.aggregates.mean]))
        .collect();
    let range = if metric.is_share() {
        (0.0, 1.0)
    } else {
        let ends = rows.iter().filter(|r| r.judged == Judged::Selected).flat_map(|r| {
            [
                r.aggregates.iqm.ci_low,
                r.aggregates.mean.ci_low,
                r.aggregates.iqm.ci_high,
                r.aggregates.mean.ci_high,
            ]
        });
        let (low, high) = ends.fold((0.0f64, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
        let pad = 0.05 * (high - low).max(1e-3);
        (low - pad, high + pad)
    };
    let titles = [
        format!("IQM of {} (selected policy)", metric.short()),
        format!("mean of {} (selected policy)", metric.short()),
    ];
    crate::plot::draw_intervals(
        &interval_rows,
        &[titles[0].as_str(), titles[1].as_str()],
        range,
        "95% stratified bootstrap intervals",
        names,
        path,
    )
}

/// The pairs to report: `pairs` when given (each name a group's), else every ordered pair.
fn checked_pairs(
    pairs: Option<&[(String, String)]>,
    names: &[&str],
) -> Result<Vec<(String, String)>, CompareError> {
    Ok(match pairs {
        Some(p) => {
            for (a, b) in p {
                for name in [a, b] {
                    if !names.contains(&name.as_str()) {
                        return Err(CompareError::Group {
                            group: name.clone(),
                            what: "in --pairs, not a group".to_owned(),
                        });
                    }
                }
            }
            p.to_vec()
        }
        None => names
            .iter()
            .flat_map(|a| {
                names.iter().filter(move |b| *b != a).map(move |b| ((*a).to_owned(), (*b).to_owned()))
            })
            .collect(),
    })
}

/// The selected policies' P(A > B) table, then the final policies' (each when not empty).
fn both_improvements_markdown(name: &str, selected: &[Improvement], last: &[Improvement]) -> String {
    let mut text = String::new();
    if !selected.is_empty() {
        text.push_str(&format!("\nProbability of improvement (selected policy's {name}):\n\n"));
        text.push_str(&improvement_markdown(selected));
    }
    if !last.is_empty() {
        text.push_str(&format!(
            "\nProbability of improvement (final policy's {name}, `improvement-final.csv`):\n\n"
        ));
        text.push_str(&improvement_markdown(last));
    }
    text
}

/// `compare.md`: the groups' aggregates, the improvements and what the scores are.
fn markdown(
    groups: &[(&str, Vec<&RunCurves>)],
    rows: &[CompareRow],
    [improvements, improvements_final]: [&[Improvement]; 2],
    bootstrap: &Bootstrap,
    objects: Option<&[vge_sim::ObjectShape]>,
    metric: Metric,
    seed: u64,
) -> Result<String, StatsError> {
    let name = metric.name();
    let scores: Vec<&Score> =
        groups.iter().flat_map(|(_, rs)| rs.iter().filter_map(|r| r.score.as_ref())).collect();
    let mut text = format!(
        "| group | runs | policy | {name} IQM [95% CI] | {name} mean [95% CI] |\n|---|---|---|---|---|\n"
    );
    for r in rows {
        let runs = groups.iter().find(|(n, _)| *n == r.group).map_or(0, |(_, rs)| rs.len());
        text.push_str(&format!(
            "| {} | {}{} | {} | {} | {} |\n",
            r.group,
            r.aggregates.runs,
            if r.aggregates.runs < runs { format!(" of {runs}") } else { String::new() },
            r.judged.name(),
            with_interval(&r.aggregates.iqm),
            with_interval(&r.aggregates.mean),
        ));
    }
    text.push_str(&both_improvements_markdown(name, improvements, improvements_final));
    text.push_str(&critic_gap_markdown(groups));
    text.push_str(&critic_gap_early_markdown(groups));
    text.push_str(&critic_gap_at_hard_stop_markdown(groups));
    if let Some(objects) = objects {
        // Each object's mean over runs, with its interval: where a group's score comes from.
        let names: Vec<&str> = objects.iter().map(|o| o.name()).collect();
        text.push_str(&format!(
            "\nSelected policy's {name} per object, mean over runs [95% CI]:\n\n| group | {} |\n|---|{}\n",
            names.join(" | "),
            "---|".repeat(names.len())
        ));
        for (name, runs) in groups {
            let figure = Figure { judged: Judged::Selected, metric };
            let Some(scores) = judged_scores(runs, figure, Some(objects))? else { continue };
            let mut cells = Vec::new();
            for (object, runs) in names.iter().zip(scores.task_scores()) {
                let label = format!("{name} selected {object}");
                let a = bootstrap.aggregates(&Scores::one_task(runs)?, &mut rng_for(seed, &label))?;
                cells.push(with_interval(&a.mean));
            }
            text.push_str(&format!("| {name} | {} |\n", cells.join(" | ")));
        }
    }
    let mut episodes: Vec<usize> = scores.iter().map(|s| s.episodes).collect();
    episodes.sort_unstable();
    episodes.dedup();
    let mut seeds: Vec<u64> = scores.iter().map(|s| s.seed).collect();
    seeds.sort_unstable();
    seeds.dedup();
    let episodes: Vec<String> = episodes.iter().map(ToString::to_string).collect();
    let seeds: Vec<String> = seeds.iter().map(ToString::to_string).collect();
    text.push_str(&format!(
        "\nScores: each run's {} on {} held-out episodes (env seeds from {}; score.json, \
         docs/scoring.md). IQM: the mean of the middle half of the runs' scores; intervals: {:.0}% \
         stratified bootstrap percentile intervals over {} resamples. P(A > B): the probability that \
         a run of A scores above a run of B, ties half.{}\n",
        metric.describe(),
        episodes.join(" or "),
        seeds.join(" or "),
        100.0 * bootstrap.confidence,
        bootstrap.resamples,
        if metric == Metric::Success {
            ""
        } else {
            " The success test is the task's verdict; this metric ranks runs where it cannot, as a \
             secondary reading."
        }
    ));
    if let Some(objects) = objects {
        let names: Vec<&str> = objects.iter().map(|o| o.name()).collect();
        text.push_str(&format!(
            "\nThe runs were scored on {} objects ({}), and each object is a task, as in rliable: a \
             run's {name} on each object is one score, the IQM is over runs x objects, the mean is \
             the mean over objects of each object's mean over runs, resamples draw runs within each \
             object, and P(A > B) is the mean over objects. The last snapshots are pooled over objects.\n",
            names.len(),
            names.join(", ")
        ));
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_and_pairs_parse() {
        assert_eq!(
            parse_group("vge=a/b,c"),
            Ok(GroupSpec { name: "vge".to_owned(), dirs: vec![PathBuf::from("a/b"), PathBuf::from("c")] })
        );
        assert!(parse_group("vge").is_err());
        assert!(parse_group("=a").is_err());
        assert!(parse_group("x=").is_err());
        assert_eq!(parse_pair("a:b"), Ok(("a".to_owned(), "b".to_owned())));
    }

    #[test]
    fn metrics_parse_by_name_and_read_their_figure() {
        for metric in Metric::ALL {
            assert_eq!(metric.name().parse::<Metric>(), Ok(metric));
        }
        assert!("rotation".parse::<Metric>().is_err_and(|e| e.contains("one of success, held")));
        let figures = ObjectFigures {
            success_rate: 0.25,
            drop_rate: 0.125,
            mean_return: -3.0,
            mean_rotation_rad: 7.5,
            mean_contact_switches: 40.0,
            episodes: 8,
        };
        let values: Vec<f64> = Metric::ALL.iter().map(|m| m.of_object(&figures)).collect();
        assert_eq!(values, [0.25, 0.875, 7.5, -3.0]);
    }

    #[test]
    fn an_improvement_is_supported_only_when_its_interval_excludes_a_half() {
        let e = |point, ci_low, ci_high| Estimate { point, ci_low, ci_high };
        assert!(improvement_verdict(&e(0.8, 0.55, 0.95)).starts_with("supported"));
        assert!(improvement_verdict(&e(0.7, 0.45, 0.9)).starts_with("not supported"));
        assert!(improvement_verdict(&e(0.2, 0.05, 0.4)).starts_with("reversed"));
    }

    /// A committed run's gap at its hard stop, against the gap computed here from its
    /// `metrics.csv` by hand: the last three windows up to the hard stop.
    #[test]
    fn the_critic_at_the_hard_stop_is_read_from_the_windows_up_to_it() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../docs/results/variants/fixed-start-paper-reward/table1");
        let vge = vge_run::run_dir::read_run(&root.join("vge/seed-2")).expect("a committed run");
        let rl = vge_run::run_dir::read_run(&root.join("rl/seed-4")).expect("a committed run");
        assert_eq!((vge.hard_stop_step, rl.hard_stop_step), (200_000, 200_000));
        let by_hand = |run: &RunCurves| {
            let text = std::fs::read_to_string(run.dir.join("metrics.csv")).expect("metrics.csv");
            let mut lines = text.lines();
            let header: Vec<&str> = lines.next().expect("header").split(',').collect();
            let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
            let (step, q, ret) = (col("step"), col("mean_q"), col("mc_return"));
            let gaps: Vec<f64> = lines
                .map(|l| l.split(',').collect::<Vec<_>>())
                .filter(|f| f[step].parse::<u64>().expect("step") <= 200_000)
                .map(|f| f[q].parse::<f64>().expect("q") - f[ret].parse::<f64>().expect("return"))
                .collect();
            gaps[gaps.len() - 3..].iter().sum::<f64>() / 3.0
        };
        let (vge_gap, rl_gap) = (by_hand(&vge), by_hand(&rl));
        assert!((vge.critic_gap_at_step(200_000).expect("a gap") - vge_gap).abs() < 1e-9);
        // Not the gap at the end: the hard stop is read where it is.
        assert!((vge.critic_gap_at_end().expect("a gap") - vge_gap).abs() > 1.0);
        let md = critic_gap_at_hard_stop_markdown(&[("vge", vec![&vge]), ("rl", vec![&rl])]);
        assert!(md.contains("env step 200000"), "{md}");
        assert!(md.contains(&format!("| vge | 1 | 2: {vge_gap:.1} | {vge_gap:.1} |")), "{md}");
        assert!(md.contains(&format!("| rl | 1 | 4: {rl_gap:.1} | {rl_gap:.1} |")), "{md}");
        let mut short = rl.clone();
        short.step.retain(|&s| s < 200_000.0);
        assert_eq!(critic_gap_at_hard_stop_markdown(&[("rl", vec![&short])]), "", "not reached yet");

        // Its binary logged no early steps' returns: no table; a run with them gets one.
        assert!(vge.critic_gap_early.is_empty());
        assert_eq!(critic_gap_early_markdown(&[("vge", vec![&vge])]), "");
        let mut early = vge.clone();
        early.critic_gap_early = vge.critic_gap.iter().map(|gap| gap - 12.0).collect();
        let end = vge.critic_gap_at_end().expect("a gap") - 12.0;
        let md = critic_gap_early_markdown(&[("vge", vec![&early])]);
        assert!(md.contains(&format!("| vge | 1 | 2: {end:.1} | {end:.1} |")), "{md}");
    }

    #[test]
    fn no_values_have_no_aggregates() {
        assert_eq!(aggregates(&[], &Bootstrap::default(), 7, "none").expect("empty"), None);
    }
}
