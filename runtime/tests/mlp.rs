//! Host tests for the MLP runtime: hand-computed networks and every error path.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use vge_runtime::{Activation, Layer, Mlp, PolicyMlp, RuntimeError, Weights};

type Small<'a> = Mlp<'a, 4, 8>;

fn layer<'a>(in_dim: usize, out_dim: usize, w: &'a [f32], b: &'a [f32], act: Activation) -> Layer<'a> {
    Layer { in_dim, out_dim, weights: Weights::F32(w), bias: b, activation: act }
}

// 3×2 row-major: rows [1,2], [3,4], [5,6]. Non-square, so a transposed layout would fail.
const W32: [f32; 6] = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];

#[test]
fn single_identity_layer_is_row_major() {
    let b = [0.5, -0.5, 1.0];
    let mlp = Small::new(&[layer(2, 3, &W32, &b, Activation::Identity)]).unwrap();
    assert_eq!((mlp.in_dim(), mlp.out_dim()), (2, 3));
    let mut y = [0.0; 3];
    mlp.forward(&[1.0, -1.0], &mut y).unwrap();
    assert_eq!(y, [-0.5, -1.5, 0.0]);
}

#[test]
fn relu_then_identity() {
    let b0 = [0.5, -20.0, 1.0];
    let w1 = [1.0, 100.0, -0.5];
    let b1 = [0.25];
    let mlp =
        Small::new(&[layer(2, 3, &W32, &b0, Activation::Relu), layer(3, 1, &w1, &b1, Activation::Identity)])
            .unwrap();
    // hidden = relu([4.5, -10.5, 17]) = [4.5, 0, 17]; out = 4.5 + 0 - 8.5 + 0.25
    let mut y = [0.0; 1];
    mlp.forward(&[2.0, 1.0], &mut y).unwrap();
    assert_eq!(y, [-3.75]);
}

#[test]
fn three_layers_relu_identity_tanh() {
    let w0 = [1.0, -1.0, 0.5, 2.0];
    let b0 = [0.0, -1.0];
    let w1 = [0.5, 0.0, -1.0, 1.0, 0.25, 0.75];
    let b1 = [0.1, 0.2, -0.3];
    let w2 = [0.3, -0.2, 0.1, -0.4, 0.6, 0.2];
    let b2 = [0.05, -0.05];
    let mlp = Small::new(&[
        layer(2, 2, &w0, &b0, Activation::Relu),
        layer(2, 3, &w1, &b1, Activation::Identity),
        layer(3, 2, &w2, &b2, Activation::Tanh),
    ])
    .unwrap();
    let x = [0.8f32, -0.3];
    // By hand: h0 = relu([0.8 + 0.3, 0.4 - 0.6 - 1]) = [1.1, 0]
    //          h1 = [0.55 + 0.1, -1.1 + 0.2, 0.275 - 0.3] = [0.65, -0.9, -0.025]
    //          out = tanh([0.195 + 0.18 - 0.0025 + 0.05, -0.26 - 0.54 - 0.005 - 0.05])
    let expected = [0.4225f64.tanh(), (-0.855f64).tanh()];
    let mut y = [0.0; 2];
    mlp.forward(&x, &mut y).unwrap();
    for (got, want) in y.iter().zip(expected) {
        assert!((f64::from(*got) - want).abs() < 1e-6, "{got} vs {want}");
    }
}

#[test]
fn tanh_saturates_without_nan() {
    let w = [1.0e30];
    let b = [0.0];
    let mlp = Small::new(&[layer(1, 1, &w, &b, Activation::Tanh)]).unwrap();
    let mut y = [0.0];
    mlp.forward(&[1.0e8], &mut y).unwrap();
    assert_eq!(y, [1.0]);
    mlp.forward(&[-1.0e8], &mut y).unwrap();
    assert_eq!(y, [-1.0]);
}

