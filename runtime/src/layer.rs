//! A single dense layer over borrowed weights.

use nalgebra::{ComplexField, DVectorView, DVectorViewMut, Dyn, MatrixView};

use crate::{RuntimeError, Weights};

/// Element-wise non-linearity applied after a layer's affine map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Activation {
    /// `y = x`
    Identity,
    /// `y = max(x, 0)`, with NaN kept as NaN (`f32::max` would turn it into 0 and hide it).
    Relu,
    /// `y = tanh(x)`
    Tanh,
}

impl Activation {
    /// Applies the activation to one value.
    #[inline]
    pub fn apply(self, x: f32) -> f32 {
        match self {
            Self::Identity => x,
            // `!(x <= 0)` is true for NaN, so NaN passes through to the non-finite check.
            Self::Relu => {
                if x <= 0.0 {
                    0.0
                } else {
                    x
                }
            }
            Self::Tanh => ComplexField::tanh(x),
        }
    }
}

/// A dense layer `y = activation(W x + b)` over borrowed data.
///
/// `weights` is row-major `out_dim × in_dim` (the layout of a PyTorch/tch `Linear` weight),
/// `bias` has `out_dim` entries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layer<'a> {
    pub in_dim: usize,
    pub out_dim: usize,
    pub weights: Weights<'a>,
    pub bias: &'a [f32],
    pub activation: Activation,
}

impl<'a> Layer<'a> {
    /// Dimensions and slice lengths, not values: what [`Layer::validate`] checks at build and
    /// the kernels re-check at every forward ([`Layer::check_io`]).
    pub(crate) fn check_lengths(&self, index: usize) -> Result<(), RuntimeError> {
        if self.in_dim == 0 || self.out_dim == 0 {
            return Err(RuntimeError::ZeroDim { layer: index });
        }
        let expected =
            self.in_dim.checked_mul(self.out_dim).ok_or(RuntimeError::SizeOverflow { layer: index })?;
        if self.weights.len() != expected {
            return Err(RuntimeError::WeightLen { layer: index, expected, got: self.weights.len() });
        }
        if self.bias.len() != self.out_dim {
            return Err(RuntimeError::BiasLen { layer: index, expected: self.out_dim, got: self.bias.len() });
        }
        if let Weights::I8 { row_scale, .. } = self.weights {
            if row_scale.len() != self.out_dim {
                let (expected, got) = (self.out_dim, row_scale.len());
                return Err(RuntimeError::ScaleLen { layer: index, expected, got });
            }
            if self.in_dim > crate::weights::I8_MAX_IN_DIM {
                let (in_dim, max) = (self.in_dim, crate::weights::I8_MAX_IN_DIM);
                return Err(RuntimeError::TooWideForI8 { layer: index, in_dim, max });
            }
        }
        Ok(())
    }

    /// [`Layer::check_lengths`] and the input and output slices of one forward, so that a
    /// mismatch is an error, not a panic or a silently short product.
    pub(crate) fn check_io(&self, index: usize, x: &[f32], y: &[f32]) -> Result<(), RuntimeError> {
        if x.len() != self.in_dim {
            return Err(RuntimeError::DimMismatch {
                layer: index,
                expected_in: x.len(),
                got_in: self.in_dim,
            });
        }
        if y.len() != self.out_dim {
            return Err(RuntimeError::ActionLen { expected: self.out_dim, got: y.len() });
        }
        self.check_lengths(index)
    }

    /// Checks slice lengths against the dimensions, and that all parameters are finite.
    /// `index` is only used to label errors.
    pub fn validate(&self, index: usize) -> Result<(), RuntimeError> {
        self.check_lengths(index)?;
        if let Some(i) = self.weights.first_invalid() {
            return Err(match self.weights {
                Weights::I8 { .. } => RuntimeError::BadScale { layer: index, index: i },
                _ => RuntimeError::NonFiniteWeight { layer: index, index: i },
            });
        }
        if let Some(i) = self.bias.iter().position(|b| !b.is_finite()) {
            return Err(RuntimeError::NonFiniteBias { layer: index, index: i });
        }
        Ok(())
    }

    /// Computes `y = activation(W x + b)` with nalgebra's product, for `f32` layers too
    /// narrow for the kernels' chunks; other weight types go through [`crate::kernel`].
    ///
    /// The layer must have passed [`Layer::validate`]; sizes are re-checked here (cheaply)
    /// so that a mismatch is an error rather than a panic inside nalgebra.
    /// `index` labels errors.
    pub(crate) fn apply_narrow_f32(
        &self,
        index: usize,
        x: &[f32],
        y: &mut [f32],
    ) -> Result<(), RuntimeError> {
        let Weights::F32(weights) = self.weights else {
            return Err(RuntimeError::WeightLen { layer: index, expected: 0, got: self.weights.len() });
        };
        self.check_io(index, x, y)?;
        let (n_in, n_out) = (self.in_dim, self.out_dim);

        // Row-major out×in is column-major in×out: view it as Wᵀ and use the transposed product.
        let w_t = MatrixView::<f32, Dyn, Dyn>::from_slice_generic(weights, Dyn(n_in), Dyn(n_out));
        let xv = DVectorView::<f32>::from_slice(x, n_in);
        for (yo, b) in y.iter_mut().zip(self.bias) {
            *yo = *b;
        }
        let mut yv = DVectorViewMut::<f32>::from_slice(y, n_out);
        // y = 1 * (Wᵀ)ᵀ x + 1 * b
        yv.gemv_tr(1.0, &w_t, &xv, 1.0);
        activate(self.activation, index, y)
    }
}

/// Checks the affine outputs `y` of layer `index` and applies the activation in place.
///
/// The check comes before the activation: tanh maps an overflow (±inf) to a finite ±1 and
/// ReLU a -inf to 0, so a layer that overflowed would otherwise reach the motors looking
/// like a valid action. Costs one compare per output, noise beside the layer's products.
pub(crate) fn activate(activation: Activation, layer: usize, y: &mut [f32]) -> Result<(), RuntimeError> {
    if let Some(index) = y.iter().position(|v| !v.is_finite()) {
        return Err(RuntimeError::NonFiniteActivation { layer, index });
    }
    if activation != Activation::Identity {
        for v in y.iter_mut() {
            *v = activation.apply(*v);
        }
    }
    Ok(())
}
