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

/// The last metrics row's step, and its env steps per second where they tell how fast the
/// run trains: read by column name (a run on several objects has columns after
/// `steps_per_s`), and only for a window spent wholly learning (the row before it had
/// updates). The first window is mostly warm-up, stepping without updates at several times
/// the learning rate, and would promise an end far too early.
fn last_metrics(dir: &Path) -> Option<(u64, f64)> {
    let text = std::fs::read_to_string(dir.join(METRICS)).ok()?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next()?.split(',').collect();
    let column = |name: &str| header.iter().position(|c| *c == name);
    let (rate_at, updates_at) = (column("steps_per_s"), column("updates"));
    let rows: Vec<Vec<&str>> = lines
        .filter(|l| l.starts_with(|c: char| c.is_ascii_digit()))
        .map(|l| l.split(',').collect())
        .collect();
    let field =
        |row: &[&str], at: Option<usize>| at.and_then(|i| row.get(i)).and_then(|v| v.parse::<f64>().ok());
    let last = rows.last()?;
    let step = last.first()?.parse().ok()?;
    let learning = rows.len() >= 2 && field(&rows[rows.len() - 2], updates_at).is_some_and(|u| u > 0.0);
    let rate = if learning { field(last, rate_at).unwrap_or(0.0) } else { 0.0 };
    Some((step, rate))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metrics(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("vge-status-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(dir.join(METRICS), text).expect("metrics.csv");
        dir
    }

    #[test]
    fn the_rate_is_read_by_name_from_a_window_spent_learning() {
        // After warm-up: the first window's 802.7 steps/s (2 updates) is no guide.
        let one = metrics("warm-up", "step,updates,steps_per_s\n10000,2,802.7\n");
        assert_eq!(last_metrics(&one), Some((10_000, 0.0)));
        let two = metrics("learning", "step,updates,steps_per_s\n10000,2,802.7\n20000,2502,214.5\n");
        assert_eq!(last_metrics(&two), Some((20_000, 214.5)));
        // Several objects: per-object columns follow steps_per_s.
        let objects = metrics(
            "objects",
            "step,updates,steps_per_s,cube_success,cube_rotation\n10000,2,800.0,0.5,3.0\n\
             20000,2502,201.5,0.25,6.5\n",
        );
        assert_eq!(last_metrics(&objects), Some((20_000, 201.5)));
        for dir in [one, two, objects] {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}
