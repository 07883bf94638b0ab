//! Weight storage types: `f32`, `f16` and per-row-scaled `i8`, each borrowed in place.

/// How a layer's weight matrix is stored (biases are always `f32`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WeightType {
    /// IEEE-754 binary32: 4 bytes per weight, exact.
    F32,
    /// IEEE-754 binary16: 2 bytes per weight, widened to `f32` as it is read (about 3
    /// significant digits).
    F16,
    /// Signed 8-bit with one `f32` scale per output row: `w[r][c] = scale[r] * q[r][c]`.
    /// The layer input is quantised to `i16` (one scale per call, `max|x| / 32767`: its
    /// rounding is negligible beside the weights'), the products are summed exactly in `i32`
    /// (hence at most [`I8_MAX_IN_DIM`] inputs), and the sum is scaled back to `f32` with the
    /// bias. The same scheme as CMSIS-NN's `s8` kernels, which widen inputs to `q15` to
    /// multiply.
    I8,
}

impl WeightType {
    /// The code stored in a v2 policy file.
    pub const fn code(self) -> u8 {
        match self {
            Self::F32 => 0,
            Self::F16 => 1,
            Self::I8 => 2,
        }
    }

    /// The type of a stored code, if known.
    pub const fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(Self::F32),
            1 => Some(Self::F16),
            2 => Some(Self::I8),
            _ => None,
        }
    }

    /// Bytes per weight in the file and in memory.
    pub const fn bytes_per_weight(self) -> usize {
        match self {
            Self::F32 => 4,
            Self::F16 => 2,
            Self::I8 => 1,
        }
    }

    /// `"f32"`, `"f16"` or `"i8"`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::F16 => "f16",
            Self::I8 => "i8",
        }
    }
}

impl core::fmt::Display for WeightType {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// A layer's weight matrix, row-major `out_dim × in_dim`, borrowed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Weights<'a> {
    F32(&'a [f32]),
    /// binary16 bit patterns (see [`f16_to_f32`]).
    F16(&'a [u16]),
    /// Quantised weights and one scale per output row.
    I8 {
        q: &'a [i8],
        row_scale: &'a [f32],
    },
}

impl Weights<'_> {
    /// Number of weights.
    pub fn len(&self) -> usize {
        match self {
            Self::F32(w) => w.len(),
            Self::F16(w) => w.len(),
            Self::I8 { q, .. } => q.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn weight_type(&self) -> WeightType {
        match self {
            Self::F32(_) => WeightType::F32,
            Self::F16(_) => WeightType::F16,
            Self::I8 { .. } => WeightType::I8,
        }
    }

    /// Index of the first weight (or row scale) that is not finite, or a row scale that is
    /// not > 0.
    pub(crate) fn first_invalid(&self) -> Option<usize> {
        match self {
            Self::F32(w) => w.iter().position(|v| !v.is_finite()),
            Self::F16(w) => w.iter().position(|&h| !f16_is_finite(h)),
            Self::I8 { row_scale, .. } => row_scale.iter().position(|s| !(s.is_finite() && *s > 0.0)),
        }
    }
}

/// Most inputs an `i8` layer may have: `127 · 32767 · n` must fit in an `i32` sum.
pub const I8_MAX_IN_DIM: usize = (i32::MAX as usize) / (127 * 32767);

/// Whether a binary16 bit pattern is finite (its exponent field is not all ones).
#[inline]
pub const fn f16_is_finite(h: u16) -> bool {
    h & 0x7C00 != 0x7C00
}

/// Widens a finite binary16 bit pattern to `f32`, exactly (subnormals included).
///
/// Moving the exponent and mantissa fields into an `f32`'s (shift by 13) gives the value
/// scaled by 2^-112; one multiplication by 2^112 corrects it, and is exact for normal and
/// subnormal inputs alike. Branch-free, so the kernels' loops still vectorise (a table or
/// a branchy conversion would not); this is why it is written here rather than taken from
/// the `half` crate, whose portable path branches. Infinities and NaNs (rejected when a file
/// loads) would come out finite and wrong.
#[inline(always)]
pub fn f16_to_f32(h: u16) -> f32 {
    const TWO_POW_112: f32 = f32::from_bits((127 + 112) << 23);
    let magnitude = f32::from_bits(u32::from(h & 0x7FFF) << 13) * TWO_POW_112;
    f32::from_bits(magnitude.to_bits() | (u32::from(h & 0x8000) << 16))
}

/// Quantises `x` to `i16` with one symmetric scale `max|x| / 32767` (round half away from
/// zero), writing the codes to `q`; returns the scale (0 when `x` is all zeros, so every code
/// is 0).
#[inline]
pub(crate) fn quantise_input(x: &[f32], q: &mut [i16]) -> f32 {
    let max_abs = x.iter().fold(0.0f32, |m, v| if v.abs() > m { v.abs() } else { m });
    if max_abs == 0.0 {
        q.fill(0);
        return 0.0;
    }
    let inv = 32767.0 / max_abs;
    for (qi, xi) in q.iter_mut().zip(x) {
        let v = xi * inv;
        // `as` saturates, and |v| <= 32767 by construction; the +-0.5 rounds half away from 0.
        *qi = if v >= 0.0 { (v + 0.5) as i16 } else { (v - 0.5) as i16 };
    }
    max_abs / 32767.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f16_widening_matches_the_definition_on_every_finite_pattern() {
        for h in 0..=u16::MAX {
            if !f16_is_finite(h) {
                continue;
            }
            let sign = if h & 0x8000 != 0 { -1.0f64 } else { 1.0 };
            let exp = i32::from((h >> 10) & 0x1F);
            let mant = f64::from(h & 0x3FF);
            let expected = if exp == 0 {
                sign * mant * 2f64.powi(-24)
            } else {
                sign * (1.0 + mant / 1024.0) * 2f64.powi(exp - 15)
            };
            let got = f16_to_f32(h);
            assert_eq!(f64::from(got), expected, "pattern {h:#06x}");
            assert_eq!(got.is_sign_negative(), h & 0x8000 != 0, "sign of {h:#06x}");
        }
    }

    #[test]
    fn weight_type_codes_round_trip() {
        for t in [WeightType::F32, WeightType::F16, WeightType::I8] {
            assert_eq!(WeightType::from_code(t.code()), Some(t));
        }
        assert_eq!(WeightType::from_code(3), None);
    }

    #[test]
    fn input_quantisation_is_symmetric_and_rounds_half_away() {
        let mut q = [0i16; 5];
        // max |x| = 32767: the scale is 1 and every product below is exact.
        let s = quantise_input(&[32767.0, -32767.0, 63.5, 0.0, -0.5], &mut q);
        assert_eq!(s, 1.0);
        assert_eq!(q, [32767, -32767, 64, 0, -1]);
        assert_eq!(quantise_input(&[0.0; 3], &mut q[..3]), 0.0);
        assert_eq!(I8_MAX_IN_DIM, 516);
        assert_eq!(q[..3], [0, 0, 0]);
    }
}
