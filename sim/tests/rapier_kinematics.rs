//! The hand file's kinematics (`vge_hand::Hand`: body poses, fingertips, fingertip Jacobians)
//! against the rapier world built from it, for every shipped hand: the world places its bodies
//! where the description's kinematics put them, and moves its fingertips as their Jacobians
//! say. (The kinematics themselves are checked against MuJoCo in python/tests and
//! tests/mujoco_model.rs.)

use std::sync::Arc;

use nalgebra::{Isometry3, Matrix3xX};
use vge_hand::Hand;
use vge_sim::{EnvConfig, HandWorld, ObjectConfig, PhysicsConfig};

fn shipped() -> Vec<(Arc<Hand>, EnvConfig)> {
    vge_sim::hands::shipped_names()
        .into_iter()
        .map(|name| {
            let hand = vge_sim::hands::load(name).expect("a shipped hand");
            let env = EnvConfig::for_hand(Arc::clone(&hand)).expect("servos");
            (hand, env)
        })
        .collect()
}

fn world_at(hand: &Arc<Hand>, env: &EnvConfig, q: &[f32]) -> HandWorld {
    // The object far away so nothing touches.
    let far = Isometry3::translation(0.0, 0.0, -1.0);
    HandWorld::new(hand, &env.servos, &PhysicsConfig::default(), &ObjectConfig::default(), q, &far)
        .expect("world")
}

/// Four configurations inside the servos' ranges, spread over them.
fn configs(env: &EnvConfig) -> Vec<Vec<f32>> {
    (0..4)
        .map(|k| {
            env.servos
                .iter()
                .enumerate()
                .map(|(j, s)| {
                    let frac = 0.1 + 0.2 * ((k * 7 + j * 3) % 5) as f32;
                    s.limit.lower_rad + frac * (s.limit.upper_rad - s.limit.lower_rad)
                })
                .collect()
        })
        .collect()
}

/// rapier's bodies sit on the description's body frames and its fingertips on the kinematics'.
#[test]
fn rapier_bodies_and_fingertips_match_the_hand_s_kinematics() {
    for (hand, env) in shipped() {
        for q in configs(&env) {
            let world = world_at(&hand, &env, &q);
            assert_eq!(world.joint_positions(), q, "{}", hand.name());
            let poses = hand.body_poses_world(&q).expect("kinematics");
            for (b, pose) in poses.iter().enumerate().skip(1) {
                let rapier = world.body_pose(b).expect("pose");
                let dp = (rapier.translation.vector - pose.translation.vector).norm();
                let dr = rapier.rotation.angle_to(&pose.rotation);
                assert!(dp < 1e-5 && dr < 1e-4, "{} body {b}: {dp} m, {dr} rad", hand.name());
            }
            let tips = hand.fingertip_positions_m(&q).expect("kinematics");
            for (f, tip) in tips.iter().enumerate() {
                let rapier = world.fingertip_position_m(f).expect("tip");
                assert!(
                    (rapier - tip).norm() < 1e-5,
                    "{} finger {f}: rapier {rapier:?}, file {tip:?}",
                    hand.name()
                );
            }
        }
    }
}

/// Central differences of the rapier fingertip positions (joints moved in the world) match the
/// description's fingertip Jacobians (relative error < 1e-3), and the check can fail.
#[test]
fn fingertip_jacobians_match_finite_differences_of_the_rapier_world() {
    let h = 2e-3f32;
    for (hand, env) in shipped() {
        for q in configs(&env) {
            let mut world = world_at(&hand, &env, &q);
            let jacobians = hand.fingertip_jacobians(&q).expect("kinematics");
            for (f, finger) in hand.fingers().iter().enumerate() {
                let analytic = &jacobians[f];
                let mut fd = Matrix3xX::zeros(hand.num_joints());
                for j in finger.joints.clone() {
                    let (mut plus, mut minus) = (q.clone(), q.clone());
                    plus[j] += h;
                    minus[j] -= h;
                    world.set_joint_positions(&plus).expect("set");
                    let p = world.fingertip_position_m(f).expect("tip");
                    world.set_joint_positions(&minus).expect("set");
                    let m = world.fingertip_position_m(f).expect("tip");
                    fd.set_column(j, &((p - m) / (2.0 * h)));
                }
                world.set_joint_positions(&q).expect("set");
                let err = (analytic - &fd).norm() / analytic.norm();
                assert!(err < 1e-3, "{} finger {f}: relative error {err}\n{analytic}\n{fd}", hand.name());
                // Sensitivity: a wrong column is caught.
                let mut wrong = analytic.clone();
                wrong.swap_columns(finger.joints.start, finger.joints.start + 1);
                assert!((wrong - &fd).norm() / analytic.norm() > 1e-3, "{} finger {f}", hand.name());
            }
        }
    }
}
