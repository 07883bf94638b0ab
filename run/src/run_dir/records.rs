//! A run folder read whole, as `vge plot`, `vge compare` and Table I see it ([`RunCurves`]),
//! its JSON records (`final-eval.json`, `best-eval.json`, `score.json`), and the run folders
//! below a set of folders ([`find_runs`]).

use std::path::{Path, PathBuf};

use vge_controllers::ControllerKind;

use super::tables::{csv_columns, csv_columns_if_present};
use super::{RunDir, RunFileError};
use crate::config::{AlgorithmName, Config, Method};
use crate::eval::PerObjectFigures;

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
    /// The critic's gap per metrics window: `mean_q - mc_return` (NaN where a window lacks
    /// either; empty where the run logged neither).
    pub critic_gap: Vec<f64>,
    /// The same against the early steps' returns, which the time limit cuts by little:
    /// `mean_q - mc_return_early` (empty in runs that predate the column).
    pub critic_gap_early: Vec<f64>,
    /// The run config's hard stop (`vge.hard_stop`, env steps): where the guided methods'
    /// controllers stop acting; every config carries it, so runs compare at one step.
    pub hard_stop_step: u64,
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
    /// The run's score on many held-out episodes (`score.json`, written by `vge score` or the end of training); None
    /// until `vge score` (or the end of training) wrote it.
    pub score: Option<super::Score>,
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
    per_object: Option<PerObjectFigures>,
}

impl From<SelectedFields> for Selected {
    fn from(f: SelectedFields) -> Self {
        Self {
            selected_step: f.selected_step,
            success_rate: f.success_rate,
            worst_object_success_rate: f.per_object.as_ref().and_then(PerObjectFigures::worst_success_rate),
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

    /// The critic's gap at the end of the run ([`critic_gap_at_end`] of its metrics).
    pub fn critic_gap_at_end(&self) -> Option<f64> {
        critic_gap_at_end(&self.critic_gap)
    }

    /// [`Self::critic_gap_at_end`] against the early steps' returns (None in runs that
    /// predate them, or where episodes are too short to have early steps).
    pub fn critic_gap_early_at_end(&self) -> Option<f64> {
        critic_gap_at_end(&self.critic_gap_early)
    }

    /// The critic's gap at env step `step`: [`critic_gap_at_end`] of the metrics windows up to
    /// and including it. None where no window up to `step` has both figures, or where the run
    /// has not reached `step` (its gap there is not known yet).
    pub fn critic_gap_at_step(&self, step: u64) -> Option<f64> {
        critic_gap_at_step(&self.step, &self.critic_gap, step)
    }
}

/// [`RunCurves::critic_gap_at_step`] on a run's metrics steps and gaps (one per window).
#[must_use]
pub fn critic_gap_at_step(steps: &[f64], gaps: &[f64], step: u64) -> Option<f64> {
    let step = step as f64;
    if !steps.last().is_some_and(|&last| last >= step) {
        return None;
    }
    let upto = steps.iter().take_while(|&&s| s <= step).count().min(gaps.len());
    critic_gap_at_end(&gaps[..upto])
}

/// Metrics windows the critic's gap at the end of a run is averaged over: one window's gap
/// swings by tens.
pub const CRITIC_GAP_WINDOWS: usize = 3;

/// The critic's gap at the end of a run from its gap per metrics window (mean Q minus the
/// collected discounted Monte-Carlo return, NaN where a window lacks either): the mean over
/// the last [`CRITIC_GAP_WINDOWS`] windows that have both. Above 0 the critic overestimates
/// what the behaviour policy collected. None where no window has both.
#[must_use]
pub fn critic_gap_at_end(gaps: &[f64]) -> Option<f64> {
    let gaps: Vec<f64> = gaps.iter().copied().filter(|gap| gap.is_finite()).collect();
    let last = &gaps[gaps.len().saturating_sub(CRITIC_GAP_WINDOWS)..];
    (!last.is_empty()).then(|| last.iter().sum::<f64>() / last.len() as f64)
}

/// The fields of `final-eval.json` that the plot and `vge eval --run` read.
#[derive(Debug, serde::Deserialize)]
pub struct FinalEvalFields {
    pub success_rate: f64,
    /// Absent in files of older vge versions.
    #[serde(default)]
    pub mean_return: Option<f64>,
    #[serde(default)]
    pub mean_rotation_rad: Option<f64>,
    #[serde(default)]
    pub mean_contact_switches: Option<f64>,
    #[serde(default)]
    pub mean_tip_slip_m: Option<f64>,
    pub env_steps: u64,
    pub wall_s: f64,
    #[serde(default)]
    pub cpu_s: Option<f64>,
    #[serde(default)]
    pub per_object: Option<PerObjectFigures>,
}

/// Reads one run directory.
pub fn read_run(dir: &Path) -> Result<RunCurves, RunFileError> {
    let config = RunDir::new(dir).read_config()?;
    let experiment = experiment(&config);
    let metrics = RunDir::new(dir).metrics();
    let cols = csv_columns(&metrics, &["step", "return", "rotation", "controller_share"])?;
    let [step, mean_return, rotation_rad, controller_share]: [Vec<f64>; 4] = cols
        .try_into()
        .map_err(|_| RunFileError::Format { path: metrics.clone(), message: "columns".into() })?;
    // Columns later vge versions added: empty for the runs from before them.
    let optional = |name: &str| {
        csv_columns_if_present(&metrics, &[name])
            .map(|c| c.and_then(|c| c.into_iter().next()).unwrap_or_default())
    };
    let (mean_q, mc_return) = (optional("mean_q")?, optional("mc_return")?);
    let critic_gap = mean_q.iter().zip(&mc_return).map(|(q, r)| q - r).collect();
    let critic_gap_early = mean_q.iter().zip(&optional("mc_return_early")?).map(|(q, r)| q - r).collect();
    let final_eval = read_final_eval(dir)?;
    let eval = RunDir::new(dir).eval_csv();
    let [eval_step, eval_return, eval_success]: [Vec<f64>; 3] = if eval.exists() {
        csv_columns(&eval, &["step", "return", "success"])?
            .try_into()
            .map_err(|_| RunFileError::Format { path: eval.clone(), message: "columns".into() })?
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
        .and_then(PerObjectFigures::worst_success_rate);
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
        critic_gap,
        critic_gap_early,
        hard_stop_step: config.vge.hard_stop,
        eval_step,
        eval_return,
        eval_success,
        final_success,
        final_worst_object_success,
        final_return: final_eval.as_ref().and_then(|f| f.mean_return),
        final_contact_switches: final_eval.as_ref().and_then(|f| f.mean_contact_switches),
        env_steps: final_eval.as_ref().map(|f| f.env_steps),
        wall_s: final_eval.as_ref().map(|f| f.wall_s),
        selected: read_json(&RunDir::new(dir).best_eval())?,
        score: read_json(&RunDir::new(dir).score())?,
    })
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

/// `dir/final-eval.json`; `None` when the run has none (unfinished).
pub fn read_final_eval(dir: &Path) -> Result<Option<FinalEvalFields>, RunFileError> {
    read_json(&RunDir::new(dir).final_eval())
}

/// A JSON file of a run, if it exists.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Option<T>, RunFileError> {
    if !path.exists() {
        return Ok(None);
    }
    let text = crate::read_limits::read_to_string_bounded(path, crate::read_limits::MAX_RECORD_FILE_LEN)
        .map_err(|source| RunFileError::Io { path: path.to_owned(), source })?;
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| RunFileError::Format { path: path.to_owned(), message: e.to_string() })
}

