//! The rapier3d world of a hand read from its description ([`vge_hand::Hand`]) and one
//! dynamic object: the palm and every body welded to it fixed, one multibody per finger
//! (a revolute joint with a position motor for each of the finger's hinges, reduced
//! coordinates), the bodies welded to a moving body merged into it. Bodies and joints are
//! placed from the description's kinematics, so the physics and the kinematics agree by
//! construction (tested in `tests/`).
//!
//! Why these settings (see `shared/notes/rapier-hand.md`): multibody joints (impulse-joint
//! motors never reach the commanded torque), one multibody per finger (2.5-3x faster than
//! one tree), `ForceBased` motors whose torque cap sets the grip force, contact softness
//! 120 Hz / 10 (the default 30 Hz lets the object creep), contact recycling off (it leaves
//! contact normals up to 11 deg stale).

use nalgebra::{Isometry3, Quaternion, UnitQuaternion, Vector3};
use rapier3d::dynamics::{
    GenericJointBuilder, IntegrationParameters, JointAxesMask, JointAxis, MassProperties, MotorModel,
    MultibodyJointHandle, RigidBodyBuilder, RigidBodyHandle, SpringCoefficients,
};
use rapier3d::geometry::{ColliderBuilder, ColliderHandle, Group, InteractionGroups, InteractionTestMode};
use rapier3d::math::{Pose, Rotation, Vector};
use rapier3d::pipeline::PhysicsWorld;

use crate::error::SimError;
use std::ops::Range;
use std::sync::Arc;

use vge_hand::{GeomMass, GeomShape, Hand};

use crate::JointLimit;
use crate::objects::ObjectConfig;

/// Physics parameters of the world (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicsConfig {
    /// Physics step rate. Default 120 Hz with 4 solver iterations (which act as substeps
    /// in rapier 0.36, so the contact solver runs at 480 Hz): measured to hold all five
    /// objects and turn the cube like 240 Hz x 4 does, at half the cost per second of sim.
    pub physics_hz: f32,
    /// Solver iterations per physics step (substeps in rapier 0.36).
    pub solver_iterations: usize,
    /// Contact softness natural frequency (Hz); 120 per the notes (default 30 creeps).
    pub contact_natural_frequency_hz: f32,
    /// Contact softness damping ratio; 10 per the notes.
    pub contact_damping_ratio: f32,
    /// Friction coefficient of the fingers (combined with the object's by average).
    pub finger_friction: f32,
    /// Density of the finger links.
    pub link_density_kg_per_m3: f32,
    /// Gravity magnitude; its direction in the hand's frame is set by `hand_orientation`.
    pub gravity_m_per_s2: f32,
    /// How the hand is held relative to gravity (palm down: gravity along the hand's -z,
    /// the rotation axis).
    pub hand_orientation: HandOrientation,
    /// Whether the fingers collide with each other (links and tips of different fingers).
    /// Off by default: the hand's colliders touch the object only, and two fingers can pass
    /// through each other. A finger's own links never collide (they meet at its joints).
    pub finger_collisions: bool,
    /// Distance below which rapier creates predictive contacts (m). Default 5 mm:
    /// rapier's 0.02 (human-scale scenes) made every link within 2 cm of the object a
    /// contact constraint and cost 35% of the step time (measured: 2.1k -> 3.2k control
    /// steps/s); fingertips move < 1 mm per physics step at the default rates.
    pub contact_prediction_distance_m: f32,
}

impl Default for PhysicsConfig {
    fn default() -> Self {
        Self {
            physics_hz: 120.0,
            solver_iterations: 4,
            contact_natural_frequency_hz: 120.0,
            contact_damping_ratio: 10.0,
            finger_friction: 0.8,
            link_density_kg_per_m3: 1000.0,
            gravity_m_per_s2: 9.81,
            hand_orientation: HandOrientation::PalmDown,
            finger_collisions: false,
            contact_prediction_distance_m: 0.005,
        }
    }
}

impl PhysicsConfig {
    pub(crate) fn validate(&self) -> Result<(), SimError> {
        let pos = |v: f32| v.is_finite() && v > 0.0;
        if !pos(self.physics_hz) || self.physics_hz > 10_000.0 {
            return Err(SimError::InvalidConfig(format!("physics rate {} Hz", self.physics_hz)));
        }
        if !(1..=64).contains(&self.solver_iterations) {
            return Err(SimError::InvalidConfig(format!("solver iterations {}", self.solver_iterations)));
        }
        for (name, v) in [
            ("contact natural frequency", self.contact_natural_frequency_hz),
            ("contact damping ratio", self.contact_damping_ratio),
            ("link density", self.link_density_kg_per_m3),
            ("contact prediction distance", self.contact_prediction_distance_m),
        ] {
            if !pos(v) {
                return Err(SimError::InvalidConfig(format!("{name} {v}")));
            }
        }
        for (name, v) in [("finger friction", self.finger_friction), ("gravity", self.gravity_m_per_s2)] {
            if !v.is_finite() || v < 0.0 {
                return Err(SimError::InvalidConfig(format!("{name} {v}")));
            }
        }
        Ok(())
    }

    /// Physics time step.
    #[must_use]
    pub fn dt_s(&self) -> f32 {
        1.0 / self.physics_hz
    }

    /// Gravity (m/s^2) in the world frame, which is the hand's frame (the palm is fixed).
    #[must_use]
    pub fn gravity_m_per_s2_vector(&self) -> Vector3<f32> {
        self.hand_orientation.down() * self.gravity_m_per_s2
    }
}

