//! The unseen object (the hexagonal prism, on which no config trains) in the real rapier
//! world: it builds as the 12-vertex hull it should be, and the hand's frozen initial grasp
//! holds it, so that a policy tested on it meets an object it could hold.

use vge_sim::{Env, EnvConfig, ObjectConfig, ObjectShape};

/// vge15's sizes (the default env's hand): five fingers of three joints.
const NUM_FINGERS: usize = 5;
const NUM_JOINTS: usize = 15;

#[test]
fn the_hexagonal_prism_builds_as_a_twelve_vertex_hull() {
    let object = ObjectConfig::of(ObjectShape::HexagonalPrism);
    let shape = object.shape().expect("shape");
    let hull = shape.as_convex_polyhedron().expect("a convex hull");
    assert_eq!(hull.points().len(), 12, "two hexagons");
    // Eight faces: two hexagons and six rectangles.
    assert_eq!(hull.faces().len(), 8);
    assert!(!ObjectShape::PAPER.contains(&ObjectShape::HexagonalPrism));
}

/// Zero actions keep every joint at the initial grasp: over 10 s and three grasps (one with
/// the pose noise of the success test) the prism neither drops nor slides (< 2 mm, < 0.01
/// rad), and at least 3 fingertips touch it throughout.
#[test]
fn a_frozen_grasp_holds_the_hexagonal_prism_for_ten_seconds() {
    for (seed, pose_noise_rad) in [(7, 0.0), (11, 0.0), (3, 0.02)] {
        let mut config = EnvConfig {
            object: ObjectConfig::of(ObjectShape::HexagonalPrism),
            episode_length_steps: 100_000,
            ..EnvConfig::default()
        };
        config.grasp.pose_noise_rad = pose_noise_rad;
        let mut env = Env::new(config).expect("the prism's env builds");
        let (_, info) = env.reset(seed).expect("reset");
        assert!(info.num_tip_contacts >= 3, "seed {seed}: {} tips after the grasp", info.num_tip_contacts);
        let start = env.privileged().expect("state").object;
        let steps = (10.0 / env.config().control_dt_s()).round() as usize;
        let mut min_contacts = NUM_FINGERS;
        for _ in 0..steps {
            let r = env.step(&[0.0; NUM_JOINTS]).expect("step");
            assert!(!r.terminated, "seed {seed}: dropped at step {}", r.info.step);
            min_contacts = min_contacts.min(r.info.num_tip_contacts);
        }
        let end = env.privileged().expect("state").object;
        let dz = (end.pose.translation.vector.z - start.pose.translation.vector.z).abs();
        let dyaw = (end.yaw_rad() - start.yaw_rad()).abs();
        println!(
            "seed {seed}: tips {} (min {min_contacts}), dz {:.3} mm, dyaw {dyaw:.5} rad",
            info.num_tip_contacts,
            dz * 1e3
        );
        assert!(dz < 2e-3, "seed {seed}: height drift {dz} m");
        assert!(dyaw < 0.01, "seed {seed}: yaw drift {dyaw} rad");
        assert!(min_contacts >= 3, "seed {seed}: contacts fell to {min_contacts}");
    }
}
