//! What the bridge needs to know about the Allegro Hand beyond its CAN protocol: joint ranges,
//! the PD gains and the start grasp, read from the hand's description (`hands/allegro.xml` and
//! its TOML, shipped inside vge-sim, physics-free) so that the bridge, the emulator and the
//! simulator agree on one hand.

use thiserror::Error;
use vge_hand::JointLimit;

use crate::protocol::allegro::{Finger, JOINTS_PER_FINGER, NUM_JOINTS};

/// How far the start grasp's targets press past contact on every joint but each finger's
/// first (its spread or rotation), as vge's grasp squeezes: with the targets at the contact
/// pose the cube slips out (hands/allegro.toml).
pub const DEFAULT_SQUEEZE_RAD: f32 = 0.05;

#[derive(Debug, Error)]
pub enum AllegroHandError {
    #[error("reading the Allegro hand's description: {0}")]
    Description(String),
    #[error("the hand description `{hand}` does not match the Allegro's CAN joint order: {why}")]
    Layout { hand: String, why: String },
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
    /// The PD law's damping on the estimated joint velocity, the servo's kv (N m s / rad).
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
            kv[k] = servo.kv_nms_per_rad;
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
}
