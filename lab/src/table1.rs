//! The paper's Table I and Fig. 3 from run folders (`vge plot --table1 DIR`): for every
//! (controller, method) the seeds that finished, how many learned (the success test of
//! [`vge_run::eval`]), their mean final success rate and return, and learning curves of the
//! periodic evaluations, one figure per controller with one band per method.
//!
//! Runs are found under the given folders (a run folder holds `config.toml` and
//! `metrics.csv`) and placed in the table by their config's `controller` and `method`,
//! never by folder names. A run counts once it has its `final-eval.json`; unfinished runs
//! are counted apart. The controllers alone (`vge controller --json`, the same success
//! test's episodes) are read from `DIR/controllers/{igm,cs,fg}.json` when present.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::plot::{Groups, PlotError};
use vge_controllers::ControllerKind;
use vge_run::config::Method;
use vge_run::run_dir::{RunCurves, read_run};

/// Controllers in the table's order (the paper's: FG, then CS; IGM last).
pub const CONTROLLERS: [ControllerKind; 3] = [ControllerKind::Fg, ControllerKind::Cs, ControllerKind::Igm];

/// The method label of the controllers-alone rows.
pub const CONTROLLER_ALONE: &str = "controller-alone";

/// The figures (one per controller) that [`write`] draws.
pub const CURVE_FIGURES: [ControllerKind; 2] = [ControllerKind::Fg, ControllerKind::Cs];

/// The paper's Table I (share of about 10 seeds that learned), and its text for the
/// baselines ("RL + BC loss and RL" never learn).
#[must_use]
pub fn paper_learned_share(controller: ControllerKind, method: &str) -> Option<f64> {
    match (controller, method) {
        (ControllerKind::Fg, "vge" | "vge-bc") => Some(1.0),
        (ControllerKind::Fg, "fge") => Some(0.73),
        (ControllerKind::Cs, "vge") => Some(0.27),
        (ControllerKind::Cs, "vge-bc") => Some(0.36),
        (ControllerKind::Cs, "fge") => Some(0.67),
        (ControllerKind::Fg | ControllerKind::Cs, "rl" | "rl-bc") => Some(0.0),
        _ => None,
    }
}

/// One row of `table1.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub controller: ControllerKind,
    /// [`Method::name`], or [`CONTROLLER_ALONE`].
    pub method: String,
    /// Finished runs (with `final-eval.json`); 0 for the controller alone.
    pub seeds: usize,
    /// Of those, the runs whose final policy learned (success rate >= 50%).
    pub learned: usize,
    /// Mean over seeds of the final success rate (the controller alone: over its episodes).
    pub success_rate_mean: f64,
    /// Mean and standard deviation over seeds of the final evaluation's mean return (the
    /// controller alone: its mean return, no deviation).
    pub return_mean: f64,
    pub return_std: Option<f64>,
    /// Mean env steps of the finished runs (0 for the controller alone).
    pub env_steps: u64,
    /// Mean over seeds of the final evaluation's contact switches per episode, the evidence
    /// that a success is finger gaiting (table1.md only; None where no run reports it).
    pub contact_switches_mean: Option<f64>,
    /// Runs found for this cell that have not finished.
    pub unfinished: usize,
    /// Finished runs that did not learn but were still rising when the budget stopped them
    /// ([`still_rising`]; table1.md only).
    pub rising: usize,
    /// Mean over seeds of [`late_success`] (table1.md only; None where no run has periodic
    /// tests).
    pub late_success_mean: Option<f64>,
    /// Finished runs that did not learn although a periodic test passed during the run
    /// ([`passed_a_periodic_test`]; table1.md only): the late swing, not a failure to find a gait.
    pub passed_then_fell: usize,
    /// (seed, final success rate) of each finished run, by seed (table1.md only): the
    /// verdicts behind the count, which swing from seed to seed.
    pub per_seed: Vec<(u64, f64)>,
    /// Of the finished runs with a model selection (`best-eval.json`), how many learned by it
    /// and how many have one (table1.md only): the verdicts if each run shipped the snapshot
    /// its own periodic tests picked, scored on held-out grasps, instead of its final policy.
    pub selection_learned: (usize, usize),
    /// Finished runs with a score of their selected policy (`score.json`, [`vge_run::score`]).
    pub scored: usize,
    /// IQM and mean over those runs of the selected policy's success on the held-out
    /// episodes, with 95% stratified bootstrap intervals ([`crate::stats`]); None where no
    /// run of the cell is scored.
    pub selected_success: Option<crate::stats::Aggregates>,
    /// The same for the final policy (`score.json`'s `final`): the paper's rule on the same
    /// held-out episodes, kept beside the selection.
    pub final_success: Option<crate::stats::Aggregates>,
}

