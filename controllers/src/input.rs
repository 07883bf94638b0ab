//! The adapter from the simulator's privileged state to a [`ControllerInput`].
//!
//! [`vge_sim::PrivilegedState`] already reports one reading per fingertip (the
//! impulse-weighted mean point of the pair's solver contacts, the unit normal from the
//! fingertip into the object, the summed normal force), so the conversion is field by
//! field. A reading with a non-finite or zero normal, or a non-finite point or force, is
//! dropped (treated as no contact) rather than handed to the QP; forces are clamped at 0.

use vge_sim::{ContactReading, PrivilegedState};

use super::{ControllerInput, FingerContact};

impl FingerContact {
    /// The contact of one fingertip reading, or `None` when the reading is unusable
    /// (non-finite point, force or normal, or a normal of near-zero length).
    #[must_use]
    pub fn from_reading(reading: &ContactReading) -> Option<Self> {
        let normal = reading.normal.try_normalize(1e-6)?;
        let finite = reading.position_m.iter().all(|v| v.is_finite())
            && normal.iter().all(|v| v.is_finite())
            && reading.normal_force_n.is_finite();
        finite.then(|| Self { point_m: reading.position_m, normal, force_n: reading.normal_force_n.max(0.0) })
    }
}

impl ControllerInput {
    /// What a controller sees of the env's noise-free state (module docs).
    #[must_use]
    pub fn from_privileged(state: &PrivilegedState) -> Self {
        Self {
            q_rad: state.q_rad.clone(),
            q_target_rad: state.q_target_rad.clone(),
            contacts: state
                .contacts
                .iter()
                .map(|c| c.as_ref().and_then(FingerContact::from_reading))
                .collect(),
            object_position_m: state.object.pose.translation.vector,
            object_orientation: state.object.pose.rotation,
        }
    }
}

impl From<&PrivilegedState> for ControllerInput {
    fn from(state: &PrivilegedState) -> Self {
        Self::from_privileged(state)
    }
}
