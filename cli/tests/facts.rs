//! `vge facts`, which the results write-ups quote, on a committed run folder: its row and
//! segments are what the run's own files say, and its lane lines come from the lanes' logs.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_owned()
}

fn facts(args: &[&str], lanes: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge"))
        .arg("facts")
        .arg("--lanes")
        .arg(lanes)
        .args(args)
        .current_dir(repo())
        .output()
        .expect("vge runs")
}

#[test]
fn a_committed_run_gives_its_row_its_two_segments_and_its_lanes() {
    let lanes = common::temp_dir("facts-lanes");
    let rel = "variants/sac-alpha0/table1/rl/seed-6";
    std::fs::write(
        lanes.join("lane-a.log"),
        format!(
            "2026-11-20T10:00:00Z start {rel} with vge-abc1234\n2026-11-20T11:00:00Z end {rel} (exit 143)\n\
             2026-11-20T11:00:01Z start other/seed-0 with vge-abc1234\n"
        ),
    )
    .expect("a lane log");
    std::fs::write(lanes.join("lane-b.log"), format!("2026-11-21T09:00:00Z end {rel} (exit 0)\n"))
        .expect("log");
    let out = facts(&[&format!("docs/results/{rel}")], &lanes);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // score.json: selected (the final policy, 1M) and final on 100 held-out episodes.
    assert!(text.contains("\n  0.00 (1.00) | 1M | 0.00 (1.00) | 2.57 | 4,000\n"), "{text}");
    // train.log: stopped checkpointed at a session's end, then resumed to the end.
    assert!(
        text.contains(
            "segments (train.log): 2: from 0, 3,130 s, stopped checkpointed at 820,288; \
             from 820,288, 914 s, done\n"
        ),
        "{text}"
    );
    assert!(text.contains("periodic tests (step: success, drops): 100k: 0%, 95%;"), "{text}");
    // metrics.csv's last three windows: mean Q minus the collected return -9.85, -20.98, -6.96.
    assert!(text.contains("\n  gap (mean Q - return), mean of the last 3 windows: -12.6\n"), "{text}");
    assert!(!text.contains("actor log-std"), "its binary did not log one: {text}");
    assert!(!text.contains("early steps"), "nor the early steps' returns: {text}");
    assert!(
        text.contains(
            "lanes: 2026-11-20T10:00:00Z start (lane-a); 2026-11-20T11:00:00Z end (lane-a); \
             2026-11-21T09:00:00Z end (lane-b)\n"
        ),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&lanes);
}

#[test]
fn a_run_still_training_shows_where_it_stands_and_a_folder_without_metrics_is_refused() {
    let dir = common::temp_dir("facts-training");
    let run = dir.join("seed-6");
    common::copy_dir(&repo().join("docs/results/variants/sac-alpha0/table1/rl/seed-6"), &run);
    // Stopped at 500k: no final evaluation or score yet, periodic tests to 500k.
    for file in ["final-eval.json", "score.json", "best-eval.json"] {
        let _ = std::fs::remove_file(run.join(file));
    }
    let keep_to = |file: &str, last_step: u64| {
        let text = std::fs::read_to_string(run.join(file)).expect(file);
        let kept: Vec<&str> = text
            .lines()
            .filter(|l| {
                l.split(',').next().and_then(|s| s.parse::<u64>().ok()).is_none_or(|s| s <= last_step)
            })
            .collect();
        std::fs::write(run.join(file), kept.join("\n") + "\n").expect(file);
    };
    keep_to("metrics.csv", 500_000);
    keep_to("eval.csv", 500_000);
    // As newer binaries log it: the early steps' returns, here each window's return + 10.
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).expect("metrics.csv");
    let mut lines = metrics.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let at = header.iter().position(|c| *c == "mc_return").expect("mc_return");
    let with_early: Vec<String> = std::iter::once(format!("{},mc_return_early", header.join(",")))
        .chain(lines.map(|l| {
            let ret = l.split(',').nth(at).expect("field");
            let early = ret.parse::<f64>().map_or(String::new(), |r| format!("{:.6}", r + 10.0));
            format!("{l},{early}")
        }))
        .collect();
    std::fs::write(run.join("metrics.csv"), with_early.join("\n") + "\n").expect("metrics.csv");
    let out = facts(&[run.to_str().expect("utf-8 path")], &dir);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let gap_after = |label: &str| -> f64 {
        let line = text.lines().find(|l| l.contains(label)).unwrap_or_else(|| panic!("{label}: {text}"));
        line.rsplit(": ").next().and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("{line}"))
    };
    let (gap, early_gap) =
        (gap_after("gap (mean Q - return), mean"), gap_after("gap (mean Q - early steps' return), mean"));
    assert!((gap - early_gap - 10.0).abs() < 0.11, "{gap} and {early_gap}: {text}");
    assert!(
        text.contains("in training (no final-eval.json yet): its last metrics window at 500,000"),
        "{text}"
    );
    assert!(text.contains("  at 500k: mean Q "), "the critic at its last window: {text}");
    assert!(text.contains("gap (mean Q - return), mean of the last 3 windows: "), "{text}");
    assert!(text.contains("periodic tests (step: success, drops): 100k: "), "{text}");
    assert!(!text.contains("row: "), "no table row before the score: {text}");

    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).expect("dir");
    let out = facts(&[empty.to_str().expect("utf-8 path")], &dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("no metrics.csv: not a training run's folder"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A run whose metrics carry the actor's log-std (SAC, newer binaries) gets its last value.
#[test]
fn a_run_that_logged_its_actors_log_std_gives_the_last_one() {
    let dir = common::temp_dir("facts-log-std");
    let run = dir.join("seed-6");
    common::copy_dir(&repo().join("docs/results/variants/sac-alpha0/table1/rl/seed-6"), &run);
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).expect("metrics.csv");
    let rows: Vec<&str> = metrics.lines().collect();
    let mut with_log_std = vec![format!("{},actor_log_std", rows[0])];
    for (k, row) in rows[1..].iter().enumerate() {
        // Empty in the first rows (no update yet), then a value per window.
        let value = if k < 2 { String::new() } else { format!("{:.3}", -0.5 - k as f64 / 100.0) };
        with_log_std.push(format!("{row},{value}"));
    }
    std::fs::write(run.join("metrics.csv"), with_log_std.join("\n") + "\n").expect("write");
    let out = facts(&[run.to_str().expect("utf-8 path")], &dir);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let last = -0.5 - (rows.len() - 2) as f64 / 100.0;
    assert!(text.contains(&format!("\nactor log-std at 1M: {last:.2}\n")), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}