/// Seed of the bootstrap of every interval of the table (each cell's generator also takes
/// its name: [`crate::compare::rng_for`]).
pub const BOOTSTRAP_SEED: u64 = 0;

/// The label a cell's intervals are drawn under, and its name in `improvement.csv`.
#[must_use]
pub fn cell_label(controller: ControllerKind, method: &str) -> String {
    format!("{}/{method}", controller.name())
}

/// The pairs of `improvement.csv` (FG cells): P(a run of A beats a run of B). Every guided
/// method against plain RL (what guidance buys), then VGE against FGE (what the critic's
/// choice adds to the controller) and VGE + BC against VGE (what the BC term adds).
pub const IMPROVEMENT_PAIRS: [(ControllerKind, &str, &str); 6] = [
    (ControllerKind::Fg, "vge", "rl"),
    (ControllerKind::Fg, "fge", "rl"),
    (ControllerKind::Fg, "rl-bc", "rl"),
    (ControllerKind::Fg, "vge-bc", "rl"),
    (ControllerKind::Fg, "vge", "fge"),
    (ControllerKind::Fg, "vge-bc", "vge"),
];

/// Periodic tests a seed's [`late_success`] averages.
pub const LATE_TESTS: usize = 3;

/// Mean success rate of a run's last [`LATE_TESTS`] periodic tests (fewer if it has fewer).
/// Why beside the final one: a final policy's success swings by tens of points between
/// policies a few hundred updates apart (docs/results/polyak-actor/), so one test is a noisy
/// sample of where a seed ended.
#[must_use]
pub fn late_success(eval_success: &[f64]) -> Option<f64> {
    let late = &eval_success[eval_success.len().saturating_sub(LATE_TESTS)..];
    (!late.is_empty()).then(|| mean(late))
}

/// Whether any of a run's periodic tests reached the learned success rate: with a final
/// verdict of not learned, the seed found a gait and lost it by the end of its budget.
#[must_use]
pub fn passed_a_periodic_test(eval_success: &[f64]) -> bool {
    eval_success.iter().any(|&s| s >= vge_run::eval::LEARNED_SUCCESS_RATE)
}

/// How much a seed's last periodic test must beat its best earlier one to count as still
/// rising at the end of its budget.
pub const RISING_FACTOR: f64 = 1.25;

/// Whether a run's last periodic evaluation return exceeds [`RISING_FACTOR`] times the best
/// earlier one (and is positive): the issue asks to say so where a method is still rising
/// at the budget's end.
#[must_use]
pub fn still_rising(eval_return: &[f64]) -> bool {
    match eval_return.split_last() {
        Some((&last, earlier)) if !earlier.is_empty() => {
            let best = earlier.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            last > 0.0 && last > RISING_FACTOR * best.max(0.0)
        }
        _ => false,
    }
}

/// The `vge controller --json` fields the table reads.
#[derive(Debug, serde::Deserialize)]
struct ControllerAlone {
    success_rate: f64,
    mean_return: f64,
    mean_contact_switches: f64,
}

/// A controller alone's figures: success rate, mean return, contact switches per episode.
pub type AloneFigures = (f64, f64, f64);

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

/// Sample standard deviation (n - 1); None below two values.
fn std_dev(values: &[f64]) -> Option<f64> {
    (values.len() >= 2).then(|| {
        let m = mean(values);
        (values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (values.len() - 1) as f64).sqrt()
    })
}

