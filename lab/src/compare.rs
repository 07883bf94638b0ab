//! `vge compare GROUP=DIR,DIR... --out DIR`: groups of scored runs side by side, reported
//! the way the field trusts ([`crate::stats`]): per group the IQM and mean of the runs'
//! success rates on held-out episodes (`score.json`, [`crate::score`]) with 95% stratified
//! bootstrap intervals, the probability of improvement between groups with its interval,
//! performance profiles with bands, and the IQM of the periodic success and return against
//! env steps with bands. `vge plot --table1` reports its cells with the same functions.
//!
//! Every interval draws from a generator seeded by the command's seed and the group's (or
//! pair's) label, so that one group's interval does not change when another group is added.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use thiserror::Error;

use crate::plot::{Groups, PlotError, RunCurves, Series, XAxis};
use crate::score::Score;
use crate::stats::{Aggregates, Bootstrap, Estimate, Scores, StatsError};

#[derive(Debug, Error)]
pub enum CompareError {
    #[error(transparent)]
    Plot(#[from] PlotError),
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
        match self {
            Self::Selected => score.selected.as_ref().map(|s| s.success_rate),
            Self::Final => Some(score.final_policy.success_rate),
            Self::LastSnapshots => score.last_snapshots.as_ref().map(|s| s.success_rate),
        }
    }
}

/// The success rates of the scored runs among `runs` whose score has `judged`'s policy.
#[must_use]
pub fn success_rates(runs: &[&RunCurves], judged: Judged) -> Vec<f64> {
    runs.iter().filter_map(|r| r.score.as_ref().and_then(|s| judged.success(s))).collect()
}

