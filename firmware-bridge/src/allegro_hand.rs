//! What the bridge needs to know about the Allegro Hand beyond its CAN protocol: joint ranges,
//! the PD gains and the start grasp, read from the hand's description (`hands/allegro.xml` and
//! its TOML, shipped inside vge-sim, physics-free) so that the bridge, the emulator and the
//! simulator agree on one hand.
//!
//! The PD law's gains are the simulator's servo on each joint (`vge_sim::JointServo`): kp the
//! position actuator's, kv its kv plus the joint's own damping, the D term the policies were
//! trained with. The start grasp `--hold` keeps is pressed as the simulator's env presses it
//! ([`pressed_grasp_rad`]: each fingertip into its face with the env's force per kg of the
//! cube, the thumb against the others' resultant), which needs the simulator's statics; a flexion
//! squeeze by angle ([`AllegroHand::squeezed_grasp_rad`]) is the fallback without them.

use thiserror::Error;
use vge_hand::JointLimit;

use crate::protocol::allegro::{Finger, JOINTS_PER_FINGER, NUM_JOINTS};

/// How far a flexion squeeze ([`AllegroHand::squeezed_grasp_rad`]) presses the start grasp's
/// targets past contact on every joint but each finger's first (its spread or rotation), as
/// vge's grasp squeezes a hand without a keyframe. On the Allegro the thumb's flexion then
/// presses mostly upwards and pushes the cube towards the thumb (hands/allegro.toml), which
/// [`pressed_grasp_rad`] does not.
pub const DEFAULT_SQUEEZE_RAD: f32 = 0.05;

#[derive(Debug, Error)]
pub enum AllegroHandError {
    #[error("reading the Allegro hand's description: {0}")]
    Description(String),
    #[error("the hand description `{hand}` does not match the Allegro's CAN joint order: {why}")]
    Layout { hand: String, why: String },
    #[error("pressing the start grasp as the simulator does: {0}")]
    Press(String),
}

/// The Allegro's joints in CAN order (index, middle, ring, thumb; joints 0..=3 of each).
#[derive(Debug, Clone, PartialEq)]
pub struct AllegroHand {
    /// The joints' names in the description (ffj0 .. thj3).
    pub joint_names: Vec<String>,
    /// Each joint's range: PD targets are clamped to it, and a measured position far outside
    /// it is implausible.
    pub limits: [JointLimit; NUM_JOINTS],
    /// The PD law's stiffness, the description's position-servo kp (N m / rad).
    pub kp_nm_per_rad: [f32; NUM_JOINTS],
    /// The PD law's damping on the estimated joint velocity (N m s / rad): the position
    /// servo's kv plus the joint's damping, as the simulator's servo (`vge_sim::JointServo`)
    /// sums them, since its joints have no damping of their own.
    pub kv_nms_per_rad: [f32; NUM_JOINTS],
    /// The description's start grasp (rad): the fingertips on the cube's faces.
    pub start_grasp_rad: [f32; NUM_JOINTS],
}

impl AllegroHand {
    /// The Allegro vge ships (`vge_sim::hands::load("allegro")`).
    pub fn shipped() -> Result<Self, AllegroHandError> {
        let hand =
            vge_sim::hands::load("allegro").map_err(|e| AllegroHandError::Description(e.to_string()))?;
        let layout = |why: String| AllegroHandError::Layout { hand: hand.name().to_owned(), why };
        if hand.num_joints() != NUM_JOINTS {
            return Err(layout(format!("{} joints, the protocol carries {NUM_JOINTS}", hand.num_joints())));
        }
        // The frames' finger f is the description's finger f: check the order, not just the count.
        let want = ["index", "middle", "ring", "thumb"];
        let fingers: Vec<&str> = hand.fingers().iter().map(|f| f.name.as_str()).collect();
        if fingers != want {
            return Err(layout(format!("fingers {fingers:?}, the protocol's are {want:?}")));
        }
        for (f, finger) in hand.fingers().iter().enumerate() {
            if finger.joints != (f * JOINTS_PER_FINGER..(f + 1) * JOINTS_PER_FINGER) {
                return Err(layout(format!("finger {} has joints {:?}", finger.name, finger.joints)));
            }
        }
        let mut limits = [JointLimit { lower_rad: 0.0, upper_rad: 0.0 }; NUM_JOINTS];
        let mut kp = [0.0; NUM_JOINTS];
        let mut kv = [0.0; NUM_JOINTS];
        for (k, joint) in hand.joints().iter().enumerate() {
            let limit = joint.limit.ok_or_else(|| layout(format!("joint {} has no range", joint.name)))?;
            let servo = joint
                .servo
                .as_ref()
                .ok_or_else(|| layout(format!("joint {} has no position servo", joint.name)))?;
            limits[k] = JointLimit { lower_rad: limit.lower_rad, upper_rad: limit.upper_rad };
            kp[k] = servo.kp_nm_per_rad;
            kv[k] = servo.kv_nms_per_rad + joint.damping_nms_per_rad;
        }
        let grasp = hand.start_grasp_rad().ok_or_else(|| layout("no start grasp".to_owned()))?;
        let start_grasp_rad = <[f32; NUM_JOINTS]>::try_from(grasp.as_slice())
            .map_err(|_| layout("start grasp length".to_owned()))?;
        Ok(Self {
            joint_names: hand.joints().iter().map(|j| j.name.clone()).collect(),
            limits,
            kp_nm_per_rad: kp,
            kv_nms_per_rad: kv,
            start_grasp_rad,
        })
    }

