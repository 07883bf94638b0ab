//! A fixed-capacity MLP over borrowed layers.

use heapless::Vec;

use crate::kernel::{self, LANES};
use crate::{Layer, RuntimeError, Weights};

/// A multi-layer perceptron with at most `MAX_LAYERS` layers, each at most `MAX_WIDTH` wide.
///
/// Evaluation uses two `[f32; MAX_WIDTH]` ping-pong buffers and one `[u32; MAX_WIDTH]` on the
/// stack (`12 * MAX_WIDTH` bytes) and never allocates.
#[derive(Debug, Clone)]
pub struct Mlp<'a, const MAX_LAYERS: usize, const MAX_WIDTH: usize> {
    layers: Vec<Layer<'a>, MAX_LAYERS>,
}

/// Capacity suited to the dexterous-hand policies: up to 4 layers of width up to 256.
pub type PolicyMlp<'a> = Mlp<'a, 4, 256>;

impl<'a, const MAX_LAYERS: usize, const MAX_WIDTH: usize> Mlp<'a, MAX_LAYERS, MAX_WIDTH> {
    /// Validates `layers` (dimension chain, capacity, slice lengths, finite parameters) and
    /// builds the network. The layers are copied; the weight data stays borrowed.
    pub fn new(layers: &[Layer<'a>]) -> Result<Self, RuntimeError> {
        if layers.is_empty() {
            return Err(RuntimeError::NoLayers);
        }
        if layers.len() > MAX_LAYERS {
            return Err(RuntimeError::TooManyLayers { count: layers.len(), max: MAX_LAYERS });
        }
        let mut stored = Vec::new();
        let mut prev_out: Option<usize> = None;
        for (i, layer) in layers.iter().enumerate() {
            layer.validate(i)?;
            for dim in [layer.in_dim, layer.out_dim] {
                if dim > MAX_WIDTH {
                    return Err(RuntimeError::WidthExceedsCapacity { layer: i, dim, max: MAX_WIDTH });
                }
            }
            if let Some(expected_in) = prev_out
                && expected_in != layer.in_dim
            {
                return Err(RuntimeError::DimMismatch { layer: i, expected_in, got_in: layer.in_dim });
            }
            prev_out = Some(layer.out_dim);
            stored
                .push(*layer)
                .map_err(|_| RuntimeError::TooManyLayers { count: layers.len(), max: MAX_LAYERS })?;
        }
        Ok(Self { layers: stored })
    }

    /// The validated layers.
    pub fn layers(&self) -> &[Layer<'a>] {
        &self.layers
    }

    /// Observation size (input of the first layer).
    pub fn in_dim(&self) -> usize {
        self.layers.first().map_or(0, |l| l.in_dim)
    }

    /// Action size (output of the last layer).
    pub fn out_dim(&self) -> usize {
        self.layers.last().map_or(0, |l| l.out_dim)
    }

    /// Evaluates the network on `obs`, writing the result to `action`.
    ///
    /// Errors if `obs`/`action` have the wrong length, if `obs` holds a NaN or infinity, or
    /// if the output is not finite; on error `action` is left unchanged.
    pub fn forward(&self, obs: &[f32], action: &mut [f32]) -> Result<(), RuntimeError> {
        let (n_obs, n_act) = (self.in_dim(), self.out_dim());
        if obs.len() != n_obs {
            return Err(RuntimeError::ObsLen { expected: n_obs, got: obs.len() });
        }
        if action.len() != n_act {
            return Err(RuntimeError::ActionLen { expected: n_act, got: action.len() });
        }
        if let Some(index) = obs.iter().position(|x| !x.is_finite()) {
            return Err(RuntimeError::NonFiniteObs { index });
        }

        let mut buf_a = [0.0f32; MAX_WIDTH];
        // Quantised input of an `i8` layer: `i16` codes, two per word (words keep the DSP
        // kernel's pairs aligned). Twice the room needed; a generic `MAX_WIDTH / 2` needs
        // unstable const generics.
        let mut q_buf = [0u32; MAX_WIDTH];
        let mut buf_b = [0.0f32; MAX_WIDTH];
        let mut src: &mut [f32; MAX_WIDTH] = &mut buf_a;
        let mut dst: &mut [f32; MAX_WIDTH] = &mut buf_b;
        let mut len = n_obs;
        {
            let first = src.get_mut(..n_obs).ok_or(RuntimeError::WidthExceedsCapacity {
                layer: 0,
                dim: n_obs,
                max: MAX_WIDTH,
            })?;
            for (b, o) in first.iter_mut().zip(obs) {
                *b = *o;
            }
        }

        for (i, layer) in self.layers.iter().enumerate() {
            let x = src.get(..len).ok_or(RuntimeError::WidthExceedsCapacity {
                layer: i,
                dim: len,
                max: MAX_WIDTH,
            })?;
            let y = dst.get_mut(..layer.out_dim).ok_or(RuntimeError::WidthExceedsCapacity {
                layer: i,
                dim: layer.out_dim,
                max: MAX_WIDTH,
            })?;
            if layer.in_dim < LANES && matches!(layer.weights, Weights::F32(_)) {
                // Too narrow for one chunk: nalgebra's generic product does as well.
                narrow(layer, i, x, y)?;
            } else {
                kernel::affine(layer, i, x, &mut q_buf, y)?;
                crate::layer::activate(layer.activation, i, y)?;
            }
            len = layer.out_dim;
            core::mem::swap(&mut src, &mut dst);
        }

        let out = src.get(..len).ok_or(RuntimeError::ActionLen { expected: len, got: action.len() })?;
        if let Some(index) = out.iter().position(|y| !y.is_finite()) {
            return Err(RuntimeError::NonFiniteAction { index });
        }
        for (a, y) in action.iter_mut().zip(out) {
            *a = *y;
        }
        Ok(())
    }
}

/// Kept out of line so that nalgebra's code does not change how the kernels are optimised.
#[inline(never)]
fn narrow(layer: &Layer<'_>, index: usize, x: &[f32], y: &mut [f32]) -> Result<(), RuntimeError> {
    layer.apply_narrow_f32(index, x, y)
}
