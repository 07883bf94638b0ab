//! An episode written by [`EpisodeRecorder`]: the JSON Lines file holds the header and one
//! line per control step with the episode's own figures, and drawn by the Python package's
//! converter (python/vge/recording.py) it reads back in Rerun's own Python SDK
//! (`rrd_summary.py`, rerun-sdk 0.36.3, which scripts/test.sh installs in .deps/py) with every
//! entity, one row per control step. A path ending in `.rrd` is refused with the way to get one.

use vge_sim::{Env, EnvConfig, EpisodeRecorder, ObjectShape, RecordingError};

use crate::python_env;
use python_env::recording_summary;

#[test]
fn a_recorded_episode_reads_back_with_every_entity_and_one_row_per_step() {
    let dir = std::env::temp_dir().join(format!("vge-sim-recording-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let allegro =
        EnvConfig::for_hand(vge_sim::hands::load("allegro").expect("allegro")).expect("allegro env");
    for (mut config, shape) in [
        (EnvConfig::default(), ObjectShape::Cube),
        (EnvConfig::default(), ObjectShape::Dodecahedron),
        (allegro, ObjectShape::Cube),
    ] {
        config.object.shape = shape;
        config.episode_length_steps = 8;
        let hand = std::sync::Arc::clone(&config.hand);
        let path = dir.join(format!("{}-{shape}.jsonl", hand.name()));
        let mut recorder = EpisodeRecorder::create(&path, &config).expect("recording");
        // Fingers close a little every step, so the contacts change.
        let action = vec![0.01f32; config.hand.num_joints()];
        let mut rewards = Vec::new();
        let mut rotation_rad = 0.0f64;
        let outcome = Env::new(config)
            .expect("env")
            .run_episode::<vge_sim::SimError>(
                0,
                |_, _| Ok(action.clone()),
                |env, r, _| {
                    recorder.record_step(env, &action, r).expect("step recorded");
                    rewards.push(r.reward);
                    rotation_rad += f64::from(r.info.object_rotation_z_rad);
                },
            )
            .expect("episode");
        assert_eq!(recorder.finish().expect("file written"), 8);
        assert_eq!(outcome.length, 8);

        // The file itself: a header and one line per step, the env's own figures in them.
        let text = std::fs::read_to_string(&path).expect("recording written");
        let lines: Vec<serde_json::Value> =
            text.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect();
        assert_eq!(lines.len(), 9, "a header and 8 steps");
        assert_eq!(lines[0]["format"], "vge episode");
        assert_eq!(lines[0]["object"]["shape"], shape.to_string());
        assert_eq!(lines[0]["hand"], hand.name());
        assert_eq!(lines[0]["fingers"].as_array().expect("fingers").len(), hand.num_fingers());
        assert_eq!(lines[0]["link_geoms"].as_array().expect("link geoms").len(), hand.num_joints());
        assert_eq!(lines[0]["object"].get("mesh_vertices_m").is_some(), shape == ObjectShape::Dodecahedron);
        for (k, line) in lines[1..].iter().enumerate() {
            assert_eq!(line["step"], k as u64 + 1);
            assert_eq!(line["links"].as_array().expect("links").len(), hand.num_joints());
            assert_eq!(line["action_rad"].as_array().expect("actions").len(), hand.num_joints());
            // f32 written as its shortest decimal: read back exactly as f32.
            assert_eq!(line["reward"].as_f64().expect("reward") as f32, rewards[k]);
        }
        let last = lines[8]["rotation_about_z_rad"].as_f64().expect("rotation");
        assert!((last - rotation_rad).abs() < 1e-9, "{last} vs {rotation_rad}");
        // Closing fingers touch the object: some step records a fingertip contact with a force.
        let contact = lines[1..]
            .iter()
            .flat_map(|l| l["fingertip_contacts"].as_array().expect("contacts").clone())
            .next()
            .expect("a fingertip contact");
        let force: f64 = contact["normal_force_n"]
            .as_array()
            .expect("force")
            .iter()
            .map(|x| x.as_f64().expect("number").powi(2))
            .sum();
        assert!(force > 0.0, "{contact}");

        let doc = recording_summary(&path, &dir.join(format!("{}-{shape}.rrd", hand.name())));
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
        for finger in hand.fingers() {
            for j in finger.joints.clone() {
                per_step(&format!("/world/hand/{}/link{j}", finger.name));
                per_step(&format!("/action/{}/joint{j}_rad", finger.name));
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
        let logged: Vec<f32> = doc["scalars"]["/reward_rad_per_s"]
            .as_array()
            .expect("rewards")
            .iter()
            .map(|row| row[1].as_f64().expect("value") as f32)
            .collect();
        let expected = rewards;
        assert_eq!(logged, expected, "{shape}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_recording_named_rrd_is_refused_with_the_way_to_get_one() {
    let path = std::env::temp_dir().join(format!("vge-sim-recording-{}.rrd", std::process::id()));
    let err = EpisodeRecorder::create(&path, &EnvConfig::default()).expect_err("refused");
    assert!(matches!(err, RecordingError::RrdPath(_)), "{err}");
    assert!(err.to_string().contains("python -m vge.recording"), "{err}");
    assert!(!path.exists(), "nothing written");
}
