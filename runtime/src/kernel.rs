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

/// Rows per call on the AVX-512 path ([`dispatch`]): one zmm register accumulates a row's
/// `LANES`. Measured on the 65-256-256-15 bench (AMD EPYC, `vge bench runtime`): 2 rows
/// 6.5 us, 4 rows 6.9-7.1 us, 8 rows 9.5 us (LLVM then vectorises across the rows with
/// gathers); the portable SSE2 build 9.2-9.5 us. It is not the add latency: 32 lanes (four
/// chains, another summation order) ran no faster. 346 KB of weights per forward from L2 at
/// ~32 B/cycle is ~3.6 us at 3 GHz, so f32 is near what the cache delivers.
#[cfg(all(feature = "std", target_arch = "x86_64"))]
const ROWS_AVX512: usize = 2;

/// Rows per call of the `i8` kernel: integer sums are exact in any order.
const ROWS_I8: usize = 4;

/// `y = W x + b` for one layer (no activation), dispatching on the weight type. `q_buf` is
/// scratch for the quantised input of an `i8` layer (two `i16` codes per word, so at least
/// `x.len() / 2` words).
pub(crate) fn affine(
    layer: &Layer<'_>,
    index: usize,
    x: &[f32],
    q_buf: &mut [u32],
    y: &mut [f32],
) -> Result<(), RuntimeError> {
    layer.check_io(index, x, y)?;
    #[cfg(all(feature = "simd", target_arch = "x86_64"))]
    if let Some(level) = crate::simd::level() {
        let w = match layer.weights {
            Weights::F32(w) => Some(crate::simd::SimdWeights::F32(w)),
            Weights::F16(w) => Some(crate::simd::SimdWeights::F16(w)),
            Weights::I8 { .. } => None,
        };
        if let Some(w) = w
            && crate::simd::dense(level, w, layer.bias, x, y)
        {
            return Ok(());
        }
    }
    match layer.weights {
        Weights::F32(w) => dense_f32(w, layer.bias, x, y),
        Weights::F16(w) => dense_f::<ROWS, u16>(w, layer.bias, x, y, weights::f16_to_f32),
        Weights::I8 { q, row_scale } => dense_i8(q, row_scale, layer.bias, index, x, q_buf, y)?,
    }
    Ok(())
}

/// Which floating-point kernel this build runs on this CPU: `"fma-avx512"` or `"fma-avx2"`
/// (the `simd` feature's fused kernel), `"portable-avx512"` (the portable kernel compiled for
/// AVX-512F, `std` on x86-64), or `"portable"`.
#[must_use]
pub fn float_kernel() -> &'static str {
    #[cfg(all(feature = "simd", target_arch = "x86_64"))]
    match crate::simd::level() {
        Some(crate::simd::Level::Avx512) => return "fma-avx512",
        Some(crate::simd::Level::Avx2) => return "fma-avx2",
        None => {}
    }
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if dispatch::has_avx512() {
        return "portable-avx512";
    }
    "portable"
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

/// `i8` kernel: quantise `x` into `i16` codes in `q_buf` (one scale), sum `q_w · q_x` exactly
/// in `i32` (at most 127 · 32767 · in_dim, and `in_dim <= I8_MAX_IN_DIM` is checked at load),
/// then `y[r] = b[r] + (row_scale[r] · x_scale) · sum_r`. Integer sums are exact in any order,
/// so the Cortex-M DSP build ([`dsp`]) gives the same results as the portable one.
/// `index` labels the error when `q_buf` (two `i16` codes per word) cannot hold `x`.
#[inline(always)]
fn dense_i8(
    q: &[i8],
    row_scale: &[f32],
    bias: &[f32],
    index: usize,
    x: &[f32],
    q_buf: &mut [u32],
    y: &mut [f32],
) -> Result<(), RuntimeError> {
    let n_in = x.len();
    let max = q_buf.len().saturating_mul(2);
    let too_wide = RuntimeError::WidthExceedsCapacity { layer: index, dim: n_in, max };
    let q16: &mut [i16] = bytemuck::cast_slice_mut(q_buf);
    let q_x = q16.get_mut(..n_in).ok_or(too_wide)?;
    let x_scale = weights::quantise_input(x, q_x);
    #[cfg(all(feature = "armv7em-dsp", target_arch = "arm"))]
    dsp::interleave(q_x);
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
    Ok(())
}

