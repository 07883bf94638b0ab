//! The Allegro hand (`hands/allegro.xml`) in the real rapier world: built from its file, it
//! holds the 65 mm cube from its start grasp with the hand still.

use nalgebra::Isometry3;
use vge_sim::{HandWorld, JointServo, ObjectConfig, ObjectShape, PhysicsConfig};

/// The cube the Allegro's file is laid out for (its comments): 65 mm, 0.1 kg.
fn allegro_cube() -> ObjectConfig {
    ObjectConfig { shape: ObjectShape::Cube, width_m: 0.065, mass_kg: 0.1, friction: 0.8 }
}

/// The start grasp's targets: every joint but each finger's first (its spread or rotation)
/// pressed `squeeze_rad` further, as vge's grasp squeezes.
fn squeezed(hand: &vge_hand::Hand, q: &[f32], squeeze_rad: f32) -> Vec<f32> {
    let mut target = q.to_vec();
    for finger in hand.fingers() {
        for j in finger.joints.clone().skip(1) {
            target[j] += squeeze_rad;
        }
    }
    target
}

#[test]
fn the_allegro_builds_from_its_file_with_its_own_sizes() {
    let hand = vge_sim::hands::load("allegro").expect("allegro");
    assert_eq!((hand.num_joints(), hand.num_fingers()), (16, 4));
    let servos = JointServo::from_description(&hand).expect("servos");
    let q = hand.start_grasp_rad().expect("the file's grasp keyframe");
    let far = Isometry3::translation(0.0, 0.0, -1.0);
    let world =
        HandWorld::new(&hand, &servos, &PhysicsConfig::default(), &allegro_cube(), &q, &far).expect("world");
    assert_eq!(world.joint_positions().len(), 16);
    assert_eq!(world.fingertip_contacts().len(), 4);
    // rapier places the fingertips where the file's kinematics put them.
    let fk = hand.fingertip_positions_m(&q).expect("fk");
    for (f, want) in fk.iter().enumerate() {
        let got = world.fingertip_position_m(f).expect("tip");
        assert!((got - want).norm() < 1e-5, "finger {f}: rapier {got:?}, file {want:?}");
    }
    // A servo of the wrong count is refused.
    assert!(
        HandWorld::new(&hand, &servos[..15], &PhysicsConfig::default(), &allegro_cube(), &q, &far).is_err()
    );
}

#[test]
fn the_allegro_holds_the_cube_for_5_s_from_its_start_grasp() {
    let hand = vge_sim::hands::load("allegro").expect("allegro");
    let servos = JointServo::from_description(&hand).expect("servos");
    let q = hand.start_grasp_rad().expect("grasp");
    let physics = PhysicsConfig::default();
    let mut world =
        HandWorld::new(&hand, &servos, &physics, &allegro_cube(), &q, &Isometry3::identity()).expect("world");
    world.set_object_fixed(true);
    world.set_joint_targets(&squeezed(&hand, &q, 0.05));
    let steps = |s: f32| (s * physics.physics_hz).round() as usize;
    for _ in 0..steps(0.05) {
        world.step();
    }
    world.set_object_fixed(false);
    for _ in 0..steps(0.25) {
        world.step();
    }
    let start = world.object_state().pose;
    let touching = world.fingertip_contacts().iter().filter(|c| c.is_some()).count();
    assert!(touching >= 3, "after settling {touching} fingertips touch the cube");
    for _ in 0..steps(5.0) {
        world.step();
    }
    assert!(world.is_finite());
    let end = world.object_state().pose;
    let fall_m = start.translation.vector.z - end.translation.vector.z;
    let moved_m = (end.translation.vector - start.translation.vector).norm();
    let turned_rad = end.rotation.angle_to(&start.rotation);
    let touching = world.fingertip_contacts().iter().filter(|c| c.is_some()).count();
    println!(
        "5 s held: fell {fall_m:.4} m, moved {moved_m:.4} m, turned {turned_rad:.3} rad, {touching} tips touch"
    );
    assert!(touching >= 3, "{touching} fingertips touch after 5 s");
    assert!(fall_m < 0.01, "the cube sank {fall_m} m in 5 s");
    assert!(moved_m < 0.015 && turned_rad < 0.3, "the cube moved {moved_m} m and turned {turned_rad} rad");
}