/// A policy-sized network against a naive f64 reference.
#[test]
fn policy_sized_matches_naive_reference() {
    let dims = [65usize, 256, 256, 15];
    // Deterministic pseudo-random parameters (LCG) in [-0.1, 0.1).
    let mut state = 0x1234_5678_u32;
    let mut next = || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32 * 0.2 - 0.1
    };
    let params: Vec<(Vec<f32>, Vec<f32>)> = dims
        .windows(2)
        .map(|d| ((0..d[0] * d[1]).map(|_| next()).collect(), (0..d[1]).map(|_| next()).collect()))
        .collect();
    let acts = [Activation::Relu, Activation::Relu, Activation::Tanh];
    let layers: Vec<Layer<'_>> = params
        .iter()
        .zip(dims.windows(2))
        .zip(acts)
        .map(|(((w, b), d), a)| layer(d[0], d[1], w, b, a))
        .collect();
    let mlp = PolicyMlp::new(&layers).unwrap();

    for _ in 0..20 {
        let obs: Vec<f32> = (0..65).map(|_| next() * 30.0).collect();
        let mut x: Vec<f64> = obs.iter().map(|&v| f64::from(v)).collect();
        for (l, (w, _)) in layers.iter().zip(&params) {
            x = (0..l.out_dim)
                .map(|o| {
                    let s: f64 = (0..l.in_dim).map(|i| f64::from(w[o * l.in_dim + i]) * x[i]).sum::<f64>()
                        + f64::from(l.bias[o]);
                    match l.activation {
                        Activation::Identity => s,
                        Activation::Relu => s.max(0.0),
                        Activation::Tanh => s.tanh(),
                    }
                })
                .collect();
        }
        let mut y = [0.0f32; 15];
        mlp.forward(&obs, &mut y).unwrap();
        let max_diff = y.iter().zip(&x).map(|(a, b)| (f64::from(*a) - b).abs()).fold(0.0, f64::max);
        assert!(max_diff < 1e-5, "max diff {max_diff}");
    }
}

#[test]
fn full_capacity_width_works() {
    let w = [1.0f32; 8 * 8];
    let b = [0.0f32; 8];
    let mlp = Small::new(&[layer(8, 8, &w, &b, Activation::Identity); 4]).unwrap();
    let mut y = [0.0; 8];
    mlp.forward(&[1.0; 8], &mut y).unwrap();
    assert_eq!(y, [8.0f32 * 8.0 * 8.0 * 8.0; 8]);
}

#[test]
fn empty_network_rejected() {
    assert_eq!(Small::new(&[]).unwrap_err(), RuntimeError::NoLayers);
}

#[test]
fn too_many_layers_rejected() {
    let w = [1.0];
    let b = [0.0];
    let l = layer(1, 1, &w, &b, Activation::Identity);
    let err = Mlp::<'_, 2, 4>::new(&[l, l, l]).unwrap_err();
    assert_eq!(err, RuntimeError::TooManyLayers { count: 3, max: 2 });
}

#[test]
fn width_over_capacity_rejected() {
    let w = [0.0f32; 9 * 2];
    let b = [0.0f32; 2];
    let err = Small::new(&[layer(9, 2, &w, &b, Activation::Relu)]).unwrap_err();
    assert_eq!(err, RuntimeError::WidthExceedsCapacity { layer: 0, dim: 9, max: 8 });
    let w = [0.0f32; 2 * 9];
    let b = [0.0f32; 9];
    let err = Small::new(&[layer(2, 9, &w, &b, Activation::Relu)]).unwrap_err();
    assert_eq!(err, RuntimeError::WidthExceedsCapacity { layer: 0, dim: 9, max: 8 });
}

#[test]
fn dimension_chain_mismatch_rejected() {
    let b3 = [0.0; 3];
    let w2 = [0.0; 2 * 2];
    let b2 = [0.0; 2];
    let err =
        Small::new(&[layer(2, 3, &W32, &b3, Activation::Relu), layer(2, 2, &w2, &b2, Activation::Tanh)])
            .unwrap_err();
    assert_eq!(err, RuntimeError::DimMismatch { layer: 1, expected_in: 3, got_in: 2 });
}

