//! Forward kinematics and fingertip Jacobians, generic over [`RealField`] so that the same code
//! runs in `f32` for a simulator and in `f64` for checks against MuJoCo (which computes in f64).
//!
//! A body's world frame is its parent's times its pose in the parent, then each of its hinges
//! in order turns it by q about the hinge axis through the hinge anchor (MuJoCo's
//! `mj_kinematics`). A Jacobian column is `axis x (point - anchor)` in the world frame for the
//! joints on the point's path, zero for all others (MuJoCo's `mj_jac`, translational part).

use nalgebra::{Isometry3, Matrix3xX, Point3, RealField, Translation3, Unit, UnitQuaternion, Vector3};

use crate::Hand;
use crate::error::HandError;

/// `f32` model data to the computation scalar (exact for f32 and f64).
fn lift<T: RealField + Copy>(x: f32) -> T {
    nalgebra::convert(f64::from(x))
}

fn lift_vector<T: RealField + Copy>(v: &Vector3<f32>) -> Vector3<T> {
    Vector3::new(lift(v.x), lift(v.y), lift(v.z))
}

fn lift_isometry<T: RealField + Copy>(iso: &Isometry3<f32>) -> Isometry3<T> {
    let q = iso.rotation.quaternion();
    Isometry3::from_parts(
        Translation3::from(lift_vector(&iso.translation.vector)),
        unit_in::<T>(nalgebra::Quaternion::new(lift(q.w), lift(q.i), lift(q.j), lift(q.k))),
    )
}

/// A quaternion renormalised in `T` where it is off unit at `T`'s precision: an f32 unit
/// quaternion lifted to f64 is unit only to f32 precision, while in f32 it is kept as it is
/// (renormalising it there would move it by an ulp from the frames the simulator uses).
fn unit_in<T: RealField + Copy>(q: nalgebra::Quaternion<T>) -> UnitQuaternion<T> {
    let tolerance = T::default_epsilon() * nalgebra::convert::<f64, T>(4.0);
    if (q.norm() - T::one()).abs() <= tolerance {
        UnitQuaternion::new_unchecked(q)
    } else {
        UnitQuaternion::new_normalize(q)
    }
}

/// Joint anchors and axes in the world frame, with the bodies' frames.
struct WorldFrames<T: RealField + Copy> {
    bodies: Vec<Isometry3<T>>,
    anchors: Vec<Vector3<T>>,
    axes: Vec<Vector3<T>>,
}

impl Hand {
    fn check_q<T: RealField + Copy>(&self, q_rad: &[T]) -> Result<(), HandError> {
        if q_rad.len() != self.joints.len() {
            return Err(HandError::JointCount { expected: self.joints.len(), got: q_rad.len() });
        }
        match q_rad.iter().position(|v| !v.is_finite()) {
            Some(index) => Err(HandError::NonFiniteJoint { index }),
            None => Ok(()),
        }
    }

    fn world_frames<T: RealField + Copy>(&self, q_rad: &[T]) -> Result<WorldFrames<T>, HandError> {
        self.check_q(q_rad)?;
        let n = self.joints.len();
        let mut frames = WorldFrames {
            bodies: Vec::with_capacity(self.bodies.len()),
            anchors: Vec::with_capacity(n),
            axes: Vec::with_capacity(n),
        };
        for body in &self.bodies {
            let local = lift_isometry::<T>(&body.pose_in_parent);
            // Parents precede their children (checked when the hand is built).
            let mut pose = match body.parent.and_then(|p| frames.bodies.get(p)) {
                Some(parent) => parent * local,
                None => local,
            };
            for j in body.joints.clone() {
                let joint = &self.joints[j];
                let pos = lift_vector::<T>(&joint.pos_in_body_m);
                let axis = lift_vector::<T>(joint.axis_in_body.as_ref());
                let anchor = pose * Point3::from(pos);
                frames.anchors.push(anchor.coords);
                frames.axes.push(pose.rotation * axis);
                // As a scaled axis (nalgebra's `Isometry3::rotation`), which rounds as the
                // simulator's kinematics always have, so that a world closed on an object from
                // these frames is the former world bit for bit.
                let turn =
                    UnitQuaternion::from_scaled_axis(Unit::new_normalize(axis).into_inner() * q_rad[j]);
                let rotation = pose.rotation * turn;
                pose = Isometry3::from_parts(Translation3::from(anchor.coords - rotation * pos), rotation);
            }
            frames.bodies.push(pose);
        }
        Ok(frames)
    }

    fn finger_index(&self, finger: usize) -> Result<&crate::Finger, HandError> {
        self.fingers
            .get(finger)
            .ok_or(HandError::FingerOutOfRange { index: finger, count: self.fingers.len() })
    }

    fn tip_point<T: RealField + Copy>(&self, frames: &WorldFrames<T>, finger: &crate::Finger) -> Vector3<T> {
        (frames.bodies[finger.tip_body] * Point3::from(lift_vector::<T>(&finger.tip_offset_in_body_m))).coords
    }

    fn jacobian<T: RealField + Copy>(
        &self,
        frames: &WorldFrames<T>,
        finger: &crate::Finger,
        point: &Vector3<T>,
    ) -> Matrix3xX<T> {
        let mut jacobian = Matrix3xX::zeros(self.joints.len());
        for j in finger.joints.clone() {
            jacobian.set_column(j, &frames.axes[j].cross(&(point - frames.anchors[j])));
        }
        jacobian
    }

    /// World frames of all bodies at joint angles `q_rad` (body 0, the world, is the identity).
    pub fn body_poses_world<T: RealField + Copy>(&self, q_rad: &[T]) -> Result<Vec<Isometry3<T>>, HandError> {
        Ok(self.world_frames(q_rad)?.bodies)
    }

    /// World positions of the fingertips, in finger order: a site's position, or a body's
    /// origin for a fingertip named by its body (MuJoCo's `site_xpos`, `xpos`).
    pub fn fingertip_positions_m<T: RealField + Copy>(
        &self,
        q_rad: &[T],
    ) -> Result<Vec<Vector3<T>>, HandError> {
        let frames = self.world_frames(q_rad)?;
        Ok(self.fingers.iter().map(|f| self.tip_point(&frames, f)).collect())
    }

    /// d(fingertip position)/dq of each finger, 3 x num_joints in the world frame; the columns
    /// of other fingers' joints are zero (MuJoCo's `mj_jacSite` / `mj_jacBody`, translation).
    pub fn fingertip_jacobians<T: RealField + Copy>(
        &self,
        q_rad: &[T],
    ) -> Result<Vec<Matrix3xX<T>>, HandError> {
        let frames = self.world_frames(q_rad)?;
        Ok(self.fingers.iter().map(|f| self.jacobian(&frames, f, &self.tip_point(&frames, f))).collect())
    }

    /// The 3 x num_joints Jacobian of a point rigidly attached to `finger`'s tip body that is at
    /// `point_world_m` at configuration `q_rad` (a contact point: what in-grasp manipulation's
    /// J_S is made of).
    pub fn fingertip_jacobian_at_point<T: RealField + Copy>(
        &self,
        finger: usize,
        q_rad: &[T],
        point_world_m: &Vector3<T>,
    ) -> Result<Matrix3xX<T>, HandError> {
        let finger = self.finger_index(finger)?;
        if !point_world_m.iter().all(|c| c.is_finite()) {
            return Err(HandError::NonFinitePoint { what: "contact point".to_owned() });
        }
        let frames = self.world_frames(q_rad)?;
        Ok(self.jacobian(&frames, finger, point_world_m))
    }
}
