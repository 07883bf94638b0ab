//! The task variants on the real rapier world: each option changes what the sim does, in
//! the expected direction (a heavier object sinks faster in the same frozen grasp, a more
//! slippery one slides sooner, a doubled torque cap squeezes harder, the side-on hand's
//! gravity points along the hand's +x and its drop test follows it, finger collisions keep
//! two fingertips apart), and bad values are refused naming the field.

use nalgebra::{Isometry3, Vector3};
use vge_sim::{Env, EnvConfig, HandOrientation, HandWorld, ObjectConfig, PhysicsConfig};

/// vge15's sizes (the default env's hand): five fingers of three joints.
const NUM_FINGERS: usize = 5;
const NUM_JOINTS: usize = 15;

/// Joint `joint` of finger `finger` in vge15's finger-major joint vector.
const fn joint_index(finger: usize, joint: usize) -> usize {
    3 * finger + joint
}

/// A long episode so that nothing truncates the few steps a test takes.
fn config_with(edit: impl FnOnce(&mut EnvConfig)) -> EnvConfig {
    let mut config = EnvConfig { episode_length_steps: 10_000, ..EnvConfig::default() };
    edit(&mut config);
    config
}

/// How far (m) the object's centre moved along gravity from where the grasp released it
/// (the origin) to the end of `steps` control steps of zero action, and the step it dropped
/// at (if it did).
fn sink_under_frozen_grasp(config: EnvConfig, steps: usize) -> (f32, Option<usize>) {
    let mut env = Env::new(config).expect("valid config");
    let (_, info) = env.reset(0).expect("reset");
    let mut dropped_at = None;
    let mut height = info.object_height_m;
    for k in 0..steps {
        let r = env.step(&[0.0; NUM_JOINTS]).expect("step");
        height = r.info.object_height_m;
        if r.info.dropped {
            dropped_at = Some(k + 1);
            break;
        }
    }
    (-height, dropped_at)
}

#[test]
fn a_heavier_cube_sinks_faster_under_the_same_frozen_grasp() {
    // The squeeze lifts the default cube a little (negative sink); the contacts' softness lets
    // a heavier one sink further, and past what friction carries (about 14 N) it falls.
    let steps = 40;
    let masses = [0.15, 0.4, 1.0, 1.5];
    let sinks: Vec<(f32, Option<usize>)> = masses
        .iter()
        .map(|&m| sink_under_frozen_grasp(config_with(|c| c.object.mass_kg = m), steps))
        .collect();
    println!("sink (m) and drop step over {steps} steps for {masses:?} kg: {sinks:?}");
    for k in 1..masses.len() {
        assert!(
            sinks[k].0 > sinks[k - 1].0 + 5e-5,
            "{} kg sank no further than {} kg: {sinks:?}",
            masses[k],
            masses[k - 1]
        );
    }
    assert!(sinks[..3].iter().all(|s| s.1.is_none()), "up to 1 kg the grasp holds: {sinks:?}");
    assert!(sinks[3].1.is_some() && sinks[3].0 > 0.03, "1.5 kg falls out: {sinks:?}");
}

#[test]
fn a_lower_friction_cube_slips_sooner() {
    let steps = 40;
    let mass = |c: &mut EnvConfig| c.object.mass_kg = 1.0;
    let (grippy, grippy_drop) = sink_under_frozen_grasp(config_with(mass), steps);
    let (slippery, slippery_drop) = sink_under_frozen_grasp(
        config_with(|c| {
            mass(c);
            c.object.friction = 0.1;
        }),
        steps,
    );
    println!(
        "1 kg over {steps} steps: friction 0.8 sank {grippy} m ({grippy_drop:?}), 0.1 {slippery} m ({slippery_drop:?})"
    );
    assert!(slippery > grippy + 1e-3, "friction 0.1 sank {slippery} m, 0.8 {grippy} m");
}

/// Sum of the fingertips' normal forces (N) after the grasp settled.
fn grip_force_n(config: EnvConfig) -> f32 {
    let mut env = Env::new(config).expect("valid config");
    env.reset(0).expect("reset");
    env.privileged().expect("state").contacts.iter().flatten().map(|c| c.normal_force_n).sum()
}