/// The table's rows: one per (controller, method) with runs, in [`CONTROLLERS`] and
/// [`Method::ALL`] order, each controller followed by its controller-alone row if given.
pub fn rows(
    runs: &[RunCurves],
    alone: &BTreeMap<ControllerKind, AloneFigures>,
) -> Result<Vec<Row>, PlotError> {
    let mut rows = Vec::new();
    for controller in CONTROLLERS {
        for method in Method::ALL {
            let cell: Vec<&RunCurves> = runs.iter().filter(|r| in_cell(r, controller, method)).collect();
            if !cell.is_empty() {
                rows.push(cell_row(controller, method, &cell)?);
            }
        }
        if let Some(figures) = alone.get(&controller) {
            rows.push(alone_row(controller, figures));
        }
    }
    Ok(rows)
}

/// The row of one cell's runs (at least one).
fn cell_row(controller: ControllerKind, method: Method, cell: &[&RunCurves]) -> Result<Row, PlotError> {
    // Finished: it has a final-eval.json (which gives the env steps).
    let finished: Vec<&RunCurves> = cell.iter().copied().filter(|r| r.env_steps.is_some()).collect();
    let success: Vec<f64> = finished.iter().filter_map(|r| r.final_success).collect();
    let returns: Vec<f64> = finished.iter().filter_map(|r| r.final_return).collect();
    let steps: Vec<f64> = finished.iter().filter_map(|r| r.env_steps).map(|s| s as f64).collect();
    let switches: Vec<f64> = finished.iter().filter_map(|r| r.final_contact_switches).collect();
    let late: Vec<f64> = finished.iter().filter_map(|r| late_success(&r.eval_success)).collect();
    let mut per_seed: Vec<(u64, f64)> =
        finished.iter().filter_map(|r| r.final_success.map(|s| (r.seed, s))).collect();
    per_seed.sort_by_key(|&(seed, _)| seed);
    // IQM and mean of the held-out success of one policy per run (the label seeds the
    // cell's bootstrap, so each stays "CELL selected" / "CELL final").
    let aggregates = |judged: crate::compare::Judged| {
        let rates = crate::compare::success_rates(&finished, judged);
        let label = format!("{} {}", cell_label(controller, method.name()), judged.name());
        crate::compare::aggregates(&rates, &crate::stats::Bootstrap::default(), BOOTSTRAP_SEED, &label)
            .map(|a| (rates.len(), a))
            .map_err(|e| PlotError::Draw(format!("{label}: {e}")))
    };
    let (scored, selected_success) = aggregates(crate::compare::Judged::Selected)?;
    let (_, final_success) = aggregates(crate::compare::Judged::Final)?;
    Ok(Row {
        controller,
        method: method.name().to_owned(),
        seeds: finished.len(),
        learned: finished.iter().filter(|r| r.learned() == Some(true)).count(),
        success_rate_mean: mean(&success),
        return_mean: mean(&returns),
        return_std: std_dev(&returns),
        env_steps: mean(&steps).round() as u64,
        contact_switches_mean: (!switches.is_empty()).then(|| mean(&switches)),
        unfinished: cell.len() - finished.len(),
        rising: finished
            .iter()
            .filter(|r| r.learned() == Some(false) && still_rising(&r.eval_return))
            .count(),
        late_success_mean: (!late.is_empty()).then(|| mean(&late)),
        passed_then_fell: finished
            .iter()
            .filter(|r| r.learned() == Some(false) && passed_a_periodic_test(&r.eval_success))
            .count(),
        per_seed,
        selection_learned: (
            finished.iter().filter(|r| r.selected.is_some_and(|s| s.learned())).count(),
            finished.iter().filter(|r| r.selected.is_some()).count(),
        ),
        scored,
        selected_success,
        final_success,
    })
}

