//! The policy observation, built from raw readings only (joint angles, joint targets,
//! per-fingertip contacts), so that the simulator and the deployment bridge (which gets the
//! same readings over CAN) build it with these functions. Its sizes come from the hand.
//!
//! Layout of the [`ObservationSet::Full`] observation of a hand of J joints and F fingertips
//! (named slices, in order; all world frame, SI units; 65 floats for vge15, 60 for the Allegro):
//!
//! | slice | length | content |
//! |---|---|---|
//! | `q_rad` | J | joint angles q (rad), in the hand's joint order |
//! | `q_target_rad` | J | joint position targets (rad) |
//! | `contact_position_m` | 3F | per fingertip contact point (m) |
//! | `contact_normal` | 3F | per fingertip unit normal, fingertip into object |
//! | `contact_force_n` | F | per fingertip normal force magnitude (N) |
//!
//! A fingertip out of contact contributes zeros to the last three slices.
//! [`ObservationSet::Proprio`] keeps the first two and adds the last `history` of each.

use std::collections::VecDeque;
use std::ops::Range;

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

    /// The range of the slice named `name`, if the layout has it.
    #[must_use]
    pub fn range(&self, name: &str) -> Option<Range<usize>> {
        self.slices.iter().find(|(n, _)| *n == name).map(|(_, r)| r.clone())
    }

    /// Whether a policy's observation layout (`(name, start, end)` per slice, in order) is
    /// this one; `Err` says where they differ.
    pub fn check<'a>(&self, slices: impl IntoIterator<Item = (&'a str, usize, usize)>) -> Result<(), String> {
        let got: Vec<(&str, usize, usize)> = slices.into_iter().collect();
        let want: Vec<(&str, usize, usize)> = self.slices.iter().map(|(n, r)| (*n, r.start, r.end)).collect();
        if got == want {
            return Ok(());
        }
        let show = |v: &[(&str, usize, usize)]| {
            v.iter().map(|(n, a, b)| format!("{n} {a}..{b}")).collect::<Vec<_>>().join(", ")
        };
        Err(format!("the policy observes [{}], the hand provides [{}]", show(&got), show(&want)))
    }
}

impl ObservationSet {
    /// The name a config and a policy file use: `full`, or `proprio` with its history as
    /// `proprio:K` (K past control steps; `proprio` alone is K = 0).
    #[must_use]
    pub fn name(&self) -> String {
        match self {
            Self::Full => "full".to_owned(),
            Self::Proprio { history: 0 } => "proprio".to_owned(),
            Self::Proprio { history } => format!("proprio:{history}"),
        }
    }

    /// Reads [`Self::name`]'s spelling; the error names what is accepted.
    pub fn parse(text: &str) -> Result<Self, String> {
        let refuse = || {
            format!(
                "observation set `{text}`: expected `full`, `proprio` or `proprio:K` (K past steps, 0-64)"
            )
        };
        match text {
            "full" => Ok(Self::Full),
            "proprio" => Ok(Self::Proprio { history: 0 }),
            _ => {
                let k = text.strip_prefix("proprio:").ok_or_else(refuse)?;
                let history: usize = k.parse().map_err(|_| refuse())?;
                if history > MAX_HISTORY {
                    return Err(refuse());
                }
                Ok(Self::Proprio { history })
            }
        }
    }
}

/// The longest proprioceptive history a layout takes (control steps): 3.2 s at 20 Hz.
pub const MAX_HISTORY: usize = 64;

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

/// Builds the [`ObservationSet::Full`] observation from raw readings (see the module docs
/// for the layout): `q_rad` and `q_target_rad` of the hand's J joints, `contacts[i]` `None`
/// when fingertip `i` does not touch the object.
#[must_use]
pub fn build_observation(
    q_rad: &[f32],
    q_target_rad: &[f32],
    contacts: &[Option<FingertipReading>],
) -> Vec<f32> {
    let (joints, fingers) = (q_rad.len(), contacts.len());
    let mut obs = vec![0.0; 2 * joints + 7 * fingers];
    obs[..joints].copy_from_slice(q_rad);
    obs[joints..2 * joints].copy_from_slice(&q_target_rad[..joints.min(q_target_rad.len())]);
    let (positions, normals, forces) = (2 * joints, 2 * joints + 3 * fingers, 2 * joints + 6 * fingers);
    for (i, contact) in contacts.iter().enumerate() {
        if let Some(c) = contact {
            obs[positions + 3 * i..positions + 3 * i + 3].copy_from_slice(&c.position_m);
            obs[normals + 3 * i..normals + 3 * i + 3].copy_from_slice(&c.normal);
            obs[forces + i] = c.force_n;
        }
    }
    obs
}

/// The [`ObservationSet::Proprio`] observation: joint angles and targets now and at the
/// last `history` control steps, newest first. At an episode's start the past is the
/// present repeated (a hand at rest), so the first observation has the full size.
#[derive(Debug, Clone, PartialEq)]
pub struct ProprioHistory {
    history: usize,
    /// (q, q_target) of past steps, newest first, at most `history`.
    past: VecDeque<(Vec<f32>, Vec<f32>)>,
}

