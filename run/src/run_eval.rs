//! A run's success tests during and after training, on the exported actor and the runtime, and model
//! selection: every periodic evaluation keeps its actor in `snapshots/`, and at the end the
//! snapshot with the best validation evaluation is reported on held-out test grasps
//! (`policy-best.vgep`, `best-eval.json`) apart from the final policy (`final-eval.json`).
//!
//! A run on several objects (`env.objects`) is tested on each of them: `run.eval_episodes`
//! episodes per object, every object on the same episode seeds, for every snapshot alike.
//! `eval.csv` then gains each object's columns (`cube_success`, `cube_return`, ...), the
//! JSON files a `per_object` table, and the overall figures (all episodes pooled, i.e. the
//! mean over objects) stay where they were. Selection ranks snapshots by their worst
//! object's success, then the mean success, then the mean return ([`best_eval_row`]): a
//! policy for five objects is only as good as its worst, and the mean alone would prefer a
//! snapshot that turns four objects perfectly and drops the fifth. With one object the rule
//! is the single-object one, and a single-object run writes exactly what it wrote before.

use std::fs::File;
use std::path::{Path, PathBuf};

use serde::Serialize;
use thiserror::Error;
use vge_sim::{EnvConfig, ObjectShape};

use crate::config::{Config, ConfigError};
use crate::eval::{EpisodeOutcome, EvalError, EvalReport, ObjectsReport, PerObjectFigures};
use crate::run_dir::RunDir;

