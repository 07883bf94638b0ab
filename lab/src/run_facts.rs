//! `vge facts`: a run's facts as the results write-ups report them: for a finished, scored
//! run one table row (selected and final success and drops, where the selection fell, the
//! final policy's rotation, the wall time), and for any run the numbers a bullet quotes (the
//! critic's mean Q against the discounted return collected, the BC term, the controller's
//! share, the periodic tests, each training segment of `train.log`, and when each lane
//! started and ended the run): a run still training shows where it stands.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde_json::Value;
use thiserror::Error;
use vge_run::run_dir::{EVAL, FINAL_EVAL, METRICS, RunFileError, SCORE, SegmentEnd};

#[derive(Debug, Error)]
pub enum FactsError {
    #[error("{run}: no {METRICS}: not a training run's folder")]
    NotARun { run: String },
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{path}: {why}")]
    Format { path: String, why: String },
    #[error(transparent)]
    RunFile(#[from] RunFileError),
}

/// The critic and the returns are reported from here on: the first 100k steps are the
/// warm-up, where neither means much yet.
pub const FROM_STEP: u64 = 100_000;

/// The facts of the run in `run`, as lines of text. `lanes` is the folder of the lanes' logs
/// (`runs/lanes`): their start and end lines of this run, which is named as in its queue
/// (the path after `results/`).
pub fn facts(run: &Path, lanes: &Path) -> Result<String, FactsError> {
    if !run.join(METRICS).is_file() {
        return Err(FactsError::NotARun { run: run.display().to_string() });
    }
    let metrics = Table::read(&run.join(METRICS))?;
    let periodic = if run.join(EVAL).is_file() { Table::read(&run.join(EVAL))? } else { Table::default() };
    let mut out = String::new();
    let _ = writeln!(out, "== {}", run.display());
    match (run.join(FINAL_EVAL).is_file(), run.join(SCORE).is_file()) {
        (true, true) => {
            let score = read_json(&run.join(SCORE))?;
            let final_eval = read_json(&run.join(FINAL_EVAL))?;
            row(&mut out, &score, &final_eval, &run.join(SCORE))?;
        }
        (true, false) => {
            let _ = writeln!(out, "finished, not scored: `vge score {}` gives its row", run.display());
        }
        (false, _) => {
            let last =
                metrics.column("step", 0).last().map_or("no metrics window yet".to_owned(), |(step, _)| {
                    format!("its last metrics window at {}", thousands(*step as f64))
                });
            let _ = writeln!(out, "in training (no {FINAL_EVAL} yet): {last}");
        }
    }
    critic(&mut out, &metrics);
    let tests: Vec<String> = periodic
        .rows
        .iter()
        .filter_map(|r| {
            let step = periodic.get(r, "step")?.parse::<u64>().ok()?;
            let success: f64 = periodic.get(r, "success")?.parse().ok()?;
            let drops: f64 = periodic.get(r, "drops")?.parse().ok()?;
            Some(format!("{}: {}, {}", steps_label(step), percent(success), percent(drops)))
        })
        .collect();
    let tests = if tests.is_empty() { "none yet".to_owned() } else { tests.join("; ") };
    let _ = writeln!(out, "periodic tests (step: success, drops): {tests}");
    let segments = vge_run::run_dir::read_train_log(run)?.unwrap_or_default();
    if !segments.is_empty() {
        let text: Vec<String> = segments
            .iter()
            .map(|s| {
                let wall = s.wall_s.map_or("-".to_owned(), |w| format!("{} s", thousands(w)));
                let end = match s.end {
                    SegmentEnd::NoEndLine => "killed (no end line)".to_owned(),
                    SegmentEnd::Stopped { step } => {
                        format!("stopped checkpointed at {}", thousands(step as f64))
                    }
                    SegmentEnd::Done => "done".to_owned(),
                };
                format!("from {}, {wall}, {end}", thousands(s.from_step as f64))
            })
            .collect();
        let _ = writeln!(out, "segments (train.log): {}: {}", segments.len(), text.join("; "));
    }
    let events = lane_events(run, lanes);
    if !events.is_empty() {
        let text: Vec<String> = events.iter().map(|(t, what, lane)| format!("{t} {what} ({lane})")).collect();
        let _ = writeln!(out, "lanes: {}", text.join("; "));
    }
    Ok(out)
}

/// The table row and the selected policy's line.
fn row(out: &mut String, score: &Value, final_eval: &Value, path: &Path) -> Result<(), FactsError> {
    let field = |part: &str, key: &str| {
        score[part][key].as_f64().ok_or_else(|| FactsError::Format {
            path: path.display().to_string(),
            why: format!("no number {part}.{key}"),
        })
    };
    let (sel_step, sel_success, sel_drops) =
        (field("selected", "step")?, field("selected", "success_rate")?, field("selected", "drop_rate")?);
    let (fin_success, fin_drops, fin_rotation) =
        (field("final", "success_rate")?, field("final", "drop_rate")?, field("final", "mean_rotation_rad")?);
    let wall = final_eval["wall_s"].as_f64().map_or("-".to_owned(), thousands);
    let _ = writeln!(
        out,
        "row: selected: success (drops) | selected at | final: success (drops) | final: rotation (rad) | wall (s)"
    );
    let _ = writeln!(
        out,
        "  {sel_success:.2} ({sel_drops:.2}) | {} | {fin_success:.2} ({fin_drops:.2}) | {fin_rotation:.2} | {wall}",
        steps_label(sel_step as u64)
    );
    let _ = writeln!(
        out,
        "selected: rotation {:.2} rad, {:.1} contact switches per episode",
        field("selected", "mean_rotation_rad")?,
        field("selected", "mean_contact_switches")?
    );
    if let Some(last) = score.get("last_snapshots").filter(|l| !l.is_null()) {
        let n = last["snapshots"].as_array().map_or(0, Vec::len);
        let success = last["success_rate"].as_f64().unwrap_or(f64::NAN);
        let _ = writeln!(out, "last {n} snapshots: success {success:.2}");
    }
    Ok(())
}

/// Mean Q against the collected return from [`FROM_STEP`], the BC term, the controller's share.
fn critic(out: &mut String, metrics: &Table) {
    let q = metrics.column("mean_q", FROM_STEP);
    let ret = metrics.column("mc_return", FROM_STEP);
    let _ = writeln!(
        out,
        "from {}k: mean Q {}, collected discounted return {}",
        FROM_STEP / 1000,
        range_text(&q, 1),
        range_text(&ret, 1)
    );
    if let (Some(q_last), Some(ret_last)) = (q.last(), ret.last()) {
        let _ =
            writeln!(out, "  at {}: mean Q {:.1}, return {:.1}", steps_label(q_last.0), q_last.1, ret_last.1);
    }
    // The critic's gap as the budget plans' rules, `vge compare` and Table I read it: mean Q
    // minus the collected return over the last windows that have both.
    gap_line(out, "gap (mean Q - return)", &q, &ret);
    // The same against the early steps' returns, which the time limit cuts by at most 5%
    // (binaries from before the column have none; docs/scoring.md).
    let early = metrics.column("mc_return_early", FROM_STEP);
    gap_line(out, "gap (mean Q - early steps' return)", &q, &early);
    // The actor's exploration: SAC's mean log-std (empty for TD3, absent in older binaries).
    if let Some((step, log_std)) = metrics.column("actor_log_std", 0).last() {
        let _ = writeln!(out, "actor log-std at {}: {log_std:.2}", steps_label(*step));
    }
    let bc = metrics.column("bc_loss", 0);
    if let Some((low, high)) = value_range(&bc)
        && (low != 0.0 || high != 0.0)
    {
        let _ = writeln!(out, "bc_loss: {}", range_text(&bc, 2));
    }
    let share = metrics.column("controller_share", 0);
    if let (Some(first), Some(last_acting)) = (share.first(), share.iter().rfind(|(_, v)| *v > 0.0)) {
        let _ = writeln!(
            out,
            "controller share: {} at {}, {} at {} (last step it acted)",
            percent(first.1),
            steps_label(first.0),
            percent(last_acting.1),
            steps_label(last_acting.0)
        );
    }
}

/// `label`: mean Q minus `returns` over the last windows that have both; nothing when
/// no window has both.
fn gap_line(out: &mut String, label: &str, q: &[(u64, f64)], returns: &[(u64, f64)]) {
    let returns: std::collections::BTreeMap<u64, f64> = returns.iter().copied().collect();
    let gaps: Vec<f64> = q.iter().filter_map(|(step, v)| returns.get(step).map(|r| v - r)).collect();
    if let Some(gap) = vge_run::run_dir::critic_gap_at_end(&gaps) {
        let windows = vge_run::run_dir::CRITIC_GAP_WINDOWS.min(gaps.len());
        let _ = writeln!(out, "  {label}, mean of the last {windows} windows: {gap:.1}");
    }
}

/// A CSV file with a header (metrics.csv, eval.csv), its fields as text.
#[derive(Default)]
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    /// vge writes these files itself, numbers and names without quotes or commas inside.
    fn read(path: &Path) -> Result<Self, FactsError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| FactsError::Io { path: path.display().to_string(), source })?;
        let mut lines = text.lines();
        let split = |line: &str| line.split(',').map(|f| f.trim().to_owned()).collect::<Vec<_>>();
        let header = lines.next().map(split).ok_or_else(|| FactsError::Format {
            path: path.display().to_string(),
            why: "empty: no header".to_owned(),
        })?;
        Ok(Self { header, rows: lines.filter(|l| !l.trim().is_empty()).map(split).collect() })
    }

    fn get<'a>(&self, row: &'a [String], name: &str) -> Option<&'a str> {
        let index = self.header.iter().position(|h| h == name)?;
        row.get(index).map(String::as_str)
    }

    /// (step, value) of one column from `from_step` on, empty fields skipped.
    fn column(&self, name: &str, from_step: u64) -> Vec<(u64, f64)> {
        self.rows
            .iter()
            .filter_map(|r| {
                let step = self.get(r, "step")?.parse::<u64>().ok()?;
                let value = self.get(r, name).filter(|v| !v.is_empty())?.parse::<f64>().ok()?;
                (step >= from_step).then_some((step, value))
            })
            .collect()
    }
}