/// Every run folder at or below `roots` (a folder with `config.toml` and `metrics.csv`;
/// subfolders are searched in name order, three levels down at most), each once however
/// the roots overlap.
pub fn find_runs(roots: &[PathBuf]) -> Result<Vec<PathBuf>, RunFileError> {
    fn walk(dir: &Path, depth: usize, found: &mut Vec<PathBuf>) -> Result<(), RunFileError> {
        let run = RunDir::new(dir);
        if run.config().is_file() && run.metrics().is_file() {
            found.push(dir.to_owned());
            return Ok(());
        }
        if depth == 0 {
            return Ok(());
        }
        let io = |source| RunFileError::Io { path: dir.to_owned(), source };
        let mut subdirs: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(io)?
            .map(|e| e.map(|e| e.path()))
            .collect::<Result<Vec<_>, _>>()
            .map_err(io)?
            .into_iter()
            .filter(|p| p.is_dir())
            .collect();
        subdirs.sort();
        subdirs.iter().try_for_each(|d| walk(d, depth - 1, found))
    }
    let mut found = Vec::new();
    for root in roots {
        if !root.is_dir() {
            return Err(RunFileError::Io {
                path: root.clone(),
                source: std::io::Error::new(std::io::ErrorKind::NotFound, "not a folder"),
            });
        }
        walk(root, 3, &mut found)?;
    }
    let mut seen = std::collections::HashSet::new();
    found.retain(|d| seen.insert(std::fs::canonicalize(d).unwrap_or_else(|_| d.clone())));
    Ok(found)
}

