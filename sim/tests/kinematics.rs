//! Checks of the hand kinematics against finite differences and hand computations.

use nalgebra::{DMatrix, Isometry3, Matrix3, Point3, UnitQuaternion, Vector3, Vector6};
use vge_sim::{
    Contact, HandModel, JOINTS_PER_FINGER, KinematicsError, NOMINAL_CUBE_SIDE_M, NUM_FINGERS, NUM_JOINTS,
    grasp_map,
};

const TOLERANCE: f64 = 1e-3;
const STEP: f64 = 1e-6;

/// Small deterministic generator so that the configurations are reproducible.
struct Lcg(u64);

impl Lcg {
    fn unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn in_range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    fn vector(&mut self, half_width: f64) -> Vector3<f64> {
        Vector3::new(
            self.in_range(-half_width, half_width),
            self.in_range(-half_width, half_width),
            self.in_range(-half_width, half_width),
        )
    }
}

fn random_configs(hand: &HandModel, finger: usize, n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Lcg(seed);
    let limits = hand.fingers[finger].joint_limits;
    (0..n)
        .map(|_| {
            std::array::from_fn(|j| {
                rng.in_range(f64::from(limits[j].lower_rad), f64::from(limits[j].upper_rad))
            })
        })
        .collect()
}

fn to_f32(q: &[f64; 3]) -> [f32; 3] {
    q.map(|v| v as f32)
}

/// Central differences of a point function of the three joint angles, in f64.
fn central_differences(q: &[f64; 3], point: impl Fn(&[f64; 3]) -> Vector3<f64>) -> Matrix3<f64> {
    let mut jacobian = Matrix3::zeros();
    for j in 0..3 {
        let mut plus = *q;
        let mut minus = *q;
        plus[j] += STEP;
        minus[j] -= STEP;
        jacobian.set_column(j, &((point(&plus) - point(&minus)) / (2.0 * STEP)));
    }
    jacobian
}

fn relative_error(analytic: &DMatrix<f64>, reference: &DMatrix<f64>) -> f64 {
    (analytic - reference).norm() / analytic.norm()
}

/// The acceptance check used by the Jacobian tests (shared so that its sensitivity is
/// tested too).
fn jacobian_matches(analytic: &Matrix3<f64>, reference: &Matrix3<f64>) -> bool {
    let a = DMatrix::from_column_slice(3, 3, analytic.as_slice());
    let r = DMatrix::from_column_slice(3, 3, reference.as_slice());
    relative_error(&a, &r) < TOLERANCE
}

#[test]
fn fingertip_jacobian_matches_central_differences() {
    let hand = HandModel::default();
    for finger in 0..NUM_FINGERS {
        let model = &hand.fingers[finger];
        for q in random_configs(&hand, finger, 8, 17 + finger as u64) {
            let fd = central_differences(&q, |q| model.fingertip_position_m(q).expect("finite"));
            let analytic_f32 = hand.fingertip_jacobian(finger, &to_f32(&q)).expect("valid").cast::<f64>();
            assert!(
                jacobian_matches(&analytic_f32, &fd),
                "finger {finger}, q {q:?}:\n{analytic_f32}\nvs\n{fd}"
            );
            let analytic_f64 = model.fingertip_jacobian(&q).expect("valid");
            assert!((analytic_f64 - fd).norm() / analytic_f64.norm() < 1e-6);
        }
    }
}

#[test]
fn contact_jacobian_matches_differences_of_a_point_fixed_on_the_distal_link() {
    let hand = HandModel::default();
    let mut rng = Lcg(99);
    for finger in 0..NUM_FINGERS {
        let model = &hand.fingers[finger];
        for q in random_configs(&hand, finger, 5, 300 + finger as u64) {
            let direction = rng.vector(1.0).normalize();
            let offset = direction * f64::from(model.tip_radius_m);
            // The contact point expressed in the distal frame, so that it moves rigidly
            // with the distal link when q is perturbed.
            let distal = model.frames(&q).expect("finite")[3];
            let tip = model.fingertip_position_m(&q).expect("finite");
            let local = distal.inverse() * Point3::from(tip + offset);
            let fd = central_differences(&q, |q| (model.frames(q).expect("finite")[3] * local).coords);
            let analytic =
                model.contact_jacobian(&to_f32(&q), &offset.cast::<f32>()).expect("valid").cast::<f64>();
            assert!(jacobian_matches(&analytic, &fd), "finger {finger}, q {q:?}");
        }
    }
}

