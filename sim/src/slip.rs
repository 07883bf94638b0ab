//! Fingertip slip: how far the fingertips' contact points travel over the object's surface,
//! the figure that tells finger gaiting (tips stay put on the object and are moved by
//! breaking and remaking contact) from spinning the object under fingertips that never let
//! go (they slide over its faces, with zero contact switches).
//!
//! Per control step, for each fingertip touching the object both before and after the step,
//! the distance between its contact points before and after, both expressed in the object's
//! own frame: the object turning with a fixed grasp moves no contact point in its frame and
//! counts zero, a fingertip sliding over a face counts its path. A fingertip rolling over
//! the surface moves the contact point too, and counts. A fingertip that breaks contact
//! starts fresh when it touches again (that is a contact switch, [`crate::gait`]). Summed
//! over fingertips and steps it is an episode's `tip_slip_m` ([`crate::EpisodeTracker`]).
//!
//! The contact point is the impulse-weighted mean of the solver's contact points, so a
//! resting fingertip whose contact spreads over several points reads a small jitter; the
//! still-hand test bounds it.

use nalgebra::{Isometry3, Point3, Vector3};

/// Each fingertip's contact point in the object's frame (m), `None` where it does not touch:
/// world points `contacts_world_m` of an object at `object_pose`.
#[must_use]
pub fn contact_points_in_object_frame(
    object_pose: &Isometry3<f32>,
    contacts_world_m: impl IntoIterator<Item = Option<Vector3<f32>>>,
) -> Vec<Option<Point3<f32>>> {
    contacts_world_m
        .into_iter()
        .map(|p| p.map(|p| object_pose.inverse_transform_point(&Point3::from(p))))
        .collect()
}

/// The step's slip (m): the summed distance, in the object's frame, between each
/// fingertip's contact point `before` and `after` the step, over the fingertips touching at
/// both (in finger order; a fingertip missing from either side counts zero).
#[must_use]
pub fn step_slip_m(before: &[Option<Point3<f32>>], after: &[Option<Point3<f32>>]) -> f32 {
    before.iter().zip(after).filter_map(|(b, a)| Some(nalgebra::distance(&(*b)?, &(*a)?))).sum()
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};

    use super::*;

    /// Three fingertips on a 6.5 cm cube's side faces (object frame).
    fn grasp() -> Vec<Vector3<f32>> {
        vec![
            Vector3::new(0.0325, 0.0, 0.0),
            Vector3::new(-0.0325, 0.01, 0.0),
            Vector3::new(0.0, 0.0325, 0.005),
        ]
    }

    fn pose(yaw_rad: f32) -> Isometry3<f32> {
        Isometry3::from_parts(
            Translation3::new(0.01, -0.02, 0.1),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_rad),
        )
    }

    /// World points of object-frame points on an object at `pose`.
    fn world(pose: &Isometry3<f32>, points: &[Vector3<f32>]) -> Vec<Option<Vector3<f32>>> {
        points.iter().map(|p| Some((pose * Point3::from(*p)).coords)).collect()
    }

    #[test]
    fn an_object_turning_in_a_fixed_grasp_slips_nothing() {
        let (a, b) = (pose(0.0), pose(0.7));
        let before = contact_points_in_object_frame(&a, world(&a, &grasp()));
        let after = contact_points_in_object_frame(&b, world(&b, &grasp()));
        let slip = step_slip_m(&before, &after);
        assert!(slip < 1e-6, "{slip} m");
    }

    #[test]
    fn an_object_turning_under_fixed_fingertips_slips_their_arcs() {
        // The fingertips stay where they are in the world while the object turns 0.1 rad
        // about its z: each contact point moves over the object by its chord about the axis.
        let (a, b) = (pose(0.0), pose(0.1));
        let tips = world(&a, &grasp());
        let before = contact_points_in_object_frame(&a, tips.clone());
        let after = contact_points_in_object_frame(&b, tips);
        let chord = |p: &Vector3<f32>| 2.0 * p.xy().norm() * (0.05f32).sin();
        let expected: f32 = grasp().iter().map(chord).sum();
        let slip = step_slip_m(&before, &after);
        assert!((slip - expected).abs() < 1e-6, "{slip} m against {expected} m");
        assert!(slip > 0.009, "three tips ~3 cm from the axis, 0.1 rad: ~1 cm: {slip} m");
    }

    #[test]
    fn a_fingertip_counts_only_while_it_touches_before_and_after() {
        let a = pose(0.0);
        let tips = grasp();
        let before = contact_points_in_object_frame(&a, world(&a, &tips));
        // Finger 0 slides 2 mm along y; finger 1 lets go; finger 2 stays.
        let mut moved = world(&a, &tips);
        moved[0] = Some((a * Point3::from(tips[0] + Vector3::new(0.0, 0.002, 0.0))).coords);
        moved[1] = None;
        let after = contact_points_in_object_frame(&a, moved);
        assert!((step_slip_m(&before, &after) - 0.002).abs() < 1e-6);
        // Touching again: no slip counted for the step that remade contact.
        let again = contact_points_in_object_frame(&a, world(&a, &tips));
        assert!((step_slip_m(&after, &again) - 0.002).abs() < 1e-6, "finger 1 starts fresh");
    }
}