impl ProprioHistory {
    /// A history of `history` past steps, empty until [`Self::start`].
    #[must_use]
    pub fn new(history: usize) -> Self {
        Self { history, past: VecDeque::with_capacity(history + 1) }
    }

    /// Starts an episode at (`q_rad`, `q_target_rad`) and returns its first observation.
    pub fn start(&mut self, q_rad: &[f32], q_target_rad: &[f32]) -> Vec<f32> {
        self.past.clear();
        for _ in 0..self.history {
            self.past.push_back((q_rad.to_vec(), q_target_rad.to_vec()));
        }
        self.observe(q_rad, q_target_rad)
    }

    /// The observation at (`q_rad`, `q_target_rad`) after one more control step; the
    /// present then joins the past.
    pub fn step(&mut self, q_rad: &[f32], q_target_rad: &[f32]) -> Vec<f32> {
        let obs = self.observe(q_rad, q_target_rad);
        if self.history > 0 {
            self.past.pop_back();
            self.past.push_front((q_rad.to_vec(), q_target_rad.to_vec()));
        }
        obs
    }

    fn observe(&self, q_rad: &[f32], q_target_rad: &[f32]) -> Vec<f32> {
        let mut obs = Vec::with_capacity(2 * q_rad.len() * (1 + self.history));
        obs.extend_from_slice(q_rad);
        obs.extend_from_slice(q_target_rad);
        for (q, _) in &self.past {
            obs.extend_from_slice(q);
        }
        for (_, t) in &self.past {
            obs.extend_from_slice(t);
        }
        obs
    }
}

/// A policy's observation made from the env's full one ([`build_observation`]): the full
/// observation itself, or its joint angles and targets with their history. The same code
/// feeds a policy in training, evaluation and on the bridge.
#[derive(Debug, Clone, PartialEq)]
pub struct Observer {
    set: ObservationSet,
    num_joints: usize,
    history: ProprioHistory,
}

impl Observer {
    /// An observer of `set` for a hand of `num_joints` joints.
    #[must_use]
    pub fn new(set: ObservationSet, num_joints: usize) -> Self {
        let history = match set {
            ObservationSet::Full => 0,
            ObservationSet::Proprio { history } => history,
        };
        Self { set, num_joints, history: ProprioHistory::new(history) }
    }

    /// The set it observes.
    #[must_use]
    pub fn set(&self) -> ObservationSet {
        self.set
    }

    /// The policy's first observation of an episode, from the env's full one.
    pub fn start(&mut self, full: &[f32]) -> Vec<f32> {
        match self.set {
            ObservationSet::Full => full.to_vec(),
            ObservationSet::Proprio { .. } => {
                let (q, target) = self.joints(full);
                self.history.start(q, target)
            }
        }
    }

    /// The policy's observation after a control step, from the env's full one.
    pub fn step(&mut self, full: &[f32]) -> Vec<f32> {
        match self.set {
            ObservationSet::Full => full.to_vec(),
            ObservationSet::Proprio { .. } => {
                let (q, target) = self.joints(full);
                self.history.step(q, target)
            }
        }
    }

    /// The joint angles and targets at the front of a full observation (empty if it is short).
    fn joints<'a>(&self, full: &'a [f32]) -> (&'a [f32], &'a [f32]) {
        let j = self.num_joints;
        (full.get(..j).unwrap_or(&[]), full.get(j..2 * j).unwrap_or(&[]))
    }
}

