//! The Allegro from its file through the whole path, as a user runs it: `vge controller
//! --hand allegro` acts with its 16 joints, `vge train` on `configs/allegro-cube-fg-vge.toml`
//! (VGE, FG, a `proprio:3` actor) writes a policy of the Allegro's sizes with its task record,
//! `vge eval --policy` runs it on its own hand without a config, and a policy of the other hand
//! is refused by eval, naming the hand.

use std::path::{Path, PathBuf};
use std::process::Command;

fn vge(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_vge")).args(args).output().expect("run vge");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `vge controller --kind fg --hand allegro` for two 2 s episodes with `extra` arguments: its
/// JSON summary.
fn allegro_fg_controller(extra: &[&str]) -> serde_json::Value {
    let mut args =
        vec!["controller", "--kind", "fg", "--hand", "allegro", "--episodes", "2", "--episode-s", "2"];
    args.extend_from_slice(extra);
    args.push("--json");
    let (ok, out, err) = vge(&args);
    assert!(ok, "{err}");
    serde_json::from_str(out.trim()).expect("one JSON line")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_allegro_trains_exports_and_evaluates_from_its_file_and_refuses_the_other_hands_policy() {
    let summary = allegro_fg_controller(&[]);
    assert!(summary["mean_rotation_rad"].as_f64().is_some_and(f64::is_finite), "{summary}");

    let dir = std::env::temp_dir().join(format!("vge-second-hand-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = repo().join("configs/allegro-cube-fg-vge.toml");
    let (ok, _, err) = vge(&[
        "train",
        "--config",
        config.to_str().expect("utf-8"),
        "--out",
        dir.to_str().expect("utf-8"),
        "--steps",
        "400",
        "--set",
        "num_envs=2",
        "--set",
        "sac.warmup=200",
        "--set",
        "sac.threads=1",
        "--set",
        "run.eval_interval=0",
        "--set",
        "run.score_episodes=2",
    ]);
    assert!(ok, "{err}");
    let policy = dir.join("policy.vgep");
    let (ok, out, err) = vge(&["inspect", policy.to_str().expect("utf-8")]);
    assert!(ok, "{err}");
    assert!(out.contains("hand:       allegro_right"), "{out}");
    assert!(out.contains("observation set proprio:3"), "{out}");
    assert!(out.contains("obs (128)") && out.contains("actions (16)"), "{out}");

    let (ok, out, err) = vge(&[
        "eval",
        "--policy",
        policy.to_str().expect("utf-8"),
        "--episodes",
        "2",
        "--episode-s",
        "2",
        "--json",
    ]);
    assert!(ok, "{err}");
    let report: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON line");
    assert_eq!(report["episodes"].as_u64(), Some(2), "{report}");

    let (ok, _, err) =
        vge(&["eval", "--policy", policy.to_str().expect("utf-8"), "--hand", "vge15", "--episodes", "1"]);
    assert!(!ok);
    assert!(err.contains("drives the hand allegro_right, not vge15"), "{err}");
    let shipped = repo().join("policies/cube.vgep");
    let (ok, _, err) =
        vge(&["eval", "--policy", shipped.to_str().expect("utf-8"), "--hand", "allegro", "--episodes", "1"]);
    assert!(!ok);
    assert!(err.contains("drives the hand vge15, not allegro_right"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--set` without `--config` overrides the default task on `--hand`: a tilt bound tighter
/// than the grasp's settling ends every episode as a drop, and a key that does not exist is
/// refused by name.
#[test]
fn controller_set_without_a_config_changes_the_hands_task() {
    let free = allegro_fg_controller(&[]);
    assert_eq!(free["drops"], 0, "{free}");
    let bounded = allegro_fg_controller(&["--set", "env.upright_within_rad=0.0001"]);
    assert_eq!(bounded["drops"], 2, "{bounded}");
    assert!(bounded["mean_steps"].as_f64() < free["mean_steps"].as_f64(), "{bounded} {free}");
    let (ok, _, err) =
        vge(&["controller", "--kind", "fg", "--hand", "allegro", "--set", "env.no_such_key=1"]);
    assert!(!ok && err.contains("no_such_key"), "{err}");
}
