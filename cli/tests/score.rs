//! `vge score` and the score.json training writes at its end, on a real tiny run (TINY, with
//! periodic evaluations so that it has a model selection and snapshots): what is scored, on
//! which episodes, skipping and rescoring, and the refusals (a damaged, missing or
//! other-layout policy file names the file; an unfinished run writes nothing).

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use vge_run::score::{HELD_OUT_SEED, SCORE_FILE, Score};

const STEPS: u64 = 400;
/// `run.score_episodes` of the tiny run: training's own score at its end.
const TRAINED_SCORE_EPISODES: usize = 4;

fn vge(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge")).args(args).output().expect("vge runs")
}

/// A finished tiny run with periodic evaluations every 100 steps (snapshots at 100..400),
/// trained once per test binary.
fn trained() -> &'static Path {
    &trained_run().0
}

/// The tiny run and what its training printed to stderr (a pipe here, not a terminal).
fn trained_run() -> &'static (PathBuf, String) {
    static RUN: OnceLock<(PathBuf, String)> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = common::temp_dir("score-run").join("run");
        let mut args: Vec<String> = [
            "train",
            "--config",
            common::config("cube-fg-vge.toml").to_str().expect("utf-8"),
            "--out",
            dir.to_str().expect("utf-8"),
            "--steps",
            &STEPS.to_string(),
        ]
        .map(str::to_owned)
        .into();
        for o in common::TINY
            .iter()
            .filter(|o| !o.starts_with("run.eval_interval") && !o.starts_with("run.score_"))
        {
            args.extend(["--set".to_owned(), (*o).to_owned()]);
        }
        // Training scores its policies at its end, on TRAINED_SCORE_EPISODES episodes each.
        for o in ["run.eval_interval=100".to_owned(), format!("run.score_episodes={TRAINED_SCORE_EPISODES}")]
        {
            args.extend(["--set".to_owned(), o]);
        }
        let out = Command::new(env!("CARGO_BIN_EXE_vge")).args(&args).output().expect("vge train");
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "training failed: {stderr}");
        (dir, stderr)
    })
}

/// A copy of the trained run in a folder of its own.
fn copy_of_run(name: &str) -> PathBuf {
    let dir = common::temp_dir(name).join("run");
    common::copy_dir(trained(), &dir);
    dir
}

