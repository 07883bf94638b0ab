//! Typed errors for kinematics queries: user input (indices, joint vectors, points) is
//! validated instead of panicking, because it may come from a policy or a sensor.

use thiserror::Error;

/// Why a kinematics query was rejected.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum KinematicsError {
    /// A finger index outside `0..count`.
    #[error("finger index {index} is out of range: the hand has {count} fingers")]
    FingerOutOfRange {
        /// The index that was asked for.
        index: usize,
        /// How many fingers the hand has.
        count: usize,
    },
    /// A joint angle that is NaN or infinite; `index` is the position in the vector given.
    #[error("joint angle {index} is not finite")]
    NonFiniteJoint {
        /// Position of the offending entry in the joint vector passed in.
        index: usize,
    },
    /// A point, offset or position that has a NaN or infinite component.
    #[error("{what} is not finite")]
    NonFiniteInput {
        /// Which argument was bad, e.g. "contact point 2".
        what: String,
    },
}