#[test]
fn jacobian_check_detects_a_sign_flipped_column() {
    let hand = HandModel::default();
    for finger in 0..NUM_FINGERS {
        let model = &hand.fingers[finger];
        for q in random_configs(&hand, finger, 4, 55 + finger as u64) {
            let fd = central_differences(&q, |q| model.fingertip_position_m(q).expect("finite"));
            let good = model.fingertip_jacobian(&q).expect("valid");
            assert!(jacobian_matches(&good, &fd));
            for j in 0..JOINTS_PER_FINGER {
                let mut wrong = good;
                wrong.set_column(j, &(-good.column(j)));
                assert!(
                    !jacobian_matches(&wrong, &fd),
                    "flipping column {j} went unnoticed (finger {finger}, q {q:?})"
                );
            }
        }
    }
}

#[test]
fn grasp_map_transpose_gives_velocities_of_points_fixed_to_the_object() {
    let mut rng = Lcg(2024);
    for trial in 0..10 {
        let centre = rng.vector(0.1);
        let points: Vec<Vector3<f64>> = (0..3 + trial % 3).map(|_| centre + rng.vector(0.07)).collect();
        let v = rng.vector(0.5);
        let omega = rng.vector(2.0);
        let moved = |eps: f64| -> Vec<Vector3<f64>> {
            let rotation = UnitQuaternion::from_scaled_axis(omega * eps);
            points.iter().map(|p| centre + v * eps + rotation * (p - centre)).collect()
        };
        let (plus, minus) = (moved(STEP), moved(-STEP));
        let fd = DMatrix::from_fn(3 * points.len(), 1, |r, _| {
            (plus[r / 3][r % 3] - minus[r / 3][r % 3]) / (2.0 * STEP)
        });
        let points_f32: Vec<Vector3<f32>> = points.iter().map(|p| p.cast()).collect();
        let g = grasp_map(&points_f32, centre.cast()).expect("finite").cast::<f64>();
        assert_eq!(g.shape(), (6, 3 * points.len()));
        let twist = DMatrix::from_column_slice(
            6,
            1,
            Vector6::new(v.x, v.y, v.z, omega.x, omega.y, omega.z).as_slice(),
        );
        let predicted = g.transpose() * &twist;
        assert!(relative_error(&predicted, &fd) < TOLERANCE, "trial {trial}");

        // The check is sensitive: a grasp map with the torque block negated fails it.
        let mut wrong = g.clone();
        wrong.rows_mut(3, 3).neg_mut();
        assert!(relative_error(&(wrong.transpose() * &twist), &fd) > TOLERANCE);
    }
}

#[test]
fn grasp_map_wrench_matches_hand_computation() {
    let centre = Vector3::new(0.1_f32, 0.0, 0.0);
    let points = [centre + Vector3::new(0.05, 0.0, 0.0), centre + Vector3::new(0.0, 0.05, 0.02)];
    let forces = DMatrix::from_column_slice(6, 1, &[-2.0_f32, 0.0, 1.0, 0.0, -3.0, 0.5]);
    let wrench = grasp_map(&points, centre).expect("finite") * forces;
    // force: sum of forces; torque: (0.05,0,0)x(-2,0,1) + (0,0.05,0.02)x(0,-3,0.5)
    //   = (0,-0.05,0) + (0.05*0.5 + 0.02*3, 0, 0) = (0.085, -0.05, 0).
    let expected = [-2.0_f32, -3.0, 1.5, 0.085, -0.05, 0.0];
    for (k, e) in expected.iter().enumerate() {
        approx::assert_abs_diff_eq!(wrench[k], *e, epsilon = 1e-6);
    }
}

#[test]
fn stacked_jacobian_has_finger_blocks_and_zeros_elsewhere() {
    let hand = HandModel::default();
    let q_all: [f32; NUM_JOINTS] = std::array::from_fn(|j| 0.05 * j as f32 - 0.2);
    let contacts = [
        Contact { finger: 3, offset_from_tip_m: Vector3::new(0.0, 0.0, -0.012) },
        Contact::at_tip_centre(0),
        Contact { finger: 3, offset_from_tip_m: Vector3::new(0.012, 0.0, 0.0) },
    ];
    let stacked = hand.stacked_jacobian(&contacts, &q_all).expect("valid");
    assert_eq!(stacked.shape(), (9, NUM_JOINTS));
    for (i, contact) in contacts.iter().enumerate() {
        let q = hand.finger_joints(contact.finger, &q_all).expect("valid");
        let block =
            hand.fingers[contact.finger].contact_jacobian(&q, &contact.offset_from_tip_m).expect("valid");
        let first = contact.finger * JOINTS_PER_FINGER;
        for c in 0..NUM_JOINTS {
            for r in 0..3 {
                let value = stacked[(3 * i + r, c)];
                if (first..first + 3).contains(&c) {
                    assert_eq!(value, block[(r, c - first)]);
                } else {
                    assert_eq!(value, 0.0, "contact {i}: nonzero at column {c}");
                }
            }
        }
        assert!(block.norm() > 0.01, "block {i} is degenerate");
    }
    // The two contacts on finger 3 differ (different points), so the rows differ.
    assert_ne!(stacked.rows(0, 3), stacked.rows(6, 3));
    // Block 1 is the fingertip Jacobian itself.
    let tip_jac = hand.fingertip_jacobian(0, &hand.finger_joints(0, &q_all).expect("valid")).expect("valid");
    assert_eq!(stacked.view((3, 0), (3, 3)), tip_jac);

    let empty = hand.stacked_jacobian(&[], &q_all).expect("valid");
    assert_eq!(empty.shape(), (0, NUM_JOINTS));
}

