//! A hand, its object and a held grasp as a MuJoCo model (MJCF), written from the same
//! [`Hand`] description, servos and [`PhysicsConfig`] the rapier world is built from.
//!
//! Why: `scripts/bench-vs-mujoco.sh` compares the simulator's speed with MuJoCo's on "the same
//! hand, grasp and contact readout". Loading the hand's own file in MuJoCo would not be that
//! model: the task changes the servos, the physics sets friction, gravity and which geoms
//! touch, and rapier leaves out what it does not simulate. This model is generated from what
//! the rapier world is built from, for any hand (vge15, the Allegro, a user's file).
//!
//! What carries over: the body tree with each body's pose at q = 0, hinge joints (axis,
//! anchor, and the servo's range), the collision geoms (spheres, capsules, cylinders, boxes:
//! visual meshes and geoms that touch nothing are left out, as rapier leaves them out), each
//! body's mass, centre of mass and inertia as an explicit `<inertial>` (the description's
//! `mass_properties`: its `<inertial>`, else what its geoms compile to, the masses the rapier
//! world gives its bodies; MuJoCo adds nothing from the geoms), the object's likewise, the
//! sites (the fingertips among them), the contact excludes, one position actuator per joint
//! with the servo's stiffness, damping, torque cap and range, gravity along the hand's
//! orientation, the object's shape, size, mass and friction, and a keyframe `grasp` of a
//! settled grasp (joint angles, motor targets, object pose) taken from the rapier world. What
//! cannot: contact softness and the solver. MuJoCo keeps its default contact softness and
//! solver at the `timestep_s` the caller picks, with elliptic friction cones and `impratio`
//! 10, its advice for grasping: with its default pyramidal cones vge15's cube settles 5 mm
//! lower and the bench's target changes drop it more often (54 against 35 episode ends in
//! 2,000 control steps at 240 Hz).
//!
//! The motor is rapier's: the servo's damping (`JointServo::from_description` adds the
//! joint's own damping to the actuator's kv) is the actuator's `kv`, and the joint gets no
//! `damping`, so that, as in rapier, the damping torque counts against the torque cap (the
//! actuator's `forcerange`) and is not counted twice. The file's joint armature and friction
//! loss are not written: rapier's joints have neither (but see the armature below).
//!
//! Contacts: rapier's groups, in MuJoCo's bits. Hand geoms have contype 1 and conaffinity 2
//! (3 with `finger_collisions`), the object contype 2 and conaffinity 1: the hand touches the
//! object, and other fingers only when the world lets them (MuJoCo skips parent-child pairs
//! itself, as rapier's joints do). Friction: rapier has one coefficient per collider, the
//! hand's `finger_friction`, combined with the object's by average; MuJoCo takes the larger
//! of two geoms' unless one has priority, so the object's geom has priority 1 and the average
//! as its coefficient (the torsional and rolling ones are MuJoCo's defaults, unused with its
//! default `condim` 3, which is written on every geom since rapier has no torsional friction).
//!
//! Angles are radians throughout (`<compiler angle="radian">`): MJCF reads hinge `range` in
//! degrees by default, which once turned vge15's flexion limits -0.3..1.6 rad into
//! -0.3..1.6 deg, so that every flexed joint of the grasp sat 0.24 rad past its limit and the
//! limit constraint, not the fingertips, took the motor torque (thumb: 0.45 N*m of motor
//! against a 0.25 N*m limit force; 6.5 N of fingertip normal force in all, against rapier's
//! 17.6 N).
//!
//! One addition rapier does not have: joint `armature` kp*dt^2/4 (rotor inertia), from each
//! joint's servo. MuJoCo integrates the position motor's stiffness explicitly (only velocity
//! terms are implicit), and explicit integration of a spring kp on an inertia I is stable only
//! while sqrt(kp/I)*dt < 2, i.e. I > kp*dt^2/4; vge15's light finger links (distal
//! ~2.7e-5 kg*m^2) are below that at 240 Hz (8.7e-5), and the held cube then shakes (about
//! 2 rad/s) and drops at the first target change. rapier solves its motors as implicit
//! constraints and needs no such inertia. The armature is that stability bound, not a fitted
//! value, and vanishes as `timestep_s` goes to 0.
//!
//! Names: bodies, joints and sites keep the description's names (an unnamed body that an
//! exclude needs is named `body{index}`), an actuator is named as its joint, and each
//! finger's fingertip geom is named `fingertip.{finger}` so that a harness finds the
//! fingertips of any hand; the object's body, free joint and geom are `object`.