/// The `R` rows' `y = b + (s · x_scale) · (q_w · q_x)`, portable.
#[cfg(not(all(feature = "armv7em-dsp", target_arch = "arm")))]
#[inline(always)]
fn rows_i8<const R: usize>(w: &[i8], s: &[f32], b: &[f32], q_x: &[i16], x_scale: f32, y: &mut [f32]) {
    let mut acc = [0i32; R];
    for (acc, w_row) in acc.iter_mut().zip(w.chunks_exact(q_x.len().max(1))) {
        for (wv, xv) in w_row.iter().zip(q_x) {
            *acc += i32::from(*wv) * i32::from(*xv);
        }
    }
    scale_rows(&acc, s, b, x_scale, y);
}

#[inline(always)]
fn scale_rows(acc: &[i32], s: &[f32], b: &[f32], x_scale: f32, y: &mut [f32]) {
    for (((yo, acc), s), b) in y.iter_mut().zip(acc).zip(s).zip(b) {
        *yo = b + (s * x_scale) * *acc as f32;
    }
}

/// The `i8` rows on a Cortex-M4/M7 (ARMv7E-M, feature `armv7em-dsp`): two multiply-accumulates
/// per instruction with the DSP extension's SMLAD, on 16-bit halves.
///
/// Four `i8` weights load as one word; SXTB16 sign-extends bytes 0 and 2 into its two
/// halves, SXTB16 ROR 8 bytes 1 and 3. [`interleave`] stores each group of four input codes
/// in the matching order `x0 x2 | x1 x3`, so each word pair meets its inputs with two SMLADs.
/// Rows are taken `R` at a time so that each input word is loaded once for `R` rows. Stable
/// Rust has no intrinsics for these instructions (`core::arch::arm`'s are unstable), hence
/// three one-instruction `asm!` blocks: register in, register out, nothing else touched.
#[cfg(all(feature = "armv7em-dsp", target_arch = "arm"))]
mod dsp {
    use core::arch::asm;

    /// `[x0, x1, x2, x3]` -> `[x0, x2, x1, x3]` for each full group of four; the rest stays.
    pub(super) fn interleave(q_x: &mut [i16]) {
        let (groups, _) = q_x.as_chunks_mut::<4>();
        for g in groups {
            g.swap(1, 2);
        }
    }

    /// SXTB16 of `x` rotated right by `ROR` bits (0 or 8): bytes `ROR / 8` and `ROR / 8 + 2`
    /// sign-extended into the two halves.
    #[inline(always)]
    fn sxtb16<const ROR: u32>(x: u32) -> u32 {
        let r: u32;
        // SAFETY: one register-to-register instruction of ARMv7E-M (the feature's contract):
        // no memory, no stack, no flags.
        #[allow(unsafe_code)]
        unsafe {
            asm!(
                "sxtb16 {r}, {x}, ror #{ror}",
                r = lateout(reg) r,
                x = in(reg) x,
                ror = const ROR,
                options(pure, nomem, nostack, preserves_flags)
            )
        };
        r
    }

    #[inline(always)]
    fn smlad(a: u32, b: u32, acc: i32) -> i32 {
        let r: i32;
        // SAFETY: register-only, no memory or stack. It may set the sticky Q flag on overflow
        // (not `preserves_flags`), which nothing reads; the sums cannot overflow anyway
        // (`I8_MAX_IN_DIM`).
        #[allow(unsafe_code)]
        unsafe {
            asm!("smlad {r}, {a}, {b}, {acc}", r = lateout(reg) r, a = in(reg) a, b = in(reg) b, acc = in(reg) acc, options(pure, nomem, nostack))
        };
        r
    }