/// (time, start or end, lane) of the run in the lanes' logs, the run named as in its queue:
/// its path after `results/`.
fn lane_events(run: &Path, lanes: &Path) -> Vec<(String, String, String)> {
    let Ok(resolved) = std::fs::canonicalize(run) else { return Vec::new() };
    let parts: Vec<String> =
        resolved.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    let Some(at) = parts.iter().position(|p| p == "results") else { return Vec::new() };
    let rel = parts[at + 1..].join("/");
    let mut logs: Vec<PathBuf> = std::fs::read_dir(lanes)
        .map(|entries| entries.filter_map(Result::ok).map(|e| e.path()).collect())
        .unwrap_or_default();
    logs.retain(|p| p.extension().is_some_and(|e| e == "log"));
    logs.sort();
    let mut events = Vec::new();
    for log in logs {
        let lane = log.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let Ok(text) = std::fs::read_to_string(&log) else { continue };
        for line in text.lines() {
            let fields: Vec<&str> = line.split_whitespace().collect();
            if let [time, what @ ("start" | "end"), name, ..] = fields[..]
                && name == rel
            {
                events.push((time.to_owned(), what.to_owned(), lane.clone()));
            }
        }
    }
    events.sort();
    events
}

fn read_json(path: &Path) -> Result<Value, FactsError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| FactsError::Io { path: path.display().to_string(), source })?;
    serde_json::from_str(&text)
        .map_err(|e| FactsError::Format { path: path.display().to_string(), why: e.to_string() })
}

