//! Episodes recorded as Rerun `.rrd` files (feature `rerun`): what `vge eval --record` and
//! `vge-bridge run --record` write, opened with the Rerun viewer (`rerun F.rrd`, from
//! `pip install rerun-sdk==0.36.3`, the version of the `rerun` crate that writes them).
//!
//! One row per control step, on two timelines: `step` (control steps since the reset, 1 for
//! the state after the first action) and `sim_time` (s). The wall clock is left out: it says
//! nothing about a simulated episode. Entities (world frame: z up, SI units):
//!
//! - `world/hand/<finger>/<link>` (`roll`, `proximal`, `distal`): the link body's pose, as a
//!   transform; the proximal and distal links carry their capsules (static, in the link's
//!   frame) and `.../distal/tip` the fingertip sphere.
//! - `world/object`: the object's pose, as a transform, and its shape (static).
//! - `world/contacts/fingertip_points`, `world/contacts/link_points`: contact points of the
//!   fingertip spheres and of the link capsules with the object, labelled by finger.
//! - `world/contacts/fingertip_normal_force_1cm_per_N`, `..._link_normal_force_1cm_per_N`:
//!   the normal force on the object at each contact point, as arrows of 1 cm per newton
//!   ([`FORCE_ARROW_M_PER_N`]).
//! - `action/<finger>/<joint>_rad`: the step's 15 joint-target changes: the policy's output
//!   in `vge eval`, the change the bridge commanded (after its safety filter) in `vge-bridge`.
//! - `reward_rad_per_s`: the step's reward; `object_rotation_about_z_rad`: the object's
//!   rotation about world z since the reset (what the success test measures).

use std::path::Path;
use std::time::Duration;

use nalgebra::{Isometry3, Vector3};
use rerun::log::ChunkBatcherConfig;
use rerun::{
    Arrows3D, Boxes3D, Capsules3D, Color, Cylinders3D, Ellipsoids3D, Mesh3D, Points3D, Quaternion,
    RecordingStream, RecordingStreamBuilder, Scalars, Transform3D, ViewCoordinates,
};
use thiserror::Error;

use crate::env::{Env, EnvConfig, StepResult};
use crate::error::SimError;
use crate::kinematics::{FINGER_NAMES, JOINT_NAMES, JOINTS_PER_FINGER, NUM_FINGERS, NUM_JOINTS, joint_index};
use crate::objects::{ObjectConfig, ObjectShape};
use crate::world::{ContactReading, HandWorld};

/// Length of a contact-force arrow per newton of force (m/N): a grip of a few newtons draws
/// arrows of a few centimetres beside the 10 cm cube.
pub const FORCE_ARROW_M_PER_N: f32 = 0.01;

/// The object's grey.
const OBJECT_RGB: rerun::datatypes::Rgba32 = rerun::datatypes::Rgba32::from_rgb(190, 190, 190);

/// The link bodies of a finger, in [`HandWorld::link_pose`]'s order.
const LINK_NAMES: [&str; JOINTS_PER_FINGER] = ["roll", "proximal", "distal"];

/// One colour per finger, so that contacts tell which finger made them.
const FINGER_COLORS: [[u8; 3]; NUM_FINGERS] =
    [[230, 85, 13], [49, 130, 189], [49, 163, 84], [117, 107, 177], [214, 39, 40]];

