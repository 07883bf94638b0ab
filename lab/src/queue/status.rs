//! `vge queue status`: where each run of a queue stands (collected, finished, at which step
//! and checkpoint, training now and for about how long), and the env steps and hours the
//! queue has left, to plan working sessions around it.

use std::path::Path;

use vge_run::config::{Config, load_config};
use vge_run::run_dir::{METRICS, RunDir};

use super::lane::{held_by, is_done};
use super::{Checkout, QueueError, QueueLine};

/// One run's state as a line of text, and what the queue has left.
#[derive(Debug, Clone, PartialEq)]
pub struct QueueStatus {
    /// (REL, its state) in queue order.
    pub runs: Vec<(String, String)>,
    /// Runs not finished.
    pub waiting: usize,
    /// Their env steps left.
    pub steps_left: u64,
    /// The running run's env steps per second, when one trains.
    pub rate_per_s: Option<f64>,
}

impl QueueStatus {
    /// `to go: N runs, X.XXM env steps[, about H h at the running run's R steps/s]`. Runs of
    /// other configs train at other rates: the hours are a guide.
    pub fn summary(&self) -> String {
        let mut text =
            format!("to go: {} runs, {:.2}M env steps", self.waiting, self.steps_left as f64 / 1e6);
        if let Some(rate) = self.rate_per_s {
            let hours = self.steps_left as f64 / rate / 3600.0;
            text += &format!(", about {hours:.1} h at the running run's {rate:.0} steps/s");
        }
        text
    }
}

/// The status of every line of `queue`.
pub fn status(checkout: &Checkout, queue: &Path) -> Result<QueueStatus, QueueError> {
    let lines = super::read(queue)?;
    let mut status = QueueStatus { runs: Vec::new(), waiting: 0, steps_left: 0, rate_per_s: None };
    for line in &lines {
        let dir = checkout.run_dir(&line.rel);
        let run = RunDir::new(&dir);
        let budget = budget(checkout, line);
        let state = if checkout.results_dir(&line.rel).join(vge_run::run_dir::SCORE).is_file() {
            "collected".to_owned()
        } else if is_done(checkout, line) {
            "finished, not collected".to_owned()
        } else if run.final_eval().is_file() {
            "trained, not scored".to_owned()
        } else if dir.exists() {
            let last = last_metrics(&dir);
            let mut state = format!("at step {}", last.map_or(0, |(step, _)| step));
            let checkpoint = vge_run::run_dir::checkpoint_step(&dir);
            match (&checkpoint, run.resume_checkpoint()) {
                (Some(step), Some(folder)) => {
                    state += &format!(
                        ", {} at step {step}",
                        folder.file_name().unwrap_or_default().to_string_lossy()
                    );
                }
                _ => state += ", no checkpoint yet",
            }
            let mut done_steps = checkpoint.unwrap_or(0);
            if held_by(&dir).is_some() {
                state += ", training now";
                if let Some((step, rate)) = last.filter(|(_, rate)| *rate > 0.0) {
                    let minutes = budget.saturating_sub(step) as f64 / rate / 60.0;
                    state += &format!(", about {minutes:.0} min of training left");
                    status.rate_per_s = Some(rate);
                    done_steps = step;
                }
            } else if checkpoint.is_none() {
                state += ": starts again";
            }
            status.steps_left += budget.saturating_sub(done_steps);
            status.waiting += 1;
            state
        } else {
            status.steps_left += budget;
            status.waiting += 1;
            "not started".to_owned()
        };
        status.runs.push((line.rel.clone(), state));
    }
    Ok(status)
}

/// A line's env-step budget: its config at its commit with its overrides, else the
/// default's.
fn budget(checkout: &Checkout, line: &QueueLine) -> u64 {
    let config = checkout.source(&line.commit).join(&line.config);
    load_config(&config, &line.sets).map_or(Config::default().total_steps, |c| c.total_steps)
}

/// The last metrics row's step and env steps per second (its last column).
fn last_metrics(dir: &Path) -> Option<(u64, f64)> {
    let text = std::fs::read_to_string(dir.join(METRICS)).ok()?;
    let last = text.lines().rev().find(|l| l.starts_with(|c: char| c.is_ascii_digit()))?;
    let step = last.split(',').next()?.parse().ok()?;
    let rate = last.rsplit(',').next()?.parse().ok()?;
    Some((step, rate))
}
