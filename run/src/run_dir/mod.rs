//! A run folder: every file name a run writes or a tool reads, and the readers of its files,
//! in one place.
//!
//! `vge train` writes these (vge-trainer's `train` module says when and how each is made
//! crash-safe, through [`atomic_file`] under the folder's [`lock`]); `vge score`, `vge plot`,
//! `vge sweep` and the success tests read them. A [`RunDir`] is a path with one method per
//! file, so no other module spells a file name; its tables are read by column name
//! ([`csv_columns`]), its records as JSON ([`read_json`]), the whole folder as the plots see it
//! ([`read_run`]), its training sessions ([`read_train_log`], [`tensorboard_sessions`]), and
//! every reader fails with a [`RunFileError`] naming the file.

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::config::{Config, ConfigError};

pub mod atomic_file;
pub mod lock;
mod records;
mod score_file;
mod sessions;
mod tables;

pub use records::{
    CRITIC_GAP_WINDOWS, FinalEvalFields, RunCurves, Selected, check_finished, checkpoint_step,
    critic_gap_at_end, critic_gap_at_step, find_runs, read_final_eval, read_json, read_run,
};
pub use score_file::{PolicyScore, Score, SnapshotsScore};
pub use sessions::{SegmentEnd, TrainSegment, read_train_log, tensorboard_sessions};
pub use tables::{StepsAndValues, csv_columns, csv_columns_if_present, object_success, whole_steps};

/// A run's file that cannot be read, or does not say what its kind must.
#[derive(Debug, Error)]
pub enum RunFileError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    /// A table or record whose content is not what the file's kind holds.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// A run's `config.toml` that the config parser cannot read (the message names the file).
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// The resolved configuration the run trained with.
pub const CONFIG: &str = "config.toml";
/// One row every `run.log_interval` env steps.
pub const METRICS: &str = "metrics.csv";
/// The periodic success tests (the validation episodes).
pub const EVAL: &str = "eval.csv";
/// TensorBoard event files, one per session.
pub const TENSORBOARD: &str = "tensorboard";
/// The actor exported at each periodic evaluation, `policy-<step>.vgep`.
pub const SNAPSHOTS: &str = "snapshots";
/// The final actor, written last but one.
pub const POLICY: &str = "policy.vgep";
/// The final actor's success test, written last: a run is finished when it and [`POLICY`]
/// read back whole.
pub const FINAL_EVAL: &str = "final-eval.json";
/// The selected snapshot (best validation success) and its test on held-out episodes.
pub const POLICY_BEST: &str = "policy-best.vgep";
pub const BEST_EVAL: &str = "best-eval.json";
/// `vge score`'s held-out scores of the selected, final and last snapshots' policies.
pub const SCORE: &str = "score.json";
/// `vge train`'s output, where a lane or a sweep writes it (not a run file: it is written
/// before training starts, and a run trained by hand has none).
pub const TRAIN_LOG: &str = "train.log";
/// Held by the one process writing the folder.
pub const LOCK: &str = "vge.lock";
/// The checkpoint folder.
pub const CHECKPOINT: &str = "checkpoint";
/// Where a checkpoint is written before it is renamed to [`CHECKPOINT`].
pub const CHECKPOINT_TMP: &str = "checkpoint.tmp";
/// The previous checkpoint while a save swaps the folders.
pub const CHECKPOINT_OLD: &str = "checkpoint.old";
/// The training loop's counters and generator, inside a checkpoint.
pub const CHECKPOINT_STATE: &str = "state.toml";

/// What a run writes into its folder from its first moments on, the checkpoint's folders
/// included: a folder holding any of them holds a run, which `vge train --config` must not
/// start over.
pub const RUN_FILES: [&str; 10] = [
    CONFIG,
    METRICS,
    EVAL,
    TENSORBOARD,
    CHECKPOINT,
    CHECKPOINT_OLD,
    CHECKPOINT_TMP,
    SNAPSHOTS,
    POLICY,
    FINAL_EVAL,
];

