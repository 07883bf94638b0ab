//! The rapier3d world: a fixed palm (five fixed finger bases), one multibody per finger
//! (roll, proximal flexion, distal flexion; reduced coordinates with position motors),
//! and one dynamic object. Bodies and joints are placed from [`HandModel`]'s frames, so
//! the physics and the kinematics agree by construction (tested in `tests/`).
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
use crate::kinematics::{HandModel, JOINTS_PER_FINGER, NUM_FINGERS, NUM_JOINTS, joint_index};
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
    /// Motor stiffness (N*m/rad, `ForceBased`); the torque caps of the hand model bound it.
    pub motor_stiffness_nm_per_rad: f32,
    /// Motor damping (N*m*s/rad).
    pub motor_damping_nms_per_rad: f32,
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
            motor_stiffness_nm_per_rad: 20.0,
            motor_damping_nms_per_rad: 0.1,
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
            ("motor stiffness", self.motor_stiffness_nm_per_rad),
            ("link density", self.link_density_kg_per_m3),
            ("contact prediction distance", self.contact_prediction_distance_m),
        ] {
            if !pos(v) {
                return Err(SimError::InvalidConfig(format!("{name} {v}")));
            }
        }
        for (name, v) in [
            ("finger friction", self.finger_friction),
            ("motor damping", self.motor_damping_nms_per_rad),
            ("gravity", self.gravity_m_per_s2),
        ] {
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
}

impl HandOrientation {
    /// All orientations, in a fixed order.
    pub const ALL: [Self; 2] = [Self::PalmDown, Self::SideOn];