/// How the hand is held relative to gravity. The world frame is the hand's frame (palm fixed,
/// knuckles in the plane z = 0.085 m above the object centre, thumb on -x, the object turned
/// about +z), so an orientation is the direction gravity takes in it. The observation and the
/// reward live in the hand's frame and do not change; the drop test measures the object's
/// fall along gravity ([`Self::down`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HandOrientation {
    /// Palm down (the paper's hand): gravity along the hand's -z, the rotation axis, so the
    /// fingertips share the object's weight.
    #[default]
    PalmDown,
    /// The hand on its side, thumb up: gravity along the hand's +x, from the thumb (on -x)
    /// towards the middle and ring fingers (at +-36 deg about +x), perpendicular to the
    /// rotation axis. The middle and ring fingertips carry the object's weight from below.
    SideOn,
    /// Palm up: gravity along the hand's +z, from the object towards the palm (the hand
    /// turned 180 deg about x, the fingers' direction: the Allegro's palm-up mount in
    /// hands/allegro.toml). The fingertips' friction carries the object, as palm down.
    PalmUp,
}

impl HandOrientation {
    /// All orientations, in a fixed order.
    pub const ALL: [Self; 3] = [Self::PalmDown, Self::SideOn, Self::PalmUp];

    /// The name configs use (`"palm_down"`, `"side_on"`, `"palm_up"`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::PalmDown => "palm_down",
            Self::SideOn => "side_on",
            Self::PalmUp => "palm_up",
        }
    }

    /// Unit vector along gravity in the hand's frame.
    #[must_use]
    pub fn down(self) -> Vector3<f32> {
        match self {
            Self::PalmDown => Vector3::new(0.0, 0.0, -1.0),
            Self::SideOn => Vector3::new(1.0, 0.0, 0.0),
            Self::PalmUp => Vector3::new(0.0, 0.0, 1.0),
        }
    }

    /// Unit vector against gravity: the object's height is its position along it.
    #[must_use]
    pub fn up(self) -> Vector3<f32> {
        -self.down()
    }
}

impl std::str::FromStr for HandOrientation {
    type Err = String;

    /// Parses [`HandOrientation::name`].
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL.into_iter().find(|o| o.name() == s).ok_or_else(|| {
            let names: Vec<_> = Self::ALL.iter().map(|o| o.name()).collect();
            format!("hand_orientation: unknown orientation `{s}` (one of: {})", names.join(", "))
        })
    }
}

impl std::fmt::Display for HandOrientation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A fingertip contact with the object as the physics sees it (noise-free).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactReading {
    /// Contact point (world, m): impulse-weighted mean of the solver contact points.
    pub position_m: Vector3<f32>,
    /// Unit normal (world), from the fingertip into the object.
    pub normal: Vector3<f32>,
    /// Normal force magnitude (N), summed over the solver contacts of the pair.
    pub normal_force_n: f32,
    /// Friction force on the object (world, N), summed over the pair's solver contacts.
    pub friction_force_n: Vector3<f32>,
}

impl ContactReading {
    /// Total contact force on the object (normal + friction), world frame.
    #[must_use]
    pub fn force_on_object_n(&self) -> Vector3<f32> {
        self.normal * self.normal_force_n + self.friction_force_n
    }
}

/// Pose and velocity of the object (world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectState {
    /// Pose of the object's body frame (centre of the shape).
    pub pose: Isometry3<f32>,
    /// Linear velocity of the centre (m/s).
    pub linvel_m_per_s: Vector3<f32>,
    /// Angular velocity (rad/s).
    pub angvel_rad_per_s: Vector3<f32>,
}

impl ObjectState {
    /// Euler yaw (rad, in (-pi, pi]): meaningful only while the object is near upright; to
    /// measure turning, sum [`crate::rotation_about_z_rad`] instead (gimbal lock at 90° tilt).
    #[must_use]
    pub fn yaw_rad(&self) -> f32 {
        self.pose.rotation.euler_angles().2
    }
}

const HAND_GROUP: Group = Group::GROUP_1;
const OBJECT_GROUP: Group = Group::GROUP_2;

pub(crate) fn iso_to_pose(iso: &Isometry3<f32>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Pose::from_parts(Vector::new(t.x, t.y, t.z), Rotation::from_xyzw(q.i, q.j, q.k, q.w))
}

pub(crate) fn pose_to_iso(p: &Pose) -> Isometry3<f32> {
    let r = p.rotation;
    Isometry3::from_parts(
        nalgebra::Translation3::new(p.translation.x, p.translation.y, p.translation.z),
        UnitQuaternion::new_unchecked(Quaternion::new(r.w, r.x, r.y, r.z)),
    )
}

pub(crate) fn v3(v: Vector) -> Vector3<f32> {
    Vector3::new(v.x, v.y, v.z)
}

/// The servo that holds one joint at its target: what the world's position motor does. The
/// description gives each joint's (its `<position>` actuator and range); a task may change
/// them (a stiffer motor, a larger torque cap).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointServo {
    /// Range of motion; targets and teleports are clamped into it.
    pub limit: JointLimit,
    /// Motor stiffness (N m / rad).
    pub kp_nm_per_rad: f32,
    /// Motor damping (N m s / rad).
    pub kv_nms_per_rad: f32,
    /// Largest motor torque (N m): with a position motor it sets the grip force.
    pub torque_cap_nm: f32,
}

