//! One error type for reading a hand and for querying it. A reader error names the file,
//! the line, the element and the offending name or attribute, so that the person who wrote
//! the file can find it; a query error names the argument that was wrong.

use std::fmt;

use thiserror::Error;

/// Where in a hand description something is: the file (or the name given to
/// [`crate::Hand::from_strs`]), the line (1-based) and the element.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// The file, as given.
    pub file: String,
    /// 1-based line of the element's start tag (or of the attribute).
    pub line: u32,
    /// The element's tag, e.g. `joint`.
    pub element: String,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: <{}>", self.file, self.line, self.element)
    }
}

/// Why a hand could not be read, or why a query on it was refused.
#[derive(Debug, Error)]
pub enum HandError {
    /// The file could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The path is not a regular file (a directory, a device, a pipe).
    #[error("{path}: not a regular file")]
    NotAFile {
        /// The path.
        path: String,
    },
    /// The file is larger than a hand description can sensibly be.
    #[error("{path}: {len_bytes} bytes, more than the {limit_bytes} a hand description may have")]
    TooLarge {
        /// The file.
        path: String,
        /// Its size (or at least this many bytes).
        len_bytes: u64,
        /// The limit.
        limit_bytes: u64,
    },
    /// The file is not well-formed XML (or not UTF-8).
    #[error("{file}:{line}: not well-formed XML: {message}")]
    Xml {
        /// The file.
        file: String,
        /// 1-based line of the fault.
        line: u32,
        /// The XML reader's message.
        message: String,
    },
    /// An element or attribute that would change the physics and that vge's MJCF subset does
    /// not carry (the crate docs list the subset).
    #[error("{at}: {what} is outside vge's MJCF subset ({why})")]
    Unsupported {
        /// Where.
        at: Location,
        /// The element or attribute, with its name where it has one.
        what: String,
        /// Why vge cannot carry it, or what to write instead.
        why: String,
    },
    /// Something inside the subset with a wrong value: a malformed number, a missing name, a
    /// reference to a body that does not exist, a joint on two fingers.
    #[error("{at}: {message}")]
    Invalid {
        /// Where.
        at: Location,
        /// What is wrong, naming the offending name or attribute.
        message: String,
    },
    /// The TOML beside the XML is malformed, or names something the XML does not have.
    #[error("{file}: {message}")]
    Spec {
        /// The TOML file (or the XML file when the fault is a missing TOML).
        file: String,
        /// What is wrong, naming the offending key or name.
        message: String,
    },
    /// A joint vector of the wrong length.
    #[error("joint vector has {got} entries, the hand has {expected} joints")]
    JointCount {
        /// The hand's number of joints.
        expected: usize,
        /// The length given.
        got: usize,
    },
    /// A joint angle that is NaN or infinite.
    #[error("joint angle {index} is not finite")]
    NonFiniteJoint {
        /// Its position in the joint vector.
        index: usize,
    },
    /// A point with a NaN or infinite component.
    #[error("{what} is not finite")]
    NonFinitePoint {
        /// Which argument.
        what: String,
    },
    /// A finger index outside `0..count`.
    #[error("finger index {index} is out of range: the hand has {count} fingers")]
    FingerOutOfRange {
        /// The index asked for.
        index: usize,
        /// The hand's number of fingers.
        count: usize,
    },
}