use std::fmt::Write as _;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use vge_hand::{GeomShape, Hand};

use crate::error::SimError;
use crate::objects::{ObjectConfig, ObjectShape};
use crate::world::{HandWorld, JointServo, PhysicsConfig};

/// The name of the object's body, free joint and geom in the written model.
pub const OBJECT_NAME: &str = "object";

/// The prefix of the fingertip geoms' names: `fingertip.{finger}`.
pub const FINGERTIP_GEOM_PREFIX: &str = "fingertip.";

/// A held grasp to start MuJoCo from (the rapier world's state after `Env::reset`).
#[derive(Debug, Clone, PartialEq)]
pub struct GraspKeyframe {
    /// Joint angles (rad), in the hand's joint order.
    pub q_rad: Vec<f32>,
    /// Motor targets (rad), in the hand's joint order.
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

/// What the model is written from: the hand and what the task makes of it.
#[derive(Debug, Clone, PartialEq)]
pub struct MjcfSettings<'a> {
    /// The hand (bodies, joints, geoms, masses, fingers, excludes).
    pub hand: &'a Hand,
    /// Its servos, one per joint (range, stiffness, damping, torque cap).
    pub servos: &'a [JointServo],
    /// Physics parameters (gravity and orientation, friction, finger collisions).
    pub physics: &'a PhysicsConfig,
    /// The object (cube, sphere or cylinder: MuJoCo has no convex hulls without meshes).
    pub object: &'a ObjectConfig,
    /// MuJoCo's time step (s).
    pub timestep_s: f32,
}