#[derive(Debug, Error)]
pub enum RecordingError {
    #[error("recording to {path}: {source}")]
    Create { path: String, source: rerun::RecordingStreamError },
    #[error("logging to the recording: {0}")]
    Log(#[from] rerun::RecordingStreamError),
    #[error("writing the recording: {0}")]
    Flush(#[from] rerun::sink::SinkFlushError),
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("object shape: {0}")]
    Shape(String),
    #[error("the env has not been reset: nothing to record")]
    NotReset,
}

/// Writes one episode to an `.rrd` file, a control step at a time.
#[derive(Debug)]
pub struct EpisodeRecorder {
    rec: RecordingStream,
    control_dt_s: f64,
    rotation_rad: f64,
    steps: u64,
}

impl EpisodeRecorder {
    /// Creates (or truncates) `path` and logs what does not change over the episode: the
    /// view's axes and the shapes of the links and the object of `config`.
    pub fn create(path: &Path, config: &EnvConfig) -> Result<Self, RecordingError> {
        let rec = RecordingStreamBuilder::new("vge")
            // Explicitly on: a `RERUN=off` in the environment must not leave the file asked for
            // unwritten.
            .enabled(true)
            // Rows are batched into chunks every 200 ms by default: 4 steps a chunk at the
            // bridge's real-time 20 Hz, and 2 s of it took 726 KB instead of 216 KB. Nobody
            // watches this file live, so chunks wait for 10 s or 2 MiB.
            .batcher_config(ChunkBatcherConfig {
                flush_tick: Duration::from_secs(10),
                ..ChunkBatcherConfig::DEFAULT
            })
            .save(path)
            .map_err(|source| RecordingError::Create { path: path.display().to_string(), source })?;
        rec.set_log_time_enabled(false);
        // In f64 from the rates: f32's control period (0.050000001 s) adds up over an episode.
        let control_dt_s = config.physics_steps_per_control() as f64 / f64::from(config.physics.physics_hz);
        let recorder = Self { rec, control_dt_s, rotation_rad: 0.0, steps: 0 };
        recorder.log_geometry(config)?;
        Ok(recorder)
    }

    fn log_geometry(&self, config: &EnvConfig) -> Result<(), RecordingError> {
        self.rec.log_static("world", &ViewCoordinates::RIGHT_HAND_Z_UP())?;
        for (f, finger) in config.hand.fingers.iter().enumerate() {
            let color = finger_color(f);
            // Links point along their frame's -z; a capsule runs from its origin along +z.
            for (link, length_m) in [(1, finger.proximal_length_m), (2, finger.distal_length_m)] {
                let capsule = Capsules3D::from_lengths_and_radii([length_m], [finger.link_radius_m])
                    .with_translations([[0.0, 0.0, -length_m]])
                    .with_colors([color]);
                self.rec.log_static(link_path(f, link), &capsule)?;
            }
            let tip = Ellipsoids3D::from_centers_and_radii(
                [[0.0, 0.0, -finger.distal_length_m]],
                [finger.tip_radius_m],
            )
            .with_colors([color]);
            self.rec.log_static(format!("{}/tip", link_path(f, 2)), &tip)?;
        }
        log_object_shape(&self.rec, &config.object)
    }

    /// Logs the state after a control step of `env`: poses, contacts, the `action` the policy
    /// asked for and the step's reward.
    pub fn record_step(
        &mut self,
        env: &Env,
        action: &[f32; NUM_JOINTS],
        result: &StepResult,
    ) -> Result<(), RecordingError> {
        let world = env.world().ok_or(RecordingError::NotReset)?;
        let step = result.info.step as u64;
        self.rec.set_time_sequence("step", i64::try_from(step).unwrap_or(i64::MAX));
        self.rec.set_duration_secs("sim_time", step as f64 * self.control_dt_s);
        self.log_hand(world)?;
        let object = world.object_state().pose;
        self.rec.log("world/object", &transform(&object))?;
        self.log_contacts(world)?;
        for (f, finger) in FINGER_NAMES.iter().enumerate() {
            for (j, joint) in JOINT_NAMES.iter().enumerate() {
                let a = action[joint_index(f, j)];
                self.rec.log(format!("action/{finger}/{joint}_rad"), &Scalars::single(f64::from(a)))?;
            }
        }
        self.rec.log("reward_rad_per_s", &Scalars::single(f64::from(result.reward)))?;
        self.rotation_rad += f64::from(result.info.object_rotation_z_rad);
        self.rec.log("object_rotation_about_z_rad", &Scalars::single(self.rotation_rad))?;
        self.steps += 1;
        Ok(())
    }

    fn log_hand(&self, world: &HandWorld) -> Result<(), RecordingError> {
        for f in 0..NUM_FINGERS {
            for link in 0..JOINTS_PER_FINGER {
                let pose = world.link_pose(f, link)?;
                self.rec.log(link_path(f, link), &transform(&pose))?;
            }
        }
        Ok(())
    }

