//! Acceptance tests on the real rapier world: holding, turning, force balance.

use vge_sim::{Env, EnvConfig, ObjectConfig, ObjectShape, StepResult};

fn env_for(shape: ObjectShape) -> Env {
    let config =
        EnvConfig { object: ObjectConfig::of(shape), episode_length_steps: 100_000, ..EnvConfig::default() };
    Env::new(config).expect("config")
}

fn steps_for(env: &Env, seconds: f32) -> usize {
    (seconds / env.config().control_dt_s()).round() as usize
}

/// The zero action of the env's hand.
fn zeros(env: &Env) -> Vec<f32> {
    vec![0.0; env.config().hand.num_joints()]
}

/// Every finger's flexion joints (all but its first, the roll) opened by 1 rad per step.
fn opening(env: &Env) -> Vec<f32> {
    let mut open = zeros(env);
    for finger in env.config().hand.fingers() {
        for j in finger.joints.clone().skip(1) {
            open[j] = -1.0;
        }
    }
    open
}

/// Each object is held for 10 s with zero action: height drift < 2 mm, yaw drift
/// < 0.01 rad, never fewer than 3 fingertips in contact.
#[test]
fn zero_action_holds_every_object_for_ten_seconds() {
    for shape in ObjectShape::ALL {
        let mut env = env_for(shape);
        let (_, info) = env.reset(7).expect("reset");
        assert!(
            info.num_tip_contacts >= 3,
            "{}: only {} tips after the grasp",
            shape.name(),
            info.num_tip_contacts
        );
        let start = env.privileged().expect("state").object;
        let n = steps_for(&env, 10.0);
        let mut min_contacts = env.config().hand.num_fingers();
        let mut last: Option<StepResult> = None;
        let zero = zeros(&env);
        for _ in 0..n {
            let r = env.step(&zero).expect("step");
            min_contacts = min_contacts.min(r.info.num_tip_contacts);
            assert!(!r.terminated, "{}: terminated at step {} ({:?})", shape.name(), r.info.step, r.info);
            last = Some(r);
        }
        let end = env.privileged().expect("state").object;
        let dz = (end.pose.translation.vector.z - start.pose.translation.vector.z).abs();
        let dyaw = (end.yaw_rad() - start.yaw_rad()).abs();
        println!(
            "{}: tips {} (min {min_contacts}), dz {:.3} mm, dyaw {:.5} rad",
            shape.name(),
            info.num_tip_contacts,
            dz * 1e3,
            dyaw
        );
        assert!(last.is_some());
        assert!(dz < 2e-3, "{}: height drift {dz} m", shape.name());
        assert!(dyaw < 0.01, "{}: yaw drift {dyaw} rad", shape.name());
        assert!(min_contacts >= 3, "{}: contacts fell to {min_contacts}", shape.name());
    }
}

/// Ramping all roll joints 0 -> 0.3 rad over 2 s turns the cube > 0.3 rad about z while
/// at least 3 fingertips stay in contact.
#[test]
fn roll_ramp_turns_the_cube_in_grasp() {
    let mut env = env_for(ObjectShape::Cube);
    env.reset(3).expect("reset");
    let yaw0 = env.privileged().expect("state").object.yaw_rad();
    let n = steps_for(&env, 2.0);
    let per_step = 0.3 / n as f32;
    let mut action = zeros(&env);
    for finger in env.config().hand.fingers() {
        action[finger.joints.start] = per_step;
    }
    let mut min_contacts = env.config().hand.num_fingers();
    let mut integrated_reward_rad = 0.0;
    for _ in 0..n + steps_for(&env, 0.5) {
        let r = env.step(&action).expect("step");
        if r.info.step >= n {
            action = zeros(&env);
        }
        min_contacts = min_contacts.min(r.info.num_tip_contacts);
        integrated_reward_rad += r.reward * env.config().control_dt_s();
        assert!(!r.terminated, "terminated: {:?}", r.info);
    }
    let yaw = env.privileged().expect("state").object.yaw_rad() - yaw0;
    println!(
        "cube turned {yaw:.3} rad, reward integrates to {integrated_reward_rad:.3} rad, min contacts {min_contacts}"
    );
    assert!(yaw > 0.3, "turned only {yaw} rad");
    assert!(min_contacts >= 3);
    // The reward is the period-averaged angular velocity: over the ramp it integrates to the
    // rotation (the yaw of a cube held level is its rotation about z).
    assert!((integrated_reward_rad - yaw).abs() < 0.1 * yaw, "reward {integrated_reward_rad} vs yaw {yaw}");
}

