//! scripts/run-facts.py, which the results write-ups quote, on a committed run folder: its
//! row and segments are what the run's own files say.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_owned()
}

fn run_facts(args: &[&str]) -> std::process::Output {
    Command::new("python3")
        .arg(repo().join("scripts/run-facts.py"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("python3 runs")
}

#[test]
fn a_committed_run_gives_its_row_and_its_two_segments() {
    let out = run_facts(&["docs/results/variants/sac-alpha0/table1/rl/seed-6"]);
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
}

#[test]
fn a_folder_without_a_score_is_refused_naming_what_is_missing() {
    let dir = std::env::temp_dir().join(format!("vge-run-facts-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    std::fs::write(dir.join("metrics.csv"), "step\n").expect("write");
    let out = run_facts(&[dir.to_str().expect("utf-8 path")]);
    let _ = std::fs::remove_dir_all(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("missing score.json, final-eval.json, eval.csv"), "{stderr}");
}
