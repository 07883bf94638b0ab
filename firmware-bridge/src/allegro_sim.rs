//! The simulated Allegro Hand as the emulator's plant: vge-sim's world of `hands/allegro.xml`
//! holding its 65 mm cube, driven by joint torques at 1 kHz.
//!
//! The hand powers up at its start grasp with its servos off, so its joints are limp; the cube
//! sits on a stand (held fixed) until the hand grips it: once the servos are on and at least
//! three fingertips have touched the cube for [`SimAllegroConfig::grip_ms`], the stand is
//! taken away. From then on the summary says how well the cube is held: how far it fell, moved
//! and turned since, measured when the servos go off (a limp hand drops it) or at the end;
//! and, as the env accounts for an episode, how far it turned about z (summed at the env's
//! 20 Hz), the fingertips' contact switches (`vge_sim::gait`) and whether it fell by the env's
//! drop height.

use thiserror::Error;
use vge_sim::gait::ContactSwitches;
use vge_sim::{HandWorld, JointServo, ObjectConfig, ObjectShape, ObjectState, PhysicsConfig};

use crate::allegro_emulator::AllegroPlant;
use crate::protocol::allegro::NUM_JOINTS;

#[derive(Debug, Error)]
pub enum SimAllegroError {
    #[error("building the simulated Allegro: {0}")]
    Build(String),
}

/// The simulated hand's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimAllegroConfig {
    /// Physics steps per second: 1 kHz, a whole number of steps in the hand's 3 ms period.
    pub physics_hz: f32,
    /// How long three fingertips must touch the cube, servos on, before the stand goes.
    pub grip_ms: u64,
    /// The cube (the size the Allegro's start grasp is laid out for).
    pub object: ObjectConfig,
    /// How often the turn about z and the contacts are sampled (ms): the env's control period,
    /// so that contact switches count as the env counts them.
    pub sample_ms: u64,
    /// A cube sunk this far below where it was released is dropped (m): the env's drop height.
    pub drop_height_m: f32,
}

impl Default for SimAllegroConfig {
    fn default() -> Self {
        Self {
            physics_hz: 1000.0,
            grip_ms: 200,
            object: ObjectConfig { shape: ObjectShape::Cube, width_m: 0.065, mass_kg: 0.1, friction: 0.8 },
            sample_ms: 50,
            drop_height_m: 0.03,
        }
    }
}

/// How the cube fared from its release to a moment (the servos going off, or the end).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HoldSummary {
    /// Simulated seconds from the release to the moment.
    pub held_s: f64,
    /// How far the cube sank (m).
    pub fell_m: f32,
    /// How far its centre moved (m).
    pub moved_m: f32,
    /// How far it turned (rad).
    pub turned_rad: f32,
    /// Fingertips touching it at the moment.
    pub tips_touching: usize,
    /// Its turn about z, summed over the samples (rad, the reward's sense).
    pub rotation_z_rad: f32,
    /// How far the axis it turned about overall leans from z (rad, 0 to π/2; the samples'
    /// rotation vectors summed, [`vge_sim::angle::rotation_axis_tilt_rad`]).
    pub rotation_axis_tilt_rad: f32,
    /// Fingertips that let go and touched again ([`ContactSwitches`], sampled).
    pub contact_switches: u32,
    /// Whether it sank by the drop height at some sample.
    pub dropped: bool,
}

/// What the samples since the release have gathered.
#[derive(Debug, Clone)]
struct Episode {
    /// The cube at the last sample.
    last: ObjectState,
    rotation_z_rad: f32,
    /// Each sample's world-frame rotation vector, summed.
    net_rotation_rad: [f64; 3],
    switches: ContactSwitches,
    dropped: bool,
}

/// The simulated Allegro and its cube.
pub struct SimAllegro {
    world: HandWorld,
    config: SimAllegroConfig,
    steps_per_ms: u32,
    applied: Option<(bool, [f32; NUM_JOINTS])>,
    grip_ms: u64,
    sim_ms: u64,
    /// When the stand went (ms) and the cube's position and rotation then.
    released: Option<(u64, [f32; 3], [f32; 4])>,
    episode: Option<Episode>,
    /// The hold when the servos first went off after the release.
    at_servo_off: Option<HoldSummary>,
    was_on: bool,
    q_rad: [f32; NUM_JOINTS],
}

impl std::fmt::Debug for SimAllegro {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimAllegro").field("sim_ms", &self.sim_ms).field("released", &self.released).finish()
    }
}

impl SimAllegro {
    pub fn new(config: SimAllegroConfig) -> Result<Self, SimAllegroError> {
        let build = |e: String| SimAllegroError::Build(e);
        let hand = vge_sim::hands::load("allegro").map_err(|e| build(e.to_string()))?;
        let servos = JointServo::from_description(&hand).map_err(|e| build(e.to_string()))?;
        let q = hand.start_grasp_rad().ok_or_else(|| build("the hand has no start grasp".to_owned()))?;
        let steps_per_ms = config.physics_hz / 1000.0;
        if steps_per_ms < 1.0 || steps_per_ms.fract() != 0.0 {
            return Err(build(format!("physics rate {} Hz is not a whole number of kHz", config.physics_hz)));
        }
        let physics = PhysicsConfig { physics_hz: config.physics_hz, ..PhysicsConfig::default() };
        let mut world = HandWorld::new(&hand, &servos, &physics, &config.object, &q, &Default::default())
            .map_err(|e| build(e.to_string()))?;
        world.set_object_fixed(true);
        world.set_joint_torques(&[0.0; NUM_JOINTS]).map_err(|e| build(e.to_string()))?;
        let q_rad = read_q(&world);
        Ok(Self {
            world,
            config,
            steps_per_ms: steps_per_ms as u32,
            applied: Some((false, [0.0; NUM_JOINTS])),
            grip_ms: 0,
            sim_ms: 0,
            released: None,
            episode: None,
            at_servo_off: None,
            was_on: false,
            q_rad,
        })
    }

