//! `vge plot`: training curves of runs grouped by experiment (mean and min-max spread over
//! seeds), like the paper's figures, the critic's mean Q beside the discounted Monte-Carlo
//! returns of the data it learns from, and a markdown table of final success rates, like its
//! Table I. A run's final success is that of its `final-eval.json` (the success test of
//! [`crate::eval`]) or else its last periodic evaluation; a run *learned* when it reaches
//! [`crate::eval::LEARNED_SUCCESS_RATE`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use thiserror::Error;

use crate::config::{AlgorithmName, Config, ConfigError, Method, parse_with_overrides};
use vge_controllers::ControllerKind;

#[derive(Debug, Error)]
pub enum PlotError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: {message}")]
    Csv { path: PathBuf, message: String },
    #[error("no run directories given")]
    NoRuns,
    #[error("no font for the plot's text: {0}")]
    Font(String),
    #[error("drawing: {0}")]
    Draw(String),
    /// A run's `config.toml` that the config parser cannot read (the message names the file).
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// One run's curves, from its `metrics.csv` and `eval.csv`.
#[derive(Debug, Clone)]
pub struct RunCurves {
    pub dir: PathBuf,
    /// The experiment, from the run's config (`name`): runs with one name are seeds of it.
    pub experiment: String,
    /// The run config's seed.
    pub seed: u64,
    /// The run config's method and controller (the cell of Table I it belongs to).
    pub method: Method,
    pub controller: Option<ControllerKind>,
    /// The objects its envs train on (`env.objects`).
    pub objects: Vec<vge_sim::ObjectShape>,
    pub step: Vec<f64>,
    pub mean_return: Vec<f64>,
    pub rotation_rad: Vec<f64>,
    pub controller_share: Vec<f64>,
    /// The critic's mean Q on replayed batches (empty in runs that predate the column).
    pub mean_q: Vec<f64>,
    /// Mean discounted Monte-Carlo return of the visited states (empty when not logged).
    pub mc_return: Vec<f64>,
    /// The periodic evaluations (`eval.csv`: the success test on the exported policy):
    /// their env steps, mean returns and success rates (empty without evaluations).
    pub eval_step: Vec<f64>,
    pub eval_return: Vec<f64>,
    pub eval_success: Vec<f64>,
    /// Success rate of the final evaluation (`final-eval.json`), else of the last periodic
    /// one, if any.
    pub final_success: Option<f64>,
    /// For a run on several objects, its worst object's success in the final evaluation.
    pub final_worst_object_success: Option<f64>,
    /// Mean return and contact switches per episode of the final evaluation
    /// (`final-eval.json`).
    pub final_return: Option<f64>,
    pub final_contact_switches: Option<f64>,
    /// Env steps and wall time of the finished run (from `final-eval.json`).
    pub env_steps: Option<u64>,
    pub wall_s: Option<f64>,
    /// Model selection (`best-eval.json`): the snapshot with the best periodic evaluation and
    /// its success rate on held-out test grasps; None for runs without snapshots.
    pub selected: Option<Selected>,
    /// The run's score on many held-out episodes (`score.json`, [`crate::score`]); None
    /// until `vge score` (or the end of training) wrote it.
    pub score: Option<crate::score::Score>,
}

/// The fields of `best-eval.json` that the plot reads.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(from = "SelectedFields")]
pub struct Selected {
    pub selected_step: u64,
    /// On the test grasps, which the selection never saw.
    pub success_rate: f64,
    /// For a run on several objects, its worst object's success on those grasps.
    pub worst_object_success_rate: Option<f64>,
}

#[derive(serde::Deserialize)]
struct SelectedFields {
    selected_step: u64,
    success_rate: f64,
    #[serde(default)]
    per_object: Option<crate::eval::PerObjectFigures>,
}

impl From<SelectedFields> for Selected {
    fn from(f: SelectedFields) -> Self {
        Self {
            selected_step: f.selected_step,
            success_rate: f.success_rate,
            worst_object_success_rate: f
                .per_object
                .as_ref()
                .and_then(crate::eval::PerObjectFigures::worst_success_rate),
        }
    }
}

/// The success test's verdict: the pooled success and, on several objects, every object's
/// reach [`crate::eval::LEARNED_SUCCESS_RATE`] (a policy for five objects that drops one
/// has not learned the task).
fn learned(success: f64, worst_object: Option<f64>) -> bool {
    let pass = |s: f64| s >= crate::eval::LEARNED_SUCCESS_RATE;
    pass(success) && worst_object.is_none_or(pass)
}

impl Selected {
    pub fn learned(&self) -> bool {
        learned(self.success_rate, self.worst_object_success_rate)
    }
}

impl RunCurves {
    /// Whether the run learned by the success test's definition (None: not evaluated).
    pub fn learned(&self) -> Option<bool> {
        self.final_success.map(|s| learned(s, self.final_worst_object_success))
    }
}

/// The fields of `final-eval.json` that the plot and `vge eval --run` read.
#[derive(Debug, serde::Deserialize)]
pub(crate) struct FinalEvalFields {
    pub(crate) success_rate: f64,
    /// Absent in files of older vge versions.
    #[serde(default)]
    pub(crate) mean_return: Option<f64>,
    #[serde(default)]
    pub(crate) mean_rotation_rad: Option<f64>,
    #[serde(default)]
    pub(crate) mean_contact_switches: Option<f64>,
    pub(crate) env_steps: u64,
    pub(crate) wall_s: f64,
    #[serde(default)]
    pub(crate) cpu_s: Option<f64>,
    #[serde(default)]
    pub(crate) per_object: Option<crate::eval::PerObjectFigures>,
}

