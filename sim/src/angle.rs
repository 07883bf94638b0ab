//! How far an object turned about world z between two orientations, and how far it tipped. Physics-free (it stays in the crate without the `physics` feature), since
//! episode accounting and the bridge use it as well as the env.

use nalgebra::UnitQuaternion;

/// Rotation about world z (rad) from orientation `before` to `after`: the z component of the
/// world-frame rotation vector of `after * before⁻¹`, i.e. the angular velocity about z
/// integrated over the interval (exact for a rotation about z, and for a short interval in
/// general). The reward and the success test's rotation are sums of this.
///
/// Not a difference of Euler yaw angles: at a tilt near 90° (pitch ±π/2, gimbal lock) the
/// Euler yaw swings by radians while the object barely moves, and a plain RL policy learned
/// to tip the cube onto its side and wiggle it there, "turning" it 166 rad in 30 s with
/// three fingertips resting on it (docs/results/euler-yaw-reward/rl-exploit/).
#[must_use]
pub fn rotation_about_z_rad(before: &UnitQuaternion<f32>, after: &UnitQuaternion<f32>) -> f32 {
    (after * before.inverse()).scaled_axis().z
}

/// The world-frame rotation vector (rad) from orientation `before` to `after`: the axis of
/// `after * before⁻¹` scaled by its angle; its z component is [`rotation_about_z_rad`]. Summed
/// over an episode, wobbles cancel and what remains points along the axis the object turned
/// about overall ([`rotation_axis_tilt_rad`]).
#[must_use]
pub fn rotation_vector_rad(before: &UnitQuaternion<f32>, after: &UnitQuaternion<f32>) -> [f32; 3] {
    let v = (after * before.inverse()).scaled_axis();
    [v.x, v.y, v.z]
}

/// How far the axis of a (summed) rotation vector leans from world z (rad, 0 to π/2, either
/// sense of turning): 0 for an object turned upright about z, π/2 for one rolled about a
/// horizontal axis; 0 for no rotation. A tumble about a tilted axis passes the success test
/// on the z part of its turning alone; this says how tilted it was.
#[must_use]
pub fn rotation_axis_tilt_rad(rotation_vector_rad: [f64; 3]) -> f64 {
    let [x, y, z] = rotation_vector_rad;
    x.hypot(y).atan2(z.abs())
}

/// How far an object has tipped since orientation `reference` (rad, 0 to π): the angle
/// between world z and where the object's axis that pointed along world z at `reference`
/// points now. 0 for any turn about z, whatever its size; a cube rolled onto its side reads
/// π/2. Where [`rotation_axis_tilt_rad`] judges an episode's turning after the fact, this is
/// the state at one instant, which an env can end an episode on.
#[must_use]
pub fn tilt_rad(reference: &UnitQuaternion<f32>, now: &UnitQuaternion<f32>) -> f32 {
    let axis = (now * reference.inverse()) * nalgebra::Vector3::z();
    axis.x.hypot(axis.y).atan2(axis.z)
}

#[cfg(test)]
mod tests {
    use nalgebra::{UnitQuaternion, Vector3};
    use std::f32::consts::PI;

    use super::rotation_about_z_rad;

    /// Angle wrapped to (-pi, pi]: how an Euler-yaw difference was measured before.
    fn wrap_angle_rad(a: f32) -> f32 {
        let a = a % (2.0 * PI);
        if a > PI {
            a - 2.0 * PI
        } else if a <= -PI {
            a + 2.0 * PI
        } else {
            a
        }
    }

    #[test]
    fn rotation_about_z_is_the_turn_about_world_z_at_any_tilt() {
        let z = |a: f32| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
        // Upright: the turn itself, also across ±π.
        assert!((rotation_about_z_rad(&z(3.0), &z(3.2)) - 0.2).abs() < 1e-5);
        assert!((rotation_about_z_rad(&z(0.5), &z(0.3)) + 0.2).abs() < 1e-5);
        // Tipped onto its side (pitch 89.5°), then a turn of 0.2 rad about world z: still 0.2.
        let tipped = UnitQuaternion::from_euler_angles(0.3, 1.562, -1.0);
        assert!((rotation_about_z_rad(&tipped, &(z(0.2) * tipped)) - 0.2).abs() < 1e-5);
        // At that tilt a 0.05 rad wiggle about world x swings the Euler yaw by far more, yet
        // turns nothing about z.
        let wiggled = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.05) * tipped;
        let euler_yaw_change = wrap_angle_rad(wiggled.euler_angles().2 - tipped.euler_angles().2);
        assert!(euler_yaw_change.abs() > 0.5, "Euler yaw moved only {euler_yaw_change}");
        assert!(rotation_about_z_rad(&tipped, &wiggled).abs() < 1e-5);
    }

    #[test]
    fn wraps_angles_into_minus_pi_exclusive_to_pi_inclusive() {
        assert!((wrap_angle_rad(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-5);
        assert!((wrap_angle_rad(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-5);
        assert_eq!(wrap_angle_rad(0.25), 0.25);
        assert_eq!(wrap_angle_rad(PI), PI);
        assert_eq!(wrap_angle_rad(-PI), PI);
    }

    #[test]
    fn a_turn_about_a_tilted_axis_reads_its_tilt_and_a_wobble_cancels() {
        use super::{rotation_axis_tilt_rad, rotation_vector_rad};
        let tilt_rad = 60f32.to_radians();
        let axis = nalgebra::Unit::new_normalize(Vector3::new(0.0, tilt_rad.sin(), -tilt_rad.cos()));
        let mut orientation = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3);
        let mut sum = [0.0f64; 3];
        let mut add = |before: &UnitQuaternion<f32>, after: &UnitQuaternion<f32>| {
            let v = rotation_vector_rad(before, after);
            assert!((v[2] - rotation_about_z_rad(before, after)).abs() < 1e-7);
            sum.iter_mut().zip(v).for_each(|(s, v)| *s += f64::from(v));
        };
        for k in 0..40 {
            // A turn about the tilted axis, with a wobble about x back and forth.
            let wobble =
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), if k % 2 == 0 { 0.2 } else { -0.2 });
            let after = wobble * UnitQuaternion::from_axis_angle(&axis, 0.05) * orientation;
            add(&orientation, &after);
            orientation = after;
        }
        assert!((rotation_axis_tilt_rad(sum) - f64::from(tilt_rad)).abs() < 0.03, "{sum:?}");
        assert_eq!(rotation_axis_tilt_rad([0.0, 0.0, -3.0]), 0.0, "either sense about z is upright");
        assert_eq!(rotation_axis_tilt_rad([0.0; 3]), 0.0);
    }

    #[test]
    fn tilt_ignores_turns_about_z_and_reads_a_roll() {
        use super::tilt_rad;
        let reference = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7);
        let turned = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 2.5) * reference;
        assert!(tilt_rad(&reference, &turned) < 1e-6, "a turn about z is no tilt");
        for roll_rad in [0.1f32, 0.6, 1.2, 2.0, 3.0] {
            let rolled = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), roll_rad) * turned;
            assert!((tilt_rad(&reference, &rolled) - roll_rad).abs() < 1e-5, "{roll_rad}");
        }
    }
}
