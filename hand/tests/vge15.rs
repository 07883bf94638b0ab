//! hands/vge15.xml is vge's own hand, once written as code and now only as this file: its
//! names, limits, servos and masses, and its fingertips and Jacobians at a few configurations,
//! pinned as the figures the code computed (which the file matched to 1e-6 m), so that an edit
//! of the file that moves the hand fails here.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Matrix3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vge_hand::{GeomShape, Hand};

const FINGERS: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];
const JOINTS: [&str; 3] = ["roll", "flex_prox", "flex_dist"];
/// Link radius, fingertip sphere radius and distal link length (m).
const LINK_RADIUS_M: f64 = 0.009;
const TIP_RADIUS_M: f32 = 0.012;
const DISTAL_LENGTH_M: f64 = 0.045;

fn vge15() -> Hand {
    Hand::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../hands/vge15.xml")).expect("hands/vge15.xml loads")
}

/// Three configurations, per finger (roll, flex_prox, flex_dist): all zero; spread per finger;
/// near the limits.
fn configurations() -> [Vec<f64>; 3] {
    let spread = |f: usize| [0.1 * f as f64 - 0.2, 0.3 + 0.2 * f as f64, 1.2 - 0.25 * f as f64];
    [vec![0.0; 15], (0..5).flat_map(spread).collect(), (0..5).flat_map(|_| [-0.45, 1.55, -0.25]).collect()]
}

/// The fingertips (m) at [`configurations`], finger by finger, as the code computed them.
const FINGERTIPS_M: [[[f64; 3]; 5]; 3] = [
    [
        [-0.10000000149011612, -8.742278012618954e-9, -0.010000001639127731],
        [-0.03090170957148075, -0.09510564804077148, -0.010000001639127731],
        [0.08090172708034515, -0.05877849459648132, -0.010000001639127731],
        [0.08090170472860336, 0.05877852439880371, -0.010000001639127731],
        [-0.030901744961738586, 0.09510564059019089, -0.010000001639127731],
    ],
    [
        [-0.040336715640938076, 0.010122198752418595, 0.035065609370896346],
        [-0.014370801280212456, -0.028300966093758942, 0.035944547663420534],
        [0.018966499758622662, -0.01377995891094324, 0.039109370926129976],
        [0.011291366245937122, 0.013255173137272987, 0.044268710922476966],
        [-0.010292459300354818, 0.009356928780988767, 0.050974779560267046],
    ],
    [
        [-0.006650692966273318, 0.005688125991484956, 0.07322468379715298],
        [-0.0074649072513993785, -0.004567460454228914, 0.07322467825840619],
        [0.00203712827488773, -0.008510970889500143, 0.07322468667907928],
        [0.008723918622709784, -0.0006926116855996457, 0.07322468644091283],
        [0.0033545466909417378, 0.008082916435347809, 0.07322468264815915],
    ],
];

/// The thumb's and the index's fingertip Jacobians (m/rad, rows x y z, columns their own three
/// joints) at the second configuration, as the code computed them.
const JACOBIANS_M_PER_RAD: [[f64; 9]; 2] = [
    [
        4.365403153462849e-9,
        0.05095000040584133,
        0.0031831749811468083,
        -0.049934391523173326,
        -0.011853260794304944,
        -0.008917724841779143,
        -0.0101222022787665,
        0.05847399325223989,
        0.04399251915517326,
    ],
    [
        0.046654503537964166,
        0.021752577495810225,
        0.005917173931807974,
        -0.015158970017966518,
        0.044771088404092815,
        0.003779080512979663,
        -0.004921957406010889,
        0.06830042256842504,
        0.04444890521085359,
    ],
];

