//! The MuJoCo model `vge bench sim --write-mjcf` writes (vge_sim::mjcf), for each shipped hand,
//! read by real MuJoCo (the PyPI wheel scripts/test.sh installs in .deps/py) as the oracle:
//! its joints are the hand's, in the hand's order; at the keyframe its fingertips are where the
//! hand's kinematics put them; and, stepped by the comparison's own harness
//! (scripts/bench_mujoco.py), it holds the grasp as the rapier world does, or the speed
//! comparison times another workload (a model with degree-valued joint limits dropped vge15's
//! cube onto 1.6 fingertips on average).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;

use vge_hand::Hand;
use vge_sim::{Env, EnvConfig};

use crate::python_env;
use python_env::python;

/// The bench's MuJoCo time step (`vge bench sim --mujoco-timestep-s`'s default).
const TIMESTEP_S: f32 = 1.0 / 240.0;
/// Control steps the harness runs.
const STEPS: usize = 200;

/// MuJoCo's view of the model at its keyframe: joint names in qpos order, the keyframe's qpos,
/// and each fingertip's position (a site's, else a body's, by name).
const READ_KEYFRAME: &str = r#"
import json, sys
import mujoco
model = mujoco.MjModel.from_xml_path(sys.argv[1])
data = mujoco.MjData(model)
mujoco.mj_resetDataKeyframe(model, data, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "grasp"))
mujoco.mj_forward(model, data)
tips = []
for name in sys.argv[2:]:
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    if site >= 0:
        tips.append(data.site_xpos[site].tolist())
    else:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        assert body >= 0, name
        tips.append(data.xpos[body].tolist())
print(json.dumps({
    "joints": [model.joint(j).name for j in range(model.njnt)],
    "qpos": data.qpos.tolist(),
    "tips": tips,
    "body_mass": {model.body(b).name: float(model.body_mass[b]) for b in range(model.nbody)},
}))
"#;

fn run_python(args: &[&std::ffi::OsStr]) -> serde_json::Value {
    let out = Command::new(python())
        .args(args)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with mujoco)");
    assert!(out.status.success(), "python failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("one JSON line")
}

/// What MuJoCo makes of `env`'s model: the keyframe's readout, the harness's JSON line, and
/// rapier's object height after the same reset.
struct Oracle {
    keyframe: serde_json::Value,
    bench: serde_json::Value,
    rapier_height_m: f32,
}

fn oracle(env: &EnvConfig, dir: &Path) -> Oracle {
    let mut sim = Env::new(env.clone()).expect("env");
    sim.reset(0).expect("reset");
    let world = sim.world().expect("world");
    let up = env.physics.hand_orientation.up();
    let rapier_height_m = world.object_state().pose.translation.vector.dot(&up);

    let xml = vge_sim::mjcf::settled_grasp_mjcf(env, 0, TIMESTEP_S).expect("model");
    std::fs::create_dir_all(dir).expect("temp dir");
    let model = dir.join("hand.xml");
    std::fs::write(&model, &xml).expect("write model");
    let actions = dir.join("actions.f32");
    std::fs::write(
        &actions,
        vge_sim::bench::first_world_actions_f32_le(STEPS, env.hand.num_joints(), env.max_action_rad),
    )
    .expect("write actions");

    let tips: Vec<&str> = env.hand.fingers().iter().map(|f| f.tip_name.as_str()).collect();
    let mut args = vec!["-c".as_ref(), READ_KEYFRAME.as_ref(), model.as_os_str()];
    args.extend(tips.iter().map(|t| std::ffi::OsStr::new(*t)));
    let keyframe = run_python(&args);

    let harness = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scripts/bench_mujoco.py");
    let steps = STEPS.to_string();
    let bench = run_python(&[
        harness.as_os_str(),
        model.as_os_str(),
        "--steps".as_ref(),
        steps.as_ref(),
        "--actions".as_ref(),
        actions.as_os_str(),
    ]);
    Oracle { keyframe, bench, rapier_height_m }
}

