//! The policy observation: exactly [`OBS_DIM`] = 65 `f32`, built from raw readings only
//! (joint angles, joint targets, per-fingertip contacts), so that the simulator and the
//! deployment bridge (which gets the same readings over CAN) build it with this one
//! function.
//!
//! Layout (named slices; all world frame, SI units):
//!
//! | slice | content |
//! |---|---|
//! | [`OBS_Q`] = 0..15 | joint angles q (rad), finger-major |
//! | [`OBS_Q_TARGET`] = 15..30 | joint position targets (rad) |
//! | [`OBS_CONTACT_POSITION`] = 30..45 | per fingertip contact point (m), 5 x 3 |
//! | [`OBS_CONTACT_NORMAL`] = 45..60 | per fingertip unit normal, fingertip into object, 5 x 3 |
//! | [`OBS_CONTACT_FORCE`] = 60..65 | per fingertip normal force magnitude (N) |
//!
//! A fingertip out of contact contributes zeros to the last three slices.

use std::ops::Range;

use crate::kinematics::{NUM_FINGERS, NUM_JOINTS};

/// Length of the observation vector.
pub const OBS_DIM: usize = 65;
/// Joint angles (rad), finger-major.
pub const OBS_Q: Range<usize> = 0..15;
/// Joint position targets (rad), finger-major.
pub const OBS_Q_TARGET: Range<usize> = 15..30;
/// Contact points (m, world), three per fingertip.
pub const OBS_CONTACT_POSITION: Range<usize> = 30..45;
/// Contact normals (unit, world, from the fingertip into the object), three per fingertip.
pub const OBS_CONTACT_NORMAL: Range<usize> = 45..60;
/// Normal force magnitudes (N), one per fingertip.
pub const OBS_CONTACT_FORCE: Range<usize> = 60..65;

/// The observation's named slices, in order: the names a policy file carries
/// (`obs_layout`) and that the bridge and eval check before they run one.
pub const OBS_LAYOUT: [(&str, Range<usize>); 5] = [
    ("q_rad", OBS_Q),
    ("q_target_rad", OBS_Q_TARGET),
    ("contact_position_m", OBS_CONTACT_POSITION),
    ("contact_normal", OBS_CONTACT_NORMAL),
    ("contact_force_n", OBS_CONTACT_FORCE),
];

/// Whether a policy's observation layout (`(name, start, end)` per slice, in order) is the
/// one [`build_observation`] fills; `Err` says where they differ.
pub fn check_layout<'a>(slices: impl IntoIterator<Item = (&'a str, usize, usize)>) -> Result<(), String> {
    let got: Vec<(&str, usize, usize)> = slices.into_iter().collect();
    let want: Vec<(&str, usize, usize)> = OBS_LAYOUT.iter().map(|(n, r)| (*n, r.start, r.end)).collect();
    if got == want {
        return Ok(());
    }
    let show = |v: &[(&str, usize, usize)]| {
        v.iter().map(|(n, a, b)| format!("{n} {a}..{b}")).collect::<Vec<_>>().join(", ")
    };
    Err(format!("the policy observes [{}], the hand provides [{}]", show(&got), show(&want)))
}

/// Which readings a policy observes, named in a config: what the hand measures decides which
/// it can run on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObservationSet {
    /// Joint angles, joint targets and, per fingertip, the contact point, normal and force:
    /// the paper's observation, for a hand with fingertip sensing.
    Full,
    /// Joint angles and targets now and at the last `history` control steps: what a hand
    /// that measures joint positions only (a stock Allegro) can give.
    Proprio {
        /// Past control steps observed besides the current one.
        history: usize,
    },
}

/// The named slices of an observation for a hand of `num_joints` joints and `num_fingers`
/// fingertips: the sizes come from the hand, the names are what a policy file carries.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObservationLayout {
    slices: Vec<(&'static str, Range<usize>)>,
}

/// The slices that need fingertip sensing.
const CONTACT_SLICES: [&str; 3] = ["contact_position_m", "contact_normal", "contact_force_n"];

impl ObservationLayout {
    /// The layout of `set` for a hand of `num_joints` joints and `num_fingers` fingertips.
    #[must_use]
    pub fn new(set: ObservationSet, num_joints: usize, num_fingers: usize) -> Self {
        let sizes: Vec<(&'static str, usize)> = match set {
            ObservationSet::Full => vec![
                ("q_rad", num_joints),
                ("q_target_rad", num_joints),
                (CONTACT_SLICES[0], 3 * num_fingers),
                (CONTACT_SLICES[1], 3 * num_fingers),
                (CONTACT_SLICES[2], num_fingers),
            ],
            ObservationSet::Proprio { history } => {
                let mut sizes = vec![("q_rad", num_joints), ("q_target_rad", num_joints)];
                if history > 0 {
                    sizes.push(("q_rad_past", history * num_joints));
                    sizes.push(("q_target_rad_past", history * num_joints));
                }
                sizes
            }
        };
        let mut start = 0;
        let slices = sizes
            .into_iter()
            .map(|(name, len)| {
                let range = start..start + len;
                start += len;
                (name, range)
            })
            .collect();
        Self { slices }
    }