/// Why a run's evaluation could not be made or written.
#[derive(Debug, Error)]
pub enum RunEvalError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Eval(#[from] EvalError),
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{path}: not a finished run's file: {what}")]
    NotFinished { path: String, what: String },
    #[error(transparent)]
    Lock(#[from] crate::run_dir::lock::LockError),
    #[error(transparent)]
    RunFile(#[from] crate::run_dir::RunFileError),
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> RunEvalError + '_ {
    move |source| RunEvalError::Io { path: path.display().to_string(), source }
}

/// Cost of a run up to some moment, as `final-eval.json` records it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunCost {
    pub wall_s: f64,
    /// None when an earlier session was run by a vge that did not count it.
    pub cpu_s: Option<f64>,
}

/// The effective configuration stored in a run folder (`config.toml`), validated.
pub fn run_config(dir: &Path) -> Result<Config, RunEvalError> {
    let config = RunDir::new(dir).read_config()?;
    config.validate()?;
    Ok(config)
}

/// The success test's env for a run's object `index` (of `env.objects`): that object's env
/// without the disturbances it may train with (a config with domain randomisation is judged
/// by the same test as any other), `run.eval_episode_s` long, grasps randomised by
/// `run.eval_grasp_noise_rad`.
pub(crate) fn success_test_env_of(config: &Config, index: usize) -> Result<EnvConfig, EvalError> {
    let run = &config.run;
    Ok(crate::eval::success_test_env(&task_env(config, index)?, run.eval_episode_s, run.eval_grasp_noise_rad))
}

/// The task of a run's object `index` (of `env.objects`): its object, hand, physics and reward,
/// without the disturbances it may train with.
fn task_env(config: &Config, index: usize) -> Result<EnvConfig, EvalError> {
    Ok(crate::eval::without_training_disturbances(&config.env_config(index)?))
}

/// The task a run's policies are judged on, one env per object it trains on (in the order of
/// [`training_objects`], [`task_env`] each). `vge ship` and `vge screen` measure policies on these.
pub fn task_envs(config: &Config) -> Result<Vec<EnvConfig>, EvalError> {
    training_objects(config).into_iter().map(|(index, _)| task_env(config, index)).collect()
}

/// The objects a run trains on, each once, in the order of `env.objects` (a list may name
/// one twice to give it more envs), with the index of its first place there.
pub(crate) fn training_objects(config: &Config) -> Vec<(usize, ObjectShape)> {
    let mut seen = Vec::new();
    for (i, &object) in config.env.objects.iter().enumerate() {
        if !seen.iter().any(|&(_, o)| o == object) {
            seen.push((i, object));
        }
    }
    seen
}

/// Whether the run trains on more than one object (and is tested per object).
fn is_multi_object(config: &Config) -> bool {
    training_objects(config).len() > 1
}

/// The success test ([`crate::eval`]) of an exported actor (policy-file bytes) on the
/// runtime: `run.eval_episodes` episodes of [`success_test_env_of`] per training object,
/// seeded from the config's seed only (training is not perturbed), every object on the same
/// seeds.
fn evaluate_policy(config: &Config, bytes: &[u8], set: EpisodeSet) -> Result<ObjectsReport, RunEvalError> {
    let run = &config.run;
    let eval_seed = set.first_seed(config.seed);
    let episodes = run.eval_episodes;
    let objects = training_objects(config);
    if let [(index, object)] = objects.as_slice() {
        // One object: the single-object test as it always ran.
        let env = success_test_env_of(config, *index)?;
        let report = crate::eval::eval_policy_bytes(bytes, &env, episodes, eval_seed)?;
        return Ok(ObjectsReport { overall: report.clone(), per_object: vec![(*object, report)] });
    }
    let envs: Vec<EnvConfig> =
        objects.iter().map(|&(i, _)| success_test_env_of(config, i)).collect::<Result<_, _>>()?;
    Ok(crate::eval::eval_policy_bytes_per_object(bytes, &envs, episodes, eval_seed)?)
}

/// The per-object figures a JSON file holds: only for a run on several objects (a
/// single-object run's files stay as they were).
fn per_object_figures(r: &ObjectsReport) -> Option<PerObjectFigures> {
    (r.per_object.len() > 1).then(|| r.figures())
}

/// Whether a policy with this report learned: its success rate reaches
/// [`crate::eval::LEARNED_SUCCESS_RATE`], on every object for a run on several.
fn learned(r: &ObjectsReport) -> bool {
    r.overall.learned() && r.every_object_learned()
}

pub use crate::episode_sets::EpisodeSet;

fn snapshot_path(out_dir: &Path, step: u64) -> PathBuf {
    RunDir::new(out_dir).snapshot(step)
}

/// One row of `eval.csv`, as model selection reads it.
#[derive(Debug, Clone, Copy)]
struct EvalRow {
    step: u64,
    mean_return: f64,
    /// Over all episodes (the mean over objects).
    success: f64,
    /// The lowest of the objects' success rates (`success` for a single-object run).
    worst_object_success: f64,
}

/// The evaluation row model selection picks ([module docs](self)): highest success rate of
/// the worst object, then highest mean success rate, then highest return, then the earlier
/// step. With one object: highest success rate, then return, then the earlier step.
fn best_eval_row(rows: &[EvalRow]) -> Option<EvalRow> {
    let key = |r: &EvalRow| (r.worst_object_success, r.success, r.mean_return);
    rows.iter().copied().fold(None, |best: Option<EvalRow>, r| match best {
        Some(b) if key(&b) >= key(&r) => Some(b),
        _ => Some(r),
    })
}

/// `eval.csv`'s column `{object}_{figure}` for a run on several objects.
fn object_column(object: ObjectShape, figure: &str) -> String {
    format!("{}_{figure}", object.name())
}

/// A policy's success test as `final-eval.json` and `best-eval.json` both record it, in
/// their key order (each file adds its own keys).
#[derive(Debug, Serialize)]
struct TestFigures<'a> {
    /// Whether the policy learned (success rate >= [`crate::eval::LEARNED_SUCCESS_RATE`], on
    /// every object for a run on several).
    learned: bool,
    success_rate: f64,
    episodes: usize,
    mean_return: f64,
    mean_rotation_rad: f64,
    drop_rate: f64,
    mean_contact_switches: f64,
    /// Fingertip slip per episode (m, [`vge_sim::slip`]).
    mean_tip_slip_m: f64,
    /// How far the axis the object turned about overall leans from z (rad, mean over the
    /// episodes): near 0 for a finger gait, large for a policy that tumbles the object.
    mean_rotation_axis_tilt_rad: f64,
    /// Several objects: each object's figures (the overall ones above pool them).
    #[serde(skip_serializing_if = "Option::is_none")]
    per_object: Option<PerObjectFigures>,
    per_episode: &'a [EpisodeOutcome],
}