/// `value` escaped for an XML attribute in double quotes.
fn esc(value: &str) -> String {
    let mut out = String::with_capacity(value.len());
    for c in value.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

fn vec3(v: &Vector3<f32>) -> String {
    format!("{} {} {}", v.x, v.y, v.z)
}

fn quat(q: &UnitQuaternion<f32>) -> String {
    format!("{} {} {} {}", q.w, q.i, q.j, q.k)
}

/// ` pos="..." quat="..."`, each left out where it is MuJoCo's default.
fn frame_attrs(pose: &Isometry3<f32>) -> String {
    let mut out = String::new();
    let t = pose.translation.vector;
    if t != Vector3::zeros() {
        let _ = write!(out, r#" pos="{}""#, vec3(&t));
    }
    if pose.rotation != UnitQuaternion::identity() {
        let _ = write!(out, r#" quat="{}""#, quat(&pose.rotation));
    }
    out
}

/// The MJCF `type` and `size` of a collision geom; `None` for a visual mesh.
fn geom_type_size(shape: &GeomShape) -> Option<String> {
    match shape {
        GeomShape::Sphere { radius_m } => Some(format!(r#"type="sphere" size="{radius_m}""#)),
        GeomShape::Capsule { radius_m, half_length_m } => {
            Some(format!(r#"type="capsule" size="{radius_m} {half_length_m}""#))
        }
        GeomShape::Cylinder { radius_m, half_length_m } => {
            Some(format!(r#"type="cylinder" size="{radius_m} {half_length_m}""#))
        }
        GeomShape::Box { half_extents_m } => Some(format!(r#"type="box" size="{}""#, vec3(half_extents_m))),
        GeomShape::VisualMesh { .. } => None,
    }
}

/// The object's geom type and size and its principal moments of inertia (kg m^2, uniform
/// density, as rapier computes them from the collider's mass), or why MuJoCo cannot have it.
fn object_shape_and_inertia(object: &ObjectConfig) -> Result<(String, Vector3<f32>), SimError> {
    let half = 0.5 * object.width_m;
    let m = object.mass_kg;
    match object.shape {
        ObjectShape::Cube => {
            let i = m * object.width_m * object.width_m / 6.0;
            Ok((format!(r#"type="box" size="{half} {half} {half}""#), Vector3::new(i, i, i)))
        }
        ObjectShape::Sphere => {
            let i = 0.4 * m * half * half;
            Ok((format!(r#"type="sphere" size="{half}""#), Vector3::new(i, i, i)))
        }
        ObjectShape::Cylinder => {
            // Radius `half`, height `width`, along z.
            let across = m * (3.0 * half * half + object.width_m * object.width_m) / 12.0;
            Ok((
                format!(r#"type="cylinder" size="{half} {half}""#),
                Vector3::new(across, across, 0.5 * m * half * half),
            ))
        }
        other => Err(SimError::InvalidConfig(format!(
            "no MJCF for the {other}: MuJoCo needs a mesh for convex hulls (cube, sphere, cylinder)"
        ))),
    }
}

/// Writes the hand's body tree into `xml`, given each body's name (if written) and children.
struct TreeWriter<'a> {
    hand: &'a Hand,
    servos: &'a [JointServo],
    body_names: Vec<Option<String>>,
    children: Vec<Vec<usize>>,
    /// Per body and geom: the fingertip geom's name.
    tip_geoms: Vec<(usize, usize, String)>,
    timestep_s: f32,
}

impl TreeWriter<'_> {
    /// Body `b`'s content (inertial, joints, geoms, sites, children), indented by `depth`.
    fn body_content(&self, xml: &mut String, b: usize, depth: usize) {
        let pad = "  ".repeat(depth);
        let body = &self.hand.bodies()[b];
        let m = &body.mass_properties;
        if b != 0 && m.mass_kg > 0.0 {
            let i = &m.inertia_kg_m2;
            let inertia = if i[(0, 1)] == 0.0 && i[(0, 2)] == 0.0 && i[(1, 2)] == 0.0 {
                format!(r#"diaginertia="{} {} {}""#, i[(0, 0)], i[(1, 1)], i[(2, 2)])
            } else {
                format!(
                    r#"fullinertia="{} {} {} {} {} {}""#,
                    i[(0, 0)],
                    i[(1, 1)],
                    i[(2, 2)],
                    i[(0, 1)],
                    i[(0, 2)],
                    i[(1, 2)]
                )
            };
            let _ = writeln!(
                xml,
                r#"{pad}<inertial pos="{}" mass="{}" {inertia}/>"#,
                vec3(&m.com_in_body_m),
                m.mass_kg
            );
        }
        for j in body.joints.clone() {
            let joint = &self.hand.joints()[j];
            let servo = &self.servos[j];
            // The smallest joint inertia at which MuJoCo's explicit motor spring is stable
            // (module docs).
            let armature = servo.kp_nm_per_rad * self.timestep_s * self.timestep_s / 4.0;
            let _ = writeln!(
                xml,
                r#"{pad}<joint name="{}" type="hinge" pos="{}" axis="{}" limited="true" range="{} {}" armature="{armature}"/>"#,
                esc(&joint.name),
                vec3(&joint.pos_in_body_m),
                vec3(joint.axis_in_body.as_ref()),
                servo.limit.lower_rad,
                servo.limit.upper_rad,
            );
        }
        for (g, geom) in body.geoms.iter().enumerate() {
            if !geom.collides() {
                continue;
            }
            let Some(type_size) = geom_type_size(&geom.shape) else { continue };
            let tip = self.tip_geoms.iter().find(|(tb, tg, _)| (*tb, *tg) == (b, g));
            let name = match (tip, &geom.name) {
                (Some((_, _, tip_name)), _) => format!(r#" name="{}""#, esc(tip_name)),
                (None, Some(name)) => format!(r#" name="{}""#, esc(name)),
                (None, None) => String::new(),
            };
            let _ = writeln!(xml, r#"{pad}<geom{name} {type_size}{}/>"#, frame_attrs(&geom.pose_in_body));
        }
        for site in self.hand.sites().iter().filter(|s| s.body == b) {
            let name = site.name.as_ref().map(|n| format!(r#" name="{}""#, esc(n))).unwrap_or_default();
            let _ = writeln!(xml, r#"{pad}<site{name}{}/>"#, frame_attrs(&site.pose_in_body));
        }
        for &child in &self.children[b] {
            let name =
                self.body_names[child].as_ref().map(|n| format!(r#" name="{}""#, esc(n))).unwrap_or_default();
            let pose = &self.hand.bodies()[child].pose_in_parent;
            let _ = writeln!(xml, r#"{pad}<body{name}{}>"#, frame_attrs(pose));
            self.body_content(xml, child, depth + 1);
            let _ = writeln!(xml, "{pad}</body>");
        }
    }
}

/// The MJCF document: the hand's body tree under the world (the palm and what is welded to it
/// fixed, as in the rapier world), the object on a free joint, one position actuator per
/// joint, and the keyframe `grasp`.
pub fn hand_mjcf(settings: &MjcfSettings<'_>, grasp: &GraspKeyframe) -> Result<String, SimError> {
    let MjcfSettings { hand, servos, physics, object, timestep_s } = *settings;
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
    if grasp.q_rad.len() != n {
        return Err(SimError::ActionLength { got: grasp.q_rad.len(), expected: n });
    }
    if grasp.q_target_rad.len() != n {
        return Err(SimError::ActionLength { got: grasp.q_target_rad.len(), expected: n });
    }
    let keyframe_numbers = grasp.q_rad.iter().chain(&grasp.q_target_rad);
    let pose_numbers =
        grasp.object_pose.translation.vector.iter().chain(grasp.object_pose.rotation.coords.iter());
    if !keyframe_numbers.chain(pose_numbers).all(|v| v.is_finite()) {
        return Err(SimError::NonFiniteState("the grasp keyframe".to_owned()));
    }
    if !(timestep_s.is_finite() && timestep_s > 0.0) {
        return Err(SimError::InvalidConfig(format!("MuJoCo time step {timestep_s} s")));
    }
    physics.validate()?;
    object.validate()?;
    let (object_geom, object_inertia) = object_shape_and_inertia(object)?;
    let bodies = hand.bodies();
    if bodies.iter().any(|b| b.name.as_deref() == Some(OBJECT_NAME))
        || hand.joints().iter().any(|j| j.name == OBJECT_NAME)
        || bodies.iter().flat_map(|b| &b.geoms).any(|g| g.name.as_deref() == Some(OBJECT_NAME))
    {
        return Err(SimError::InvalidConfig(format!(
            "hand {}: a body, joint or geom is named `{OBJECT_NAME}`, the written model's object",
            hand.name()
        )));
    }

    // Body names: the description's, and one for an unnamed body that an exclude names.
    let mut body_names: Vec<Option<String>> = bodies.iter().map(|b| b.name.clone()).collect();
    for exclude in hand.contact_excludes() {
        for b in [exclude.body1, exclude.body2] {
            let slot = body_names.get_mut(b).ok_or_else(|| {
                SimError::InvalidConfig(format!("hand {}: contact exclude of body {b}", hand.name()))
            })?;
            if slot.is_none() {
                *slot = Some(format!("body{b}"));
            }
        }
    }
    let mut children = vec![Vec::new(); bodies.len()];
    for (b, body) in bodies.iter().enumerate().skip(1) {
        let parent = body.parent.filter(|p| *p < b).ok_or_else(|| {
            SimError::InvalidConfig(format!("hand {}: body {b} has no parent before it", hand.name()))
        })?;
        children[parent].push(b);
    }
    let tip_geoms = hand
        .fingers()
        .iter()
        .filter_map(|f| f.tip_geom.map(|g| (f.tip_body, g, format!("{FINGERTIP_GEOM_PREFIX}{}", f.name))))
        .collect();
    let tree = TreeWriter { hand, servos, body_names, children, tip_geoms, timestep_s };

    // contype/conaffinity: rapier's hand and object groups (module docs).
    let hand_affinity = if physics.finger_collisions { 3 } else { 2 };
    let gravity = physics.gravity_m_per_s2_vector();
    // rapier averages the two colliders' coefficients; MuJoCo uses the priority geom's.
    let object_friction = 0.5 * (physics.finger_friction + object.friction);
    let mut xml = String::new();
    let w = &mut xml;
    // Writing into a String cannot fail; the results are discarded with `let _`.
    let _ = writeln!(w, r#"<mujoco model="{}">"#, esc(hand.name()));
    // Radians (MJCF's default reads hinge ranges in degrees, module docs); masses only from the
    // explicit inertials, which are the rapier world's.
    let _ = writeln!(w, r#"  <compiler angle="radian" inertiafromgeom="false"/>"#);
    let _ = writeln!(
        w,
        r#"  <option timestep="{timestep_s}" gravity="{}" integrator="implicitfast" cone="elliptic" impratio="10"/>"#,
        vec3(&gravity)
    );
    let _ = writeln!(
        w,
        r#"  <default><geom contype="1" conaffinity="{hand_affinity}" condim="3" friction="{} 0.005 0.0001"/></default>"#,
        physics.finger_friction
    );
    let _ = writeln!(w, "  <worldbody>");
    tree.body_content(w, 0, 2);
    let o = &grasp.object_pose;
    let _ = writeln!(w, r#"    <body name="{OBJECT_NAME}"{}>"#, frame_attrs(o));
    let _ = writeln!(w, r#"      <freejoint name="{OBJECT_NAME}"/>"#);
    let _ = writeln!(
        w,
        r#"      <inertial pos="0 0 0" mass="{}" diaginertia="{}"/>"#,
        object.mass_kg,
        vec3(&object_inertia)
    );
    let _ = writeln!(
        w,
        r#"      <geom name="{OBJECT_NAME}" {object_geom} contype="2" conaffinity="1" priority="1" friction="{object_friction} 0.005 0.0001"/>"#
    );
    let _ = writeln!(w, "    </body>\n  </worldbody>");
    if !hand.contact_excludes().is_empty() {
        let _ = writeln!(w, "  <contact>");
        for exclude in hand.contact_excludes() {
            let name = |b: usize| tree.body_names[b].as_deref().map(esc).unwrap_or_default();
            let _ = writeln!(
                w,
                r#"    <exclude body1="{}" body2="{}"/>"#,
                name(exclude.body1),
                name(exclude.body2)
            );
        }
        let _ = writeln!(w, "  </contact>");
    }
    let _ = writeln!(w, "  <actuator>");
    for (joint, servo) in hand.joints().iter().zip(servos) {
        let (lo, hi, cap) = (servo.limit.lower_rad, servo.limit.upper_rad, servo.torque_cap_nm);
        let _ = writeln!(
            w,
            r#"    <position name="{0}" joint="{0}" kp="{1}" kv="{2}" ctrllimited="true" ctrlrange="{lo} {hi}" forcelimited="true" forcerange="{3} {cap}"/>"#,
            esc(&joint.name),
            servo.kp_nm_per_rad,
            servo.kv_nms_per_rad,
            -cap,
        );
    }
    let _ = writeln!(w, "  </actuator>");
    let numbers = |v: &mut dyn Iterator<Item = f32>| v.map(|x| x.to_string()).collect::<Vec<_>>().join(" ");
    let r = o.rotation;
    let object_qpos = [o.translation.x, o.translation.y, o.translation.z, r.w, r.i, r.j, r.k];
    let _ = writeln!(
        w,
        r#"  <keyframe><key name="grasp" qpos="{}" ctrl="{}"/></keyframe>"#,
        numbers(&mut grasp.q_rad.iter().copied().chain(object_qpos)),
        numbers(&mut grasp.q_target_rad.iter().copied())
    );
    let _ = writeln!(w, "</mujoco>");
    Ok(xml)
}

/// The MJCF of `env`'s task on its hand, with the grasp that `Env::reset(seed)` settles as
/// keyframe `grasp` (the state `vge bench sim` starts its first world from, for seed 0). The
/// object's mass is the world's (domain randomization draws it at reset); its friction is the
/// configured one.
pub fn settled_grasp_mjcf(
    env: &crate::env::EnvConfig,
    seed: u64,
    timestep_s: f32,
) -> Result<String, SimError> {
    // Checked before the grasp is simulated, which takes a while.
    object_shape_and_inertia(&env.object)?;
    if !(timestep_s.is_finite() && timestep_s > 0.0) {
        return Err(SimError::InvalidConfig(format!("MuJoCo time step {timestep_s} s")));
    }
    let mut sim = crate::env::Env::new(env.clone())?;
    sim.reset(seed)?;
    let world = sim.world().ok_or_else(|| SimError::InvalidConfig("no world after reset".to_owned()))?;
    let object = ObjectConfig { mass_kg: world.object_mass_kg(), ..env.object };
    let settings = MjcfSettings {
        hand: &env.hand,
        servos: &env.servos,
        physics: &env.physics,
        object: &object,
        timestep_s,
    };
    hand_mjcf(&settings, &GraspKeyframe::of(world))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::env::EnvConfig;

    fn key_attr(xml: &str, name: &str) -> Vec<f32> {
        let key = xml.lines().find(|l| l.contains("<key ")).unwrap();
        let start = key.find(&format!(r#"{name}=""#)).unwrap() + name.len() + 2;
        let end = start + key[start..].find('"').unwrap();
        key[start..end].split(' ').map(|v| v.parse().unwrap()).collect()
    }

    #[test]
    fn the_model_has_every_joint_actuator_and_the_settled_grasp_as_keyframe() {
        let env = EnvConfig::default();
        let xml = settled_grasp_mjcf(&env, 0, 1.0 / 240.0).unwrap();
        assert_eq!(xml.matches(r#"type="hinge""#).count(), 15);
        assert_eq!(xml.matches("<position ").count(), 15);
        assert_eq!(xml.matches(r#"name="fingertip."#).count(), 5, "one fingertip geom per finger");
        assert!(xml.contains(r#"<geom name="fingertip.thumb" type="sphere" size="0.012""#));
        // The keyframe holds 15 joint angles and the object's 7 pose numbers, then 15 targets.
        let (qpos, ctrl) = (key_attr(&xml, "qpos"), key_attr(&xml, "ctrl"));
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
        assert!(xml.contains(r#"<compiler angle="radian" inertiafromgeom="false"/>"#));
        assert!(xml.contains(r#"range="-0.3 1.6""#));
        assert!(qpos[..15].iter().zip(&env.servos).all(|(q, s)| s.limit.contains(*q)));
        // The thumb's torque cap, the others', and the stability armature kp dt^2 / 4.
        assert!(xml.contains(r#"forcerange="-0.45 0.45""#) && xml.contains(r#"forcerange="-0.3 0.3""#));
        let dt_s = 1.0f32 / 240.0;
        assert!(xml.contains(&format!(r#"armature="{}""#, 20.0 * dt_s * dt_s / 4.0)));
    }

    #[test]
    fn the_allegro_gets_its_tree_masses_excludes_and_motor_with_the_joint_damping_in_kv() {
        let hand = crate::hands::load("allegro").unwrap();
        let env = EnvConfig::for_hand(hand).unwrap();
        let xml = settled_grasp_mjcf(&env, 0, 1.0 / 240.0).unwrap();
        assert_eq!(xml.matches(r#"type="hinge""#).count(), 16);
        assert_eq!(xml.matches("<position ").count(), 16);
        assert_eq!(xml.matches("<exclude ").count(), 21);
        assert_eq!(xml.matches(r#"name="fingertip."#).count(), 4);
        assert!(xml.contains(r#"<body name="ff_tip" pos="0 0 0.0267">"#));
        assert!(xml.contains(
            r#"<inertial pos="-0.0093 0 -0.0475" mass="0.4154" diaginertia="0.0007544 0.00037 0.0004996"/>"#
        ));
        // kp 3, the joint's damping 0.001 carried by the motor (none on the joint), cap 0.7 N m.
        assert!(xml.contains(r#"kp="3" kv="0.001""#) && xml.contains(r#"forcerange="-0.7 0.7""#));
        assert!(!xml.contains("damping="));
        let (qpos, ctrl) = (key_attr(&xml, "qpos"), key_attr(&xml, "ctrl"));
        assert_eq!((qpos.len(), ctrl.len()), (16 + 7, 16));
    }

    #[test]
    fn gravity_follows_the_orientation_and_finger_collisions_open_the_hand_s_affinity() {
        let mut env = EnvConfig::default();
        env.physics.hand_orientation = crate::world::HandOrientation::SideOn;
        env.physics.finger_collisions = true;
        let grasp = GraspKeyframe {
            q_rad: vec![0.0; 15],
            q_target_rad: vec![0.0; 15],
            object_pose: Isometry3::identity(),
        };
        let settings = MjcfSettings {
            hand: &env.hand,
            servos: &env.servos,
            physics: &env.physics,
            object: &env.object,
            timestep_s: 0.002,
        };
        let xml = hand_mjcf(&settings, &grasp).unwrap();
        assert!(xml.contains(r#"gravity="9.81 0 0""#), "{xml}");
        assert!(xml.contains(r#"conaffinity="3""#));
        let short = GraspKeyframe { q_rad: vec![0.0; 14], ..grasp.clone() };
        assert!(matches!(
            hand_mjcf(&settings, &short),
            Err(SimError::ActionLength { got: 14, expected: 15 })
        ));
        let nan = GraspKeyframe { q_target_rad: vec![f32::NAN; 15], ..grasp };
        assert!(hand_mjcf(&settings, &nan).is_err());
    }

    #[test]
    fn shapes_mujoco_cannot_build_without_a_mesh_are_refused() {
        let env = EnvConfig { object: ObjectConfig::of(ObjectShape::Dodecahedron), ..EnvConfig::default() };
        let err = settled_grasp_mjcf(&env, 0, 1.0 / 240.0).unwrap_err();
        assert!(err.to_string().contains("dodecahedron"), "{err}");
        let env = EnvConfig::default();
        assert!(settled_grasp_mjcf(&env, 0, 0.0).is_err());
    }

    #[test]
    fn attribute_values_are_escaped() {
        assert_eq!(esc(r#"a<b>&"c'"#), "a&lt;b&gt;&amp;&quot;c&apos;");
    }
}