impl JointServo {
    /// Each joint's servo as the description gives it: its range, its `<position>` actuator's
    /// kp, its kv plus the joint's own damping (rapier's joints have no passive damping, so the
    /// motor carries it; unlike MuJoCo's, it then counts against the torque cap), and the
    /// larger magnitude of its force range. A joint without a range, without
    /// an actuator or without a force range is refused: an unlimited motor on a simulated
    /// hand squeezes without bound.
    pub fn from_description(hand: &Hand) -> Result<Vec<Self>, SimError> {
        hand.joints()
            .iter()
            .map(|joint| {
                let refuse = |what: &str| {
                    SimError::InvalidConfig(format!(
                        "hand {}: joint {} has no {what}",
                        hand.name(),
                        joint.name
                    ))
                };
                let limit = joint.limit.ok_or_else(|| refuse("range"))?;
                let servo = joint.servo.as_ref().ok_or_else(|| refuse("position actuator"))?;
                let [lo, hi] = servo.force_range_nm.ok_or_else(|| refuse("actuator force range"))?;
                Ok(Self {
                    limit,
                    kp_nm_per_rad: servo.kp_nm_per_rad,
                    kv_nms_per_rad: servo.kv_nms_per_rad + joint.damping_nms_per_rad,
                    torque_cap_nm: lo.abs().max(hi.abs()),
                })
            })
            .collect()
    }

    pub(crate) fn validate(&self, joint: &str) -> Result<(), SimError> {
        let JointLimit { lower_rad, upper_rad } = self.limit;
        let ok = lower_rad.is_finite()
            && upper_rad.is_finite()
            && lower_rad <= upper_rad
            && self.kp_nm_per_rad.is_finite()
            && self.kp_nm_per_rad > 0.0
            && self.kv_nms_per_rad.is_finite()
            && self.kv_nms_per_rad >= 0.0
            && self.torque_cap_nm.is_finite()
            && self.torque_cap_nm > 0.0;
        if ok {
            Ok(())
        } else {
            Err(SimError::InvalidConfig(format!(
                "joint {joint}: servo {self:?} (needs a finite range, kp > 0, kv >= 0, torque cap > 0)"
            )))
        }
    }
}

/// The rapier body a joint moves and the joint that moves it.
#[derive(Debug, Clone, Copy)]
struct JointHandles {
    body: RigidBodyHandle,
    joint: MultibodyJointHandle,
}

/// A finger's colliders: the fingertip and the rest.
#[derive(Debug, Clone)]
struct FingerHandles {
    /// Its joints in the joint vector.
    joints: Range<usize>,
    /// The fingertip's collider (the sphere or capsule at the fingertip).
    tip: ColliderHandle,
    /// Every other collider on the finger's moving bodies, in body order.
    links: Vec<ColliderHandle>,
}

/// Where each body of the description lives in rapier: on a fixed body (the palm and what
/// is welded to it) or on a moving body, at a pose in that body's frame.
#[derive(Debug, Clone, Copy)]
enum Placement {
    Fixed,
    Moving { joint: usize, pose_in_rigid_body: Isometry3<f32> },
}

/// The joint frame of a revolute joint turning about `axis`: rapier turns about the frame's
/// x. Axis-aligned axes get exact quarter turns (a general arc carries rounding into every
/// joint frame).
fn frame_turning_about(axis: &Vector3<f32>) -> Rotation {
    use std::f32::consts::{FRAC_PI_2, PI};
    match (axis.x, axis.y, axis.z) {
        (1.0, 0.0, 0.0) => Rotation::IDENTITY,
        (-1.0, 0.0, 0.0) => Rotation::from_rotation_z(PI),
        (0.0, 1.0, 0.0) => Rotation::from_rotation_z(FRAC_PI_2),
        (0.0, -1.0, 0.0) => Rotation::from_rotation_z(-FRAC_PI_2),
        (0.0, 0.0, 1.0) => Rotation::from_rotation_y(-FRAC_PI_2),
        (0.0, 0.0, -1.0) => Rotation::from_rotation_y(FRAC_PI_2),
        _ => Rotation::from_rotation_arc(Vector::X, Vector::new(axis.x, axis.y, axis.z)),
    }
}

/// A collision geom as a rapier collider (its pose in the geom's rigid body still to set);
/// `None` for a visual mesh.
fn geom_collider(shape: &GeomShape) -> Option<(ColliderBuilder, Pose)> {
    match shape {
        GeomShape::Sphere { radius_m } => Some((ColliderBuilder::ball(*radius_m), Pose::IDENTITY)),
        GeomShape::Capsule { radius_m, half_length_m } => {
            Some((ColliderBuilder::capsule_z(*half_length_m, *radius_m), Pose::IDENTITY))
        }
        // rapier's cylinders stand along y, MuJoCo's along z.
        GeomShape::Cylinder { radius_m, half_length_m } => Some((
            ColliderBuilder::cylinder(*half_length_m, *radius_m),
            Pose::from_rotation(Rotation::from_rotation_x(std::f32::consts::FRAC_PI_2)),
        )),
        GeomShape::Box { half_extents_m: h } => {
            Some((ColliderBuilder::cuboid(h.x, h.y, h.z), Pose::IDENTITY))
        }
        GeomShape::VisualMesh { .. } => None,
    }
}

/// A colliding geom's collider with its friction, groups and mass (none when its body's
/// `<inertial>` gives the mass), and the frame of rapier's shape in the geom's frame.
fn collider_builder(
    geom: &vge_hand::Geom,
    body_has_inertial: bool,
    physics: &PhysicsConfig,
    groups: InteractionGroups,
) -> Option<(ColliderBuilder, Pose)> {
    if !geom.collides() {
        return None;
    }
    let (builder, shape_frame) = geom_collider(&geom.shape)?;
    let builder = builder.friction(physics.finger_friction).collision_groups(groups);
    let builder = if body_has_inertial {
        builder.density(0.0)
    } else {
        match geom.mass {
            GeomMass::Kg(kg) => builder.mass(kg),
            GeomMass::DensityKgPerM3(density) => builder.density(density),
        }
    };
    Some((builder, shape_frame))
}