/// A run folder: the path of each of its files.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    pub fn config(&self) -> PathBuf {
        self.root.join(CONFIG)
    }

    pub fn metrics(&self) -> PathBuf {
        self.root.join(METRICS)
    }

    pub fn eval_csv(&self) -> PathBuf {
        self.root.join(EVAL)
    }

    pub fn tensorboard(&self) -> PathBuf {
        self.root.join(TENSORBOARD)
    }

    pub fn snapshots(&self) -> PathBuf {
        self.root.join(SNAPSHOTS)
    }

    /// The actor exported at the periodic evaluation of env step `step`.
    pub fn snapshot(&self, step: u64) -> PathBuf {
        self.snapshots().join(format!("policy-{step}.vgep"))
    }

    pub fn policy(&self) -> PathBuf {
        self.root.join(POLICY)
    }

    pub fn final_eval(&self) -> PathBuf {
        self.root.join(FINAL_EVAL)
    }

    pub fn policy_best(&self) -> PathBuf {
        self.root.join(POLICY_BEST)
    }

    pub fn best_eval(&self) -> PathBuf {
        self.root.join(BEST_EVAL)
    }

    pub fn score(&self) -> PathBuf {
        self.root.join(SCORE)
    }

    pub fn train_log(&self) -> PathBuf {
        self.root.join(TRAIN_LOG)
    }

    pub fn lock(&self) -> PathBuf {
        self.root.join(LOCK)
    }

    pub fn checkpoint(&self) -> PathBuf {
        self.root.join(CHECKPOINT)
    }

    pub fn checkpoint_tmp(&self) -> PathBuf {
        self.root.join(CHECKPOINT_TMP)
    }

    pub fn checkpoint_old(&self) -> PathBuf {
        self.root.join(CHECKPOINT_OLD)
    }

    /// The checkpoint folder a resume reads: `checkpoint/` when it exists (whatever state it
    /// is in), else `checkpoint.old/` when that exists (a save killed between its two
    /// renames), else `None`.
    pub fn resume_checkpoint(&self) -> Option<PathBuf> {
        let dir = self.checkpoint();
        if dir.symlink_metadata().is_ok() {
            return Some(dir);
        }
        let old = self.checkpoint_old();
        old.symlink_metadata().is_ok().then_some(old)
    }

    /// The text of the run's `config.toml` as stored (read within a config file's bound).
    pub fn read_config_text(&self) -> Result<String, RunFileError> {
        let path = self.config();
        crate::read_limits::read_to_string_bounded(&path, crate::read_limits::MAX_CONFIG_FILE_LEN)
            .map_err(|source| RunFileError::Io { path, source })
    }

    /// The run's `config.toml`, read with the config parser (so a file it cannot read is an
    /// error naming the file; keys left out take the config's defaults). Not validated: a
    /// run's readers that go on to use it validate it (`run_eval::run_config`).
    pub fn read_config(&self) -> Result<Config, RunFileError> {
        let text = self.read_config_text()?;
        Ok(crate::config::parse_with_overrides(&text, &self.config().display().to_string(), &[])?)
    }

    /// Which of [`RUN_FILES`] the folder holds.
    pub fn run_files_present(&self) -> Vec<&'static str> {
        RUN_FILES.iter().copied().filter(|name| self.root.join(name).symlink_metadata().is_ok()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_resume_reads_the_checkpoint_then_the_previous_one() {
        let tmp = std::env::temp_dir().join(format!("vge-run-dir-{}", std::process::id()));
        let run = RunDir::new(&tmp);
        std::fs::create_dir_all(run.checkpoint_old()).expect("mkdir");
        assert_eq!(run.resume_checkpoint(), Some(run.checkpoint_old()));
        std::fs::create_dir_all(run.checkpoint()).expect("mkdir");
        assert_eq!(run.resume_checkpoint(), Some(run.checkpoint()));
        assert_eq!(run.run_files_present(), vec![CHECKPOINT, CHECKPOINT_OLD]);
        std::fs::remove_dir_all(&tmp).expect("clean up");
        assert_eq!(run.resume_checkpoint(), None);
        assert_eq!(run.snapshot(50_000), tmp.join("snapshots/policy-50000.vgep"));
    }
}
