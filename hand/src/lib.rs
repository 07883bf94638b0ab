//! A hand as a file: an MJCF file (MuJoCo's XML) in vge's subset, plus an optional TOML beside
//! it, read into a [`Hand`]: its bodies, hinge joints, position servos, collision geoms and
//! fingers, and its kinematics (fingertip positions and Jacobians, like MuJoCo's).
//!
//! # Files
//! `hands/vge15.xml` is read with `hands/vge15.toml` if that exists (same stem). The TOML is
//! short, and every key is optional:
//! ```toml
//! fingertips = ["thumb.tip", "index.tip"]   # site or body names, in finger order
//! finger_names = ["thumb", "index"]         # default: the fingertip names
//! palm = "palm"                             # a body name
//! start_grasp = "grasp"                     # a keyframe name
//! object_width_m = 0.065                    # the object the hand is sized for: a cube's side
//! object_mass_kg = 0.1                      # and its mass (both or neither)
//! ```
//! Without `fingertips` (or without a TOML), the fingertips are the sites whose name starts with
//! [`FINGERTIP_SITE_PREFIX`] (`fingertip`), in file order; a hand with neither is refused. No
//! other name is guessed.
//!
//! # The subset, read with MuJoCo's semantics
//! - `<compiler>`: `angle` (MuJoCo's default is degree), `eulerseq`, `autolimits` (default true:
//!   a joint or actuator range makes it limited), `inertiafromgeom`.
//! - `<default>` classes, nested (the root class is `main`), for `joint`, `geom`, `site`,
//!   `position` and `general`; `class=` on elements and `childclass=` on bodies, inherited by
//!   the body's descendants. Attributes a class leaves out keep MuJoCo's defaults; `size` and
//!   `friction` are read partially as MuJoCo does.
//! - `<worldbody>`: bodies with `pos` and one orientation among `quat` (w x y z, normalised),
//!   `axisangle`, `euler` (with `eulerseq`: lowercase turns about the axes of the frame as
//!   turned so far, uppercase about the fixed parent axes), `xyaxes` and `zaxis`;
//!   `<inertial>` (`diaginertia` or `fullinertia`); hinge joints (`pos`, `axis`, `range`,
//!   `limited`, `damping`, `armature`, `frictionloss`); geoms of type sphere, capsule, box and
//!   cylinder (`size` or `fromto`, `contype`, `conaffinity`, `condim`, `friction`, `density`,
//!   `mass`, `group`); mesh geoms that never collide (contype and conaffinity 0), kept as names
//!   for drawing; sites.
//! - `<actuator>`: `<position>` servos on joints (`kp`, `kv`, `ctrlrange`, `forcerange`,
//!   `inheritrange`, and their `*limited`), and `<general>` actuators that are exactly such a
//!   servo. A class may set `position` or `general` values, not both (MuJoCo merges the two).
//! - `<contact><exclude>`, `<keyframe><key qpos>`, `<option gravity timestep>`.
//!
//! Skipped, as they do not change the physics: `asset`, `visual`, `statistic`, `size`,
//! `sensor`, `custom`, cameras, lights, and the drawing attributes (`material`, `rgba`, a
//! site's type and size). Read and deliberately not carried: MuJoCo's solver settings in
//! `<option>` (integrator, cone, iterations, tolerances) and the contact and constraint
//! softness of geoms and joints (`solref`, `solimp`, `margin`, `gap`, `priority`, `solmix`):
//! they describe MuJoCo's solver, which a simulator built from the hand does not have. A
//! keyframe's `ctrl` and `time` are checked and not carried.
//!
//! # Refused
//! Anything else that would change the physics is refused with a [`HandError`] naming the file,
//! the line, the element and its name: tendons, equality constraints (also how MJCF writes
//! mimic joints), ball, slide and free joints, `include`, actuators other than position servos,
//! `frame`, `composite`, `flexcomp`, plugins, meshes that collide (their files are never
//! opened), a mesh whose mass MuJoCo would take from the file, other geom types, joint springs,
//! `ref`, and any element or attribute the reader does not know. A refusal is better than a
//! hand that silently moves differently from the file.
//!
//! # Fingers and the joint vector
//! A finger is the set of joints on the path from the root to its fingertip's body. Every hinge
//! joint must be on exactly one finger's path (a joint shared by two fingers, such as a wrist,
//! or on none is refused), which with MuJoCo's depth-first numbering makes each finger's joints
//! contiguous; the fingers must be listed in the order of their joints. The joint vector is
//! then MuJoCo's qpos of a hand-only model (file order) and finger-major.
//!
//! # Frames and units
//! The world frame is the MJCF world frame; a joint's axis and anchor are in its body's frame,
//! as MuJoCo stores them; angles are radians (the compiler's degrees are converted, except in
//! `ctrlrange`, which MuJoCo leaves as written); lengths are metres, torques N m. The model is
//! stored in `f32`; the kinematics are generic over [`nalgebra::RealField`].

