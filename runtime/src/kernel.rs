//! The forward pass's matrix-vector kernels, one per [`Weights`] type.
//!
//! Each output is a dot product of a contiguous weight row with the layer input. Every weight
//! is read once, so at batch 1 a layer is bound by how fast its weights stream from cache
//! (host) or flash (microcontroller): smaller weights are faster as well as smaller.

use crate::weights::{self, Weights};
use crate::{Layer, RuntimeError};

/// Lanes per accumulator block of the floating-point kernels: 16 `f32` (one AVX-512 register,
/// two AVX ones, four SSE/NEON ones). LLVM vectorises the lane-wise loops below for whatever
/// the target has, without reassociating: the summation order is fixed by this constant, so
/// every target (x86-64 with or without AVX, thumbv7em) computes bit-identical results.
pub(crate) const LANES: usize = 16;

/// Output rows per call of [`rows_f`] on the portable path. Each row is still summed on its
/// own, so the row count does not change any result, only the code LLVM emits: on the
/// 65-256-256-15 bench 2 beat 4 by ~12% on the default x86-64 target (SSE2: 16 xmm
/// registers hold 2 rows x 4 registers of accumulators) (7.45 -> 6.5 us); 1, 3, 6 and 8
/// were slower, and chunk-outer interleavings of the rows lost vectorisation.
const ROWS: usize = 2;

/// Rows per call on the AVX-512 path ([`dispatch`]): one zmm register accumulates a row, so
/// 8 rows give 8 independent add chains (enough to hide the add latency) in 32 registers.
#[cfg(all(feature = "std", target_arch = "x86_64"))]
const ROWS_AVX512: usize = 8;

/// Rows per call of the `i8` kernel: integer sums are exact in any order.
const ROWS_I8: usize = 4;

/// `y = W x + b` for one layer (no activation), dispatching on the weight type. `q_buf` is
/// scratch for the quantised input of an `i8` layer (at least `x.len()` long).
pub(crate) fn affine(
    layer: &Layer<'_>,
    index: usize,
    x: &[f32],
    q_buf: &mut [i16],
    y: &mut [f32],
) -> Result<(), RuntimeError> {
    check_dims(layer, index, x, y)?;
    match layer.weights {
        Weights::F32(w) => dense_f32(w, layer.bias, x, y),
        Weights::F16(w) => dense_f::<ROWS, u16>(w, layer.bias, x, y, weights::f16_to_f32),
        Weights::I8 { q, row_scale } => {
            let max = q_buf.len();
            let q_x = q_buf.get_mut(..x.len()).ok_or(RuntimeError::WidthExceedsCapacity {
                layer: index,
                dim: x.len(),
                max,
            })?;
            dense_i8(q, row_scale, layer.bias, x, q_x, y);
        }
    }
    Ok(())
}

/// Re-checks every length the kernels rely on, so that a mismatch is an error, not a panic
/// or a silently short product.
fn check_dims(layer: &Layer<'_>, index: usize, x: &[f32], y: &[f32]) -> Result<(), RuntimeError> {
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
    if let Weights::I8 { row_scale, .. } = layer.weights {
        if row_scale.len() != n_out {
            return Err(RuntimeError::ScaleLen { layer: index, expected: n_out, got: row_scale.len() });
        }
        if n_in > weights::I8_MAX_IN_DIM {
            return Err(RuntimeError::TooWideForI8 {
                layer: index,
                in_dim: n_in,
                max: weights::I8_MAX_IN_DIM,
            });
        }
    }
    Ok(())
}

/// The `f32` kernel: with the `std` feature on x86-64, the AVX-512 build of the same code
/// when this CPU has it (bit-identical results: only the row blocking differs); else the
/// portable build, vectorised for the compile-time target.
#[inline(always)]
fn dense_f32(w: &[f32], bias: &[f32], x: &[f32], y: &mut [f32]) {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if dispatch::has_avx512() {
        // SAFETY: the function only differs from the portable one by being compiled with
        // AVX-512F enabled, and `has_avx512` checked at run time that this CPU has AVX-512F.
        #[allow(unsafe_code)]
        unsafe {
            dispatch::dense_f32_avx512(w, bias, x, y)
        };
        return;
    }
    dense_f::<ROWS, f32>(w, bias, x, y, |v| v);
}

/// Run-time CPU dispatch of the host build (`std` feature: feature detection needs std).
#[cfg(all(feature = "std", target_arch = "x86_64"))]
mod dispatch {
    extern crate std;

    use std::sync::OnceLock;

    /// Whether this CPU has AVX-512F (detected once).
    pub(super) fn has_avx512() -> bool {
        static HAS: OnceLock<bool> = OnceLock::new();
        *HAS.get_or_init(|| std::is_x86_feature_detected!("avx512f"))
    }

    /// [`super::dense_f`] compiled for AVX-512F, with [`super::ROWS_AVX512`] rows per block.
    #[target_feature(enable = "avx512f")]
    pub(super) fn dense_f32_avx512(w: &[f32], bias: &[f32], x: &[f32], y: &mut [f32]) {
        super::dense_f::<{ super::ROWS_AVX512 }, f32>(w, bias, x, y, |v| v);
    }
}