/// A run's CSV table or JSON record (the larger bound of the two).
fn read(path: &Path) -> Result<String, PlotError> {
    crate::read_limits::read_to_string_bounded(path, crate::read_limits::MAX_TABLE_FILE_LEN)
        .map_err(|source| PlotError::Io { path: path.to_owned(), source })
}

/// Columns of a CSV with a header row, by name; a name the header lacks is an error naming
/// it. An empty field (a metrics window in which no episode ended, or before the first
/// update) is NaN: nothing was measured there, and curves leave it out
/// ([`on_common_grid`]).
pub(crate) fn csv_columns(path: &Path, names: &[&str]) -> Result<Vec<Vec<f64>>, PlotError> {
    let columns = columns_by_name(path, names)?;
    names
        .iter()
        .zip(columns)
        .map(|(n, c)| {
            c.ok_or_else(|| PlotError::Csv { path: path.to_owned(), message: format!("no column `{n}`") })
        })
        .collect()
}

/// [`csv_columns`], or None when the file or one of the columns is missing (a run from
/// before the column existed, or without periodic evaluations).
pub(crate) fn csv_columns_if_present(
    path: &Path,
    names: &[&str],
) -> Result<Option<Vec<Vec<f64>>>, PlotError> {
    if !path.exists() {
        return Ok(None);
    }
    Ok(columns_by_name(path, names)?.into_iter().collect())
}

/// Each of `names`' column, None where the header lacks it. A last line without its newline
/// is a row still being written (or cut short by a kill, which a resume drops too) and is
/// not read; a complete row without a field of a named column is an error naming the row.
fn columns_by_name(path: &Path, names: &[&str]) -> Result<Vec<Option<Vec<f64>>>, PlotError> {
    let bad = |message: String| PlotError::Csv { path: path.to_owned(), message };
    let text = read(path)?;
    let complete = text.rfind('\n').map_or("", |end| &text[..=end]);
    let mut reader =
        csv::ReaderBuilder::new().flexible(true).trim(csv::Trim::All).from_reader(complete.as_bytes());
    let header = reader.headers().map_err(|e| bad(e.to_string()))?.clone();
    let index: Vec<Option<usize>> = names.iter().map(|n| header.iter().position(|h| h == *n)).collect();
    let mut columns: Vec<Option<Vec<f64>>> = index.iter().map(|i| i.map(|_| Vec::new())).collect();
    for (row, record) in reader.records().enumerate() {
        let record = record.map_err(|e| bad(e.to_string()))?;
        if record.iter().all(str::is_empty) {
            continue;
        }
        for (col, i) in index.iter().enumerate() {
            let (Some(i), Some(values)) = (i, columns[col].as_mut()) else { continue };
            let field = record.get(*i).ok_or_else(|| {
                bad(format!(
                    "row {} has {} fields, the header {}: no `{}`",
                    row + 2,
                    record.len(),
                    header.len(),
                    names[col]
                ))
            })?;
            let value = if field.is_empty() {
                f64::NAN
            } else {
                field.parse::<f64>().map_err(|_| {
                    bad(format!("row {}: column `{}` is `{field}`, not a number", row + 2, names[col]))
                })?
            };
            values.push(value);
        }
    }
    Ok(columns)
}

/// A CSV's step column as whole env steps: a negative, fractional or non-finite step is
/// refused, naming its row, rather than cast to another step.
pub(crate) fn whole_steps(path: &Path, steps: &[f64]) -> Result<Vec<u64>, PlotError> {
    // Below 2^53 every whole f64 is exact, and no run takes that many steps.
    const EXACT: f64 = 9_007_199_254_740_992.0;
    steps
        .iter()
        .enumerate()
        .map(|(i, &step)| {
            if step.is_finite() && (0.0..=EXACT).contains(&step) && step.fract() == 0.0 {
                Ok(step as u64)
            } else {
                Err(PlotError::Csv {
                    path: path.to_owned(),
                    message: format!("row {}: step `{step}` is not a whole number of env steps", i + 2),
                })
            }
        })
        .collect()
}