#[test]
fn names_limits_servos_and_masses_are_the_hand_s() {
    let hand = vge15();
    assert_eq!(hand.name(), "vge15");
    assert_eq!((hand.num_joints(), hand.num_fingers()), (15, 5));
    for (f, (finger, name)) in hand.fingers().iter().zip(FINGERS).enumerate() {
        assert_eq!(finger.name, name);
        assert_eq!(finger.tip_name, format!("{name}.tip"));
        assert_eq!(finger.joints, f * 3..(f + 1) * 3);
        assert_eq!(finger.tip_radius_m, Some(TIP_RADIUS_M));
        // The thumb alone opposes two fingers: a larger torque cap.
        let cap_nm = if name == "thumb" { 0.45 } else { 0.3 };
        for (j, joint_name) in JOINTS.iter().enumerate() {
            let joint = &hand.joints()[f * 3 + j];
            assert_eq!(joint.name, format!("{name}.{joint_name}"));
            let limit = joint.limit.unwrap();
            let expected = if j == 0 { (-0.5, 0.5) } else { (-0.3, 1.6) };
            assert_eq!((limit.lower_rad, limit.upper_rad), expected);
            let servo = joint.servo.as_ref().unwrap();
            assert_eq!((servo.kp_nm_per_rad, servo.kv_nms_per_rad), (20.0, 0.1));
            assert_eq!(servo.force_range_nm, Some([-cap_nm, cap_nm]));
            assert_eq!(servo.ctrl_range_rad, Some([expected.0, expected.1]));
            assert_eq!((joint.damping_nms_per_rad, joint.armature_kg_m2), (0.0, 0.0));
        }
    }
    assert_eq!(hand.palm().and_then(|p| hand.bodies()[p].name.clone()).as_deref(), Some("palm"));
    assert_eq!(hand.start_grasp_rad(), None);
    // The roll link: a point mass. The distal link: a capsule and the tip sphere at 1000 kg/m^3.
    let roll = &hand.bodies()[hand.joints()[0].body];
    assert_eq!(roll.inertial.map(|i| i.mass_kg), Some(0.005));
    let distal = &hand.bodies()[hand.joints()[2].body];
    assert!(distal.inertial.is_none());
    let (r, rt, l) = (LINK_RADIUS_M, f64::from(TIP_RADIUS_M), DISTAL_LENGTH_M);
    let pi = std::f64::consts::PI;
    let volume = pi * r * r * l + 4.0 / 3.0 * pi * r.powi(3) + 4.0 / 3.0 * pi * rt.powi(3);
    assert!((f64::from(distal.mass_properties.mass_kg) - 1000.0 * volume).abs() < 1e-7);
    assert!(matches!(distal.geoms[1].shape, GeomShape::Sphere { radius_m } if radius_m == TIP_RADIUS_M));
    assert!(distal.geoms.iter().all(|g| g.contype == 1 && g.conaffinity == 2 && g.friction[0] == 0.8));
}

#[test]
fn fingertips_and_jacobians_are_the_pinned_figures() {
    let hand = vge15();
    for (c, (q, expected)) in configurations().iter().zip(FINGERTIPS_M).enumerate() {
        let tips = hand.fingertip_positions_m(q).unwrap();
        for (f, (tip, want)) in tips.iter().zip(expected).enumerate() {
            let error_m = (tip - Vector3::from(want)).norm();
            assert!(error_m < 1e-6, "configuration {c}, {}: {tip:?} is {error_m} m off", FINGERS[f]);
        }
    }
    let q = &configurations()[1];
    let jacobians = hand.fingertip_jacobians(q).unwrap();
    for (f, rows) in JACOBIANS_M_PER_RAD.iter().enumerate() {
        let want = Matrix3::from_row_slice(rows);
        for j in 0..15 {
            let column = jacobians[f].column(j).into_owned();
            let expected = if j / 3 == f { want.column(j % 3).into_owned() } else { Vector3::zeros() };
            assert!((column - expected).norm() < 1e-6, "{} joint {j}: {column:?}", FINGERS[f]);
        }
    }
}

#[test]
fn jacobians_match_central_differences_at_100_random_configurations() {
    let hand = vge15();
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    let step = 1e-6;
    let mut worst = 0.0f64;
    for _ in 0..100 {
        let q: Vec<f64> = hand
            .joints()
            .iter()
            .map(|j| {
                let l = j.limit.unwrap();
                rng.random_range(f64::from(l.lower_rad)..=f64::from(l.upper_rad))
            })
            .collect();
        let jacobians = hand.fingertip_jacobians(&q).unwrap();
        for j in 0..q.len() {
            let (mut plus, mut minus) = (q.clone(), q.clone());
            plus[j] += step;
            minus[j] -= step;
            let (p, m) =
                (hand.fingertip_positions_m(&plus).unwrap(), hand.fingertip_positions_m(&minus).unwrap());
            for f in 0..hand.num_fingers() {
                let numeric = (p[f] - m[f]) / (2.0 * step);
                worst = worst.max((jacobians[f].column(j) - numeric).norm());
            }
        }
    }
    assert!(worst < 1e-6, "Jacobian columns differ from central differences by up to {worst} m/rad");
}

#[test]
fn the_f32_kinematics_agree_with_the_f64_ones() {
    let hand = vge15();
    let q: Vec<f32> = (0..15).map(|j| 0.1 * j as f32 - 0.4).collect();
    let q64: Vec<f64> = q.iter().map(|v| f64::from(*v)).collect();
    let (a, b) = (hand.fingertip_positions_m(&q).unwrap(), hand.fingertip_positions_m(&q64).unwrap());
    for (a, b) in a.iter().zip(&b) {
        assert!((a.cast::<f64>() - b).norm() < 1e-6);
    }
}
