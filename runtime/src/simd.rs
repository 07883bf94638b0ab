//! The `simd` feature's floating-point kernel for x86-64: fused multiply-adds (AVX-512F, else
//! AVX2 with FMA) with four rows sharing each load of the input, and `f16` weights widened by
//! the F16C conversion instead of bit arithmetic.
//!
//! Not bit-identical to the portable kernel ([`crate::kernel`]): a fused multiply-add rounds
//! once where the portable kernel rounds the product and the sum, and the lanes are reduced in
//! another order. Both are sums of the same products, so they differ by at most the two
//! summations' rounding: [`tolerance`] bounds it, and the tests check every layer shape class
//! against it. The portable kernel stays what firmware and the default host build run (and
//! bit-exact between them); this one is opt-in for hosts.
//!
//! Which kernel runs: with `std`, the best this CPU has, detected once at run time; without
//! it, what the build's target features allow (`-C target-feature=+avx512f` or
//! `+avx2,+fma,+f16c`), else none, and the caller falls back to the portable kernel. On other
//! architectures the feature changes nothing.

use core::arch::x86_64::*;

/// A layer's weights as the kernel reads them.
#[derive(Debug, Clone, Copy)]
pub(crate) enum SimdWeights<'a> {
    F32(&'a [f32]),
    /// IEEE half-precision bits.
    F16(&'a [u16]),
}

/// Largest difference allowed between this kernel's output `y` and the portable kernel's for
/// one output: `(in_dim + 2) * f32::EPSILON * (|b| + sum |w_i x_i|)`. Each kernel's sum of
/// `in_dim + 1` terms is within `(in_dim + 1) * EPSILON / 2` of that magnitude from the exact
/// value (recursive summation's bound; pairwise and fused sums do better), so the two are
/// within the bound of each other.
#[must_use]
pub fn tolerance(in_dim: usize, bias: f32, abs_products: f32) -> f32 {
    (in_dim as f32 + 2.0) * f32::EPSILON * (bias.abs() + abs_products)
}

/// Which fused kernel this CPU (or build) runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Level {
    Avx512,
    Avx2,
}

/// The kernel this process uses, if any.
pub(crate) fn level() -> Option<Level> {
    #[cfg(feature = "std")]
    {
        extern crate std;
        static LEVEL: std::sync::OnceLock<Option<Level>> = std::sync::OnceLock::new();
        *LEVEL.get_or_init(|| {
            let avx2 = std::is_x86_feature_detected!("avx2")
                && std::is_x86_feature_detected!("fma")
                && std::is_x86_feature_detected!("f16c");
            match (avx2, std::is_x86_feature_detected!("avx512f")) {
                (true, true) => Some(Level::Avx512),
                (true, false) => Some(Level::Avx2),
                (false, _) => None,
            }
        })
    }
    #[cfg(not(feature = "std"))]
    {
        let avx2 = cfg!(all(target_feature = "avx2", target_feature = "fma", target_feature = "f16c"));
        match (avx2, cfg!(target_feature = "avx512f")) {
            (true, true) => Some(Level::Avx512),
            (true, false) => Some(Level::Avx2),
            (false, _) => None,
        }
    }
}

/// `y = W x + b` with the fused kernel at `level` (at most [`level()`]); `false` (and `y`
/// untouched) when this CPU or build cannot run it. The caller has checked the sizes
/// (`Layer::check_io`): `W` holds `y.len()` rows of `x.len()`, `b` one entry per row.
pub(crate) fn dense(level: Level, w: SimdWeights<'_>, bias: &[f32], x: &[f32], y: &mut [f32]) -> bool {
    let available = match (level, self::level()) {
        (_, None) | (Level::Avx512, Some(Level::Avx2)) => false,
        (_, Some(Level::Avx512)) | (Level::Avx2, Some(Level::Avx2)) => true,
    };
    if !available {
        return false;
    }
    // SAFETY: each function only needs the target features it enables, and `level()` found
    // them on this CPU (std) or in this build's target features (no_std).
    #[allow(unsafe_code)]
    unsafe {
        match (level, w) {
            (Level::Avx512, SimdWeights::F32(w)) => avx512::dense(w, bias, x, y, avx512::load_f32, |v| v),
            (Level::Avx512, SimdWeights::F16(w)) => {
                avx512::dense(w, bias, x, y, avx512::load_f16, crate::weights::f16_to_f32)
            }
            (Level::Avx2, SimdWeights::F32(w)) => avx2::dense(w, bias, x, y, avx2::load_f32, |v| v),
            (Level::Avx2, SimdWeights::F16(w)) => {
                avx2::dense(w, bias, x, y, avx2::load_f16, crate::weights::f16_to_f32)
            }
        }
    }
    true
}

/// Rows per block: each input vector is loaded once for this many rows, and their
/// accumulators are independent chains that hide the fused multiply-add's latency.
const ROWS: usize = 4;

