//! Policy files: zero-copy parsing and validation, and a [`Policy`] that evaluates
//! `obs -> normalise -> MLP -> scale -> action`.
//!
//! # Where the weights live
//!
//! **Version 2** stores every array at a 16-byte aligned file offset, in the layout the
//! kernels read (`f32`, `f16` or `i8` weights, see [`crate::WeightType`]). [`Policy::load`]
//! borrows them in place: with the file in flash (`include_bytes!` into a 16-byte aligned
//! static) a policy needs no RAM for its parameters. The file must sit at an address aligned
//! for its arrays (4 bytes for `f32`); a misaligned one is [`PolicyError::Misaligned`].
//!
//! **Version 1** (still read) puts each `f32` array right after postcard's varint length, at
//! an arbitrary offset, so its arrays cannot be viewed in place: `load` decodes every `f32`
//! once into a caller-given `&mut [f32]` (size it with [`PolicyInfo::storage_len`] or
//! [`storage_len`]; version 2 needs none, `storage_len` is 0).
//!
//! **Version 3** is version 2 with an optional task record at the end of its metadata (which
//! hand, observation set, object and orientation the policy was trained for, [`TaskInfo`]);
//! its arrays are read in place as version 2's.
//!
//! Names, provenance strings, layouts and the task record stay borrowed from the file bytes in
//! every version.

use heapless::Vec;

use crate::weights::Weights;
use crate::{Layer, Mlp, PolicyError, RuntimeError, WeightType};

mod fields;
mod parse;
mod task;

pub use fields::{F32s, Names, ObsLayout, ObsSlice, TENSOR_ALIGN};
use parse::parse;
pub use parse::{RawLayer, RawWeights, Vectors};
pub use task::{
    MAX_PROPRIO_HISTORY, MAX_TASK_NAME_LEN, TaskInfo, UNRECORDED_HAND, UNRECORDED_OBSERVATION_SET,
    check_task_name, is_observation_set,
};

/// Layers a [`HandPolicy`] holds at most (the trainer refuses configs beyond it).
pub const HAND_MAX_LAYERS: usize = 4;
/// Width of any layer of a [`HandPolicy`] at most.
pub const HAND_MAX_WIDTH: usize = 256;

/// A policy with capacity for the dexterous-hand actors: up to 4 layers of width up to 256.
/// `vge-bridge` and the firmware load hand policies as this type.
pub type HandPolicy<'a> = Policy<'a, HAND_MAX_LAYERS, HAND_MAX_WIDTH>;

/// `f32`s needed by [`Policy::load`] for a version-1 file of a network `dims[0] -> dims[1] -> ... -> dims[n]`
/// (weights, biases, observation mean and std, action scale and offset). Saturates on
/// overflow. Usable in const context to size a static buffer:
/// `static mut BUF: [f32; storage_len(&[65, 256, 256, 15])]`.
pub const fn storage_len(dims: &[usize]) -> usize {
    let (Some((&obs, _)), Some((&act, _))) = (dims.split_first(), dims.split_last()) else {
        return 0;
    };
    let mut total = 0usize;
    let mut rest = dims;
    while let [n_in, n_out, ..] = rest {
        total = total.saturating_add(n_in.saturating_mul(*n_out)).saturating_add(*n_out);
        rest = match rest.split_first() {
            Some((_, r)) => r,
            None => break,
        };
    }
    total.saturating_add(obs.saturating_mul(2)).saturating_add(act.saturating_mul(2))
}

/// Bytes a policy file may hold besides its parameter arrays: its names, provenance strings
/// and task record, and the header, trailer, varints and padding around its fields. Generous (the
/// hand's names take well under 1 KiB); it bounds [`max_file_len`].
pub const MAX_TEXT_LEN: usize = 1 << 20;

/// The longest policy file a `Policy<MAX_LAYERS, MAX_WIDTH>` can load: every layer
/// `max_width` square with its bias (and `i8` row scales), the observation and action vectors
/// `max_width` long, all as `f32` (the widest weight type) at [`TENSOR_ALIGN`] padding, plus
/// [`MAX_TEXT_LEN`]. File readers compare a file's length with it before reading it, so that
/// a huge file (a 2 GB sparse file, say) is refused without reading or allocating it.
/// Saturates on overflow.
pub const fn max_file_len(max_layers: usize, max_width: usize) -> usize {
    let per_layer = max_width.saturating_mul(max_width).saturating_add(max_width.saturating_mul(2));
    let floats = max_layers.saturating_mul(per_layer).saturating_add(max_width.saturating_mul(4));
    let arrays = max_layers.saturating_mul(3).saturating_add(4);
    floats.saturating_mul(4).saturating_add(arrays.saturating_mul(TENSOR_ALIGN)).saturating_add(MAX_TEXT_LEN)
}