mod error;
mod geometry;
mod kinematics;
mod mjcf;
mod model;
mod spec;

use std::io::Read as _;
use std::path::Path;

use sha2::{Digest, Sha256};

pub use error::{HandError, Location};
pub use model::{
    Body, ContactExclude, Finger, Geom, GeomMass, GeomShape, Inertial, Joint, JointLimit, Keyframe,
    PhysicsOptions, PositionServo, Site,
};
pub use spec::{FINGERTIP_SITE_PREFIX, NominalObject};

/// The largest hand file (XML or TOML) read: Menagerie's hand files are tens of kilobytes.
pub const MAX_FILE_BYTES: u64 = 4 << 20;

/// A hand read from its description. Immutable; built by [`Hand::load`] or [`Hand::from_strs`].
#[derive(Debug, Clone, PartialEq)]
pub struct Hand {
    name: String,
    description_sha256: [u8; 32],
    bodies: Vec<Body>,
    joints: Vec<Joint>,
    sites: Vec<Site>,
    fingers: Vec<Finger>,
    contact_excludes: Vec<ContactExclude>,
    keyframes: Vec<Keyframe>,
    options: PhysicsOptions,
    palm: Option<usize>,
    start_grasp: Option<usize>,
    nominal_object: Option<NominalObject>,
}

/// Reads a regular file of at most [`MAX_FILE_BYTES`]; `Ok(None)` if it does not exist and
/// `optional`.
fn read_limited(path: &Path, optional: bool) -> Result<Option<String>, HandError> {
    let shown = || path.display().to_string();
    // Checked before opening, as opening a named pipe would wait for a writer.
    match std::fs::metadata(path) {
        Ok(meta) if !meta.is_file() => return Err(HandError::NotAFile { path: shown() }),
        Err(e) if optional && e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(HandError::Io { path: shown(), source }),
        Ok(_) => {}
    }
    let file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if optional && e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(HandError::Io { path: shown(), source }),
    };
    // And the opened file's, so that what is checked is what is read.
    let meta = file.metadata().map_err(|source| HandError::Io { path: shown(), source })?;
    if !meta.is_file() {
        return Err(HandError::NotAFile { path: shown() });
    }
    if meta.len() > MAX_FILE_BYTES {
        return Err(HandError::TooLarge {
            path: shown(),
            len_bytes: meta.len(),
            limit_bytes: MAX_FILE_BYTES,
        });
    }
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|source| HandError::Io { path: shown(), source })?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        let len_bytes = bytes.len() as u64;
        return Err(HandError::TooLarge { path: shown(), len_bytes, limit_bytes: MAX_FILE_BYTES });
    }
    String::from_utf8(bytes).map(Some).map_err(|e| HandError::Io {
        path: shown(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()),
    })
}

impl Hand {
    /// Reads the MJCF file at `path` and the TOML beside it (same stem, `.toml`) if there is one.
    /// Each must be a regular file of at most [`MAX_FILE_BYTES`].
    pub fn load(path: impl AsRef<Path>) -> Result<Self, HandError> {
        let path = path.as_ref();
        let xml = read_limited(path, false)?.unwrap_or_default();
        let toml_path = path.with_extension("toml");
        let toml = read_limited(&toml_path, true)?;
        let stem = path.file_stem().map_or_else(|| "hand".to_owned(), |s| s.to_string_lossy().into_owned());
        Self::build(
            &xml,
            toml.as_deref(),
            &stem,
            &path.display().to_string(),
            &toml_path.display().to_string(),
        )
    }