/// Reads one run directory.
pub fn read_run(dir: &Path) -> Result<RunCurves, PlotError> {
    let config = run_config(dir)?;
    let experiment = experiment(&config);
    let metrics = dir.join(crate::run_dir::METRICS);
    let cols = csv_columns(&metrics, &["step", "return", "rotation", "controller_share"])?;
    let [step, mean_return, rotation_rad, controller_share]: [Vec<f64>; 4] =
        cols.try_into().map_err(|_| PlotError::Csv { path: metrics.clone(), message: "columns".into() })?;
    // Columns later vge versions added: empty for the runs from before them.
    let optional = |name: &str| {
        csv_columns_if_present(&metrics, &[name])
            .map(|c| c.and_then(|c| c.into_iter().next()).unwrap_or_default())
    };
    let (mean_q, mc_return) = (optional("mean_q")?, optional("mc_return")?);
    let final_eval = read_final_eval(dir)?;
    let eval = dir.join(crate::run_dir::EVAL);
    let [eval_step, eval_return, eval_success]: [Vec<f64>; 3] = if eval.exists() {
        csv_columns(&eval, &["step", "return", "success"])?
            .try_into()
            .map_err(|_| PlotError::Csv { path: eval.clone(), message: "columns".into() })?
    } else {
        Default::default()
    };
    let final_success = match &final_eval {
        Some(f) => Some(f.success_rate),
        None => eval_success.last().copied(),
    };
    let final_worst_object_success = final_eval
        .as_ref()
        .and_then(|f| f.per_object.as_ref())
        .and_then(crate::eval::PerObjectFigures::worst_success_rate);
    Ok(RunCurves {
        dir: dir.to_owned(),
        experiment,
        seed: config.seed,
        method: config.method,
        controller: config.controller,
        objects: config.env.objects.clone(),
        step,
        mean_return,
        rotation_rad,
        controller_share,
        mean_q,
        mc_return,
        eval_step,
        eval_return,
        eval_success,
        final_success,
        final_worst_object_success,
        final_return: final_eval.as_ref().and_then(|f| f.mean_return),
        final_contact_switches: final_eval.as_ref().and_then(|f| f.mean_contact_switches),
        env_steps: final_eval.as_ref().map(|f| f.env_steps),
        wall_s: final_eval.as_ref().map(|f| f.wall_s),
        selected: read_json(&dir.join(crate::run_dir::BEST_EVAL))?,
        score: read_json(&dir.join(crate::score::SCORE_FILE))?,
    })
}

/// The run's `config.toml`, read with the config parser (so a file it cannot read is an
/// error naming the file; keys left out take the config's defaults).
fn run_config(dir: &Path) -> Result<Config, PlotError> {
    let path = dir.join(crate::run_dir::CONFIG);
    Ok(parse_with_overrides(&read(&path)?, &path.display().to_string(), &[])?)
}

/// The experiment of a run: its config's `name`. A run of a SAC config switched to TD3
/// (`--set algorithm="td3"`) is another experiment: the learner is appended unless the name
/// already says it.
fn experiment(config: &Config) -> String {
    let algorithm = config.algorithm.name();
    if config.algorithm != AlgorithmName::Sac && !config.name.contains(algorithm) {
        format!("{} ({algorithm})", config.name)
    } else {
        config.name.clone()
    }
}

/// The run's `final-eval.json`, if it finished.
/// `dir/final-eval.json`; `None` when the run has none (unfinished).
pub(crate) fn read_final_eval(dir: &Path) -> Result<Option<FinalEvalFields>, PlotError> {
    read_json(&dir.join(crate::run_dir::FINAL_EVAL))
}

/// A JSON file of a run, if it exists.
fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Option<T>, PlotError> {
    if !path.exists() {
        return Ok(None);
    }
    let text = read(path)?;
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| PlotError::Csv { path: path.to_owned(), message: e.to_string() })
}

/// One point of a group's curve: step, mean, min and max over its runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SpreadPoint {
    pub(crate) step: f64,
    pub(crate) mean: f64,
    pub(crate) min: f64,
    pub(crate) max: f64,
}

/// `ys` at `x`, linearly interpolated between the logged steps `xs` (clamped at the ends).
fn interpolate(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let n = xs.len().min(ys.len());
    match xs[..n].iter().position(|&xi| xi >= x) {
        None => ys[n - 1],
        Some(0) => ys[0],
        Some(i) => {
            let t = (x - xs[i - 1]) / (xs[i] - xs[i - 1]).max(f64::MIN_POSITIVE);
            ys[i - 1] + t * (ys[i] - ys[i - 1])
        }
    }
}

/// Mean, min and max over runs of `series` (steps and values) at the logged steps of the
/// run that ended earliest (runs may log at different intervals: the others are
/// interpolated).
fn spread(runs: &[&RunCurves], series: Series) -> Vec<SpreadPoint> {
    on_common_grid(runs, series)
        .into_iter()
        .map(|(x, values)| {
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            let min = values.iter().copied().fold(f64::INFINITY, f64::min);
            let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            SpreadPoint { step: x, mean, min, max }
        })
        .collect()
}

/// Every run's value of `series` at the logged steps of the run that ended earliest (the
/// others interpolated), runs without the series left out: (step, one value per run). A
/// step a run measured nothing at (a NaN from an empty CSV field) is not a point of its
/// series: its neighbours are interpolated across it.
pub(crate) fn on_common_grid(runs: &[&RunCurves], series: Series) -> Vec<(f64, Vec<f64>)> {
    let usable: Vec<(Vec<f64>, Vec<f64>)> = runs
        .iter()
        .map(|r| {
            let (xs, ys) = series(r);
            xs.iter().zip(ys).filter(|(_, y)| !y.is_nan()).map(|(&x, &y)| (x, y)).unzip()
        })
        .filter(|(xs, _): &(Vec<f64>, Vec<f64>)| !xs.is_empty())
        .collect();
    let Some(grid) = usable.iter().map(|(xs, _)| xs).min_by(|a, b| a[a.len() - 1].total_cmp(&b[b.len() - 1]))
    else {
        return Vec::new();
    };
    grid.iter().map(|&x| (x, usable.iter().map(|(xs, ys)| interpolate(xs, ys, x)).collect())).collect()
}

