//! The MuJoCo model `vge bench sim --write-mjcf` writes, stepped in real MuJoCo (the PyPI
//! wheel scripts/test.sh installs in .deps/py) by the comparison's own harness,
//! scripts/bench_mujoco.py: it must hold the cube as the rapier world does, or the speed
//! comparison times another workload (a model with degree-valued joint limits
//! dropped the cube onto 1.6 fingertips on average).

use std::path::PathBuf;
use std::process::Command;

use vge_sim::EnvConfig;
use vge_sim::mjcf::{GraspKeyframe, MjcfSettings, hand_mjcf};

#[path = "../../tests/support/python.rs"]
mod python_env;
use python_env::python;

#[test]
fn mujoco_holds_the_settled_grasp_on_five_fingertips() {
    // One reset gives both the model's keyframe and rapier's height to compare with.
    let env = EnvConfig::default();
    let hand = vge_sim::HandModel::default();
    let mut sim = vge_sim::Env::new(env.clone()).expect("env");
    sim.reset(0).expect("reset");
    let world = sim.world().expect("world");
    let keyframe_z = world.object_state().pose.translation.vector.z;
    let settings = MjcfSettings {
        hand: &hand,
        servos: &env.servos,
        physics: &env.physics,
        object: &env.object,
        timestep_s: 1.0 / 240.0,
    };
    let xml = hand_mjcf(&settings, &GraspKeyframe::of(world)).expect("model");
    let dir = std::env::temp_dir().join(format!("vge-mjcf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let model = dir.join("hand.xml");
    std::fs::write(&model, &xml).expect("write model");
    let actions = dir.join("actions.f32");
    std::fs::write(
        &actions,
        vge_sim::bench::first_world_actions_f32_le(200, env.hand.num_joints(), env.max_action_rad),
    )
    .expect("write actions");

    let harness = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scripts/bench_mujoco.py");
    let out = Command::new(python())
        .arg(harness)
        .arg(&model)
        .args(["--steps", "200"])
        .arg("--actions")
        .arg(&actions)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with mujoco)");
    let _ = std::fs::remove_dir_all(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "bench_mujoco.py failed: {stderr}");
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON line");

    assert_eq!(r["settled_tip_contacts"], 5, "{r}");
    let settled_z = r["settled_height_m"].as_f64().expect("height");
    assert!(
        (settled_z - f64::from(keyframe_z)).abs() < 0.005,
        "settled at {settled_z} m, rapier at {keyframe_z}"
    );
    // Under the bench's random target changes most steps keep >= 4 fingertips on the cube.
    let mean = r["mean_tip_contacts"].as_f64().expect("mean contacts");
    assert!(mean >= 4.0, "{mean} fingertips on average: {r}");
    assert!(r["sim_seconds_per_s"].as_f64().expect("speed") > 0.0);
}
