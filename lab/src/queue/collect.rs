//! `vge queue collect`: a finished run's record copied from `runs/REL` to `docs/results/REL`,
//! where results are committed: what a result needs (config, metrics, tests, scores, plots,
//! the final and selected policies, the training log), never checkpoints, replay buffers,
//! snapshots or TensorBoard files.

use std::path::PathBuf;

use vge_run::run_dir::{BEST_EVAL, CONFIG, EVAL, FINAL_EVAL, METRICS, POLICY, POLICY_BEST, SCORE, TRAIN_LOG};

use super::{Checkout, QueueError, io_err};

/// The run-folder files a result keeps, when present.
pub const COLLECTED: [&str; 8] = [CONFIG, METRICS, EVAL, FINAL_EVAL, BEST_EVAL, SCORE, POLICY, POLICY_BEST];

/// Copies the run `rel` (which must be scored) to `docs/results/REL`, its lane log
/// `runs/REL.log` as the folder's [`TRAIN_LOG`]; returns that folder and the names copied.
pub fn collect(checkout: &Checkout, rel: &str) -> Result<(PathBuf, Vec<String>), QueueError> {
    let dir = checkout.run_dir(rel);
    if !dir.join(SCORE).is_file() {
        return Err(QueueError::Invalid(format!("{} has no {SCORE}: not finished", dir.display())));
    }
    let out = checkout.results_dir(rel);
    std::fs::create_dir_all(&out).map_err(io_err(&out))?;
    let mut copied = Vec::new();
    let mut names: Vec<String> = COLLECTED.iter().map(|n| (*n).to_owned()).collect();
    for entry in std::fs::read_dir(&dir).map_err(io_err(&dir))? {
        let name = entry.map_err(io_err(&dir))?.file_name().to_string_lossy().into_owned();
        if name.ends_with(".png") {
            names.push(name);
        }
    }
    for name in names {
        let from = dir.join(&name);
        if from.is_file() {
            std::fs::copy(&from, out.join(&name)).map_err(io_err(&from))?;
            copied.push(name);
        }
    }
    let log = checkout.run_log(rel);
    if log.is_file() {
        std::fs::copy(&log, out.join(TRAIN_LOG)).map_err(io_err(&log))?;
        copied.push(TRAIN_LOG.to_owned());
    }
    Ok((out, copied))
}
