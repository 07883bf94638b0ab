//! A run's score (`vge score`, and training at its end): its policies on many held-out
//! episodes, so that runs can be aggregated with confidence intervals (vge-lab's statistics).
//!
//! A finished run folder is scored on [`DEFAULT_EPISODES`] (or `--episodes N`) episodes of
//! its own success test (its config's task without the disturbances it may train with,
//! `run.eval_episode_s` long, grasps randomised by `run.eval_grasp_noise_rad`: 30 s and
//! 0.02 rad in every stored config), from env seeds [`HELD_OUT_SEED`] + k. Those seeds are
//! the same for every run (so runs meet the same episodes) and apart from the validation and
//! test episodes training drew (refused if they ever met; [`check_held_out`]), so nothing
//! the run selected on is reused. Three policies are scored on them:
//!
//! - `selected`: the run's own model selection, `policy-best.vgep` at `best-eval.json`'s
//!   `selected_step` (null for a run without periodic snapshots, which has no selection);
//! - `final`: `policy.vgep`, the paper's rule (its step: `final-eval.json`'s `env_steps`);
//! - `last_snapshots`: where the last [`LAST_SNAPSHOTS`] periodic snapshots (`snapshots/`,
//!   the steps of the last rows of `eval.csv`) are all kept, the mean of their figures (and
//!   each one's), a less noisy view of where the run ended than one policy.
//!
//! A run on several objects (`env.objects`) is scored on the episodes above for *each* of
//! its objects (the same seeds for every object): each policy's figures are then those of
//! all its episodes pooled, with `per_object` beside them (the fields of `final-eval.json`'s
//! `per_object`), as its training's evaluations report them.
//!
//! Written to `DIR/score.json` whole or not at all (temporary file and rename). A run whose
//! score.json already holds the same definition, episodes, seed and policy files (their
//! CRC-32) is skipped. An unfinished run (no `final-eval.json`) is refused and nothing is
//! written; a missing, damaged or other-layout policy file fails naming the file.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use thiserror::Error;
use vge_sim::EnvConfig;

use crate::config::Config;
use crate::episode_sets::EpisodeSet;
use crate::eval::{EpisodeOutcome, EvalError, ObjectFigures, PerObjectFigures};
use crate::run_dir::RunDir;

/// The score's file in a run folder.
pub const SCORE_FILE: &str = crate::run_dir::SCORE;
/// What a score means; a different definition is scored again, never compared.
pub const DEFINITION: &str = "held-out success test v1";
/// Episodes per policy by default (and at the end of training), and the env seed of the
/// first (episode k: this + k).
pub use crate::episode_sets::{HELD_OUT_EPISODES as DEFAULT_EPISODES, HELD_OUT_SEED};
/// Periodic snapshots whose mean is scored beside the selected and final policies.
pub const LAST_SNAPSHOTS: usize = 3;

#[derive(Debug, Error)]
pub enum ScoreError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{dir}: not a finished run ({what}); nothing written")]
    Unfinished { dir: PathBuf, what: String },
    #[error("{path}: {message}")]
    RunFile { path: PathBuf, message: String },
    /// A run's file that cannot be read (the message names it).
    #[error(transparent)]
    Read(#[from] crate::run_dir::RunFileError),
    #[error("policy file {path}: {message}")]
    Policy { path: PathBuf, message: String },
    #[error("scoring {path}: {source}")]
    Eval { path: PathBuf, source: EvalError },
    #[error(
        "held-out episodes {first}..{end} meet the run's {set} episodes from seed {theirs} (run seed {seed}): \
         choose another --seed"
    )]
    Overlap { first: u64, end: u64, set: &'static str, theirs: u64, seed: u64 },
    #[error("--episodes must be at least 1")]
    NoEpisodes,
}

/// `score.json`'s record (its readers and writer are the run folder's).
pub use crate::run_dir::{PolicyScore, Score, SnapshotsScore};

/// How to score.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScoreOptions {
    pub episodes: usize,
    pub seed: u64,
    /// Score again even when score.json holds this very score.
    pub force: bool,
}