/// [`max_file_len`] of a [`HandPolicy`] (about 2 MiB).
pub const HAND_MAX_FILE_LEN: usize = max_file_len(HAND_MAX_LAYERS, HAND_MAX_WIDTH);

/// Who made the policy, from what.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Provenance<'a> {
    /// `vge` version that trained and exported it.
    pub vge_version: &'a str,
    /// Hash of the training configuration (free-form text, typically hex).
    pub config_hash: &'a str,
    /// Training seed.
    pub seed: u64,
    /// Environment steps trained.
    pub steps: u64,
}

/// Everything about a policy file except its parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolicyInfo<'a> {
    pub format_version: u16,
    /// The file's CRC-32 (verified).
    pub checksum: u32,
    pub provenance: Provenance<'a>,
    /// Control rate the policy was trained at.
    pub control_hz: f32,
    pub obs_dim: usize,
    pub act_dim: usize,
    pub obs_layout: ObsLayout<'a>,
    /// Observations are clamped to `[-clip, clip]` after normalisation, when set.
    pub obs_clip: Option<f32>,
    pub action_names: Names<'a>,
    /// Which hand and observation set the policy was trained for: the task record of a
    /// version-3 file. `None` for versions 1 and 2 and for a version-3 file without one (a
    /// generic MLP): such a policy is for [`UNRECORDED_HAND`] with [`UNRECORDED_OBSERVATION_SET`].
    pub task: Option<TaskInfo<'a>>,
    /// Number of layers.
    pub num_layers: usize,
    /// Widest layer input or output (the `MAX_WIDTH` a [`Policy`] needs).
    pub max_width: usize,
    /// Weights and biases of all layers.
    pub num_params: usize,
    /// How the weight matrices are stored (`F32` in version 1).
    pub weight_type: WeightType,
    /// `f32`s of storage [`Policy::load`] needs: 0 for versions 2 and 3, whose arrays are
    /// borrowed in place.
    pub storage_len: usize,
}

/// Validates a whole policy file (framing, checksum, every field) without copying anything,
/// and returns its description; `info.storage_len` sizes the storage for [`Policy::load`].
pub fn inspect(bytes: &[u8]) -> Result<PolicyInfo<'_>, PolicyError> {
    parse(bytes, true, |_, _| Ok(())).map(|(info, _)| info)
}

/// An `f32` array of the file as the network reads it: borrowed in place (versions 2 and 3,
/// the versions with aligned arrays, whose files have `storage_len` 0) or decoded
/// into the next `storage` (version 1, whose arrays follow a varint at any offset).
fn place<'a>(
    values: F32s<'a>,
    storage: &mut &'a mut [f32],
    field: &'static str,
) -> Result<&'a [f32], PolicyError> {
    if values.is_in_place() { values.borrow(field) } else { values.copy_into(storage) }
}

/// Validates a policy file (its CRC only when `verify_crc`, so that a tool can still show a
/// damaged file) and calls `f` on each layer record; returns the description and the arrays
/// outside the layers, all still in the file.
pub fn decode<'a>(
    bytes: &'a [u8],
    verify_crc: bool,
    mut f: impl FnMut(usize, RawLayer<'a>),
) -> Result<(PolicyInfo<'a>, Vectors<'a>), PolicyError> {
    parse(bytes, verify_crc, |i, l| {
        f(i, l);
        Ok(())
    })
}

/// A loaded policy: `action = offset + scale * mlp(clip((obs - mean) / std))`.
#[derive(Debug, Clone)]
pub struct Policy<'a, const MAX_LAYERS: usize, const MAX_WIDTH: usize> {
    info: PolicyInfo<'a>,
    mlp: Mlp<'a, MAX_LAYERS, MAX_WIDTH>,
    obs_mean: &'a [f32],
    obs_std: &'a [f32],
    action_scale: &'a [f32],
    action_offset: &'a [f32],
}

