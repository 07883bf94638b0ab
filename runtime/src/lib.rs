//! `no_std`, allocation-free MLP runtime for vge policies.
//!
//! The runtime evaluates a multi-layer perceptron whose weights are *borrowed* slices
//! (`f32`, `f16` or `i8` with row scales, see [`Weights`]), so a policy can live in flash and
//! be evaluated without copying it into RAM. Capacity is chosen at compile time with const
//! generics:
//!
//! ```
//! use vge_runtime::{Activation, Layer, Mlp, Weights};
//!
//! // 2 -> 2 (ReLU) -> 1 (tanh)
//! let w0 = [1.0, 0.0, 0.0, -1.0];
//! let b0 = [0.0, 0.0];
//! let w1 = [1.0, 1.0];
//! let b1 = [0.0];
//! let layers = [
//!     Layer { in_dim: 2, out_dim: 2, weights: Weights::F32(&w0), bias: &b0, activation: Activation::Relu },
//!     Layer { in_dim: 2, out_dim: 1, weights: Weights::F32(&w1), bias: &b1, activation: Activation::Tanh },
//! ];
//! let mlp: Mlp<'_, 4, 8> = Mlp::new(&layers)?;
//! let mut action = [0.0f32; 1];
//! mlp.forward(&[0.5, -0.25], &mut action)?;
//! assert!((action[0] - 0.75f32.tanh()).abs() < 1e-6);
//! # Ok::<(), vge_runtime::RuntimeError>(())
//! ```
//!
//! No function in this crate panics on any input: every size coming from outside is checked
//! (with checked arithmetic) before it is used, and errors are reported as [`RuntimeError`].
#![no_std]
#![deny(clippy::indexing_slicing)]
#![cfg_attr(not(test), deny(clippy::panic, clippy::unwrap_used, clippy::expect_used, clippy::unreachable))]

#[cfg(feature = "std")]
mod aligned;
mod error;
pub mod format;
mod kernel;
mod layer;
mod mlp;
pub mod policy;
#[cfg(all(feature = "simd", target_arch = "x86_64"))]
mod simd;
#[cfg(all(feature = "simd", target_arch = "x86_64"))]
pub use simd::tolerance as simd_tolerance;
mod weights;

#[cfg(feature = "std")]
pub use aligned::AlignedBytes;
pub use error::{PolicyError, RuntimeError};
pub use kernel::float_kernel;
pub use layer::{Activation, Layer};
pub use mlp::{Mlp, PolicyMlp};
pub use policy::{HandPolicy, ObsLayout, ObsSlice, Policy, PolicyInfo, Provenance, storage_len};
pub use weights::{I8_MAX_IN_DIM, WeightType, Weights, f16_is_finite, f16_to_f32};
