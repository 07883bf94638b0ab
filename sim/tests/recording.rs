//! An episode written by [`EpisodeRecorder`] read back by Rerun's own Python SDK
//! (`rrd_summary.py`, rerun-sdk 0.36.3, which scripts/test.sh installs in .deps/py): every
//! entity is there, with one row per control step, and the rewards are the episode's.

use std::path::Path;
use std::process::Command;

use vge_sim::{Env, EnvConfig, EpisodeRecorder, NUM_JOINTS, ObjectShape};

#[path = "../../tests/support/python.rs"]
mod python_env;
use python_env::python;

/// `rrd_summary.py`'s JSON for `rrd`.
fn summary(rrd: &Path) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/rrd_summary.py");
    let out = Command::new(python())
        .arg(script)
        .arg(rrd)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with rerun-sdk)");
    assert!(
        out.status.success(),
        "rerun-sdk could not read {}: {}",
        rrd.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

#[test]
fn a_recorded_episode_reads_back_with_every_entity_and_one_row_per_step() {
    let dir = std::env::temp_dir().join(format!("vge-sim-recording-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    for shape in [ObjectShape::Cube, ObjectShape::Dodecahedron] {
        let mut config = EnvConfig::default();
        config.object.shape = shape;
        config.episode_length_steps = 8;
        let rrd = dir.join(format!("{shape}.rrd"));
        let mut recorder = EpisodeRecorder::create(&rrd, &config).expect("recording");
        // Fingers close a little every step, so the contacts change.
        let action = [0.01f32; NUM_JOINTS];
        let mut rewards = Vec::new();
        let outcome = Env::new(config)
            .expect("env")
            .run_episode::<vge_sim::SimError>(
                0,
                |_, _| Ok(action),
                |env, r, _| {
                    recorder.record_step(env, &action, r).expect("step recorded");
                    rewards.push(r.reward);
                },
            )
            .expect("episode");
        assert_eq!(recorder.finish().expect("file written"), 8);
        assert_eq!(outcome.length, 8);

        let doc = summary(&rrd);
        let steps: Vec<u64> = (1..=8).collect();
        assert_eq!(doc["steps"], serde_json::json!(steps), "{shape}");
        assert!((doc["sim_time_s"].as_f64().expect("sim_time") - 8.0 * 0.05).abs() < 1e-6, "{doc}");
        let entities = doc["entities"].as_object().expect("entities");
        let per_step = |path: &str| {
            let e = entities.get(path).unwrap_or_else(|| panic!("{path} missing: {:?}", entities.keys()));
            assert_eq!(e["steps"], serde_json::json!(steps), "{path}");
            e
        };
        let object = per_step("/world/object");
        let expected_shape =
            if shape == ObjectShape::Cube { "Boxes3D:half_sizes" } else { "Mesh3D:vertex_positions" };
        assert!(object["static"].as_array().expect("static").iter().any(|c| c == expected_shape), "{object}");
        for finger in ["thumb", "index", "middle", "ring", "little"] {
            for link in ["roll", "proximal", "distal"] {
                per_step(&format!("/world/hand/{finger}/{link}"));
            }
            for joint in ["roll", "flex_prox", "flex_dist"] {
                per_step(&format!("/action/{finger}/{joint}_rad"));
            }
        }
        for contacts in [
            "fingertip_points",
            "fingertip_normal_force_1cm_per_N",
            "link_points",
            "link_normal_force_1cm_per_N",
        ] {
            per_step(&format!("/world/contacts/{contacts}"));
        }
        per_step("/object_rotation_about_z_rad");
        per_step("/reward_rad_per_s");
        let logged: Vec<f64> = doc["scalars"]["/reward_rad_per_s"]
            .as_array()
            .expect("rewards")
            .iter()
            .map(|row| row[1].as_f64().expect("value"))
            .collect();
        let expected: Vec<f64> = rewards.iter().map(|r| f64::from(*r)).collect();
        assert_eq!(logged, expected, "{shape}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