impl<'a, const MAX_LAYERS: usize, const MAX_WIDTH: usize> Policy<'a, MAX_LAYERS, MAX_WIDTH> {
    /// Validates `bytes` (magic, version, length, CRC-32, every field, finite parameters,
    /// dimensions against `MAX_LAYERS` / `MAX_WIDTH`). A version-2 or -3 file's arrays are then
    /// borrowed in place (alignment checked; `storage` is not used and may be empty); a
    /// version-1 file's are decoded into the front of `storage`, which must hold at least
    /// [`PolicyInfo::storage_len`] `f32`. Names, provenance and the task record stay borrowed
    /// from `bytes`.
    pub fn load(bytes: &'a [u8], storage: &'a mut [f32]) -> Result<Self, PolicyError> {
        let got = storage.len();
        let mut rest: &'a mut [f32] = storage;
        let mut layers: Vec<Layer<'a>, MAX_LAYERS> = Vec::new();
        // One pass: validate and copy. When the storage or the layer capacity runs out
        // midway, a validate-only pass finds the totals for the error.
        let totals = |e: PolicyError| match (e, inspect(bytes)) {
            (PolicyError::StorageTooSmall { .. }, Ok(info)) => {
                PolicyError::StorageTooSmall { needed: info.storage_len, got }
            }
            (PolicyError::Runtime(RuntimeError::TooManyLayers { .. }), Ok(info)) => {
                RuntimeError::TooManyLayers { count: info.num_layers, max: MAX_LAYERS }.into()
            }
            (_, Err(e)) => e,
            (e, Ok(_)) => e,
        };
        let parsed = parse(bytes, true, |i, raw| {
            let weights = match raw.weights {
                RawWeights::F32(w) => Weights::F32(place(w, &mut rest, "layer.weights")?),
                RawWeights::F16 { bytes, offset } => {
                    Weights::F16(fields::borrow_in_place(bytes, offset, "layer.weights")?)
                }
                RawWeights::I8 { q, row_scale } => Weights::I8 {
                    q: bytemuck::cast_slice(q),
                    row_scale: place(row_scale, &mut rest, "layer.row_scale")?,
                },
            };
            let bias = place(raw.bias, &mut rest, "layer.bias")?;
            let layer =
                Layer { in_dim: raw.in_dim, out_dim: raw.out_dim, weights, bias, activation: raw.activation };
            layers.push(layer).map_err(|_| {
                RuntimeError::TooManyLayers { count: i.saturating_add(1), max: MAX_LAYERS }.into()
            })
        });
        let (info, v) = parsed.map_err(totals)?;
        let mut vectors = || -> Result<_, PolicyError> {
            Ok((
                place(v.obs_mean, &mut rest, "obs_mean")?,
                place(v.obs_std, &mut rest, "obs_std")?,
                place(v.action_scale, &mut rest, "action_scale")?,
                place(v.action_offset, &mut rest, "action_offset")?,
            ))
        };
        let (obs_mean, obs_std, action_scale, action_offset) = vectors().map_err(totals)?;
        let mlp = Mlp::new(&layers)?;
        Ok(Self { info, mlp, obs_mean, obs_std, action_scale, action_offset })
    }

    /// Metadata: dimensions, layouts, provenance, control rate, checksum.
    pub fn info(&self) -> &PolicyInfo<'a> {
        &self.info
    }

    /// The network (without normalisation and action scaling).
    pub fn mlp(&self) -> &Mlp<'a, MAX_LAYERS, MAX_WIDTH> {
        &self.mlp
    }

    pub fn obs_dim(&self) -> usize {
        self.info.obs_dim
    }

    pub fn act_dim(&self) -> usize {
        self.info.act_dim
    }

    /// Computes the action for `obs`: normalise (and clip), run the MLP, scale and offset.
    ///
    /// Errors, leaving `action` untouched, if a slice has the wrong length, if `obs` holds a
    /// NaN or infinity ([`RuntimeError::NonFiniteObs`]), or if the action is not finite.
    /// Never allocates or panics.
    pub fn forward(&self, obs: &[f32], action: &mut [f32]) -> Result<(), PolicyError> {
        let (n_obs, n_act) = (self.info.obs_dim, self.info.act_dim);
        if obs.len() != n_obs {
            return Err(RuntimeError::ObsLen { expected: n_obs, got: obs.len() }.into());
        }
        if action.len() != n_act {
            return Err(RuntimeError::ActionLen { expected: n_act, got: action.len() }.into());
        }
        if let Some(index) = obs.iter().position(|x| !x.is_finite()) {
            return Err(RuntimeError::NonFiniteObs { index }.into());
        }
        let cap = |dim| RuntimeError::WidthExceedsCapacity { layer: 0, dim, max: MAX_WIDTH };
        let mut x_buf = [0.0f32; MAX_WIDTH];
        let x = x_buf.get_mut(..n_obs).ok_or(cap(n_obs))?;
        for (((xi, o), m), s) in x.iter_mut().zip(obs).zip(self.obs_mean).zip(self.obs_std) {
            *xi = (o - m) / s;
        }
        if let Some(c) = self.info.obs_clip {
            for xi in x.iter_mut() {
                *xi = xi.max(-c).min(c);
            }
        }
        let mut y_buf = [0.0f32; MAX_WIDTH];
        let y = y_buf.get_mut(..n_act).ok_or(cap(n_act))?;
        self.mlp.forward(x, y)?;
        for ((yi, s), o) in y.iter_mut().zip(self.action_scale).zip(self.action_offset) {
            *yi = o + s * *yi;
        }
        if let Some(index) = y.iter().position(|v| !v.is_finite()) {
            return Err(RuntimeError::NonFiniteAction { index }.into());
        }
        for (a, v) in action.iter_mut().zip(y.iter()) {
            *a = *v;
        }
        Ok(())
    }
}