/// The objects of a run on several, as its score names them for `judged`'s policy (the
/// last snapshots are pooled only, so they have none).
fn judged_objects(score: &Score, judged: Judged) -> Option<&crate::eval::PerObjectFigures> {
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

/// The scores of `runs` for `judged`: runs x objects where `objects` are the tasks, else
/// one task of their pooled success. None for no scored run.
fn judged_scores(
    runs: &[&RunCurves],
    judged: Judged,
    objects: Option<&[vge_sim::ObjectShape]>,
) -> Result<Option<Scores>, StatsError> {
    let scored: Vec<&Score> =
        runs.iter().filter_map(|r| r.score.as_ref()).filter(|s| judged.success(s).is_some()).collect();
    if scored.is_empty() {
        return Ok(None);
    }
    let Some(objects) = objects else {
        return Scores::one_task(&scored.iter().filter_map(|s| judged.success(s)).collect::<Vec<_>>())
            .map(Some);
    };
    let by_task = objects
        .iter()
        .map(|object| {
            scored
                .iter()
                .filter_map(|s| judged_objects(s, judged))
                .filter_map(|p| p.of(*object).map(|f| f.success_rate))
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

/// Thresholds of the performance profiles: tau from 0 to 1 in steps of 0.01.
#[must_use]
pub fn profile_thresholds() -> Vec<f64> {
    crate::stats::thresholds(0.0, 1.0, 101)
}

/// The performance profile of `values` at [`profile_thresholds`] with its band, as points
/// for [`crate::plot::draw_panels`].
pub(crate) fn profile(
    scores: &Scores,
    bootstrap: &Bootstrap,
    seed: u64,
    label: &str,
) -> Result<Vec<crate::plot::SpreadPoint>, StatsError> {
    let taus = profile_thresholds();
    let estimates = bootstrap.performance_profile(scores, &taus, &mut rng_for(seed, label))?;
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

/// Draws the performance profiles of the `judged` success of `groups` (scored runs only).
pub fn draw_profiles(
    groups: &Groups,
    judged: Judged,
    bootstrap: &Bootstrap,
    seed: u64,
    caption: &str,
    palette: &[&str],
    out: &Path,
) -> Result<(), CompareError> {
    let mut scored: Groups = BTreeMap::new();
    let mut curves = Vec::new();
    let listed: Vec<(&str, Vec<&RunCurves>)> = groups.iter().map(|(n, rs)| (*n, rs.clone())).collect();
    let objects = object_tasks(&listed, judged);
    for (name, runs) in groups {
        let with: Vec<&RunCurves> = runs
            .iter()
            .copied()
            .filter(|r| r.score.as_ref().and_then(|s| judged.success(s)).is_some())
            .collect();
        if with.is_empty() {
            continue;
        }
        let Some(scores) = judged_scores(&with, judged, objects.as_deref())? else { continue };
        curves.push((*name, profile(&scores, bootstrap, seed, name)?, false));
        scored.insert(*name, with);
    }
    let title = match judged {
        Judged::Selected => "fraction of runs with success > tau (selected policy)",
        Judged::Final => "fraction of runs with success > tau (final policy)",
        Judged::LastSnapshots => "fraction of runs with success > tau (last snapshots)",
    };
    Ok(crate::plot::draw_panels(&[(title, XAxis::Threshold, curves)], &scored, caption, palette, out)?)
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
    pub improvements: Vec<Improvement>,
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
        let dirs = crate::table1::find_runs(&spec.dirs)?;
        if dirs.is_empty() {
            return Err(CompareError::Group {
                group: spec.name.clone(),
                what: "no run folder found".to_owned(),
            });
        }
        let runs = dirs.iter().map(|d| crate::plot::read_run(d)).collect::<Result<Vec<_>, _>>()?;
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
/// `profiles.png` and `curves.png` for `specs`, with P(A > B) for `pairs` (every ordered pair
/// when None); for runs scored object by object also `per-object.csv`
/// ([`crate::object_rows`]).
pub fn write(
    specs: &[GroupSpec],
    pairs: Option<&[(String, String)]>,
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
            if let Some(scores) = judged_scores(runs, judged, objects.as_deref())? {
                let aggregates = bootstrap.aggregates(&scores, &mut rng_for(seed, &label))?;
                rows.push(CompareRow { group: (*name).to_owned(), judged, aggregates });
            }
        }
    }
    rows.sort_by_key(|r| {
        (names.iter().position(|n| *n == r.group), Judged::ALL.iter().position(|j| *j == r.judged))
    });
    let by_name: BTreeMap<&str, &Vec<&RunCurves>> = refs.iter().map(|(n, rs)| (*n, rs)).collect();
    let selected_objects = object_tasks(&refs, Judged::Selected);
    let mut improvements = Vec::new();
    for (a, b) in &pairs {
        let x = judged_scores(by_name[a.as_str()], Judged::Selected, selected_objects.as_deref())?;
        let y = judged_scores(by_name[b.as_str()], Judged::Selected, selected_objects.as_deref())?;
        if let (Some(x), Some(y)) = (x, y) {
            let estimate =
                bootstrap.probability_of_improvement(&x, &y, &mut rng_for(seed, &format!("{a} > {b}")))?;
            improvements.push(Improvement { a: a.clone(), b: b.clone(), estimate });
        }
    }
    std::fs::create_dir_all(out).map_err(|source| CompareError::Io { path: out.to_owned(), source })?;
    let mut files = Vec::new();
    let scores: Vec<&Score> =
        refs.iter().flat_map(|(_, rs)| rs.iter().filter_map(|r| r.score.as_ref())).collect();
    let mut md =
        markdown(&refs, &rows, &improvements, &scores, bootstrap, selected_objects.as_deref(), seed)?;
    let mut texts =
        vec![("compare.csv", compare_csv(&rows)), ("improvement.csv", improvement_csv(&improvements))];
    if let Some(objects) = selected_objects.as_deref() {
        let object_rows = crate::object_rows::rows(&refs, objects)?;
        md.push_str(&format!(
            "\nEach run on each object (per-object.csv): the first periodic test at which the object's \
             success reached {:.0}%, and the held-out figures of the selected and final policies.\n\n",
            100.0 * crate::eval::LEARNED_SUCCESS_RATE
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
    let interval_rows: Vec<crate::plot::IntervalRow> = rows
        .iter()
        .filter(|r| r.judged == Judged::Selected)
        .map(|r| (r.group.as_str(), r.aggregates.runs, vec![r.aggregates.iqm, r.aggregates.mean]))
        .collect();
    let path = out.join("aggregates.png");
    crate::plot::draw_intervals(
        &interval_rows,
        &["IQM of success (selected policy)", "mean of success (selected policy)"],
        (0.0, 1.0),
        "95% stratified bootstrap intervals",
        &names,
        &path,
    )?;
    files.push(path);
    let path = out.join("profiles.png");
    draw_profiles(&group_map, Judged::Selected, bootstrap, seed, "", &names, &path)?;
    files.push(path);
    let path = out.join("curves.png");
    draw_iqm_curves(&group_map, bootstrap, seed, "IQM over runs, 95% bootstrap band", &names, &path)?;
    files.push(path);
    Ok(Written { rows, improvements, files })
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

/// `compare.md`: the groups' aggregates, the improvements and what the scores are.
fn markdown(
    groups: &[(&str, Vec<&RunCurves>)],
    rows: &[CompareRow],
    improvements: &[Improvement],
    scores: &[&Score],
    bootstrap: &Bootstrap,
    objects: Option<&[vge_sim::ObjectShape]>,
    seed: u64,
) -> Result<String, StatsError> {
    let mut text = String::from(
        "| group | runs | policy | success IQM [95% CI] | success mean [95% CI] |\n|---|---|---|---|---|\n",
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
    if !improvements.is_empty() {
        text.push_str("\nProbability of improvement (selected policy's success):\n\n");
        text.push_str(&improvement_markdown(improvements));
    }
    if let Some(objects) = objects {
        // Each object's mean over runs, with its interval: where a group's score comes from.
        let names: Vec<&str> = objects.iter().map(|o| o.name()).collect();
        text.push_str(&format!(
            "\nSelected policy's success per object, mean over runs [95% CI]:\n\n| group | {} |\n|---|{}\n",
            names.join(" | "),
            "---|".repeat(names.len())
        ));
        for (name, runs) in groups {
            let Some(scores) = judged_scores(runs, Judged::Selected, Some(objects))? else { continue };
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
        "\nScores: each run's success rate on {} held-out episodes (env seeds from {}; score.json, \
         docs/scoring.md). IQM: the mean of the middle half of the runs' scores; intervals: {:.0}% \
         stratified bootstrap percentile intervals over {} resamples. P(A > B): the probability that \
         a run of A scores above a run of B, ties half.\n",
        episodes.join(" or "),
        seeds.join(" or "),
        100.0 * bootstrap.confidence,
        bootstrap.resamples
    ));
    if let Some(objects) = objects {
        let names: Vec<&str> = objects.iter().map(|o| o.name()).collect();
        text.push_str(&format!(
            "\nThe runs were scored on {} objects ({}), and each object is a task, as in rliable: a \
             run's success on each object is one score, the IQM is over runs x objects, the mean is \
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
    fn an_improvement_is_supported_only_when_its_interval_excludes_a_half() {
        let e = |point, ci_low, ci_high| Estimate { point, ci_low, ci_high };
        assert!(improvement_verdict(&e(0.8, 0.55, 0.95)).starts_with("supported"));
        assert!(improvement_verdict(&e(0.7, 0.45, 0.9)).starts_with("not supported"));
        assert!(improvement_verdict(&e(0.2, 0.05, 0.4)).starts_with("reversed"));
    }

    #[test]
    fn a_groups_interval_does_not_depend_on_the_other_groups() {
        let b = Bootstrap::default();
        let x = [0.1, 0.5, 0.9, 0.95];
        let alone = aggregates(&x, &b, 7, "vge selected").expect("stats");
        let _other = aggregates(&[0.2, 0.3], &b, 7, "rl selected").expect("stats");
        assert_eq!(alone, aggregates(&x, &b, 7, "vge selected").expect("stats"));
        assert_eq!(aggregates(&[], &b, 7, "none").expect("empty"), None);
    }
}