/// At rest the contact normal and friction forces on the object balance its weight.
#[test]
fn contact_forces_balance_the_weight_at_rest() {
    for shape in [ObjectShape::Cube, ObjectShape::Sphere, ObjectShape::Icosahedron] {
        let mut env = env_for(shape);
        env.reset(11).expect("reset");
        let zero = zeros(&env);
        for _ in 0..steps_for(&env, 0.5) {
            env.step(&zero).expect("step");
        }
        let world = env.world().expect("world");
        let weight = world.object_mass_kg() * world.physics().gravity_m_per_s2;
        let mut total = nalgebra::Vector3::zeros();
        let mut normal_only = nalgebra::Vector3::zeros();
        for c in world.fingertip_contacts().iter().flatten() {
            total += c.force_on_object_n();
            normal_only += c.normal * c.normal_force_n;
        }
        for c in world.link_contacts().iter().flatten().flatten() {
            total += c.force_on_object_n();
        }
        println!(
            "{}: weight {weight:.4} N, contact force {total:?}, normal part {normal_only:?}",
            shape.name()
        );
        assert!(
            (total.z - weight).abs() < 0.05 * weight,
            "{}: vertical {} vs weight {weight}",
            shape.name(),
            total.z
        );
        assert!(
            total.xy().norm() < 0.05 * weight,
            "{}: horizontal residual {}",
            shape.name(),
            total.xy().norm()
        );
        // The check must be able to fail: the normal forces alone do not carry the
        // weight of a cube squeezed on vertical faces.
        if shape == ObjectShape::Cube {
            assert!((normal_only.z - weight).abs() > 0.05 * weight);
        }
    }
}

/// Opening the hand drops the object and terminates the episode.
#[test]
fn dropping_the_object_terminates() {
    let mut env = env_for(ObjectShape::Cube);
    env.reset(5).expect("reset");
    let open = opening(&env);
    let mut ended = None;
    for _ in 0..steps_for(&env, 2.0) {
        let r = env.step(&open).expect("step");
        if r.terminated {
            ended = Some(r);
            break;
        }
    }
    let r = ended.expect("episode did not terminate");
    assert!(!r.truncated);
    assert_eq!(r.reward, 0.0, "no reward once the grasp is lost");
    // Keep stepping the world: the object does fall away.
    let world = env.world_mut().expect("world");
    for _ in 0..60 {
        world.step();
    }
    assert!(world.object_state().pose.translation.vector.z < -0.05);
}

/// The drop penalty is charged on the drop's step and nowhere else: the same opening of the
/// hand with and without it differs by exactly the penalty, on the last step.
#[test]
fn a_drop_costs_the_drop_penalty_on_its_step_only() {
    let rewards = |penalty: f32| {
        let mut env = env_for(ObjectShape::Cube);
        env.set_drop_penalty(penalty).expect("a valid penalty");
        env.reset(5).expect("reset");
        let open = opening(&env);
        let mut rewards = Vec::new();
        for _ in 0..steps_for(&env, 2.0) {
            let r = env.step(&open).expect("step");
            rewards.push(r.reward);
            if r.terminated {
                assert!(r.info.dropped);
                return rewards;
            }
        }
        panic!("the cube did not drop");
    };
    let (plain, charged) = (rewards(0.0), rewards(7.5));
    assert_eq!(plain.len(), charged.len());
    let last = plain.len() - 1;
    assert_eq!(plain[..last], charged[..last]);
    assert_eq!(charged[last], plain[last] - 7.5);

    let mut env = env_for(ObjectShape::Cube);
    for bad in [-1.0, f32::NAN, f32::INFINITY] {
        assert!(env.set_drop_penalty(bad).is_err(), "{bad}");
    }
    assert_eq!(env.config().drop_penalty, 0.0, "a refused penalty changes nothing");
}

/// NaN, infinite and wrong-length actions are errors and leave the world finite and
/// unchanged.
#[test]
fn bad_actions_are_errors_and_the_world_stays_finite() {
    let mut env = env_for(ObjectShape::Cube);
    let n = env.config().hand.num_joints();
    assert!(matches!(env.step(&zeros(&env)), Err(vge_sim::SimError::NotReset)));
    env.reset(1).expect("reset");
    let before = env.privileged().expect("state").clone();
    let mut nan = zeros(&env);
    nan[4] = f32::NAN;
    let mut inf = zeros(&env);
    inf[0] = f32::NEG_INFINITY;
    assert!(matches!(env.step(&nan), Err(vge_sim::SimError::NonFiniteAction { index: 4, .. })));
    assert!(matches!(env.step(&inf), Err(vge_sim::SimError::NonFiniteAction { index: 0, .. })));
    let short = vec![0.0; n - 1];
    assert!(
        matches!(env.step(&short), Err(vge_sim::SimError::ActionLength { got, expected }) if got == n - 1 && expected == n)
    );
    let long = vec![0.0; n + 1];
    assert!(matches!(env.step(&long), Err(vge_sim::SimError::ActionLength { got, .. }) if got == n + 1));
    let world = env.world().expect("world");
    assert!(world.is_finite());
    assert_eq!(world.joint_targets(), &before.q_target_rad);
    assert_eq!(world.object_state(), before.object);
    // Huge finite actions are clipped, not errors.
    let r = env.step(&vec![1e30; n]).expect("clipped");
    assert!(r.obs.iter().all(|v| v.is_finite()));
    let max = env.config().max_action_rad;
    let targets = env.config().observation_layout().range("q_target_rad").expect("targets");
    for (t, t0) in r.obs[targets].iter().zip(&before.q_target_rad) {
        assert!(*t - *t0 <= max + 1e-6);
    }
}