/// The row of the controller alone: its success rate, mean return and contact switches.
fn alone_row(controller: ControllerKind, &(success_rate, mean_return, switches): &AloneFigures) -> Row {
    Row {
        controller,
        method: CONTROLLER_ALONE.to_owned(),
        seeds: 0,
        learned: 0,
        success_rate_mean: success_rate,
        return_mean: mean_return,
        return_std: None,
        env_steps: 0,
        contact_switches_mean: Some(switches),
        unfinished: 0,
        rising: 0,
        late_success_mean: None,
        passed_then_fell: 0,
        per_seed: Vec::new(),
        selection_learned: (0, 0),
        scored: 0,
        selected_success: None,
        final_success: None,
    }
}

/// `table1.csv`: `controller,method,seeds,learned,success_rate_mean,return_mean,return_std,
/// env_steps,scored,iqm,iqm_ci_low,iqm_ci_high,mean,mean_ci_low,mean_ci_high` (return_std
/// empty below two seeds; `seeds` and `learned` empty for the controller alone; the figures
/// empty for a cell with no finished run; `scored` counts the finished runs with a score
/// of their selected policy, and the IQM and mean with their 95% intervals are of those
/// runs' held-out success, empty where none is scored), then `final_iqm,final_iqm_ci_low,
/// final_iqm_ci_high`: the IQM of the final policies' held-out success, the paper's rule.
#[must_use]
pub fn to_csv(rows: &[Row]) -> String {
    let mut text = String::from(
        "controller,method,seeds,learned,success_rate_mean,return_mean,return_std,env_steps,\
         scored,iqm,iqm_ci_low,iqm_ci_high,mean,mean_ci_low,mean_ci_high,final_iqm,final_iqm_ci_low,\
         final_iqm_ci_high\n",
    );
    for r in rows {
        let alone = r.method == CONTROLLER_ALONE;
        let count = |n: usize| if alone { String::new() } else { n.to_string() };
        // A cell whose runs are all still running has no figures yet (not zeros).
        let figure = |text: String| if !alone && r.seeds == 0 { String::new() } else { text };
        let aggregates = r.selected_success.map_or_else(
            || ",,,,,".to_owned(),
            |a| {
                let (i, m) = (a.iqm, a.mean);
                format!(
                    "{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}",
                    i.point, i.ci_low, i.ci_high, m.point, m.ci_low, m.ci_high
                )
            },
        );
        let final_iqm = r.final_success.map_or_else(
            || ",,".to_owned(),
            |a| format!("{:.4},{:.4},{:.4}", a.iqm.point, a.iqm.ci_low, a.iqm.ci_high),
        );
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{aggregates},{final_iqm}\n",
            r.controller.name(),
            r.method,
            count(r.seeds),
            count(r.learned),
            figure(format!("{:.4}", r.success_rate_mean)),
            figure(format!("{:.2}", r.return_mean)),
            r.return_std.map_or_else(String::new, |s| format!("{s:.2}")),
            if alone { String::new() } else { figure(r.env_steps.to_string()) },
            count(r.scored),
        ));
    }
    text
}

/// `table1.md`: [`to_markdown`], then the probability of improvement between cells, of the
/// selected policies and then of the final ones.
#[must_use]
pub fn to_markdown_with(
    rows: &[Row],
    improvements: &[crate::compare::Improvement],
    improvements_final: &[crate::compare::Improvement],
) -> String {
    let mut text = to_markdown(rows);
    if !improvements.is_empty() {
        text.push_str(
            "\nProbability of improvement (FG controller; selected policy's held-out success, \
             `improvement.csv`): the probability that a run of A scores above a run of B (ties half), \
             with its 95% stratified bootstrap interval.\n\n",
        );
        text.push_str(&crate::compare::improvement_markdown(improvements));
    }
    if !improvements_final.is_empty() {
        text.push_str("\nThe same of the final policies (`improvement-final.csv`):\n\n");
        text.push_str(&crate::compare::improvement_markdown(improvements_final));
    }
    text
}