fn mass_properties(inertial: &vge_hand::Inertial) -> MassProperties {
    let c = inertial.com_in_body_m;
    let com = Vector::new(c.x, c.y, c.z);
    let m = inertial.inertia_kg_m2;
    let diagonal = m[(0, 1)] == 0.0 && m[(0, 2)] == 0.0 && m[(1, 2)] == 0.0;
    if diagonal {
        MassProperties::new(com, inertial.mass_kg, Vector::new(m[(0, 0)], m[(1, 1)], m[(2, 2)]))
    } else {
        let column = |j: usize| rapier3d::math::Vector::new(m[(0, j)], m[(1, j)], m[(2, j)]);
        MassProperties::with_inertia_matrix(
            com,
            inertial.mass_kg,
            rapier3d::math::Matrix::from_cols(column(0), column(1), column(2)),
        )
    }
}

/// The physics world of one hand and one object.
pub struct HandWorld {
    hand: Arc<Hand>,
    servos: Vec<JointServo>,
    physics: PhysicsConfig,
    world: PhysicsWorld,
    joints: Vec<JointHandles>,
    fingers: Vec<FingerHandles>,
    placements: Vec<Placement>,
    object_body: RigidBodyHandle,
    object_collider: ColliderHandle,
    q_target: Vec<f32>,
}

impl std::fmt::Debug for HandWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HandWorld")
            .field("hand", &self.hand.name())
            .field("physics", &self.physics)
            .field("q_target", &self.q_target)
            .field("object", &self.object_state())
            .finish_non_exhaustive()
    }
}

/// Per body of the description: where it is placed in rapier. A moving body is the one its
/// (single) hinge turns; a body without joints goes with its parent.
fn placements(hand: &Hand) -> Result<Vec<Placement>, SimError> {
    let mut out: Vec<Placement> = Vec::with_capacity(hand.bodies().len());
    for body in hand.bodies() {
        let placement = match body.joints.len() {
            0 => match body.parent.and_then(|p| out.get(p)) {
                None | Some(Placement::Fixed) => Placement::Fixed,
                Some(Placement::Moving { joint, pose_in_rigid_body }) => Placement::Moving {
                    joint: *joint,
                    pose_in_rigid_body: pose_in_rigid_body * body.pose_in_parent,
                },
            },
            1 => Placement::Moving { joint: body.joints.start, pose_in_rigid_body: Isometry3::identity() },
            n => {
                return Err(SimError::InvalidConfig(format!(
                    "hand {}: body {} has {n} joints; the simulator takes one hinge per body",
                    hand.name(),
                    body.name.as_deref().unwrap_or("(unnamed)")
                )));
            }
        };
        out.push(placement);
    }
    Ok(out)
}

