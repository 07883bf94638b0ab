//! A hand on vge's own CAN protocol ([`crate::protocol`]), read from its description: how many
//! finger nodes it has, their names, and the joint limits the bridge holds every target and
//! reading to. Everything the vge15 path sizes (the hand state, the safety filter, the
//! emulated nodes, the observation) takes its counts from here, not from constants.
//!
//! The protocol's frames carry three joints per finger node, so a hand can run on it when each
//! of its fingers is three joints, finger `f` the description's joints `3f..3f+3`, and it has
//! at most [`MAX_FINGERS`] fingers. Any other hand is refused with what does not fit (the
//! Allegro, four joints a finger, speaks its own protocol: `--hand allegro`).

use std::sync::Arc;

use thiserror::Error;
use vge_hand::{Hand, JointLimit};

use crate::protocol::{JOINTS_PER_NODE, MAX_FINGERS, NodeLayout};

#[derive(Debug, Error)]
pub enum ProtocolHandError {
    #[error("reading the hand: {0}")]
    Load(String),
    #[error(
        "hand {hand}: vge's CAN protocol cannot carry it: {why} (the protocol carries 1 to {MAX_FINGERS} \
         finger nodes of {JOINTS_PER_NODE} joints each, finger f driving joints {JOINTS_PER_NODE}f..{JOINTS_PER_NODE}f+{JOINTS_PER_NODE}; \
         the Allegro Hand speaks its own protocol: --hand allegro)"
    )]
    NotCarried { hand: String, why: String },
    #[error("hand {hand}: joint {joint} has no range, and the bridge clamps every target to one")]
    NoRange { hand: String, joint: String },
}

/// A hand the protocol carries: its nodes, names and joint limits, in the description's order.
#[derive(Debug, Clone, PartialEq)]
pub struct ProtocolHand {
    /// The description's name (`vge15`).
    pub name: String,
    pub nodes: NodeLayout,
    /// Node `f`'s finger (vge15: thumb, index, middle, ring, little).
    pub finger_names: Vec<String>,
    /// Joint `k`'s name (vge15: `thumb.roll`, ...; the names a policy's actions carry).
    pub joint_names: Vec<String>,
    /// Joint `k`'s range: targets are clamped to it, readings far outside it are implausible.
    pub limits: Vec<JointLimit>,
}

impl ProtocolHand {
    /// `hand`, if the protocol carries it.
    pub fn of(hand: &Hand) -> Result<Self, ProtocolHandError> {
        let refuse = |why: String| ProtocolHandError::NotCarried { hand: hand.name().to_owned(), why };
        let nodes = NodeLayout::new(hand.num_fingers())
            .map_err(|_| refuse(format!("it has {} fingers", hand.num_fingers())))?;
        for (f, finger) in hand.fingers().iter().enumerate() {
            let want = f * JOINTS_PER_NODE..(f + 1) * JOINTS_PER_NODE;
            if finger.joints != want {
                return Err(refuse(format!(
                    "finger {f} ({}) has joints {}..{} ({} joints)",
                    finger.name,
                    finger.joints.start,
                    finger.joints.end,
                    finger.joints.len()
                )));
            }
        }
        if hand.num_joints() != nodes.num_joints() {
            return Err(refuse(format!(
                "it has {} joints, its {} fingers {}",
                hand.num_joints(),
                nodes.num_fingers(),
                nodes.num_joints()
            )));
        }
        let limits = hand
            .joints()
            .iter()
            .map(|j| {
                j.limit.ok_or_else(|| ProtocolHandError::NoRange {
                    hand: hand.name().to_owned(),
                    joint: j.name.clone(),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            name: hand.name().to_owned(),
            nodes,
            finger_names: hand.fingers().iter().map(|f| f.name.clone()).collect(),
            joint_names: hand.joints().iter().map(|j| j.name.clone()).collect(),
            limits,
        })
    }

    /// vge's own hand as it ships (`vge_sim::hands::vge15`).
    pub fn vge15() -> Result<Self, ProtocolHandError> {
        Self::of(load("vge15")?.as_ref())
    }

    pub fn num_fingers(&self) -> usize {
        self.nodes.num_fingers()
    }

    pub fn num_joints(&self) -> usize {
        self.nodes.num_joints()
    }

    /// Node `f`'s finger name, or `node f` for a node the hand does not have.
    #[must_use]
    pub fn finger_name(&self, f: usize) -> String {
        self.finger_names.get(f).cloned().unwrap_or_else(|| format!("node {f}"))
    }

    /// Joint `k`'s name, or `joint k` past the hand's joints.
    #[must_use]
    pub fn joint_name(&self, k: usize) -> String {
        self.joint_names.get(k).cloned().unwrap_or_else(|| format!("joint {k}"))
    }

    /// `node f (name)`, as the loop's messages name a node.
    #[must_use]
    pub fn node_label(&self, f: usize) -> String {
        format!("node {f} ({})", self.finger_name(f))
    }
}

/// A hand by name or path (`vge_sim::hands::load`).
pub fn load(spec: &str) -> Result<Arc<Hand>, ProtocolHandError> {
    vge_sim::hands::load(spec).map_err(|e| ProtocolHandError::Load(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vge15_is_five_nodes_of_three_joints_with_its_descriptions_limits() {
        let hand = ProtocolHand::vge15().expect("vge15");
        assert_eq!((hand.num_fingers(), hand.num_joints()), (5, 15));
        assert_eq!(hand.finger_names, ["thumb", "index", "middle", "ring", "little"]);
        assert_eq!(
            (hand.joint_name(0).as_str(), hand.joint_name(14).as_str()),
            ("thumb.roll", "little.flex_dist")
        );
        assert_eq!(hand.limits.len(), 15);
        assert_eq!(hand.limits[0], JointLimit { lower_rad: -0.5, upper_rad: 0.5 });
        assert_eq!(hand.node_label(4), "node 4 (little)");
        assert_eq!(hand.finger_name(7), "node 7");
    }

    #[test]
    fn the_allegro_is_refused_saying_why_and_where_it_runs() {
        let allegro = load("allegro").expect("allegro");
        let text = ProtocolHand::of(&allegro).expect_err("four joints a finger").to_string();
        let want = format!("hand {}: vge's CAN protocol cannot carry it", allegro.name());
        assert!(text.starts_with(&want), "{text}");
        assert!(
            text.contains("finger 0 (index) has joints 0..4 (4 joints)") && text.contains("--hand allegro"),
            "{text}"
        );
    }
}