/// `table1.md`: ours beside the paper's share of seeds that learned.
#[must_use]
pub fn to_markdown(rows: &[Row]) -> String {
    let mut text = String::from(
        "| controller | method | seeds learned (ours) | final success per seed (seed: rate) | learned by the run's selection | selected policy's held-out success, IQM [95% CI] | its mean [95% CI] | final policy's held-out success, IQM [95% CI] | paper (about 10 seeds) | final success rate, mean | success of the last 3 periodic tests, mean | final return, mean ± std | contact switches per episode, mean | env steps |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let paper = paper_learned_share(r.controller, &r.method)
            .map_or_else(|| "not reported".to_owned(), |p| format!("{:.0}%", 100.0 * p));
        let learned = learned_cell(r);
        let ret = match r.return_std {
            Some(s) => format!("{:.1} ± {s:.1}", r.return_mean),
            None => format!("{:.1}", r.return_mean),
        };
        let paper = if r.method == CONTROLLER_ALONE { "-".to_owned() } else { paper };
        let per_seed = if r.per_seed.is_empty() {
            "-".to_owned()
        } else {
            let seeds: Vec<String> =
                r.per_seed.iter().map(|(seed, rate)| format!("{seed}: {:.0}%", 100.0 * rate)).collect();
            seeds.join(", ")
        };
        if r.method != CONTROLLER_ALONE && r.seeds == 0 {
            // All of the cell's runs are still running: no figures yet.
            text.push_str(&format!(
                "| {} | {} | {learned} | - | - | - | - | - | {paper} | - | - | - | - | - |\n",
                r.controller.name().to_uppercase(),
                r.method
            ));
            continue;
        }
        let selection = match r.selection_learned {
            (_, 0) => "-".to_owned(),
            (learned, of) => format!("{learned}/{of}"),
        };
        let steps = if r.method == CONTROLLER_ALONE { "-".to_owned() } else { r.env_steps.to_string() };
        let switches = r.contact_switches_mean.map_or_else(|| "-".to_owned(), |s| format!("{s:.1}"));
        let late = r.late_success_mean.map_or_else(|| "-".to_owned(), |s| format!("{s:.2}"));
        let (iqm, mean) = match r.selected_success {
            Some(a) => {
                let of = if a.runs < r.seeds {
                    format!(" ({} of {} runs)", a.runs, r.seeds)
                } else {
                    String::new()
                };
                (
                    format!("{}{of}", crate::compare::with_interval(&a.iqm)),
                    crate::compare::with_interval(&a.mean),
                )
            }
            None => ("-".to_owned(), "-".to_owned()),
        };
        let final_iqm =
            r.final_success.map_or_else(|| "-".to_owned(), |a| crate::compare::with_interval(&a.iqm));
        text.push_str(&format!(
            "| {} | {} | {learned} | {per_seed} | {selection} | {iqm} | {mean} | {final_iqm} | {paper} | {:.2} | {late} | {ret} | {switches} | {steps} |\n",
            r.controller.name().to_uppercase(),
            r.method,
            r.success_rate_mean,
        ));
    }
    text.push_str(&markdown_notes(rows));
    text
}

/// The notes under `table1.md`'s table, each where its column shows something.
fn markdown_notes(rows: &[Row]) -> String {
    let mut text = String::new();
    if rows.iter().any(|r| r.late_success_mean.is_some()) {
        text.push_str(&format!(
            "\nThe last {LATE_TESTS} periodic tests (the final one included) stand beside the final \
             one because a final policy's success swings by tens of points between policies a few \
             hundred updates apart (docs/results/polyak-actor/); seeds are learned or not by the \
             final test alone.\n"
        ));
    }
    if rows.iter().any(|r| r.selected_success.is_some()) {
        text.push_str(
            "\nSelected policy's held-out success: each run's selected snapshot scored on its held-out \
             episodes (`score.json`: 100 randomised 30 s episodes apart from those training selected on; \
             docs/scoring.md); per cell the interquartile mean (IQM) and the mean over its runs, each with \
             a 95% stratified bootstrap interval.\n",
        );
    }
    if rows.iter().any(|r| r.selection_learned.1 > 0) {
        text.push_str(
            "\nLearned by the run's selection: the snapshot a run's periodic tests picked (`best-eval.json`), \
             scored on held-out grasps, instead of its final policy; a run without snapshots is not counted.\n",
        );
    }
    let not_learned: usize =
        rows.iter().filter(|r| r.method != CONTROLLER_ALONE).map(|r| r.seeds - r.learned).sum();
    if not_learned > 0 {
        let fell: usize = rows.iter().map(|r| r.passed_then_fell).sum();
        text.push_str(&format!(
            "\nPassed earlier: of the {not_learned} seeds that did not learn, {fell} passed a periodic \
             test (success >= {:.0}%) during the run and fell below it by the final test.\n",
            100.0 * vge_run::eval::LEARNED_SUCCESS_RATE
        ));
    }
    if rows.iter().any(|r| r.rising > 0) {
        text.push_str(&format!(
            "\nStill rising: a seed that did not learn within its budget but whose last periodic test \
             returned more than {RISING_FACTOR}x its best earlier one; a longer run may learn.\n"
        ));
    }
    text
}