    /// The start grasp pressed `squeeze_rad` further on every joint but each finger's first,
    /// clamped into the joints' ranges: the targets that hold the cube.
    #[must_use]
    pub fn squeezed_grasp_rad(&self, squeeze_rad: f32) -> [f32; NUM_JOINTS] {
        let mut q = self.start_grasp_rad;
        for finger in Finger::ALL {
            for joint in 1..JOINTS_PER_FINGER {
                let k = finger.joint_index(joint);
                q[k] = self.limits[k].clamp(q[k] + squeeze_rad);
            }
        }
        q
    }

    /// The Allegro's start grasp as vge's simulator presses it: the joint targets its env's
    /// reset sets (`vge_sim::Env::reset`, no pose noise, the file's cube and mass, the env's
    /// `GraspConfig::squeeze_force_n_per_kg`) with the hand mounted `orientation`. These are the
    /// targets the policies start from in training; with the simulator's kp (the PD law's) they
    /// press each tip into its face and carry the cube's and the links' weight.
    #[cfg(feature = "sim")]
    pub fn pressed_grasp_rad(
        orientation: vge_sim::HandOrientation,
    ) -> Result<[f32; NUM_JOINTS], AllegroHandError> {
        let press = |e: vge_sim::SimError| AllegroHandError::Press(e.to_string());
        let hand =
            vge_sim::hands::load("allegro").map_err(|e| AllegroHandError::Description(e.to_string()))?;
        let mut config = vge_sim::EnvConfig::for_hand(hand).map_err(press)?;
        config.physics.hand_orientation = orientation;
        config.grasp.pose_noise_rad = 0.0;
        config.grasp.randomize_fingers = false;
        config.randomization = vge_sim::DomainRandomization::default();
        let mut env = vge_sim::Env::new(config).map_err(press)?;
        env.reset(0).map_err(press)?;
        let state =
            env.privileged().ok_or_else(|| AllegroHandError::Press("no state after the reset".into()))?;
        let targets = &state.q_target_rad;
        <[f32; NUM_JOINTS]>::try_from(targets.as_slice())
            .map_err(|_| AllegroHandError::Press(format!("{} targets", targets.len())))
    }

    /// `joint_names[k]`, or its index where the name is missing.
    #[must_use]
    pub fn joint_name(&self, k: usize) -> String {
        self.joint_names.get(k).cloned().unwrap_or_else(|| format!("joint {k}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_allegro_is_in_can_order_with_its_gains_and_grasp() {
        let hand = AllegroHand::shipped().expect("shipped allegro");
        assert_eq!(hand.joint_names[0], "ffj0");
        assert_eq!(hand.joint_names[15], "thj3");
        assert!(hand.kp_nm_per_rad.iter().all(|&kp| kp > 0.0));
        assert!(hand.kv_nms_per_rad.iter().all(|&kv| kv >= 0.0));
        for (k, q) in hand.start_grasp_rad.iter().enumerate() {
            assert!(hand.limits[k].contains(*q), "{} grasp {q} outside its range", hand.joint_name(k));
        }
        // The D term is the simulator's: the servo's kv plus the joint's damping.
        assert!(hand.kv_nms_per_rad.iter().all(|&kv| kv > 0.0), "{:?}", hand.kv_nms_per_rad);
        let squeezed = hand.squeezed_grasp_rad(DEFAULT_SQUEEZE_RAD);
        for (k, (q, grasp)) in squeezed.iter().zip(&hand.start_grasp_rad).enumerate() {
            let pressed = q - grasp;
            if k % JOINTS_PER_FINGER == 0 {
                assert_eq!(pressed, 0.0, "a finger's first joint is not squeezed");
            } else {
                assert!(
                    pressed > 0.0 && pressed <= DEFAULT_SQUEEZE_RAD + 1e-6,
                    "{}: {pressed}",
                    hand.joint_name(k)
                );
            }
        }
    }

    /// The PD law's gains are the simulator's servo on every joint, so that a policy meets the
    /// stiffness and damping it was trained with.
    #[cfg(feature = "sim")]
    #[test]
    fn the_pd_gains_are_the_simulators_servo_gains() {
        let hand = AllegroHand::shipped().expect("shipped allegro");
        let description = vge_sim::hands::load("allegro").expect("allegro");
        let servos = vge_sim::JointServo::from_description(&description).expect("servos");
        for (k, servo) in servos.iter().enumerate() {
            let name = hand.joint_name(k);
            assert_eq!(hand.kp_nm_per_rad[k], servo.kp_nm_per_rad, "{name}");
            assert_eq!(hand.kv_nms_per_rad[k], servo.kv_nms_per_rad, "{name}");
        }
    }

    /// `--hold`'s press: the targets past the start grasp on the fingers that press, inside the
    /// joints' ranges, the thumb pressing back.
    #[cfg(feature = "sim")]
    #[test]
    fn the_pressed_grasp_presses_past_the_start_grasp_within_the_ranges() {
        let hand = AllegroHand::shipped().expect("shipped allegro");
        let pressed = AllegroHand::pressed_grasp_rad(vge_sim::HandOrientation::PalmDown).expect("press");
        let mut moved = 0;
        for (k, (p, g)) in pressed.iter().zip(&hand.start_grasp_rad).enumerate() {
            assert!(hand.limits[k].contains(*p), "{} pressed to {p}", hand.joint_name(k));
            moved += usize::from((p - g).abs() > 1e-3);
        }
        assert!(
            moved >= 8,
            "the press moves most joints' targets: {pressed:?} from {:?}",
            hand.start_grasp_rad
        );
    }
}