    /// Whether the stand is gone.
    pub fn released(&self) -> bool {
        self.released.is_some()
    }

    /// The hold when the servos first went off after the release, else now; `None` before the
    /// release.
    pub fn hold(&self) -> Option<HoldSummary> {
        self.at_servo_off.or_else(|| self.hold_now())
    }

    fn tips_touching(&self) -> usize {
        self.world.fingertip_contacts().iter().filter(|c| c.is_some()).count()
    }

    fn touching(&self) -> Vec<bool> {
        self.world.fingertip_contacts().iter().map(Option::is_some).collect()
    }

    /// One sample of the episode: the turn since the last, the contacts, the drop.
    fn sample(&mut self) {
        let now = self.world.object_state();
        let touching = self.touching();
        let fell_m = self.released.map_or(0.0, |(_, p0, _)| p0[2] - now.pose.translation.vector.z);
        let drop_height_m = self.config.drop_height_m;
        if let Some(e) = &mut self.episode {
            e.rotation_z_rad += vge_sim::rotation_about_z_rad(&e.last.pose.rotation, &now.pose.rotation);
            let turn = vge_sim::angle::rotation_vector_rad(&e.last.pose.rotation, &now.pose.rotation);
            for (sum, v) in e.net_rotation_rad.iter_mut().zip(turn) {
                *sum += f64::from(v);
            }
            e.last = now;
            e.switches.update(&touching);
            e.dropped |= fell_m >= drop_height_m;
        }
    }

    fn hold_now(&self) -> Option<HoldSummary> {
        let (at_ms, p0, r0) = self.released?;
        let pose = self.world.object_state().pose;
        let p = pose.translation.vector;
        let moved = ((p.x - p0[0]).powi(2) + (p.y - p0[1]).powi(2) + (p.z - p0[2]).powi(2)).sqrt();
        let q = pose.rotation.quaternion().coords;
        // The angle between two unit quaternions: 2 acos |<a, b>|.
        let dot = (q.x * r0[0] + q.y * r0[1] + q.z * r0[2] + q.w * r0[3]).abs().min(1.0);
        let episode = self.episode.as_ref();
        Some(HoldSummary {
            held_s: (self.sim_ms - at_ms) as f64 / 1000.0,
            fell_m: p0[2] - p.z,
            moved_m: moved,
            turned_rad: 2.0 * dot.acos(),
            tips_touching: self.tips_touching(),
            rotation_z_rad: episode.map_or(0.0, |e| e.rotation_z_rad),
            rotation_axis_tilt_rad: episode
                .map_or(0.0, |e| vge_sim::angle::rotation_axis_tilt_rad(e.net_rotation_rad) as f32),
            contact_switches: episode.map_or(0, |e| e.switches.count),
            dropped: episode.is_some_and(|e| e.dropped),
        })
    }

    /// Whether the world is still finite (a blown-up world reports nothing sensible).
    pub fn is_finite(&self) -> bool {
        self.world.is_finite()
    }
}

fn read_q(world: &HandWorld) -> [f32; NUM_JOINTS] {
    let mut q = [0.0; NUM_JOINTS];
    for (v, w) in q.iter_mut().zip(world.joint_positions()) {
        *v = w;
    }
    q
}

impl AllegroPlant for SimAllegro {
    fn step(&mut self, servo_on: bool, tau_nm: &[f32; NUM_JOINTS], ms: u32) {
        let drive = if servo_on { *tau_nm } else { [0.0; NUM_JOINTS] };
        if self.applied != Some((servo_on, drive)) {
            // Non-finite torques never come from the protocol's decoder; were they to, the
            // joints keep the previous ones.
            if self.world.set_joint_torques(&drive).is_ok() {
                self.applied = Some((servo_on, drive));
            }
        }
        if self.was_on && !servo_on && self.at_servo_off.is_none() {
            self.at_servo_off = self.hold_now();
        }
        self.was_on = servo_on;
        for _ in 0..ms {
            for _ in 0..self.steps_per_ms {
                self.world.step();
            }
            self.sim_ms += 1;
            if self.released.is_none() {
                self.grip_ms = if servo_on && self.tips_touching() >= 3 { self.grip_ms + 1 } else { 0 };
                if self.grip_ms >= self.config.grip_ms {
                    self.world.set_object_fixed(false);
                    let pose = self.world.object_state().pose;
                    let p = pose.translation.vector;
                    let r = pose.rotation.quaternion().coords;
                    self.released = Some((self.sim_ms, [p.x, p.y, p.z], [r.x, r.y, r.z, r.w]));
                    self.episode = Some(Episode {
                        last: self.world.object_state(),
                        rotation_z_rad: 0.0,
                        net_rotation_rad: [0.0; 3],
                        switches: ContactSwitches::new(&self.touching()),
                        dropped: false,
                    });
                }
            } else if self.config.sample_ms > 0 && self.sim_ms.is_multiple_of(self.config.sample_ms) {
                self.sample();
            }
        }
        self.q_rad = read_q(&self.world);
    }

    fn q_rad(&self) -> [f32; NUM_JOINTS] {
        self.q_rad
    }
}