/// The "seeds learned (ours)" cell: learned of finished, and what the others did.
fn learned_cell(r: &Row) -> String {
    if r.method == CONTROLLER_ALONE {
        return "(no learning)".to_owned();
    }
    let share = if r.seeds > 0 { 100.0 * r.learned as f64 / r.seeds as f64 } else { 0.0 };
    let mut cell = format!("{}/{} ({share:.0}%)", r.learned, r.seeds);
    if r.passed_then_fell > 0 {
        cell.push_str(&format!(", {} passed earlier", r.passed_then_fell));
    }
    if r.rising > 0 {
        cell.push_str(&format!(", {} still rising", r.rising));
    }
    if r.unfinished > 0 {
        cell.push_str(&format!(", {} running", r.unfinished));
    }
    cell
}

/// The controllers-alone figures under `dir/controllers/` (`{kind}.json`, written by `vge
/// controller --json`): success rate, mean return and contact switches per controller found.
pub fn read_controllers_alone(dir: &Path) -> Result<BTreeMap<ControllerKind, AloneFigures>, PlotError> {
    let mut alone = BTreeMap::new();
    for kind in CONTROLLERS {
        let path = dir.join("controllers").join(format!("{}.json", kind.name()));
        if !path.exists() {
            continue;
        }
        let text =
            vge_run::read_limits::read_to_string_bounded(&path, vge_run::read_limits::MAX_RECORD_FILE_LEN)
                .map_err(|source| PlotError::Io { path: path.clone(), source })?;
        let c: ControllerAlone = serde_json::from_str(text.trim())
            .map_err(|e| PlotError::Csv { path: path.clone(), message: e.to_string() })?;
        alone.insert(kind, (c.success_rate, c.mean_return, c.mean_contact_switches));
    }
    Ok(alone)
}

/// What [`write`] produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    pub rows: Vec<Row>,
    pub files: Vec<PathBuf>,
    /// Runs found that are not a cell of the table (no controller, or not the cube alone).
    pub skipped: Vec<PathBuf>,
    /// [`IMPROVEMENT_PAIRS`] whose cells both have scored runs, by their selected policies.
    pub improvements: Vec<crate::compare::Improvement>,
    /// The same by their final policies.
    pub improvements_final: Vec<crate::compare::Improvement>,
}

/// P(A > B) of `judged` policies for the pairs of [`IMPROVEMENT_PAIRS`] whose cells both have
/// scored runs ([`crate::compare::improvement_label`]).
fn improvements(
    runs: &[RunCurves],
    judged: crate::compare::Judged,
) -> Result<Vec<crate::compare::Improvement>, PlotError> {
    use crate::compare::{Improvement, success_rates};
    let cell = |controller: ControllerKind, method: &str| -> Vec<f64> {
        let finished: Vec<&RunCurves> = runs
            .iter()
            .filter(|r| {
                r.controller == Some(controller) && r.method.name() == method && r.env_steps.is_some()
            })
            .collect();
        success_rates(&finished, judged)
    };
    let mut found = Vec::new();
    for (controller, method_a, method_b) in IMPROVEMENT_PAIRS {
        let (x, y) = (cell(controller, method_a), cell(controller, method_b));
        let (a, b) = (cell_label(controller, method_a), cell_label(controller, method_b));
        let label = crate::compare::improvement_label(&a, &b, judged);
        let estimate =
            crate::compare::improvement(&x, &y, &crate::stats::Bootstrap::default(), BOOTSTRAP_SEED, &label)
                .map_err(|e| PlotError::Draw(format!("{label}: {e}")))?;
        if let Some(estimate) = estimate {
            found.push(Improvement { a, b, estimate });
        }
    }
    Ok(found)
}

