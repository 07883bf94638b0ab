//! The hand, its object and a held grasp as a MuJoCo model (MJCF), written from the same
//! [`HandModel`] and [`PhysicsConfig`] the rapier world is built from.
//!
//! Why: `scripts/bench-vs-mujoco.sh` compares the simulator's speed with MuJoCo's on "the same hand, grasp and
//! contact readout". A hand-written MJCF would be a second copy of the geometry that could
//! drift; this one is generated, and `scripts/bench-vs-mujoco.sh` times both in one run.
//!
//! What carries over: link frames, lengths and radii, joint axes, limits and torque caps,
//! the roll link's point mass, link density, friction, gravity, the object's shape, size and
//! mass, position motors with the same stiffness and damping, the hand's orientation to
//! gravity, hand-object collisions only (and finger-finger ones when the world has them),
//! and a keyframe of a settled grasp (joint angles, motor targets, object pose) taken from
//! the rapier world. What cannot: contact softness and the solver. MuJoCo keeps its default
//! contact softness and solver at the `timestep_s` the caller picks, with elliptic friction
//! cones and `impratio` 10, its advice for grasping: with its default pyramidal cones the
//! cube settles 5 mm lower and the bench's target changes drop it more often (54 against 35
//! episode ends in 2,000 control steps at 240 Hz).
//!
//! Angles are radians throughout (`<compiler angle="radian">`): MJCF reads hinge `range` in
//! degrees by default, which turned the flexion limits -0.3..1.6 rad into -0.3..1.6 deg, so
//! every flexed joint of the grasp sat 0.24 rad past its limit and the limit constraint, not
//! the fingertips, took the motor torque (thumb: 0.45 N*m of motor against a 0.25 N*m limit
//! force; 6.5 N of fingertip normal force in all, against rapier's 17.6 N).
//!
//! One addition rapier does not have: joint `armature` kp*dt^2/4 (rotor inertia). MuJoCo
//! integrates the position motor's stiffness explicitly (only velocity terms are implicit),
//! and explicit integration of a spring kp on an inertia I is stable only while
//! sqrt(kp/I)*dt < 2, i.e. I > kp*dt^2/4; the light finger links (distal ~2.7e-5 kg*m^2) are
//! below that at 240 Hz (8.7e-5), and the held cube then shakes (about 2 rad/s) and drops at
//! the first target change. rapier solves its motors as implicit constraints and needs no
//! such inertia. The armature is that stability bound, not a fitted value, and vanishes as
//! `timestep_s` goes to 0.

use std::fmt::Write as _;

use nalgebra::{Isometry3, UnitQuaternion};

use crate::error::SimError;
use crate::kinematics::{HandModel, JOINT_NAMES};
use crate::objects::{ObjectConfig, ObjectShape};
use crate::world::{HandWorld, JointServo, PhysicsConfig};

/// A held grasp to start MuJoCo from (the rapier world's state after `Env::reset`).
#[derive(Debug, Clone, PartialEq)]
pub struct GraspKeyframe {
    /// Joint angles (rad), finger-major.
    pub q_rad: Vec<f32>,
    /// Motor targets (rad), finger-major.
    pub q_target_rad: Vec<f32>,
    /// Object pose (world).
    pub object_pose: Isometry3<f32>,
}

impl GraspKeyframe {
    /// The current state of `world`.
    #[must_use]
    pub fn of(world: &HandWorld) -> Self {
        Self {
            q_rad: world.joint_positions(),
            q_target_rad: world.joint_targets().to_vec(),
            object_pose: world.object_state().pose,
        }
    }
}

/// What MuJoCo needs beyond the hand: physics, object, time step.
#[derive(Debug, Clone, PartialEq)]
pub struct MjcfSettings<'a> {
    /// The hand (geometry, limits, torque caps).
    pub hand: &'a HandModel,
    /// Its servos (stiffness and damping; the caps are the hand's).
    pub servos: &'a [JointServo],
    /// Physics parameters (gravity, motors, density, friction).
    pub physics: &'a PhysicsConfig,
    /// The object (cube, sphere or cylinder: MuJoCo has no convex hulls without meshes).
    pub object: &'a ObjectConfig,
    /// MuJoCo's time step (s).
    pub timestep_s: f32,
}

fn pos(iso: &Isometry3<f32>) -> String {
    let t = iso.translation.vector;
    format!("{} {} {}", t.x, t.y, t.z)
}

fn quat(q: &UnitQuaternion<f32>) -> String {
    format!("{} {} {} {}", q.w, q.i, q.j, q.k)
}

