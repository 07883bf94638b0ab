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
    /// A bias is NaN or infinite.
    NonFiniteBias { layer: usize, index: usize },
    /// The observation slice has the wrong length.
    ObsLen { expected: usize, got: usize },
    /// The action slice has the wrong length.
    ActionLen { expected: usize, got: usize },
    /// An observation is NaN or infinite.
    NonFiniteObs { index: usize },
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
        }
    }
}

impl core::error::Error for RuntimeError {}
