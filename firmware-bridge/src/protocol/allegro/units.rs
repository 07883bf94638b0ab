//! Counts on the wire to physical units, as Wonik's drivers convert them.

use super::{AllegroError, Finger, JOINTS_PER_FINGER, NUM_FINGERS};

/// Degrees per position count: every driver converts with `333.3 / 65536` (the user manual's
/// equation differs by 1%, see docs/allegro-protocol.md).
pub const POSITION_DEG_PER_COUNT: f64 = 333.3 / 65536.0;
/// Radians per position count (8.876e-5 rad; the i16 range is ±2.9086 rad).
pub const POSITION_RAD_PER_COUNT: f64 = POSITION_DEG_PER_COUNT * core::f64::consts::PI / 180.0;

/// A joint angle from its position count.
pub fn counts_to_rad(count: i16) -> f32 {
    (f64::from(count) * POSITION_RAD_PER_COUNT) as f32
}

/// The position count nearest to `q_rad`; an error when it is not finite or outside the i16
/// range (a measurement is reported as it is, never clipped).
pub fn rad_to_counts(q_rad: f32) -> Result<i16, AllegroError> {
    let (min, max) = (counts_to_rad(i16::MIN), counts_to_rad(i16::MAX));
    if !q_rad.is_finite() || !(min..=max).contains(&q_rad) {
        return Err(AllegroError::OutOfRange { what: "q_rad", value: q_rad, min, max });
    }
    let count = round_half_away(f64::from(q_rad) / POSITION_RAD_PER_COUNT);
    Ok(count.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16)
}

/// Round half away from zero without std; `|x|` is a few times 32768 at most here.
fn round_half_away(x: f64) -> f64 {
    let t = x as i64 as f64;
    let frac = x - t;
    if frac >= 0.5 {
        t + 1.0
    } else if frac <= -0.5 {
        t - 1.0
    } else {
        t
    }
}

/// Joint torque to the PWM counts of a set-torque frame, and the per-joint clips.
///
/// The drivers multiply torque by a hardware constant (1200 on a v4 at 12 V, 800 on earlier
/// hands at 8 V) and clip each joint's PWM to its own limit (`PWM_LIMIT_*` of
/// allegro_hand_ros_v4's AllegroHandDrv.cpp, the same as allegro_hand_ros2's torque limits
/// times 1200). The drivers publish that torque as joint effort in N·m; Wonik publishes no
/// calibration from PWM to measured torque, so `_nm` here is the drivers' nominal N·m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueScale {
    /// PWM counts per N·m.
    pub pwm_per_nm: f32,
    /// Largest |PWM count| per finger and joint, in frame order.
    pub pwm_limit: [[i16; JOINTS_PER_FINGER]; NUM_FINGERS],
}

/// Per-joint PWM limits: the drivers' base limits times 1.5, fingers index, middle, ring
/// alike (roll, proximal, middle, distal) and the thumb's own.
const PWM_LIMITS: [[i16; JOINTS_PER_FINGER]; NUM_FINGERS] =
    [[375, 675, 450, 285], [375, 675, 450, 285], [375, 675, 450, 285], [525, 405, 270, 270]];

/// A frame's four torques as PWM counts, and which of them the clip changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PwmCounts {
    pub counts: [i16; JOINTS_PER_FINGER],
    pub clipped: [bool; JOINTS_PER_FINGER],
}

impl TorqueScale {
    /// Allegro Hand v4 at 12 V: 1200 counts per N·m, the drivers' clips (each below the
    /// 1200-count global limit).
    pub const V4_12V: Self = Self { pwm_per_nm: 1200.0, pwm_limit: PWM_LIMITS };
    /// Earlier hands (hardware version below 4) at 8 V: 800 counts per N·m, the same clips
    /// (each below the 800-count global limit).
    pub const V3_8V: Self = Self { pwm_per_nm: 800.0, pwm_limit: PWM_LIMITS };

    /// The scale for a hand reporting `hardware_major` in its info frame, as
    /// allegro_hand_ros_v4 picks it: v4 for 4, v3 otherwise.
    pub fn for_hardware(hardware_major: u8) -> Self {
        if hardware_major == 4 { Self::V4_12V } else { Self::V3_8V }
    }

    /// Whether the scale is usable: a finite positive counts-per-N·m and non-negative clips.
    pub fn validate(&self) -> Result<(), AllegroError> {
        if !(self.pwm_per_nm.is_finite() && self.pwm_per_nm > 0.0) {
            return Err(AllegroError::BadConfig("pwm_per_nm must be finite and positive"));
        }
        if self.pwm_limit.iter().flatten().any(|&l| l < 0) {
            return Err(AllegroError::BadConfig("a PWM limit is negative"));
        }
        Ok(())
    }

    /// The clip of `finger`'s `joint` in N·m.
    pub fn limit_nm(&self, finger: Finger, joint: usize) -> f32 {
        let limit = self.pwm_limit[usize::from(finger.index())].get(joint).copied().unwrap_or(0);
        // As `to_nm` converts, so that a frame at the clip decodes to exactly this value.
        (f64::from(limit) / f64::from(self.pwm_per_nm)) as f32
    }

