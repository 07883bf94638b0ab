//! `vge-bridge run --backend sim --record F.jsonl`: the simulated episode, drawn by the
//! Python package's converter and read back by Rerun's own Python SDK
//! (sim/tests/rrd_summary.py, rerun-sdk 0.36.3 in .deps/py), holds one frame per sim step the
//! bridge reports; `--record` over CAN is refused before touching the bus, and a `.rrd` name
//! with the way to get one.

use std::process::Command;

/// The bridge binary built with this test's features (`sim` among them).
const BRIDGE: &str = env!("CARGO_BIN_EXE_vge-bridge");

use crate::python_env;
use python_env::recording_summary;

#[test]
fn bridge_run_records_the_simulated_episode_and_refuses_to_over_can() {
    let dir = std::env::temp_dir().join(format!("vge-bridge-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let recording = dir.join("bridge.jsonl");
    let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");
    let run = Command::new(BRIDGE)
        .args(["run", "--backend", "sim", "--duration", "2", "--json", "--policy", policy, "--record"])
        .arg(&recording)
        .output()
        .expect("vge-bridge runs");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(stderr.contains("recorded in") && stderr.contains("python -m vge.recording"), "{stderr}");
    let report: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&run.stdout).trim()).expect("one JSON line");
    let sim_steps = report["sim_steps"].as_u64().expect("sim_steps");
    assert!(sim_steps >= 30, "about 40 periods in 2 s at 20 Hz: {report}");

    let doc = recording_summary(&recording, &dir.join("bridge.rrd"));
    let steps: Vec<u64> = (1..=sim_steps).collect();
    assert_eq!(doc["steps"], serde_json::json!(steps), "one frame per sim step");
    for path in [
        "/world/object",
        "/world/hand/thumb/link2",
        "/world/contacts/fingertip_points",
        "/world/contacts/fingertip_normal_force_1cm_per_N",
        "/action/little/joint14_rad",
        "/reward_rad_per_s",
    ] {
        assert_eq!(doc["entities"][path]["steps"], serde_json::json!(steps), "{path}");
    }
    // The recorded turn is the one the bridge reports.
    let rotation = doc["scalars"]["/object_rotation_about_z_rad"]
        .as_array()
        .and_then(|rows| rows.last())
        .and_then(|row| row[1].as_f64())
        .expect("rotation");
    let reported = report["rotation_rad"].as_f64().expect("rotation_rad");
    assert!((rotation - reported).abs() < 1e-3, "recorded {rotation} rad, reported {reported} rad");

    let rrd = Command::new(BRIDGE)
        .args(["run", "--backend", "sim", "--duration", "1", "--policy", policy, "--record"])
        .arg(dir.join("named.rrd"))
        .output()
        .expect("vge-bridge runs");
    let err = String::from_utf8_lossy(&rrd.stderr);
    assert!(!rrd.status.success() && err.contains("python -m vge.recording"), "{err}");
    assert!(!dir.join("named.rrd").exists());

    let can = Command::new(BRIDGE)
        .args(["run", "--backend", "can", "--iface", "vge-none0", "--policy", policy, "--record"])
        .arg(dir.join("can.jsonl"))
        .output()
        .expect("vge-bridge runs");
    let err = String::from_utf8_lossy(&can.stderr);
    assert!(!can.status.success() && err.contains("--record needs --backend sim"), "{err}");
    assert!(!dir.join("can.jsonl").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