#[test]
fn torque_driven_joints_turn_the_way_they_are_pushed_and_return_to_their_servos() {
    let hand = vge_sim::hands::load("allegro").expect("allegro");
    let servos = JointServo::from_description(&hand).expect("servos");
    let q = hand.start_grasp_rad().expect("grasp");
    let far = Isometry3::translation(0.0, 0.0, -1.0);
    let mut world =
        HandWorld::new(&hand, &servos, &PhysicsConfig::default(), &allegro_cube(), &q, &far).expect("world");
    // The index finger's middle flexion (ffj2), pushed each way for 0.1 s.
    let joint = hand.joint_index("ffj2").expect("ffj2");
    let mut moved = Vec::new();
    for push_nm in [0.3f32, -0.3] {
        world.set_joint_targets(&q);
        for _ in 0..30 {
            world.step();
        }
        let before = world.joint_positions()[joint];
        let mut torques = vec![0.0; q.len()];
        torques[joint] = push_nm;
        world.set_joint_torques(&torques).expect("torques");
        for _ in 0..12 {
            world.step();
        }
        moved.push(world.joint_positions()[joint] - before);
    }
    assert!(moved[0] > 0.02 && moved[1] < -0.02, "ffj2 moved {moved:?} rad under +-0.3 N m");
    // Back on its servo, it returns to its target.
    world.set_joint_targets(&q);
    for _ in 0..120 {
        world.step();
    }
    let error = (world.joint_positions()[joint] - q[joint]).abs();
    assert!(error < 0.02, "ffj2 is {error} rad from its target 1 s after its servo took over");
    let mut bad = vec![0.0; q.len()];
    bad[3] = f32::NAN;
    assert!(world.set_joint_torques(&bad).is_err());
}

#[test]
fn the_allegro_env_starts_from_its_file_grasp_with_observations_and_actions_of_its_own_size() {
    let hand = vge_sim::hands::load("allegro").expect("allegro");
    let config = vge_sim::EnvConfig::for_hand(hand).expect("config");
    assert_eq!((config.object.width_m, config.object.mass_kg), (0.065, 0.1), "the file's cube");
    let layout = config.observation_layout();
    assert_eq!(layout.dim(), 2 * 16 + 7 * 4);
    let mut env = vge_sim::Env::new(config).expect("env");
    let (obs, info) = env.reset(3).expect("reset");
    assert_eq!(obs.len(), layout.dim());
    assert_eq!(info.grasping_fingers, [true; 4]);
    assert!(info.num_tip_contacts >= 3, "{info:?}");
    // Held still for 2 s (40 control steps at 20 Hz): no drop, the object stays in the grasp.
    let mut contacts = Vec::new();
    for _ in 0..40 {
        let r = env.step(&[0.0; 16]).expect("step");
        assert_eq!(r.obs.len(), layout.dim());
        assert!(!r.terminated, "dropped at step {}", r.info.step);
        contacts.push(r.info.num_tip_contacts);
    }
    assert!(contacts.iter().all(|n| *n >= 3), "fingertips touching: {contacts:?}");
    // Its action has 16 entries, not vge15's 15.
    assert!(env.step(&[0.0; 15]).is_err());
}

/// One zero-action episode from `Env::reset`: what the start grasp must survive.
#[derive(Debug, Clone, Copy)]
struct Hold {
    /// Control step of the drop, if any.
    dropped_at: Option<usize>,
    /// Largest |rotation about z| since the reset (rad): the sum of the steps' turns.
    max_turn_rad: f32,
    /// Fewest fingertips touching at any step.
    min_contacts: usize,
    /// The object's largest distance from where the reset left it (m).
    max_shift_m: f32,
    /// Where the reset left the object's centre (m; the cube starts at the origin).
    reset_at_m: nalgebra::Vector3<f32>,
}

fn hold_from_reset(config: &vge_sim::EnvConfig, seed: u64, steps: usize) -> Hold {
    let mut env = vge_sim::Env::new(config.clone()).expect("env");
    let (_, info) = env.reset(seed).expect("reset");
    let start = env.privileged().expect("state").object.pose.translation.vector;
    let mut hold = Hold {
        dropped_at: None,
        max_turn_rad: 0.0,
        min_contacts: info.num_tip_contacts,
        max_shift_m: 0.0,
        reset_at_m: start,
    };
    let mut turn_rad = 0.0f32;
    let zero = vec![0.0; config.hand.num_joints()];
    for _ in 0..steps {
        let r = env.step(&zero).expect("step");
        turn_rad += r.info.object_rotation_z_rad;
        hold.max_turn_rad = hold.max_turn_rad.max(turn_rad.abs());
        hold.min_contacts = hold.min_contacts.min(r.info.num_tip_contacts);
        let at = env.privileged().expect("state").object.pose.translation.vector;
        hold.max_shift_m = hold.max_shift_m.max((at - start).norm());
        if r.info.dropped {
            hold.dropped_at = Some(r.info.step);
            break;
        }
    }
    hold
}

fn allegro_env_config() -> vge_sim::EnvConfig {
    let hand = vge_sim::hands::load("allegro").expect("allegro");
    let mut config = vge_sim::EnvConfig::for_hand(hand).expect("config");
    config.episode_length_steps = 600;
    config
}