impl<'a> TestFigures<'a> {
    fn of(report: &'a ObjectsReport) -> Self {
        let r = &report.overall;
        Self {
            learned: learned(report),
            success_rate: r.success_rate,
            episodes: r.episodes,
            mean_return: r.mean_return,
            mean_rotation_rad: r.mean_rotation_rad,
            drop_rate: r.drop_rate,
            mean_contact_switches: r.mean_contact_switches,
            mean_tip_slip_m: r.mean_tip_slip_m,
            mean_rotation_axis_tilt_rad: r.mean_rotation_axis_tilt_rad,
            per_object: per_object_figures(report),
            per_episode: &r.per_episode,
        }
    }
}

/// What `best-eval.json` holds: which snapshot was selected on the validation episodes, and
/// its success test on the held-out test episodes.
#[derive(Debug, Serialize)]
struct BestEval<'a> {
    selected_step: u64,
    validation_success_rate: f64,
    /// Several objects: the lowest object success rate on the validation episodes, what the
    /// selection ranked by first.
    #[serde(skip_serializing_if = "Option::is_none")]
    validation_worst_object_success_rate: Option<f64>,
    validation_mean_return: f64,
    /// The selected policy on the test episodes.
    #[serde(flatten)]
    test: TestFigures<'a>,
}

/// Model selection ([module docs](self)): copies the best snapshot to `policy-best.vgep` and
/// writes its test-set evaluation to `best-eval.json`. A run without periodic evaluations
/// (or without their snapshots, as runs older than this rule) has nothing to select from.
fn select_best_snapshot(out_dir: &Path, config: &Config) -> Result<(), RunEvalError> {
    let csv_path = out_dir.join(crate::run_dir::EVAL);
    if !csv_path.exists() {
        return Ok(());
    }
    let columns = crate::run_dir::csv_columns(&csv_path, &["step", "return", "success"])
        .map_err(|e| io_err(&csv_path)(std::io::Error::other(e)))?;
    let multi = is_multi_object(config);
    let per_object_success: Vec<Vec<f64>> = if multi {
        let names: Vec<String> =
            training_objects(config).iter().map(|&(_, o)| object_column(o, "success")).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        crate::run_dir::csv_columns(&csv_path, &names)
            .map_err(|e| io_err(&csv_path)(std::io::Error::other(e)))?
    } else {
        Vec::new()
    };
    let rows: Vec<EvalRow> = match columns.as_slice() {
        [step, ret, success] => (0..step.len())
            .map(|i| EvalRow {
                step: step[i] as u64,
                mean_return: ret[i],
                success: success[i],
                worst_object_success: per_object_success.iter().map(|c| c[i]).fold(success[i], f64::min),
            })
            .collect(),
        _ => Vec::new(),
    };
    let Some(best) = best_eval_row(&rows) else { return Ok(()) };
    let snapshot = snapshot_path(out_dir, best.step);
    let bytes = match crate::eval::read_policy_file(&snapshot) {
        Ok(b) => b,
        Err(crate::eval::EvalError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            // Not eprintln!: a closed stderr must not stop the run that is finishing.
            let _ = std::io::Write::write_fmt(
                &mut std::io::stderr(),
                format_args!("model selection skipped: {} is missing\n", snapshot.display()),
            );
            return Ok(());
        }
        Err(e) => return Err(e.into()),
    };
    let r = evaluate_policy(config, &bytes, EpisodeSet::Test)?;
    let path = out_dir.join(crate::run_dir::POLICY_BEST);
    crate::run_dir::atomic_file::write(&path, &bytes).map_err(io_err(&path))?;
    let doc = BestEval {
        selected_step: best.step,
        validation_success_rate: best.success,
        validation_worst_object_success_rate: multi.then_some(best.worst_object_success),
        validation_mean_return: best.mean_return,
        test: TestFigures::of(&r),
    };
    let path = out_dir.join(crate::run_dir::BEST_EVAL);
    let text = serde_json::to_string_pretty(&doc).map_err(|e| io_err(&path)(std::io::Error::other(e)))?;
    crate::run_dir::atomic_file::write(&path, (text + "\n").as_bytes()).map_err(io_err(&path))
}

