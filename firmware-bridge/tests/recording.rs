//! `vge-bridge run --backend sim --record F.rrd` (a test of the `rerun` feature, built on its
//! own: `cargo test --release -p vge-bridge --features rerun --test recording`, as
//! scripts/test.sh does, so the Rerun SDK stays out of the workspace's main test build): the
//! simulated episode read back by Rerun's own Python SDK
//! (sim/tests/rrd_summary.py, rerun-sdk 0.36.3 in .deps/py) holds one frame per sim step the
//! bridge reports; `--record` over CAN is refused before touching the bus.

use std::path::Path;
use std::process::Command;

/// The bridge binary built with this test's features (`rerun` among them).
const BRIDGE: &str = env!("CARGO_BIN_EXE_vge-bridge");

#[path = "../../tests/support/python.rs"]
mod python_env;
use python_env::python;

#[test]
fn bridge_run_records_the_simulated_episode_and_refuses_to_over_can() {
    let dir = std::env::temp_dir().join(format!("vge-bridge-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let rrd = dir.join("bridge.rrd");
    let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");
    let run = Command::new(BRIDGE)
        .args(["run", "--backend", "sim", "--duration", "2", "--json", "--policy", policy, "--record"])
        .arg(&rrd)
        .output()
        .expect("vge-bridge runs");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(stderr.contains("recorded in") && stderr.contains("rerun "), "{stderr}");
    let report: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&run.stdout).trim()).expect("one JSON line");
    let sim_steps = report["sim_steps"].as_u64().expect("sim_steps");
    assert!(sim_steps >= 30, "about 40 periods in 2 s at 20 Hz: {report}");

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/tests/rrd_summary.py");
    let read = Command::new(python())
        .arg(script)
        .arg(&rrd)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with rerun-sdk)");
    assert!(
        read.status.success(),
        "rerun-sdk could not read the recording: {}",
        String::from_utf8_lossy(&read.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&read.stdout).expect("one JSON object");
    let steps: Vec<u64> = (1..=sim_steps).collect();
    assert_eq!(doc["steps"], serde_json::json!(steps), "one frame per sim step");
    for path in [
        "/world/object",
        "/world/hand/thumb/distal",
        "/world/contacts/fingertip_points",
        "/world/contacts/fingertip_normal_force_1cm_per_N",
        "/action/little/flex_dist_rad",
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

    let can = Command::new(BRIDGE)
        .args(["run", "--backend", "can", "--iface", "vge-none0", "--policy", policy, "--record"])
        .arg(dir.join("can.rrd"))
        .output()
        .expect("vge-bridge runs");
    let err = String::from_utf8_lossy(&can.stderr);
    assert!(!can.status.success() && err.contains("--record needs --backend sim"), "{err}");
    assert!(!dir.join("can.rrd").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
