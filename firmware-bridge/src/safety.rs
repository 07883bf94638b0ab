//! The last line before the motors: every commanded target is finite, within the joint
//! limits, and no further than a fixed step from the previous safe target.

use vge_hand::JointLimit;

/// What the filter did to one proposed command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SafetyCounts {
    /// Proposals that contained NaN/inf: the previous safe targets were held instead.
    pub non_finite_holds: u64,
    /// Joint deltas cut to the per-step maximum.
    pub delta_clamps: u64,
    /// Joint targets cut to the joint limits.
    pub limit_clamps: u64,
}

/// The filter of a hand's joints, as many as its limits (vge15's 15, the Allegro's 16).
#[derive(Debug, Clone)]
pub struct SafetyFilter {
    max_delta_rad: f32,
    limits: Vec<JointLimit>,
    last_safe_rad: Vec<f32>,
    pub counts: SafetyCounts,
}

impl SafetyFilter {
    /// `start_rad` (e.g. the measured joint positions) becomes the first safe target; it is
    /// clamped into the limits. A joint `start_rad` lacks starts at the middle of its range.
    pub fn new(max_delta_rad: f32, limits: Vec<JointLimit>, start_rad: &[f32]) -> Self {
        let last_safe_rad = limits
            .iter()
            .enumerate()
            .map(|(i, l)| l.clamp(start_rad.get(i).copied().unwrap_or(0.5 * (l.lower_rad + l.upper_rad))))
            .collect();
        Self { max_delta_rad: max_delta_rad.abs(), limits, last_safe_rad, counts: SafetyCounts::default() }
    }

    /// Joints filtered.
    pub fn num_joints(&self) -> usize {
        self.limits.len()
    }

    pub fn last_safe_rad(&self) -> &[f32] {
        &self.last_safe_rad
    }

    /// Moves the safe targets towards proposed absolute targets (a PD loop's): the same
    /// checks as [`Self::apply_delta`] on the change they ask for.
    pub fn apply_target(&mut self, target_rad: &[f32]) -> &[f32] {
        let delta: Vec<f32> = (0..self.num_joints())
            .map(|i| target_rad.get(i).map_or(f32::NAN, |t| t - self.last_safe_rad[i]))
            .collect();
        self.apply_delta(&delta)
    }

    /// Applies a proposed change of the targets and returns the safe targets to send. A
    /// proposal with a non-finite entry, or with another number of joints than the hand's, is
    /// not applied: the last safe targets hold.
    pub fn apply_delta(&mut self, delta_rad: &[f32]) -> &[f32] {
        if delta_rad.len() != self.num_joints() || delta_rad.iter().any(|d| !d.is_finite()) {
            self.counts.non_finite_holds += 1;
            return &self.last_safe_rad;
        }
        for (i, &d) in delta_rad.iter().enumerate() {
            let clamped = d.clamp(-self.max_delta_rad, self.max_delta_rad);
            if clamped != d {
                self.counts.delta_clamps += 1;
            }
            let proposed = self.last_safe_rad[i] + clamped;
            let limited = self.limits[i].clamp(proposed);
            if limited != proposed {
                self.counts.limit_clamps += 1;
            }
            self.last_safe_rad[i] = limited;
        }
        &self.last_safe_rad
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> Vec<JointLimit> {
        vec![JointLimit { lower_rad: -0.5, upper_rad: 0.5 }; 15]
    }

    #[test]
    fn clamps_deltas_and_limits_and_holds_on_nan() {
        let mut f = SafetyFilter::new(0.05, limits(), &[0.0; 15]);
        let mut d = [0.01; 15];
        d[0] = 1.0;
        d[1] = -1.0;
        let t = f.apply_delta(&d).to_vec();
        assert_eq!((t[0], t[1], t[2]), (0.05, -0.05, 0.01));
        assert_eq!(f.counts.delta_clamps, 2);
        for _ in 0..20 {
            f.apply_delta(&[0.05; 15]);
        }
        assert_eq!(f.last_safe_rad()[3], 0.5);
        assert!(f.counts.limit_clamps > 0);
        let before = f.last_safe_rad().to_vec();
        let mut bad = [0.0; 15];
        bad[7] = f32::NAN;
        assert_eq!(f.apply_delta(&bad), before);
        bad[7] = f32::INFINITY;
        assert_eq!(f.apply_delta(&bad), before);
        assert_eq!(f.counts.non_finite_holds, 2);
        assert_eq!(f.apply_delta(&[0.01; 14]), before, "another joint count holds");
        assert_eq!(f.counts.non_finite_holds, 3);
    }

    #[test]
    fn absolute_targets_are_approached_a_step_at_a_time_and_nan_holds() {
        let limits = vec![JointLimit { lower_rad: -0.5, upper_rad: 0.5 }; 16];
        let mut f = SafetyFilter::new(0.05, limits, &[0.0; 16]);
        let mut goal = [0.12; 16];
        goal[3] = 9.0;
        assert_eq!(f.apply_target(&goal)[0], 0.05);
        f.apply_target(&goal);
        let t = f.apply_target(&goal).to_vec();
        assert!((t[0] - 0.12).abs() < 1e-6 && t[3] == 0.15, "{t:?}");
        for _ in 0..20 {
            f.apply_target(&goal);
        }
        assert_eq!(f.last_safe_rad()[3], 0.5);
        goal[7] = f32::NAN;
        let before = f.last_safe_rad().to_vec();
        assert_eq!(f.apply_target(&goal), before);
        assert_eq!(f.counts.non_finite_holds, 1);
    }

    #[test]
    fn start_outside_the_limits_is_pulled_in() {
        let f = SafetyFilter::new(0.05, limits(), &[2.0; 15]);
        assert_eq!(f.last_safe_rad(), [0.5; 15]);
    }
}