/// Whether the run in `dir` finished: `policy.vgep` parses and its CRC holds, and
/// `final-eval.json` (written after it, and last of all) parses. Err: what is missing or
/// wrong, naming the file.
pub fn check_finished(dir: &Path) -> Result<(), String> {
    let policy = RunDir::new(dir).policy();
    vge_export::PolicyFile::read(&policy).map_err(|e| match &e {
        vge_export::ExportError::Io { source, .. } => format!("{e}: {source}"),
        _ => format!("{}: {e}", policy.display()),
    })?;
    let path = RunDir::new(dir).final_eval();
    match read_final_eval(dir) {
        Ok(Some(_)) => Ok(()),
        Ok(None) => Err(format!("{} is missing", path.display())),
        Err(e) => Err(e.to_string()),
    }
}

/// The step of a run directory's last checkpoint (`state.toml` of the folder a resume reads,
/// [`RunDir::resume_checkpoint`]), for messages: the checkpoint is not verified here.
pub fn checkpoint_step(dir: &Path) -> Option<u64> {
    let ckpt = RunDir::new(dir).resume_checkpoint()?;
    let path = ckpt.join(super::CHECKPOINT_STATE);
    let text =
        crate::read_limits::read_to_string_bounded(&path, crate::read_limits::MAX_RECORD_FILE_LEN).ok()?;
    let table: toml::Table = toml::from_str(&text).ok()?;
    u64::try_from(table.get("step")?.as_integer()?).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_critic_gap_at_the_end_averages_the_last_windows_with_both_figures() {
        let nan = f64::NAN;
        // Windows: gaps 100, 1, (no return), 2, 3, (no Q), 7.
        let q = [110.0, 11.0, 5.0, 12.0, 13.0, nan, 17.0];
        let ret = [10.0, 10.0, nan, 10.0, 10.0, 4.0, 10.0];
        let gaps: Vec<f64> = q.iter().zip(&ret).map(|(q, r)| q - r).collect();
        assert_eq!(critic_gap_at_end(&gaps), Some((2.0 + 3.0 + 7.0) / 3.0));
        assert_eq!(critic_gap_at_end(&gaps[..2]), Some((100.0 + 1.0) / 2.0), "fewer windows");
        assert_eq!(critic_gap_at_end(&[]), None, "a run that predates the columns");
        assert_eq!(critic_gap_at_end(&[nan - 1.0]), None);
    }

    #[test]
    fn the_critic_gap_at_a_step_reads_only_the_windows_up_to_it() {
        let nan = f64::NAN;
        let steps = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0];
        let gaps = [1.0, 2.0, nan, 4.0, 8.0, 16.0];
        // At 40: the last three windows with both figures up to 40 (10, 20, 40).
        assert_eq!(critic_gap_at_step(&steps, &gaps, 40), Some((1.0 + 2.0 + 4.0) / 3.0));
        // Between windows: those before it.
        assert_eq!(critic_gap_at_step(&steps, &gaps, 55), Some((2.0 + 4.0 + 8.0) / 3.0));
        assert_eq!(critic_gap_at_step(&steps, &gaps, 60), critic_gap_at_end(&gaps), "the end");
        assert_eq!(critic_gap_at_step(&steps, &gaps, 5), None, "no window yet");
        assert_eq!(critic_gap_at_step(&steps, &gaps, 61), None, "a run that has not reached it");
        assert_eq!(critic_gap_at_step(&steps, &[], 40), None, "a run that predates the columns");
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
    fn records_written_before_the_slip_figure_still_read() {
        let old = r#"{"success_rate": 0.5, "mean_contact_switches": 3.0, "env_steps": 10, "wall_s": 1.0}"#;
        let f: FinalEvalFields = serde_json::from_str(old).expect("old final-eval.json");
        assert_eq!((f.mean_contact_switches, f.mean_tip_slip_m), (Some(3.0), None));
        let new = old.replace("\"env_steps\"", "\"mean_tip_slip_m\": 0.25, \"env_steps\"");
        let f: FinalEvalFields = serde_json::from_str(&new).expect("new final-eval.json");
        assert_eq!(f.mean_tip_slip_m, Some(0.25));

        let policy = r#"{"file": "policy.vgep", "step": 5, "crc32": 7, "success_rate": 1.0,
            "mean_return": 2.0, "drop_rate": 0.0, "mean_rotation_rad": 7.0, "mean_contact_switches": 4.0}"#;
        let old: super::super::PolicyScore = serde_json::from_str(policy).expect("old score.json entry");
        assert_eq!(old.mean_tip_slip_m, None);
        let scored = super::super::PolicyScore { mean_tip_slip_m: Some(1.5), ..old };
        let text = serde_json::to_string(&scored).expect("json");
        let back: super::super::PolicyScore = serde_json::from_str(&text).expect("read back");
        assert_eq!(back.mean_tip_slip_m, Some(1.5), "{text}");
    }
}
