//! The controllers' math on the hand's kinematics (vge15 read from its file): contact-force
//! QP, grasp map, IGM's rotation and stability terms, CS trajectories, FG superposition.
//! The controllers on the rapier env: `controllers_sim.rs`.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use vge_controllers::qp::grasp_map_f64;
use vge_controllers::{
    Controller, ControllerError, ControllerInput, CsConfig, CsController, FgController, FingerContact,
    IgmConfig, IgmController, QpError, TipContact, contact_force_qp, grasp_map, igm::damped_least_squares,
    igm_step, limit_to_joint_range,
};
use vge_hand::Hand;

// ---------------------------------------------------------------- QP

fn check_constraints(c: &[f64], fixed: usize) {
    assert!(c.iter().all(|&v| v >= -1e-9), "negative force in {c:?}");
    assert!((c[fixed] - 1.0).abs() < 1e-9, "c_j = {} != 1", c[fixed]);
}

fn solve(
    points: &[Vector3<f64>],
    normals: &[Vector3<f64>],
) -> Result<vge_controllers::ContactForces, QpError> {
    contact_force_qp(&grasp_map_f64(points, Vector3::zeros()), normals)
}

/// k contacts on a circle of radius 5 cm in the z = 0 plane, normals towards the centre.
fn ring(k: usize) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let points: Vec<_> = (0..k)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / k as f64;
            Vector3::new(0.05 * a.cos(), 0.05 * a.sin(), 0.0)
        })
        .collect();
    let normals = points.iter().map(|p| -p.normalize()).collect();
    (points, normals)
}

#[test]
fn qp_symmetric_three_contacts_reach_equilibrium() {
    let (points, normals) = ring(3);
    let sol = solve(&points, &normals).expect("solvable");
    assert!(sol.residual < 1e-6, "residual {}", sol.residual);
    check_constraints(&sol.magnitudes, sol.fixed_index);
    // 120 deg symmetry: equal forces.
    for c in &sol.magnitudes {
        assert!((c - 1.0).abs() < 1e-6, "{:?}", sol.magnitudes);
    }
}

#[test]
fn qp_symmetric_four_contacts_reach_equilibrium() {
    // Two opposing pairs on the faces of a cube, not through a common line.
    let points = [
        Vector3::new(0.05, 0.01, 0.0),
        Vector3::new(-0.05, 0.01, 0.0),
        Vector3::new(0.0, 0.05, -0.01),
        Vector3::new(0.0, -0.05, -0.01),
    ];
    let normals = [-Vector3::x(), Vector3::x(), -Vector3::y(), Vector3::y()];
    let sol = solve(&points, &normals).expect("solvable");
    assert!(sol.residual < 1e-6, "residual {}", sol.residual);
    check_constraints(&sol.magnitudes, sol.fixed_index);
    // Pairs balance: c0 = c1 and c2 = c3; the largest is the fixed one (normalisation).
    let c = &sol.magnitudes;
    assert!((c[0] - c[1]).abs() < 1e-6 && (c[2] - c[3]).abs() < 1e-6, "{c:?}");
    assert!(c.iter().all(|&v| v <= 1.0 + 1e-9), "{c:?}");
    let (points, normals) = ring(4);
    let sol = solve(&points, &normals).expect("solvable");
    assert!(sol.residual < 1e-6);
    check_constraints(&sol.magnitudes, sol.fixed_index);
}

