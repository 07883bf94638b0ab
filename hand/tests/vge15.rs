//! hands/vge15.xml is vge's hand as code (`vge_sim::HandModel::default()`) written as a file:
//! the same fingertips and Jacobians at random configurations, and the same limits, servos and
//! masses the rapier world gives it.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vge_hand::{GeomShape, Hand};
use vge_sim::kinematics::JOINT_NAMES;
use vge_sim::{HandModel, JOINTS_PER_FINGER, NUM_FINGERS, NUM_JOINTS};

fn vge15() -> Hand {
    Hand::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../hands/vge15.xml")).expect("hands/vge15.xml loads")
}

#[test]
fn names_limits_servos_and_masses_are_today_s_hand() {
    let hand = vge15();
    let model = HandModel::default();
    assert_eq!(hand.name(), "vge15");
    assert_eq!((hand.num_joints(), hand.num_fingers()), (NUM_JOINTS, NUM_FINGERS));
    let caps = model.torque_caps_nm();
    for (f, (finger, expected)) in hand.fingers().iter().zip(&model.fingers).enumerate() {
        assert_eq!(finger.name, expected.name);
        assert_eq!(finger.tip_name, format!("{}.tip", expected.name));
        assert_eq!(finger.joints, f * JOINTS_PER_FINGER..(f + 1) * JOINTS_PER_FINGER);
        assert_eq!(finger.tip_radius_m, Some(expected.tip_radius_m));
        for (j, limit) in expected.joint_limits.iter().enumerate() {
            let index = f * JOINTS_PER_FINGER + j;
            let joint = &hand.joints()[index];
            assert_eq!(joint.name, format!("{}.{}", expected.name, JOINT_NAMES[j]));
            let got = joint.limit.unwrap();
            assert_eq!((got.lower_rad, got.upper_rad), (limit.lower_rad, limit.upper_rad));
            let servo = joint.servo.as_ref().unwrap();
            // PhysicsConfig::default(): motor stiffness 20 N m/rad, damping 0.1 N m s/rad.
            assert_eq!((servo.kp_nm_per_rad, servo.kv_nms_per_rad), (20.0, 0.1));
            assert_eq!(servo.force_range_nm, Some([-caps[index], caps[index]]));
            assert_eq!(servo.ctrl_range_rad, Some([limit.lower_rad, limit.upper_rad]));
            assert_eq!((joint.damping_nms_per_rad, joint.armature_kg_m2), (0.0, 0.0));
        }
    }
    assert_eq!(hand.palm().and_then(|p| hand.bodies()[p].name.clone()).as_deref(), Some("palm"));
    assert_eq!(hand.start_grasp_rad(), None);
    // The roll link: the rapier world's point mass. The distal link: a capsule and the tip
    // sphere at 1000 kg/m^3.
    let roll = &hand.bodies()[hand.joints()[0].body];
    assert_eq!(roll.inertial.map(|i| i.mass_kg), Some(0.005));
    let distal = &hand.bodies()[hand.joints()[2].body];
    assert!(distal.inertial.is_none());
    let f = &model.fingers[0];
    let (r, rt, l) = (f64::from(f.link_radius_m), f64::from(f.tip_radius_m), f64::from(f.distal_length_m));
    let pi = std::f64::consts::PI;
    let volume = pi * r * r * l + 4.0 / 3.0 * pi * r.powi(3) + 4.0 / 3.0 * pi * rt.powi(3);
    assert!((f64::from(distal.mass_properties.mass_kg) - 1000.0 * volume).abs() < 1e-7);
    assert!(matches!(distal.geoms[1].shape, GeomShape::Sphere { radius_m } if radius_m == f.tip_radius_m));
    assert!(distal.geoms.iter().all(|g| g.contype == 1 && g.conaffinity == 2 && g.friction[0] == 0.8));
}

#[test]
fn fingertips_and_jacobians_equal_hand_model_at_1000_random_configurations() {
    let hand = vge15();
    let model = HandModel::default();
    let limits = model.joint_limits();
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..1000 {
        let q: Vec<f64> = limits
            .iter()
            .map(|l| rng.random_range(f64::from(l.lower_rad)..=f64::from(l.upper_rad)))
            .collect();
        let tips = hand.fingertip_positions_m(&q).unwrap();
        let jacobians = hand.fingertip_jacobians(&q).unwrap();
        for (f, finger) in model.fingers.iter().enumerate() {
            let start = f * JOINTS_PER_FINGER;
            let qf = [q[start], q[start + 1], q[start + 2]];
            let expected = finger.fingertip_position_m(&qf).unwrap();
            worst.0 = worst.0.max((tips[f] - expected).norm());
            let expected_jacobian = finger.fingertip_jacobian(&qf).unwrap();
            for j in 0..NUM_JOINTS {
                let column = jacobians[f].column(j).into_owned();
                let want = if (start..start + JOINTS_PER_FINGER).contains(&j) {
                    expected_jacobian.column(j - start).into_owned()
                } else {
                    Vector3::zeros()
                };
                worst.1 = worst.1.max((column - want).norm());
            }
            // A contact point 1 cm off the tip centre, rigidly on the distal link.
            let offset = Vector3::new(0.004, -0.006, 0.0078);
            let at_point = hand.fingertip_jacobian_at_point(f, &q, &(expected + offset)).unwrap();
            let contact = finger.contact_jacobian(&qf, &offset).unwrap();
            for j in 0..JOINTS_PER_FINGER {
                worst.1 = worst.1.max((at_point.column(start + j) - contact.column(j)).norm());
            }
        }
    }
    assert!(worst.0 < 1e-6, "fingertip positions differ by up to {} m", worst.0);
    assert!(worst.1 < 1e-6, "Jacobian columns differ by up to {} m/rad", worst.1);
}

#[test]
fn the_f32_kinematics_agree_with_the_f64_ones() {
    let hand = vge15();
    let q: Vec<f32> = (0..NUM_JOINTS).map(|j| 0.1 * j as f32 - 0.4).collect();
    let q64: Vec<f64> = q.iter().map(|v| f64::from(*v)).collect();
    let (a, b) = (hand.fingertip_positions_m(&q).unwrap(), hand.fingertip_positions_m(&q64).unwrap());
    for (a, b) in a.iter().zip(&b) {
        assert!((a.cast::<f64>() - b).norm() < 1e-6);
    }
}
