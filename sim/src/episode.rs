//! One episode's accounting, shared by every loop that runs episodes (training's envs,
//! `vge eval`, the controller rollouts, the bridge's sim summary) so that they all measure
//! return, rotation, contacts, contact switches and fingertip slip the same way.
//!
//! Rotation is the sum of each step's rotation about world z ([`crate::rotation_about_z_rad`],
//! never Euler yaw differences, which a tipped object games), so several turns add up; sums
//! are kept in f64 so that a 30 s episode loses nothing to rounding.

use serde::Serialize;

use crate::gait::ContactSwitches;

/// One episode's figures.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct EpisodeOutcome {
    /// Sum of the rewards.
    pub episode_return: f64,
    /// Object rotation about world z over the episode (rad, unwrapped; positive = the
    /// rewarded sense).
    pub rotation_rad: f64,
    /// The object's net rotation (rad, world frame): each step's rotation vector, summed
    /// ([`crate::angle::rotation_vector_rad`]); its z component is `rotation_rad`, and its
    /// direction the axis the object turned about overall.
    pub net_rotation_rad: [f64; 3],
    /// The env ended it early (a drop), as opposed to the time limit.
    pub terminated: bool,
    /// Mean number of fingertips touching the object after each step.
    pub mean_contacts: f64,
    /// Fingertips that broke and remade contact ([`ContactSwitches`]).
    pub contact_switches: u32,
    /// Fingertip slip (m): how far the fingertips' contact points travelled over the
    /// object, in its own frame, while they touched it ([`crate::slip`]). Zero for an object
    /// turned in a fixed grasp; a spin under fingertips that never let go slides them.
    pub tip_slip_m: f64,
    /// Control steps run.
    pub length: usize,
}

impl EpisodeOutcome {
    /// How far the axis the object turned about overall leans from world z (rad, 0 to π/2;
    /// [`crate::angle::rotation_axis_tilt_rad`] of `net_rotation_rad`).
    #[must_use]
    pub fn rotation_axis_tilt_rad(&self) -> f64 {
        crate::angle::rotation_axis_tilt_rad(self.net_rotation_rad)
    }

    /// The success test: a full turn (2π) about z without a drop.
    #[must_use]
    pub fn success(&self) -> bool {
        !self.terminated && self.rotation_rad >= std::f64::consts::TAU
    }

    /// The success test, with the object kept upright: a success whose overall turning axis
    /// leans at most `max_tilt_rad` from z. A tumble about a tilted axis can pass the success
    /// test on the z part of its turning alone; it does not pass this one.
    #[must_use]
    pub fn upright_success(&self, max_tilt_rad: f64) -> bool {
        self.success() && self.rotation_axis_tilt_rad() <= max_tilt_rad
    }
}

/// Accumulates one episode step by step.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EpisodeTracker {
    episode_return: f64,
    /// Each step's rotation vector, summed: its z component is the rotation about z.
    net_rotation_rad: [f64; 3],
    contact_sum: u64,
    length: usize,
    switches: ContactSwitches,
    tip_slip_m: f64,
}

impl EpisodeTracker {
    /// An episode that starts with fingertips `touching`.
    #[must_use]
    pub fn start(touching: &[bool]) -> Self {
        Self { switches: ContactSwitches::new(touching), ..Self::default() }
    }

    /// Records one step: its reward, the object's rotation during it as a world-frame rotation
    /// vector ([`crate::angle::rotation_vector_rad`]; its z component is the rotation about z
    /// the success test counts), the fingertips touching after it and their slip over the
    /// object during it ([`crate::slip::step_slip_m`]). Returns the contact switches completed
    /// on this step.
    pub fn record(&mut self, reward: f32, rotation_rad: [f32; 3], touching: &[bool], tip_slip_m: f32) -> u32 {
        self.episode_return += f64::from(reward);
        for (sum, v) in self.net_rotation_rad.iter_mut().zip(rotation_rad) {
            *sum += f64::from(v);
        }
        self.tip_slip_m += f64::from(tip_slip_m);
        self.contact_sum += touching.iter().filter(|&&t| t).count() as u64;
        self.length += 1;
        self.switches.update(touching)
    }

    /// Object rotation about z so far (rad, unwrapped).
    #[must_use]
    pub fn rotation_rad(&self) -> f64 {
        self.net_rotation_rad[2]
    }

    /// Steps recorded so far.
    #[must_use]
    pub fn length(&self) -> usize {
        self.length
    }

    /// The episode's figures, ended by a drop (`terminated`) or the time limit.
    #[must_use]
    pub fn outcome(&self, terminated: bool) -> EpisodeOutcome {
        EpisodeOutcome {
            episode_return: self.episode_return,
            rotation_rad: self.net_rotation_rad[2],
            net_rotation_rad: self.net_rotation_rad,
            terminated,
            mean_contacts: self.contact_sum as f64 / self.length.max(1) as f64,
            contact_switches: self.switches.count,
            tip_slip_m: self.tip_slip_m,
            length: self.length,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turns_add_up() {
        let mut t = EpisodeTracker::start(&[true; 5]);
        // 0.3 rad per step, 25 steps: 7.5 rad, more than a turn.
        for _ in 0..25 {
            t.record(1.0, [0.3, 0.0, 0.3], &[true; 5], 0.001);
        }
        let o = t.outcome(false);
        assert!((o.rotation_rad - 7.5).abs() < 1e-4, "{o:?}");
        assert!(o.success());
        assert!(!t.outcome(true).success(), "a drop never succeeds");
        assert_eq!((o.length, o.episode_return, o.mean_contacts), (25, 25.0, 5.0));
        assert!((o.tip_slip_m - 0.025).abs() < 1e-6, "slip adds up: {o:?}");
        assert!((o.net_rotation_rad[0] - 7.5).abs() < 1e-4, "the rotation vector adds up: {o:?}");
        assert!((o.rotation_axis_tilt_rad() - std::f64::consts::FRAC_PI_4).abs() < 1e-6, "{o:?}");
        // Turned about an axis 45 deg from z: a success, upright only under a looser bound.
        assert!(!o.upright_success(0.7) && o.upright_success(0.8), "{o:?}");
        assert!(!t.outcome(true).upright_success(std::f64::consts::FRAC_PI_2), "a drop never succeeds");
    }

    #[test]
    fn contacts_average_and_switches_count() {
        let touching = [true, true, true, true, false];
        let mut t = EpisodeTracker::start(&touching);
        let detached = [false, true, true, true, false];
        let mut completed = 0;
        for _ in 0..crate::gait::MIN_DETACH_STEPS {
            completed += t.record(0.0, [0.0; 3], &detached, 0.0);
        }
        completed += t.record(0.0, [0.0; 3], &touching, 0.0);
        let o = t.outcome(false);
        assert_eq!((completed, o.contact_switches), (1, 1));
        assert!((o.mean_contacts - (3.0 * 3.0 + 4.0) / 4.0).abs() < 1e-12);
        assert!(!o.success(), "no rotation");
    }
}