impl Default for ScoreOptions {
    fn default() -> Self {
        Self { episodes: DEFAULT_EPISODES, seed: HELD_OUT_SEED, force: false }
    }
}

/// Where a long scoring is: episodes done of all policies of the run.
#[derive(Debug, Clone, Copy)]
pub struct ScoreProgress<'a> {
    pub dir: &'a Path,
    /// The policy file being scored, relative to the run folder.
    pub file: &'a str,
    pub done: usize,
    pub total: usize,
}

/// What [`score_run`] did.
#[derive(Debug, Clone, PartialEq)]
pub enum ScoreOutcome {
    /// Scored now and written.
    Scored(Score),
    /// score.json already held this score.
    Skipped(Score),
}

/// Why a run's score lacks a part (for the caller to print).
pub type Notes = Vec<String>;

/// A policy file to score: its place, step and bytes.
struct PlannedPolicy {
    file: String,
    step: u64,
    bytes: Vec<u8>,
}

impl PlannedPolicy {
    fn read(dir: &Path, file: &str, step: u64, env: &EnvConfig) -> Result<Self, ScoreError> {
        let path = dir.join(file);
        let bytes =
            crate::read_limits::read_bounded(&path, vge_export::MAX_FILE_LEN as u64).map_err(|e| {
                ScoreError::Policy {
                    path: path.clone(),
                    message: if e.kind() == std::io::ErrorKind::NotFound {
                        "missing".to_owned()
                    } else {
                        e.to_string()
                    },
                }
            })?;
        check_policy(&path, &bytes, env)?;
        Ok(Self { file: file.to_owned(), step, bytes })
    }

    /// The file's CRC-32, as its format stores it: of everything before the 4-byte trailer,
    /// which holds that CRC (so the CRC of a whole valid file would be the same constant for
    /// every file). [`check_policy`] has verified the trailer.
    fn crc32(&self) -> u32 {
        crc32fast::hash(&self.bytes[..self.bytes.len().saturating_sub(4)])
    }
}

/// A policy file the evaluator can run on the hand: valid (framing, checksum, fields) and
/// of the hand's observation and action layouts. Checked before any episode runs, so that a
/// bad file fails at once, not after the others' episodes.
fn check_policy(path: &Path, bytes: &[u8], env: &EnvConfig) -> Result<(), ScoreError> {
    let bad = |message: String| ScoreError::Policy { path: path.to_owned(), message };
    let info =
        vge_runtime::policy::inspect(bytes).map_err(|e| bad(format!("not a valid policy file: {e}")))?;
    vge_sim::check_policy_interface(&info, &env.hand, &env.policy_layout()).map_err(bad)
}

/// The fields of `best-eval.json` and `final-eval.json` the score reads.
#[derive(Deserialize)]
struct BestEvalStep {
    selected_step: u64,
}
#[derive(Deserialize)]
struct FinalEvalSteps {
    env_steps: u64,
}

/// A record the score needs: an error when missing or unreadable.
fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, ScoreError> {
    crate::run_dir::read_json(path)?
        .ok_or_else(|| ScoreError::Io { path: path.to_owned(), source: std::io::ErrorKind::NotFound.into() })
}

/// The run's config (`DIR/config.toml`), validated.
fn run_config(dir: &Path) -> Result<Config, ScoreError> {
    let config = RunDir::new(dir).read_config()?;
    config
        .validate()
        .map_err(|e| ScoreError::RunFile { path: RunDir::new(dir).config(), message: e.to_string() })?;
    Ok(config)
}

/// The envs the run's policies are scored in: its success test's ([`crate::eval`]), one per
/// object it trains on, without training disturbances.
fn score_envs(config: &Config, dir: &Path) -> Result<Vec<EnvConfig>, ScoreError> {
    crate::run_eval::training_objects(config)
        .into_iter()
        .map(|(index, _)| crate::run_eval::success_test_env_of(config, index))
        .collect::<Result<_, _>>()
        .map_err(|e| ScoreError::RunFile { path: dir.join(crate::run_dir::CONFIG), message: e.to_string() })
}