fn touching_flexion(hand: &HandModel, finger: usize) -> f32 {
    hand.flexion_touching_nominal_cube(finger).expect("valid finger").expect("the finger reaches the cube")
}

#[test]
fn default_hand_reaches_the_cube_faces_within_joint_limits() {
    let hand = HandModel::default();
    let half = NOMINAL_CUBE_SIDE_M / 2.0;
    for finger in 0..NUM_FINGERS {
        let s = touching_flexion(&hand, finger);
        let q = [0.0, s, s];
        let model = &hand.fingers[finger];
        for (j, limit) in model.joint_limits.iter().enumerate() {
            assert!(limit.contains(q[j]), "finger {finger} joint {j} at {} outside limits", q[j]);
        }
        // Moderate flexion: 0.3 to 0.8 rad in total at the tip.
        assert!((0.3..=0.8).contains(&(2.0 * s)), "finger {finger}: total flexion {}", 2.0 * s);
        let tip = hand.fingertip_position_m(finger, &q).expect("valid");
        let (normal_coord, tangential_coord) =
            if tip.x.abs() >= tip.y.abs() { (tip.x.abs(), tip.y.abs()) } else { (tip.y.abs(), tip.x.abs()) };
        // Tip centre at tip_radius from the face plane, i.e. touching it ...
        approx::assert_abs_diff_eq!(normal_coord - half, model.tip_radius_m, epsilon = 1e-5);
        // ... and the touching point lies on the face, not beyond an edge (the fingers at
        // +-36 deg meet the +x face 5 mm from its edges: 72 deg spacing vs a 4-sided cube).
        assert!(tangential_coord < half - 0.004, "finger {finger}: off the face sideways");
        assert!(tip.z.abs() < half - 0.02, "finger {finger}: tip at height {}", tip.z);
    }
    // The thumb (on -x) meets its face squarely at mid-height.
    let s = touching_flexion(&hand, 0);
    let thumb = hand.fingertip_position_m(0, &[0.0, s, s]).expect("valid");
    approx::assert_abs_diff_eq!(thumb.x, -(half + 0.012), epsilon = 1e-5);
    approx::assert_abs_diff_eq!(thumb.y, 0.0, epsilon = 1e-5);
    approx::assert_abs_diff_eq!(thumb.z, 0.0, epsilon = 0.003);
}

#[test]
fn positive_roll_turns_every_fingertip_counter_clockwise() {
    let hand = HandModel::default();
    for finger in 0..NUM_FINGERS {
        let s = touching_flexion(&hand, finger);
        let q = [0.0, s, s];
        let before = hand.fingertip_position_m(finger, &q).expect("valid");
        let after = hand.fingertip_position_m(finger, &[0.1, s, s]).expect("valid");
        let tangent = Vector3::z().cross(&before);
        assert!(tangent.dot(&(after - before)) > 0.0, "finger {finger} moved clockwise");
        let turned = after.y.atan2(after.x) - before.y.atan2(before.x);
        let turned = (turned + std::f32::consts::PI).rem_euclid(std::f32::consts::TAU) - std::f32::consts::PI;
        assert!(turned > 0.0, "finger {finger}: azimuth change {turned}");
        let jacobian = hand.fingertip_jacobian(finger, &q).expect("valid");
        assert!(tangent.dot(&jacobian.column(0).into_owned()) > 0.0);
        // Positive flexion moves the tip radially inward.
        let radial_out = Vector3::new(before.x, before.y, 0.0);
        assert!(radial_out.dot(&jacobian.column(1).into_owned()) < 0.0);
        assert!(radial_out.dot(&jacobian.column(2).into_owned()) < 0.0);
    }
}