/// One kernel per vector width: `$lanes` lanes of `$vec`, the loads, fused multiply-add and
/// lane sum of that width, compiled with `$features`.
macro_rules! fused_kernel {
    ($features:literal, $lanes:literal, $vec:ty, $zero:expr, $fmadd:ident, $reduce:expr, $load_f32:expr) => {
        pub(super) const LANES: usize = $lanes;

        /// `y = W x + b`: [`super::ROWS`] rows at a time, then one at a time.
        #[target_feature(enable = $features)]
        pub(super) fn dense<W: Copy>(
            w: &[W],
            bias: &[f32],
            x: &[f32],
            y: &mut [f32],
            load: impl Fn(&[W; LANES]) -> $vec + Copy,
            widen: impl Fn(W) -> f32 + Copy,
        ) {
            let n_in = x.len().max(1);
            let mut w_blocks = w.chunks_exact(n_in * super::ROWS);
            let mut y_blocks = y.chunks_exact_mut(super::ROWS);
            let mut b_blocks = bias.chunks_exact(super::ROWS);
            for ((wb, yb), bb) in (&mut w_blocks).zip(&mut y_blocks).zip(&mut b_blocks) {
                rows::<W, { super::ROWS }>(wb, bb, x, yb, load, widen);
            }
            for ((wr, yo), b) in w_blocks
                .remainder()
                .chunks_exact(n_in)
                .zip(y_blocks.into_remainder())
                .zip(b_blocks.remainder())
            {
                let (b, yo) = (core::slice::from_ref(b), core::slice::from_mut(yo));
                rows::<W, 1>(wr, b, x, yo, load, widen);
            }
        }

        /// `y[r] = b[r] + w_r · x` for the `R` rows of `w`: one accumulator per row over the
        /// input's whole vectors, then the lane sum plus the input's last `len % LANES`
        /// products (scalar: at most one partial vector per row).
        #[inline]
        #[target_feature(enable = $features)]
        fn rows<W: Copy, const R: usize>(
            w: &[W],
            b: &[f32],
            x: &[f32],
            y: &mut [f32],
            load: impl Fn(&[W; LANES]) -> $vec,
            widen: impl Fn(W) -> f32,
        ) {
            let (x_chunks, x_tail) = x.as_chunks::<LANES>();
            let mut split: [(&[[W; LANES]], &[W]); R] = [(&[], &[]); R];
            for (s, row) in split.iter_mut().zip(w.chunks_exact(x.len().max(1))) {
                *s = row.as_chunks::<LANES>();
            }
            let mut acc: [$vec; R] = [$zero; R];
            for (c, xc) in x_chunks.iter().enumerate() {
                let xv = $load_f32(xc);
                for (a, (chunks, _)) in acc.iter_mut().zip(&split) {
                    if let Some(wc) = chunks.get(c) {
                        *a = $fmadd(load(wc), xv, *a);
                    }
                }
            }
            for (((yo, a), (_, w_tail)), b) in y.iter_mut().zip(&acc).zip(&split).zip(b) {
                let mut tail = 0.0f32;
                for (wv, xv) in w_tail.iter().zip(x_tail) {
                    tail += widen(*wv) * xv;
                }
                *yo = b + ($reduce(*a) + tail);
            }
        }
    };
}

/// The AVX-512F kernel: 16 lanes.
mod avx512 {
    use super::{__m512, _mm256_loadu_si256};
    use super::{_mm512_cvtph_ps, _mm512_fmadd_ps, _mm512_loadu_ps, _mm512_reduce_add_ps, _mm512_setzero_ps};

    fused_kernel!(
        "avx512f,avx2,fma,f16c",
        16,
        __m512,
        _mm512_setzero_ps(),
        _mm512_fmadd_ps,
        _mm512_reduce_add_ps,
        load_f32
    );

    /// 16 weights as `f32`.
    #[inline(always)]
    pub(super) fn load_f32(w: &[f32; LANES]) -> __m512 {
        // SAFETY: reads the 16 floats of `w`, unaligned; called only from the kernel above,
        // compiled for AVX-512F.
        #[allow(unsafe_code)]
        unsafe {
            _mm512_loadu_ps(w.as_ptr())
        }
    }

    /// 16 half-precision weights widened to `f32` (exact).
    #[inline(always)]
    pub(super) fn load_f16(w: &[u16; LANES]) -> __m512 {
        // SAFETY: reads the 32 bytes of `w`, unaligned; called only from the kernel above.
        #[allow(unsafe_code)]
        unsafe {
            _mm512_cvtph_ps(_mm256_loadu_si256(w.as_ptr().cast()))
        }
    }
}

/// The AVX2 + FMA kernel: 8 lanes.
mod avx2 {
    use super::{__m256, _mm_loadu_si128};
    use super::{_mm_add_ps, _mm_add_ss, _mm_cvtss_f32, _mm_movehl_ps, _mm_shuffle_ps};
    use super::{_mm256_castps256_ps128, _mm256_cvtph_ps, _mm256_extractf128_ps};
    use super::{_mm256_fmadd_ps, _mm256_loadu_ps, _mm256_setzero_ps};

    fused_kernel!("avx2,fma,f16c", 8, __m256, _mm256_setzero_ps(), _mm256_fmadd_ps, reduce, load_f32);

    /// 8 weights as `f32`.
    #[inline(always)]
    pub(super) fn load_f32(w: &[f32; LANES]) -> __m256 {
        // SAFETY: reads the 8 floats of `w`, unaligned; called only from the kernel above,
        // compiled for AVX2.
        #[allow(unsafe_code)]
        unsafe {
            _mm256_loadu_ps(w.as_ptr())
        }
    }

    /// 8 half-precision weights widened to `f32` (exact).
    #[inline(always)]
    pub(super) fn load_f16(w: &[u16; LANES]) -> __m256 {
        // SAFETY: reads the 16 bytes of `w`, unaligned; called only from the kernel above.
        #[allow(unsafe_code)]
        unsafe {
            _mm256_cvtph_ps(_mm_loadu_si128(w.as_ptr().cast()))
        }
    }

    /// The sum of the 8 lanes.
    #[inline]
    #[target_feature(enable = "avx2,fma,f16c")]
    fn reduce(v: __m256) -> f32 {
        let s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
        let s = _mm_add_ps(s, _mm_movehl_ps(s, s));
        _mm_cvtss_f32(_mm_add_ss(s, _mm_shuffle_ps::<0b01>(s, s)))
    }
}