/// Refuses held-out episodes that would meet the validation or test episodes training drew
/// ([`EpisodeSet`], `run.eval_episodes` each).
pub fn check_held_out(config: &Config, first: u64, episodes: usize) -> Result<(), ScoreError> {
    let n = config.run.eval_episodes as u64;
    let end = first.saturating_add(episodes as u64);
    for (episode_set, set) in EpisodeSet::ALL {
        let theirs = episode_set.first_seed(config.seed);
        if first < theirs.saturating_add(n) && theirs < end {
            return Err(ScoreError::Overlap { first, end, set, theirs, seed: config.seed });
        }
    }
    Ok(())
}

/// The policies of a finished run to score: selected (if any), final, last snapshots (if
/// all kept). Fails on an unfinished run and on a missing or bad policy file.
fn plan(
    dir: &Path,
    notes: &mut Notes,
    env: &EnvConfig,
) -> Result<(Option<PlannedPolicy>, PlannedPolicy, Vec<PlannedPolicy>), ScoreError> {
    if !dir.join(crate::run_dir::CONFIG).is_file() {
        return Err(ScoreError::RunFile {
            path: dir.join(crate::run_dir::CONFIG),
            message: "missing: not a run folder".to_owned(),
        });
    }
    let final_eval = dir.join(crate::run_dir::FINAL_EVAL);
    if !final_eval.is_file() {
        return Err(ScoreError::Unfinished {
            dir: dir.to_owned(),
            what: "no final-eval.json: training has not ended (`vge train --resume DIR` finishes it)"
                .to_owned(),
        });
    }
    let final_step = read_json::<FinalEvalSteps>(&final_eval)?.env_steps;
    let final_policy = PlannedPolicy::read(dir, crate::run_dir::POLICY, final_step, env)?;
    let best_eval = dir.join(crate::run_dir::BEST_EVAL);
    let selected = if best_eval.is_file() {
        let step = read_json::<BestEvalStep>(&best_eval)?.selected_step;
        Some(PlannedPolicy::read(dir, crate::run_dir::POLICY_BEST, step, env)?)
    } else {
        notes.push("no best-eval.json: the run has no model selection (no periodic snapshots)".to_owned());
        None
    };
    let eval_csv = dir.join(crate::run_dir::EVAL);
    let steps: Vec<u64> = if eval_csv.is_file() {
        let columns = crate::run_dir::csv_columns(&eval_csv, &["step"])?;
        crate::run_dir::whole_steps(&eval_csv, &columns.into_iter().next().unwrap_or_default())?
    } else {
        Vec::new()
    };
    let last = &steps[steps.len().saturating_sub(LAST_SNAPSHOTS)..];
    let files: Vec<(String, u64)> = last.iter().map(|s| (format!("snapshots/policy-{s}.vgep"), *s)).collect();
    let snapshots = if last.len() == LAST_SNAPSHOTS && files.iter().all(|(f, _)| dir.join(f).is_file()) {
        files.iter().map(|(f, s)| PlannedPolicy::read(dir, f, *s, env)).collect::<Result<Vec<_>, _>>()?
    } else {
        notes.push(format!(
            "the last {LAST_SNAPSHOTS} periodic snapshots are not all kept: no last_snapshots"
        ));
        Vec::new()
    };
    Ok((selected, final_policy, snapshots))
}