/// The IQM over runs of `series` at each step of [`on_common_grid`], as a line over its
/// stratified bootstrap band ([`crate::stats`]).
pub(crate) fn iqm_curve<R: rand::Rng + ?Sized>(
    runs: &[&RunCurves],
    series: Series,
    bootstrap: &crate::stats::Bootstrap,
    rng: &mut R,
) -> Result<Vec<SpreadPoint>, PlotError> {
    on_common_grid(runs, series)
        .into_iter()
        .map(|(x, values)| {
            let scores =
                crate::stats::Scores::one_task(&values).map_err(|e| PlotError::Draw(e.to_string()))?;
            let e = bootstrap
                .estimate(&scores, crate::stats::Scores::iqm, rng)
                .map_err(|e| PlotError::Draw(e.to_string()))?;
            Ok(SpreadPoint { step: x, mean: e.point, min: e.ci_low, max: e.ci_high })
        })
        .collect()
}

/// Registers DejaVu Sans as plotters' `sans-serif` (Debian's fonts-dejavu-core).
pub(crate) fn load_font() -> Result<(), PlotError> {
    const CANDIDATES: [&str; 3] = [
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/TTF/DejaVuSans.ttf",
        "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    ];
    let bytes = CANDIDATES.iter().find_map(|p| std::fs::read(p).ok()).ok_or_else(|| {
        PlotError::Font(format!("none of {CANDIDATES:?} (Debian: apt-get install fonts-dejavu-core)"))
    })?;
    // plotters keeps registered fonts for the process's lifetime.
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| PlotError::Font("DejaVuSans.ttf is not a usable font".into()))
}

/// Ready to draw a PNG at `out`: the font registered and `out`'s folder created, so that a
/// new folder in `--plot`'s path works and a folder that cannot be made is named.
pub(crate) fn prepare_png(out: &Path) -> Result<(), PlotError> {
    load_font()?;
    match out.parent() {
        Some(folder) if !folder.as_os_str().is_empty() => std::fs::create_dir_all(folder)
            .map_err(|source| PlotError::Io { path: folder.to_owned(), source }),
        _ => Ok(()),
    }
}

/// Runs grouped by a label (the experiment, or the method in Table I), in label order.
pub(crate) type Groups<'a> = BTreeMap<&'a str, Vec<&'a RunCurves>>;

/// One series of a run: its env steps and values (e.g. its mean returns).
pub(crate) type Series = fn(&RunCurves) -> (&[f64], &[f64]);

/// A panel of a figure: its title, its series and an optional second series drawn dashed.
pub(crate) type PanelSpec = (&'static str, Series, Option<Series>);

/// A group's curve in one panel: the experiment, its points, and whether it is the panel's
/// second (dashed) series.
pub(crate) type Curve<'a> = (&'a str, Vec<SpreadPoint>, bool);

/// What a panel's x axis shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum XAxis {
    /// Env steps (labelled in thousands or millions).
    EnvSteps,
    /// A threshold tau on the named score (performance profiles).
    Threshold(&'static str),
}

/// One panel of [`draw_panels`]: its title, x axis and curves.
pub(crate) type Panel<'a> = (&'a str, XAxis, Vec<Curve<'a>>);

type Chart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

pub(crate) fn draw_err(e: impl std::fmt::Display) -> PlotError {
    PlotError::Draw(e.to_string())
}

/// Draws return, rotation and controller share against env steps for every experiment in
/// `runs` into a PNG at `out`; returns the markdown success table.
pub fn plot(runs: &[RunCurves], out: &Path) -> Result<String, PlotError> {
    if runs.is_empty() {
        return Err(PlotError::NoRuns);
    }
    let mut groups: Groups = BTreeMap::new();
    for r in runs {
        groups.entry(r.experiment.as_str()).or_default().push(r);
    }
    // Each panel: a title and its series (a second one, e.g. Monte-Carlo returns beside
    // mean Q, is drawn dashed in the same colour).
    let specs: [PanelSpec; 4] = [
        ("episode return", |r| (&r.step, &r.mean_return), None),
        ("rotation about z per episode (rad)", |r| (&r.step, &r.rotation_rad), None),
        ("controller share", |r| (&r.step, &r.controller_share), None),
        (
            "mean Q (solid) vs Monte-Carlo return (dashed)",
            |r| (&r.step, &r.mean_q),
            Some(|r| (&r.step, &r.mc_return)),
        ),
    ];
    draw_figure(&groups, &specs, "", &[], out)?;
    Ok(success_table(&groups))
}

/// One row of panels, one per spec, each with every group's mean over its min-max band,
/// into a PNG at `out`, under `caption` (none if empty). A group named in `palette` takes
/// the colour of its place there, so that it keeps its colour whichever other groups are
/// present; others take their place among the groups.
pub(crate) fn draw_figure(
    groups: &Groups,
    specs: &[PanelSpec],
    caption: &str,
    palette: &[&str],
    out: &Path,
) -> Result<(), PlotError> {
    let panels: Vec<Panel> = specs
        .iter()
        .map(|&(title, series, second)| {
            let mut curves: Vec<Curve> =
                groups.iter().map(|(name, rs)| (*name, spread(rs, series), false)).collect();
            if let Some(second) = second {
                curves.extend(groups.iter().map(|(name, rs)| (*name, spread(rs, second), true)));
            }
            (title, XAxis::EnvSteps, curves)
        })
        .collect();
    draw_panels(&panels, groups, caption, palette, out)
}

