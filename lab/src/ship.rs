//! Choosing and shipping a trained policy. [`screen`] (`vge screen`) tests a run's passing
//! snapshots and its final policy on episodes the run never saw: the success test and the two
//! pushes at the object's weight. [`ship`] (`vge ship`) copies one policy and its run's config
//! to a policies folder and measures the copy (the success test, the robustness test on every
//! axis), writing `NAME.json` with the goals and whether each holds, `NAME-robustness.png`
//! and the gait diagram of one episode.
//!
//! Both measure on the run's own task ([`vge_run::run_eval::task_envs`]): its object, hand,
//! physics and reward, without its training disturbances, so that a policy trained on a
//! task variant (a heavier cube, the hand on its side) is judged on that variant. A policy
//! trained on several objects is measured on each: the success test and the pushes pooled
//! over them, and `vge ship` records every object's figures (`per_object`).

use std::path::{Path, PathBuf};

use serde::Serialize;
use thiserror::Error;
use vge_sim::EnvConfig;

use crate::plot::PlotError;
use crate::robustness::{self, Axis, RobustnessOptions, RobustnessReport};
use vge_run::eval::{self, EvalError, EvalReport, ObjectFigures};
use vge_run::run_dir::{self, RunDir};

#[derive(Debug, Error)]
pub enum ShipError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{path}: {message}")]
    Run { path: String, message: String },
    #[error("{path}: {message}")]
    Json { path: String, message: String },
    #[error(transparent)]
    Eval(#[from] EvalError),
    #[error(transparent)]
    Plot(#[from] PlotError),
    #[error(transparent)]
    RunFile(#[from] vge_run::run_dir::RunFileError),
    #[error(transparent)]
    Export(#[from] vge_export::ExportError),
    #[error(transparent)]
    RunConfig(#[from] vge_run::run_eval::RunEvalError),
    #[error(transparent)]
    Gait(#[from] crate::gait_diagram::DrawEpisodeError),
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> ShipError + '_ {
    move |source| ShipError::Io { path: path.display().to_string(), source }
}

/// The success a policy needs in the success test to be shipped, and the share of its clean
/// return it must keep at each robustness axis's paper level.
pub const SHIP_MIN_SUCCESS: f64 = 0.8;
/// A policy for several objects: the success it needs on each object after the first (the
/// first, the cube in the multi-object configs, needs [`SHIP_MIN_SUCCESS`]).
pub const SHIP_MIN_SUCCESS_OTHER_OBJECTS: f64 = 0.5;
pub const SHIP_MIN_RETURN_FRACTION: f64 = 0.75;

/// The episodes [`screen`] runs per test, and their first seed: far from training's
/// evaluation seeds, so that no screened policy was selected on them.
#[derive(Debug, Clone, PartialEq)]
pub struct ScreenOptions {
    pub episodes: usize,
    pub seed: u64,
    /// A snapshot is screened when its periodic test (eval.csv) reached this success.
    pub min_success: f64,
}

impl Default for ScreenOptions {
    fn default() -> Self {
        Self { episodes: 20, seed: 11_000, min_success: SHIP_MIN_SUCCESS }
    }
}

/// One screened policy: `step` is the snapshot's env step, or `None` for the final policy.
#[derive(Debug, Clone, PartialEq)]
pub struct ScreenRow {
    pub step: Option<u64>,
    pub policy: PathBuf,
    pub success: EvalReport,
    /// The push of the object's weight in size, random direction (`perturbation_magnitude_n`
    /// at its paper level), and the Gaussian push with the weight as each component's std
    /// (`perturbation_force_n`).
    pub push_magnitude: PushFigures,
    pub push_std: PushFigures,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PushFigures {
    /// Mean return as a fraction of the undisturbed return (NaN when that is <= 0).
    pub return_fraction: f64,
    pub success_rate: f64,
}

/// The policies a screen tests: the snapshots whose periodic test passed, oldest first, then
/// the final policy unless it is byte for byte one of them.
pub fn screen_candidates(run: &Path, min_success: f64) -> Result<Vec<(Option<u64>, PathBuf)>, ShipError> {
    let dir = RunDir::new(run);
    let eval_csv = dir.eval_csv();
    if !eval_csv.exists() {
        return Err(ShipError::Run {
            path: eval_csv.display().to_string(),
            message: "missing: the run has no periodic tests to screen".into(),
        });
    }
    let [steps, success]: [Vec<f64>; 2] = vge_run::run_dir::csv_columns(&eval_csv, &["step", "success"])?
        .try_into()
        .map_err(|_| ShipError::Run { path: eval_csv.display().to_string(), message: "columns".into() })?;
    let mut out = Vec::new();
    for (step, success) in vge_run::run_dir::whole_steps(&eval_csv, &steps)?.into_iter().zip(success) {
        let path = dir.snapshot(step);
        if success >= min_success && path.exists() {
            out.push((Some(step), path));
        }
    }
    let final_policy = dir.policy();
    if final_policy.exists() {
        let read = |p: &Path| {
            vge_run::read_limits::read_bounded(p, vge_export::MAX_FILE_LEN as u64).map_err(io_err(p))
        };
        let bytes = read(&final_policy)?;
        let mut same = false;
        for (_, p) in &out {
            same |= read(p)? == bytes;
        }
        if !same {
            out.push((None, final_policy));
        }
    }
    Ok(out)
}

/// Screens `candidates` (from [`screen_candidates`]) of the run in `run` on its task
/// ([`vge_run::run_eval::task_envs`]) with the success test and the two pushes, each pooled over
/// the run's objects; `on_row` sees each row as it is measured.
pub fn screen(
    run: &Path,
    candidates: &[(Option<u64>, PathBuf)],
    options: &ScreenOptions,
    mut on_row: impl FnMut(&ScreenRow),
) -> Result<Vec<ScreenRow>, ShipError> {
    let bases = vge_run::run_eval::task_envs(&vge_run::run_eval::run_config(run)?)?;
    let success_envs = success_test_envs(&bases);
    let pushes = RobustnessOptions {
        episodes: options.episodes,
        episode_s: eval::SUCCESS_TEST_EPISODE_S,
        grasp_noise_rad: eval::SUCCESS_TEST_GRASP_NOISE_RAD,
        seed: options.seed,
        levels: 2,
        axes: vec![Axis::PerturbationMagnitude, Axis::Perturbation],
    };
    let mut rows = Vec::with_capacity(candidates.len());
    for (step, policy) in candidates {
        let bytes = eval::read_policy_file(policy)?;
        let success =
            eval::eval_policy_bytes_per_object(&bytes, &success_envs, options.episodes, options.seed)?
                .overall;
        let report = robustness::run_objects(&bytes, &bases, &pushes, |_| {})?;
        let at_paper_level = |axis: Axis| {
            let r = report.rows.iter().find(|r| r.axis == axis.name() && r.fraction_of_max == 1.0);
            r.map_or(PushFigures { return_fraction: f64::NAN, success_rate: f64::NAN }, |r| PushFigures {
                return_fraction: r.return_fraction,
                success_rate: r.success_rate,
            })
        };
        let row = ScreenRow {
            step: *step,
            policy: policy.clone(),
            success,
            push_magnitude: at_paper_level(Axis::PerturbationMagnitude),
            push_std: at_paper_level(Axis::Perturbation),
        };
        on_row(&row);
        rows.push(row);
    }
    Ok(rows)
}

/// The file [`screen`]'s rows are written to in the run's folder.
pub const SCREEN_CSV: &str = "screen.csv";

/// `screen.csv`: one row per policy (`final` for the final policy's step).
pub fn screen_csv(rows: &[ScreenRow]) -> String {
    let mut text = String::from(
        "step,success,drops,rotation_rad,push_magnitude_return_fraction,push_magnitude_success,\
         push_std_return_fraction,push_std_success\n",
    );
    let frac = |f: f64| if f.is_finite() { format!("{f:.2}") } else { "nan".to_owned() };
    for r in rows {
        let step = r.step.map_or_else(|| "final".to_owned(), |s| s.to_string());
        text.push_str(&format!(
            "{step},{:.2},{:.2},{:.1},{},{:.2},{},{:.2}\n",
            r.success.success_rate,
            r.success.drop_rate,
            r.success.mean_rotation_rad,
            frac(r.push_magnitude.return_fraction),
            r.push_magnitude.success_rate,
            frac(r.push_std.return_fraction),
            r.push_std.success_rate,
        ));
    }
    text
}

/// What `vge ship` writes to `NAME.json`.
#[derive(Debug, Clone, Serialize)]
pub struct ShipRecord {
    /// The run folder, as given.
    pub source_run: String,
    /// The shipped file, relative to the run folder.
    pub source_policy: String,
    /// The policy file's provenance, as `vge inspect` prints it.
    pub provenance: String,
    pub success_test: EvalReport,
    pub robustness: RobustnessReport,
    /// Per axis: the return at the paper's level as a fraction of the clean return.
    pub return_fraction_at_paper_level: std::collections::BTreeMap<String, f64>,
    /// The goals, each with whether it holds: success >= 0.8 in the success test, and >= 0.75
    /// of the clean return at each axis's paper level; the push "at the object's weight" read
    /// as the paper's, a force of that size in a random direction.
    pub goals: std::collections::BTreeMap<String, bool>,
    /// Measured beside the goals: the Gaussian push with the weight as each component's std
    /// (1.6 times the weight on average), and for a policy of several objects the other
    /// objects' returns at the paper's levels.
    pub beside_goals: std::collections::BTreeMap<String, bool>,
    /// A policy trained on several objects: each object's success test and its robustness at
    /// the paper's level of every axis, in the order the run trained them. `success_test`,
    /// above, pools their episodes; `robustness` (all levels, and the figure) is the first
    /// object's. Absent for a single object.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub per_object: Vec<ShippedObject>,
}

/// One object of a policy trained on several: what `vge ship` measured on it.
#[derive(Debug, Clone, Serialize)]
pub struct ShippedObject {
    pub object: String,
    pub success_test: ObjectFigures,
    /// Per axis, at the paper's level: the return as a fraction of this object's clean
    /// return, and the success rate.
    pub return_fraction_at_paper_level: std::collections::BTreeMap<String, f64>,
    pub success_at_paper_level: std::collections::BTreeMap<String, f64>,
}

impl ShipRecord {
    /// Every goal holds.
    pub fn qualifies(&self) -> bool {
        self.goals.values().all(|&ok| ok)
    }
}

/// The files [`ship`] writes into the policies folder for `name`.
#[derive(Debug, Clone, PartialEq)]
pub struct ShippedFiles {
    pub policy: PathBuf,
    pub config: PathBuf,
    pub record: PathBuf,
    pub robustness_png: PathBuf,
    /// The gait diagram of the success test's first episode; for a policy of several objects
    /// all of them, one panel per object, beside one file per object
    /// ([`ShippedFiles::gait_png_of`]).
    pub gait_png: PathBuf,
}

impl ShippedFiles {
    pub fn new(policies: &Path, name: &str) -> Self {
        Self {
            policy: policies.join(format!("{name}.vgep")),
            config: policies.join(format!("{name}.toml")),
            record: policies.join(format!("{name}.json")),
            robustness_png: policies.join(format!("{name}-robustness.png")),
            gait_png: policies.join(format!("{name}-gait.png")),
        }
    }

    /// The first of the policy file, its config and its record that already exists: a gait
    /// shipped under this name, which shipping again would replace.
    pub fn already_shipped(&self) -> Option<&Path> {
        [&self.policy, &self.config, &self.record].into_iter().map(PathBuf::as_path).find(|p| p.exists())
    }

    /// `NAME-gait-OBJECT.png`: the gait diagram on one object of a policy of several.
    pub fn gait_png_of(&self, object: vge_sim::ObjectShape) -> PathBuf {
        crate::gait_diagram::per_object_png(&self.gait_png, object)
    }

    /// The gait diagram of each of `objects`: `NAME-gait.png` for one object, else one
    /// `NAME-gait-OBJECT.png` per object.
    fn gait_png_per_object(&self, objects: &[vge_sim::ObjectShape]) -> Vec<PathBuf> {
        match objects {
            [_] => vec![self.gait_png.clone()],
            many => many.iter().map(|&o| self.gait_png_of(o)).collect(),
        }
    }

    /// The gait diagrams [`ship`] writes for a run trained on `objects`: the per-object
    /// files and, for several objects, `NAME-gait.png` with all of them.
    pub fn gait_pngs(&self, objects: &[vge_sim::ObjectShape]) -> Vec<PathBuf> {
        let mut pngs = self.gait_png_per_object(objects);
        if objects.len() > 1 {
            pngs.push(self.gait_png.clone());
        }
        pngs
    }
}

/// What [`ship`] ships and how it measures it.
#[derive(Debug, Clone, PartialEq)]
pub struct ShipOptions {
    /// The policy file to ship, relative to the run folder: `policy.vgep` (the final policy),
    /// `policy-best.vgep` (the snapshot the run's selection picked) or
    /// `snapshots/policy-STEP.vgep`.
    pub policy: String,
    /// Episodes of the success test, and per robustness level.
    pub success_episodes: usize,
    pub robustness_episodes: usize,
    pub robustness_levels: usize,
}

impl Default for ShipOptions {
    fn default() -> Self {
        Self {
            policy: run_dir::POLICY.to_owned(),
            success_episodes: eval::SUCCESS_TEST_EPISODES,
            robustness_episodes: 10,
            robustness_levels: 5,
        }
    }
}

/// Copies the run's policy and config to `files`, measures the copy and writes the record,
/// the robustness figure and the gait diagrams, whose paths it returns beside the record.
/// `on_row` sees each robustness row of the first object as it is measured.
pub fn ship(
    run: &Path,
    files: &ShippedFiles,
    options: &ShipOptions,
    on_row: impl FnMut(&robustness::RobustnessRow),
) -> Result<(ShipRecord, Vec<PathBuf>), ShipError> {
    let dir = RunDir::new(run);
    let source = run.join(&options.policy);
    for needed in [source.clone(), dir.config(), dir.final_eval()] {
        if !needed.exists() {
            return Err(ShipError::Run {
                path: needed.display().to_string(),
                message: "missing: not a finished training run".into(),
            });
        }
    }
    // Measured before anything is written: a policy that cannot be read replaces nothing.
    let bytes = eval::read_policy_file(&source)?;
    let provenance = provenance_line(&bytes)?;
    let bases = vge_run::run_eval::task_envs(&vge_run::run_eval::run_config(run)?)?;
    let success_envs = success_test_envs(&bases);
    let success_test =
        eval::eval_policy_bytes_per_object(&bytes, &success_envs, options.success_episodes, 0)?;
    let robustness =
        robustness::run(&bytes, &bases[0], &robustness_options(options, options.robustness_levels), on_row)?;
    // Every object at the paper's levels; the first object's full test already holds them.
    let mut at_paper_level = Vec::new();
    if bases.len() > 1 {
        at_paper_level.push(robustness.clone());
        for base in &bases[1..] {
            at_paper_level.push(robustness::run(&bytes, base, &robustness_options(options, 2), |_| {})?);
        }
    }
    let record = record(run, options, provenance, &success_test, robustness, &at_paper_level);

    if let Some(parent) = files.policy.parent() {
        std::fs::create_dir_all(parent).map_err(io_err(parent))?;
    }
    vge_run::run_dir::atomic_file::write(&files.policy, &bytes).map_err(io_err(&files.policy))?;
    let config = vge_run::read_limits::read_bounded(&dir.config(), vge_run::read_limits::MAX_CONFIG_FILE_LEN)
        .map_err(io_err(&dir.config()))?;
    vge_run::run_dir::atomic_file::write(&files.config, &config).map_err(io_err(&files.config))?;
    robustness::plot(&record.robustness, &files.robustness_png)?;
    let objects: Vec<_> = bases.iter().map(|b| b.object.shape).collect();
    let label = files.policy.display().to_string();
    // The success test's first episode on each object.
    let per_object = files.gait_png_per_object(&objects);
    let panels: Vec<(&vge_sim::EnvConfig, &Path)> =
        success_envs.iter().zip(per_object.iter().map(PathBuf::as_path)).collect();
    crate::gait_diagram::draw_episodes(&bytes, &panels, 0, &label, &files.gait_png)?;
    let gait_pngs = files.gait_pngs(&objects);
    let mut json = serde_json::to_string_pretty(&record)
        .map_err(|e| ShipError::Json { path: files.record.display().to_string(), message: e.to_string() })?;
    json.push('\n');
    vge_run::run_dir::atomic_file::write(&files.record, json.as_bytes()).map_err(io_err(&files.record))?;
    Ok((record, gait_pngs))
}

/// The success test's env on each of `bases`.
fn success_test_envs(bases: &[EnvConfig]) -> Vec<EnvConfig> {
    bases
        .iter()
        .map(|b| eval::success_test_env(b, eval::SUCCESS_TEST_EPISODE_S, eval::SUCCESS_TEST_GRASP_NOISE_RAD))
        .collect()
}

/// The robustness test `vge ship` runs: every axis, `levels` levels up to the paper's.
fn robustness_options(options: &ShipOptions, levels: usize) -> RobustnessOptions {
    RobustnessOptions {
        episodes: options.robustness_episodes,
        episode_s: eval::SUCCESS_TEST_EPISODE_S,
        grasp_noise_rad: eval::SUCCESS_TEST_GRASP_NOISE_RAD,
        seed: 0,
        levels,
        axes: Axis::ALL.to_vec(),
    }
}

/// Per axis, at the paper's level: the return as a fraction of the clean one, and the success.
fn paper_level(report: &RobustnessReport) -> [std::collections::BTreeMap<String, f64>; 2] {
    let rows = report.rows.iter().filter(|r| r.fraction_of_max == 1.0);
    [
        rows.clone().map(|r| (r.axis.to_owned(), r.return_fraction)).collect(),
        rows.map(|r| (r.axis.to_owned(), r.success_rate)).collect(),
    ]
}

fn record(
    run: &Path,
    options: &ShipOptions,
    provenance: String,
    success_test: &eval::ObjectsReport,
    robustness: RobustnessReport,
    per_object_robustness: &[RobustnessReport],
) -> ShipRecord {
    let [at_paper_level, _] = paper_level(&robustness);
    // Goal names carry the object where there are several: `cube: success_rate >= 0.8`.
    let several = success_test.per_object.len() > 1;
    let named = |object: vge_sim::ObjectShape, goal: String| {
        if several { format!("{}: {goal}", object.name()) } else { goal }
    };
    let first = success_test.per_object.first().map_or(vge_sim::ObjectShape::Cube, |(o, _)| *o);
    let mut goals = std::collections::BTreeMap::new();
    let mut beside_goals = std::collections::BTreeMap::new();
    if several {
        for (k, (object, report)) in success_test.per_object.iter().enumerate() {
            let min = if k == 0 { SHIP_MIN_SUCCESS } else { SHIP_MIN_SUCCESS_OTHER_OBJECTS };
            goals.insert(named(*object, format!("success_rate >= {min}")), report.success_rate >= min);
        }
    } else {
        goals.insert(
            format!("success_rate >= {SHIP_MIN_SUCCESS}"),
            success_test.overall.success_rate >= SHIP_MIN_SUCCESS,
        );
    }
    let return_goal =
        |axis: &str| format!("{axis}: return at the paper's level >= {SHIP_MIN_RETURN_FRACTION} of clean");
    for (axis, &fraction) in &at_paper_level {
        // NaN (no clean return to compare with) holds nothing.
        let holds = fraction >= SHIP_MIN_RETURN_FRACTION;
        if axis == Axis::Perturbation.name() {
            beside_goals.insert(named(first, return_goal(axis)), holds);
        } else {
            goals.insert(named(first, return_goal(axis)), holds);
        }
    }
    let mut per_object = Vec::new();
    for (k, ((object, report), robustness)) in
        success_test.per_object.iter().zip(per_object_robustness).enumerate()
    {
        let [return_fraction_at_paper_level, success_at_paper_level] = paper_level(robustness);
        if k > 0 {
            for (axis, &fraction) in &return_fraction_at_paper_level {
                beside_goals.insert(named(*object, return_goal(axis)), fraction >= SHIP_MIN_RETURN_FRACTION);
            }
        }
        per_object.push(ShippedObject {
            object: object.name().to_owned(),
            success_test: ObjectFigures::of(report),
            return_fraction_at_paper_level,
            success_at_paper_level,
        });
    }
    ShipRecord {
        source_run: run.display().to_string(),
        source_policy: options.policy.clone(),
        provenance,
        success_test: success_test.overall.clone(),
        robustness,
        return_fraction_at_paper_level: at_paper_level,
        goals,
        beside_goals,
        per_object,
    }
}

/// The provenance line `vge inspect` prints for the policy file's bytes, without its label.
fn provenance_line(bytes: &[u8]) -> Result<String, ShipError> {
    let report = vge_export::inspect::report(bytes)?;
    let pv = &report.policy.provenance;
    Ok(format!("vge {}, config {}, seed {}, {} steps", pv.vge_version, pv.config_hash, pv.seed, pv.steps))
}