#[test]
fn a_doubled_torque_cap_squeezes_harder_and_keeps_the_thumbs_proportion() {
    // vge15's file: 0.3 N m on the four fingers, 0.45 on the thumb (joints 0-2).
    let caps = |c: &EnvConfig| c.servos.iter().map(|s| s.torque_cap_nm).collect::<Vec<_>>();
    let mut env = EnvConfig::default();
    let default_caps = caps(&env);
    env.set_motor_torque_cap_nm(0.3);
    assert_eq!(caps(&env), default_caps, "the default cap gives the default hand");
    env.set_motor_torque_cap_nm(0.6);
    let doubled_caps = caps(&env);
    assert!((doubled_caps[1] - 0.9).abs() < 1e-6, "{doubled_caps:?}");
    assert!((doubled_caps[4] - 0.6).abs() < 1e-6, "{doubled_caps:?}");

    let base = grip_force_n(config_with(|_| {}));
    let doubled = grip_force_n(config_with(|c| c.set_motor_torque_cap_nm(0.6)));
    let stiffer = grip_force_n(config_with(|c| c.set_motor_stiffness_nm_per_rad(5.0)));
    println!("grip: default {base} N, cap x2 {doubled} N, stiffness 5 {stiffer} N");
    assert!(doubled > 1.5 * base, "cap x2: {doubled} N against {base} N");
    assert!(stiffer < base, "a softer motor squeezes less within 0.05 rad: {stiffer} N against {base} N");
}

/// The object's displacement (m, world = hand frame) after `steps` physics steps, released
/// at rest in the open hand (fingers straight, 3.8 cm from its faces).
fn free_fall(orientation: HandOrientation, steps: usize) -> Vector3<f32> {
    let physics = PhysicsConfig { hand_orientation: orientation, ..PhysicsConfig::default() };
    let mut world = HandWorld::new(
        &vge_sim::hands::vge15().expect("vge15"),
        &EnvConfig::default().servos,
        &physics,
        &ObjectConfig::default(),
        &[0.0; NUM_JOINTS],
        &Isometry3::identity(),
    )
    .expect("world");
    for _ in 0..steps {
        world.step();
    }
    world.object_state().pose.translation.vector
}

#[test]
fn the_side_on_hands_gravity_points_along_the_hands_plus_x() {
    // 8 steps at 120 Hz: 0.067 s, 2.2 cm of free fall, short of the fingers.
    let fall = 0.5 * 9.81 * (8.0f32 / 120.0).powi(2);
    let side = free_fall(HandOrientation::SideOn, 8);
    let down = free_fall(HandOrientation::PalmDown, 8);
    println!("side on {side:?}, palm down {down:?}, expected {fall} m");
    assert!((side.x - fall).abs() < 0.1 * fall && side.y.abs() < 1e-5 && side.z.abs() < 1e-5, "{side:?}");
    assert!((-down.z - fall).abs() < 0.1 * fall && down.x.abs() < 1e-5 && down.y.abs() < 1e-5, "{down:?}");
    assert_eq!(HandOrientation::SideOn.down(), Vector3::x());
    assert_eq!(PhysicsConfig::default().hand_orientation, HandOrientation::PalmDown);
}

/// Side on, the grasp holds the cube and the drop test measures its fall along +x: opening
/// every finger lets it fall out of the hand sideways, which the drop test sees although
/// its z barely changes.
#[test]
fn the_side_on_drop_test_follows_gravity() {
    let mut env =
        Env::new(config_with(|c| c.physics.hand_orientation = HandOrientation::SideOn)).expect("config");
    let (_, info) = env.reset(0).expect("reset");
    assert!(info.num_tip_contacts >= 3, "side on, {} tips after the grasp", info.num_tip_contacts);
    let start = env.privileged().expect("state").object.pose.translation.vector;
    assert!((info.object_height_m + start.x).abs() < 1e-6, "height is -x side on");
    let mut open = [0.0f32; NUM_JOINTS];
    for finger in 0..NUM_FINGERS {
        open[joint_index(finger, 1)] = -0.05;
        open[joint_index(finger, 2)] = -0.05;
    }
    let mut dropped_at = None;
    for k in 0..40 {
        if env.step(&open).expect("step").info.dropped {
            dropped_at = Some(k + 1);
            break;
        }
    }
    let end = env.privileged().expect("state").object.pose.translation.vector;
    println!("side on, opened: dropped at {dropped_at:?}, moved {:?}", end - start);
    assert!(dropped_at.is_some(), "the opened hand let go: moved {:?}", end - start);
    assert!(end.x - start.x > 0.03 && end.x - start.x > 3.0 * (end.z - start.z).abs(), "{:?}", end - start);
}

