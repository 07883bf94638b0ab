//! The kinematics (FK, fingertip Jacobian, grasp map) against the real rapier world.

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3, Vector6};
use vge_sim::{
    Env, EnvConfig, HandModel, HandWorld, JOINTS_PER_FINGER, NUM_FINGERS, NUM_JOINTS, ObjectConfig,
    PhysicsConfig, grasp_map,
};

fn world_at(q: &[f32; NUM_JOINTS]) -> HandWorld {
    // The object far away so nothing touches.
    let far = Isometry3::translation(0.0, 0.0, -1.0);
    let hand = vge_sim::hands::vge15().expect("vge15");
    let servos = EnvConfig::default().servos;
    HandWorld::new(&hand, &servos, &PhysicsConfig::default(), &ObjectConfig::default(), q, &far)
        .expect("world")
}

fn configs() -> Vec<[f32; NUM_JOINTS]> {
    (0..4)
        .map(|k| {
            std::array::from_fn(|j| {
                0.1 + 0.37 * ((k * 7 + j * 3) % 5) as f32 * if j % 3 == 0 { 0.2 } else { 0.6 }
            })
        })
        .collect()
}

/// rapier's link bodies sit on the kinematics frames and the fingertip on the FK.
#[test]
fn rapier_links_and_fingertips_match_forward_kinematics() {
    let hand = HandModel::default();
    for q in configs() {
        let world = world_at(&q);
        for f in 0..NUM_FINGERS {
            let qf = hand.finger_joints(f, &q).expect("q");
            let frames = hand.finger_frames(f, &qf).expect("frames");
            for link in 0..JOINTS_PER_FINGER {
                let pose = world.link_pose(vge_sim::kinematics::joint_index(f, link)).expect("pose");
                let dp = (pose.translation.vector - frames[link + 1].translation.vector).norm();
                let dr = pose.rotation.angle_to(&frames[link + 1].rotation);
                assert!(dp < 1e-5 && dr < 1e-5, "finger {f} link {link}: {dp} m, {dr} rad");
            }
            let tip = world.fingertip_position_m(f).expect("tip");
            let fk = hand.fingertip_position_m(f, &qf).expect("fk");
            assert!((tip - fk).norm() < 1e-5, "finger {f}: rapier {tip:?} vs FK {fk:?}");
        }
        assert_eq!(world.joint_positions(), q.to_vec());
    }
}

/// Central differences of the rapier fingertip position (joints moved in the world)
/// match the analytic Jacobian (relative error < 1e-3).
#[test]
fn fingertip_jacobian_matches_finite_differences_of_the_rapier_world() {
    let hand = HandModel::default();
    let h = 2e-3f32;
    for q in configs() {
        let mut world = world_at(&q);
        for f in 0..NUM_FINGERS {
            let qf = hand.finger_joints(f, &q).expect("q");
            let analytic = hand.fingertip_jacobian(f, &qf).expect("J");
            let mut fd = Matrix3::zeros();
            for j in 0..JOINTS_PER_FINGER {
                let k = vge_sim::kinematics::joint_index(f, j);
                let mut plus = q;
                let mut minus = q;
                plus[k] += h;
                minus[k] -= h;
                world.set_joint_positions(&plus).expect("set");
                let p = world.fingertip_position_m(f).expect("tip");
                world.set_joint_positions(&minus).expect("set");
                let m = world.fingertip_position_m(f).expect("tip");
                fd.set_column(j, &((p - m) / (2.0 * h)));
            }
            world.set_joint_positions(&q).expect("set");
            let err = (analytic - fd).norm() / analytic.norm();
            assert!(err < 1e-3, "finger {f}: relative error {err}\n{analytic}\n{fd}");
            // Sensitivity: a wrong column is caught.
            let mut wrong = analytic;
            wrong.swap_columns(1, 2);
            assert!((wrong - fd).norm() / wrong.norm() > 1e-3);
        }
    }
}

/// The grasp map's transpose gives the velocities of the (rapier) contact points when the
/// rapier object body moves by a small twist; G applied to the contact forces read from
/// rapier gives the object wrench that balances gravity.
#[test]
fn grasp_map_matches_finite_differences_of_the_rapier_object() {
    let mut env = Env::new(EnvConfig::default()).expect("env");
    env.reset(2).expect("reset");
    let state = env.privileged().expect("state").clone();
    let contacts: Vec<_> = state.contacts.iter().flatten().copied().collect();
    assert!(contacts.len() >= 3);
    let points: Vec<Vector3<f32>> = contacts.iter().map(|c| c.position_m).collect();
    let pose0 = state.object.pose;
    let centre = pose0.translation.vector;
    let g = grasp_map(&points, centre).expect("G");
    let local: Vec<Vector3<f32>> =
        points.iter().map(|p| pose0.inverse_transform_point(&(*p).into()).coords).collect();
    let world = env.world_mut().expect("world");
    let h = 1e-3f32;
    for axis in 0..6 {
        let mut twist = Vector6::zeros();
        twist[axis] = 1.0;
        let moved = |s: f32| {
            let v = twist.fixed_rows::<3>(0) * s;
            let w = twist.fixed_rows::<3>(3) * s;
            // Rotation about the object centre, then translation.
            let rot = UnitQuaternion::from_scaled_axis(w.into_owned());
            Isometry3::from_parts(Translation3::from(centre + v), rot * pose0.rotation)
        };
        let mut read = |s: f32| -> Vec<Vector3<f32>> {
            world.set_object_pose(&moved(s)).expect("pose");
            let pose = world.object_state().pose;
            local.iter().map(|l| (pose * nalgebra::Point3::from(*l)).coords).collect()
        };
        let plus = read(h);
        let minus = read(-h);
        let predicted = g.transpose() * twist;
        let mut fd = nalgebra::DVector::zeros(3 * points.len());
        for i in 0..points.len() {
            fd.fixed_rows_mut::<3>(3 * i).copy_from(&((plus[i] - minus[i]) / (2.0 * h)));
        }
        let err = (&predicted - &fd).norm() / predicted.norm();
        assert!(err < 1e-3, "twist axis {axis}: relative error {err}");
    }
    // w = G f with the forces rapier applied: balances gravity (force) and nearly zero torque.
    let mut f = nalgebra::DVector::zeros(3 * contacts.len());
    for (i, c) in contacts.iter().enumerate() {
        f.fixed_rows_mut::<3>(3 * i).copy_from(&c.force_on_object_n());
    }
    let wrench = &g * f;
    let weight = 0.15 * 9.81;
    assert!((wrench[2] - weight).abs() < 0.05 * weight, "wrench {wrench}");
    assert!(wrench.fixed_rows::<3>(3).norm() < 0.01, "torque {wrench}");
}
