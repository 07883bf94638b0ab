//! Weight quantisation for version-2 policy files: `f16` (round to nearest even) and `i8`
//! with one symmetric scale per output row, the scheme `vge_runtime`'s kernels read.

use half::f16;

use crate::ExportError;

/// Rounds each weight to the nearest binary16; a weight beyond f16's range (±65504) is an
/// error rather than an infinity the runtime would refuse.
pub fn to_f16(weights: &[f32], layer: usize) -> Result<Vec<u16>, ExportError> {
    weights
        .iter()
        .enumerate()
        .map(|(i, &w)| {
            let h = f16::from_f32(w);
            if h.is_finite() {
                Ok(h.to_bits())
            } else {
                Err(ExportError::InvalidSpec(format!(
                    "layer {layer} weight {i} = {w} is outside the f16 range (±65504)"
                )))
            }
        })
        .collect()
}

/// Per-row symmetric `i8`: `scale[r] = max_c |w[r][c]| / 127`, `q = round(w / scale)` (half
/// away from zero), so every row uses the full ±127. An all-zero row gets scale 1 (any
/// positive scale represents it; the runtime requires > 0).
pub fn to_i8(weights: &[f32], in_dim: usize) -> (Vec<i8>, Vec<f32>) {
    let mut q = Vec::with_capacity(weights.len());
    let mut scales = Vec::with_capacity(weights.len() / in_dim.max(1));
    for row in weights.chunks(in_dim.max(1)) {
        let max_abs = row.iter().fold(0.0f32, |m, w| m.max(w.abs()));
        let scale = if max_abs > 0.0 { max_abs / 127.0 } else { 1.0 };
        q.extend(row.iter().map(|w| (w / scale).round().clamp(-127.0, 127.0) as i8));
        scales.push(scale);
    }
    (q, scales)
}

/// The weights a quantised row holds: `scale[r] * q[r][c]`.
pub fn from_i8(q: &[i8], scales: &[f32], in_dim: usize) -> Vec<f32> {
    q.chunks(in_dim.max(1))
        .zip(scales)
        .flat_map(|(row, s)| row.iter().map(move |&v| s * f32::from(v)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn i8_rows_use_the_full_range_and_round_trip_within_half_a_step() {
        let w = [0.5, -1.0, 0.25, 0.0, 0.0, 0.0, 2.0, 1.0, -0.003];
        let (q, s) = to_i8(&w, 3);
        assert_eq!(s, vec![1.0 / 127.0, 1.0, 2.0 / 127.0]);
        assert_eq!(q[..3], [64, -127, 32]);
        assert_eq!(q[3..6], [0, 0, 0]);
        assert_eq!(q[6], 127);
        let back = from_i8(&q, &s, 3);
        for (r, (a, b)) in w.iter().zip(&back).enumerate() {
            assert!((a - b).abs() <= 0.5 * s[r / 3] + 1e-7, "weight {r}: {a} vs {b}");
        }
    }

    #[test]
    fn f16_refuses_what_it_cannot_hold() {
        assert_eq!(to_f16(&[1.0, -2.5], 0).expect("in range"), vec![0x3C00, 0xC100]);
        assert!(matches!(to_f16(&[7.0e4], 3), Err(ExportError::InvalidSpec(m)) if m.contains("layer 3")));
    }
}