fn read_score(dir: &Path) -> Score {
    let text = std::fs::read_to_string(dir.join(SCORE_FILE)).expect("score.json");
    serde_json::from_str(&text).expect("score.json parses")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Without a terminal, training prints a line per metrics row (TINY's `run.log_interval` of
/// 50, so 8 over 400 steps) and one per periodic test (every 100 steps), each test's line
/// with the figures `eval.csv` recorded.
#[test]
fn training_without_a_terminal_prints_a_line_per_metrics_row_and_per_test() {
    let (dir, stderr) = trained_run();
    let steps: Vec<&str> = stderr.lines().filter(|l| l.starts_with("step ")).collect();
    assert_eq!(steps.len(), 8, "progress lines: {stderr}");
    for (k, line) in (1..).zip(&steps) {
        let start = format!("step {}/{STEPS} (", 50 * k);
        assert!(
            line.starts_with(&start) && line.contains(" steps/s, ") && line.contains(" left, return "),
            "{line}"
        );
    }
    let tests: Vec<&str> = stderr.lines().filter(|l| l.starts_with("test at step ")).collect();
    let eval_csv = std::fs::read_to_string(dir.join("eval.csv")).expect("eval.csv");
    let rows: Vec<Vec<&str>> = eval_csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(tests.len(), 4, "one line per periodic test: {stderr}");
    assert_eq!(tests.len(), rows.len(), "one line per eval.csv row: {eval_csv}");
    // eval.csv: step, episodes, return, rotation, success, drops, ...; the line rounds to 0.01.
    for (line, row) in tests.iter().zip(&rows) {
        let figure = |name: &str| -> f64 {
            let rest = &line[line.find(&format!(" {name} ")).unwrap_or_else(|| panic!("{name} in {line}"))
                + name.len()
                + 2..];
            rest.split([',', ' '])
                .next()
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{name} in {line}"))
        };
        let column = |i: usize| row[i].parse::<f64>().expect("a number");
        assert!(line.starts_with(&format!("test at step {}: ", row[0])), "{line}");
        assert!(line.ends_with(&format!(" rad ({} episodes)", row[1])), "{line}");
        for (name, i) in [("success", 4), ("drops", 5), ("return", 2), ("rotation", 3)] {
            assert!((figure(name) - column(i)).abs() <= 0.0051, "{name}: {line} against {row:?}");
        }
    }
}

#[test]
fn training_writes_the_score_and_vge_score_skips_it_or_scores_again() {
    let dir = copy_of_run("score-skip");
    let s = read_score(&dir);
    assert_eq!((s.episodes, s.seed), (TRAINED_SCORE_EPISODES, HELD_OUT_SEED), "run.score_episodes");
    assert_eq!((s.episode_s, s.grasp_noise_rad), (1.0, 0.02), "the run's success test (TINY: 1 s)");
    let best: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("best-eval.json")).expect("best-eval.json"))
            .expect("json");
    let selected = s.selected.as_ref().expect("the run has a model selection");
    assert_eq!(selected.file, "policy-best.vgep");
    assert_eq!(Some(selected.step), best["selected_step"].as_u64());
    assert_eq!((s.final_policy.file.as_str(), s.final_policy.step), ("policy.vgep", STEPS));
    let last = s.last_snapshots.as_ref().expect("the last three snapshots are kept");
    let steps: Vec<u64> = last.snapshots.iter().map(|p| p.step).collect();
    assert_eq!(steps, vec![200, 300, 400]);
    assert_eq!(last.snapshots[2].file, "snapshots/policy-400.vgep");
    let mean_return = last.snapshots.iter().map(|p| p.mean_return).sum::<f64>() / 3.0;
    assert!((last.mean_return - mean_return).abs() < 1e-9, "{last:?}");
    // The final policy is the snapshot at its step: the same bytes, the same figures; the
    // other snapshots are other files.
    assert_eq!(last.snapshots[2].crc32, s.final_policy.crc32);
    assert_ne!(last.snapshots[1].crc32, s.final_policy.crc32);
    assert_eq!(last.snapshots[2].mean_return, s.final_policy.mean_return);
    for p in [selected, &s.final_policy] {
        assert!((0.0..=1.0).contains(&p.success_rate) && (0.0..=1.0).contains(&p.drop_rate), "{p:?}");
        assert!(p.mean_return.is_finite() && p.mean_rotation_rad.is_finite(), "{p:?}");
        assert!(p.mean_tip_slip_m.is_some_and(|m| m.is_finite() && m >= 0.0), "{p:?}");
    }
    assert!(last.mean_tip_slip_m.is_some_and(f64::is_finite), "{last:?}");

    // Scored with the same episodes already: skipped, the file untouched.
    let before = std::fs::read(dir.join(SCORE_FILE)).expect("score.json");
    let path = dir.to_str().expect("utf-8");
    let out = vge(&["score", path, "--episodes", &TRAINED_SCORE_EPISODES.to_string()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("already scored, skipped"), "{out:?}");
    assert_eq!(std::fs::read(dir.join(SCORE_FILE)).expect("score.json"), before);

    // Other episodes: scored again, one thread, with progress on stderr.
    let out = vge(&["score", path, "--episodes", "3", "--threads", "1"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("15 episodes of 15"), "progress: {}", stderr(&out));
    let three = read_score(&dir);
    assert_eq!(three.episodes, 3);
    let three_bytes = std::fs::read(dir.join(SCORE_FILE)).expect("score.json");
    let out = vge(&["score", path, "--episodes", "3"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("already scored, skipped"), "{out:?}");
    // --force scores again, and the episodes are the same ones: the same file.
    let out = vge(&["score", path, "--episodes", "3", "--force"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains(": scored:"), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stdout).contains(" fingertip slip"), "{out:?}");
    assert_eq!(std::fs::read(dir.join(SCORE_FILE)).expect("score.json"), three_bytes);
    assert!(!dir.join("score.json.tmp").exists(), "the temporary file is renamed into place");

    // A policy file that changed (an extended run) is scored again.
    let other = if selected.step == 300 { 200 } else { 300 };
    std::fs::copy(dir.join(format!("snapshots/policy-{other}.vgep")), dir.join("policy-best.vgep"))
        .expect("copy");
    let out = vge(&["score", path, "--episodes", "3"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains(": scored:"), "{out:?}");
}

/// `vge score DIR` fails, naming `file`, and leaves no score.json.
fn assert_refused(dir: &Path, file: &str, why: &str) {
    let _ = std::fs::remove_file(dir.join(SCORE_FILE));
    let out = vge(&["score", dir.to_str().expect("utf-8"), "--episodes", "2"]);
    assert!(!out.status.success(), "scored a run with a bad {file}");
    let err = stderr(&out);
    assert!(err.contains(&dir.join(file).display().to_string()), "names {file}: {err}");
    assert!(err.contains(why), "says `{why}`: {err}");
    assert!(!dir.join(SCORE_FILE).exists(), "wrote a score despite the bad {file}");
}

#[test]
fn a_damaged_missing_other_layout_or_other_joints_policy_file_fails_naming_the_file() {
    let damaged = copy_of_run("score-damaged");
    let path = damaged.join("policy.vgep");
    let mut bytes = std::fs::read(&path).expect("policy");
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x10;
    std::fs::write(&path, &bytes).expect("damage");
    assert_refused(&damaged, "policy.vgep", "not a valid policy file");

    let missing = copy_of_run("score-missing");
    std::fs::remove_file(missing.join("policy-best.vgep")).expect("remove");
    assert_refused(&missing, "policy-best.vgep", "missing");

    // A valid policy file for another observation layout (same sizes, other slices).
    let other = copy_of_run("score-layout");
    let snapshot = other.join("snapshots/policy-400.vgep");
    let mut file =
        vge_export::PolicyFile::from_bytes(&std::fs::read(&snapshot).expect("snapshot")).expect("decode");
    file.obs_layout = vec![vge_export::ObsSlice::new("q", 0..15), vge_export::ObsSlice::new("rest", 15..65)];
    std::fs::write(&snapshot, file.to_bytes().expect("encode")).expect("write");
    assert_refused(&other, "snapshots/policy-400.vgep", "another observation layout");

    // A valid policy file whose outputs name the thumb's two flexion joints the other way
    // round: run as it is, it would drive the wrong joints.
    let swapped = copy_of_run("score-actions");
    let snapshot = swapped.join("snapshots/policy-400.vgep");
    let mut file =
        vge_export::PolicyFile::from_bytes(&std::fs::read(&snapshot).expect("snapshot")).expect("decode");
    file.action_names.swap(1, 2);
    std::fs::write(&snapshot, file.to_bytes().expect("encode")).expect("write");
    assert_refused(
        &swapped,
        "snapshots/policy-400.vgep",
        "other actions: the policy's actions are [thumb.roll, thumb.flex_dist",
    );
}

#[test]
fn an_unfinished_run_is_refused_and_nothing_is_written() {
    let dir = copy_of_run("score-unfinished");
    // What a run killed before its end lacks: the final evaluation (and so the score).
    std::fs::remove_file(dir.join("final-eval.json")).expect("remove");
    std::fs::remove_file(dir.join(SCORE_FILE)).expect("remove");
    let out = vge(&["score", dir.to_str().expect("utf-8")]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("not a finished run"), "{}", stderr(&out));
    assert!(!dir.join(SCORE_FILE).exists());
    assert!(!dir.join("score.json.tmp").exists());
}
