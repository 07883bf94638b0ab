//! The hand as data: five fingers, each a roll joint and two flexion joints, with
//! geometry, joint limits and torque caps. The rapier world and the controllers are
//! both built from a [`HandModel`], so there is a single source of truth.
//!
//! # Default geometry (why these numbers)
//! The palm is a horizontal plane at [`NOMINAL_PALM_HEIGHT_M`] = 0.085 m above the
//! object centre, facing down. The five knuckles sit on a circle of radius
//! [`NOMINAL_BASE_RADIUS_M`] = 0.10 m about the z axis, 72 deg apart, with the thumb at
//! azimuth 180 deg (on -x) so that it opposes the two fingers at +-36 deg. Links hang down:
//! proximal 0.05 m, distal 0.045 m, fingertip sphere radius 0.012 m, link capsule radius
//! 0.009 m (smaller than the tip so that the tip touches first).
//!
//! At roll 0 and both flexions at 0.28 rad (0.56 rad at the tip) the thumb's tip centre
//! has moved 0.038 m inward and 0.086 m down: 0.062 m from the axis at mid-height
//! (z = -1 mm), i.e. touching a face of the nominal 10 cm cube squarely (0.05 m + 0.012 m).
//! Five fingers 72 deg apart cannot all meet a four-sided cube squarely: the fingers at
//! +-108 deg touch the +-y faces 20 mm off-centre at flexions of 0.26 rad, the fingers at
//! +-36 deg touch the +x face 45 mm off-centre (5 mm from its edges) at 0.17 rad, 7 mm
//! below mid-height. All these are well inside the joint limits (roll +-0.5 rad, flexions
//! -0.3..1.6 rad).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::error::KinematicsError;

/// Number of fingers of the hand.
pub const NUM_FINGERS: usize = 5;
/// The fingers' names, in finger (and CAN node) order.
pub const FINGER_NAMES: [&str; NUM_FINGERS] = ["thumb", "index", "middle", "ring", "little"];
/// Joints per finger: roll, proximal flexion, distal flexion.
pub const JOINTS_PER_FINGER: usize = 3;
/// A finger's joints' names, in joint order: a joint of the hand is named
/// `{finger}.{joint}`, e.g. `index.flex_prox` (the policy's action names, the bridge's
/// messages).
pub const JOINT_NAMES: [&str; JOINTS_PER_FINGER] = ["roll", "flex_prox", "flex_dist"];
/// Degrees of freedom of the whole hand.
pub const NUM_JOINTS: usize = NUM_FINGERS * JOINTS_PER_FINGER;

/// Side of the cube the default hand is sized for.
pub const NOMINAL_CUBE_SIDE_M: f32 = 0.10;
/// Distance of each knuckle (roll/proximal-flexion axes intersection) from the z axis.
pub const NOMINAL_BASE_RADIUS_M: f32 = 0.10;
/// Height of the palm (knuckle plane) above the object centre.
pub const NOMINAL_PALM_HEIGHT_M: f32 = 0.085;

const PROXIMAL_LENGTH_M: f32 = 0.05;
const DISTAL_LENGTH_M: f32 = 0.045;
const TIP_RADIUS_M: f32 = 0.012;
const LINK_RADIUS_M: f32 = 0.009;
/// Motor torque cap of an ordinary finger: sets the grip force (rapier-hand notes).
pub const FINGER_TORQUE_CAP_NM: f32 = 0.3;
/// The thumb alone opposes two fingers, so it gets a higher cap to balance them.
pub const THUMB_TORQUE_CAP_NM: f32 = 0.45;

/// Position of joint `joint` (0 = roll, 1 = proximal flexion, 2 = distal flexion) of
/// finger `finger` in the hand's 15-vector (finger-major order).
#[must_use]
pub const fn joint_index(finger: usize, joint: usize) -> usize {
    finger * JOINTS_PER_FINGER + joint
}

/// Range of motion of one joint, in radians: the hand description's.
pub use vge_hand::JointLimit;

