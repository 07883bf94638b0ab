//! The hand as read: bodies, joints, geoms, fingers, in MuJoCo's order. Plain data with public
//! fields, `f32` as the simulator uses; [`crate::Hand`] keeps them consistent (indices in
//! range, parents before children, each finger's joints contiguous).

use std::ops::Range;

use nalgebra::{Isometry3, Matrix3, Unit, Vector3};

/// Range of motion of a hinge joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimit {
    /// Smallest allowed angle (rad).
    pub lower_rad: f32,
    /// Largest allowed angle (rad).
    pub upper_rad: f32,
}

impl JointLimit {
    /// Whether `q_rad` lies within the closed range.
    #[must_use]
    pub fn contains(&self, q_rad: f32) -> bool {
        (self.lower_rad..=self.upper_rad).contains(&q_rad)
    }

    /// `q_rad` clamped into the range (NaN stays NaN).
    #[must_use]
    pub fn clamp(&self, q_rad: f32) -> f32 {
        q_rad.clamp(self.lower_rad, self.upper_rad)
    }
}

/// A position servo on one joint (MJCF `<position>`, or a `<general>` that is exactly one):
/// torque = kp (target - q) - kv q', the target clamped to `ctrl_range_rad` and the torque to
/// `force_range_nm` where given.
#[derive(Debug, Clone, PartialEq)]
pub struct PositionServo {
    /// The actuator's name, if it has one.
    pub name: Option<String>,
    /// Stiffness (N m / rad).
    pub kp_nm_per_rad: f32,
    /// Damping on the joint velocity (N m s / rad).
    pub kv_nms_per_rad: f32,
    /// Torque cap `[lower, upper]` (N m); `None`: unlimited.
    pub force_range_nm: Option<[f32; 2]>,
    /// Target range `[lower, upper]` (rad); `None`: unlimited. MuJoCo does not convert
    /// `ctrlrange` from degrees, so this is the file's number as written.
    pub ctrl_range_rad: Option<[f32; 2]>,
}

/// A hinge joint. Its axis and anchor are in the frame of its body (MuJoCo's `jnt_axis`,
/// `jnt_pos`); the body turns about that axis through that anchor by q.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// The joint's name (required in the subset: it names the joint-vector entry).
    pub name: String,
    /// Index of the body it moves, in [`crate::Hand::bodies`].
    pub body: usize,
    /// Unit axis in the body frame.
    pub axis_in_body: Unit<Vector3<f32>>,
    /// Anchor in the body frame (m).
    pub pos_in_body_m: Vector3<f32>,
    /// Range of motion; `None`: unlimited.
    pub limit: Option<JointLimit>,
    /// Viscous damping (N m s / rad).
    pub damping_nms_per_rad: f32,
    /// Rotor inertia added to the joint (kg m^2).
    pub armature_kg_m2: f32,
    /// Dry friction torque (N m).
    pub frictionloss_nm: f32,
    /// The position servo that drives it, if any.
    pub servo: Option<PositionServo>,
}

/// A geom's shape, in its own frame (MuJoCo's conventions: capsules and cylinders along +z).
#[derive(Debug, Clone, PartialEq)]
pub enum GeomShape {
    /// A sphere about the frame origin.
    Sphere {
        /// Radius (m).
        radius_m: f32,
    },
    /// A capsule: a segment of `2 * half_length_m` along z, swept by a sphere.
    Capsule {
        /// Radius (m).
        radius_m: f32,
        /// Half the segment's length (m).
        half_length_m: f32,
    },
    /// A cylinder along z.
    Cylinder {
        /// Radius (m).
        radius_m: f32,
        /// Half its height (m).
        half_length_m: f32,
    },
    /// A box.
    Box {
        /// Half extents along x, y, z (m).
        half_extents_m: Vector3<f32>,
    },
    /// A mesh that never collides (contype and conaffinity 0): kept as a name only, for
    /// drawing. Its file is never opened.
    VisualMesh {
        /// The mesh asset's name.
        mesh: String,
    },
}

/// How a geom's mass is given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GeomMass {
    /// An explicit mass (kg).
    Kg(f32),
    /// A density (kg / m^3), the mass being density times volume.
    DensityKgPerM3(f32),
}