const EVAL_HEADER: &str = "step,episodes,return,rotation,success,drops,contacts,contact_switches";

/// The figures of each object's columns in `eval.csv` (a run on several objects), in order.
const OBJECT_FIGURES: [&str; 5] = ["success", "return", "rotation", "drops", "contact_switches"];

/// Appends one evaluation to `eval.csv`: the overall figures, then, for a run on several
/// objects, each object's [`OBJECT_FIGURES`].
fn append_eval_row(out_dir: &Path, step: u64, report: &ObjectsReport) -> Result<(), RunEvalError> {
    let path = out_dir.join(crate::run_dir::EVAL);
    let new = !path.exists();
    let file = File::options().append(true).create(true).open(&path).map_err(io_err(&path))?;
    let mut writer = csv::WriterBuilder::new().has_headers(false).from_writer(file);
    let csv_err = |e: csv::Error| io_err(&path)(std::io::Error::other(e));
    let per_object: &[(ObjectShape, EvalReport)] =
        if report.per_object.len() > 1 { &report.per_object } else { &[] };
    if new {
        let mut header: Vec<String> = EVAL_HEADER.split(',').map(str::to_owned).collect();
        for (object, _) in per_object {
            header.extend(OBJECT_FIGURES.iter().map(|f| object_column(*object, f)));
        }
        writer.write_record(&header).map_err(csv_err)?;
    }
    let fraction = |x: f64| format!("{x:.4}");
    let r = &report.overall;
    let mut record = vec![
        step.to_string(),
        r.episodes.to_string(),
        format!("{:.6}", r.mean_return),
        format!("{:.6}", r.mean_rotation_rad),
        fraction(r.success_rate),
        fraction(r.drop_rate),
        fraction(r.mean_contacts),
        fraction(r.mean_contact_switches),
    ];
    for (_, r) in per_object {
        record.extend([
            fraction(r.success_rate),
            format!("{:.6}", r.mean_return),
            format!("{:.6}", r.mean_rotation_rad),
            fraction(r.drop_rate),
            fraction(r.mean_contact_switches),
        ]);
    }
    writer.write_record(&record).map_err(csv_err)?;
    writer.flush().map_err(io_err(&path))
}

/// What `final-eval.json` holds: the test's settings, what the run cost, and the final
/// policy's success test.
#[derive(Debug, Serialize)]
struct FinalEval<'a> {
    episode_s: f32,
    grasp_noise_rad: f32,
    env_steps: u64,
    /// Wall time of the training run, pauses and time waiting for a core included.
    wall_s: f64,
    /// CPU time of the training process, all threads (absent where a session of the run was
    /// made by a vge that did not count it).
    #[serde(skip_serializing_if = "Option::is_none")]
    cpu_s: Option<f64>,
    /// The final policy on the test episodes.
    #[serde(flatten)]
    test: TestFigures<'a>,
}

fn write_final_eval(
    out_dir: &Path,
    config: &Config,
    report: &ObjectsReport,
    env_steps: u64,
    cost: RunCost,
) -> Result<(), RunEvalError> {
    let path = out_dir.join(crate::run_dir::FINAL_EVAL);
    let doc = FinalEval {
        episode_s: config.run.eval_episode_s,
        grasp_noise_rad: config.run.eval_grasp_noise_rad,
        env_steps,
        wall_s: cost.wall_s,
        cpu_s: cost.cpu_s,
        test: TestFigures::of(report),
    };
    let text = serde_json::to_string_pretty(&doc).map_err(|e| io_err(&path)(std::io::Error::other(e)))?;
    crate::run_dir::atomic_file::write(&path, (text + "\n").as_bytes()).map_err(io_err(&path))
}

