//! `vge eval --record F.jsonl`: the first episode, step by step, drawn by the Python
//! package's converter and read back by Rerun's own Python SDK (sim/tests/rrd_summary.py,
//! rerun-sdk 0.36.3 in .deps/py); a `.rrd` name is refused with the way to get one.

use crate::common;

use std::process::{Command, Output};

fn vge(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge")).args(args).output().expect("vge runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn eval_record_writes_the_first_episode_step_by_step() {
    let dir = common::temp_dir("eval-record");
    let policy = dir.join("init.vgep").display().to_string();
    let export = vge(&["export", "--init", "--seed", "3", "--out", &policy]);
    assert!(export.status.success(), "{}", text(&export.stderr));
    let recording = dir.join("episode.jsonl");
    let recording_arg = recording.display().to_string();
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
        &recording_arg,
    ]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(
        text(&run.stderr).contains(&format!("`python -m vge.recording {recording_arg} --spawn`")),
        "{}",
        text(&run.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).expect("one JSON line");
    let episode = &report["per_episode"][0];

    let doc = common::recording_summary(&recording, &dir.join("episode.rrd"));

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
    // The converter names links and actions by the hand file's fingers and joint indices.
    let hand = vge_sim::hands::vge15().expect("vge15");
    for finger in hand.fingers() {
        for j in finger.joints.clone() {
            expected.push(format!("/world/hand/{}/link{j}", finger.name));
            expected.push(format!("/action/{}/joint{j}_rad", finger.name));
        }
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

#[test]
fn eval_record_into_an_rrd_name_says_how_to_get_one() {
    let rrd = std::env::temp_dir().join(format!("vge-record-{}.rrd", std::process::id()));
    let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");
    let out = vge(&["eval", "--policy", policy, "--record", &rrd.display().to_string()]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(err.contains("not a Rerun .rrd") && err.contains("python -m vge.recording"), "{err}");
    assert!(!rrd.exists(), "nothing written");
}