/// Whether `existing` is the score these options and files would give.
fn same_score(
    existing: &Score,
    options: &ScoreOptions,
    config: &Config,
    policies: (&Option<PlannedPolicy>, &PlannedPolicy, &[PlannedPolicy]),
) -> bool {
    let (selected, final_policy, snapshots) = policies;
    let same_file =
        |s: &PolicyScore, p: &PlannedPolicy| s.file == p.file && s.step == p.step && s.crc32 == p.crc32();
    let objects: Vec<_> = crate::run_eval::training_objects(config).into_iter().map(|(_, o)| o).collect();
    let same_objects = |s: &PolicyScore| match &s.per_object {
        Some(per_object) => objects.len() > 1 && per_object.objects() == objects,
        None => objects.len() == 1,
    };
    existing.definition == DEFINITION
        && existing.episodes == options.episodes
        && existing.selected.iter().chain([&existing.final_policy]).all(same_objects)
        && existing.seed == options.seed
        && existing.episode_s == config.run.eval_episode_s
        && existing.grasp_noise_rad == config.run.eval_grasp_noise_rad
        && match (&existing.selected, selected) {
            (Some(s), Some(p)) => same_file(s, p),
            (None, None) => true,
            _ => false,
        }
        && same_file(&existing.final_policy, final_policy)
        && match &existing.last_snapshots {
            Some(s) => {
                s.snapshots.len() == snapshots.len()
                    && s.snapshots.iter().zip(snapshots).all(|(s, p)| same_file(s, p))
            }
            None => snapshots.is_empty(),
        }
}

/// `DIR/score.json`, if the run has one (an error if it cannot be read).
pub fn read_score(dir: &Path) -> Result<Option<Score>, ScoreError> {
    Ok(crate::run_dir::read_json(&RunDir::new(dir).score())?)
}

/// Scores the finished run in `dir` ([module docs](self)) and writes `DIR/score.json`,
/// calling `progress` as episodes finish. Episodes run on rayon's current pool.
pub fn score_run(
    dir: &Path,
    options: &ScoreOptions,
    progress: &mut dyn FnMut(&ScoreProgress),
) -> Result<(ScoreOutcome, Notes), ScoreError> {
    if options.episodes == 0 {
        return Err(ScoreError::NoEpisodes);
    }
    let config = run_config(dir)?;
    let mut notes = Notes::new();
    let envs = score_envs(&config, dir)?;
    let task = envs.first().ok_or_else(|| ScoreError::RunFile {
        path: dir.join(crate::run_dir::CONFIG),
        message: "no object to score on".to_owned(),
    })?;
    let (selected, final_policy, snapshots) = plan(dir, &mut notes, task)?;
    check_held_out(&config, options.seed, options.episodes)?;
    if !options.force {
        // A score.json that cannot be read is scored again (and replaced).
        if let Ok(Some(existing)) = read_score(dir)
            && same_score(&existing, options, &config, (&selected, &final_policy, &snapshots))
        {
            return Ok((ScoreOutcome::Skipped(existing), notes));
        }
    }
    let all: Vec<&PlannedPolicy> = selected.iter().chain([&final_policy]).chain(&snapshots).collect();
    let per_policy = envs.len() * options.episodes;
    let total = all.len() * per_policy;
    let mut scores = Vec::with_capacity(all.len());
    for (k, p) in all.iter().enumerate() {
        let mut outcomes = Vec::with_capacity(per_policy);
        let mut per_object = Vec::with_capacity(envs.len());
        for env in &envs {
            let done_before = k * per_policy + outcomes.len();
            let object = run_policy(dir, p, env, options, &mut |done| {
                progress(&ScoreProgress { dir, file: &p.file, done: done_before + done, total });
            })?;
            per_object.push((env.object.shape, ObjectFigures::of(&crate::eval::summarise(&object))));
            outcomes.extend(object);
        }
        let report = crate::eval::summarise(&outcomes);
        scores.push(PolicyScore {
            file: p.file.clone(),
            step: p.step,
            crc32: p.crc32(),
            success_rate: report.success_rate,
            mean_return: report.mean_return,
            drop_rate: report.drop_rate,
            mean_rotation_rad: report.mean_rotation_rad,
            mean_contact_switches: report.mean_contact_switches,
            mean_tip_slip_m: Some(report.mean_tip_slip_m),
            mean_rotation_axis_tilt_rad: Some(report.mean_rotation_axis_tilt_rad),
            per_object: (per_object.len() > 1).then_some(PerObjectFigures(per_object)),
        });
    }
    let mut scores = scores.into_iter();
    let selected = selected.as_ref().and_then(|_| scores.next());
    let final_score = scores.next().ok_or_else(|| ScoreError::RunFile {
        path: dir.join(crate::run_dir::POLICY),
        message: "not scored".to_owned(),
    })?;
    let snapshot_scores: Vec<PolicyScore> = scores.collect();
    let score = Score {
        definition: DEFINITION.to_owned(),
        episodes: options.episodes,
        seed: options.seed,
        episode_s: config.run.eval_episode_s,
        grasp_noise_rad: config.run.eval_grasp_noise_rad,
        selected,
        final_policy: final_score,
        last_snapshots: (!snapshot_scores.is_empty()).then(|| mean_of_snapshots(snapshot_scores)),
    };
    let path = dir.join(SCORE_FILE);
    let text = serde_json::to_string_pretty(&score)
        .map_err(|e| ScoreError::RunFile { path: path.clone(), message: e.to_string() })?;
    crate::run_dir::atomic_file::write(&path, format!("{text}\n").as_bytes())
        .map_err(|source| ScoreError::Io { path, source })?;
    Ok((ScoreOutcome::Scored(score), notes))
}

