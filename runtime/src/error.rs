//! Error type shared by model construction and evaluation.

use core::fmt;

/// Everything that can go wrong building or evaluating an [`Mlp`](crate::Mlp).
///
/// `layer` fields are zero-based layer indices; `index` fields are element indices into the
/// offending slice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RuntimeError {
    /// The network has no layers.
    NoLayers,
    /// More layers than the `MAX_LAYERS` capacity.
    TooManyLayers { count: usize, max: usize },
    /// A layer has `in_dim == 0` or `out_dim == 0`.
    ZeroDim { layer: usize },
    /// A layer dimension exceeds the `MAX_WIDTH` capacity.
    WidthExceedsCapacity { layer: usize, dim: usize, max: usize },
    /// `in_dim` of `layer` differs from `out_dim` of the layer before it.
    DimMismatch { layer: usize, expected_in: usize, got_in: usize },
    /// `in_dim * out_dim` does not fit in `usize`.
    SizeOverflow { layer: usize },
    /// The weight slice is not `out_dim * in_dim` long.
    WeightLen { layer: usize, expected: usize, got: usize },
    /// The bias slice is not `out_dim` long.
    BiasLen { layer: usize, expected: usize, got: usize },
    /// A weight is NaN or infinite.
    NonFiniteWeight { layer: usize, index: usize },
    /// An `i8` layer's row scales are not `out_dim` long.
    ScaleLen { layer: usize, expected: usize, got: usize },
    /// An `i8` layer's row scale is NaN, infinite or not > 0.
    BadScale { layer: usize, index: usize },
    /// An `i8` layer has more inputs than its `i32` sums can hold exactly.
    TooWideForI8 { layer: usize, in_dim: usize, max: usize },
    /// A bias is NaN or infinite.
    NonFiniteBias { layer: usize, index: usize },
    /// The observation slice has the wrong length.
    ObsLen { expected: usize, got: usize },
    /// The action slice has the wrong length.
    ActionLen { expected: usize, got: usize },
    /// An observation is NaN or infinite.
    NonFiniteObs { index: usize },
    /// A layer's affine output (before its activation) is NaN or infinite: an overflow in
    /// the weights or inputs. Caught per layer because tanh or ReLU could hide it.
    NonFiniteActivation { layer: usize, index: usize },
    /// The network produced a NaN or infinite action (e.g. overflow in an identity layer).
    /// The action buffer is left untouched.
    NonFiniteAction { index: usize },
}

impl fmt::Display for RuntimeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::NoLayers => write!(f, "network has no layers"),
            Self::TooManyLayers { count, max } => {
                write!(f, "network has {count} layers, capacity is {max}")
            }
            Self::ZeroDim { layer } => write!(f, "layer {layer} has a zero dimension"),
            Self::WidthExceedsCapacity { layer, dim, max } => {
                write!(f, "layer {layer} has width {dim}, capacity is {max}")
            }
            Self::DimMismatch { layer, expected_in, got_in } => {
                write!(f, "layer {layer} takes {got_in} inputs but the previous layer outputs {expected_in}")
            }
            Self::SizeOverflow { layer } => write!(f, "layer {layer} weight count overflows usize"),
            Self::WeightLen { layer, expected, got } => {
                write!(f, "layer {layer} has {got} weights, expected {expected}")
            }
            Self::BiasLen { layer, expected, got } => {
                write!(f, "layer {layer} has {got} biases, expected {expected}")
            }
            Self::NonFiniteWeight { layer, index } => {
                write!(f, "layer {layer} weight {index} is not finite")
            }
            Self::ScaleLen { layer, expected, got } => {
                write!(f, "layer {layer} has {got} row scales, expected {expected}")
            }
            Self::BadScale { layer, index } => {
                write!(f, "layer {layer} row scale {index} is not finite and > 0")
            }
            Self::TooWideForI8 { layer, in_dim, max } => {
                write!(f, "i8 layer {layer} has {in_dim} inputs, at most {max} fit its i32 sums")
            }
            Self::NonFiniteBias { layer, index } => {
                write!(f, "layer {layer} bias {index} is not finite")
            }
            Self::ObsLen { expected, got } => {
                write!(f, "observation has {got} values, expected {expected}")
            }
            Self::ActionLen { expected, got } => {
                write!(f, "action buffer has {got} values, expected {expected}")
            }
            Self::NonFiniteObs { index } => write!(f, "observation {index} is not finite"),
            Self::NonFiniteAction { index } => write!(f, "action {index} is not finite"),
            Self::NonFiniteActivation { layer, index } => {
                write!(f, "layer {layer} output {index} is not finite (overflow inside the network)")
            }
        }
    }
}

impl core::error::Error for RuntimeError {}

