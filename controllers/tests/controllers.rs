//! The controllers' math on the shared hand kinematics: contact-force QP, IGM's rotation
//! and stability terms, CS trajectories, FG superposition. (Tests on the rapier env come
//! when the env exists.)

use nalgebra::{DMatrix, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use vge_controllers::qp::grasp_map_f64;
use vge_controllers::{
    Controller, ControllerError, ControllerInput, CsConfig, CsController, FgController, FingerContact,
    IgmConfig, IgmController, QpError, TipContact, contact_force_qp, igm::damped_least_squares, igm_step,
};
use vge_sim::kinematics::joint_index;
use vge_sim::{HandModel, NOMINAL_CUBE_SIDE_M, NUM_FINGERS, NUM_JOINTS};

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

// ---------------------------------------------------------------- hand at a grasp

fn touching_flexion(hand: &HandModel, finger: usize) -> f32 {
    hand.flexion_touching_nominal_cube(finger).expect("valid finger").expect("the finger reaches the cube")
}

struct Grasp {
    hand: HandModel,
    q: [f32; NUM_JOINTS],
    contacts: Vec<TipContact>,
}

/// All five fingertips touching the cube's faces; contact point on the face, normal into
/// the cube (given *outward* on purpose: the controllers must orient it), force `force_n`.
fn cube_grasp(force_n: f32) -> Grasp {
    let hand = HandModel::default();
    let half = NOMINAL_CUBE_SIDE_M / 2.0;
    let mut q = [0.0; NUM_JOINTS];
    let mut contacts = Vec::new();
    for finger in 0..NUM_FINGERS {
        let s = touching_flexion(&hand, finger);
        q[joint_index(finger, 1)] = s;
        q[joint_index(finger, 2)] = s;
        let tip = hand.fingertip_position_m(finger, &[0.0, s, s]).expect("valid");
        let outward = if tip.x.abs() >= tip.y.abs() {
            Vector3::new(tip.x.signum(), 0.0, 0.0)
        } else {
            Vector3::new(0.0, tip.y.signum(), 0.0)
        };
        let point = tip - outward * hand.fingers[finger].tip_radius_m;
        assert!((point.x.abs().max(point.y.abs()) - half).abs() < 1e-4);
        contacts.push(TipContact { finger, point_m: point, normal: outward, force_n });
    }
    Grasp { hand, q, contacts }
}

fn tips(hand: &HandModel, q: &[f32; NUM_JOINTS]) -> Vec<Vector3<f32>> {
    (0..NUM_FINGERS)
        .map(|f| hand.fingertip_position_m(f, &hand.finger_joints(f, q).expect("ok")).expect("ok"))
        .collect()
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
    // Least-squares residual of J_S dq_rot = G^T do, relative.
    let kin: Vec<_> = g
        .contacts
        .iter()
        .map(|c| {
            let tip = g
                .hand
                .fingertip_position_m(c.finger, &g.hand.finger_joints(c.finger, &g.q).expect("ok"))
                .expect("ok");
            vge_sim::Contact { finger: c.finger, offset_from_tip_m: c.point_m - tip }
        })
        .collect();
    let js = g.hand.stacked_jacobian(&kin, &g.q).expect("ok").cast::<f64>();
    let points: Vec<_> = g.contacts.iter().map(|c| c.point_m).collect();
    let grasp = vge_sim::grasp_map(&points, Vector3::zeros()).expect("ok").cast::<f64>();
    let twist = nalgebra::DVector::from_iterator(6, config.object_delta.iter().map(|&v| f64::from(v)));
    let wanted = grasp.transpose() * twist;
    let dq = nalgebra::DVector::from_iterator(NUM_JOINTS, out.dq_rot_rad.iter().map(|&v| f64::from(v)));
    let rel = (&js * &dq - &wanted).norm() / wanted.norm();
    assert!(rel < 0.1, "relative residual {rel}");

    // Move the joints in the kinematics: each tip's displacement follows its G^T do row
    // block and turns about +z in the commanded sense.
    let q_after: [f32; NUM_JOINTS] = std::array::from_fn(|j| g.q[j] + out.dq_rot_rad[j]);
    let before = tips(&g.hand, &g.q);
    let after = tips(&g.hand, &q_after);
    let sense = if reverse { -1.0 } else { 1.0 };
    for finger in 0..NUM_FINGERS {
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
    let q_after: [f32; NUM_JOINTS] = std::array::from_fn(|j| g.q[j] + out.delta_rad[j]);
    let moved = tips(&g.hand, &q_after)[0] - tips(&g.hand, &g.q)[0];
    assert!(moved.x > 1e-4, "thumb moved {moved:?}");
    assert!(moved.y.abs() < 0.2 * moved.x && moved.z.abs() < 0.2 * moved.x, "thumb moved {moved:?}");
    // Fingers not in the contact set do not move.
    for f in [1, 4] {
        for j in 0..3 {
            assert_eq!(out.delta_rad[joint_index(f, j)], 0.0);
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
    let rhs = nalgebra::DVector::from_vec(vec![1.0, -1.0]);
    let lambda: f64 = 0.3;
    let dq = damped_least_squares(&j, &rhs, lambda);
    // Same as the normal-equations form (J^T J + lambda^2 I)^-1 J^T rhs.
    let other =
        (j.transpose() * &j + DMatrix::identity(3, 3) * lambda.powi(2)).try_inverse().expect("invertible")
            * j.transpose()
            * &rhs;
    assert!((dq - other).norm() < 1e-12);
}

// ---------------------------------------------------------------- controllers on an input

fn input_from(g: &Grasp, in_contact: &[usize]) -> ControllerInput {
    let mut contacts = [None; NUM_FINGERS];
    for c in &g.contacts {
        if in_contact.contains(&c.finger) {
            contacts[c.finger] =
                Some(FingerContact { point_m: c.point_m, normal: c.normal, force_n: c.force_n });
        }
    }
    ControllerInput {
        q_rad: g.q,
        q_target_rad: g.q,
        contacts,
        object_position_m: Vector3::zeros(),
        object_orientation: UnitQuaternion::identity(),
    }
}

fn run_cs(seed: u64, input: &ControllerInput, steps: usize) -> (Vec<usize>, Vec<[f32; NUM_JOINTS]>) {
    let mut cs = CsController::new(HandModel::default(), CsConfig::default());
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
        for (step, delta) in deltas[..h].iter().enumerate() {
            for (j, &d) in delta.iter().enumerate() {
                if j / 3 != f {
                    assert_eq!(d, 0.0, "seed {seed}: joint {j} of another finger moved");
                }
            }
            let (roll, prox, dist) =
                (delta[joint_index(f, 0)] / dt, delta[joint_index(f, 1)] / dt, delta[joint_index(f, 2)] / dt);
            assert_eq!(dist, 0.0, "distal flexion must be held");
            assert!((0.1 - 1e-5..=0.4 + 1e-5).contains(&prox.abs()), "flexion speed {prox}");
            if step < open {
                assert!(prox < 0.0, "detach opens the flexion");
                assert!((0.1 - 1e-5..=0.4 + 1e-5).contains(&roll.abs()), "roll speed {roll}");
            } else {
                assert!(prox > 0.0, "attach closes the flexion");
                assert_eq!(roll, 0.0);
            }
            flex_total += delta[joint_index(f, 1)];
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
    let mut cs = CsController::new(HandModel::default(), CsConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let three = input_from(&g, &[0, 2, 3]);
    assert_eq!(cs.act(&three, &mut rng), Err(ControllerError::TooFewContacts { got: 3, need: 4 }));
}

#[test]
fn cs_rolls_back_towards_centre() {
    let g = cube_grasp(1.0);
    let mut input = input_from(&g, &[0, 1, 2, 3, 4]);
    for f in 0..NUM_FINGERS {
        input.q_target_rad[joint_index(f, 0)] = 0.3;
    }
    for seed in 0..10 {
        let (fingers, deltas) = run_cs(seed, &input, 1);
        assert!(deltas[0][joint_index(fingers[0], 0)] < 0.0);
    }
}

#[test]
fn fg_is_igm_on_the_others_plus_cs_on_the_switching_finger() {
    let g = cube_grasp(1.0);
    let input = input_from(&g, &[0, 1, 2, 3, 4]);
    let hand = HandModel::default();
    let mut fg = FgController::new(hand.clone(), IgmConfig::default(), CsConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    fg.reset(&mut rng);
    let total = fg.act(&input, &mut rng).expect("fg acts");
    // Replay the same draws on a separate CS.
    let (fingers, deltas) = run_cs(3, &input, 1);
    let f = fingers[0];
    let others: Vec<_> = g.contacts.iter().filter(|c| c.finger != f).copied().collect();
    let igm = igm_step(&hand, &g.q, &others, Vector3::zeros(), &IgmConfig::default()).expect("igm");
    for j in 0..NUM_JOINTS {
        let expect = igm.delta_rad[j] + deltas[0][j];
        assert!((total[j] - expect).abs() < 1e-6, "joint {j}: {} vs {expect}", total[j]);
        if j / 3 == f {
            assert_eq!(igm.delta_rad[j], 0.0, "IGM must not drive the switching finger");
        }
    }
    // With three contacts CS cannot start: FG is IGM alone.
    let three = input_from(&g, &[0, 2, 3]);
    let mut fresh = FgController::new(hand.clone(), IgmConfig::default(), CsConfig::default());
    let mut igm_ctl = IgmController::new(hand, IgmConfig::default());
    assert_eq!(fresh.act(&three, &mut rng), igm_ctl.act(&three, &mut rng));
    assert!(fresh.cs.plan().is_none());
}
