//! Domain randomisation on the real rapier world: the object's mass drawn per episode from
//! its range (seeded), the action latency, and disturbances changed between episodes.

use vge_sim::{DomainRandomization, Env, EnvConfig, NoiseConfig, PerturbationConfig};

/// vge15's joints (the default env's hand).
const NUM_JOINTS: usize = 15;

fn env_with(randomization: DomainRandomization) -> Env {
    Env::new(EnvConfig { randomization, ..EnvConfig::default() }).expect("valid config")
}

fn mass_after_reset(env: &mut Env, seed: u64) -> f32 {
    env.reset(seed).expect("reset");
    env.world().expect("world after reset").object_mass_kg()
}

#[test]
fn the_object_mass_is_drawn_per_episode_from_its_range_and_seeded() {
    let nominal = mass_after_reset(&mut env_with(DomainRandomization::default()), 0);
    let fixed = DomainRandomization { mass_scale: [2.0, 2.0], ..DomainRandomization::default() };
    assert!((mass_after_reset(&mut env_with(fixed), 0) - 2.0 * nominal).abs() < 1e-5 * nominal);

    let ranged = DomainRandomization { mass_scale: [0.5, 1.5], ..DomainRandomization::default() };
    let mut env = env_with(ranged);
    let masses: Vec<f32> = (0..6).map(|seed| mass_after_reset(&mut env, seed)).collect();
    assert!(masses.iter().all(|m| (0.5 * nominal..=1.5 * nominal).contains(m)), "{masses:?}");
    assert!(masses.windows(2).any(|w| (w[0] - w[1]).abs() > 1e-3 * nominal), "{masses:?}");
    assert_eq!(mass_after_reset(&mut env, 3), masses[3], "same seed, same draw");
}

#[test]
fn an_action_takes_effect_after_the_latency() {
    let mut env = env_with(DomainRandomization { action_latency_steps: 2, ..DomainRandomization::default() });
    env.reset(1).expect("reset");
    let targets = |env: &Env| env.privileged().expect("state").q_target_rad.clone();
    let before = targets(&env);
    let mut push = [0.0f32; NUM_JOINTS];
    push[0] = 0.04;
    env.step(&push).expect("step");
    env.step(&[0.0; NUM_JOINTS]).expect("step");
    assert_eq!(targets(&env)[0], before[0], "still in flight after 2 steps");
    env.step(&[0.0; NUM_JOINTS]).expect("step");
    assert!((targets(&env)[0] - (before[0] + 0.04)).abs() < 1e-6, "applied on the third step");

    let bad = EnvConfig {
        randomization: DomainRandomization { friction_scale: [1.2, 0.8], ..DomainRandomization::default() },
        ..EnvConfig::default()
    };
    assert!(Env::new(bad).is_err(), "an empty range is refused");
}

/// A curriculum changes the noise and the forces between episodes; a level that is not a
/// valid config is refused and leaves the env as it was, and a valid one shows in the
/// episode that follows (the object is pushed).
#[test]
fn disturbances_can_be_changed_between_episodes_and_invalid_ones_are_refused() {
    let mut env = env_with(DomainRandomization::default());
    let push =
        PerturbationConfig { force_std_n: 1.0, change_probability: 1.0, ..PerturbationConfig::default() };
    let bad =
        PerturbationConfig { force_std_n: -1.0, change_probability: 1.0, ..PerturbationConfig::default() };
    assert!(env.set_disturbances(NoiseConfig::default(), bad).is_err());
    let nan = NoiseConfig { q_std_rad: f32::NAN, ..NoiseConfig::default() };
    assert!(env.set_disturbances(nan, push).is_err());
    assert_eq!(env.config().perturbation, PerturbationConfig::default(), "unchanged after a refusal");
    env.reset(0).expect("reset");
    env.step(&[0.0; NUM_JOINTS]).expect("step");
    assert_eq!(env.external_force_n().norm(), 0.0, "no force before the curriculum raises it");
    env.set_disturbances(NoiseConfig::default(), push).expect("valid levels");
    env.reset(0).expect("reset");
    env.step(&[0.0; NUM_JOINTS]).expect("step");
    assert!(env.external_force_n().norm() > 0.0, "the new level pushes the object");
}

/// A force of fixed magnitude (the paper's "equivalent to the full weight of the object") has
/// that magnitude at every draw, in directions that cover the sphere (each component takes
/// both signs); the per-component Gaussian's magnitude varies. Setting both draws is refused.
#[test]
fn a_fixed_magnitude_force_has_its_magnitude_in_random_directions() {
    let weight_n = 0.15 * 9.81;
    let forces = |push: PerturbationConfig| -> Vec<nalgebra::Vector3<f32>> {
        let mut env =
            Env::new(EnvConfig { perturbation: push, ..EnvConfig::default() }).expect("valid config");
        env.reset(3).expect("reset");
        (0..40).map(|_| env.step(&[0.0; NUM_JOINTS]).map(|_| env.external_force_n()).expect("step")).collect()
    };
    let fixed = PerturbationConfig {
        force_magnitude_n: weight_n,
        change_probability: 1.0,
        ..PerturbationConfig::default()
    };
    let drawn = forces(fixed);
    assert!(drawn.iter().all(|f| (f.norm() - weight_n).abs() < 1e-4), "{drawn:?}");
    for k in 0..3 {
        assert!(drawn.iter().any(|f| f[k] > 0.1) && drawn.iter().any(|f| f[k] < -0.1), "axis {k}: {drawn:?}");
    }
    assert!(drawn.windows(2).all(|w| w[0] != w[1]), "redrawn at every step");

    let gaussian = forces(PerturbationConfig {
        force_std_n: weight_n,
        change_probability: 1.0,
        ..PerturbationConfig::default()
    });
    let norms: Vec<f32> = gaussian.iter().map(|f| f.norm()).collect();
    assert!(norms.iter().any(|&n| n > 1.5 * weight_n) && norms.iter().any(|&n| n < weight_n), "{norms:?}");

    let both = PerturbationConfig { force_std_n: 1.0, ..fixed };
    assert!(
        Env::new(EnvConfig { perturbation: both, ..EnvConfig::default() }).is_err(),
        "one draw or the other"
    );
}