    /// The two SMLADs of one group of four weights against its interleaved inputs.
    #[inline(always)]
    fn group(acc: i32, w: &[i8; 4], x02: u32, x13: u32) -> i32 {
        let packed = u32::from_le_bytes(w.map(|v| v as u8));
        smlad(sxtb16::<8>(packed), x13, smlad(sxtb16::<0>(packed), x02, acc))
    }

    /// Rows four at a time share each input load; each row's slices are walked by one
    /// zipped iterator, so the loop has one end test (per-row iterators made LLVM spill the
    /// accumulators). Measured on the seed-0 policy when this was chosen: 210k instructions
    /// per forward with four rows (32 per 16 multiply-accumulates, three accumulators
    /// spilled), 242k with three (LLVM then shuffles the row pointers), 227k with two, 275k
    /// with per-row iterators. The surrounding code moves this by a few percent (218k since
    /// the length checks became `Layer::check_io`).
    /// Other row counts go one row at a time. The interleaved input groups are read as word
    /// pairs: `q_x` lies in the caller's `u32` buffer, so the cast cannot fail (if it did, the
    /// same sums would come from one row at a time, slower).
    #[inline(always)]
    pub(super) fn rows_i8<const R: usize>(
        w: &[i8],
        s: &[f32],
        b: &[f32],
        q_x: &[i16],
        x_scale: f32,
        y: &mut [f32],
    ) {
        let n_in = q_x.len().max(1);
        let (x_groups, x_tail) = q_x.as_chunks::<4>();
        let x_words: Option<&[[u32; 2]]> = bytemuck::try_cast_slice(x_groups).ok();
        let mut acc = [0i32; R];
        if let (Some(x_words), [r0, r1, r2, r3], [a0, a1, a2, a3]) = (
            x_words,
            [0, 1, 2, 3].map(|k| w.get(k * n_in..(k + 1) * n_in).unwrap_or(&[]).as_chunks::<4>().0),
            &mut acc[..],
        ) && R == 4
        {
            for ((((&[x02, x13], w0), w1), w2), w3) in x_words.iter().zip(r0).zip(r1).zip(r2).zip(r3) {
                *a0 = group(*a0, w0, x02, x13);
                *a1 = group(*a1, w1, x02, x13);
                *a2 = group(*a2, w2, x02, x13);
                *a3 = group(*a3, w3, x02, x13);
            }
        } else {
            for (a, row) in acc.iter_mut().zip(w.chunks_exact(n_in)) {
                for (xg, wg) in x_groups.iter().zip(row.as_chunks::<4>().0) {
                    let half = |v: i16| u32::from(v as u16);
                    let (x02, x13) = (half(xg[0]) | (half(xg[1]) << 16), half(xg[2]) | (half(xg[3]) << 16));
                    *a = group(*a, wg, x02, x13);
                }
            }
        }
        for (a, row) in acc.iter_mut().zip(w.chunks_exact(n_in)) {
            let (_, w_tail) = row.as_chunks::<4>();
            for (wv, xv) in w_tail.iter().zip(x_tail) {
                *a += i32::from(*wv) * i32::from(*xv);
            }
        }
        super::scale_rows(&acc, s, b, x_scale, y);
    }
}

#[cfg(all(feature = "armv7em-dsp", target_arch = "arm"))]
use dsp::rows_i8;

#[cfg(all(test, feature = "simd", target_arch = "x86_64"))]
#[allow(clippy::indexing_slicing)]
mod simd_tests {
    use super::{ROWS, dense_f};
    use crate::simd::{self, Level, SimdWeights};
    use crate::weights::f16_to_f32;

    /// xorshift64*: reproducible values without a dependency.
    struct Draw(u64);

    impl Draw {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }

        /// Uniform in [-1, 1).
        fn unit(&mut self) -> f32 {
            (self.next() >> 40) as f32 / (1u64 << 23) as f32 - 1.0
        }

