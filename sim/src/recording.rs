//! Episodes recorded as JSON Lines files: what `vge eval --record` and
//! `vge-bridge run --record` write, and what the Python package turns into a Rerun
//! recording (`python -m vge.recording F.jsonl --spawn`, or `-o F.rrd`, with
//! `pip install rerun-sdk`).
//!
//! The file is the episode's data, not a viewer's format: the Rerun SDK for Rust is a build
//! twice the size of the rest of vge (its Arrow and gRPC stack), while the Python SDK comes
//! prebuilt, so vge writes the data and Python draws it ([`FORMAT`] version [`VERSION`]).
//!
//! The first line is the header: `format`, `version`, `control_dt_s`, `force_arrow_m_per_n`,
//! `hand` (its name), `fingers` (per finger: `name`, `joints`: its links' indices),
//! `link_geoms` (per link, the collision geoms of the body its joint moves, in that body's
//! frame: `shape` `sphere`/`capsule`/`cylinder`/`box`, `size_m` as MuJoCo's `size`, `pose`)
//! and `object` (`shape`, `width_m`, and for the polyhedra the collider's
//! hull as `mesh_vertices_m` and `mesh_triangles`). Then one line per control step, the
//! state after it (world frame: z up, SI units, poses as `[x, y, z, qx, qy, qz, qw]`):
//!
//! - `step` (control steps since the reset, 1 for the state after the first action) and
//!   `sim_time_s`;
//! - `links`: the poses of the bodies the hand's joints move, in joint order;
//! - `object`: the object's pose;
//! - `fingertip_contacts`, `link_contacts`: `{finger, point_m, normal_force_n}` per contact
//!   with the object, the force on the object as a vector (N);
//! - `action_rad`: the step's joint-target changes (one per joint): the policy's output in `vge eval`,
//!   the change the bridge commanded (after its safety filter) in `vge-bridge`;
//! - `reward`: the step's reward; `rotation_about_z_rad`: the object's rotation about world
//!   z since the reset (what the success test measures).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use nalgebra::Isometry3;
use serde::Serialize;
use thiserror::Error;

use crate::env::{Env, EnvConfig, StepResult};
use crate::error::SimError;
use crate::objects::{ObjectConfig, ObjectShape};
use crate::world::{ContactReading, HandWorld};

/// The header's `format`.
pub const FORMAT: &str = "vge episode";
/// The header's `version`; a reader refuses another.
pub const VERSION: u32 = 2;

/// Length of a contact-force arrow per newton of force (m/N) in the viewer: a grip of a few
/// newtons draws arrows of a few centimetres beside the 10 cm cube.
pub const FORCE_ARROW_M_PER_N: f32 = 0.01;

#[derive(Debug, Error)]
pub enum RecordingError {
    #[error("recording to {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("recording to {path}: {source}")]
    Encode { path: PathBuf, source: serde_json::Error },
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("object shape: {0}")]
    Shape(String),
    #[error("the env has not been reset: nothing to record")]
    NotReset,
    #[error(
        "{0}: a recording is vge's episode file (JSON Lines), not a Rerun .rrd: name it F.jsonl, then \
         `python -m vge.recording F.jsonl --spawn` shows it (or `-o F.rrd` converts it)"
    )]
    RrdPath(PathBuf),
}

#[derive(Serialize)]
struct Header<'a> {
    format: &'static str,
    version: u32,
    control_dt_s: f64,
    force_arrow_m_per_n: f32,
    hand: &'a str,
    fingers: Vec<FingerHeader<'a>>,
    link_geoms: Vec<Vec<GeomHeader>>,
    object: ObjectHeader,
}

#[derive(Serialize)]
struct FingerHeader<'a> {
    name: &'a str,
    joints: Vec<usize>,
}

#[derive(Serialize)]
struct GeomHeader {
    shape: &'static str,
    size_m: Vec<f32>,
    pose: [f32; 7],
}

