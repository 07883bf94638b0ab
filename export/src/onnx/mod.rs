//! Policies in and out as ONNX models (`docs/onnx.md`).
//!
//! [`export`] writes a policy file as one ONNX graph from the raw observation to the action
//! the bridge sends: `Sub` (mean), `Div` (std), optionally `Clip`, one `Gemm` (+ `Relu` or
//! `Tanh`) per layer, `Mul` (action scale) and `Add` (action offset), in opset
//! [`OPSET_VERSION`], with the observation layout, action names, control rate, provenance and
//! task (hand, observation set) in `metadata_props`. [`import`] reads an MLP actor back (as torch's exporter writes one,
//! or as [`export`] does) into a policy file for the hand, and refuses any graph the runtime
//! cannot run exactly, naming the node.
//!
//! The protobuf messages are `onnx-protobuf`'s, generated from the ONNX project's `onnx.proto`.

pub mod census;
mod error;
mod read;
mod tensor;
mod write;

use std::path::Path;

pub use error::OnnxError;
pub use read::{ActionScale, ImportOptions, ImportTarget, Imported, import};
pub use write::{export, policy_bytes_to_onnx, to_bytes};

/// The default-domain opset exported graphs declare: the oldest whose `Clip` takes its bounds
/// as inputs and that onnxruntime, TensorRT and the TFLite converters all read (>= 17).
pub const OPSET_VERSION: i64 = 17;
/// The ONNX IR version written: IR 8 is the one that introduced opset 17 (ONNX 1.12).
pub const IR_VERSION: i64 = 8;
/// Name of the graph's input: the raw observation, `float32 [batch, obs_dim]`.
pub const INPUT_NAME: &str = "obs";
/// Name of the graph's output: the action, `float32 [batch, act_dim]`.
pub const OUTPUT_NAME: &str = "action";
/// The largest ONNX file [`import_file`] reads: far above any actor the runtime holds (a
/// `HandPolicy` is at most 4 layers of 256), so a larger file is refused unread.
pub const MAX_ONNX_FILE_LEN: u64 = 64 << 20;

/// Keys of the `metadata_props` [`export`] writes and [`import`] reads.
pub mod keys {
    /// JSON array of `{"name", "start", "end"}`: the observation's named slices.
    pub const OBS_LAYOUT: &str = "obs_layout";
    /// JSON array of strings: one name per action dimension.
    pub const ACTION_NAMES: &str = "action_names";
    /// Decimal: observation width.
    pub const OBS_DIM: &str = "obs_dim";
    /// Decimal: action size.
    pub const ACT_DIM: &str = "act_dim";
    /// Decimal: control rate (Hz) the policy was trained at.
    pub const CONTROL_HZ: &str = "control_hz";
    /// What the action means (units), for a reader of the file.
    pub const ACTION_UNITS: &str = "action_units";
    /// Provenance: vge version that made the policy.
    pub const VGE_VERSION: &str = "vge_version";
    /// Provenance: hash of the training configuration.
    pub const CONFIG_HASH: &str = "config_hash";
    /// Provenance: training seed (decimal).
    pub const SEED: &str = "seed";
    /// Provenance: environment steps trained (decimal).
    pub const STEPS: &str = "steps";
    /// Task: the hand's name (1 to 64 bytes). The task keys are written only for a policy
    /// with a task record; a file without `hand` has none (vge's own hand `vge15`, `full`).
    pub const HAND: &str = "hand";
    /// Task: SHA-256 of the hand's MJCF description, 64 hex digits (written lowercase).
    pub const HAND_SHA256: &str = "hand_sha256";
    /// Task: `full`, `proprio` or `proprio:K` (K 1 to 64).
    pub const OBSERVATION_SET: &str = "observation_set";
    /// Task: the object manipulated (at most 64 bytes); absent or empty when unspecified.
    pub const OBJECT: &str = "object";
    /// Task: the hand's orientation (at most 64 bytes); absent or empty when unspecified.
    pub const ORIENTATION: &str = "orientation";
    /// Every task key, `hand` first.
    pub const TASK: [&str; 5] = [HAND, HAND_SHA256, OBSERVATION_SET, OBJECT, ORIENTATION];
}

/// Reads the ONNX model at `onnx` (at most [`MAX_ONNX_FILE_LEN`] bytes), imports it with
/// [`import`] and writes the policy file (format version 3, `f32` weights) to `out`. Nothing
/// is written when the import is refused.
pub fn import_file(
    onnx: &Path,
    out: &Path,
    target: &ImportTarget,
    options: &ImportOptions,
) -> Result<Imported, OnnxError> {
    use std::io::Read;
    let io = |source| OnnxError::Io { path: onnx.to_owned(), source };
    crate::policy_file::check_regular_file(onnx).map_err(io)?;
    let file = std::fs::File::open(onnx).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    if len > MAX_ONNX_FILE_LEN {
        return Err(OnnxError::TooLarge { path: onnx.to_owned(), len, max: MAX_ONNX_FILE_LEN });
    }
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(MAX_ONNX_FILE_LEN + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > MAX_ONNX_FILE_LEN {
        let len = bytes.len() as u64;
        return Err(OnnxError::TooLarge { path: onnx.to_owned(), len, max: MAX_ONNX_FILE_LEN });
    }
    let imported = import(&bytes, target, options)?;
    let encoded = imported.policy.to_bytes()?;
    std::fs::write(out, encoded).map_err(|source| OnnxError::Io { path: out.to_owned(), source })?;
    Ok(imported)
}