/// A geom of a body.
#[derive(Debug, Clone, PartialEq)]
pub struct Geom {
    /// Its name, if it has one.
    pub name: Option<String>,
    /// Its shape.
    pub shape: GeomShape,
    /// Its frame in its body's frame.
    pub pose_in_body: Isometry3<f32>,
    /// MuJoCo's contact type bits.
    pub contype: u32,
    /// MuJoCo's contact affinity bits: two geoms may touch when either's contype shares a bit
    /// with the other's conaffinity.
    pub conaffinity: u32,
    /// Sliding, torsional and rolling friction.
    pub friction: [f32; 3],
    /// MuJoCo's contact dimensionality: 1 frictionless, 3 sliding friction (the default), 4
    /// and torsional, 6 and rolling.
    pub condim: u8,
    /// Its mass or density.
    pub mass: GeomMass,
    /// MuJoCo's visualisation group (groups 0..=5 add to the body's mass).
    pub group: i32,
}

impl Geom {
    /// Whether it can touch anything (contype or conaffinity non-zero).
    #[must_use]
    pub fn collides(&self) -> bool {
        self.contype != 0 || self.conaffinity != 0
    }
}

/// Mass, centre of mass and inertia of a body, in its frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    /// Mass (kg).
    pub mass_kg: f32,
    /// Centre of mass in the body frame (m).
    pub com_in_body_m: Vector3<f32>,
    /// Inertia tensor about the centre of mass, axes of the body frame (kg m^2).
    pub inertia_kg_m2: Matrix3<f32>,
}

/// A body of the tree. Body 0 is the world, as in MuJoCo.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    /// Its name (`world` for body 0; `None` for an unnamed body).
    pub name: Option<String>,
    /// Its parent's index; `None` for the world. Parents come before their children.
    pub parent: Option<usize>,
    /// Its frame in its parent's frame at q = 0.
    pub pose_in_parent: Isometry3<f32>,
    /// Its joints (indices into [`crate::Hand::joints`]), applied in order; empty when the
    /// body is welded to its parent. The subset's fingers have one joint per body, but MJCF
    /// allows several and the kinematics follow MuJoCo for them.
    pub joints: Range<usize>,
    /// Its geoms, collision and visual.
    pub geoms: Vec<Geom>,
    /// The `<inertial>` written in the file, if any.
    pub inertial: Option<Inertial>,
    /// The mass properties MuJoCo compiles: the `<inertial>` or, where the compiler's
    /// `inertiafromgeom` says so, the sum over its geoms (groups 0..=5). Zero mass for a body
    /// with neither.
    pub mass_properties: Inertial,
}

/// A site: a named point (and frame) on a body, with no physics.
#[derive(Debug, Clone, PartialEq)]
pub struct Site {
    /// Its name, if it has one.
    pub name: Option<String>,
    /// Its body's index.
    pub body: usize,
    /// Its frame in the body frame.
    pub pose_in_body: Isometry3<f32>,
}

/// A finger: the joints on the path from the root to its fingertip, and the fingertip.
#[derive(Debug, Clone, PartialEq)]
pub struct Finger {
    /// Its name (from the TOML's `finger_names`, else the fingertip's name).
    pub name: String,
    /// The fingertip's name as given (a site's or a body's).
    pub tip_name: String,
    /// Its joints, a contiguous range of the joint vector.
    pub joints: Range<usize>,
    /// The body that carries the fingertip.
    pub tip_body: usize,
    /// The fingertip point in that body's frame (m): the site's position, or the origin for
    /// a fingertip named by its body.
    pub tip_offset_in_body_m: Vector3<f32>,
    /// The fingertip's geom: the tip body's colliding sphere or capsule nearest the fingertip
    /// point (its index in that body's geoms), if it has one.
    pub tip_geom: Option<usize>,
    /// Radius of that geom (m).
    pub tip_radius_m: Option<f32>,
}

/// A pair of bodies whose contacts are excluded (`<contact><exclude>`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ContactExclude {
    /// First body's index.
    pub body1: usize,
    /// Second body's index.
    pub body2: usize,
}

/// A keyframe (`<keyframe><key>`): joint angles only; its `ctrl` and `time` are not carried.
#[derive(Debug, Clone, PartialEq)]
pub struct Keyframe {
    /// Its name, if it has one.
    pub name: Option<String>,
    /// Joint angles in joint-vector order (rad): MuJoCo's qpos, zero where not given.
    pub qpos_rad: Vec<f32>,
}

/// The global physics settings of `<option>` that are not MuJoCo's solver: `None` where the
/// file leaves MuJoCo's default (gravity 0 0 -9.81, time step 0.002 s).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PhysicsOptions {
    /// Gravity in the world frame (m/s^2).
    pub gravity_m_per_s2: Option<Vector3<f32>>,
    /// MuJoCo's time step (s).
    pub timestep_s: Option<f32>,
}