    /// A hand from its texts: `name_hint` names it when `<mujoco>` has no `model`, and names
    /// the files in errors (`{name_hint}.xml`, `{name_hint}.toml`).
    pub fn from_strs(xml: &str, toml: Option<&str>, name_hint: &str) -> Result<Self, HandError> {
        Self::build(xml, toml, name_hint, &format!("{name_hint}.xml"), &format!("{name_hint}.toml"))
    }

    fn build(
        xml: &str,
        toml: Option<&str>,
        stem: &str,
        xml_file: &str,
        toml_file: &str,
    ) -> Result<Self, HandError> {
        let parsed = mjcf::parse(xml, xml_file)?;
        let spec = toml.map(|t| spec::Spec::parse(t, toml_file)).transpose()?.unwrap_or_default();
        let resolved = spec::resolve(&parsed, &spec, toml_file, xml_file)?;
        let mut hasher = Sha256::new();
        hasher.update(xml.as_bytes());
        hasher.update(toml.unwrap_or_default().as_bytes());
        Ok(Self {
            name: parsed.model_name.clone().unwrap_or_else(|| stem.to_owned()),
            description_sha256: hasher.finalize().into(),
            bodies: parsed.bodies,
            joints: parsed.joints,
            sites: parsed.sites,
            fingers: resolved.fingers,
            contact_excludes: parsed.excludes,
            keyframes: parsed.keyframes,
            options: parsed.options,
            palm: resolved.palm,
            start_grasp: resolved.start_grasp,
            nominal_object: resolved.nominal_object,
        })
    }

    /// `<mujoco model="...">`, else the file's stem (or the name hint).
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// SHA-256 of the XML's bytes followed by the TOML's (none without a TOML): what a run
    /// records to say which hand it used.
    #[must_use]
    pub fn description_sha256(&self) -> [u8; 32] {
        self.description_sha256
    }

    /// Number of hinge joints: the joint vector's length.
    #[must_use]
    pub fn num_joints(&self) -> usize {
        self.joints.len()
    }

    /// Number of fingers.
    #[must_use]
    pub fn num_fingers(&self) -> usize {
        self.fingers.len()
    }

    /// The joints, in joint-vector (MuJoCo qpos) order.
    #[must_use]
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    /// The fingers, in the TOML's order (which is joint order).
    #[must_use]
    pub fn fingers(&self) -> &[Finger] {
        &self.fingers
    }

    /// The bodies in MuJoCo's order; body 0 is the world.
    #[must_use]
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }

    /// The sites in file order.
    #[must_use]
    pub fn sites(&self) -> &[Site] {
        &self.sites
    }

    /// Body pairs whose contacts are excluded.
    #[must_use]
    pub fn contact_excludes(&self) -> &[ContactExclude] {
        &self.contact_excludes
    }

    /// The keyframes in file order.
    #[must_use]
    pub fn keyframes(&self) -> &[Keyframe] {
        &self.keyframes
    }

    /// `<option>`'s gravity and time step, where the file sets them.
    #[must_use]
    pub fn physics_options(&self) -> PhysicsOptions {
        self.options
    }

    /// The palm body's index, if the TOML names one.
    #[must_use]
    pub fn palm(&self) -> Option<usize> {
        self.palm
    }

    /// Joint angles of the start grasp (the keyframe the TOML names), if any.
    #[must_use]
    pub fn start_grasp_rad(&self) -> Option<Vec<f32>> {
        self.start_grasp.and_then(|k| self.keyframes.get(k)).map(|k| k.qpos_rad.clone())
    }

    /// The object the hand is sized for, if the TOML gives it.
    #[must_use]
    pub fn nominal_object(&self) -> Option<NominalObject> {
        self.nominal_object
    }

    /// The index of the joint named `name`.
    #[must_use]
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The index of the body named `name`.
    #[must_use]
    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name.as_deref() == Some(name))
    }
}