#[test]
fn slice_length_and_zero_dim_errors() {
    let b3 = [0.0; 3];
    let err = Small::new(&[layer(2, 3, &W32[..5], &b3, Activation::Relu)]).unwrap_err();
    assert_eq!(err, RuntimeError::WeightLen { layer: 0, expected: 6, got: 5 });
    let err = Small::new(&[layer(2, 3, &W32, &b3[..2], Activation::Relu)]).unwrap_err();
    assert_eq!(err, RuntimeError::BiasLen { layer: 0, expected: 3, got: 2 });
    let err = Small::new(&[layer(0, 3, &[], &b3, Activation::Relu)]).unwrap_err();
    assert_eq!(err, RuntimeError::ZeroDim { layer: 0 });
    let err =
        Mlp::<'_, 1, { usize::MAX }>::new(&[layer(usize::MAX, 2, &W32, &b3, Activation::Relu)]).unwrap_err();
    assert_eq!(err, RuntimeError::SizeOverflow { layer: 0 });
}

#[test]
fn non_finite_parameters_rejected() {
    let b = [0.0; 3];
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut w = W32;
        w[4] = bad;
        let err = Small::new(&[layer(2, 3, &w, &b, Activation::Relu)]).unwrap_err();
        assert_eq!(err, RuntimeError::NonFiniteWeight { layer: 0, index: 4 });
        let bias = [0.0, 0.0, bad];
        let err = Small::new(&[layer(2, 3, &W32, &bias, Activation::Relu)]).unwrap_err();
        assert_eq!(err, RuntimeError::NonFiniteBias { layer: 0, index: 2 });
    }
}

#[test]
fn forward_input_errors_leave_action_untouched() {
    let b = [0.0; 3];
    let mlp = Small::new(&[layer(2, 3, &W32, &b, Activation::Tanh)]).unwrap();
    let mut y = [7.0; 3];
    assert_eq!(mlp.forward(&[1.0], &mut y), Err(RuntimeError::ObsLen { expected: 2, got: 1 }));
    assert_eq!(mlp.forward(&[1.0, 2.0, 3.0], &mut y), Err(RuntimeError::ObsLen { expected: 2, got: 3 }));
    assert_eq!(mlp.forward(&[1.0, 2.0], &mut [0.0; 2]), Err(RuntimeError::ActionLen { expected: 3, got: 2 }));
    assert_eq!(mlp.forward(&[f32::NAN, 0.0], &mut y), Err(RuntimeError::NonFiniteObs { index: 0 }));
    assert_eq!(mlp.forward(&[0.0, f32::NEG_INFINITY], &mut y), Err(RuntimeError::NonFiniteObs { index: 1 }));
    assert_eq!(y, [7.0; 3]);
}

#[test]
fn overflowing_output_is_an_error() {
    let w = [3.0e38, 3.0e38];
    let b = [0.0];
    let mlp = Small::new(&[layer(2, 1, &w, &b, Activation::Identity)]).unwrap();
    let mut y = [7.0];
    assert_eq!(
        mlp.forward(&[10.0, 10.0], &mut y),
        Err(RuntimeError::NonFiniteActivation { layer: 0, index: 0 })
    );
    assert_eq!(y, [7.0]);
}