/// A finished run's final policy scored again by the success test of this vge (the same
/// config, episodes and grasps as its `final-eval.json`): for runs scored by an older test.
#[derive(Debug, Clone)]
pub struct Rescored {
    /// This vge's success test of `DIR/policy.vgep` (all objects' episodes pooled).
    pub report: EvalReport,
    /// Each object's report, for a run on several objects (empty for one).
    pub per_object: Vec<(ObjectShape, EvalReport)>,
    /// The success rate `DIR/final-eval.json` held before, when it could be read.
    pub stored_success_rate: Option<f64>,
    /// The rotation (rad per episode) `DIR/final-eval.json` held before.
    pub stored_rotation_rad: Option<f64>,
}

/// Re-runs the final success test of the finished run in `dir`; with `write`, replaces its
/// `final-eval.json` (keeping `env_steps`, `wall_s` and `cpu_s`, which describe the training
/// run).
pub fn rescore_final_eval(dir: &Path, write: bool) -> Result<Rescored, RunEvalError> {
    let config = run_config(dir)?;
    let stored = crate::run_dir::read_final_eval(dir);
    // What --write keeps must be there before the episodes run.
    let kept = match (&stored, write) {
        (Ok(Some(s)), true) => Some((s.env_steps, RunCost { wall_s: s.wall_s, cpu_s: s.cpu_s })),
        (_, false) => None,
        (Ok(None), true) => {
            return Err(RunEvalError::NotFinished {
                path: dir.join(crate::run_dir::FINAL_EVAL).display().to_string(),
                what: "no env_steps and wall_s to keep".to_owned(),
            });
        }
        (Err(e), true) => {
            return Err(RunEvalError::NotFinished {
                path: dir.join(crate::run_dir::FINAL_EVAL).display().to_string(),
                what: e.to_string(),
            });
        }
    };
    // --write replaces a file of the run: as its one writer.
    let _lock = if write { Some(crate::run_dir::lock::RunLock::acquire(dir)?) } else { None };
    let policy = dir.join(crate::run_dir::POLICY);
    let bytes = crate::eval::read_policy_file(&policy)?;
    let report = evaluate_policy(&config, &bytes, EpisodeSet::Validation)?;
    if let Some((env_steps, cost)) = kept {
        write_final_eval(dir, &config, &report, env_steps, cost)?;
    }
    let stored = stored.ok().flatten();
    let per_object = if report.per_object.len() > 1 { report.per_object } else { Vec::new() };
    Ok(Rescored {
        stored_success_rate: stored.as_ref().map(|s| s.success_rate),
        stored_rotation_rad: stored.as_ref().and_then(|s| s.mean_rotation_rad),
        report: report.overall,
        per_object,
    })
}

/// The periodic evaluation at `step`: the actor (policy-file `bytes`) on the validation
/// episodes of every training object, a row of `eval.csv`, and the actor kept as a snapshot.
/// Returns the report.
pub fn periodic(
    out_dir: &Path,
    config: &Config,
    step: u64,
    bytes: &[u8],
) -> Result<ObjectsReport, RunEvalError> {
    let report = evaluate_policy(config, bytes, EpisodeSet::Validation)?;
    append_eval_row(out_dir, step, &report)?;
    let dir = RunDir::new(out_dir).snapshots();
    std::fs::create_dir_all(&dir).map_err(io_err(&dir))?;
    let path = snapshot_path(out_dir, step);
    crate::run_dir::atomic_file::write(&path, bytes).map_err(io_err(&path))?;
    Ok(report)
}

