//! The start grasp of a hand whose file names one (a keyframe): each grasping finger is closed
//! onto the object along the surface normal, then its motor targets are set past that contact
//! pose so that, with the object where it starts, the motors press each fingertip into the
//! object with a chosen force and carry the links' and the object's weight.
//!
//! Why not the targets `squeeze_rad` past the pose on every flexion joint (what a hand without
//! a keyframe gets): on the Allegro the thumb's flexion presses mostly upwards, not into its
//! face, so the fingers push the cube 6 mm towards the thumb while the grip builds, and the
//! grasp pose noise, which opens the fingers, is taken off the squeeze (measured over 30 s
//! with the protocol's noise: the cube turned up to 0.036 rad and a tip came off at times;
//! with this press 0.008 rad, all four tips on, and the reset leaves the cube in place).
//! Here the targets come from statics: at the contact pose the servos' torques
//! `kp (target - q)` equal `J^T f` plus the links' gravity torques, with `f` the force each
//! fingertip should put on the object; the thumb's `f` is minus the other fingers' resultant,
//! so the grip pushes the object nowhere.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix3xX, Vector3};
use vge_hand::Hand;

use crate::error::SimError;
use crate::objects::ObjectConfig;
use crate::world::{JointServo, v3};

/// Damping of the least-squares steps that close a finger onto the object (m): small beside
/// a fingertip Jacobian's singular values (tens of mm per rad), large enough to keep a step
/// bounded near a singular pose.
const DLS_DAMPING_M: f32 = 0.005;

/// Newton steps at most to close a finger; each fixes the tip's gap to the object to first
/// order.
const MAX_CLOSING_STEPS: usize = 8;

/// A closing step ends once the tip's gap is within this (m).
const GAP_TOLERANCE_M: f32 = 1e-5;

/// A start grasp: where the joints start and the targets their servos hold.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PressedGrasp {
    /// Joint angles with every grasping fingertip on the object's surface (rad).
    pub q_rad: Vec<f32>,
    /// Servo targets (rad) that press the grasping tips into the object.
    pub target_rad: Vec<f32>,
}

/// The object's surface, as the world places it at a reset (its centre at the origin).
struct Surface {
    shape: rapier3d::geometry::SharedShape,
    pose: rapier3d::math::Pose,
}

impl Surface {
    fn new(object: &ObjectConfig) -> Result<Self, SimError> {
        let collider = object.collider()?;
        Ok(Self { shape: collider.shape, pose: collider.position })
    }

    /// The gap (m, negative when penetrating) from a sphere of `radius_m` at `centre` to the
    /// surface, and the unit direction from the centre into the object along the surface
    /// normal at the nearest point.
    fn gap_and_normal(&self, centre: &Vector3<f32>, radius_m: f32) -> (f32, Vector3<f32>) {
        let pt = rapier3d::math::Vector::new(centre.x, centre.y, centre.z);
        let projection = self.shape.project_point(&self.pose, pt, false);
        let to_surface = v3(projection.point) - centre;
        let distance = to_surface.norm();
        let fallback = || {
            let to_centre = v3(self.pose.translation) - centre;
            to_centre.try_normalize(1e-9).unwrap_or_else(Vector3::z)
        };
        let inward = to_surface.try_normalize(1e-9).unwrap_or_else(fallback);
        if projection.is_inside {
            // The centre is inside: the way out is towards the surface, into the object is back.
            (-distance - radius_m, -inward)
        } else {
            (distance - radius_m, inward)
        }
    }
}

/// `J^T (J J^T + l^2 I)^-1 dx`: the smallest joint step (damped) that moves the point by `dx`.
fn damped_least_squares(jacobian: &Matrix3xX<f32>, dx: &Vector3<f32>) -> DVector<f32> {
    let damping = DLS_DAMPING_M * DLS_DAMPING_M;
    let jjt = jacobian * jacobian.transpose() + Matrix3::identity() * damping;
    // Symmetric positive definite once damped: the inverse exists.
    let solved = jjt.try_inverse().map_or_else(Vector3::zeros, |inv| inv * dx);
    jacobian.transpose() * solved
}

/// The generalised gravity torque on the joints of the finger whose joints are `joints`
/// (N m, one per joint of the hand, zero off the finger): `sum_b J_b^T m_b g` over the bodies
/// those joints move, `J_b` the Jacobian of body `b`'s centre of mass.
fn finger_gravity_torques_nm(
    hand: &Hand,
    joints: &std::ops::Range<usize>,
    q_rad: &[f32],
    gravity_m_per_s2: &Vector3<f32>,
) -> Result<Vec<f32>, SimError> {
    let poses = hand.body_poses_world(q_rad).map_err(|e| SimError::InvalidConfig(e.to_string()))?;
    let bodies = hand.bodies();
    let joint_desc = hand.joints();
    // World anchor and axis of each of the finger's joints (its body turns about them).
    let frames: Vec<(usize, Vector3<f32>, Vector3<f32>)> = joints
        .clone()
        .map(|j| {
            let joint = &joint_desc[j];
            let pose = poses[joint.body];
            (
                j,
                (pose * nalgebra::Point3::from(joint.pos_in_body_m)).coords,
                pose.rotation * joint.axis_in_body.as_ref(),
            )
        })
        .collect();
    let mut torques = vec![0.0; hand.num_joints()];
    for (b, body) in bodies.iter().enumerate() {
        let mass = body.mass_properties;
        if mass.mass_kg <= 0.0 {
            continue;
        }
        let weight = gravity_m_per_s2 * mass.mass_kg;
        let com = (poses[b] * nalgebra::Point3::from(mass.com_in_body_m)).coords;
        // The finger's joints on the path from the root to this body.
        let mut path = Vec::new();
        let mut at = Some(b);
        while let Some(k) = at {
            path.push(k);
            at = bodies[k].parent;
        }
        for (j, anchor, axis) in &frames {
            if path.contains(&joint_desc[*j].body) {
                torques[*j] += axis.cross(&(com - anchor)).dot(&weight);
            }
        }
    }
    Ok(torques)
}

