//! The grasp map G of a set of point contacts on the object. It depends on the contact
//! points and the object centre only, not on the hand.
//!
//! Convention: G is 6 x 3k with column block i = `[I3; [r_i]x]`, r_i = p_i - c (contact
//! point minus object centre, world frame). Then
//! - the wrench on the object from stacked contact forces f (forces *on the object*) is
//!   `w = G f`, with w = [force; torque about the object centre];
//! - the velocities of the contact points, seen as points of the object moving with
//!   twist [v; omega] (v = velocity of the centre, omega = angular velocity, world frame),
//!   are `G^T [v; omega]` (v + omega x r_i).
//!
//! The paper writes both `w = G_S^T f` and `J_S dq = G_S^T do`, which cannot hold with one
//! G_S dimensionally (J_S dq has 3k rows). We use G (6 x 3k) with `w = G f` and
//! `J_S dq = G^T do`: the standard grasp-map duality.

use nalgebra::{DMatrix, Matrix3, RealField, Vector3};

use super::ControllerError;

/// G (6 x 3k) for contact points `contact_points_m` on an object centred at
/// `object_position_m` (all world frame); see the module docs for the convention. Generic
/// so that IGM can build it in f64 from the simulator's f32 points.
pub fn grasp_map<T: RealField + Copy>(
    contact_points_m: &[Vector3<T>],
    object_position_m: Vector3<T>,
) -> Result<DMatrix<T>, ControllerError> {
    if !object_position_m.iter().all(|c| c.is_finite()) {
        return Err(ControllerError::NonFinite("object position".to_owned()));
    }
    if let Some(i) = contact_points_m.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(ControllerError::NonFinite(format!("contact point {i}")));
    }
    Ok(grasp_map_unchecked(contact_points_m, &object_position_m))
}

pub(crate) fn grasp_map_unchecked<T: RealField + Copy>(
    contact_points_m: &[Vector3<T>],
    object_position_m: &Vector3<T>,
) -> DMatrix<T> {
    let mut grasp = DMatrix::zeros(6, 3 * contact_points_m.len());
    for (i, point) in contact_points_m.iter().enumerate() {
        let lever = point - object_position_m;
        grasp.fixed_view_mut::<3, 3>(0, 3 * i).copy_from(&Matrix3::identity());
        grasp.fixed_view_mut::<3, 3>(3, 3 * i).copy_from(&lever.cross_matrix());
    }
    grasp
}