/// A hidden layer that overflows to NaN (inf - inf) must not be laundered by ReLU into 0, nor
/// an overflow to inf by tanh into a valid-looking ±1: both stop the forward pass, naming the
/// layer, whichever kernel (narrow or dense) runs it.
#[test]
fn overflow_inside_the_network_is_caught_at_its_layer() {
    let (w1, b1) = ([1.0f32; 3], [0.0f32]);
    for in_dim in [2usize, 32] {
        // Row 1 sums +3e38 * 10 and -3e38 * 10: inf - inf = NaN.
        let mut w0 = vec![0.1f32; 3 * in_dim];
        w0[in_dim] = 3.0e38;
        w0[in_dim + 1] = -3.0e38;
        let b0 = [0.0f32; 3];
        let x = vec![10.0f32; in_dim];
        let relu = Mlp::<4, 64>::new(&[
            layer(in_dim, 3, &w0, &b0, Activation::Relu),
            layer(3, 1, &w1, &b1, Activation::Tanh),
        ])
        .unwrap();
        let mut y = [7.0];
        assert_eq!(relu.forward(&x, &mut y), Err(RuntimeError::NonFiniteActivation { layer: 0, index: 1 }));
        assert_eq!(y, [7.0], "the action is left untouched");

        // Row 2 overflows to +inf; tanh of it would be exactly 1.
        let mut w0 = vec![0.1f32; 3 * in_dim];
        w0[2 * in_dim] = 3.0e38;
        let tanh = Mlp::<4, 64>::new(&[
            layer(in_dim, 3, &w0, &b0, Activation::Tanh),
            layer(3, 1, &w1, &b1, Activation::Identity),
        ])
        .unwrap();
        assert_eq!(tanh.forward(&x, &mut y), Err(RuntimeError::NonFiniteActivation { layer: 0, index: 2 }));
    }
    assert_eq!(Activation::Relu.apply(f32::NAN).to_bits(), f32::NAN.to_bits());
    assert_eq!((Activation::Relu.apply(-2.0), Activation::Relu.apply(2.0)), (0.0, 2.0));
}

#[test]
fn errors_display() {
    let e = RuntimeError::DimMismatch { layer: 1, expected_in: 3, got_in: 2 };
    assert_eq!(e.to_string(), "layer 1 takes 2 inputs but the previous layer outputs 3");
    assert_eq!(RuntimeError::NonFiniteObs { index: 4 }.to_string(), "observation 4 is not finite");
}

/// A 65-256-256-15 network's parameters from a fixed LCG, weights in [-0.1, 0.1).
fn hand_sized_params() -> Vec<(Vec<f32>, Vec<f32>)> {
    let mut state = 0x9E37_79B9_u32;
    let mut next = || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32 * 0.2 - 0.1
    };
    [65usize, 256, 256, 15]
        .windows(2)
        .map(|d| ((0..d[0] * d[1]).map(|_| next()).collect(), (0..d[1]).map(|_| next()).collect()))
        .collect()
}

const ACTS: [Activation; 3] = [Activation::Relu, Activation::Relu, Activation::Tanh];

fn observation(k: usize) -> Vec<f32> {
    (0..65).map(|i| ((i * 7 + k * 13) % 31) as f32 / 5.0 - 3.0).collect()
}

#[test]
fn f16_kernel_equals_the_f32_kernel_on_the_widened_weights() {
    let params = hand_sized_params();
    let halves: Vec<Vec<u16>> =
        params.iter().map(|(w, _)| w.iter().map(|v| half_bits(*v)).collect()).collect();
    let widened: Vec<Vec<f32>> =
        halves.iter().map(|h| h.iter().map(|b| vge_runtime::f16_to_f32(*b)).collect()).collect();
    let dims = [65usize, 256, 256, 15];
    let f16_layers: Vec<Layer<'_>> = (0..3)
        .map(|k| Layer {
            in_dim: dims[k],
            out_dim: dims[k + 1],
            weights: Weights::F16(&halves[k]),
            bias: &params[k].1,
            activation: ACTS[k],
        })
        .collect();
    let f32_layers: Vec<Layer<'_>> =
        (0..3).map(|k| layer(dims[k], dims[k + 1], &widened[k], &params[k].1, ACTS[k])).collect();
    let (a, b) = (PolicyMlp::new(&f16_layers).unwrap(), PolicyMlp::new(&f32_layers).unwrap());
    for k in 0..10 {
        let (mut ya, mut yb) = ([0.0f32; 15], [0.0f32; 15]);
        a.forward(&observation(k), &mut ya).unwrap();
        b.forward(&observation(k), &mut yb).unwrap();
        assert_eq!(ya, yb, "same summation order, so bit-identical");
    }
}