/// One finger: a roll joint at the knuckle, then two flexion joints, links hanging down.
///
/// Frame conventions, all right-handed:
/// - `base_in_world` maps the finger base frame into the world. In that frame the origin
///   is the knuckle, +x points radially *outward* (away from the object axis), +y is the
///   counter-clockwise tangent about world +z, +z is world up.
/// - Roll turns about base +x. The axis lies on the radial line through the object axis;
///   it is oriented outward so that positive roll swings a hanging fingertip towards +y,
///   i.e. counter-clockwise about +z: rolling all fingers positively turns the object +z.
/// - Both flexions turn about the (rolled) +y axis: positive flexion swings the link's
///   free end radially inward, towards the object.
/// - Each link points along its frame's -z from the joint: proximal from the knuckle,
///   distal from the distal joint, and the fingertip point is the centre of the tip sphere
///   at the end of the distal link.
#[derive(Debug, Clone, PartialEq)]
pub struct FingerModel {
    /// Human-readable name, e.g. "thumb".
    pub name: String,
    /// Pose of the finger base frame (at the knuckle) in the world frame.
    pub base_in_world: Isometry3<f32>,
    /// Knuckle to distal joint.
    pub proximal_length_m: f32,
    /// Distal joint to fingertip sphere centre.
    pub distal_length_m: f32,
    /// Radius of the fingertip sphere (the intended contact surface).
    pub tip_radius_m: f32,
    /// Radius of the link capsules.
    pub link_radius_m: f32,
    /// Limits of [roll, proximal flexion, distal flexion].
    pub joint_limits: [JointLimit; JOINTS_PER_FINGER],
    /// Motor torque caps of [roll, proximal flexion, distal flexion], in N*m.
    pub torque_caps_nm: [f32; JOINTS_PER_FINGER],
}

impl FingerModel {
    /// A finger of the default geometry whose knuckle sits at `azimuth_rad` about +z
    /// (0 = on +x), `base_radius_m` from the z axis and `palm_height_m` above the origin.
    #[must_use]
    pub fn hanging_at_azimuth(
        name: impl Into<String>,
        azimuth_rad: f32,
        base_radius_m: f32,
        palm_height_m: f32,
        torque_cap_nm: f32,
    ) -> Self {
        let (sin, cos) = azimuth_rad.sin_cos();
        let base_in_world = Isometry3::from_parts(
            Translation3::new(base_radius_m * cos, base_radius_m * sin, palm_height_m),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), azimuth_rad),
        );
        let roll = JointLimit { lower_rad: -0.5, upper_rad: 0.5 };
        let flex = JointLimit { lower_rad: -0.3, upper_rad: 1.6 };
        Self {
            name: name.into(),
            base_in_world,
            proximal_length_m: PROXIMAL_LENGTH_M,
            distal_length_m: DISTAL_LENGTH_M,
            tip_radius_m: TIP_RADIUS_M,
            link_radius_m: LINK_RADIUS_M,
            joint_limits: [roll, flex, flex],
            torque_caps_nm: [torque_cap_nm; JOINTS_PER_FINGER],
        }
    }
}

/// The whole hand: five fingers, joint vector in finger-major order.
#[derive(Debug, Clone, PartialEq)]
pub struct HandModel {
    /// The fingers, in joint-vector order.
    pub fingers: [FingerModel; NUM_FINGERS],
}

impl Default for HandModel {
    /// The hand of the paper sized for a 10 cm cube (numbers in the module docs): finger 0
    /// is the thumb at azimuth 180 deg, fingers 1..4 follow counter-clockwise every 72 deg.
    fn default() -> Self {
        let fingers = std::array::from_fn(|i| {
            let azimuth_rad = std::f32::consts::PI + (i as f32) * 72f32.to_radians();
            let cap = if i == 0 { THUMB_TORQUE_CAP_NM } else { FINGER_TORQUE_CAP_NM };
            FingerModel::hanging_at_azimuth(
                FINGER_NAMES[i],
                azimuth_rad,
                NOMINAL_BASE_RADIUS_M,
                NOMINAL_PALM_HEIGHT_M,
                cap,
            )
        });
        Self { fingers }
    }
}