#[test]
fn qp_asymmetric_grasp_finds_the_unique_balance() {
    // Thumb on -x, two fingers on +x at y = +-2 cm and different heights, one on +y:
    // the +y contact cannot be balanced (nothing pushes -y), so its force must go to ~0
    // while the others balance with c_thumb = c_a + c_b and zero torque.
    let points = [
        Vector3::new(-0.05, 0.0, 0.0),
        Vector3::new(0.05, 0.02, 0.0),
        Vector3::new(0.05, -0.01, 0.0),
        Vector3::new(0.0, 0.05, 0.0),
    ];
    let normals = [Vector3::x(), -Vector3::x(), -Vector3::x(), -Vector3::y()];
    let sol = solve(&points, &normals).expect("solvable");
    assert!(sol.residual < 1e-6, "residual {}", sol.residual);
    check_constraints(&sol.magnitudes, sol.fixed_index);
    let c = &sol.magnitudes;
    assert!(c[3].abs() < 1e-6, "{c:?}");
    // torque about z: 0.02 c1 - 0.01 c2 = 0 (forces along -x at y = 0.02, -0.01) -> c2 = 2 c1.
    assert!((c[2] - 2.0 * c[1]).abs() < 1e-6, "{c:?}");
    assert!((c[0] - c[1] - c[2]).abs() < 1e-6, "{c:?}");
    assert_eq!(sol.fixed_index, 0, "the largest force is normalised to 1");
}

#[test]
fn qp_unbalanceable_grasp_reports_a_positive_residual() {
    // Normals in a half-space (all with +z) but not parallel: solvable, no equilibrium.
    let points =
        [Vector3::new(0.05, 0.0, -0.05), Vector3::new(-0.05, 0.0, -0.05), Vector3::new(0.0, 0.05, -0.05)];
    let normals: Vec<_> = points.iter().map(|p: &Vector3<f64>| -p.normalize()).collect();
    let sol = solve(&points, &normals).expect("solvable");
    check_constraints(&sol.magnitudes, sol.fixed_index);
    assert!(sol.residual > 0.1, "residual {}", sol.residual);
    assert!(!sol.in_equilibrium(1e-6));
}

#[test]
fn qp_degenerate_sets_are_typed_errors() {
    let (points, _) = ring(3);
    let parallel = vec![Vector3::x(); 3];
    assert_eq!(solve(&points, &parallel), Err(QpError::ParallelNormals { count: 3 }));
    let (p2, n2) = ring(2);
    assert_eq!(solve(&p2, &n2), Err(QpError::TooFewContacts { got: 2 }));
    let mut zero = ring(3).1;
    zero[1] = Vector3::zeros();
    assert_eq!(solve(&points, &zero), Err(QpError::ZeroNormal { index: 1 }));
    let mut nan = ring(3).1;
    nan[2].x = f64::NAN;
    assert!(matches!(solve(&points, &nan), Err(QpError::NonFinite(_))));
    let wrong = DMatrix::zeros(6, 6);
    assert!(matches!(contact_force_qp(&wrong, &ring(3).1), Err(QpError::DimensionMismatch { .. })));
}

// The QP's and the controllers' cost per call: `vge bench controllers` (timings
// live in benchmarks, not tests).

// ---------------------------------------------------------------- grasp map