/// binary16 bits of `v` (|v| < 65504): round-to-nearest-even on the f32 bits for normal
/// values, `|v| * 2^24` rounded for subnormal ones, so the test does not lean on the code it
/// checks.
fn half_bits(v: f32) -> u16 {
    let bits = v.to_bits();
    let sign = ((bits >> 16) & 0x8000) as u16;
    let exp = ((bits >> 23) & 0xFF) as i32 - 127 + 15;
    assert!(exp < 31, "{v} outside the f16 range");
    if exp < 1 {
        return sign | (f64::from(v.abs()) * 2f64.powi(24)).round() as u16;
    }
    let mant = bits & 0x7F_FFFF;
    let mut h = ((exp as u32) << 10) | (mant >> 13);
    let rest = mant & 0x1FFF;
    if rest > 0x1000 || (rest == 0x1000 && h & 1 == 1) {
        h += 1;
    }
    sign | h as u16
}

#[test]
fn i8_kernel_matches_the_dequantised_network_within_its_input_rounding() {
    let params = hand_sized_params();
    let dims = [65usize, 256, 256, 15];
    // Per-row symmetric quantisation, as vge-export writes it.
    let quantised: Vec<(Vec<i8>, Vec<f32>)> = params
        .iter()
        .zip(dims.windows(2))
        .map(|((w, _), d)| {
            let mut q = Vec::new();
            let mut s = Vec::new();
            for row in w.chunks(d[0]) {
                let scale = row.iter().fold(0.0f32, |m, v| m.max(v.abs())) / 127.0;
                q.extend(row.iter().map(|v| (v / scale).round() as i8));
                s.push(scale);
            }
            (q, s)
        })
        .collect();
    let layers: Vec<Layer<'_>> = (0..3)
        .map(|k| Layer {
            in_dim: dims[k],
            out_dim: dims[k + 1],
            weights: Weights::I8 { q: &quantised[k].0, row_scale: &quantised[k].1 },
            bias: &params[k].1,
            activation: ACTS[k],
        })
        .collect();
    let mlp = PolicyMlp::new(&layers).unwrap();
    for k in 0..10 {
        let obs = observation(k);
        // Reference in f64 with the dequantised weights and exact (unquantised) inputs.
        let mut x: Vec<f64> = obs.iter().map(|&v| f64::from(v)).collect();
        for (l, (q, s)) in layers.iter().zip(&quantised) {
            x = (0..l.out_dim)
                .map(|o| {
                    let dot: f64 =
                        (0..l.in_dim).map(|i| f64::from(s[o]) * f64::from(q[o * l.in_dim + i]) * x[i]).sum();
                    let v = dot + f64::from(l.bias[o]);
                    if l.activation == Activation::Tanh { v.tanh() } else { v.max(0.0) }
                })
                .collect();
        }
        let mut y = [0.0f32; 15];
        mlp.forward(&obs, &mut y).unwrap();
        let max_diff = y.iter().zip(&x).map(|(a, b)| (f64::from(*a) - b).abs()).fold(0.0, f64::max);
        // Each layer's input is rounded to 1/65534 of its largest value: far below the
        // weights' rounding, which the reference shares.
        assert!(max_diff < 1e-3, "observation {k}: max diff {max_diff}");
        assert!(max_diff > 0.0, "the input quantisation must show");
    }
}

#[test]
fn an_i8_layer_too_wide_for_exact_i32_sums_is_refused_when_built() {
    let n_in = vge_runtime::I8_MAX_IN_DIM + 1;
    let q = vec![1i8; n_in];
    let (s, b) = ([1.0f32], [0.0f32]);
    let wide = Layer {
        in_dim: n_in,
        out_dim: 1,
        weights: Weights::I8 { q: &q, row_scale: &s },
        bias: &b,
        activation: Activation::Identity,
    };
    assert_eq!(
        Mlp::<'_, 1, 1024>::new(&[wide]).unwrap_err(),
        RuntimeError::TooWideForI8 { layer: 0, in_dim: 517, max: 516 }
    );
    let fits = Layer { in_dim: 516, weights: Weights::I8 { q: &q[..516], row_scale: &s }, ..wide };
    assert!(Mlp::<'_, 1, 1024>::new(&[fits]).is_ok());
}