/// The collision geoms of the body joint `joint` moves, for drawing.
fn link_geoms(hand: &vge_hand::Hand, joint: usize) -> Vec<GeomHeader> {
    use vge_hand::GeomShape;
    let Some(body) = hand.joints().get(joint).and_then(|j| hand.bodies().get(j.body)) else {
        return Vec::new();
    };
    body.geoms
        .iter()
        .filter(|g| g.collides())
        .filter_map(|g| {
            let (shape, size_m) = match &g.shape {
                GeomShape::Sphere { radius_m } => ("sphere", vec![*radius_m]),
                GeomShape::Capsule { radius_m, half_length_m } => {
                    ("capsule", vec![*radius_m, *half_length_m])
                }
                GeomShape::Cylinder { radius_m, half_length_m } => {
                    ("cylinder", vec![*radius_m, *half_length_m])
                }
                GeomShape::Box { half_extents_m } => ("box", half_extents_m.iter().copied().collect()),
                GeomShape::VisualMesh { .. } => return None,
            };
            Some(GeomHeader { shape, size_m, pose: pose7(&g.pose_in_body) })
        })
        .collect()
}

#[derive(Serialize)]
struct ObjectHeader {
    shape: String,
    width_m: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    mesh_vertices_m: Option<Vec<[f32; 3]>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mesh_triangles: Option<Vec<[u32; 3]>>,
}

#[derive(Serialize)]
struct StepRow<'a> {
    step: u64,
    sim_time_s: f64,
    links: Vec<[f32; 7]>,
    object: [f32; 7],
    fingertip_contacts: Vec<ContactRow>,
    link_contacts: Vec<ContactRow>,
    action_rad: &'a [f32],
    reward: f32,
    rotation_about_z_rad: f64,
}

#[derive(Serialize)]
struct ContactRow {
    finger: usize,
    point_m: [f32; 3],
    normal_force_n: [f32; 3],
}

/// Writes one episode to a JSON Lines file, a control step at a time.
#[derive(Debug)]
pub struct EpisodeRecorder {
    out: BufWriter<File>,
    path: PathBuf,
    control_dt_s: f64,
    rotation_rad: f64,
    steps: u64,
}

impl EpisodeRecorder {
    /// Creates (or truncates) `path` and writes the header: the rates and the shapes of the
    /// links and the object of `config`.
    pub fn create(path: &Path, config: &EnvConfig) -> Result<Self, RecordingError> {
        check_path(path)?;
        let file =
            File::create(path).map_err(|source| RecordingError::Io { path: path.to_owned(), source })?;
        // In f64 from the rates: f32's control period (0.050000001 s) adds up over an episode.
        let control_dt_s = config.physics_steps_per_control() as f64 / f64::from(config.physics.physics_hz);
        let mut recorder = Self {
            out: BufWriter::new(file),
            path: path.to_owned(),
            control_dt_s,
            rotation_rad: 0.0,
            steps: 0,
        };
        let header = Header {
            format: FORMAT,
            version: VERSION,
            control_dt_s,
            force_arrow_m_per_n: FORCE_ARROW_M_PER_N,
            hand: config.hand.name(),
            fingers: config
                .hand
                .fingers()
                .iter()
                .map(|f| FingerHeader { name: &f.name, joints: f.joints.clone().collect() })
                .collect(),
            link_geoms: (0..config.hand.num_joints()).map(|j| link_geoms(&config.hand, j)).collect(),
            object: object_header(&config.object)?,
        };
        recorder.write_line(&header)?;
        Ok(recorder)
    }

    fn write_line<T: Serialize>(&mut self, row: &T) -> Result<(), RecordingError> {
        serde_json::to_writer(&mut self.out, row)
            .map_err(|source| RecordingError::Encode { path: self.path.clone(), source })?;
        self.out.write_all(b"\n").map_err(|source| RecordingError::Io { path: self.path.clone(), source })
    }