    /// `finger`'s torques as PWM counts: scaled, clipped to each joint's limit, rounded to
    /// the nearest count. A non-finite torque is an error; a finite one beyond its clip is
    /// clipped (as the drivers do) and marked in `clipped`.
    pub fn to_pwm(
        &self,
        finger: Finger,
        tau_nm: [f32; JOINTS_PER_FINGER],
    ) -> Result<PwmCounts, AllegroError> {
        let limits = self.pwm_limit[usize::from(finger.index())];
        let mut out = PwmCounts { counts: [0; JOINTS_PER_FINGER], clipped: [false; JOINTS_PER_FINGER] };
        for (joint, &tau) in tau_nm.iter().enumerate() {
            if !tau.is_finite() {
                return Err(AllegroError::NonFiniteTorque {
                    finger: finger.index(),
                    joint: joint as u8,
                    value: tau,
                });
            }
            // A negative limit (refused by validate) clips to zero rather than panicking.
            let limit = f64::from(limits[joint].max(0));
            let pwm = f64::from(tau) * f64::from(self.pwm_per_nm);
            let clipped = if pwm > limit {
                limit
            } else if pwm < -limit {
                -limit
            } else {
                round_half_away(pwm).clamp(-limit, limit)
            };
            out.clipped[joint] = pwm.abs() > limit;
            out.counts[joint] = clipped as i16;
        }
        Ok(out)
    }

    /// Torques in N·m of a frame's PWM counts.
    pub fn to_nm(&self, counts: [i16; JOINTS_PER_FINGER]) -> [f32; JOINTS_PER_FINGER] {
        counts.map(|c| (f64::from(c) / f64::from(self.pwm_per_nm)) as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_convert_as_the_drivers_do() {
        // allegro_hand_ros_v4: q = count * (333.3 / 65536) * (pi / 180).
        assert!((counts_to_rad(1000) - 0.088_763_16).abs() < 1e-7);
        assert_eq!(rad_to_counts(counts_to_rad(1000)), Ok(1000));
        for count in [i16::MIN, -1, 0, 1, 12345, i16::MAX] {
            assert_eq!(rad_to_counts(counts_to_rad(count)), Ok(count), "{count}");
        }
        // Half a count rounds away from zero.
        let half = (1.5 * POSITION_RAD_PER_COUNT) as f32;
        assert_eq!(rad_to_counts(half), Ok(2));
        assert_eq!(rad_to_counts(-half), Ok(-2));
        assert!(matches!(rad_to_counts(3.0), Err(AllegroError::OutOfRange { .. })));
        assert!(matches!(rad_to_counts(f32::NAN), Err(AllegroError::OutOfRange { .. })));
    }

    #[test]
    fn torques_scale_and_clip_per_joint() {
        let s = TorqueScale::V4_12V;
        let out = s.to_pwm(Finger::Index, [0.1, -0.2, 0.0, 0.0001]).expect("finite");
        assert_eq!(out.counts, [120, -240, 0, 0]);
        assert_eq!(out.clipped, [false; 4]);
        // Beyond the clip: index roll 375, proximal 675, middle 450, distal 285 counts.
        let out = s.to_pwm(Finger::Index, [1.0, -1.0, 100.0, -1e30]).expect("finite");
        assert_eq!(out.counts, [375, -675, 450, -285]);
        assert_eq!(out.clipped, [true; 4]);
        let out = s.to_pwm(Finger::Thumb, [1.0, 1.0, -1.0, f32::MAX]).expect("finite");
        assert_eq!(out.counts, [525, 405, -270, 270]);
        // Exactly at the clip is not clipped.
        let out = s.to_pwm(Finger::Thumb, [0.4375, 0.0, 0.0, 0.0]).expect("finite");
        assert_eq!((out.counts[0], out.clipped[0]), (525, false));
        assert_eq!(s.limit_nm(Finger::Ring, 1), 0.5625);
        assert_eq!(s.limit_nm(Finger::Thumb, 3), 0.225);
        assert_eq!(
            s.to_pwm(Finger::Middle, [0.0, f32::INFINITY, 0.0, 0.0]),
            Err(AllegroError::NonFiniteTorque { finger: 1, joint: 1, value: f32::INFINITY })
        );
        assert!(s.to_pwm(Finger::Middle, [f32::NAN, 0.0, 0.0, 0.0]).is_err());
        assert_eq!(s.to_nm([120, -240, 0, 675]), [0.1, -0.2, 0.0, 0.5625]);
    }

    #[test]
    fn the_hardware_version_picks_the_scale() {
        assert_eq!(TorqueScale::for_hardware(4), TorqueScale::V4_12V);
        assert_eq!(TorqueScale::for_hardware(3), TorqueScale::V3_8V);
        assert_eq!(TorqueScale::V3_8V.to_pwm(Finger::Index, [0.1; 4]).map(|p| p.counts), Ok([80; 4]));
        let bad = TorqueScale { pwm_per_nm: 0.0, ..TorqueScale::V4_12V };
        assert!(bad.validate().is_err());
        let negative = TorqueScale { pwm_limit: [[-1; 4]; 4], ..TorqueScale::V4_12V };
        assert!(negative.validate().is_err());
        // Even so, encoding does not panic: a negative limit clips to zero.
        assert_eq!(negative.to_pwm(Finger::Ring, [0.5; 4]).map(|p| p.counts), Ok([0; 4]));
        let nan = TorqueScale { pwm_per_nm: f32::NAN, ..TorqueScale::V4_12V };
        assert!(nan.validate().is_err());
        assert!(nan.to_pwm(Finger::Ring, [0.5; 4]).is_ok());
    }
}