/// The critic at the end of each cell's finished runs ([`crate::compare::critic_gap_markdown`]),
/// cells in the table's order.
fn critic_gaps(runs: &[RunCurves]) -> String {
    let mut cells: Vec<(String, Vec<&RunCurves>)> = Vec::new();
    for controller in CONTROLLERS {
        for method in Method::ALL {
            let finished: Vec<&RunCurves> =
                runs.iter().filter(|r| in_cell(r, controller, method) && r.env_steps.is_some()).collect();
            if !finished.is_empty() {
                cells.push((cell_label(controller, method.name()), finished));
            }
        }
    }
    crate::compare::critic_gap_markdown(&cells)
}

/// Whether `run` belongs to the cell of `controller` and `method`.
fn in_cell(run: &RunCurves, controller: ControllerKind, method: Method) -> bool {
    run.controller == Some(controller) && run.method == method
}

/// Whether a run belongs in the table: the cube alone, with a controller named.
fn in_table(run: &RunCurves) -> bool {
    run.controller.is_some() && run.objects == [vge_sim::ObjectShape::Cube]
}

/// Reads the runs below `roots` and the controllers alone under `out`, and writes
/// `out/table1.csv`, `out/table1.md` and `out/curves-{fg,cs}.png` (a figure only for a
/// controller with runs).
pub fn write(roots: &[PathBuf], out: &Path) -> Result<Written, PlotError> {
    let dirs = vge_run::run_dir::find_runs(roots)?;
    if dirs.is_empty() {
        return Err(PlotError::NoRuns);
    }
    let (runs, others): (Vec<RunCurves>, Vec<RunCurves>) =
        dirs.iter().map(|d| read_run(d)).collect::<Result<Vec<_>, _>>()?.into_iter().partition(in_table);
    let skipped = others.into_iter().map(|r| r.dir).collect();
    let alone = read_controllers_alone(out)?;
    let rows = rows(&runs, &alone)?;
    let improvements_selected = improvements(&runs, crate::compare::Judged::Selected)?;
    let improvements_final = improvements(&runs, crate::compare::Judged::Final)?;
    std::fs::create_dir_all(out).map_err(|source| PlotError::Io { path: out.to_owned(), source })?;
    let mut files = Vec::new();
    let mut md = to_markdown_with(&rows, &improvements_selected, &improvements_final);
    md.push_str(&critic_gaps(&runs));
    let mut texts = vec![("table1.csv", to_csv(&rows)), ("table1.md", md)];
    // Only once runs are scored: a table without scores has no improvements to give.
    if !improvements_selected.is_empty() {
        texts.push(("improvement.csv", crate::compare::improvement_csv(&improvements_selected)));
        texts.push(("improvement-final.csv", crate::compare::improvement_csv(&improvements_final)));
    }
    for (name, text) in texts {
        let path = out.join(name);
        std::fs::write(&path, text).map_err(|source| PlotError::Io { path: path.clone(), source })?;
        files.push(path);
    }
    let bootstrap = crate::stats::Bootstrap::default();
    for controller in CURVE_FIGURES {
        let mut groups: Groups = BTreeMap::new();
        for r in runs.iter().filter(|r| r.controller == Some(controller)) {
            groups.entry(r.method.name()).or_default().push(r);
        }
        if groups.is_empty() {
            continue;
        }
        let path = out.join(format!("curves-{}.png", controller.name()));
        let caption = format!(
            "{} controller, cube: success test every {} env steps, IQM over seeds with its 95% bootstrap band",
            controller.name().to_uppercase(),
            eval_interval(&groups)
        );
        let palette = Method::ALL.map(Method::name);
        crate::compare::draw_iqm_curves(&groups, &bootstrap, BOOTSTRAP_SEED, &caption, &palette, &path)?;
        files.push(path);
        // Performance profiles of the selected policies' held-out success, once any is scored.
        let finished: Groups = groups
            .iter()
            .map(|(name, rs)| (*name, rs.iter().copied().filter(|r| r.env_steps.is_some()).collect()))
            .collect();
        if finished.values().flatten().any(|r| r.score.is_some()) {
            let path = out.join(format!("profiles-{}.png", controller.name()));
            let caption = format!(
                // Short: the figure is 500 px wide, and the panel's own title says the rest.
                "{} controller, cube: held-out success of selected policies",
                controller.name().to_uppercase()
            );
            crate::compare::draw_profiles(
                &finished,
                crate::compare::Figure::success(crate::compare::Judged::Selected),
                &bootstrap,
                BOOTSTRAP_SEED,
                &caption,
                &palette,
                &path,
            )
            .map_err(|e| match e {
                crate::compare::CompareError::Plot(e) => e,
                other => PlotError::Draw(other.to_string()),
            })?;
            files.push(path);
        }
    }
    Ok(Written { rows, files, skipped, improvements: improvements_selected, improvements_final })
}

