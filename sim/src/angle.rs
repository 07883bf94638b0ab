//! Angles: the one yaw-difference helper. Physics-free (it stays in the crate without the
//! `physics` feature), since episode accounting and the bridge use it as well as the env.

/// Angle wrapped to (-pi, pi]: the one helper every yaw difference in vge goes through
/// (env, eval, rollouts, the bridge's sim summary).
#[must_use]
pub fn wrap_angle_rad(a: f32) -> f32 {
    use std::f32::consts::PI;
    let a = a % (2.0 * PI);
    if a > PI {
        a - 2.0 * PI
    } else if a <= -PI {
        a + 2.0 * PI
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::wrap_angle_rad;
    use std::f32::consts::PI;

    #[test]
    fn wraps_angles_into_minus_pi_exclusive_to_pi_inclusive() {
        assert!((wrap_angle_rad(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-5);
        assert!((wrap_angle_rad(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-5);
        assert_eq!(wrap_angle_rad(0.25), 0.25);
        assert_eq!(wrap_angle_rad(PI), PI);
        assert_eq!(wrap_angle_rad(-PI), PI);
    }
}