/// `1M` for a million steps, else whole thousands: `820k`.
pub(crate) fn steps_label(step: u64) -> String {
    if step == 1_000_000 { "1M".to_owned() } else { format!("{}k", step / 1000) }
}

fn value_range(pairs: &[(u64, f64)]) -> Option<(f64, f64)> {
    let mut values = pairs.iter().map(|(_, v)| *v);
    let first = values.next()?;
    Some(values.fold((first, first), |(low, high), v| (low.min(v), high.max(v))))
}

fn range_text(pairs: &[(u64, f64)], digits: usize) -> String {
    value_range(pairs).map_or("-".to_owned(), |(low, high)| format!("{low:.digits$} to {high:.digits$}"))
}

/// `0.95` as `95%`.
fn percent(fraction: f64) -> String {
    format!("{:.0}%", fraction * 100.0)
}

/// A number rounded to a whole, its thousands comma-separated: `3,130`.
pub(crate) fn thousands(value: f64) -> String {
    let text = format!("{value:.0}");
    let (sign, digits) = text.strip_prefix('-').map_or(("", text.as_str()), |d| ("-", d));
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(c);
    }
    format!("{sign}{out}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_read_as_the_write_ups_write_them() {
        assert_eq!(thousands(3130.3), "3,130");
        assert_eq!(thousands(820_288.0), "820,288");
        assert_eq!(thousands(999.6), "1,000");
        assert_eq!(thousands(-1234.0), "-1,234");
        assert_eq!(percent(0.95), "95%");
        assert_eq!(steps_label(1_000_000), "1M");
        assert_eq!(steps_label(900_000), "900k");
    }
}