/// Closes each grasping finger of `q_rad` onto the object (its tip sphere on the surface) and
/// sets its targets to press it there with `force_n` along the surface normal, the finger
/// named `thumb` (if it grasps with others) pressing against the others' resultant instead;
/// every grasping finger also carries an equal share of the object's weight, and each one's
/// targets hold its links up against gravity. Fingers that do not grasp keep their angles as
/// targets.
pub(crate) fn press_start_grasp(
    hand: &Hand,
    servos: &[JointServo],
    object: &ObjectConfig,
    gravity_m_per_s2: &Vector3<f32>,
    q_rad: &[f32],
    grasping: &[bool],
    force_n: f32,
) -> Result<PressedGrasp, SimError> {
    let surface = Surface::new(object)?;
    let fingers = hand.fingers();
    let kin = |e: vge_hand::HandError| SimError::InvalidConfig(e.to_string());
    let mut q = q_rad.to_vec();
    let radius = |f: usize| fingers[f].tip_radius_m.unwrap_or(0.0);
    // Close each finger along the surface normal, by damped least squares on its tip.
    for (f, finger) in fingers.iter().enumerate().filter(|(f, _)| grasping[*f]) {
        for _ in 0..MAX_CLOSING_STEPS {
            let tip = hand.fingertip_positions_m(&q).map_err(kin)?[f];
            let (gap, inward) = surface.gap_and_normal(&tip, radius(f));
            if gap.abs() < GAP_TOLERANCE_M {
                break;
            }
            let jacobian = hand.fingertip_jacobian_at_point(f, &q, &tip).map_err(kin)?;
            let columns = jacobian.columns(finger.joints.start, finger.joints.len()).into_owned();
            let dq = damped_least_squares(&columns, &(inward * gap));
            for (k, j) in finger.joints.clone().enumerate() {
                q[j] = servos[j].limit.clamp(q[j] + dq[k]);
            }
        }
    }
    // The force each grasping tip puts on the object.
    let tips = hand.fingertip_positions_m(&q).map_err(kin)?;
    let grasping_count = grasping.iter().filter(|g| **g).count();
    let thumb = fingers.iter().position(|f| f.name == "thumb").filter(|t| grasping[*t] && grasping_count > 1);
    let mut forces = vec![Vector3::zeros(); fingers.len()];
    for f in (0..fingers.len()).filter(|f| grasping[*f] && Some(*f) != thumb) {
        forces[f] = surface.gap_and_normal(&tips[f], radius(f)).1 * force_n;
    }
    if let Some(t) = thumb {
        forces[t] = -forces.iter().sum::<Vector3<f32>>();
    }
    // The least change to those forces that makes them carry the object's weight and turn it
    // about no axis: the normal forces' lines miss the object's centre where the tips sit at
    // different heights on their faces (the Allegro's middle tip 12 mm above the others).
    let contacts: Vec<usize> = (0..fingers.len()).filter(|f| grasping[*f]).collect();
    let centre = v3(surface.pose.translation);
    let points: Vec<Vector3<f32>> = contacts
        .iter()
        .map(|f| tips[*f] + surface.gap_and_normal(&tips[*f], radius(*f)).1 * radius(*f) - centre)
        .collect();
    let mut grasp_map = DMatrix::<f32>::zeros(6, 3 * contacts.len());
    for (k, r) in points.iter().enumerate() {
        grasp_map.fixed_view_mut::<3, 3>(0, 3 * k).copy_from(&Matrix3::identity());
        grasp_map.fixed_view_mut::<3, 3>(3, 3 * k).copy_from(&r.cross_matrix());
    }
    let mut nominal = DVector::<f32>::zeros(3 * contacts.len());
    for (k, f) in contacts.iter().enumerate() {
        nominal.fixed_rows_mut::<3>(3 * k).copy_from(&forces[*f]);
    }
    let mut wanted = DVector::<f32>::zeros(6);
    wanted.fixed_rows_mut::<3>(0).copy_from(&(-gravity_m_per_s2 * object.mass_kg));
    let missing = wanted - &grasp_map * &nominal;
    let correction = grasp_map
        .clone()
        .pseudo_inverse(1e-6)
        .map_or_else(|_| DVector::zeros(nominal.len()), |pinv| pinv * missing);
    for (k, f) in contacts.iter().enumerate() {
        forces[*f] += correction.fixed_rows::<3>(3 * k);
    }
    // Servo targets: kp (target - q) = J^T f - (the links' gravity torques).
    let mut target = q.clone();
    for (k, (f, finger)) in fingers.iter().enumerate().filter(|(f, _)| grasping[*f]).enumerate() {
        // At the contact point: a tangential force there turns the tip about its centre.
        let at = points[k] + centre;
        let jacobian = hand.fingertip_jacobian_at_point(f, &q, &at).map_err(kin)?;
        let press = jacobian.transpose() * forces[f];
        let gravity = finger_gravity_torques_nm(hand, &finger.joints, &q, gravity_m_per_s2)?;
        for j in finger.joints.clone() {
            let torque_nm = press[j] - gravity[j];
            target[j] = servos[j].limit.clamp(q[j] + torque_nm / servos[j].kp_nm_per_rad);
        }
    }
    Ok(PressedGrasp { q_rad: q, target_rad: target })
}
