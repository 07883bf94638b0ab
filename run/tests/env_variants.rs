//! The task-variant keys of `[env]` (object mass and friction, motor torque cap and
//! stiffness, hand orientation, finger collisions): absent from the canonical TOML at their
//! defaults (so existing configs keep their hashes), applied to the sim's config by the
//! variant configs under configs/variants/, and refused with the key's name when bad.

use std::path::{Path, PathBuf};

use vge_run::config::{Config, load_config};
use vge_sim::{EnvConfig, HandOrientation};

const VARIANT_KEYS: [&str; 6] = [
    "object_mass_kg",
    "object_friction",
    "motor_torque_cap_nm",
    "motor_stiffness_nm_per_rad",
    "hand_orientation",
    "finger_collisions",
];

fn repo_path(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(relative)
}

fn load(relative: &str, overrides: &[&str]) -> Result<Config, String> {
    let overrides: Vec<String> = overrides.iter().map(|s| (*s).to_owned()).collect();
    load_config(&repo_path(relative), &overrides).map_err(|e| e.to_string())
}

#[test]
fn configs_without_the_variant_keys_serialise_as_before() {
    let base = load("configs/cube-fg-rl.toml", &[]).expect("base config");
    let text = base.to_toml_string().expect("toml");
    for key in VARIANT_KEYS {
        assert!(!text.contains(key), "{key} is written at its default, changing every config's hash");
    }
    let base_env = base.env.env_config(0).expect("env");
    assert_eq!(base_env, EnvConfig { episode_length_steps: 400, ..base_env.clone() });
    let default_env = EnvConfig::default();
    let env = base_env;
    assert_eq!(env.object, default_env.object);
    assert_eq!(env.hand, default_env.hand);
    assert_eq!(env.physics, default_env.physics);
}

#[test]
fn each_variant_config_changes_its_key_only() {
    let base = load("configs/cube-fg-rl.toml", &[]).expect("base config");
    let base_env = base.env.env_config(0).expect("env");
    let variant = |name: &str| {
        let config = load(&format!("configs/variants/{name}.toml"), &[]).expect(name);
        assert_eq!(config.name, format!("cube-fg-rl-{name}"));
        let text = config.to_toml_string().expect("toml");
        (config.env.env_config(0).expect("env"), config, text)
    };

    let (env, _, text) = variant("heavy-cube");
    assert_eq!(env.object.mass_kg, 0.4);
    assert!(text.contains("object_mass_kg = 0.4"), "{text}");
    assert_eq!(EnvConfig { object: base_env.object, ..env }, base_env);

    let (env, _, _) = variant("low-friction");
    assert_eq!(env.object.friction, 0.5);
    assert_eq!(EnvConfig { object: base_env.object, ..env }, base_env);

    let (env, _, _) = variant("torque-2x");
    // vge15's file: 0.3 N m on the fingers (joint 3: the index's first), 0.45 on the thumb's.
    let caps: Vec<f32> = env.servos.iter().map(|s| s.torque_cap_nm).collect();
    assert!((caps[3] - 2.0 * 0.3).abs() < 1e-6, "{caps:?}");
    assert!((caps[0] - 2.0 * 0.45).abs() < 1e-6, "{caps:?}");
    assert!(env.servos.iter().zip(&base_env.servos).all(|(a, b)| a.kp_nm_per_rad == b.kp_nm_per_rad));
    assert_eq!(EnvConfig { servos: base_env.servos.clone(), ..env }, base_env);

    let (env, _, _) = variant("side-on");
    assert_eq!(env.physics.hand_orientation, HandOrientation::SideOn);
    assert_eq!(EnvConfig { physics: base_env.physics, ..env }, base_env);

    let (env, _, _) = variant("fixed-start-paper-reward");
    assert!(!env.charge_reverse_rotation && !env.grasp.randomize_fingers && env.grasp.pose_noise_rad == 0.0);

    let (env, config, _) = variant("sac-alpha0");
    assert_eq!(env, base_env);
    assert_eq!(config.sac, base.sac, "alpha 0 as in the base");
    assert_ne!(config.algorithm, base.algorithm);
}

#[test]
fn the_keys_can_be_set_from_the_command_line() {
    let config = load(
        "configs/cube-fg-rl.toml",
        &[
            "env.object_mass_kg=0.3",
            "env.object_friction=0.6",
            "env.motor_torque_cap_nm=0.45",
            "env.motor_stiffness_nm_per_rad=10",
            "env.hand_orientation=side_on",
            "env.finger_collisions=true",
        ],
    )
    .expect("valid overrides");
    let env = config.env.env_config(0).expect("env");
    assert_eq!((env.object.mass_kg, env.object.friction), (0.3, 0.6));
    assert!((env.servos[3].torque_cap_nm - 0.45).abs() < 1e-6);
    assert!(env.servos.iter().all(|s| s.kp_nm_per_rad == 10.0));
    assert_eq!(env.physics.hand_orientation, HandOrientation::SideOn);
    assert!(env.physics.finger_collisions);
    let text = config.to_toml_string().expect("toml");
    let again = Config::from_toml_str(&text).expect("round trip");
    assert_eq!(again.env, config.env);
}

#[test]
fn bad_values_are_refused_naming_the_key() {
    for (set, key) in [
        ("env.object_mass_kg=nan", "env.object_mass_kg"),
        ("env.object_mass_kg=-0.4", "env.object_mass_kg"),
        ("env.object_mass_kg=0", "env.object_mass_kg"),
        ("env.object_friction=-0.5", "env.object_friction"),
        ("env.motor_torque_cap_nm=0", "env.motor_torque_cap_nm"),
        ("env.motor_stiffness_nm_per_rad=inf", "env.motor_stiffness_nm_per_rad"),
        ("env.hand_orientation=upside_down", "hand_orientation"),
        ("env.finger_collisions=1", "finger_collisions"),
        ("env.action_latency_steps=1000000000000", "env.action_latency_steps"),
        ("env.episode_length=0", "env.episode_length"),
        ("env.episode_length=1000000000000", "env.episode_length"),
        ("run.eval_episodes=0", "run.eval_episodes"),
        ("run.eval_episode_s=nan", "run.eval_episode_s"),
        ("run.eval_grasp_noise_rad=-0.1", "run.eval_grasp_noise_rad"),
    ] {
        let err = load("configs/cube-fg-rl.toml", &[set]).expect_err(set);
        assert!(err.contains(key), "{set}: {err}");
    }
    let err = load("configs/cube-fg-rl.toml", &["env.hand_orientation=upside_down"]).expect_err("unknown");
    assert!(err.contains("side_on") && err.contains("palm_down"), "names the choices: {err}");
}