    /// The named slices, in order.
    #[must_use]
    pub fn slices(&self) -> &[(&'static str, Range<usize>)] {
        &self.slices
    }

    /// Length of the observation vector.
    #[must_use]
    pub fn dim(&self) -> usize {
        self.slices.last().map_or(0, |(_, r)| r.end)
    }

    /// Whether an observation of this layout needs fingertip contact sensing.
    #[must_use]
    pub fn needs_tip_sensing(&self) -> bool {
        self.slices.iter().any(|(name, _)| CONTACT_SLICES.contains(name))
    }
}

/// One fingertip's contact reading, in plain arrays so that non-simulator callers (the
/// CAN bridge) need no math library.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FingertipReading {
    /// Contact point, world frame (m).
    pub position_m: [f32; 3],
    /// Unit contact normal, world frame, pointing from the fingertip into the object.
    pub normal: [f32; 3],
    /// Normal force magnitude (N).
    pub force_n: f32,
}

/// Builds the 65-float observation from raw readings (see the module docs for the
/// layout). `contacts[i]` is `None` when fingertip `i` does not touch the object.
#[must_use]
pub fn build_observation(
    q_rad: &[f32; NUM_JOINTS],
    q_target_rad: &[f32; NUM_JOINTS],
    contacts: &[Option<FingertipReading>; NUM_FINGERS],
) -> [f32; OBS_DIM] {
    let mut obs = [0.0; OBS_DIM];
    obs[OBS_Q].copy_from_slice(q_rad);
    obs[OBS_Q_TARGET].copy_from_slice(q_target_rad);
    for (i, contact) in contacts.iter().enumerate() {
        if let Some(c) = contact {
            let p = OBS_CONTACT_POSITION.start + 3 * i;
            let n = OBS_CONTACT_NORMAL.start + 3 * i;
            obs[p..p + 3].copy_from_slice(&c.position_m);
            obs[n..n + 3].copy_from_slice(&c.normal);
            obs[OBS_CONTACT_FORCE.start + i] = c.force_n;
        }
    }
    obs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_tile_the_vector() {
        assert_eq!(OBS_Q.end, OBS_Q_TARGET.start);
        assert_eq!(OBS_Q_TARGET.end, OBS_CONTACT_POSITION.start);
        assert_eq!(OBS_CONTACT_POSITION.end, OBS_CONTACT_NORMAL.start);
        assert_eq!(OBS_CONTACT_NORMAL.end, OBS_CONTACT_FORCE.start);
        assert_eq!(OBS_CONTACT_FORCE.end, OBS_DIM);
        assert_eq!(OBS_CONTACT_POSITION.len(), 3 * NUM_FINGERS);
    }

    #[test]
    fn the_full_layout_of_vge15_is_the_65_float_observation_and_other_hands_get_their_own_sizes() {
        let full = ObservationLayout::new(ObservationSet::Full, NUM_JOINTS, NUM_FINGERS);
        let want: Vec<(&str, Range<usize>)> = OBS_LAYOUT.to_vec();
        assert_eq!(full.slices(), want.as_slice());
        assert_eq!(full.dim(), OBS_DIM);
        assert!(full.needs_tip_sensing());
        // The Allegro: 16 joints, 4 fingertips.
        let allegro = ObservationLayout::new(ObservationSet::Full, 16, 4);
        assert_eq!(allegro.dim(), 2 * 16 + 7 * 4);
        let proprio = ObservationLayout::new(ObservationSet::Proprio { history: 2 }, 16, 4);
        assert_eq!(proprio.dim(), 2 * 16 + 2 * 2 * 16);
        assert!(!proprio.needs_tip_sensing());
        let names: Vec<&str> = proprio.slices().iter().map(|(n, _)| *n).collect();
        assert_eq!(names, ["q_rad", "q_target_rad", "q_rad_past", "q_target_rad_past"]);
        let now = ObservationLayout::new(ObservationSet::Proprio { history: 0 }, 16, 4);
        assert_eq!((now.dim(), now.slices().len()), (32, 2));
    }

    #[test]
    fn contacts_land_in_their_slots_and_absent_ones_are_zero() {
        let q = std::array::from_fn(|j| j as f32);
        let t = std::array::from_fn(|j| -(j as f32));
        let mut contacts = [None; NUM_FINGERS];
        contacts[2] =
            Some(FingertipReading { position_m: [1.0, 2.0, 3.0], normal: [0.0, 1.0, 0.0], force_n: 4.5 });
        let obs = build_observation(&q, &t, &contacts);
        assert_eq!(obs[OBS_Q.start + 3], 3.0);
        assert_eq!(obs[OBS_Q_TARGET.start + 3], -3.0);
        assert_eq!(&obs[36..39], &[1.0, 2.0, 3.0]);
        assert_eq!(&obs[51..54], &[0.0, 1.0, 0.0]);
        assert_eq!(obs[62], 4.5);
        assert!(obs[30..36].iter().chain(&obs[39..51]).chain(&obs[54..62]).all(|v| *v == 0.0));
        assert_eq!(obs[64], 0.0);
    }
}