/// One row of `panels`, each with its groups' lines over their bands, into a PNG at `out`
/// ([`draw_figure`]'s layout and colours; `groups` gives the legend's run counts).
pub(crate) fn draw_panels(
    panels: &[Panel],
    groups: &Groups,
    caption: &str,
    palette: &[&str],
    out: &Path,
) -> Result<(), PlotError> {
    prepare_png(out)?;
    let width = 500 * panels.len().max(1) as u32;
    let height = if caption.is_empty() { 450 } else { 490 };
    let mut root = BitMapBackend::new(out, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    if !caption.is_empty() {
        root = root.titled(caption, ("sans-serif", 20)).map_err(draw_err)?;
    }
    let areas = root.split_evenly((1, panels.len().max(1)));
    for (area, (title, x_axis, curves)) in areas.iter().zip(panels) {
        draw_panel(area, title, *x_axis, curves, groups, palette)?;
    }
    root.present().map_err(draw_err)
}

/// `curves` without their non-finite points, and `title` counting them. A diverged critic
/// logs an infinite or NaN Q: no axis holds it (plotters' axis fitting never ends on one).
fn drawable<'a>(curves: &[Curve<'a>], title: &str) -> (Vec<Curve<'a>>, String) {
    let finite = |p: &&SpreadPoint| [p.step, p.mean, p.min, p.max].iter().all(|v| v.is_finite());
    let kept: Vec<Curve> = curves
        .iter()
        .map(|(n, c, dashed)| (*n, c.iter().filter(finite).copied().collect(), *dashed))
        .collect();
    let left_out = curves.iter().map(|(_, c, _)| c.len()).sum::<usize>()
        - kept.iter().map(|(_, c, _)| c.len()).sum::<usize>();
    let title = if left_out == 0 {
        title.to_owned()
    } else {
        format!("{title} ({left_out} non-finite points not drawn)")
    };
    (kept, title)
}

/// One panel: axes fitted to `curves`, each group's mean line over its min-max band (or a
/// dashed mean line for a second series), and the legend.
fn draw_panel(
    panel: &DrawingArea<BitMapBackend, Shift>,
    title: &str,
    x_axis: XAxis,
    curves: &[Curve],
    groups: &Groups,
    palette: &[&str],
) -> Result<(), PlotError> {
    let (curves, title) = drawable(curves, title);
    let x_max = curves.iter().flat_map(|(_, c, _)| c.iter().map(|p| p.step)).fold(1.0, f64::max);
    // Steps and shares start at 0; a threshold on returns may lie below.
    let x_min = curves.iter().flat_map(|(_, c, _)| c.iter().map(|p| p.step)).fold(0.0, f64::min);
    let (y_min, y_max) = curves
        .iter()
        .flat_map(|(_, c, _)| c.iter().flat_map(|p| [p.min, p.max]))
        .fold((0.0f64, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = 0.05 * (y_max - y_min).max(1e-3);
    let mut chart = ChartBuilder::on(panel)
        .caption(&title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(x_min..x_max, (y_min - pad)..(y_max + pad))
        .map_err(draw_err)?;
    // Steps in thousands or millions: full numbers run into each other on the axis.
    let steps_label =
        |x: &f64| if x_max >= 2e6 { format!("{:.1}M", x / 1e6) } else { format!("{:.0}k", x / 1e3) };
    let threshold_label = |x: &f64| format!("{x:.1}");
    let (x_desc, x_label): (String, &dyn Fn(&f64) -> String) = match x_axis {
        XAxis::EnvSteps => ("env steps".to_owned(), &steps_label),
        XAxis::Threshold(score) => (format!("{score} threshold tau"), &threshold_label),
    };
    chart.configure_mesh().x_desc(x_desc).x_labels(6).x_label_formatter(x_label).draw().map_err(draw_err)?;
    for (name, c, dashed) in &curves {
        let place = palette.iter().position(|p| p == name);
        let place = place.or_else(|| groups.keys().position(|k| k == name)).unwrap_or(0);
        let color = Palette99::pick(place).to_rgba();
        if *dashed {
            chart
                .draw_series(DashedLineSeries::new(
                    c.iter().map(|p| (p.step, p.mean)),
                    8,
                    5,
                    color.stroke_width(2),
                ))
                .map_err(draw_err)?;
        } else {
            draw_band_and_mean(&mut chart, c, color, runs_label(name, groups.get(name).map_or(0, Vec::len)))?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(draw_err)
}

/// One group's row of an interval figure: its name, runs, and one estimate per panel.
pub(crate) type IntervalRow<'a> = (&'a str, usize, Vec<crate::stats::Estimate>);

/// Point estimates with their confidence intervals, one panel per statistic (`titles`), one
/// row per group, like rliable's interval plots, into a PNG at `out`; the x axis spans
/// `x_range` (scores).
pub(crate) fn draw_intervals(
    rows: &[IntervalRow],
    titles: &[&str],
    x_range: (f64, f64),
    caption: &str,
    palette: &[&str],
    out: &Path,
) -> Result<(), PlotError> {
    prepare_png(out)?;
    let n = rows.len().max(1);
    let width = 450 * titles.len().max(1) as u32;
    let height = 120 + 45 * n as u32;
    let mut root = BitMapBackend::new(out, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    if !caption.is_empty() {
        root = root.titled(caption, ("sans-serif", 18)).map_err(draw_err)?;
    }
    let names: Vec<String> = rows.iter().map(|(name, runs, _)| runs_label(name, *runs)).collect();
    let label = |y: &f64| {
        let i = y.round();
        if (y - i).abs() < 1e-6 && i >= 0.0 {
            names.get(i as usize).cloned().unwrap_or_default()
        } else {
            String::new()
        }
    };
    let areas = root.split_evenly((1, titles.len().max(1)));
    for (k, (area, title)) in areas.iter().zip(titles).enumerate() {
        let mut chart = ChartBuilder::on(area)
            .caption(*title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(if k == 0 { 170 } else { 10 })
            .build_cartesian_2d(x_range.0..x_range.1, -0.5..(n as f64 - 0.5))
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .y_labels(n)
            .y_label_formatter(&|y| if k == 0 { label(y) } else { String::new() })
            .disable_y_mesh()
            .draw()
            .map_err(draw_err)?;
        for (i, (name, _, estimates)) in rows.iter().enumerate() {
            let Some(e) = estimates.get(k) else { continue };
            let place = palette.iter().position(|p| p == name).unwrap_or(i);
            let color = Palette99::pick(place).to_rgba();
            let y = i as f64;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(e.ci_low, y - 0.3), (e.ci_high, y + 0.3)],
                    color.mix(0.45).filled(),
                )))
                .map_err(draw_err)?;
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(e.point, y - 0.35), (e.point, y + 0.35)],
                    BLACK.stroke_width(2),
                )))
                .map_err(draw_err)?;
        }
    }
    root.present().map_err(draw_err)
}

