//! `vge eval --record F.rrd`: with the `rerun` feature the first episode is written for the
//! Rerun viewer and read back by Rerun's own Python SDK (sim/tests/rrd_summary.py, rerun-sdk
//! 0.36.3 in .deps/py); without it the flag is refused with the way to get it.

mod common;

use std::process::{Command, Output};

fn vge(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge")).args(args).output().expect("vge runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[cfg(feature = "rerun")]
#[test]
fn eval_record_writes_the_first_episode_step_by_step() {
    let dir = common::temp_dir("eval-record");
    let policy = dir.join("init.vgep").display().to_string();
    let export = vge(&["export", "--init", "--seed", "3", "--out", &policy]);
    assert!(export.status.success(), "{}", text(&export.stderr));
    let rrd = dir.join("episode.rrd");
    let rrd_arg = rrd.display().to_string();
    let run = vge(&[
        "eval",
        "--episodes",
        "1",
        "--episode-s",
        "1",
        "--json",
        "--policy",
        &policy,
        "--record",
        &rrd_arg,
    ]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(text(&run.stderr).contains(&format!("open it with `rerun {rrd_arg}`")), "{}", text(&run.stderr));
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).expect("one JSON line");
    let episode = &report["per_episode"][0];

    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/tests/rrd_summary.py");
    let read = Command::new(common::python())
        .arg(script)
        .arg(&rrd)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with rerun-sdk)");
    assert!(read.status.success(), "rerun-sdk could not read the recording: {}", text(&read.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&read.stdout).expect("one JSON object");

    // 1 s at the policy's 20 Hz: 20 control steps, one frame each.
    assert_eq!(episode["length"], 20, "{report}");
    let steps: Vec<u64> = (1..=20).collect();
    assert_eq!(doc["steps"], serde_json::json!(steps));
    assert!((doc["sim_time_s"].as_f64().expect("sim_time") - 1.0).abs() < 1e-6, "{}", doc["sim_time_s"]);
    let entities = doc["entities"].as_object().expect("entities");
    let mut expected = vec![
        "/world/object".to_owned(),
        "/world/contacts/fingertip_points".to_owned(),
        "/world/contacts/fingertip_normal_force_1cm_per_N".to_owned(),
        "/world/contacts/link_points".to_owned(),
        "/world/contacts/link_normal_force_1cm_per_N".to_owned(),
        "/reward_rad_per_s".to_owned(),
        "/object_rotation_about_z_rad".to_owned(),
    ];
    for finger in ["thumb", "index", "middle", "ring", "little"] {
        expected.extend(["roll", "proximal", "distal"].map(|l| format!("/world/hand/{finger}/{l}")));
        expected.extend(["roll", "flex_prox", "flex_dist"].map(|j| format!("/action/{finger}/{j}_rad")));
    }
    for path in &expected {
        let e = entities.get(path).unwrap_or_else(|| panic!("{path} missing: {:?}", entities.keys()));
        assert_eq!(e["steps"], serde_json::json!(steps), "{path}");
    }
    // The same episode as the evaluation's: its rewards add up to the reported return.
    let rewards = doc["scalars"]["/reward_rad_per_s"].as_array().expect("rewards");
    let sum: f64 = rewards.iter().map(|row| row[1].as_f64().expect("value")).sum();
    let expected_return = episode["episode_return"].as_f64().expect("episode_return");
    assert!((sum - expected_return).abs() < 1e-4, "recorded {sum}, evaluated {expected_return}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[cfg(not(feature = "rerun"))]
#[test]
fn eval_record_without_the_rerun_feature_says_how_to_get_it() {
    let rrd = std::env::temp_dir().join(format!("vge-no-rerun-{}.rrd", std::process::id()));
    let out = vge(&["eval", "--policy", "/nonexistent.vgep", "--record", &rrd.display().to_string()]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(err.contains("--features rerun"), "{err}");
    assert!(!rrd.exists(), "nothing written");
}