/// MuJoCo's joints are the hand's, in its order; its fingertips at the keyframe are the
/// hand's kinematics at the keyframe's joint angles (within 1e-5 m); its body masses are the
/// description's.
fn assert_kinematics_match(hand: &Hand, keyframe: &serde_json::Value) {
    let joints: Vec<&str> =
        keyframe["joints"].as_array().expect("joints").iter().filter_map(|v| v.as_str()).collect();
    let expected: Vec<&str> = hand.joints().iter().map(|j| j.name.as_str()).chain(["object"]).collect();
    assert_eq!(joints, expected, "{}: MuJoCo's joint order", hand.name());
    let qpos: Vec<f64> =
        keyframe["qpos"].as_array().expect("qpos").iter().filter_map(|v| v.as_f64()).collect();
    let q = &qpos[..hand.num_joints()];
    let tips = hand.fingertip_positions_m(q).expect("kinematics");
    let mujoco_tips = keyframe["tips"].as_array().expect("tips");
    assert_eq!(mujoco_tips.len(), hand.num_fingers());
    for ((finger, tip), mujoco_tip) in hand.fingers().iter().zip(&tips).zip(mujoco_tips) {
        let m: Vec<f64> = mujoco_tip.as_array().expect("xyz").iter().filter_map(|v| v.as_f64()).collect();
        let error_m = (tip - nalgebra::Vector3::new(m[0], m[1], m[2])).norm();
        assert!(
            error_m < 1e-5,
            "{} {}: MuJoCo {m:?}, the hand {tip:?} ({error_m} m)",
            hand.name(),
            finger.name
        );
    }
    for body in hand.bodies().iter().skip(1) {
        let Some(name) = &body.name else { continue };
        let mass_kg = keyframe["body_mass"][name].as_f64().expect("a body of the hand");
        let expected_kg = f64::from(body.mass_properties.mass_kg);
        assert!((mass_kg - expected_kg).abs() <= 1e-7 * expected_kg.max(1e-3), "{name}: {mass_kg} kg");
    }
}

#[test]
fn mujoco_holds_vge15_s_settled_grasp_on_five_fingertips() {
    let env = EnvConfig::default();
    let dir = std::env::temp_dir().join(format!("vge-mjcf-vge15-{}", std::process::id()));
    let Oracle { keyframe, bench: r, rapier_height_m } = oracle(&env, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    println!("vge15 in MuJoCo: {r}");
    assert_kinematics_match(&env.hand, &keyframe);

    assert_eq!(r["settled_tip_contacts"], 5, "{r}");
    let settled = r["settled_height_m"].as_f64().expect("height");
    assert!(
        (settled - f64::from(rapier_height_m)).abs() < 0.005,
        "settled at {settled} m, rapier at {rapier_height_m}"
    );
    // Under the bench's random target changes most steps keep >= 4 fingertips on the cube.
    let mean = r["mean_tip_contacts"].as_f64().expect("mean contacts");
    assert!(mean >= 4.0, "{mean} fingertips on average: {r}");
    assert!(r["sim_seconds_per_s"].as_f64().expect("speed") > 0.0);
}

#[test]
fn mujoco_holds_the_allegro_s_settled_grasp_on_four_fingertips() {
    let hand: Arc<Hand> = vge_sim::hands::load("allegro").expect("allegro");
    let env = EnvConfig::for_hand(hand).expect("env");
    let dir = std::env::temp_dir().join(format!("vge-mjcf-allegro-{}", std::process::id()));
    let Oracle { keyframe, bench: r, rapier_height_m } = oracle(&env, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    println!("allegro in MuJoCo: {r}, rapier height {rapier_height_m} m");
    assert_kinematics_match(&env.hand, &keyframe);
    assert_eq!(r["joints"], 16, "{r}");
    assert_eq!(r["fingertips"], 4, "{r}");

    assert_eq!(r["settled_tip_contacts"], 4, "{r}");
    let settled = r["settled_height_m"].as_f64().expect("height");
    assert!(
        (settled - f64::from(rapier_height_m)).abs() < 0.005,
        "settled at {settled} m, rapier at {rapier_height_m}"
    );
    let mean = r["mean_tip_contacts"].as_f64().expect("mean contacts");
    assert!(mean >= 3.0, "{mean} fingertips on average: {r}");
}
