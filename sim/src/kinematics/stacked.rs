//! The stacked contact Jacobian J_S of a set of fingertip contacts over all 15 joints,
//! as used by the in-grasp controller (J_S dq = G^T do).

use nalgebra::{DMatrix, Vector3};

use super::error::KinematicsError;
use super::finger::{check_joints, check_vector};
use super::hand::{HandModel, JOINTS_PER_FINGER, NUM_JOINTS, joint_index};

/// A contact on a fingertip: the contact point is rigidly attached to the distal link, at
/// `offset_from_tip_m` (world frame, at the configuration the Jacobian is taken at) from
/// the fingertip sphere centre. For a contact point `p` read from the physics engine use
/// `p - fingertip_position_m(...)`; on the sphere surface its norm is `tip_radius_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Which finger touches.
    pub finger: usize,
    /// Contact point minus fingertip centre, in the world frame.
    pub offset_from_tip_m: Vector3<f32>,
}

impl Contact {
    /// A contact at the fingertip centre itself (zero offset).
    #[must_use]
    pub fn at_tip_centre(finger: usize) -> Self {
        Self { finger, offset_from_tip_m: Vector3::zeros() }
    }
}

impl HandModel {
    /// J_S, of size 3k x 15 for k contacts: row block i is contact i's 3x3 point Jacobian
    /// ([`crate::FingerModel::contact_jacobian`]) in its finger's three columns and zero
    /// elsewhere, so that J_S dq stacks the contact-point velocities in contact order.
    /// Several contacts may share a finger.
    pub fn stacked_jacobian(
        &self,
        contacts: &[Contact],
        q_all_rad: &[f32; NUM_JOINTS],
    ) -> Result<DMatrix<f32>, KinematicsError> {
        check_joints(q_all_rad)?;
        let mut stacked = DMatrix::zeros(3 * contacts.len(), NUM_JOINTS);
        for (i, contact) in contacts.iter().enumerate() {
            let finger = self.finger(contact.finger)?;
            check_vector(&contact.offset_from_tip_m, || format!("offset of contact {i}"))?;
            let q = self.finger_joints(contact.finger, q_all_rad)?;
            let block = finger.contact_jacobian(&q, &contact.offset_from_tip_m)?;
            stacked
                .fixed_view_mut::<3, JOINTS_PER_FINGER>(3 * i, joint_index(contact.finger, 0))
                .copy_from(&block);
        }
        Ok(stacked)
    }
}
