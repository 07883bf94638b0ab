//! Forward kinematics and analytic Jacobians of one finger.
//!
//! Written generically over [`RealField`] so that the same code runs in `f32` for the
//! simulator and in `f64` for numerical checks (f32 finite differences are too noisy to
//! validate a Jacobian to 1e-3).

use nalgebra::{Isometry3, Matrix3, Point3, RealField, Translation3, UnitQuaternion, Vector3};

use super::error::KinematicsError;
use super::hand::{FingerModel, JOINTS_PER_FINGER};

/// `f32` model data to the computation scalar (exact for f32 and f64).
fn lift<T: RealField + Copy>(x: f32) -> T {
    nalgebra::convert(f64::from(x))
}

fn lift_isometry<T: RealField + Copy>(iso: &Isometry3<f32>) -> Isometry3<T> {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Isometry3::from_parts(
        Translation3::new(lift(t.x), lift(t.y), lift(t.z)),
        UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(lift(q.w), lift(q.i), lift(q.j), lift(q.k))),
    )
}

pub(crate) fn check_joints<T: RealField + Copy>(q: &[T]) -> Result<(), KinematicsError> {
    match q.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(KinematicsError::NonFiniteJoint { index }),
        None => Ok(()),
    }
}

pub(crate) fn check_vector<T: RealField + Copy>(
    v: &Vector3<T>,
    what: impl FnOnce() -> String,
) -> Result<(), KinematicsError> {
    if v.iter().all(|c| c.is_finite()) {
        Ok(())
    } else {
        Err(KinematicsError::NonFiniteInput { what: what() })
    }
}

impl FingerModel {
    /// World frames of the finger at joint angles `q_rad` = [roll, flex_prox, flex_dist]:
    /// `[base, after roll, after proximal flexion, after distal flexion]`.
    ///
    /// Frame `k >= 1` has its origin on joint `k - 1`'s axis; the roll axis is frame 1's
    /// +x, the flexion axes are frames 2 and 3's +y. The proximal link runs from frame 2's
    /// origin along its -z for `proximal_length_m` (to frame 3's origin), the distal link
    /// from frame 3's origin along its -z for `distal_length_m` (to the fingertip centre).
    /// The simulator places its link bodies with these frames.
    pub fn frames<T: RealField + Copy>(
        &self,
        q_rad: &[T; JOINTS_PER_FINGER],
    ) -> Result<[Isometry3<T>; JOINTS_PER_FINGER + 1], KinematicsError> {
        check_joints(q_rad)?;
        let zero = T::zero();
        let base = lift_isometry::<T>(&self.base_in_world);
        let after_roll = base * Isometry3::rotation(Vector3::x() * q_rad[0]);
        let after_prox = after_roll * Isometry3::rotation(Vector3::y() * q_rad[1]);
        let to_distal_joint = Isometry3::translation(zero, zero, -lift::<T>(self.proximal_length_m));
        let after_dist = after_prox * to_distal_joint * Isometry3::rotation(Vector3::y() * q_rad[2]);
        Ok([base, after_roll, after_prox, after_dist])
    }

    /// World position of the fingertip sphere centre.
    pub fn fingertip_position_m<T: RealField + Copy>(
        &self,
        q_rad: &[T; JOINTS_PER_FINGER],
    ) -> Result<Vector3<T>, KinematicsError> {
        let frames = self.frames(q_rad)?;
        Ok(self.tip_from_frames(&frames))
    }

    fn tip_from_frames<T: RealField + Copy>(
        &self,
        frames: &[Isometry3<T>; JOINTS_PER_FINGER + 1],
    ) -> Vector3<T> {
        let zero = T::zero();
        (frames[3] * Point3::new(zero, zero, -lift::<T>(self.distal_length_m))).coords
    }

    /// Analytic Jacobian of the fingertip centre: column j = axis_j x (p_tip - o_j).
    pub fn fingertip_jacobian<T: RealField + Copy>(
        &self,
        q_rad: &[T; JOINTS_PER_FINGER],
    ) -> Result<Matrix3<T>, KinematicsError> {
        let frames = self.frames(q_rad)?;
        let tip = self.tip_from_frames(&frames);
        Ok(jacobian_from_frames(&frames, &tip))
    }

    /// Analytic Jacobian of a point rigidly attached to the distal link that is, at
    /// configuration `q_rad`, at `offset_from_tip_m` (world frame) from the fingertip
    /// centre. This is the contact Jacobian used in J_S: only the point's position
    /// matters, not the fingertip's orientation, so column j = axis_j x (p - o_j).
    pub fn contact_jacobian<T: RealField + Copy>(
        &self,
        q_rad: &[T; JOINTS_PER_FINGER],
        offset_from_tip_m: &Vector3<T>,
    ) -> Result<Matrix3<T>, KinematicsError> {
        check_vector(offset_from_tip_m, || "contact offset".to_owned())?;
        let frames = self.frames(q_rad)?;
        let point = self.tip_from_frames(&frames) + offset_from_tip_m;
        Ok(jacobian_from_frames(&frames, &point))
    }
}

/// Columns `axis_j x (point - origin_j)` for the roll (+x of frame 1) and the two
/// flexion joints (+y of frames 2 and 3).
fn jacobian_from_frames<T: RealField + Copy>(
    frames: &[Isometry3<T>; JOINTS_PER_FINGER + 1],
    point: &Vector3<T>,
) -> Matrix3<T> {
    let axes = [
        frames[1].rotation * Vector3::x(),
        frames[2].rotation * Vector3::y(),
        frames[3].rotation * Vector3::y(),
    ];
    let mut jacobian = Matrix3::zeros();
    for (j, axis) in axes.iter().enumerate() {
        let lever = point - frames[j + 1].translation.vector;
        jacobian.set_column(j, &axis.cross(&lever));
    }
    jacobian
}
