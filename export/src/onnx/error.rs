//! Why an ONNX model could not be written or imported.

use std::path::PathBuf;

use crate::ExportError;

/// An ONNX export or import that failed. Refusals of a graph name the node, its op and why.
#[derive(Debug, thiserror::Error)]
pub enum OnnxError {
    /// The bytes are not an ONNX `ModelProto`.
    #[error("not an ONNX model: {0}")]
    Parse(protobuf::Error),
    /// protobuf could not encode the model.
    #[error("cannot encode the ONNX model: {0}")]
    Encode(protobuf::Error),
    /// A node the importer cannot turn into the runtime's MLP exactly.
    #[error("node `{node}` ({op}): {reason}")]
    Node { node: String, op: String, reason: String },
    /// The graph as a whole (its inputs, outputs, opset or shape) is not an MLP actor.
    #[error("graph: {0}")]
    Graph(String),
    /// A `metadata_props` entry is malformed or contradicts the hand.
    #[error("metadata_props `{key}`: {reason}")]
    Metadata { key: String, reason: String },
    /// An import option (observation normalisation, layout, action scale) is unusable.
    #[error("{0}")]
    Option(String),
    /// The policy stores `i8` weights, whose per-layer input quantisation ONNX's float ops
    /// would not reproduce.
    #[error(
        "the policy stores i8 weights: the runtime quantises each layer's input, which an ONNX \
         float graph would not reproduce; export the f32 (or f16) policy instead"
    )]
    Quantised,
    /// The imported policy failed the policy file's own validation.
    #[error(transparent)]
    Policy(#[from] ExportError),
    /// Reading or writing a file failed.
    #[error("{}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    /// The ONNX file is larger than any actor the runtime can hold: refused unread.
    #[error("{}: {len} bytes, more than any MLP actor the runtime holds (at most {max}); not read", path.display())]
    TooLarge { path: PathBuf, len: u64, max: u64 },
}