    /// The name configs use (`"palm_down"`, `"side_on"`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::PalmDown => "palm_down",
            Self::SideOn => "side_on",
        }
    }

    /// Unit vector along gravity in the hand's frame.
    #[must_use]
    pub fn down(self) -> Vector3<f32> {
        match self {
            Self::PalmDown => Vector3::new(0.0, 0.0, -1.0),
            Self::SideOn => Vector3::new(1.0, 0.0, 0.0),
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

#[derive(Debug, Clone, Copy)]
struct FingerHandles {
    /// [roll body, proximal body, distal body].
    links: [RigidBodyHandle; JOINTS_PER_FINGER],
    joints: [MultibodyJointHandle; JOINTS_PER_FINGER],
    tip: ColliderHandle,
    link_colliders: [ColliderHandle; 2],
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

/// The physics world of one hand and one object.
pub struct HandWorld {
    hand: HandModel,
    physics: PhysicsConfig,
    world: PhysicsWorld,
    fingers: [FingerHandles; NUM_FINGERS],
    object_body: RigidBodyHandle,
    object_collider: ColliderHandle,
    q_target: [f32; NUM_JOINTS],
}

impl std::fmt::Debug for HandWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HandWorld")
            .field("physics", &self.physics)
            .field("q_target", &self.q_target)
            .field("object", &self.object_state())
            .finish_non_exhaustive()
    }
}

impl HandWorld {
    /// Builds the world with all joints at `q_rad` (targets too) and the object at rest
    /// with its centre at `object_pose`.
    pub fn new(
        hand: &HandModel,
        physics: &PhysicsConfig,
        object: &ObjectConfig,
        q_rad: &[f32; NUM_JOINTS],
        object_pose: &Isometry3<f32>,
    ) -> Result<Self, SimError> {
        physics.validate()?;
        object.validate()?;
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

        let mut fingers = Vec::with_capacity(NUM_FINGERS);
        for (i, finger) in hand.fingers.iter().enumerate() {
            let q = hand.finger_joints(i, q_rad)?;
            let frames = finger.frames(&q)?;
            let base = world.bodies.insert(RigidBodyBuilder::fixed().pose(iso_to_pose(&frames[0])));
            // The roll link has no geometry (its axis meets the proximal flexion axis at the
            // knuckle): a small point mass keeps the reduced mass matrix regular.
            let roll = world.bodies.insert(
                RigidBodyBuilder::dynamic()
                    .pose(iso_to_pose(&frames[1]))
                    .additional_mass_properties(MassProperties::new(Vector::ZERO, 0.005, Vector::splat(1e-6)))
                    .can_sleep(false),
            );
            let prox = world
                .bodies
                .insert(RigidBodyBuilder::dynamic().pose(iso_to_pose(&frames[2])).can_sleep(false));
            let dist = world
                .bodies
                .insert(RigidBodyBuilder::dynamic().pose(iso_to_pose(&frames[3])).can_sleep(false));
            let link = |length: f32| {
                ColliderBuilder::capsule_z(0.5 * length, finger.link_radius_m)
                    .translation(Vector::new(0.0, 0.0, -0.5 * length))
                    .density(physics.link_density_kg_per_m3)
                    .friction(physics.finger_friction)
                    .collision_groups(hand_groups)
            };
            let prox_col =
                world.colliders.insert_with_parent(link(finger.proximal_length_m), prox, &mut world.bodies);
            let dist_col =
                world.colliders.insert_with_parent(link(finger.distal_length_m), dist, &mut world.bodies);
            let tip = world.colliders.insert_with_parent(
                ColliderBuilder::ball(finger.tip_radius_m)
                    .translation(Vector::new(0.0, 0.0, -finger.distal_length_m))
                    .density(physics.link_density_kg_per_m3)
                    .friction(physics.finger_friction)
                    .collision_groups(hand_groups),
                dist,
                &mut world.bodies,
            );
            // Revolute joints about the joint frame's x: identity frames for the roll (about
            // base +x), frames turned +90 deg about z for the flexions (about +y).
            let about_y = Rotation::from_rotation_z(std::f32::consts::FRAC_PI_2);
            let joint_frames = [
                (Pose::IDENTITY, Pose::IDENTITY),
                (Pose::from_rotation(about_y), Pose::from_rotation(about_y)),
                (
                    Pose::from_parts(Vector::new(0.0, 0.0, -finger.proximal_length_m), about_y),
                    Pose::from_rotation(about_y),
                ),
            ];
            let chain = [(base, roll), (roll, prox), (prox, dist)];
            let mut joints = Vec::with_capacity(JOINTS_PER_FINGER);
            for j in 0..JOINTS_PER_FINGER {
                let limit = finger.joint_limits[j];
                let target = limit.clamp(q[j]);
                let joint = GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES)
                    // A finger's links overlap at its joints: with the fingers colliding, only
                    // different fingers may touch.
                    .contacts_enabled(!physics.finger_collisions)
                    .local_frame1(joint_frames[j].0)
                    .local_frame2(joint_frames[j].1)
                    .limits(JointAxis::AngX, [limit.lower_rad, limit.upper_rad])
                    .motor_model(JointAxis::AngX, MotorModel::ForceBased)
                    .motor_position(
                        JointAxis::AngX,
                        target,
                        physics.motor_stiffness_nm_per_rad,
                        physics.motor_damping_nms_per_rad,
                    )
                    .motor_max_force(JointAxis::AngX, finger.torque_caps_nm[j])
                    .build();
                let handle = world
                    .multibody_joints
                    .insert(chain[j].0, chain[j].1, joint, true)
                    .ok_or_else(|| SimError::InvalidConfig(format!("finger {i}: joint {j} rejected")))?;
                joints.push(handle);
            }
            let joints: [MultibodyJointHandle; JOINTS_PER_FINGER] =
                joints.try_into().map_err(|_| SimError::InvalidConfig("joint count".to_owned()))?;
            fingers.push(FingerHandles {
                links: [roll, prox, dist],
                joints,
                tip,
                link_colliders: [prox_col, dist_col],
            });
        }
        let fingers: [FingerHandles; NUM_FINGERS] =
            fingers.try_into().map_err(|_| SimError::InvalidConfig("finger count".to_owned()))?;

        let object_body = world.bodies.insert(
            RigidBodyBuilder::dynamic().pose(iso_to_pose(object_pose)).can_sleep(false).ccd_enabled(false),
        );
        let object_collider = world.colliders.insert_with_parent(
            object.collider()?.collision_groups(object_groups),
            object_body,
            &mut world.bodies,
        );
        let mut this = Self {
            hand: hand.clone(),
            physics: *physics,
            world,
            fingers,
            object_body,
            object_collider,
            q_target: [0.0; NUM_JOINTS],
        };
        this.set_joint_positions(q_rad)?;
        this.set_joint_targets(q_rad);
        Ok(this)
    }

    /// The hand model the world was built from.
    #[must_use]
    pub fn hand(&self) -> &HandModel {
        &self.hand
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

    /// Joint angles (rad), finger-major, read from the multibodies.
    #[must_use]
    pub fn joint_positions(&self) -> [f32; NUM_JOINTS] {
        let mut q = [0.0; NUM_JOINTS];
        for (i, f) in self.fingers.iter().enumerate() {
            for (j, h) in f.joints.iter().enumerate() {
                if let Some((mb, link)) = self.world.multibody_joints.get(*h)
                    && let Some(l) = mb.link(link)
                {
                    q[joint_index(i, j)] = l.joint.coords()[3];
                }
            }
        }
        q
    }

    /// Joint velocities (rad/s), finger-major.
    #[must_use]
    pub fn joint_velocities(&self) -> [f32; NUM_JOINTS] {
        let mut dq = [0.0; NUM_JOINTS];
        for (i, f) in self.fingers.iter().enumerate() {
            if let Some((mb, _)) = self.world.multibody_joints.get(f.joints[0]) {
                let v = mb.generalized_velocity();
                for j in 0..JOINTS_PER_FINGER.min(v.len()) {
                    dq[joint_index(i, j)] = v[j];
                }
            }
        }
        dq
    }

    /// Teleports the joints to `q_rad` (clamped to the limits) with zero joint velocity,
    /// and moves the link bodies accordingly. Non-finite entries are rejected.
    pub fn set_joint_positions(&mut self, q_rad: &[f32; NUM_JOINTS]) -> Result<(), SimError> {
        if let Some(index) = q_rad.iter().position(|v| !v.is_finite()) {
            return Err(SimError::NonFiniteAction { index, value: q_rad[index] });
        }
        let limits = self.hand.joint_limits();
        let current = self.joint_positions();
        for (i, f) in self.fingers.iter().enumerate() {
            let Some((mb, _)) = self.world.multibody_joints.get_mut(f.joints[0]) else { continue };
            // Turns the root's provisional free joint into the fixed one first, so the
            // multibody has exactly the three finger DOFs.
            mb.forward_kinematics(&self.world.bodies, true);
            if mb.ndofs() != JOINTS_PER_FINGER {
                return Err(SimError::InvalidConfig(format!("finger {i}: {} DOFs", mb.ndofs())));
            }
            let disp: [f32; JOINTS_PER_FINGER] = std::array::from_fn(|j| {
                let k = joint_index(i, j);
                limits[k].clamp(q_rad[k]) - current[k]
            });
            mb.apply_displacements(&disp);
            mb.generalized_velocity_mut().fill(0.0);
            mb.forward_kinematics(&self.world.bodies, false);
            mb.update_rigid_bodies(&mut self.world.bodies, true);
            for h in f.links {
                if let Some(rb) = self.world.bodies.get_mut(h) {
                    rb.set_linvel(Vector::ZERO, true);
                    rb.set_angvel(Vector::ZERO, true);
                }
            }
        }
        Ok(())
    }

    /// Current joint targets (rad).
    #[must_use]
    pub fn joint_targets(&self) -> &[f32; NUM_JOINTS] {
        &self.q_target
    }

    /// Sets the motor targets; entries are clamped to the joint limits (NaN is replaced
    /// by the current target, but callers validate first).
    pub fn set_joint_targets(&mut self, q_target_rad: &[f32; NUM_JOINTS]) {
        let limits = self.hand.joint_limits();
        let kp = self.physics.motor_stiffness_nm_per_rad;
        let kd = self.physics.motor_damping_nms_per_rad;
        for (i, f) in self.fingers.iter().enumerate() {
            for (j, h) in f.joints.iter().enumerate() {
                let k = joint_index(i, j);
                let v = q_target_rad[k];
                let target = if v.is_finite() { limits[k].clamp(v) } else { self.q_target[k] };
                self.q_target[k] = target;
                if let Some((mb, link)) = self.world.multibody_joints.get_mut(*h)
                    && let Some(l) = mb.link_mut(link)
                {
                    l.joint.data.set_motor_position(JointAxis::AngX, target, kp, kd);
                }
            }
        }
    }

    /// World pose of link body `link` (0 roll, 1 proximal, 2 distal) of `finger`: equals
    /// the kinematics frame `link + 1`.
    pub fn link_pose(&self, finger: usize, link: usize) -> Result<Isometry3<f32>, SimError> {
        let f = self.hand.finger(finger)?;
        let _ = f;
        let h = *self.fingers[finger]
            .links
            .get(link)
            .ok_or_else(|| SimError::InvalidConfig(format!("link index {link}")))?;
        Ok(self.world.bodies.get(h).map(|rb| pose_to_iso(rb.position())).unwrap_or_else(Isometry3::identity))
    }

    /// World position of the fingertip sphere centre of `finger`, read from rapier.
    pub fn fingertip_position_m(&self, finger: usize) -> Result<Vector3<f32>, SimError> {
        let dist = self.link_pose(finger, 2)?;
        let len = self.hand.finger(finger)?.distal_length_m;
        Ok((dist * nalgebra::Point3::new(0.0, 0.0, -len)).coords)
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

    /// Contact of each fingertip sphere with the object (`None` when not touching:
    /// zero normal impulse in the last step).
    #[must_use]
    pub fn fingertip_contacts(&self) -> [Option<ContactReading>; NUM_FINGERS] {
        std::array::from_fn(|i| self.pair_reading(self.fingers[i].tip))
    }

    /// Contacts of the link capsules (proximal, distal) of each finger with the object;
    /// these carry load too at large roll angles.
    #[must_use]
    pub fn link_contacts(&self) -> [[Option<ContactReading>; 2]; NUM_FINGERS] {
        std::array::from_fn(|i| std::array::from_fn(|k| self.pair_reading(self.fingers[i].link_colliders[k])))
    }

    /// Whether any position, rotation or velocity in the world is non-finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.world
            .bodies
            .iter()
            .all(|(_, rb)| rb.position().is_finite() && rb.linvel().is_finite() && rb.angvel().is_finite())
    }

    /// Signed distance (m, negative when penetrating) between the fingertip sphere of
    /// `finger` at joint angles `q` and the object at its current pose; used to close the
    /// fingers geometrically. Also checks the distal link capsule, returning the smaller.
    pub fn finger_object_distance_m(
        &self,
        finger: usize,
        q: &[f32; JOINTS_PER_FINGER],
    ) -> Result<f32, SimError> {
        let f = self.hand.finger(finger)?;
        let frames = f.frames(q)?;
        let obj = self.world.colliders.get(self.object_collider).ok_or(SimError::NotReset)?;
        let obj_pose = *obj.position();
        let dist_pose = iso_to_pose(&frames[3]);
        let tip_pose = dist_pose * Pose::from_translation(Vector::new(0.0, 0.0, -f.distal_length_m));
        let ball = rapier3d::parry::shape::Ball::new(f.tip_radius_m);
        let half = 0.5 * f.distal_length_m;
        let capsule = rapier3d::parry::shape::Capsule::new_z(half, f.link_radius_m);
        let cap_pose = dist_pose * Pose::from_translation(Vector::new(0.0, 0.0, -half));
        let d = |pose: &Pose, shape: &dyn rapier3d::parry::shape::Shape| -> Result<f32, SimError> {
            match rapier3d::parry::query::contact(pose, shape, &obj_pose, obj.shape(), 0.0) {
                Ok(Some(c)) => Ok(c.dist),
                Ok(None) => rapier3d::parry::query::distance(pose, shape, &obj_pose, obj.shape())
                    .map(|d| d.distance)
                    .map_err(|e| SimError::InvalidConfig(format!("distance query: {e:?}"))),
                Err(e) => Err(SimError::InvalidConfig(format!("contact query: {e:?}"))),
            }
        };
        Ok(d(&tip_pose, &ball)?.min(d(&cap_pose, &capsule)?))
    }
}