#[test]
fn grasp_map_maps_forces_to_wrenches_and_twists_to_point_velocities() {
    let points =
        [Vector3::new(0.05f64, 0.0, 0.01), Vector3::new(-0.05, 0.02, 0.0), Vector3::new(0.0, -0.05, 0.0)];
    let centre = Vector3::new(0.0, 0.0, 0.01);
    let g = grasp_map(&points, centre).expect("finite");
    assert_eq!(g, grasp_map_f64(&points, centre));
    assert_eq!((g.nrows(), g.ncols()), (6, 9));
    // A push along -x on +x at the centre's height: a force, no torque.
    let mut f = DVector::zeros(9);
    f[0] = -1.0;
    let w = &g * &f;
    assert!((w - DVector::from_vec(vec![-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])).norm() < 1e-12);
    // Turning about +z at 1 rad/s moves the +x point along +y at 5 cm/s.
    let v = g.transpose() * DVector::from_vec(vec![0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    assert!((v[1] - 0.05).abs() < 1e-12 && v[0].abs() < 1e-12, "{v:?}");
    let nan = [Vector3::new(f32::NAN, 0.0, 0.0)];
    assert!(matches!(grasp_map(&nan, Vector3::zeros()), Err(ControllerError::NonFinite(_))));
}

// ---------------------------------------------------------------- hand at a grasp

fn vge15() -> Arc<Hand> {
    vge_sim::hands::vge15().expect("the shipped vge15 hand")
}

/// Joint `joint` (0 = roll, 1 = proximal flexion, 2 = distal flexion) of vge15's `finger`.
fn joint_index(hand: &Hand, finger: usize, joint: usize) -> usize {
    let joints = hand.fingers()[finger].joints.clone();
    assert!(joint < joints.len());
    joints.start + joint
}

fn tips(hand: &Hand, q: &[f32]) -> Vec<Vector3<f32>> {
    hand.fingertip_positions_m(q).expect("valid joints")
}

/// Equal flexion on both flexion joints (roll 0) at which `finger`'s tip sphere touches the
/// nearest face of the hand's nominal cube at the origin, by bisection on the kinematics.
fn touching_flexion(hand: &Hand, finger: usize) -> f32 {
    let half = f64::from(hand.nominal_object().expect("vge15 names its cube").width_m) / 2.0;
    let radius = f64::from(hand.fingers()[finger].tip_radius_m.expect("a tip sphere"));
    let gap = |s: f64| {
        let mut q = vec![0.0f64; hand.num_joints()];
        q[joint_index(hand, finger, 1)] = s;
        q[joint_index(hand, finger, 2)] = s;
        let tip = hand.fingertip_positions_m(&q).expect("valid")[finger];
        tip.x.abs().max(tip.y.abs()) - (half + radius)
    };
    let (mut lo, mut hi) = (0.0, 1.2);
    assert!(gap(lo) > 0.0 && gap(hi) <= 0.0, "finger {finger} does not reach the cube");
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if gap(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (0.5 * (lo + hi)) as f32
}

struct Grasp {
    hand: Arc<Hand>,
    q: Vec<f32>,
    contacts: Vec<TipContact>,
}

/// All five fingertips touching the cube's faces; contact point on the face, normal into
/// the cube (given *outward* on purpose: the controllers must orient it), force `force_n`.
fn cube_grasp(force_n: f32) -> Grasp {
    let hand = vge15();
    let half = hand.nominal_object().expect("cube").width_m / 2.0;
    let mut q = vec![0.0; hand.num_joints()];
    for finger in 0..hand.num_fingers() {
        let s = touching_flexion(&hand, finger);
        q[joint_index(&hand, finger, 1)] = s;
        q[joint_index(&hand, finger, 2)] = s;
    }
    let mut contacts = Vec::new();
    for (finger, tip) in tips(&hand, &q).into_iter().enumerate() {
        let outward = if tip.x.abs() >= tip.y.abs() {
            Vector3::new(tip.x.signum(), 0.0, 0.0)
        } else {
            Vector3::new(0.0, tip.y.signum(), 0.0)
        };
        let point = tip - outward * hand.fingers()[finger].tip_radius_m.expect("sphere");
        assert!((point.x.abs().max(point.y.abs()) - half).abs() < 1e-4);
        contacts.push(TipContact { finger, point_m: point, normal: outward, force_n });
    }
    Grasp { hand, q, contacts }
}

fn rotation_only(config: IgmConfig) -> IgmConfig {
    IgmConfig { alpha_m_per_n: 0.0, max_delta_rad: 10.0, ..config }
}

/// Applies IGM's dq_rot (stability off) and checks the fingertips follow G^T do.
fn check_rotation(reverse: bool) {
    let g = cube_grasp(1.0);
    let mut config = rotation_only(IgmConfig::default());
    if reverse {
        config = config.reversed();
    }
    let out = igm_step(&g.hand, &g.q, &g.contacts, Vector3::zeros(), &config).expect("igm");
    assert_eq!(out.delta_rad, out.dq_rot_rad, "stability term must be off");
    // Least-squares residual of J_S dq_rot = G^T do, relative, with J_S at the contact points.
    let q64: Vec<f64> = g.q.iter().map(|&v| f64::from(v)).collect();
    let mut js = DMatrix::zeros(3 * g.contacts.len(), g.hand.num_joints());
    for (i, c) in g.contacts.iter().enumerate() {
        let block = g.hand.fingertip_jacobian_at_point(c.finger, &q64, &c.point_m.cast::<f64>()).expect("ok");
        js.view_mut((3 * i, 0), (3, g.hand.num_joints())).copy_from(&block);
    }
    let points: Vec<_> = g.contacts.iter().map(|c| c.point_m.cast::<f64>()).collect();
    let grasp = grasp_map(&points, Vector3::zeros()).expect("ok");
    let twist = DVector::from_iterator(6, config.object_delta.iter().map(|&v| f64::from(v)));
    let wanted = grasp.transpose() * twist;
    let dq = DVector::from_iterator(g.hand.num_joints(), out.dq_rot_rad.iter().map(|&v| f64::from(v)));
    let rel = (&js * &dq - &wanted).norm() / wanted.norm();
    assert!(rel < 0.1, "relative residual {rel}");

    // Move the joints in the kinematics: each tip's displacement follows its G^T do row
    // block and turns about +z in the commanded sense.
    let q_after: Vec<f32> = g.q.iter().zip(&out.dq_rot_rad).map(|(q, d)| q + d).collect();
    let before = tips(&g.hand, &g.q);
    let after = tips(&g.hand, &q_after);
    let sense = if reverse { -1.0 } else { 1.0 };
    for finger in 0..g.hand.num_fingers() {
        let moved = (after[finger] - before[finger]).cast::<f64>();
        let want = wanted.fixed_rows::<3>(3 * finger).into_owned();
        assert!(
            (moved - want).norm() < 0.15 * want.norm(),
            "finger {finger}: moved {moved:?}, wanted {want:?}"
        );
        let turned =
            before[finger].cross(&after[finger]).z.atan2(before[finger].xy().dot(&after[finger].xy()));
        assert!(sense * turned > 0.005, "finger {finger} turned {turned} (reverse = {reverse})");
    }
}

#[test]
fn igm_rotation_turns_fingertips_counter_clockwise() {
    check_rotation(false);
}

#[test]
fn igm_rotation_reversed_turns_fingertips_clockwise() {
    check_rotation(true);
}

#[test]
fn igm_stability_pushes_where_force_is_missing() {
    // Thumb (-x face) and the two fingers at +-36 deg (+x face): a balanced 3-contact grasp.
    let g = cube_grasp(2.0);
    let three: Vec<_> = g.contacts.iter().filter(|c| [0, 2, 3].contains(&c.finger)).copied().collect();
    // The floor of the measured grip is below this synthetic 2 N grasp, so the stability
    // term only redistributes (the default 2.5 N floor would also squeeze every finger).
    let config = IgmConfig {
        object_delta: [0.0; 6],
        max_delta_rad: 10.0,
        force_scaling: vge_controllers::ForceScaling::MatchMeanMeasured { min_mean_n: 0.5 },
        ..IgmConfig::default()
    };
    let out = igm_step(&g.hand, &g.q, &three, Vector3::zeros(), &config).expect("igm");
    // Not exactly balanceable without friction: the +x fingers touch 7 mm below the thumb,
    // which leaves a torque about y of ~6 mN*m per N; forces still split 1 : 0.5 : 0.5.
    assert!(out.forces.residual < 0.01, "residual {}", out.forces.residual);
    let c = &out.forces.magnitudes;
    assert!((c[0] - 1.0).abs() < 1e-6 && (c[1] - 0.5).abs() < 0.01 && (c[2] - 0.5).abs() < 0.01, "{c:?}");
    // Measured forces equal to the desired ones: no motion.
    let balanced: Vec<_> =
        three.iter().zip(&out.target_forces_n).map(|(c, &f)| TipContact { force_n: f, ..*c }).collect();
    let still = igm_step(&g.hand, &g.q, &balanced, Vector3::zeros(), &config).expect("igm");
    assert!(still.delta_rad.iter().all(|v| v.abs() < 1e-5), "{:?}", still.delta_rad);
    // The thumb pushes too little: it moves inward (+x), the others barely.
    let mut weak = balanced.clone();
    weak[0].force_n *= 0.5;
    let out = igm_step(&g.hand, &g.q, &weak, Vector3::zeros(), &config).expect("igm");
    let q_after: Vec<f32> = g.q.iter().zip(&out.delta_rad).map(|(q, d)| q + d).collect();
    let moved = tips(&g.hand, &q_after)[0] - tips(&g.hand, &g.q)[0];
    assert!(moved.x > 1e-4, "thumb moved {moved:?}");
    assert!(moved.y.abs() < 0.2 * moved.x && moved.z.abs() < 0.2 * moved.x, "thumb moved {moved:?}");
    // Fingers not in the contact set do not move.
    for f in [1, 4] {
        for j in g.hand.fingers()[f].joints.clone() {
            assert_eq!(out.delta_rad[j], 0.0);
        }
    }
}

#[test]
fn igm_clips_and_rejects_too_few_contacts() {
    let g = cube_grasp(1.0);
    let config = IgmConfig { max_delta_rad: 0.001, ..IgmConfig::default() };
    let out = igm_step(&g.hand, &g.q, &g.contacts, Vector3::zeros(), &config).expect("igm");
    let largest = out.delta_rad.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!((largest - 0.001).abs() < 1e-6 && out.clip_scale < 1.0, "largest {largest}");
    let err = igm_step(&g.hand, &g.q, &g.contacts[..2], Vector3::zeros(), &config);
    assert_eq!(err, Err(ControllerError::TooFewContacts { got: 2, need: 3 }));
}

#[test]
fn damped_least_squares_matches_the_formula() {
    let j = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 2.0, 0.0, 1.0, 1.0]);
    let rhs = DVector::from_vec(vec![1.0, -1.0]);
    let lambda: f64 = 0.3;
    let dq = damped_least_squares(&j, &rhs, lambda);
    // Same as the normal-equations form (J^T J + lambda^2 I)^-1 J^T rhs.
    let other =
        (j.transpose() * &j + DMatrix::identity(3, 3) * lambda.powi(2)).try_inverse().expect("invertible")
            * j.transpose()
            * &rhs;
    assert!((dq - other).norm() < 1e-12);
}

#[test]
fn joint_range_limits_come_from_the_hand_file() {
    let hand = vge15();
    let n = hand.num_joints();
    // Roll range is +-0.5 rad: from 0.45 only 0.05 more; a target past it may come back.
    let mut target = vec![0.0; n];
    target[0] = 0.45;
    target[1] = 1.7;
    let mut delta = vec![0.0; n];
    delta[0] = 0.2;
    delta[1] = 0.1;
    delta[2] = -0.05;
    let limited = limit_to_joint_range(&hand, &target, &delta);
    assert!((limited[0] - 0.05).abs() < 1e-6, "{limited:?}");
    assert_eq!(limited[1], 0.0, "already past its upper limit: may not go further");
    assert_eq!(limited[2], -0.05);
    delta[1] = -0.2;
    assert!((limit_to_joint_range(&hand, &target, &delta)[1] + 0.2).abs() < 1e-6, "back towards the range");
}

// ---------------------------------------------------------------- controllers on an input

fn input_from(g: &Grasp, in_contact: &[usize]) -> ControllerInput {
    let mut contacts = vec![None; g.hand.num_fingers()];
    for c in &g.contacts {
        if in_contact.contains(&c.finger) {
            contacts[c.finger] =
                Some(FingerContact { point_m: c.point_m, normal: c.normal, force_n: c.force_n });
        }
    }
    ControllerInput {
        q_rad: g.q.clone(),
        q_target_rad: g.q.clone(),
        contacts,
        object_position_m: Vector3::zeros(),
        object_orientation: UnitQuaternion::identity(),
    }
}

fn run_cs(seed: u64, input: &ControllerInput, steps: usize) -> (Vec<usize>, Vec<Vec<f32>>) {
    let mut cs = CsController::new(vge15(), CsConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    cs.reset(&mut rng);
    let mut fingers = Vec::new();
    let mut deltas = Vec::new();
    for _ in 0..steps {
        let (finger, delta) = cs.raw_step(input, &mut rng).expect("cs acts");
        fingers.push(finger);
        deltas.push(delta);
    }
    (fingers, deltas)
}

#[test]
fn cs_follows_one_finger_for_h_steps_within_the_speed_range() {
    let g = cube_grasp(1.0);
    let hand = &g.hand;
    let input = input_from(&g, &[0, 1, 2, 3, 4]);
    let config = CsConfig::default();
    let h = config.horizon_steps;
    let dt = config.control_period_s;
    let mut chosen = std::collections::BTreeSet::new();
    for seed in 0..20 {
        let (fingers, deltas) = run_cs(seed, &input, 2 * h);
        // One finger for exactly H steps, then a new draw.
        assert!(fingers[..h].iter().all(|&f| f == fingers[0]));
        assert!(fingers[h..].iter().all(|&f| f == fingers[h]));
        chosen.insert(fingers[0]);
        let f = fingers[0];
        let open = (config.open_fraction * h as f32).round() as usize;
        let mut flex_total = 0.0;
        let (roll_j, prox_j, dist_j) =
            (joint_index(hand, f, 0), joint_index(hand, f, 1), joint_index(hand, f, 2));
        for (step, delta) in deltas[..h].iter().enumerate() {
            for (j, &d) in delta.iter().enumerate() {
                if !hand.fingers()[f].joints.contains(&j) {
                    assert_eq!(d, 0.0, "seed {seed}: joint {j} of another finger moved");
                }
            }
            let (roll, prox, dist) = (delta[roll_j] / dt, delta[prox_j] / dt, delta[dist_j] / dt);
            assert_eq!(dist, 0.0, "distal flexion must be held");
            assert!((0.1 - 1e-5..=0.4 + 1e-5).contains(&prox.abs()), "flexion speed {prox}");
            if step < open {
                assert!(prox < 0.0, "detach opens the flexion");
                assert!((0.1 - 1e-5..=0.4 + 1e-5).contains(&roll.abs()), "roll speed {roll}");
            } else {
                assert!(prox > 0.0, "attach closes the flexion");
                assert_eq!(roll, 0.0);
            }
            flex_total += delta[prox_j];
        }
        assert!(flex_total > 0.0, "ends closed past the start, {flex_total}");
    }
    assert!(chosen.len() >= 4, "random choice should visit most fingers, got {chosen:?}");
}

#[test]
fn cs_is_deterministic_per_seed() {
    let g = cube_grasp(1.0);
    let input = input_from(&g, &[0, 1, 2, 3, 4]);
    assert_eq!(run_cs(7, &input, 45), run_cs(7, &input, 45));
    let differs = (0..5).any(|s| run_cs(s, &input, 20) != run_cs(s + 100, &input, 20));
    assert!(differs);
}

#[test]
fn cs_keeps_three_other_contacts() {
    let g = cube_grasp(1.0);
    // Four contacts (2 is away): any of them may switch, 2 never.
    let input = input_from(&g, &[0, 1, 3, 4]);
    for seed in 0..30 {
        let (fingers, _) = run_cs(seed, &input, 1);
        assert_ne!(fingers[0], 2, "seed {seed}: chose a finger not in contact");
    }
    // Three contacts: switching any would leave two.
    let mut cs = CsController::new(vge15(), CsConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let three = input_from(&g, &[0, 2, 3]);
    assert_eq!(cs.act(&three, &mut rng), Err(ControllerError::TooFewContacts { got: 3, need: 4 }));
}

#[test]
fn cs_never_leaves_contacts_that_all_push_one_way() {
    // Every finger but the thumb moved onto the +x face (pushing along -x): the thumb is
    // the only contact opposing them, so it must stay.
    let mut g = cube_grasp(1.0);
    for c in g.contacts.iter_mut().filter(|c| c.finger != 0) {
        c.point_m.x = 0.05;
        c.normal = Vector3::x();
    }
    let input = input_from(&g, &[0, 1, 2, 3, 4]);
    for seed in 0..30 {
        let (fingers, _) = run_cs(seed, &input, 1);
        assert_ne!(fingers[0], 0, "seed {seed}: lifted the only finger opposing the others");
    }
    let only_one_way = input_from(&g, &[1, 2, 3, 4]);
    let mut cs = CsController::new(vge15(), CsConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    assert_eq!(cs.act(&only_one_way, &mut rng), Err(ControllerError::NoFingerToSwitch { contacts: 4 }));
}

#[test]
fn cs_rolls_back_towards_centre() {
    let g = cube_grasp(1.0);
    let mut input = input_from(&g, &[0, 1, 2, 3, 4]);
    for f in 0..g.hand.num_fingers() {
        input.q_target_rad[joint_index(&g.hand, f, 0)] = 0.3;
    }
    for seed in 0..10 {
        let (fingers, deltas) = run_cs(seed, &input, 1);
        assert!(deltas[0][joint_index(&g.hand, fingers[0], 0)] < 0.0);
    }
}

#[test]
fn controllers_refuse_inputs_of_another_hand_size() {
    let g = cube_grasp(1.0);
    let mut input = input_from(&g, &[0, 1, 2, 3, 4]);
    input.q_rad.push(0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let want = Err(ControllerError::InputSize { what: "q_rad", expected: 15, got: 16 });
    assert_eq!(IgmController::new(vge15(), IgmConfig::default()).act(&input, &mut rng), want);
    assert_eq!(CsController::new(vge15(), CsConfig::default()).act(&input, &mut rng), want);
    assert_eq!(
        FgController::new(vge15(), IgmConfig::default(), CsConfig::default()).act(&input, &mut rng),
        want
    );
}

#[test]
fn fg_is_igm_on_the_others_plus_cs_on_the_switching_finger() {
    let g = cube_grasp(1.0);
    let input = input_from(&g, &[0, 1, 2, 3, 4]);
    let hand = vge15();
    let mut fg = FgController::new(Arc::clone(&hand), IgmConfig::default(), CsConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    fg.reset(&mut rng);
    let total = fg.act(&input, &mut rng).expect("fg acts");
    assert_eq!(total.len(), hand.num_joints());
    // Replay the same draws on a separate CS.
    let (fingers, deltas) = run_cs(3, &input, 1);
    let f = fingers[0];
    let others: Vec<_> = g.contacts.iter().filter(|c| c.finger != f).copied().collect();
    let igm = igm_step(&hand, &g.q, &others, Vector3::zeros(), &IgmConfig::default()).expect("igm");
    for j in 0..hand.num_joints() {
        let expect = igm.delta_rad[j] + deltas[0][j];
        assert!((total[j] - expect).abs() < 1e-6, "joint {j}: {} vs {expect}", total[j]);
        if hand.fingers()[f].joints.contains(&j) {
            assert_eq!(igm.delta_rad[j], 0.0, "IGM must not drive the switching finger");
        }
    }
    // With three contacts CS cannot start: FG is IGM alone.
    let three = input_from(&g, &[0, 2, 3]);
    let mut fresh = FgController::new(Arc::clone(&hand), IgmConfig::default(), CsConfig::default());
    let mut igm_ctl = IgmController::new(hand, IgmConfig::default());
    assert_eq!(fresh.act(&three, &mut rng), igm_ctl.act(&three, &mut rng));
    assert!(fresh.cs.plan().is_none());
}
