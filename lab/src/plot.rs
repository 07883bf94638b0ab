//! `vge plot`: training curves of runs grouped by experiment (mean and min-max spread over
//! seeds), like the paper's figures, the critic's mean Q beside the discounted Monte-Carlo
//! returns of the data it learns from, and a markdown table of final success rates, like its
//! Table I. A run's final success is that of its `final-eval.json` (the success test of
//! [`vge_run::eval`]) or else its last periodic evaluation; a run *learned* when it reaches
//! [`vge_run::eval::LEARNED_SUCCESS_RATE`]. The runs are read by [`vge_run::run_dir::read_run`];
//! this module only draws.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use thiserror::Error;

use vge_run::run_dir::{RunCurves, RunFileError, Selected, object_success};

#[derive(Debug, Error)]
pub enum PlotError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    /// A file the lab reads beside the runs (a controller's figures) that does not say what
    /// it must.
    #[error("{path}: {message}")]
    Csv { path: PathBuf, message: String },
    #[error("no run directories given")]
    NoRuns,
    #[error("no font for the plot's text: {0}")]
    Font(String),
    #[error("drawing: {0}")]
    Draw(String),
    /// A run's file that cannot be read (the message names the file).
    #[error(transparent)]
    Run(#[from] RunFileError),
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
    let specs: [PanelSpec; 5] = [
        ("episode return", |r| (&r.step, &r.mean_return), None),
        ("rotation about z per episode (rad)", |r| (&r.step, &r.rotation_rad), None),
        ("controller share", |r| (&r.step, &r.controller_share), None),
        (
            "mean Q (solid) vs Monte-Carlo return (dashed)",
            |r| (&r.step, &r.mean_q),
            Some(|r| (&r.step, &r.mc_return)),
        ),
        // Their difference, which the runs' critic tables and budget rules read.
        ("critic gap: mean Q - Monte-Carlo return", |r| (&r.step, &r.critic_gap), None),
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
        [(vge_run::run_dir::EVAL, "periodic evaluations"), (vge_run::run_dir::METRICS, "training episodes")];
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

#[cfg(test)]
mod tests {
    use super::*;

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
    fn a_window_that_measured_nothing_is_left_out_of_the_curves_not_drawn_as_zero() {
        let dir = std::env::temp_dir().join(format!("vge-plot-empty-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
        let config = vge_run::config::load_config(&configs.join("cube-fg-rl.toml"), &[]).expect("config");
        std::fs::write(dir.join("config.toml"), config.to_toml_string().expect("toml")).expect("write");
        // No update before the first row ended (mean_q empty), no episode in the third.
        std::fs::write(
            dir.join(vge_run::run_dir::METRICS),
            "step,return,rotation,controller_share,mean_q\n\
             10000,1.0,0.1,1.0,\n20000,2.0,0.2,0.5,4.0\n30000,,,0.4,6.0\n40000,4.0,0.4,0.3,8.0\n",
        )
        .expect("write");
        let run = vge_run::run_dir::read_run(&dir).expect("read");
        assert!(run.mean_q[0].is_nan() && run.mean_return[2].is_nan(), "{run:?}");
        // mean Q starts where it was first measured; the return's gap is interpolated across.
        let q = on_common_grid(&[&run], |r| (&r.step, &r.mean_q));
        assert_eq!(q, vec![(20000.0, vec![4.0]), (30000.0, vec![6.0]), (40000.0, vec![8.0])]);
        let ret = on_common_grid(&[&run], |r| (&r.step, &r.mean_return));
        assert_eq!(ret, vec![(10000.0, vec![1.0]), (20000.0, vec![2.0]), (40000.0, vec![4.0])]);
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0);
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
    fn interpolates_between_logged_steps_and_clamps_outside() {
        let xs = [0.0, 10.0, 20.0];
        let ys = [0.0, 1.0, 3.0];
        assert_eq!(interpolate(&xs, &ys, 5.0), 0.5);
        assert_eq!(interpolate(&xs, &ys, 15.0), 2.0);
        assert_eq!(interpolate(&xs, &ys, -1.0), 0.0);
        assert_eq!(interpolate(&xs, &ys, 99.0), 3.0);
    }
}
