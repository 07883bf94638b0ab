//! A fixed-capacity MLP over borrowed layers.

use heapless::Vec;

use crate::{Layer, RuntimeError};

/// A multi-layer perceptron with at most `MAX_LAYERS` layers, each at most `MAX_WIDTH` wide.
///
/// Evaluation uses two `[f32; MAX_WIDTH]` ping-pong buffers on the stack (`8 * MAX_WIDTH`
/// bytes) and never allocates.
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
            if layer.in_dim < LANES {
                // Too narrow for one chunk: nalgebra's generic product does as well.
                narrow(layer, i, x, y)?;
            } else {
                dense(layer, i, x, y)?;
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

/// Lanes per accumulator block in [`dense`]: 16 `f32` (one AVX-512 register, two AVX ones,
/// four SSE/NEON ones). LLVM vectorises the lane-wise loops below for whatever the target
/// has, without reassociating: the summation order is fixed by this source, so every target
/// (x86-64, thumbv7em) computes bit-identical results.
const LANES: usize = 16;
/// Output rows per call of [`rows`]. Each row is still summed on its own (row-outer,
/// chunk-inner), so `ROWS` does not change any result, only the code LLVM emits: on the
/// 65-256-256-15 bench 2 beat 4 by ~12% on the default x86-64 target (7.45 -> 6.5 us) and
/// ~10% with target-cpu=native (4.3 -> 3.9 us); 1, 3, 6 and 8 were slower, and chunk-outer
/// interleavings of the rows lost vectorisation.
const ROWS: usize = 2;

/// `y = activation(W x + b)` for one layer: the forward pass's kernel.
///
/// `W` is row-major `out × in`, so each output is a dot product of a contiguous weight row
/// with `x`. Rows are taken `ROWS` at a time, each with `LANES` independent partial sums
/// (`LANES` independent accumulators per row hide the add latency);
/// the tail of a row shorter than `LANES` and the last `out % ROWS` rows go through the same
/// code with fewer rows. Every weight is read once, so at batch 1 the layer is bound by how
/// fast the weights stream from cache.
fn dense(layer: &Layer<'_>, index: usize, x: &[f32], y: &mut [f32]) -> Result<(), RuntimeError> {
    let (n_in, n_out) = (layer.in_dim, layer.out_dim);
    if x.len() != n_in {
        return Err(RuntimeError::DimMismatch { layer: index, expected_in: x.len(), got_in: n_in });
    }
    if y.len() != n_out {
        return Err(RuntimeError::ActionLen { expected: n_out, got: y.len() });
    }
    let n_w = n_in.checked_mul(n_out).ok_or(RuntimeError::SizeOverflow { layer: index })?;
    if layer.weights.len() != n_w {
        return Err(RuntimeError::WeightLen { layer: index, expected: n_w, got: layer.weights.len() });
    }
    if layer.bias.len() != n_out {
        return Err(RuntimeError::BiasLen { layer: index, expected: n_out, got: layer.bias.len() });
    }

    let (x_chunks, x_tail) = x.as_chunks::<LANES>();
    let row_block = n_in.checked_mul(ROWS).ok_or(RuntimeError::SizeOverflow { layer: index })?;
    let mut w_blocks = layer.weights.chunks_exact(row_block);
    let mut y_blocks = y.chunks_exact_mut(ROWS);
    let mut b_blocks = layer.bias.chunks_exact(ROWS);
    for ((w, yb), b) in (&mut w_blocks).zip(&mut y_blocks).zip(&mut b_blocks) {
        rows::<ROWS>(w, b, x_chunks, x_tail, yb);
    }
    for ((w, yo), b) in
        w_blocks.remainder().chunks_exact(n_in).zip(y_blocks.into_remainder()).zip(b_blocks.remainder())
    {
        rows::<1>(w, core::slice::from_ref(b), x_chunks, x_tail, core::slice::from_mut(yo));
    }

    crate::layer::activate(layer.activation, index, y)
}

/// Kept out of line so that nalgebra's code does not change how [`dense`] is optimised.
#[inline(never)]
fn narrow(layer: &Layer<'_>, index: usize, x: &[f32], y: &mut [f32]) -> Result<(), RuntimeError> {
    layer.apply(index, x, y)
}

/// `y[r] = b[r] + w_r · x` for the `R` rows of `w` (row-major, `R × x.len()`), where `x` is
/// given as `LANES`-wide chunks plus a tail. Callers pass `R` rows, `R` biases and `R` outputs.
#[inline(always)]
fn rows<const R: usize>(w: &[f32], b: &[f32], x_chunks: &[[f32; LANES]], x_tail: &[f32], y: &mut [f32]) {
    let n_in = x_chunks.len() * LANES + x_tail.len();
    let mut acc = [[0.0f32; LANES]; R];
    let mut tail = [0.0f32; R];
    for ((acc, tail), w_row) in acc.iter_mut().zip(tail.iter_mut()).zip(w.chunks_exact(n_in)) {
        let (w_chunks, w_tail) = w_row.as_chunks::<LANES>();
        for (wc, xc) in w_chunks.iter().zip(x_chunks) {
            for ((a, wv), xv) in acc.iter_mut().zip(wc).zip(xc) {
                *a += wv * xv;
            }
        }
        for (wv, xv) in w_tail.iter().zip(x_tail) {
            *tail += wv * xv;
        }
    }
    for (((yo, acc), tail), b) in y.iter_mut().zip(&acc).zip(&tail).zip(b) {
        // Pairwise reduction of the lanes, in a fixed order.
        let mut lanes = *acc;
        let mut width = LANES;
        while width > 1 {
            width /= 2;
            let (lo, hi) = lanes.split_at_mut(width);
            for (l, h) in lo.iter_mut().zip(hi.iter()) {
                *l += *h;
            }
        }
        *yo = b + (lanes.first().copied().unwrap_or(0.0) + tail);
    }
}