    /// Writes the state after a control step of `env`: poses, contacts, the `action` the
    /// policy asked for and the step's reward.
    pub fn record_step(
        &mut self,
        env: &Env,
        action: &[f32],
        result: &StepResult,
    ) -> Result<(), RecordingError> {
        let world = env.world().ok_or(RecordingError::NotReset)?;
        let step = result.info.step as u64;
        self.rotation_rad += f64::from(result.info.object_rotation_z_rad);
        let joints = env.config().hand.num_joints();
        let mut links = Vec::with_capacity(joints);
        for joint in 0..joints {
            links.push(pose7(&world.link_pose(joint)?));
        }
        let (fingertip_contacts, link_contacts) = contacts(world);
        let row = StepRow {
            step,
            sim_time_s: step as f64 * self.control_dt_s,
            links,
            object: pose7(&world.object_state().pose),
            fingertip_contacts,
            link_contacts,
            action_rad: action,
            reward: result.reward,
            rotation_about_z_rad: self.rotation_rad,
        };
        self.write_line(&row)?;
        self.steps += 1;
        Ok(())
    }

    /// Writes everything to the file and syncs it (the file is complete only then); returns
    /// the number of steps recorded.
    pub fn finish(self) -> Result<u64, RecordingError> {
        let path = self.path;
        let file = self
            .out
            .into_inner()
            .map_err(|e| RecordingError::Io { path: path.clone(), source: e.into_error() })?;
        file.sync_all().map_err(|source| RecordingError::Io { path, source })?;
        Ok(self.steps)
    }
}

/// Refuses a path ending in `.rrd`: that name promises a file for the viewer itself, and a
/// user who asks for one learns here how to get it.
pub fn check_path(path: &Path) -> Result<(), RecordingError> {
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("rrd")) {
        return Err(RecordingError::RrdPath(path.to_owned()));
    }
    Ok(())
}

/// The fingertip and the link contacts with the object.
fn contacts(world: &HandWorld) -> (Vec<ContactRow>, Vec<ContactRow>) {
    let row = |finger: usize, c: &ContactReading| ContactRow {
        finger,
        point_m: c.position_m.into(),
        normal_force_n: (c.normal * c.normal_force_n).into(),
    };
    let tips =
        world.fingertip_contacts().iter().enumerate().filter_map(|(f, c)| c.map(|c| row(f, &c))).collect();
    let links = world
        .link_contacts()
        .iter()
        .enumerate()
        .flat_map(|(f, pair)| pair.iter().flatten().map(move |c| row(f, c)))
        .collect();
    (tips, links)
}

fn pose7(pose: &Isometry3<f32>) -> [f32; 7] {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
}

/// The object's shape in its body frame, as its collider has it.
fn object_header(object: &ObjectConfig) -> Result<ObjectHeader, RecordingError> {
    let mut header = ObjectHeader {
        shape: object.shape.to_string(),
        width_m: object.width_m,
        mesh_vertices_m: None,
        mesh_triangles: None,
    };
    match object.shape {
        // Drawn from `width_m` alone (the cylinder stands on its axis, world z).
        ObjectShape::Cube | ObjectShape::Sphere | ObjectShape::Cylinder => {}
        ObjectShape::Dodecahedron | ObjectShape::Icosahedron | ObjectShape::HexagonalPrism => {
            let shape = object.shape().map_err(|e| RecordingError::Shape(e.to_string()))?;
            let hull = shape
                .as_convex_polyhedron()
                .ok_or_else(|| RecordingError::Shape(format!("{} is not a convex hull", object.shape)))?;
            let (vertices, triangles) = hull.to_trimesh();
            header.mesh_vertices_m = Some(vertices.iter().map(|v| [v.x, v.y, v.z]).collect());
            header.mesh_triangles = Some(triangles);
        }
    }
    Ok(header)
}