/// A legend entry: the group and how many runs it averages.
fn runs_label(name: &str, runs: usize) -> String {
    format!("{name} ({runs} run{})", if runs == 1 { "" } else { "s" })
}

/// A group's min-max band (light) and its mean line, labelled in the legend.
fn draw_band_and_mean(
    chart: &mut Chart,
    c: &[SpreadPoint],
    color: RGBAColor,
    label: String,
) -> Result<(), PlotError> {
    chart
        .draw_series(std::iter::once(Polygon::new(
            c.iter()
                .map(|p| (p.step, p.max))
                .chain(c.iter().rev().map(|p| (p.step, p.min)))
                .collect::<Vec<_>>(),
            color.mix(0.2),
        )))
        .map_err(draw_err)?;
    chart
        .draw_series(LineSeries::new(c.iter().map(|p| (p.step, p.mean)), color.stroke_width(2)))
        .map_err(draw_err)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
    Ok(())
}

/// The markdown table of final success rates, one row per experiment.
fn success_table(groups: &Groups) -> String {
    let mut table = String::from(
        "| experiment | runs | final success rate (mean) | runs that learned | selected snapshot: success on test grasps (mean) | learned |\n|---|---|---|---|---|---|\n",
    );
    let mean = |v: &[f64]| if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 };
    for (name, rs) in groups {
        let rates: Vec<f64> = rs.iter().filter_map(|r| r.final_success).collect();
        let learned = rs.iter().filter(|r| r.learned() == Some(true)).count();
        let selected: Vec<Selected> = rs.iter().filter_map(|r| r.selected).collect();
        let selected_cells = if selected.is_empty() {
            "- | -".to_owned()
        } else {
            let rates: Vec<f64> = selected.iter().map(|s| s.success_rate).collect();
            let learned = selected.iter().filter(|s| s.learned()).count();
            format!("{:.2} | {learned}/{}", mean(&rates), selected.len())
        };
        table.push_str(&format!(
            "| {name} | {} | {:.2} | {learned}/{} | {selected_cells} |\n",
            rs.len(),
            mean(&rates),
            rates.len()
        ));
    }
    table
}

/// One row per run: `run,experiment,learned,success_rate,env_steps,wall_s`, then model
/// selection's `selected_step,selected_success_rate,selected_learned` (empty fields where a
/// run has no final evaluation or no selection).
pub fn success_csv(runs: &[RunCurves]) -> String {
    let mut text = String::from(
        "run,experiment,learned,success_rate,env_steps,wall_s,selected_step,selected_success_rate,selected_learned\n",
    );
    let opt = |v: Option<String>| v.unwrap_or_default();
    for r in runs {
        let run = r
            .dir
            .file_name()
            .map_or_else(|| r.dir.display().to_string(), |n| n.to_string_lossy().into_owned());
        text.push_str(&format!(
            "{run},{},{},{},{},{},{},{},{}\n",
            r.experiment,
            opt(r.learned().map(|l| l.to_string())),
            opt(r.final_success.map(|s| format!("{s:.4}"))),
            opt(r.env_steps.map(|s| s.to_string())),
            opt(r.wall_s.map(|s| format!("{s:.0}"))),
            opt(r.selected.map(|s| s.selected_step.to_string())),
            opt(r.selected.map(|s| format!("{:.4}", s.success_rate))),
            opt(r.selected.map(|s| s.learned().to_string())),
        ));
    }
    text
}

/// The objects of the runs trained on several (`env.objects`), each once, in the order
/// they first appear.
fn multi_object_objects(runs: &[RunCurves]) -> Vec<vge_sim::ObjectShape> {
    let mut objects = Vec::new();
    for r in runs {
        let mut own = r.objects.clone();
        own.dedup();
        if own.iter().any(|o| *o != own[0]) {
            for &o in &r.objects {
                if !objects.contains(&o) {
                    objects.push(o);
                }
            }
        }
    }
    objects
}