fn mean_of_snapshots(snapshots: Vec<PolicyScore>) -> SnapshotsScore {
    let n = snapshots.len() as f64;
    let mean = |f: fn(&PolicyScore) -> f64| snapshots.iter().map(f).sum::<f64>() / n;
    SnapshotsScore {
        success_rate: mean(|s| s.success_rate),
        mean_return: mean(|s| s.mean_return),
        drop_rate: mean(|s| s.drop_rate),
        mean_rotation_rad: mean(|s| s.mean_rotation_rad),
        mean_contact_switches: mean(|s| s.mean_contact_switches),
        mean_tip_slip_m: mean_where_present(snapshots.iter().map(|s| s.mean_tip_slip_m)),
        mean_rotation_axis_tilt_rad: mean_where_present(
            snapshots.iter().map(|s| s.mean_rotation_axis_tilt_rad),
        ),
        snapshots,
    }
}

/// The mean of the values that are present; `None` when none is.
fn mean_where_present(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let present: Vec<f64> = values.flatten().collect();
    (!present.is_empty()).then(|| present.iter().sum::<f64>() / present.len() as f64)
}

/// The policy's episodes in `env`, a batch at a time (each a few episodes per thread) so
/// that progress can be shown; the same episodes as one call would run.
fn run_policy(
    dir: &Path,
    p: &PlannedPolicy,
    env: &EnvConfig,
    options: &ScoreOptions,
    progress: &mut dyn FnMut(usize),
) -> Result<Vec<EpisodeOutcome>, ScoreError> {
    let batch = (4 * rayon::current_num_threads()).clamp(10, 64);
    let mut outcomes: Vec<EpisodeOutcome> = Vec::with_capacity(options.episodes);
    while outcomes.len() < options.episodes {
        let n = batch.min(options.episodes - outcomes.len());
        let seed = options.seed.wrapping_add(outcomes.len() as u64);
        let report = crate::eval::eval_policy_bytes(&p.bytes, env, n, seed)
            .map_err(|source| ScoreError::Eval { path: dir.join(&p.file), source })?;
        outcomes.extend(report.per_episode);
        progress(outcomes.len());
    }
    Ok(outcomes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_out_episodes_stay_apart_from_training_s_validation_and_test_episodes() {
        let mut config = Config::default();
        for seed in 0..100 {
            config.seed = seed;
            check_held_out(&config, HELD_OUT_SEED, 100_000).expect("apart");
        }
        config.seed = 2;
        let validation = 2 * 1_000_003 + 0xe7a1;
        assert!(matches!(
            check_held_out(&config, validation - 5, 10),
            Err(ScoreError::Overlap { set: "validation", .. })
        ));
        // Ends just before the validation episodes: apart.
        check_held_out(&config, validation - 10, 10).expect("apart");
        let test = 2 * 1_000_033 + 0x7e57;
        assert!(matches!(
            check_held_out(&config, test + 19, 1),
            Err(ScoreError::Overlap { set: "test", .. })
        ));
    }
}
