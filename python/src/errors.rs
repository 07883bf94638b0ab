//! Rust errors as Python exceptions, each carrying the Rust message: what the caller gave
//! wrong is a `ValueError` (a bad action, an invalid key), a damaged or unusable policy file
//! a `vge.PolicyError` (a `ValueError`), a hand description outside vge's MJCF subset a
//! `vge.HandError` (a `ValueError`), a file that cannot be read an `OSError`, a state the
//! simulator cannot continue from a `RuntimeError`.

use pyo3::PyErr;
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyValueError};
use vge_config_file::EnvKeysError;
use vge_hand::HandError as HandDescriptionError;
use vge_sim::SimError;

create_exception!(
    vge,
    PolicyError,
    PyValueError,
    "A policy file that fails one of the runtime's checks (framing, checksum, a field, a dimension); the message names the check."
);

create_exception!(
    vge,
    HandError,
    PyValueError,
    "A hand description (MJCF file and its TOML) that vge refuses; the message names the file, line, element and name."
);

/// A simulator error as the exception a Python caller expects.
pub fn sim(e: SimError) -> PyErr {
    match e {
        SimError::ActionLength { .. }
        | SimError::NonFiniteAction { .. }
        | SimError::InvalidConfig(_)
        | SimError::BatchLength { .. } => PyValueError::new_err(e.to_string()),
        SimError::Hand(_) => HandError::new_err(e.to_string()),
        SimError::NotReset | SimError::NonFiniteState(_) | SimError::Kinematics(_) => {
            PyRuntimeError::new_err(e.to_string())
        }
    }
}

/// An error of the `[env]` keys.
pub fn keys(e: EnvKeysError) -> PyErr {
    match &e {
        EnvKeysError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        EnvKeysError::Io { .. } => PyOSError::new_err(e.to_string()),
        EnvKeysError::Parse { .. } | EnvKeysError::Invalid { .. } => PyValueError::new_err(e.to_string()),
    }
}

/// A `ValueError` with `message`.
pub fn value(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// A hand description's error: a file that cannot be read is an `OSError`, one vge refuses a
/// `vge.HandError`, a wrong argument to a query a `ValueError`.
pub fn hand(e: HandDescriptionError) -> PyErr {
    match &e {
        HandDescriptionError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        HandDescriptionError::Io { .. } | HandDescriptionError::NotAFile { .. } => {
            PyOSError::new_err(e.to_string())
        }
        HandDescriptionError::TooLarge { .. }
        | HandDescriptionError::Xml { .. }
        | HandDescriptionError::Unsupported { .. }
        | HandDescriptionError::Invalid { .. }
        | HandDescriptionError::Spec { .. } => HandError::new_err(e.to_string()),
        HandDescriptionError::JointCount { .. }
        | HandDescriptionError::NonFiniteJoint { .. }
        | HandDescriptionError::NonFinitePoint { .. }
        | HandDescriptionError::FingerOutOfRange { .. } => PyValueError::new_err(e.to_string()),
    }
}