/// The end of a run: `policy.vgep`, model selection and, last, the policy's evaluation
/// (`final-eval.json`).
/// `evaluated` is the validation report of these very `bytes` when a periodic evaluation
/// already ran them at this step (the evaluation is deterministic: the same episodes again
/// would give the same report).
pub fn finish(
    out_dir: &Path,
    config: &Config,
    bytes: &[u8],
    step: u64,
    cost: RunCost,
    evaluated: Option<ObjectsReport>,
) -> Result<PathBuf, RunEvalError> {
    let path = out_dir.join(crate::run_dir::POLICY);
    crate::run_dir::atomic_file::write(&path, bytes).map_err(io_err(&path))?;
    let report = match evaluated {
        Some(report) => report,
        None => evaluate_policy(config, bytes, EpisodeSet::Validation)?,
    };
    select_best_snapshot(out_dir, config)?;
    // Last: a run is finished once its final-eval.json is in place (vge-lab's `sweep::check_finished`).
    write_final_eval(out_dir, config, &report, step, cost)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_with_domain_randomisation_is_judged_by_the_clean_success_test() {
        let mut config = Config::default();
        config.env.control_hz = 30.0;
        config.env.max_action_rad = 0.04;
        config.env.terminate_below_contacts = 3;
        config.env.noise_normal_std_frac = 0.25;
        config.env.perturb_force_std_n = 0.75;
        config.env.perturb_change_probability = 0.1;
        config.env.mass_scale = [0.8, 1.2];
        config.env.action_latency_steps = 1;
        config.env.drop_penalty = 30.0;
        let env = success_test_env_of(&config, 0).expect("env");
        let nominal = EnvConfig::default();
        assert_eq!(env.noise, nominal.noise);
        assert_eq!(env.perturbation, nominal.perturbation);
        assert_eq!(env.randomization, nominal.randomization);
        assert_eq!(env.min_contacts, 0, "the paper's ends: a drop or the time limit");
        assert_eq!(env.drop_penalty, 0.0, "the paper's return");
        // What defines the task stays the run's.
        assert_eq!((env.control_hz, env.max_action_rad), (30.0, 0.04));
        assert_eq!(env.episode_length_steps, (config.run.eval_episode_s * 30.0).round() as usize);
        assert_eq!(env.grasp.pose_noise_rad, config.run.eval_grasp_noise_rad);
    }

    #[test]
    fn model_selection_takes_success_then_return_then_the_earlier_step() {
        let row = |step, mean_return, success| EvalRow {
            step,
            mean_return,
            success,
            worst_object_success: success,
        };
        assert!(best_eval_row(&[]).is_none());
        let rows =
            [row(1, 50.0, 0.2), row(2, 40.0, 0.8), row(3, 90.0, 0.8), row(4, 90.0, 0.8), row(5, 300.0, 0.1)];
        assert_eq!(best_eval_row(&rows).map(|r| r.step), Some(3));
    }

    #[test]
    fn model_selection_across_objects_takes_the_worst_object_then_the_mean_then_return() {
        let row = |step, mean_return, success, worst_object_success| EvalRow {
            step,
            mean_return,
            success,
            worst_object_success,
        };
        // Step 1 turns four objects perfectly and drops the fifth (mean 0.8, worst 0); step 2
        // turns every object half the time: the worst object decides.
        let rows =
            [row(1, 90.0, 0.8, 0.0), row(2, 40.0, 0.5, 0.5), row(3, 30.0, 0.6, 0.5), row(4, 50.0, 0.6, 0.5)];
        assert_eq!(best_eval_row(&rows).map(|r| r.step), Some(4), "worst, then mean, then return");
    }

    #[test]
    fn a_multi_object_run_is_tested_once_on_each_of_its_objects() {
        use ObjectShape::{Cube, Sphere};
        let mut config = Config::default();
        assert!(!is_multi_object(&config));
        config.env.objects = vec![Cube, Sphere, Cube];
        assert_eq!(training_objects(&config), vec![(0, Cube), (1, Sphere)]);
        assert!(is_multi_object(&config));
        let envs: Vec<ObjectShape> = training_objects(&config)
            .iter()
            .map(|&(i, _)| success_test_env_of(&config, i).expect("env").object.shape)
            .collect();
        assert_eq!(envs, vec![Cube, Sphere]);
        config.env.objects = vec![Sphere, Sphere];
        assert!(!is_multi_object(&config), "one object named twice is one object");
    }
}