impl HandModel {
    /// Equal flexion `s` on both flexion joints (roll 0) at which `finger`'s tip sphere just
    /// touches the nearest face of the axis-aligned nominal cube centred at the origin, by
    /// bisection on the kinematics alone; `None` if it does not touch within [0, 1.2] rad.
    /// Builds grasp configurations for tests and controllers without a physics world.
    pub fn flexion_touching_nominal_cube(&self, finger: usize) -> Result<Option<f32>, KinematicsError> {
        let model = self.finger(finger)?;
        let half = f64::from(NOMINAL_CUBE_SIDE_M) / 2.0;
        let radius = f64::from(model.tip_radius_m);
        let gap = |s: f64| -> Result<f64, KinematicsError> {
            let tip = model.fingertip_position_m(&[0.0, s, s])?;
            Ok(tip.x.abs().max(tip.y.abs()) - (half + radius))
        };
        let (mut lo, mut hi) = (0.0, 1.2);
        if gap(lo)? <= 0.0 || gap(hi)? > 0.0 {
            return Ok(None);
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if gap(mid)? > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Ok(Some((0.5 * (lo + hi)) as f32))
    }

    /// The finger at `finger`, or an error when out of range.
    pub fn finger(&self, finger: usize) -> Result<&FingerModel, KinematicsError> {
        self.fingers
            .get(finger)
            .ok_or(KinematicsError::FingerOutOfRange { index: finger, count: NUM_FINGERS })
    }

    /// Joint limits of all 15 joints, finger-major.
    #[must_use]
    pub fn joint_limits(&self) -> [JointLimit; NUM_JOINTS] {
        std::array::from_fn(|j| self.fingers[j / JOINTS_PER_FINGER].joint_limits[j % JOINTS_PER_FINGER])
    }

    /// Sets every joint's motor torque cap: `finger_cap_nm` on the four fingers, the thumb's
    /// in the default proportion ([`THUMB_TORQUE_CAP_NM`] / [`FINGER_TORQUE_CAP_NM`] = 1.5),
    /// since it alone opposes two fingers. At [`FINGER_TORQUE_CAP_NM`] this is the default
    /// hand's caps exactly.
    pub fn set_finger_torque_cap_nm(&mut self, finger_cap_nm: f32) {
        for (i, finger) in self.fingers.iter_mut().enumerate() {
            let cap = if i == 0 {
                THUMB_TORQUE_CAP_NM * (finger_cap_nm / FINGER_TORQUE_CAP_NM)
            } else {
                finger_cap_nm
            };
            finger.torque_caps_nm = [cap; JOINTS_PER_FINGER];
        }
    }

    /// Torque caps of all 15 joints, finger-major, in N*m.
    #[must_use]
    pub fn torque_caps_nm(&self) -> [f32; NUM_JOINTS] {
        std::array::from_fn(|j| self.fingers[j / JOINTS_PER_FINGER].torque_caps_nm[j % JOINTS_PER_FINGER])
    }

    /// The three joint angles of `finger` taken out of the whole-hand vector.
    pub fn finger_joints(
        &self,
        finger: usize,
        q_all: &[f32; NUM_JOINTS],
    ) -> Result<[f32; JOINTS_PER_FINGER], KinematicsError> {
        self.finger(finger)?;
        let start = joint_index(finger, 0);
        Ok(std::array::from_fn(|j| q_all[start + j]))
    }

    /// Frames of `finger` in the world: `[base, after roll, after proximal flexion,
    /// after distal flexion]` (see [`FingerModel::frames`]).
    pub fn finger_frames(
        &self,
        finger: usize,
        q_rad: &[f32; JOINTS_PER_FINGER],
    ) -> Result<[Isometry3<f32>; JOINTS_PER_FINGER + 1], KinematicsError> {
        self.finger(finger)?.frames(q_rad)
    }

    /// World position of the fingertip sphere centre of `finger`.
    pub fn fingertip_position_m(
        &self,
        finger: usize,
        q_rad: &[f32; JOINTS_PER_FINGER],
    ) -> Result<Vector3<f32>, KinematicsError> {
        self.finger(finger)?.fingertip_position_m(q_rad)
    }

    /// Analytic 3x3 Jacobian d(fingertip centre)/dq of `finger` (world frame).
    pub fn fingertip_jacobian(
        &self,
        finger: usize,
        q_rad: &[f32; JOINTS_PER_FINGER],
    ) -> Result<nalgebra::Matrix3<f32>, KinematicsError> {
        self.finger(finger)?.fingertip_jacobian(q_rad)
    }
}