/// Every seed of `seeds` held `steps` control steps with zero action: no drop, at least 3
/// fingertips on the object at every step, turned less than `max_turn_rad` about z.
fn assert_holds(config: &vge_sim::EnvConfig, seeds: std::ops::Range<u64>, steps: usize, max_turn_rad: f32) {
    for seed in seeds {
        let h = hold_from_reset(config, seed, steps);
        println!("seed {seed}: {h:?}");
        assert_eq!(h.dropped_at, None, "seed {seed}: {h:?}");
        assert!(h.min_contacts >= 3, "seed {seed}: {h:?}");
        assert!(h.max_turn_rad < max_turn_rad, "seed {seed}: {h:?}");
    }
}

// Measured (hold_figures, seeds 0..10, 600 steps), pose noise 0 / 0.02 rad: no drop, all 4
// tips on the cube throughout, |turn about z| at most 0.000 / 0.008 rad, the cube within
// 1.1 / 1.3 mm of where the reset left it (0.2 mm from the origin). Before (the flexion joints
// squeezed 0.05 rad, joint damping 0.1) every episode dropped, after 12-29 s.

#[test]
fn the_allegro_holds_its_start_grasp_still_for_30_s_with_zero_action() {
    assert_holds(&allegro_env_config(), 0..10, 600, 0.1);
}

#[test]
fn the_allegro_holds_its_start_grasp_for_30_s_under_the_protocols_pose_noise() {
    let mut config = allegro_env_config();
    config.grasp.pose_noise_rad = 0.02;
    assert_holds(&config, 0..10, 600, 0.1);
}

/// The press is per kg of the object: HORA's heaviest object (0.25 kg) is held as the
/// nominal cube is (measured, seeds 0..10 with the pose noise: at most 0.015 rad, 1.1 mm).
/// At 2 N/kg instead of 5 every episode drops it.
#[test]
fn the_allegro_holds_a_heavier_cube_as_firmly_for_its_weight() {
    let mut config = allegro_env_config();
    config.object.mass_kg = 0.25;
    config.grasp.pose_noise_rad = 0.02;
    assert_holds(&config, 0..3, 600, 0.1);
}

/// Palm up (gravity along the hand's +z) the same keyframe and press hold the cube (measured
/// over 30 s, seeds 0..10 with the pose noise: at most 0.062 rad, 1.6 mm, all 4 tips on).
#[test]
fn the_allegro_holds_the_cube_palm_up_for_5_s() {
    let mut config = allegro_env_config();
    config.physics.hand_orientation = vge_sim::HandOrientation::PalmUp;
    config.grasp.pose_noise_rad = 0.02;
    assert_holds(&config, 0..3, 100, 0.1);
}

/// Per-seed figures for the report, e.g. `VGE_HOLD_NOISE=0.02 cargo test --release -p
/// vge-sim --test integration hold_figures -- --ignored --nocapture` (also `VGE_HOLD_SEEDS`,
/// `VGE_HOLD_STEPS`, `VGE_HOLD_MASS_KG`, `VGE_HOLD_SQUEEZE_N_PER_KG`, `VGE_HOLD_PALM_UP`).
#[test]
#[ignore = "a measurement, not a check"]
fn hold_figures() {
    let var = |name: &str| std::env::var(name).ok().and_then(|s| s.parse::<f32>().ok());
    let mut config = allegro_env_config();
    config.grasp.pose_noise_rad = var("VGE_HOLD_NOISE").unwrap_or(0.0);
    let seeds = var("VGE_HOLD_SEEDS").unwrap_or(10.0) as u64;
    let steps = var("VGE_HOLD_STEPS").unwrap_or(600.0) as usize;
    config.episode_length_steps = steps.max(1);
    if let Some(m) = var("VGE_HOLD_MASS_KG") {
        config.object.mass_kg = m;
    }
    if let Some(f) = var("VGE_HOLD_SQUEEZE_N_PER_KG") {
        config.grasp.squeeze_force_n_per_kg = f;
    }
    if std::env::var("VGE_HOLD_PALM_UP").is_ok() {
        config.physics.hand_orientation = vge_sim::HandOrientation::PalmUp;
    }
    let (mut drops, mut turn, mut shift, mut contacts) = (0, 0.0f32, 0.0f32, usize::MAX);
    for seed in 0..seeds {
        let h = hold_from_reset(&config, seed, steps);
        println!(
            "seed {seed}: drop {:?}, max |turn| {:.3} rad, min contacts {}, max shift {:.1} mm, reset at {:.1?} mm",
            h.dropped_at,
            h.max_turn_rad,
            h.min_contacts,
            1e3 * h.max_shift_m,
            (1e3 * h.reset_at_m).as_slice()
        );
        drops += usize::from(h.dropped_at.is_some());
        turn = turn.max(h.max_turn_rad);
        shift = shift.max(h.max_shift_m);
        contacts = contacts.min(h.min_contacts);
    }
    println!(
        "noise {}: {drops} drops in {seeds}, max |turn| {turn:.3} rad, min contacts {contacts}, max shift {:.1} mm",
        config.grasp.pose_noise_rad,
        1e3 * shift
    );
}