impl ObservationSet {
    /// The set whose layout a policy file declares (its `obs_layout` slice names and ranges)
    /// for a hand of `num_joints` joints and `num_fingers` fingertips: refused when it is
    /// neither set's layout.
    pub fn of_layout(
        slices: &[(&str, usize, usize)],
        num_joints: usize,
        num_fingers: usize,
    ) -> Result<Self, String> {
        let past =
            slices.iter().find(|(n, _, _)| *n == "q_rad_past").map_or(0, |(_, a, b)| b.saturating_sub(*a));
        let candidates = if slices.iter().any(|(n, _, _)| CONTACT_SLICES.contains(n)) {
            vec![Self::Full]
        } else if num_joints > 0 && past % num_joints == 0 {
            vec![Self::Proprio { history: past / num_joints }]
        } else {
            Vec::new()
        };
        for set in candidates {
            let layout = ObservationLayout::new(set, num_joints, num_fingers);
            if layout.check(slices.iter().copied()).is_ok() {
                return Ok(set);
            }
        }
        let shown: Vec<String> = slices.iter().map(|(n, a, b)| format!("{n} {a}..{b}")).collect();
        Err(format!(
            "the policy observes [{}]: neither the full nor a proprio observation of a hand of {num_joints} joints and {num_fingers} fingertips",
            shown.join(", ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_full_layout_of_vge15_is_the_65_float_observation_and_other_hands_get_their_own_sizes() {
        let full = ObservationLayout::new(ObservationSet::Full, 15, 5);
        let names: Vec<(&str, Range<usize>)> = full.slices().to_vec();
        assert_eq!(
            names,
            [
                ("q_rad", 0..15),
                ("q_target_rad", 15..30),
                ("contact_position_m", 30..45),
                ("contact_normal", 45..60),
                ("contact_force_n", 60..65)
            ]
        );
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
        let err = full.check(proprio.slices().iter().map(|(n, r)| (*n, r.start, r.end))).expect_err("other");
        assert!(err.contains("q_rad_past"), "{err}");
    }

    #[test]
    fn observation_sets_read_back_their_names_and_refuse_others() {
        for set in [
            ObservationSet::Full,
            ObservationSet::Proprio { history: 0 },
            ObservationSet::Proprio { history: 3 },
        ] {
            assert_eq!(ObservationSet::parse(&set.name()), Ok(set));
        }
        for bad in ["", "Full", "proprio:", "proprio:x", "proprio:65", "proprio:-1"] {
            assert!(ObservationSet::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn contacts_land_in_their_slots_and_absent_ones_are_zero() {
        let q: Vec<f32> = (0..15).map(|j| j as f32).collect();
        let t: Vec<f32> = (0..15).map(|j| -(j as f32)).collect();
        let mut contacts = [None; 5];
        contacts[2] =
            Some(FingertipReading { position_m: [1.0, 2.0, 3.0], normal: [0.0, 1.0, 0.0], force_n: 4.5 });
        let obs = build_observation(&q, &t, &contacts);
        assert_eq!(obs.len(), ObservationLayout::new(ObservationSet::Full, 15, 5).dim());
        assert_eq!(obs[3], 3.0);
        assert_eq!(obs[15 + 3], -3.0);
        assert_eq!(&obs[36..39], &[1.0, 2.0, 3.0]);
        assert_eq!(&obs[51..54], &[0.0, 1.0, 0.0]);
        assert_eq!(obs[62], 4.5);
        assert!(obs[30..36].iter().chain(&obs[39..51]).chain(&obs[54..62]).all(|v| *v == 0.0));
        assert_eq!(obs[64], 0.0);
    }

    #[test]
    fn the_proprio_history_shifts_newest_first_and_starts_from_the_present() {
        let layout = ObservationLayout::new(ObservationSet::Proprio { history: 2 }, 2, 1);
        let mut h = ProprioHistory::new(2);
        let first = h.start(&[1.0, 2.0], &[3.0, 4.0]);
        assert_eq!(first, [1.0, 2.0, 3.0, 4.0, 1.0, 2.0, 1.0, 2.0, 3.0, 4.0, 3.0, 4.0]);
        assert_eq!(first.len(), layout.dim());
        let second = h.step(&[5.0, 6.0], &[7.0, 8.0]);
        assert_eq!(second, [5.0, 6.0, 7.0, 8.0, 1.0, 2.0, 1.0, 2.0, 3.0, 4.0, 3.0, 4.0]);
        let third = h.step(&[9.0, 10.0], &[11.0, 12.0]);
        assert_eq!(third, [9.0, 10.0, 11.0, 12.0, 5.0, 6.0, 1.0, 2.0, 7.0, 8.0, 3.0, 4.0]);
        assert_eq!(ProprioHistory::new(0).start(&[1.0], &[2.0]), [1.0, 2.0]);
    }

    #[test]
    fn an_observer_feeds_either_set_from_the_full_observation_and_a_layout_names_its_set() {
        let contacts =
            [Some(FingertipReading { position_m: [1.0; 3], normal: [0.0, 0.0, 1.0], force_n: 2.0 })];
        let full0 = build_observation(&[0.1, 0.2], &[0.3, 0.4], &contacts);
        let full1 = build_observation(&[0.5, 0.6], &[0.7, 0.8], &contacts);
        let mut same = Observer::new(ObservationSet::Full, 2);
        assert_eq!((same.start(&full0), same.step(&full1)), (full0.clone(), full1.clone()));
        let mut proprio = Observer::new(ObservationSet::Proprio { history: 1 }, 2);
        assert_eq!(proprio.start(&full0), [0.1, 0.2, 0.3, 0.4, 0.1, 0.2, 0.3, 0.4]);
        assert_eq!(proprio.step(&full1), [0.5, 0.6, 0.7, 0.8, 0.1, 0.2, 0.3, 0.4]);
        for set in [
            ObservationSet::Full,
            ObservationSet::Proprio { history: 0 },
            ObservationSet::Proprio { history: 3 },
        ] {
            let layout = ObservationLayout::new(set, 16, 4);
            let slices: Vec<(&str, usize, usize)> =
                layout.slices().iter().map(|(n, r)| (*n, r.start, r.end)).collect();
            assert_eq!(ObservationSet::of_layout(&slices, 16, 4), Ok(set));
            assert!(ObservationSet::of_layout(&slices, 15, 5).is_err(), "another hand's sizes");
        }
    }
}
