//! Time to a gait read from committed run folders: the default config's stored seeds (one
//! session each, Table I's VGE cell), runs resumed before and after their first pass as
//! their `train.log` tells, a resumed run whose only record is its `metrics.csv`, and a
//! copy of a run given the event files of two sessions.

use crate::common;

use std::path::{Path, PathBuf};

use vge_lab::time_to_gait::{RunGait, read_run, summarise};

fn results(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results").join(rel)
}

fn run(rel: &str) -> RunGait {
    read_run(&results(rel), 0.5).expect("a committed run folder")
}

#[test]
fn the_default_configs_seeds_give_their_first_pass_its_wall_time_and_table_is_iqm() {
    let runs: Vec<RunGait> = (0..6).map(|s| run(&format!("cube-fg-vge-seeds/seed-{s}"))).collect();
    // eval.csv's first test at >= 0.5, and metrics.csv's steps_per_s at that step.
    let expected = [
        (700_000, 0.5, 424.9),
        (600_000, 0.8, 430.1),
        (700_000, 0.9, 362.8),
        (700_000, 0.55, 368.1),
        (600_000, 0.55, 335.1),
        (800_000, 0.55, 744.9),
    ];
    for (r, (step, success, steps_per_s)) in runs.iter().zip(expected) {
        let pass = r.first_pass.expect("every seed passed a test");
        assert_eq!(
            (pass.step, pass.clock_step, pass.success, pass.steps_per_s),
            (step, step, success, steps_per_s)
        );
        assert!((pass.wall_s - step as f64 / steps_per_s).abs() < 1e-9, "{r:?}");
        assert!(!r.resumed && r.one_session && r.resume_evidence.is_empty(), "{r:?}");
    }
    assert_eq!(runs.iter().map(|r| r.seed).collect::<Vec<_>>(), [0, 1, 2, 3, 4, 5]);
    assert_eq!((runs[0].selected_success, runs[0].final_success), (Some(0.76), Some(0.89)));
    // A stricter bar: seed 0 never reached 0.9, seed 2 did at its first pass.
    assert!(read_run(&results("cube-fg-vge-seeds/seed-0"), 0.9).expect("reads").first_pass.is_none());
    assert_eq!(
        read_run(&results("cube-fg-vge-seeds/seed-2"), 0.9).expect("reads").first_pass.map(|p| p.step),
        Some(700_000)
    );
    let group = summarise("fg/vge", &runs).expect("statistics");
    // The middle two of 1,074, 1,395, 1,647, 1,791, 1,902, 1,929 s.
    let median = (700_000.0 / 424.9 + 600_000.0 / 335.1) / 2.0;
    assert!((group.median_wall_s.expect("a median") - median).abs() < 1e-9, "{group:?}");
    assert_eq!((group.median_step, group.counted), (Some(700_000.0), 6));
    assert!(group.never.is_empty() && group.not_one_session.is_empty());
    // Table I's FG + VGE cell (docs/results/table1/table1.md): selected 0.80 [0.73, 0.91],
    // final 0.58 [0.12, 0.91], drawn under the same label.
    let text = |e: vge_lab::stats::Estimate| format!("{:.2} [{:.2}, {:.2}]", e.point, e.ci_low, e.ci_high);
    assert_eq!(text(group.selected.expect("scored").iqm), "0.80 [0.73, 0.91]");
    assert_eq!(text(group.final_policy.expect("scored").iqm), "0.58 [0.12, 0.91]");
}

#[test]
fn a_pass_before_the_first_resume_is_one_sessions_and_one_after_it_is_left_out() {
    // train.log: resumed from 700,000, the step of its first pass: that row is the first
    // session's.
    let before = run("variants/side-on/seed-0");
    assert_eq!(before.first_pass.map(|p| p.step), Some(700_000));
    assert_eq!(before.resume_steps, [700_000]);
    assert!(before.resumed && before.one_session, "{before:?}");
    assert!(
        before.resume_evidence[0].starts_with("train.log: 2 sessions, resumed from 700,000"),
        "{before:?}"
    );
    // Resumed from 350,000, passed at 500,000: the clock there is the second session's.
    let after = run("variants/torque-2x/seed-1");
    assert_eq!(after.first_pass.map(|p| p.step), Some(500_000));
    assert!(after.resumed && !after.one_session, "{after:?}");
    // No train.log: the session clock of metrics.csv goes back after the resume.
    let metrics_only = run("table1/cube-fg-rl-bc/seed-0");
    assert!(!metrics_only.one_session, "{metrics_only:?}");
    assert!(
        metrics_only.resume_evidence.iter().any(|e| e.starts_with("metrics.csv: the session clock")),
        "{metrics_only:?}"
    );
    // ... or ends past final-eval.json's wall time, the sum of every session's.
    let final_eval_only = run("table1/cube-fg-vge-bc/seed-0");
    assert!(
        final_eval_only.resume_evidence.iter().any(|e| e.starts_with("final-eval.json: its wall time")),
        "{final_eval_only:?}"
    );
    let after_run = after.run.clone();
    let group = summarise("mixed", &[before, after, run("variants/sac-alpha0/table1/rl/seed-6")])
        .expect("statistics");
    assert_eq!(group.not_one_session, [after_run]);
    assert_eq!(group.never, [results("variants/sac-alpha0/table1/rl/seed-6")]);
    // Of the two counted one never passed, and the median of two falls on it too.
    assert_eq!((group.counted, group.median_wall_s), (2, None));
}

#[test]
fn two_sessions_event_files_mark_a_copy_of_a_one_session_run_as_resumed() {
    let dir = common::temp_dir("time-to-gait-tensorboard");
    common::copy_dir(&results("cube-fg-vge-seeds/seed-0"), &dir);
    assert!(read_run(&dir, 0.5).expect("reads").one_session);
    let events = dir.join("tensorboard");
    std::fs::create_dir_all(&events).expect("mkdir");
    for name in
        ["events.out.tfevents.1764000000.vge.s0.p11", "events.out.tfevents.1764001000.vge.s400000.p12"]
    {
        std::fs::write(events.join(name), b"").expect("write");
    }
    let copy = read_run(&dir, 0.5).expect("reads");
    assert_eq!(copy.resume_steps, [400_000]);
    assert!(copy.resumed && !copy.one_session, "passed at 700k, after the resume: {copy:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_still_training_without_a_pass_is_left_out_not_counted_as_never() {
    let dir = common::temp_dir("time-to-gait-in-progress");
    common::copy_dir(&results("cube-fg-vge-seeds/seed-0"), &dir);
    // The folder as it stood at 300k: the tests so far (0% each), no final test, no score.
    for name in ["final-eval.json", "score.json"] {
        std::fs::remove_file(dir.join(name)).expect("remove");
    }
    for (name, rows) in [("eval.csv", 3), ("metrics.csv", 30)] {
        let text = std::fs::read_to_string(dir.join(name)).expect("read");
        let kept: Vec<&str> = text.lines().take(1 + rows).collect();
        std::fs::write(dir.join(name), kept.join("\n") + "\n").expect("write");
    }
    let training = read_run(&dir, 0.5).expect("reads");
    assert_eq!((training.first_pass, training.last_step, training.final_wall_s), (None, 300_000, None));
    let finished = run("cube-fg-vge-seeds/seed-1");
    let group = summarise("g", &[training, finished.clone()]).expect("statistics");
    assert_eq!((group.in_progress.clone(), group.never.len(), group.counted), (vec![dir.clone()], 0, 1));
    assert_eq!(group.median_wall_s, finished.first_pass.map(|p| p.wall_s));
    let _ = std::fs::remove_dir_all(&dir);
}