/// The smallest distance (m) between two fingertip centres after closing every finger to
/// `flex` on both flexions and rolling fingers 0 and 2 by `roll`, 1 and 3 by `-roll` (towards
/// each other), the object parked out of reach, with finger collisions on or off.
fn closest_tips_m(finger_collisions: bool, flex: f32, roll: f32) -> f32 {
    let physics = PhysicsConfig { finger_collisions, ..PhysicsConfig::default() };
    let hand = vge_sim::hands::vge15().expect("vge15");
    let servos = EnvConfig::default().servos;
    let away = Isometry3::translation(0.0, 0.0, -1.0);
    let mut world =
        HandWorld::new(&hand, &servos, &physics, &ObjectConfig::default(), &[0.0; NUM_JOINTS], &away)
            .expect("world");
    world.set_object_fixed(true);
    let mut target = [0.0f32; NUM_JOINTS];
    for finger in 0..NUM_FINGERS {
        target[joint_index(finger, 0)] = [roll, -roll, roll, -roll, 0.0][finger];
        target[joint_index(finger, 1)] = flex;
        target[joint_index(finger, 2)] = flex;
    }
    world.set_joint_targets(&target);
    for _ in 0..120 {
        world.step();
    }
    let tips: Vec<Vector3<f32>> =
        (0..NUM_FINGERS).map(|f| world.fingertip_position_m(f).expect("tip")).collect();
    let mut closest = f32::INFINITY;
    for a in 0..NUM_FINGERS {
        for b in a + 1..NUM_FINGERS {
            closest = closest.min((tips[a] - tips[b]).norm());
        }
    }
    closest
}

#[test]
fn finger_collisions_keep_two_fingertips_apart() {
    // vge15's fingertip spheres: 12 mm radius (hands/vge15.xml).
    let diameter = 2.0 * 0.012;
    // Closed to 0.8 rad and rolled towards each other in pairs, the tips of fingers 0 and 1
    // (2 and 3) would meet.
    let off = closest_tips_m(false, 0.8, 0.4);
    let on = closest_tips_m(true, 0.8, 0.4);
    println!("closest tips: collisions off {off} m, on {on} m (tip diameter {diameter} m)");
    assert!(off < 0.25 * diameter, "without collisions the tips pass through each other: {off} m");
    assert!(on > 0.95 * diameter, "with collisions the tips stay apart: {on} m");
}

#[test]
fn bad_values_are_refused_naming_the_field() {
    let refused = |edit: fn(&mut EnvConfig)| Env::new(config_with(edit)).expect_err("refused").to_string();
    let nan_mass = refused(|c| c.object.mass_kg = f32::NAN);
    assert!(nan_mass.contains("mass") && nan_mass.contains("NaN"), "{nan_mass}");
    let negative_mass = refused(|c| c.object.mass_kg = -0.4);
    assert!(negative_mass.contains("mass") && negative_mass.contains("-0.4"), "{negative_mass}");
    let friction = refused(|c| c.object.friction = -0.5);
    assert!(friction.contains("friction"), "{friction}");
    let cap = refused(|c| c.set_motor_torque_cap_nm(0.0));
    assert!(cap.contains("torque cap"), "{cap}");
    let stiffness = refused(|c| c.set_motor_stiffness_nm_per_rad(f32::NAN));
    assert!(stiffness.contains("kp > 0"), "{stiffness}");
    let orientation = "upside_down".parse::<HandOrientation>().expect_err("unknown");
    assert!(orientation.contains("hand_orientation") && orientation.contains("side_on"), "{orientation}");
    for o in HandOrientation::ALL {
        assert_eq!(o.name().parse::<HandOrientation>(), Ok(o));
    }
}
