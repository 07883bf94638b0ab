//! Errors raised while reading an actor out of a `VarStore`.

use std::path::PathBuf;

/// Why an actor could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The spec itself is unusable (a zero dimension or a dimension over `i64`).
    #[error("invalid actor spec: {0}")]
    InvalidSpec(String),
    /// No variable with this name in the `VarStore`.
    #[error("variable `{name}` not found in the var store")]
    MissingVariable { name: String },
    /// The variable exists but has another shape than the spec implies.
    #[error("variable `{name}` has shape {got:?}, expected {expected:?}")]
    WrongShape { name: String, expected: Vec<i64>, got: Vec<i64> },
    /// The variable is not `f32` (tch's `Kind::Float`); `kind` is the kind it has.
    #[error("variable `{name}` has kind {kind}, expected Float (f32)")]
    WrongKind { name: String, kind: String },
    /// The variable holds a NaN or infinity at this flat (row-major) index.
    #[error("variable `{name}` holds a non-finite value at flat index {index}")]
    NonFinite { name: String, index: usize },
    /// The extracted layers were rejected by the runtime.
    #[error("runtime rejected the exported layers")]
    Runtime(#[from] vge_runtime::RuntimeError),
    /// libtorch failed while copying a tensor out: tch's error, boxed so that this crate does
    /// not link libtorch (vge-export-tch reads tch actors).
    #[error(transparent)]
    Tch(Box<dyn std::error::Error + Send + Sync>),
    /// The policy file (or the metadata going into it) failed validation.
    #[error("invalid policy file")]
    Format(#[from] vge_runtime::PolicyError),
    /// postcard could not encode the payload.
    #[error("cannot encode policy: {0}")]
    Encode(postcard::Error),
    /// postcard could not decode a payload the runtime accepted (a reader bug).
    #[error("cannot decode policy payload: {0}")]
    Decode(postcard::Error),
    /// Reading or writing a policy file failed.
    #[error("{}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    /// The file is longer than any policy the reader can load: refused before it is read.
    #[error(
        "{}: {len} bytes, longer than any policy file this reader loads (at most {max} bytes); \
         not read",
        path.display()
    )]
    TooLarge { path: PathBuf, len: u64, max: usize },
}