/// Everything that can go wrong loading or running a policy file.
///
/// `field` names are those of `docs/policy-format.md`; `offset` is a byte offset into the
/// payload (add 16 for the file offset).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PolicyError {
    /// Shorter than header + CRC.
    TooShort { len: usize, min: usize },
    /// The first eight bytes are not `VGEPOLCY`.
    BadMagic,
    /// A format version this runtime does not read.
    UnsupportedVersion { found: u16, supported: u16 },
    /// Non-zero flags (reserved).
    UnsupportedFlags { flags: u16 },
    /// The declared payload length does not match the file length (truncated or trailing bytes).
    LengthMismatch { payload_len: u32, file_len: usize },
    /// The CRC-32 stored in the file is not that of its contents.
    ChecksumMismatch { stored: u32, computed: u32 },
    /// A field could not be decoded (runs off the payload, bad varint, invalid UTF-8, ...).
    Malformed { field: &'static str, offset: usize },
    /// The payload has bytes after its last field.
    TrailingPayload { unused: usize },
    /// A list or a dimension has the wrong length.
    Len { field: &'static str, expected: usize, got: usize },
    /// A value is NaN or infinite.
    NonFinite { field: &'static str, index: usize },
    /// A value that must be > 0 (std, clip, control rate) is not.
    NotPositive { field: &'static str, index: usize },
    /// An empty name in the observation layout or the action names.
    EmptyName { field: &'static str, index: usize },
    /// The observation layout's slices are not contiguous, non-empty and covering `0..obs_dim`.
    BadLayout { index: usize },
    /// A name in the task record (version 3) is longer than
    /// [`MAX_TASK_NAME_LEN`](crate::policy::MAX_TASK_NAME_LEN) bytes, or the hand's is empty
    /// (a task record always names its hand). `len` is the name's length in bytes.
    TaskName { field: &'static str, len: usize },
    /// The task record's observation set is not `full`, `proprio` or `proprio:K` (K from 1 to
    /// [`MAX_PROPRIO_HISTORY`](crate::policy::MAX_PROPRIO_HISTORY), decimal, no leading zero).
    BadObservationSet { offset: usize },
    /// A layer record holds an unknown activation code.
    UnknownActivation { layer: usize, code: u8 },
    /// The caller's storage holds fewer `f32` than the policy needs.
    StorageTooSmall { needed: usize, got: usize },
    /// A version-2 header names a weight type this runtime does not know.
    UnknownWeightType { code: u8 },
    /// Padding before an aligned array (version 2) is not zero.
    NonZeroPadding { offset: usize },
    /// A version-2 array is not aligned in memory for its type, so it cannot be used in
    /// place: the file bytes must start at an address aligned to 16 (see `TENSOR_ALIGN`).
    Misaligned { field: &'static str, file_offset: usize, align: usize },
    /// Arrays are little-endian; a big-endian target cannot use them in place.
    InPlaceNeedsLittleEndian { field: &'static str },
    /// The network was rejected by, or failed in, the MLP runtime.
    Runtime(RuntimeError),
}

impl From<RuntimeError> for PolicyError {
    fn from(e: RuntimeError) -> Self {
        Self::Runtime(e)
    }
}

impl fmt::Display for PolicyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooShort { len, min } => {
                write!(f, "file is {len} bytes, shorter than the {min}-byte minimum")
            }
            Self::BadMagic => write!(f, "not a vge policy file (bad magic)"),
            Self::UnsupportedVersion { found, supported } => {
                write!(f, "format version {found} is not supported (this runtime reads 1 to {supported})")
            }
            Self::UnsupportedFlags { flags } => write!(f, "unsupported header flags {flags:#06x}"),
            Self::LengthMismatch { payload_len, file_len } => write!(
                f,
                "header declares a {payload_len}-byte payload but the file is {file_len} bytes (truncated or trailing data)"
            ),
            Self::ChecksumMismatch { stored, computed } => {
                write!(f, "checksum mismatch: stored {stored:#010x}, computed {computed:#010x}")
            }
            Self::Malformed { field, offset } => {
                write!(f, "malformed `{field}` at payload offset {offset}")
            }
            Self::TrailingPayload { unused } => write!(f, "{unused} unused bytes after the payload"),
            Self::Len { field, expected, got } => {
                write!(f, "`{field}` has length {got}, expected {expected}")
            }
            Self::NonFinite { field, index } => write!(f, "`{field}`[{index}] is not finite"),
            Self::NotPositive { field, index } => write!(f, "`{field}`[{index}] must be > 0"),
            Self::EmptyName { field, index } => write!(f, "`{field}`[{index}] is an empty name"),
            Self::BadLayout { index } => write!(
                f,
                "observation layout entry {index} does not continue a contiguous cover of 0..obs_dim"
            ),
            Self::TaskName { field, len: 0 } => write!(f, "`{field}` is empty: a task record names its hand"),
            Self::TaskName { field, len } => {
                write!(f, "`{field}` is {len} bytes, longer than {} bytes", crate::policy::MAX_TASK_NAME_LEN)
            }
            Self::BadObservationSet { offset } => write!(
                f,
                "`task.observation_set` at payload offset {offset} is not `full`, `proprio` or `proprio:K` (K 1 to {})",
                crate::policy::MAX_PROPRIO_HISTORY
            ),
            Self::UnknownActivation { layer, code } => {
                write!(f, "layer {layer} has unknown activation code {code}")
            }
            Self::StorageTooSmall { needed, got } => {
                write!(f, "policy needs storage for {needed} f32, got {got}")
            }
            Self::UnknownWeightType { code } => write!(f, "unknown weight type code {code}"),
            Self::NonZeroPadding { offset } => {
                write!(f, "non-zero padding byte at payload offset {offset}")
            }
            Self::Misaligned { field, file_offset, align } => write!(
                f,
                "`{field}` at file offset {file_offset} is not {align}-byte aligned in memory: load the file from a 16-byte aligned buffer"
            ),
            Self::InPlaceNeedsLittleEndian { field } => {
                write!(f, "`{field}` cannot be used in place on a big-endian target")
            }
            Self::Runtime(e) => write!(f, "{e}"),
        }
    }
}

impl core::error::Error for PolicyError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Runtime(e) => Some(e),
            _ => None,
        }
    }
}