/// The step between periodic evaluations of the first run with two (for the caption).
fn eval_interval(groups: &Groups) -> String {
    groups
        .values()
        .flatten()
        .find(|r| r.eval_step.len() >= 2)
        .map_or_else(|| "?".to_owned(), |r| format!("{:.0}k", (r.eval_step[1] - r.eval_step[0]) / 1e3))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_standard_deviation() {
        assert_eq!(std_dev(&[1.0]), None);
        assert_eq!(std_dev(&[1.0, 3.0]), Some(std::f64::consts::SQRT_2));
    }

    #[test]
    fn a_seed_is_still_rising_when_its_last_test_beats_its_best_earlier_one_by_a_quarter() {
        // RL + FG seed 1 (docs/results/utd05-hs400k/table1): 20 at 800k, 75 at 900k, 255 at 1M.
        assert!(still_rising(&[3.5, 20.3, 74.7, 254.6]));
        // FGE + FG seed 1: 342 at 900k, 407 at 1M (19% more) and 244 before.
        assert!(!still_rising(&[244.1, 186.7, 342.1, 406.8]));
        assert!(!still_rising(&[-5.0, -8.0, -1.0]), "negative returns do not rise");
        assert!(still_rising(&[-5.0, 2.0]));
        assert!(!still_rising(&[300.0]), "one test: nothing to compare");
        assert!(!still_rising(&[]));
    }

    #[test]
    fn a_seed_passed_a_periodic_test_when_any_test_reached_half() {
        // CS + VGE seed 3 (table1/cube-cs-vge/seed-3): 80% at 600k, 0% at 1M.
        assert!(passed_a_periodic_test(&[0.45, 0.8, 0.7, 0.0, 0.0, 0.0]));
        assert!(passed_a_periodic_test(&[0.0, 0.5]), "the threshold itself passes");
        assert!(!passed_a_periodic_test(&[0.0, 0.1, 0.35, 0.25, 0.3]));
        assert!(!passed_a_periodic_test(&[]));
    }

    #[test]
    fn late_success_averages_the_last_three_tests() {
        assert_eq!(late_success(&[0.0, 1.0, 0.5, 0.25, 0.75]), Some(0.5));
        let two = late_success(&[0.2, 0.4]).expect("two tests");
        assert!((two - 0.3).abs() < 1e-12, "fewer than three tests: all of them, {two}");
        assert_eq!(late_success(&[]), None);
    }

    #[test]
    fn paper_cells() {
        assert_eq!(paper_learned_share(ControllerKind::Cs, "fge"), Some(0.67));
        assert_eq!(paper_learned_share(ControllerKind::Igm, "vge"), None);
    }
}