    fn log_contacts(&self, world: &HandWorld) -> Result<(), RecordingError> {
        let tips: Vec<(usize, ContactReading)> =
            world.fingertip_contacts().iter().enumerate().filter_map(|(f, c)| c.map(|c| (f, c))).collect();
        let links: Vec<(usize, ContactReading)> = world
            .link_contacts()
            .iter()
            .enumerate()
            .flat_map(|(f, pair)| pair.iter().flatten().map(move |c| (f, *c)))
            .collect();
        for (kind, contacts) in [("fingertip", &tips), ("link", &links)] {
            // Logged every step, empty when nothing touches: the viewer shows the latest
            // value, so a contact that ended must be cleared, not left standing.
            let points: Vec<[f32; 3]> = contacts.iter().map(|(_, c)| xyz(&c.position_m)).collect();
            let colors: Vec<Color> = contacts.iter().map(|(f, _)| finger_color(*f)).collect();
            let labels: Vec<&str> = contacts.iter().map(|(f, _)| FINGER_NAMES[*f]).collect();
            let forces: Vec<[f32; 3]> = contacts
                .iter()
                .map(|(_, c)| xyz(&(c.normal * (c.normal_force_n * FORCE_ARROW_M_PER_N))))
                .collect();
            self.rec.log(
                format!("world/contacts/{kind}_points"),
                &Points3D::new(points.clone())
                    .with_radii([0.003])
                    .with_colors(colors.clone())
                    .with_labels(labels),
            )?;
            self.rec.log(
                format!("world/contacts/{kind}_normal_force_1cm_per_N"),
                &Arrows3D::from_vectors(forces).with_origins(points).with_colors(colors),
            )?;
        }
        Ok(())
    }

    /// Writes everything logged to the file and closes it (the file is complete only then);
    /// returns the number of steps recorded.
    pub fn finish(self) -> Result<u64, RecordingError> {
        self.rec.flush_blocking()?;
        // Dropping the last handle joins the writer, which ends the file with its footer.
        Ok(self.steps)
    }
}

fn link_path(finger: usize, link: usize) -> String {
    format!("world/hand/{}/{}", FINGER_NAMES[finger], LINK_NAMES[link])
}

fn finger_color(finger: usize) -> Color {
    let [r, g, b] = FINGER_COLORS[finger % NUM_FINGERS];
    Color::from_rgb(r, g, b)
}

fn xyz(v: &Vector3<f32>) -> [f32; 3] {
    [v.x, v.y, v.z]
}

fn transform(pose: &Isometry3<f32>) -> Transform3D {
    let q = pose.rotation.quaternion();
    Transform3D::from_translation_rotation(
        xyz(&pose.translation.vector),
        Quaternion::from_xyzw([q.i, q.j, q.k, q.w]),
    )
}

/// The object's shape in its body frame, as its collider has it.
fn log_object_shape(rec: &RecordingStream, object: &ObjectConfig) -> Result<(), RecordingError> {
    let half = 0.5 * object.width_m;
    let color = Color::from(OBJECT_RGB);
    match object.shape {
        ObjectShape::Cube => {
            rec.log_static("world/object", &Boxes3D::from_half_sizes([[half; 3]]).with_colors([color]))?
        }
        ObjectShape::Sphere => rec.log_static(
            "world/object",
            &Ellipsoids3D::from_centers_and_radii([[0.0; 3]], [half]).with_colors([color]),
        )?,
        // The collider's cylinder stands on its axis, world z, as Rerun's does.
        ObjectShape::Cylinder => rec.log_static(
            "world/object",
            &Cylinders3D::from_lengths_and_radii([object.width_m], [half]).with_colors([color]),
        )?,
        ObjectShape::Dodecahedron | ObjectShape::Icosahedron | ObjectShape::HexagonalPrism => {
            let shape = object.shape().map_err(|e| RecordingError::Shape(e.to_string()))?;
            let hull = shape
                .as_convex_polyhedron()
                .ok_or_else(|| RecordingError::Shape(format!("{} is not a convex hull", object.shape)))?;
            let (vertices, triangles) = hull.to_trimesh();
            let vertices: Vec<[f32; 3]> = vertices.iter().map(|v| [v.x, v.y, v.z]).collect();
            rec.log_static(
                "world/object",
                &Mesh3D::new(vertices).with_triangle_indices(triangles).with_albedo_factor(OBJECT_RGB),
            )?;
        }
    }
    Ok(())
}