/// Per-object curves of the runs trained on several objects, one column of panels per
/// object: each experiment's success on that object in the periodic evaluations (`eval.csv`'s
/// `<object>_success`) above its success in the training episodes (`metrics.csv`'s), mean and
/// min-max over seeds, into `<out stem>-per-object.png` beside `out` (a row no run has the
/// columns for is left out). Returns the file written, or `None` when no run trained on
/// several objects or none has per-object columns.
pub fn plot_per_object(runs: &[RunCurves], out: &Path) -> Result<Option<PathBuf>, PlotError> {
    let objects = multi_object_objects(runs);
    if objects.is_empty() {
        return Ok(None);
    }
    let stem = out.file_stem().map_or_else(|| "plot".to_owned(), |s| s.to_string_lossy().into_owned());
    let path = out.with_file_name(format!("{stem}-per-object.png"));
    // Each experiment keeps its colour in every panel.
    let mut palette: Vec<&str> = Vec::new();
    for r in runs {
        if !palette.contains(&r.experiment.as_str()) {
            palette.push(&r.experiment);
        }
    }
    // Per row (file) and object, each run's curve of that object's success, carried as its
    // evaluation curve.
    let rows =
        [(crate::run_dir::EVAL, "periodic evaluations"), (crate::run_dir::METRICS, "training episodes")];
    let mut per_panel: Vec<Vec<RunCurves>> = Vec::new();
    for (file, _) in &rows {
        for &object in &objects {
            let column = format!("{}_success", object.name());
            let mut curves = Vec::new();
            for r in runs.iter().filter(|r| r.objects.contains(&object)) {
                if let Some((step, success)) = object_success(&r.dir.join(file), &column)? {
                    curves.push(RunCurves { eval_step: step, eval_success: success, ..r.clone() });
                }
            }
            per_panel.push(curves);
        }
    }
    // A row no run has columns for (runs from a vge without per-object training columns)
    // is left out, not drawn empty.
    let (rows, per_row): (Vec<_>, Vec<_>) = rows
        .iter()
        .zip(per_panel.chunks(objects.len()))
        .filter(|(_, panels)| panels.iter().any(|c| !c.is_empty()))
        .map(|(row, panels)| (*row, panels.to_vec()))
        .unzip();
    let per_panel: Vec<Vec<RunCurves>> = per_row.concat();
    if rows.is_empty() {
        return Ok(None);
    }
    // The drawing borrows the path: it ends before the path is returned.
    {
        prepare_png(&path)?;
        let width = 420 * objects.len() as u32;
        let root = BitMapBackend::new(&path, (width, 400 * rows.len() as u32)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let root = root.titled("success per object", ("sans-serif", 20)).map_err(draw_err)?;
        let panels = root.split_evenly((rows.len(), objects.len()));
        let titles = rows
            .iter()
            .flat_map(|(_, what)| objects.iter().map(move |o| format!("the {o}: success, {what}")));
        for ((panel, title), curves) in panels.iter().zip(titles).zip(&per_panel) {
            let mut groups: Groups = BTreeMap::new();
            for r in curves {
                groups.entry(r.experiment.as_str()).or_default().push(r);
            }
            let drawn: Vec<Curve> = groups
                .iter()
                .map(|(name, rs)| (*name, spread(rs, |r| (&r.eval_step, &r.eval_success)), false))
                .collect();
            draw_panel(panel, &title, XAxis::EnvSteps, &drawn, &groups, &palette)?;
        }
        root.present().map_err(draw_err)?;
    }
    Ok(Some(path))
}

/// A curve's steps and values.
type StepsAndValues = (Vec<f64>, Vec<f64>);

/// `(step, success)` of a CSV's `column`; `None` when the file or the column is missing (a
/// run from before the per-object columns, or without periodic evaluations).
pub(crate) fn object_success(path: &Path, column: &str) -> Result<Option<StepsAndValues>, PlotError> {
    let Some(columns) = csv_columns_if_present(path, &["step", column])? else { return Ok(None) };
    let [step, success]: [Vec<f64>; 2] = columns
        .try_into()
        .map_err(|_| PlotError::Csv { path: path.to_owned(), message: "columns".into() })?;
    Ok(Some((step, success)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_must_be_whole_env_steps() {
        let path = Path::new("eval.csv");
        assert_eq!(whole_steps(path, &[0.0, 250_000.0, 2e6]).expect("whole"), [0, 250_000, 2_000_000]);
        for (step, row) in [(-5.0, 3), (12.7, 3), (f64::NAN, 3), (f64::INFINITY, 3), (1e30, 3)] {
            let err = whole_steps(path, &[100.0, step]).expect_err("refused").to_string();
            assert!(err.contains(&format!("row {row}: step `{step}` is not a whole number")), "{err}");
        }
    }

    #[test]
    fn an_infinite_q_is_left_out_of_the_panel_and_counted() {
        // A diverged critic logs inf or NaN as its mean Q.
        let point = |step, v| SpreadPoint { step, mean: v, min: v, max: v };
        let curve = vec![point(0.0, 1.0), point(1e4, f64::INFINITY), point(2e4, f64::NAN), point(3e4, 2.0)];
        let curves: Vec<Curve> = vec![("rl", curve, false)];
        let (kept, title) = drawable(&curves, "mean Q");
        assert_eq!(kept[0].1, [point(0.0, 1.0), point(3e4, 2.0)]);
        assert_eq!(title, "mean Q (2 non-finite points not drawn)");
        assert_eq!(drawable(&kept, "mean Q").1, "mean Q", "nothing left out, nothing said");
        // Drawn: plotters' axis fitting looped forever on the infinite point before.
        let dir = std::env::temp_dir().join(format!("vge-plot-inf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let out = dir.join("q.png");
        draw_panels(&[("mean Q", XAxis::EnvSteps, curves)], &Groups::new(), "", &["rl"], &out)
            .expect("drawn");
        assert!(std::fs::metadata(&out).expect("written").len() > 0);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_row_being_written_is_not_read_and_a_short_complete_row_is_refused_naming_it() {
        let dir = std::env::temp_dir().join(format!("vge-plot-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let csv = dir.join("eval.csv");
        // The last row has no newline yet: the writer is still at it.
        std::fs::write(&csv, "step,success,return\n100,0.5,3\n200,,4\n300,0.").expect("write");
        let columns = csv_columns(&csv, &["step", "success"]).expect("reads the complete rows");
        assert_eq!(columns[0], vec![100.0, 200.0]);
        assert!(columns[1][0] == 0.5 && columns[1][1].is_nan(), "an empty field is NaN: {columns:?}");
        assert_eq!(csv_columns_if_present(&csv, &["step", "mean_q"]).expect("reads"), None);
        assert_eq!(csv_columns_if_present(&dir.join("absent.csv"), &["step"]).expect("no file"), None);
        let err = csv_columns(&csv, &["step", "mean_q"]).expect_err("no such column").to_string();
        assert!(err.contains("no column `mean_q`"), "{err}");
        std::fs::write(&csv, "step,success,return\n100,0.5,3\n200,0.7\n").expect("write");
        let err = csv_columns(&csv, &["return"]).expect_err("a short row").to_string();
        assert!(err.contains("row 3 has 2 fields, the header 3: no `return`"), "{err}");
        assert_eq!(csv_columns(&csv, &["success"]).expect("the fields it has"), vec![vec![0.5, 0.7]]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_window_that_measured_nothing_is_left_out_of_the_curves_not_drawn_as_zero() {
        let dir = std::env::temp_dir().join(format!("vge-plot-empty-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
        let config = crate::config::load_config(&configs.join("cube-fg-rl.toml"), &[]).expect("config");
        std::fs::write(dir.join("config.toml"), config.to_toml_string().expect("toml")).expect("write");
        // No update before the first row ended (mean_q empty), no episode in the third.
        std::fs::write(
            dir.join(crate::run_dir::METRICS),
            "step,return,rotation,controller_share,mean_q\n\
             10000,1.0,0.1,1.0,\n20000,2.0,0.2,0.5,4.0\n30000,,,0.4,6.0\n40000,4.0,0.4,0.3,8.0\n",
        )
        .expect("write");
        let run = read_run(&dir).expect("read");
        assert!(run.mean_q[0].is_nan() && run.mean_return[2].is_nan(), "{run:?}");
        // mean Q starts where it was first measured; the return's gap is interpolated across.
        let q = on_common_grid(&[&run], |r| (&r.step, &r.mean_q));
        assert_eq!(q, vec![(20000.0, vec![4.0]), (30000.0, vec![6.0]), (40000.0, vec![8.0])]);
        let ret = on_common_grid(&[&run], |r| (&r.step, &r.mean_return));
        assert_eq!(ret, vec![(10000.0, vec![1.0]), (20000.0, vec![2.0]), (40000.0, vec![4.0])]);
        let mut rng = crate::compare::rng_for(0, "mean Q");
        let iqm =
            iqm_curve(&[&run, &run], |r| (&r.step, &r.mean_q), &crate::stats::Bootstrap::default(), &mut rng)
                .expect("no NaN reaches the statistics");
        assert_eq!(
            iqm.iter().map(|p| (p.step, p.mean)).collect::<Vec<_>>(),
            [(20000.0, 4.0), (30000.0, 6.0), (40000.0, 8.0)]
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_selection_on_several_objects_learned_only_if_every_object_passed() {
        let figures = |s: f64| {
            format!(
                r#"{{"success_rate": {s}, "drop_rate": 0, "mean_return": 0, "mean_rotation_rad": 0,
                   "mean_contact_switches": 0, "episodes": 20}}"#
            )
        };
        let selected = |cube: f64, sphere: f64| -> Selected {
            let json = format!(
                r#"{{"selected_step": 1500000, "success_rate": {}, "per_object":
                   {{"cube": {}, "sphere": {}}}}}"#,
                (cube + sphere) / 2.0,
                figures(cube),
                figures(sphere)
            );
            serde_json::from_str(&json).expect("best-eval.json")
        };
        // Pooled 0.6, but the sphere at 0.2: not learned.
        assert_eq!(selected(1.0, 0.2).worst_object_success_rate, Some(0.2));
        assert!(!selected(1.0, 0.2).learned());
        assert!(selected(1.0, 0.5).learned());
        let one: Selected =
            serde_json::from_str(r#"{"selected_step": 5, "success_rate": 0.5}"#).expect("one object");
        assert!(one.learned() && one.worst_object_success_rate.is_none());
    }

    #[test]
    fn interpolates_between_logged_steps_and_clamps_outside() {
        let xs = [0.0, 10.0, 20.0];
        let ys = [0.0, 1.0, 3.0];
        assert_eq!(interpolate(&xs, &ys, 5.0), 0.5);
        assert_eq!(interpolate(&xs, &ys, 15.0), 2.0);
        assert_eq!(interpolate(&xs, &ys, -1.0), 0.0);
        assert_eq!(interpolate(&xs, &ys, 99.0), 3.0);
    }
}