/// The MJCF document: one fixed base body per finger (as in the rapier world), the object
/// on a free joint, one position actuator per joint, and the keyframe `grasp`.
pub fn hand_mjcf(settings: &MjcfSettings<'_>, grasp: &GraspKeyframe) -> Result<String, SimError> {
    let MjcfSettings { hand, servos, physics, object, timestep_s } = *settings;
    let Some(servo) = servos.first() else {
        return Err(SimError::InvalidConfig("no servos".to_owned()));
    };
    let (kp, kv) = (servo.kp_nm_per_rad, servo.kv_nms_per_rad);
    if grasp.q_rad.len() != hand.joint_limits().len() || grasp.q_target_rad.len() != grasp.q_rad.len() {
        return Err(SimError::ActionLength { got: grasp.q_rad.len(), expected: hand.joint_limits().len() });
    }
    if !(timestep_s.is_finite() && timestep_s > 0.0) {
        return Err(SimError::InvalidConfig(format!("MuJoCo time step {timestep_s} s")));
    }
    physics.validate()?;
    object.validate()?;
    let half = 0.5 * object.width_m;
    let object_geom = match object.shape {
        ObjectShape::Cube => format!(r#"type="box" size="{half} {half} {half}""#),
        ObjectShape::Sphere => format!(r#"type="sphere" size="{half}""#),
        ObjectShape::Cylinder => format!(r#"type="cylinder" size="{half} {half}""#),
        other => {
            return Err(SimError::InvalidConfig(format!(
                "no MJCF for the {other}: MuJoCo needs a mesh for convex hulls (cube, sphere, cylinder)"
            )));
        }
    };
    let friction = physics.finger_friction;
    // The smallest joint inertia at which MuJoCo's explicit motor spring is stable (module docs).
    let armature = kp * timestep_s * timestep_s / 4.0;
    // contype/conaffinity: the hand touches the object (and, with `finger_collisions`, other
    // fingers: MuJoCo skips parent-child pairs, as rapier's joints do), as rapier's groups.
    let hand_affinity = if physics.finger_collisions { 3 } else { 2 };
    let gravity = physics.gravity_m_per_s2_vector();
    let mut xml = String::new();
    let w = &mut xml;
    // Writing into a String cannot fail; the results are discarded with `let _`.
    let _ = writeln!(w, r#"<mujoco model="vge-hand">"#);
    // Radians: MJCF's default reads hinge ranges in degrees (module docs).
    let _ = writeln!(w, r#"  <compiler angle="radian"/>"#);
    let _ = writeln!(
        w,
        r#"  <option timestep="{timestep_s}" gravity="{} {} {}" integrator="implicitfast" cone="elliptic" impratio="10"/>"#,
        gravity.x, gravity.y, gravity.z
    );
    let _ = writeln!(
        w,
        r#"  <default><geom contype="1" conaffinity="{hand_affinity}" friction="{friction} 0.005 0.0001"/></default>"#
    );
    let _ = writeln!(w, "  <worldbody>");
    for (i, finger) in hand.fingers.iter().enumerate() {
        let base = &finger.base_in_world;
        let (lp, ld) = (finger.proximal_length_m, finger.distal_length_m);
        let (rl, rt) = (finger.link_radius_m, finger.tip_radius_m);
        let density = physics.link_density_kg_per_m3;
        let joint = |j: usize, axis: &str| {
            let l = finger.joint_limits[j];
            format!(
                r#"<joint name="f{i}_{}" type="hinge" axis="{axis}" limited="true" range="{} {}" armature="{armature}"/>"#,
                JOINT_NAMES[j], l.lower_rad, l.upper_rad
            )
        };
        let _ =
            writeln!(w, r#"    <body name="f{i}_base" pos="{}" quat="{}">"#, pos(base), quat(&base.rotation));
        let _ = writeln!(w, r#"      <body name="f{i}_roll">"#);
        let _ = writeln!(w, r#"        {}"#, joint(0, "1 0 0"));
        let _ = writeln!(w, r#"        <inertial pos="0 0 0" mass="0.005" diaginertia="1e-6 1e-6 1e-6"/>"#);
        let _ = writeln!(w, r#"        <body name="f{i}_prox">"#);
        let _ = writeln!(w, r#"          {}"#, joint(1, "0 1 0"));
        let _ = writeln!(
            w,
            r#"          <geom type="capsule" fromto="0 0 0 0 0 {}" size="{rl}" density="{density}"/>"#,
            -lp
        );
        let _ = writeln!(w, r#"          <body name="f{i}_dist" pos="0 0 {}">"#, -lp);
        let _ = writeln!(w, r#"            {}"#, joint(2, "0 1 0"));
        let _ = writeln!(
            w,
            r#"            <geom type="capsule" fromto="0 0 0 0 0 {}" size="{rl}" density="{density}"/>"#,
            -ld
        );
        let _ = writeln!(
            w,
            r#"            <geom name="f{i}_tip" type="sphere" pos="0 0 {}" size="{rt}" density="{density}"/>"#,
            -ld
        );
        let _ = writeln!(w, "          </body>\n        </body>\n      </body>\n    </body>");
    }
    let o = &grasp.object_pose;
    let _ = writeln!(w, r#"    <body name="object" pos="{}" quat="{}">"#, pos(o), quat(&o.rotation));
    let _ = writeln!(w, r#"      <freejoint name="object"/>"#);
    let _ = writeln!(
        w,
        r#"      <geom name="object" {object_geom} mass="{}" contype="2" conaffinity="1" friction="{} 0.005 0.0001"/>"#,
        object.mass_kg, object.friction
    );
    let _ = writeln!(w, "    </body>\n  </worldbody>\n  <actuator>");
    for (i, finger) in hand.fingers.iter().enumerate() {
        for ((name, l), cap) in JOINT_NAMES.iter().zip(finger.joint_limits).zip(finger.torque_caps_nm) {
            let _ = writeln!(
                w,
                r#"    <position name="f{i}_{name}" joint="f{i}_{name}" kp="{}" kv="{}" ctrllimited="true" ctrlrange="{} {}" forcelimited="true" forcerange="{} {cap}"/>"#,
                kp, kv, l.lower_rad, l.upper_rad, -cap,
            );
        }
    }
    let _ = writeln!(w, "  </actuator>");
    let joints = |v: &[f32]| v.iter().map(f32::to_string).collect::<Vec<_>>().join(" ");
    let r = o.rotation;
    let _ = writeln!(
        w,
        r#"  <keyframe><key name="grasp" qpos="{} {} {} {} {} {} {} {}" ctrl="{}"/></keyframe>"#,
        joints(&grasp.q_rad),
        o.translation.vector.x,
        o.translation.vector.y,
        o.translation.vector.z,
        r.w,
        r.i,
        r.j,
        r.k,
        joints(&grasp.q_target_rad)
    );
    let _ = writeln!(w, "</mujoco>");
    Ok(xml)
}

/// The MJCF of `env`'s task, with the grasp that `Env::reset(seed)` settles as keyframe
/// `grasp` (the state `vge bench sim` starts its first world from, for seed 0).
pub fn settled_grasp_mjcf(
    env: &crate::env::EnvConfig,
    seed: u64,
    timestep_s: f32,
) -> Result<String, SimError> {
    if env.hand.name() != "vge15" {
        return Err(SimError::InvalidConfig(format!(
            "the MuJoCo benchmark's model is written for vge15 only, not {}",
            env.hand.name()
        )));
    }
    let mut sim = crate::env::Env::new(env.clone())?;
    sim.reset(seed)?;
    let world = sim.world().ok_or_else(|| SimError::InvalidConfig("no world after reset".to_owned()))?;
    let mut hand = HandModel::default();
    if let Some(smallest) = env.servos.iter().map(|s| s.torque_cap_nm).reduce(f32::min) {
        hand.set_finger_torque_cap_nm(smallest);
    }
    let settings = MjcfSettings {
        hand: &hand,
        servos: &env.servos,
        physics: &env.physics,
        object: &env.object,
        timestep_s,
    };
    hand_mjcf(&settings, &GraspKeyframe::of(world))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::env::EnvConfig;

    #[test]
    fn the_model_has_every_joint_actuator_and_the_settled_grasp_as_keyframe() {
        let env = EnvConfig::default();
        let xml = settled_grasp_mjcf(&env, 0, 1.0 / 240.0).unwrap();
        assert_eq!(xml.matches(r#"type="hinge""#).count(), 15);
        assert_eq!(xml.matches("<position ").count(), 15);
        assert_eq!(xml.matches(r#"type="sphere""#).count(), 5, "one fingertip per finger");
        // The keyframe holds 15 joint angles and the object's 7 pose numbers, then 15 targets.
        let key = xml.lines().find(|l| l.contains("<key ")).unwrap();
        let attr = |name: &str| -> Vec<f32> {
            let start = key.find(&format!(r#"{name}=""#)).unwrap() + name.len() + 2;
            let end = start + key[start..].find('"').unwrap();
            key[start..end].split(' ').map(|v| v.parse().unwrap()).collect()
        };
        let (qpos, ctrl) = (attr("qpos"), attr("ctrl"));
        assert_eq!((qpos.len(), ctrl.len()), (15 + 7, 15));
        // A settled grasp: fingers flexed onto the object, targets squeezed past the angles.
        let mut sim = crate::env::Env::new(env.clone()).unwrap();
        sim.reset(0).unwrap();
        let world = sim.world().unwrap();
        assert_eq!(&qpos[..15], &world.joint_positions()[..]);
        assert_eq!(&ctrl[..], world.joint_targets());
        assert!(qpos[1] > 0.1, "thumb flexed: {}", qpos[1]);
        assert!(ctrl[1] > qpos[1], "squeezed past contact");
        // Joint ranges are radians (MJCF's default unit is degrees), and hold the grasp.
        assert!(xml.contains(r#"<compiler angle="radian"/>"#));
        assert!(xml.contains(r#"range="-0.3 1.6""#));
        assert!(qpos[..15].iter().zip(&env.servos).all(|(q, s)| s.limit.contains(*q)));
    }

    #[test]
    fn shapes_mujoco_cannot_build_without_a_mesh_are_refused() {
        let env = EnvConfig { object: ObjectConfig::of(ObjectShape::Dodecahedron), ..EnvConfig::default() };
        let err = settled_grasp_mjcf(&env, 0, 1.0 / 240.0).unwrap_err();
        assert!(err.to_string().contains("dodecahedron"), "{err}");
        let env = EnvConfig::default();
        assert!(settled_grasp_mjcf(&env, 0, 0.0).is_err());
    }
}