        /// A finite half: any sign and mantissa, exponents 2^-10 .. 2^1.
        fn half(&mut self) -> u16 {
            let r = self.next();
            let sign = ((r >> 63) as u16) << 15;
            let exponent = (5 + (r >> 32) % 12) as u16;
            sign | (exponent << 10) | (r as u16 & 0x3ff)
        }
    }

    /// In and out sizes around the kernels' blocks: under, at and over one 8- or 16-lane chunk
    /// and four-row block, and the policy's 65-256-256-15.
    const SHAPES: [(usize, usize); 10] =
        [(16, 1), (17, 3), (8, 4), (23, 5), (65, 256), (256, 256), (256, 15), (31, 7), (64, 9), (1, 2)];

    fn levels() -> Vec<Level> {
        match simd::level() {
            Some(Level::Avx512) => vec![Level::Avx512, Level::Avx2],
            Some(Level::Avx2) => vec![Level::Avx2],
            None => vec![],
        }
    }

    extern crate std;
    use std::vec;
    use std::vec::Vec;

    /// Each output of the fused kernel within `simd::tolerance` of the portable kernel's, for
    /// both weight types at every level this CPU has; and the two are not the same function
    /// (some output differs in its last bits, or the test would not see a wrong order).
    fn check(weights_f16: bool) {
        let mut draw = Draw(0x9E37_79B9_7F4A_7C15);
        let mut differing = 0usize;
        for level in levels() {
            for (n_in, n_out) in SHAPES {
                let x: Vec<f32> = (0..n_in).map(|_| 4.0 * draw.unit()).collect();
                let b: Vec<f32> = (0..n_out).map(|_| draw.unit()).collect();
                let w16: Vec<u16> = (0..n_in * n_out).map(|_| draw.half()).collect();
                let w32: Vec<f32> = if weights_f16 {
                    w16.iter().map(|h| f16_to_f32(*h)).collect()
                } else {
                    (0..n_in * n_out).map(|_| draw.unit()).collect()
                };
                let mut portable = vec![0.0f32; n_out];
                let mut fused = vec![f32::NAN; n_out];
                let w = if weights_f16 {
                    dense_f::<ROWS, u16>(&w16, &b, &x, &mut portable, f16_to_f32);
                    SimdWeights::F16(&w16)
                } else {
                    dense_f::<ROWS, f32>(&w32, &b, &x, &mut portable, |v| v);
                    SimdWeights::F32(&w32)
                };
                assert!(simd::dense(level, w, &b, &x, &mut fused), "{level:?} is available");
                for r in 0..n_out {
                    let row = &w32[r * n_in..(r + 1) * n_in];
                    let abs: f32 = row.iter().zip(&x).map(|(w, x)| (w * x).abs()).sum();
                    let bound = simd::tolerance(n_in, b[r], abs);
                    let diff = (fused[r] - portable[r]).abs();
                    assert!(
                        diff <= bound,
                        "{level:?} {n_in}x{n_out} row {r}: fused {} portable {} differ by {diff} > {bound}",
                        fused[r],
                        portable[r]
                    );
                    differing += usize::from(fused[r] != portable[r]);
                }
            }
        }
        if !levels().is_empty() {
            assert!(differing > 0, "the fused kernel matched the portable one bit for bit everywhere");
        }
    }

    #[test]
    fn the_fused_f32_kernel_is_within_its_tolerance_of_the_portable_one() {
        check(false);
    }

    #[test]
    fn the_fused_f16_kernel_is_within_its_tolerance_of_the_portable_one() {
        check(true);
    }

    #[test]
    fn a_level_this_cpu_lacks_is_refused_and_leaves_the_output() {
        let mut y = [7.0f32; 2];
        let ran = simd::dense(Level::Avx512, SimdWeights::F32(&[1.0; 32]), &[0.0; 2], &[1.0; 16], &mut y);
        assert_eq!(ran, simd::level() == Some(Level::Avx512));
        if !ran {
            assert_eq!(y, [7.0; 2]);
        }
    }
}
