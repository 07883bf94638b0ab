//! Typed errors of the simulator: everything that comes from a user (actions, configs,
//! seeds of a vectorized batch) is validated and rejected with a [`SimError`], never a
//! panic, and never reaches the physics world as a NaN.

use thiserror::Error;

/// Why a simulator call was rejected.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SimError {
    /// An action of the wrong length.
    #[error("action has {got} entries, expected {expected}")]
    ActionLength {
        /// Entries given.
        got: usize,
        /// Entries expected (15).
        expected: usize,
    },
    /// An action entry that is NaN or infinite.
    #[error("action entry {index} is not finite ({value})")]
    NonFiniteAction {
        /// Position in the action.
        index: usize,
        /// The value.
        value: f32,
    },
    /// A configuration value out of its valid range.
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    /// `step` before the first `reset`.
    #[error("step called before reset")]
    NotReset,
    /// A batch call with the wrong number of entries.
    #[error("batch has {got} entries, expected {expected}")]
    BatchLength {
        /// Entries given.
        got: usize,
        /// Entries expected (number of worlds).
        expected: usize,
    },
    /// The physics produced a non-finite state (should not happen; reported, not hidden).
    #[error("physics state became non-finite: {0}")]
    NonFiniteState(String),
    /// A hand's description was refused (the reader's message names the file, element and line).
    #[error("{0}")]
    Hand(String),
    /// A kinematics query of the hand failed (the hand's message).
    #[error("{0}")]
    Kinematics(String),
}