impl HandWorld {
    /// Builds the world of `hand` with its joints driven by `servos` (one per joint), all
    /// joints at `q_rad` (targets too) and the object at rest with its centre at
    /// `object_pose`.
    pub fn new(
        hand: &Arc<Hand>,
        servos: &[JointServo],
        physics: &PhysicsConfig,
        object: &ObjectConfig,
        q_rad: &[f32],
        object_pose: &Isometry3<f32>,
    ) -> Result<Self, SimError> {
        physics.validate()?;
        object.validate()?;
        let n = hand.num_joints();
        if servos.len() != n {
            return Err(SimError::InvalidConfig(format!(
                "{} servos for the {n} joints of {}",
                servos.len(),
                hand.name()
            )));
        }
        for (servo, joint) in servos.iter().zip(hand.joints()) {
            servo.validate(&joint.name)?;
        }
        if q_rad.len() != n {
            return Err(SimError::ActionLength { got: q_rad.len(), expected: n });
        }
        let mut world = PhysicsWorld::new();
        let g = physics.gravity_m_per_s2_vector();
        world.gravity = Vector::new(g.x, g.y, g.z);
        world.integration_parameters = IntegrationParameters {
            dt: physics.dt_s(),
            num_solver_iterations: physics.solver_iterations,
            contact_softness: SpringCoefficients::new(
                physics.contact_natural_frequency_hz,
                physics.contact_damping_ratio,
            ),
            contact_recycling: false,
            normalized_prediction_distance: physics.contact_prediction_distance_m,
            ..IntegrationParameters::default()
        };
        let hand_filter = if physics.finger_collisions { OBJECT_GROUP | HAND_GROUP } else { OBJECT_GROUP };
        let hand_groups = InteractionGroups::new(HAND_GROUP, hand_filter, InteractionTestMode::And);
        let object_groups = InteractionGroups::new(OBJECT_GROUP, HAND_GROUP, InteractionTestMode::And);

        let placements = placements(hand)?;
        let clamped: Vec<f32> = q_rad.iter().zip(servos).map(|(q, s)| s.limit.clamp(*q)).collect();
        let body_poses =
            hand.body_poses_world(&clamped).map_err(|e| SimError::InvalidConfig(e.to_string()))?;
        let bodies = hand.bodies();
        let joints_desc = hand.joints();

        // Finger by finger, as rapier's solver order follows insertion: the fixed body its
        // first joint hangs from (one multibody per finger), its moving bodies (one per
        // joint, at the description's pose), their colliders, then its joints. The palm's
        // colliders (what is welded to the world) go on one fixed body after the fingers.
        let mut rigid: Vec<Option<RigidBodyHandle>> = vec![None; n];
        let mut colliders_of_joint: Vec<Vec<((usize, usize), ColliderHandle)>> = vec![Vec::new(); n];
        let mut joints: Vec<Option<JointHandles>> = vec![None; n];
        for finger in hand.fingers() {
            let Some(first) = joints_desc.get(finger.joints.start) else { continue };
            let root_parent = bodies[first.body].parent.ok_or_else(|| {
                SimError::InvalidConfig(format!("joint {} is on the world body", first.name))
            })?;
            let base = match placements[root_parent] {
                Placement::Fixed => {
                    world.bodies.insert(RigidBodyBuilder::fixed().pose(iso_to_pose(&body_poses[root_parent])))
                }
                Placement::Moving { .. } => {
                    return Err(SimError::InvalidConfig(format!(
                        "finger {}: its first joint {} hangs from a moving body (a joint shared with another finger)",
                        finger.name, first.name
                    )));
                }
            };
            for j in finger.joints.clone() {
                let pose = body_poses[joints_desc[j].body];
                let mut builder = RigidBodyBuilder::dynamic().pose(iso_to_pose(&pose)).can_sleep(false);
                // Mass: a body's `<inertial>` when the file gives one (its geoms then add none,
                // as in MuJoCo), else its geoms' densities or masses through the colliders.
                let inertials =
                    bodies.iter().enumerate().filter_map(|(b, body)| match (placements[b], body.inertial) {
                        (Placement::Moving { joint, pose_in_rigid_body }, Some(inertial)) if joint == j => {
                            Some(mass_properties(&inertial).transform_by(&iso_to_pose(&pose_in_rigid_body)))
                        }
                        _ => None,
                    });
                if let Some(props) = inertials.reduce(|a, b| a + b) {
                    builder = builder.additional_mass_properties(props);
                }
                rigid[j] = Some(world.bodies.insert(builder));
            }
            let rigid_of =
                |j: usize| rigid[j].ok_or_else(|| SimError::InvalidConfig(format!("joint {j} has no body")));
            for (b, body) in bodies.iter().enumerate() {
                let Placement::Moving { joint, pose_in_rigid_body } = placements[b] else { continue };
                if !finger.joints.contains(&joint) {
                    continue;
                }
                for (g, geom) in body.geoms.iter().enumerate() {
                    let Some(builder) = collider_builder(geom, body.inertial.is_some(), physics, hand_groups)
                    else {
                        continue;
                    };
                    let (builder, shape_frame) = builder;
                    let pose = pose_in_rigid_body * geom.pose_in_body;
                    let c = builder.position(iso_to_pose(&pose) * shape_frame);
                    let handle = world.colliders.insert_with_parent(c, rigid_of(joint)?, &mut world.bodies);
                    colliders_of_joint[joint].push(((b, g), handle));
                }
            }
            // Joints: the parent's frame of the hinge = the body's pose in its parent, then the
            // hinge's anchor and axis; the child's = the anchor and axis in the body.
            for j in finger.joints.clone() {
                let joint = &joints_desc[j];
                let body = &bodies[joint.body];
                let parent = body.parent.unwrap_or(0);
                let (parent_rigid, parent_pose) = match placements[parent] {
                    Placement::Fixed => (base, Isometry3::identity()),
                    Placement::Moving { joint: pj, pose_in_rigid_body } => {
                        (rigid_of(pj)?, pose_in_rigid_body)
                    }
                };
                let turn = frame_turning_about(joint.axis_in_body.as_ref());
                let anchor = joint.pos_in_body_m;
                let frame2 = Pose::from_parts(Vector::new(anchor.x, anchor.y, anchor.z), turn);
                let frame1 = iso_to_pose(&(parent_pose * body.pose_in_parent)) * frame2;
                let servo = servos[j];
                let data = GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES)
                    // A finger's links overlap at its joints: with the fingers colliding, only
                    // different fingers may touch.
                    .contacts_enabled(!physics.finger_collisions)
                    .local_frame1(frame1)
                    .local_frame2(frame2)
                    .limits(JointAxis::AngX, [servo.limit.lower_rad, servo.limit.upper_rad])
                    .motor_model(JointAxis::AngX, MotorModel::ForceBased)
                    .motor_position(JointAxis::AngX, clamped[j], servo.kp_nm_per_rad, servo.kv_nms_per_rad)
                    .motor_max_force(JointAxis::AngX, servo.torque_cap_nm)
                    .build();
                let child = rigid_of(j)?;
                let handle =
                    world.multibody_joints.insert(parent_rigid, child, data, true).ok_or_else(|| {
                        SimError::InvalidConfig(format!("joint {}: rejected by rapier", joint.name))
                    })?;
                joints[j] = Some(JointHandles { body: child, joint: handle });
            }
        }
        let joints: Vec<JointHandles> = joints
            .into_iter()
            .enumerate()
            .map(|(j, h)| {
                h.ok_or_else(|| {
                    SimError::InvalidConfig(format!("joint {} is on no finger", joints_desc[j].name))
                })
            })
            .collect::<Result<_, _>>()?;
        // The palm and what is welded to it: fixed colliders (the object must not rest on
        // them in a fingertip grasp, but they are there to be touched).
        let palm_geoms: Vec<(usize, &vge_hand::Geom)> = bodies
            .iter()
            .enumerate()
            .filter(|(b, _)| matches!(placements[*b], Placement::Fixed))
            .flat_map(|(b, body)| body.geoms.iter().map(move |g| (b, g)))
            .filter(|(_, g)| g.collides())
            .collect();
        if !palm_geoms.is_empty() {
            let palm = world.bodies.insert(RigidBodyBuilder::fixed());
            for (b, geom) in palm_geoms {
                if let Some((builder, shape_frame)) = collider_builder(geom, true, physics, hand_groups) {
                    let pose = body_poses[b] * geom.pose_in_body;
                    world.colliders.insert_with_parent(
                        builder.position(iso_to_pose(&pose) * shape_frame),
                        palm,
                        &mut world.bodies,
                    );
                }
            }
        }