/// Floating-point kernel: rows `R` at a time, each with `LANES` independent partial sums
/// (they hide the add latency); `widen` turns a stored weight into `f32` as it is read.
#[inline(always)]
fn dense_f<const R: usize, W: Copy>(
    w: &[W],
    bias: &[f32],
    x: &[f32],
    y: &mut [f32],
    widen: impl Fn(W) -> f32 + Copy,
) {
    let n_in = x.len();
    let (x_chunks, x_tail) = x.as_chunks::<LANES>();
    let mut w_blocks = w.chunks_exact(n_in.saturating_mul(R).max(1));
    let mut y_blocks = y.chunks_exact_mut(R);
    let mut b_blocks = bias.chunks_exact(R);
    for ((w, yb), b) in (&mut w_blocks).zip(&mut y_blocks).zip(&mut b_blocks) {
        rows_f::<R, W>(w, b, x_chunks, x_tail, yb, widen);
    }
    for ((w, yo), b) in w_blocks
        .remainder()
        .chunks_exact(n_in.max(1))
        .zip(y_blocks.into_remainder())
        .zip(b_blocks.remainder())
    {
        rows_f::<1, W>(w, core::slice::from_ref(b), x_chunks, x_tail, core::slice::from_mut(yo), widen);
    }
}

/// `y[r] = b[r] + w_r · x` for the `R` rows of `w` (row-major, `R × x.len()`), where `x` is
/// given as `LANES`-wide chunks plus a tail. Callers pass `R` rows, `R` biases and `R` outputs.
#[inline(always)]
fn rows_f<const R: usize, W: Copy>(
    w: &[W],
    b: &[f32],
    x_chunks: &[[f32; LANES]],
    x_tail: &[f32],
    y: &mut [f32],
    widen: impl Fn(W) -> f32,
) {
    let n_in = x_chunks.len() * LANES + x_tail.len();
    let mut acc = [[0.0f32; LANES]; R];
    let mut tail = [0.0f32; R];
    for ((acc, tail), w_row) in acc.iter_mut().zip(tail.iter_mut()).zip(w.chunks_exact(n_in.max(1))) {
        let (w_chunks, w_tail) = w_row.as_chunks::<LANES>();
        for (wc, xc) in w_chunks.iter().zip(x_chunks) {
            for ((a, wv), xv) in acc.iter_mut().zip(wc).zip(xc) {
                *a += widen(*wv) * xv;
            }
        }
        for (wv, xv) in w_tail.iter().zip(x_tail) {
            *tail += widen(*wv) * xv;
        }
    }
    for (((yo, acc), tail), b) in y.iter_mut().zip(&acc).zip(&tail).zip(b) {
        *yo = b + (reduce(acc) + tail);
    }
}

/// Pairwise reduction of the lanes, in a fixed order.
#[inline(always)]
fn reduce(acc: &[f32; LANES]) -> f32 {
    let mut lanes = *acc;
    let mut width = LANES;
    while width > 1 {
        width /= 2;
        let (lo, hi) = lanes.split_at_mut(width);
        for (l, h) in lo.iter_mut().zip(hi.iter()) {
            *l += *h;
        }
    }
    lanes.first().copied().unwrap_or(0.0)
}

/// `i8` kernel: quantise `x` into `q_x` (`i16`, one scale), sum `q_w · q_x` exactly in `i32`
/// (at most 127 · 32767 · in_dim, and `in_dim <= I8_MAX_IN_DIM` is checked at load), then
/// `y[r] = b[r] + (row_scale[r] · x_scale) · sum_r`.
#[inline(always)]
fn dense_i8(q: &[i8], row_scale: &[f32], bias: &[f32], x: &[f32], q_x: &mut [i16], y: &mut [f32]) {
    let n_in = x.len();
    let x_scale = weights::quantise_input(x, q_x);
    let q_x: &[i16] = q_x;
    let mut w_blocks = q.chunks_exact(n_in.saturating_mul(ROWS_I8).max(1));
    let mut y_blocks = y.chunks_exact_mut(ROWS_I8);
    let mut s_blocks = row_scale.chunks_exact(ROWS_I8);
    let mut b_blocks = bias.chunks_exact(ROWS_I8);
    for (((w, yb), s), b) in (&mut w_blocks).zip(&mut y_blocks).zip(&mut s_blocks).zip(&mut b_blocks) {
        rows_i8::<ROWS_I8>(w, s, b, q_x, x_scale, yb);
    }
    for (((w, yo), s), b) in w_blocks
        .remainder()
        .chunks_exact(n_in.max(1))
        .zip(y_blocks.into_remainder())
        .zip(s_blocks.remainder())
        .zip(b_blocks.remainder())
    {
        let (s, b, yo) = (core::slice::from_ref(s), core::slice::from_ref(b), core::slice::from_mut(yo));
        rows_i8::<1>(w, s, b, q_x, x_scale, yo);
    }
}

#[inline(always)]
fn rows_i8<const R: usize>(w: &[i8], s: &[f32], b: &[f32], q_x: &[i16], x_scale: f32, y: &mut [f32]) {
    let mut acc = [0i32; R];
    for (acc, w_row) in acc.iter_mut().zip(w.chunks_exact(q_x.len().max(1))) {
        for (wv, xv) in w_row.iter().zip(q_x) {
            *acc += i32::from(*wv) * i32::from(*xv);
        }
    }
    for (((yo, acc), s), b) in y.iter_mut().zip(&acc).zip(s).zip(b) {
        *yo = b + (s * x_scale) * *acc as f32;
    }
}