#[test]
fn frames_chain_the_links_down_to_the_fingertip() {
    let hand = HandModel::default();
    for finger in 0..NUM_FINGERS {
        let model = &hand.fingers[finger];
        let q = [0.2, 0.4, 0.7];
        let frames: [Isometry3<f32>; 4] = hand.finger_frames(finger, &q).expect("valid");
        assert_eq!(frames[0], model.base_in_world);
        let origin = |k: usize| frames[k].translation.vector;
        approx::assert_abs_diff_eq!((origin(1) - origin(0)).norm(), 0.0, epsilon = 1e-7);
        approx::assert_abs_diff_eq!((origin(2) - origin(0)).norm(), 0.0, epsilon = 1e-7);
        approx::assert_abs_diff_eq!((origin(3) - origin(2)).norm(), model.proximal_length_m, epsilon = 1e-6);
        let tip = hand.fingertip_position_m(finger, &q).expect("valid");
        approx::assert_abs_diff_eq!((tip - origin(3)).norm(), model.distal_length_m, epsilon = 1e-6);
        // The palm is above the object and the fingers hang below it.
        assert!(origin(0).z > NOMINAL_CUBE_SIDE_M / 2.0);
        assert!(tip.z < origin(3).z && origin(3).z < origin(0).z);
    }
}

#[test]
fn default_hand_data_is_complete() {
    let hand = HandModel::default();
    let caps = hand.torque_caps_nm();
    let limits = hand.joint_limits();
    assert_eq!(caps.len(), NUM_JOINTS);
    assert!(caps.iter().all(|c| *c > 0.0));
    assert!(caps[0] > caps[3], "thumb should be stronger");
    assert!(limits.iter().all(|l| l.lower_rad < 0.0 && l.upper_rad > 0.0));
    assert_eq!(hand.fingers[0].name, "thumb");
    // Knuckles 72 deg apart.
    let azimuth = |f: usize| {
        let t = hand.fingers[f].base_in_world.translation.vector;
        t.y.atan2(t.x)
    };
    for f in 0..NUM_FINGERS {
        let step = (azimuth((f + 1) % NUM_FINGERS) - azimuth(f)).rem_euclid(std::f32::consts::TAU);
        approx::assert_abs_diff_eq!(step, 72f32.to_radians(), epsilon = 1e-5);
    }
}

#[test]
fn bad_inputs_are_typed_errors() {
    let hand = HandModel::default();
    assert_eq!(
        hand.fingertip_position_m(5, &[0.0; 3]),
        Err(KinematicsError::FingerOutOfRange { index: 5, count: 5 })
    );
    assert_eq!(
        hand.fingertip_jacobian(usize::MAX, &[0.0; 3]),
        Err(KinematicsError::FingerOutOfRange { index: usize::MAX, count: 5 })
    );
    assert!(matches!(
        hand.finger_frames(7, &[0.0; 3]),
        Err(KinematicsError::FingerOutOfRange { index: 7, .. })
    ));
    assert_eq!(
        hand.fingertip_position_m(1, &[0.0, f32::NAN, 0.0]),
        Err(KinematicsError::NonFiniteJoint { index: 1 })
    );
    assert_eq!(
        hand.fingertip_jacobian(2, &[0.0, 0.0, f32::INFINITY]),
        Err(KinematicsError::NonFiniteJoint { index: 2 })
    );
    let mut q_all = [0.1_f32; NUM_JOINTS];
    assert!(matches!(
        hand.stacked_jacobian(&[Contact::at_tip_centre(5)], &q_all),
        Err(KinematicsError::FingerOutOfRange { index: 5, .. })
    ));
    let bad_offset = Contact { finger: 1, offset_from_tip_m: Vector3::new(0.0, f32::NAN, 0.0) };
    assert!(matches!(
        hand.stacked_jacobian(&[bad_offset], &q_all),
        Err(KinematicsError::NonFiniteInput { .. })
    ));
    q_all[7] = f32::NAN;
    assert_eq!(
        hand.stacked_jacobian(&[Contact::at_tip_centre(0)], &q_all),
        Err(KinematicsError::NonFiniteJoint { index: 7 })
    );
    assert!(matches!(
        grasp_map(&[Vector3::new(0.0, f32::NAN, 0.0)], Vector3::zeros()),
        Err(KinematicsError::NonFiniteInput { .. })
    ));
    assert!(matches!(
        grasp_map(&[Vector3::zeros()], Vector3::new(f32::INFINITY, 0.0, 0.0)),
        Err(KinematicsError::NonFiniteInput { .. })
    ));
    // Error messages say what was wrong.
    let message = KinematicsError::FingerOutOfRange { index: 5, count: 5 }.to_string();
    assert!(message.contains('5'));
}