        let mut fingers = Vec::with_capacity(hand.num_fingers());
        for finger in hand.fingers() {
            let Placement::Moving { joint: tip_joint, .. } = placements[finger.tip_body] else {
                return Err(SimError::InvalidConfig(format!(
                    "finger {}: its fingertip does not move",
                    finger.name
                )));
            };
            // The fingertip's collider: the geom the description names as the fingertip's.
            let Some(g) = finger.tip_geom else {
                return Err(SimError::InvalidConfig(format!(
                    "finger {}: no colliding sphere or capsule on its fingertip body",
                    finger.name
                )));
            };
            let key = (finger.tip_body, g);
            let mut tip = None;
            let mut links = Vec::new();
            for j in finger.joints.clone() {
                for (k, handle) in &colliders_of_joint[j] {
                    if *k == key && j == tip_joint {
                        tip = Some(*handle);
                    } else {
                        links.push(*handle);
                    }
                }
            }
            let tip = tip.ok_or_else(|| {
                SimError::InvalidConfig(format!("finger {}: fingertip collider", finger.name))
            })?;
            fingers.push(FingerHandles { joints: finger.joints.clone(), tip, links });
        }

        let object_body = world.bodies.insert(
            RigidBodyBuilder::dynamic().pose(iso_to_pose(object_pose)).can_sleep(false).ccd_enabled(false),
        );
        let object_collider = world.colliders.insert_with_parent(
            object.collider()?.collision_groups(object_groups),
            object_body,
            &mut world.bodies,
        );
        let mut this = Self {
            hand: Arc::clone(hand),
            servos: servos.to_vec(),
            physics: *physics,
            world,
            joints,
            fingers,
            placements,
            object_body,
            object_collider,
            q_target: vec![0.0; n],
        };
        this.set_joint_positions(q_rad)?;
        this.set_joint_targets(q_rad);
        Ok(this)
    }

    /// The hand the world was built from.
    #[must_use]
    pub fn hand(&self) -> &Arc<Hand> {
        &self.hand
    }

    /// The joints' servos.
    #[must_use]
    pub fn servos(&self) -> &[JointServo] {
        &self.servos
    }

    /// The physics parameters.
    #[must_use]
    pub fn physics(&self) -> &PhysicsConfig {
        &self.physics
    }

    /// Advances the world by one physics step.
    pub fn step(&mut self) {
        self.world.step();
    }

    /// Simulated time per [`Self::step`].
    #[must_use]
    pub fn dt_s(&self) -> f32 {
        self.world.integration_parameters.dt
    }

    /// Joint angles (rad), in the hand's joint order, read from the multibodies.
    #[must_use]
    pub fn joint_positions(&self) -> Vec<f32> {
        self.joints
            .iter()
            .map(|h| {
                self.world
                    .multibody_joints
                    .get(h.joint)
                    .and_then(|(mb, link)| mb.link(link).map(|l| l.joint.coords()[3]))
                    .unwrap_or(0.0)
            })
            .collect()
    }

    /// Joint velocities (rad/s), in the hand's joint order.
    #[must_use]
    pub fn joint_velocities(&self) -> Vec<f32> {
        let mut dq = vec![0.0; self.joints.len()];
        for f in &self.fingers {
            let Some(first) = self.joints.get(f.joints.start) else { continue };
            if let Some((mb, _)) = self.world.multibody_joints.get(first.joint) {
                let v = mb.generalized_velocity();
                for (k, j) in f.joints.clone().enumerate() {
                    if let Some(value) = v.get(k) {
                        dq[j] = *value;
                    }
                }
            }
        }
        dq
    }

    /// Teleports the joints to `q_rad` (clamped to the limits) with zero joint velocity,
    /// and moves the link bodies accordingly. Non-finite entries are rejected.
    pub fn set_joint_positions(&mut self, q_rad: &[f32]) -> Result<(), SimError> {
        if q_rad.len() != self.joints.len() {
            return Err(SimError::ActionLength { got: q_rad.len(), expected: self.joints.len() });
        }
        if let Some(index) = q_rad.iter().position(|v| !v.is_finite()) {
            return Err(SimError::NonFiniteAction { index, value: q_rad[index] });
        }
        let current = self.joint_positions();
        for f in &self.fingers {
            let Some(first) = self.joints.get(f.joints.start) else { continue };
            let Some((mb, _)) = self.world.multibody_joints.get_mut(first.joint) else { continue };
            // Turns the root's provisional free joint into the fixed one first, so the
            // multibody has exactly the finger's DOFs.
            mb.forward_kinematics(&self.world.bodies, true);
            if mb.ndofs() != f.joints.len() {
                return Err(SimError::InvalidConfig(format!(
                    "a finger's multibody has {} DOFs for {} joints",
                    mb.ndofs(),
                    f.joints.len()
                )));
            }
            let disp: Vec<f32> =
                f.joints.clone().map(|k| self.servos[k].limit.clamp(q_rad[k]) - current[k]).collect();
            mb.apply_displacements(&disp);
            mb.generalized_velocity_mut().fill(0.0);
            mb.forward_kinematics(&self.world.bodies, false);
            mb.update_rigid_bodies(&mut self.world.bodies, true);
            for h in &self.joints[f.joints.clone()] {
                if let Some(rb) = self.world.bodies.get_mut(h.body) {
                    rb.set_linvel(Vector::ZERO, true);
                    rb.set_angvel(Vector::ZERO, true);
                }
            }
        }
        Ok(())
    }

    /// Current joint targets (rad).
    #[must_use]
    pub fn joint_targets(&self) -> &[f32] {
        &self.q_target
    }

    /// Sets the motor targets; entries are clamped to the joint limits (NaN is replaced
    /// by the current target, but callers validate first). Extra entries are ignored and
    /// missing ones keep their target.
    pub fn set_joint_targets(&mut self, q_target_rad: &[f32]) {
        for (k, (h, v)) in self.joints.iter().zip(q_target_rad).enumerate() {
            let servo = self.servos[k];
            let target = if v.is_finite() { servo.limit.clamp(*v) } else { self.q_target[k] };
            self.q_target[k] = target;
            if let Some((mb, link)) = self.world.multibody_joints.get_mut(h.joint)
                && let Some(l) = mb.link_mut(link)
            {
                l.joint.data.set_motor_position(
                    JointAxis::AngX,
                    target,
                    servo.kp_nm_per_rad,
                    servo.kv_nms_per_rad,
                );
                // After torque driving, the servo's own cap again.
                l.joint.data.set_motor_max_force(JointAxis::AngX, servo.torque_cap_nm);
            }
        }
    }

    /// World pose of the description's body `body`, read from rapier (the world's own
    /// fixed frame for the palm and what is welded to it).
    pub fn body_pose(&self, body: usize) -> Result<Isometry3<f32>, SimError> {
        match self.placements.get(body) {
            None => Err(SimError::InvalidConfig(format!("body index {body}"))),
            Some(Placement::Fixed) => {
                let zeros = vec![0.0f32; self.joints.len()];
                let poses =
                    self.hand.body_poses_world(&zeros).map_err(|e| SimError::InvalidConfig(e.to_string()))?;
                Ok(poses[body])
            }
            Some(Placement::Moving { joint, pose_in_rigid_body }) => {
                let rb = self.world.bodies.get(self.joints[*joint].body).ok_or(SimError::NotReset)?;
                Ok(pose_to_iso(rb.position()) * pose_in_rigid_body)
            }
        }
    }

    /// Drives the joints by torques (N m, one per joint) instead of their servos, as a
    /// torque-controlled hand is driven (its joint controller's host runs the position loop);
    /// each torque is held until the next call, and `set_joint_targets` gives the joints back
    /// to their servos. Torques beyond a joint's cap are clipped to it; 0 leaves the joint limp.
    /// Non-finite torques are refused and nothing is changed.
    pub fn set_joint_torques(&mut self, torques_nm: &[f32]) -> Result<(), SimError> {
        if torques_nm.len() != self.joints.len() {
            return Err(SimError::ActionLength { got: torques_nm.len(), expected: self.joints.len() });
        }
        if let Some(index) = torques_nm.iter().position(|v| !v.is_finite()) {
            return Err(SimError::NonFiniteAction { index, value: torques_nm[index] });
        }
        for (k, (h, tau)) in self.joints.iter().zip(torques_nm).enumerate() {
            let cap = self.servos[k].torque_cap_nm;
            if let Some((mb, link)) = self.world.multibody_joints.get_mut(h.joint)
                && let Some(l) = mb.link_mut(link)
            {
                // A velocity motor that can never reach its target velocity pushes with its
                // whole force, which is the torque asked for: no stiffness, unit damping, a
                // target far beyond any joint speed, the torque as the force cap.
                let target_rad_per_s = if *tau >= 0.0 { 1e6 } else { -1e6 };
                l.joint.data.set_motor(JointAxis::AngX, 0.0, target_rad_per_s, 0.0, 1.0);
                l.joint.data.set_motor_max_force(JointAxis::AngX, tau.abs().min(cap));
            }
        }
        Ok(())
    }

    /// World pose of the rigid body that joint `joint` turns (its link), read from rapier.
    pub fn link_pose(&self, joint: usize) -> Result<Isometry3<f32>, SimError> {
        let h =
            self.joints.get(joint).ok_or_else(|| SimError::InvalidConfig(format!("joint index {joint}")))?;
        let rb = self.world.bodies.get(h.body).ok_or(SimError::NotReset)?;
        Ok(pose_to_iso(rb.position()))
    }

    /// World position of the fingertip point of `finger` (its site, or its body's origin),
    /// read from rapier.
    pub fn fingertip_position_m(&self, finger: usize) -> Result<Vector3<f32>, SimError> {
        let f = self
            .hand
            .fingers()
            .get(finger)
            .ok_or_else(|| SimError::InvalidConfig(format!("finger index {finger}")))?;
        let pose = self.body_pose(f.tip_body)?;
        Ok((pose * nalgebra::Point3::from(f.tip_offset_in_body_m)).coords)
    }

    /// Pose and velocity of the object.
    #[must_use]
    pub fn object_state(&self) -> ObjectState {
        match self.world.bodies.get(self.object_body) {
            Some(rb) => ObjectState {
                pose: pose_to_iso(rb.position()),
                linvel_m_per_s: v3(rb.linvel()),
                angvel_rad_per_s: v3(rb.angvel()),
            },
            None => ObjectState {
                pose: Isometry3::identity(),
                linvel_m_per_s: Vector3::zeros(),
                angvel_rad_per_s: Vector3::zeros(),
            },
        }
    }

    /// Mass of the object (kg).
    #[must_use]
    pub fn object_mass_kg(&self) -> f32 {
        self.world.bodies.get(self.object_body).map_or(0.0, |rb| rb.mass())
    }

    /// Teleports the object to `pose` (velocity kept). Non-finite poses are rejected.
    pub fn set_object_pose(&mut self, pose: &Isometry3<f32>) -> Result<(), SimError> {
        let p = iso_to_pose(pose);
        if !p.is_finite() {
            return Err(SimError::NonFiniteState("object pose".to_owned()));
        }
        if let Some(rb) = self.world.bodies.get_mut(self.object_body) {
            rb.set_position(p, true);
        }
        Ok(())
    }

    /// Makes the object fixed (`true`) or dynamic (`false`), with zero velocity.
    pub fn set_object_fixed(&mut self, fixed: bool) {
        if let Some(rb) = self.world.bodies.get_mut(self.object_body) {
            let ty = if fixed {
                rapier3d::dynamics::RigidBodyType::Fixed
            } else {
                rapier3d::dynamics::RigidBodyType::Dynamic
            };
            rb.set_body_type(ty, true);
            rb.set_linvel(Vector::ZERO, true);
            rb.set_angvel(Vector::ZERO, true);
        }
    }

    /// Sets the external force on the object's centre of mass (N, world), held until
    /// changed. Non-finite forces are ignored (callers validate).
    pub fn set_object_external_force(&mut self, force_n: &Vector3<f32>) {
        if !force_n.iter().all(|v| v.is_finite()) {
            return;
        }
        if let Some(rb) = self.world.bodies.get_mut(self.object_body) {
            rb.reset_forces(true);
            rb.add_force(Vector::new(force_n.x, force_n.y, force_n.z), true);
        }
    }

    fn pair_reading(&self, collider: ColliderHandle) -> Option<ContactReading> {
        let pair = self.world.narrow_phase.contact_pair(collider, self.object_collider)?;
        let flip = if pair.collider1 == collider { 1.0 } else { -1.0 };
        let inv_dt = 1.0 / self.dt_s();
        let substeps_per_dt = self.physics.solver_iterations as f32 * inv_dt;
        let mut total_impulse = 0.0;
        let mut point = Vector::ZERO;
        let mut normal = Vector::ZERO;
        let mut friction = Vector::ZERO;
        for m in pair.solver_manifolds() {
            for sc in m.data.solver_contacts.iter() {
                let Some(pt) = m.points.get(sc.contact_indices()[0] as usize) else { continue };
                let impulse = pt.data.impulse;
                if impulse <= 0.0 {
                    continue;
                }
                let (p1, p2) = m.data.solver_contact_world_points(sc, &self.world.bodies);
                total_impulse += impulse;
                point += (p1 + p2) * (0.5 * impulse);
                normal += m.data.normal * (flip * impulse);
                // The last substep's friction impulse (world), applied to collider 1; the
                // object is collider 2 when the finger is collider 1.
                friction += pt.data.warmstart_tangent_world * (-flip * substeps_per_dt);
            }
        }
        if total_impulse <= 0.0 {
            return None;
        }
        let n = normal.normalize_or_zero();
        Some(ContactReading {
            position_m: v3(point / total_impulse),
            normal: v3(n),
            normal_force_n: total_impulse * inv_dt,
            friction_force_n: v3(friction),
        })
    }

    /// Contact of each fingertip with the object, in finger order (`None` when not touching:
    /// zero normal impulse in the last step).
    #[must_use]
    pub fn fingertip_contacts(&self) -> Vec<Option<ContactReading>> {
        self.fingers.iter().map(|f| self.pair_reading(f.tip)).collect()
    }

    /// Contacts of each finger's other colliders (its links) with the object, per finger in
    /// body order; these carry load too at large roll angles.
    #[must_use]
    pub fn link_contacts(&self) -> Vec<Vec<Option<ContactReading>>> {
        self.fingers.iter().map(|f| f.links.iter().map(|c| self.pair_reading(*c)).collect()).collect()
    }

    /// Whether any position, rotation or velocity in the world is non-finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.world
            .bodies
            .iter()
            .all(|(_, rb)| rb.position().is_finite() && rb.linvel().is_finite() && rb.angvel().is_finite())
    }

    /// Signed distance (m, negative when penetrating) between the object at its current pose
    /// and the body carrying `finger`'s fingertip (its fingertip and any other collider on
    /// it), with the finger's joints at `q_finger_rad` and the others where they are; used
    /// to close the fingers geometrically.
    pub fn finger_object_distance_m(&self, finger: usize, q_finger_rad: &[f32]) -> Result<f32, SimError> {
        let f = self
            .fingers
            .get(finger)
            .ok_or_else(|| SimError::InvalidConfig(format!("finger index {finger}")))?;
        if q_finger_rad.len() != f.joints.len() {
            return Err(SimError::ActionLength { got: q_finger_rad.len(), expected: f.joints.len() });
        }
        let mut q = self.joint_positions();
        q[f.joints.clone()].copy_from_slice(q_finger_rad);
        let poses = self.hand.body_poses_world(&q).map_err(|e| SimError::InvalidConfig(e.to_string()))?;
        let tip_collider = self.world.colliders.get(f.tip).ok_or(SimError::NotReset)?;
        let tip_rigid = tip_collider.parent().ok_or(SimError::NotReset)?;
        let tip_joint = self.joints.iter().position(|h| h.body == tip_rigid).ok_or(SimError::NotReset)?;
        let rigid_pose = iso_to_pose(&poses[self.hand.joints()[tip_joint].body]);
        let obj = self.world.colliders.get(self.object_collider).ok_or(SimError::NotReset)?;
        let obj_pose = *obj.position();
        let mut nearest = f32::INFINITY;
        for handle in std::iter::once(&f.tip).chain(&f.links) {
            let Some(c) = self.world.colliders.get(*handle) else { continue };
            if c.parent() != Some(tip_rigid) {
                continue;
            }
            let pose = rigid_pose * c.position_wrt_parent().copied().unwrap_or(Pose::IDENTITY);
            let d = match rapier3d::parry::query::contact(&pose, c.shape(), &obj_pose, obj.shape(), 0.0) {
                Ok(Some(contact)) => contact.dist,
                Ok(None) => rapier3d::parry::query::distance(&pose, c.shape(), &obj_pose, obj.shape())
                    .map(|d| d.distance)
                    .map_err(|e| SimError::InvalidConfig(format!("distance query: {e:?}")))?,
                Err(e) => return Err(SimError::InvalidConfig(format!("contact query: {e:?}"))),
            };
            nearest = nearest.min(d);
        }
        Ok(nearest)
    }
}
