//! Policy files: zero-copy parsing and validation, and a [`Policy`] that evaluates
//! `obs -> normalise -> MLP -> scale -> action`.
//!
//! # Why weights are copied into caller storage
//!
//! In the file every `f32` is four little-endian bytes at whatever offset postcard's varint
//! length prefixes put it, so a weight array is in general not 4-byte aligned. Viewing it as
//! `&[f32]` would need `unsafe` (or an alignment-dependent cast crate) and would still fail
//! on misaligned files; decoding on the fly inside the matrix-vector product would need a
//! second kernel beside [`Mlp`]'s. So [`Policy::load`] decodes every `f32` exactly once into
//! a caller-given `&mut [f32]` (size it with [`PolicyInfo::storage_len`] or
//! [`storage_len`]) and the network then borrows that storage. Everything else (names,
//! provenance strings, layouts) stays borrowed from the file bytes, which may live in flash.

use heapless::Vec;
use serde::Deserialize;

use crate::format::{self, ACT_IDENTITY, ACT_RELU, ACT_TANH, Frame};
use crate::{Activation, Layer, Mlp, PolicyError, RuntimeError};

/// Layers a [`HandPolicy`] holds at most (the trainer refuses configs beyond it).
pub const HAND_MAX_LAYERS: usize = 4;
/// Width of any layer of a [`HandPolicy`] at most.
pub const HAND_MAX_WIDTH: usize = 256;

/// A policy with capacity for the dexterous-hand actors: up to 4 layers of width up to 256.
/// `vge-bridge` and the firmware load hand policies as this type.
pub type HandPolicy<'a> = Policy<'a, HAND_MAX_LAYERS, HAND_MAX_WIDTH>;

/// `f32`s needed by [`Policy::load`] for a network `dims[0] -> dims[1] -> ... -> dims[n]`
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

/// A borrowed array of little-endian `f32` (four bytes each) inside the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct F32s<'a> {
    bytes: &'a [u8],
}

impl<'a> F32s<'a> {
    /// Number of values.
    pub fn len(&self) -> usize {
        self.bytes.len() / 4
    }

    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Decodes the values in order.
    pub fn iter(&self) -> impl Iterator<Item = f32> + 'a {
        self.bytes.chunks_exact(4).map(|c| {
            let mut b = [0u8; 4];
            b.copy_from_slice(c);
            f32::from_le_bytes(b)
        })
    }

    fn check_finite(&self, field: &'static str) -> Result<(), PolicyError> {
        match self.iter().position(|v| !v.is_finite()) {
            Some(index) => Err(PolicyError::NonFinite { field, index }),
            None => Ok(()),
        }
    }

    fn check_positive(&self, field: &'static str) -> Result<(), PolicyError> {
        self.check_finite(field)?;
        match self.iter().position(|v| v <= 0.0) {
            Some(index) => Err(PolicyError::NotPositive { field, index }),
            None => Ok(()),
        }
    }

    fn check_len(&self, field: &'static str, expected: usize) -> Result<(), PolicyError> {
        if self.len() != expected {
            return Err(PolicyError::Len { field, expected, got: self.len() });
        }
        Ok(())
    }

    /// Decodes into the front of `*storage` and advances it past the copied values.
    fn copy_into(&self, storage: &mut &'a mut [f32]) -> Result<&'a [f32], PolicyError> {
        let n = self.len();
        let got = storage.len();
        let (head, tail) = core::mem::take(storage)
            .split_at_mut_checked(n)
            .ok_or(PolicyError::StorageTooSmall { needed: n, got })?;
        *storage = tail;
        for (dst, v) in head.iter_mut().zip(self.iter()) {
            *dst = v;
        }
        Ok(head)
    }
}

/// Sequential reader over the postcard payload.
struct Reader<'a> {
    payload: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn rest(&self) -> &'a [u8] {
        self.payload.get(self.pos..).unwrap_or(&[])
    }

    fn take<T: Deserialize<'a>>(&mut self, field: &'static str) -> Result<T, PolicyError> {
        let rest = self.rest();
        let (v, after) = postcard::take_from_bytes::<T>(rest)
            .map_err(|_| PolicyError::Malformed { field, offset: self.pos })?;
        self.pos = self.pos.saturating_add(rest.len().saturating_sub(after.len()));
        Ok(v)
    }

    /// A length or dimension: postcard varint (unsigned LEB128) of at most 32 bits.
    fn len(&mut self, field: &'static str) -> Result<usize, PolicyError> {
        let v: u32 = self.take(field)?;
        usize::try_from(v).map_err(|_| PolicyError::Malformed { field, offset: self.pos })
    }

    fn f32s(&mut self, field: &'static str) -> Result<F32s<'a>, PolicyError> {
        let start = self.pos;
        let n = self.len(field)?;
        let n_bytes = n.checked_mul(4).ok_or(PolicyError::Malformed { field, offset: start })?;
        let bytes = self.rest().get(..n_bytes).ok_or(PolicyError::Malformed { field, offset: start })?;
        self.pos = self.pos.saturating_add(n_bytes);
        Ok(F32s { bytes })
    }

    fn name(&mut self, field: &'static str, index: usize) -> Result<&'a str, PolicyError> {
        let s: &'a str = self.take(field)?;
        if s.is_empty() {
            return Err(PolicyError::EmptyName { field, index });
        }
        Ok(s)
    }
}

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

/// A named slice `start..end` of the observation vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObsSlice<'a> {
    pub name: &'a str,
    pub start: usize,
    pub end: usize,
}

/// The observation layout, decoded lazily from the (already validated) file bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObsLayout<'a> {
    raw: &'a [u8],
    count: usize,
}

impl<'a> ObsLayout<'a> {
    /// Number of named slices.
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The slices in order (they are contiguous and cover `0..obs_dim`).
    pub fn iter(&self) -> impl Iterator<Item = ObsSlice<'a>> + 'a {
        let mut r = Reader { payload: self.raw, pos: 0 };
        (0..self.count).map_while(move |_| {
            let name: &'a str = r.take("obs_layout").ok()?;
            let start = r.len("obs_layout").ok()?;
            let end = r.len("obs_layout").ok()?;
            Some(ObsSlice { name, start, end })
        })
    }

    /// The first slice called `name`.
    pub fn get(&self, name: &str) -> Option<ObsSlice<'a>> {
        self.iter().find(|s| s.name == name)
    }
}

/// A list of names (the action names), decoded lazily from the file bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Names<'a> {
    raw: &'a [u8],
    count: usize,
}

impl<'a> Names<'a> {
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    pub fn iter(&self) -> impl Iterator<Item = &'a str> + 'a {
        let mut r = Reader { payload: self.raw, pos: 0 };
        (0..self.count).map_while(move |_| r.take::<&'a str>("action_names").ok())
    }

    /// Index of the first entry equal to `name`.
    pub fn position(&self, name: &str) -> Option<usize> {
        self.iter().position(|n| n == name)
    }
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
    /// Number of layers.
    pub num_layers: usize,
    /// Widest layer input or output (the `MAX_WIDTH` a [`Policy`] needs).
    pub max_width: usize,
    /// Weights and biases of all layers.
    pub num_params: usize,
    /// `f32`s of storage [`Policy::load`] needs.
    pub storage_len: usize,
}

/// One layer record, parameters still in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawLayer<'a> {
    pub in_dim: usize,
    pub out_dim: usize,
    pub activation: Activation,
    pub weights: F32s<'a>,
    pub bias: F32s<'a>,
}

/// The parameter arrays outside the layers.
#[derive(Debug, Clone, Copy)]
struct Vectors<'a> {
    obs_mean: F32s<'a>,
    obs_std: F32s<'a>,
    action_scale: F32s<'a>,
    action_offset: F32s<'a>,
}

fn activation_from_code(layer: usize, code: u8) -> Result<Activation, PolicyError> {
    match code {
        ACT_IDENTITY => Ok(Activation::Identity),
        ACT_RELU => Ok(Activation::Relu),
        ACT_TANH => Ok(Activation::Tanh),
        _ => Err(PolicyError::UnknownActivation { layer, code }),
    }
}

/// Parses and fully validates a policy file, handing each layer to `on_layer` in order.
fn parse<'a>(
    bytes: &'a [u8],
    mut on_layer: impl FnMut(usize, RawLayer<'a>) -> Result<(), PolicyError>,
) -> Result<(PolicyInfo<'a>, Vectors<'a>), PolicyError> {
    let Frame { version, payload, checksum } = format::check_frame(bytes)?;
    let mut r = Reader { payload, pos: 0 };

    let provenance = Provenance {
        vge_version: r.take("vge_version")?,
        config_hash: r.take("config_hash")?,
        seed: r.take("seed")?,
        steps: r.take("steps")?,
    };
    let control_hz: f32 = r.take("control_hz")?;
    if !control_hz.is_finite() {
        return Err(PolicyError::NonFinite { field: "control_hz", index: 0 });
    }
    if control_hz <= 0.0 {
        return Err(PolicyError::NotPositive { field: "control_hz", index: 0 });
    }
    let obs_dim = r.len("obs_dim")?;
    let act_dim = r.len("act_dim")?;
    if obs_dim == 0 {
        return Err(PolicyError::Runtime(RuntimeError::ZeroDim { layer: 0 }));
    }
    if act_dim == 0 {
        return Err(PolicyError::Len { field: "act_dim", expected: 1, got: 0 });
    }

    // Observation layout: non-empty names, slices contiguous from 0 to obs_dim.
    let n_slices = r.len("obs_layout")?;
    let layout_start = r.pos;
    let mut covered = 0usize;
    for index in 0..n_slices {
        r.name("obs_layout", index)?;
        let start = r.len("obs_layout")?;
        let end = r.len("obs_layout")?;
        if start != covered || end <= start || end > obs_dim {
            return Err(PolicyError::BadLayout { index });
        }
        covered = end;
    }
    if covered != obs_dim {
        return Err(PolicyError::BadLayout { index: n_slices });
    }
    let layout_raw = payload.get(layout_start..r.pos).unwrap_or(&[]);
    let obs_layout = ObsLayout { raw: layout_raw, count: n_slices };

    let obs_mean = r.f32s("obs_mean")?;
    obs_mean.check_len("obs_mean", obs_dim)?;
    obs_mean.check_finite("obs_mean")?;
    let obs_std = r.f32s("obs_std")?;
    obs_std.check_len("obs_std", obs_dim)?;
    obs_std.check_positive("obs_std")?;
    let obs_clip: Option<f32> = r.take("obs_clip")?;
    if let Some(c) = obs_clip {
        if !c.is_finite() {
            return Err(PolicyError::NonFinite { field: "obs_clip", index: 0 });
        }
        if c <= 0.0 {
            return Err(PolicyError::NotPositive { field: "obs_clip", index: 0 });
        }
    }

    // Layers: dimension chain obs_dim -> ... -> act_dim, finite parameters.
    let num_layers = r.len("layers")?;
    if num_layers == 0 {
        return Err(PolicyError::Runtime(RuntimeError::NoLayers));
    }
    let mut prev_out = obs_dim;
    let mut max_width = obs_dim;
    let mut num_params = 0usize;
    for layer in 0..num_layers {
        let in_dim = r.len("layer.in_dim")?;
        let out_dim = r.len("layer.out_dim")?;
        let code: u8 = r.take("layer.activation")?;
        let activation = activation_from_code(layer, code)?;
        let weights = r.f32s("layer.weights")?;
        let bias = r.f32s("layer.bias")?;
        let raw = RawLayer { in_dim, out_dim, activation, weights, bias };
        if in_dim == 0 || out_dim == 0 {
            return Err(RuntimeError::ZeroDim { layer }.into());
        }
        if in_dim != prev_out {
            return Err(RuntimeError::DimMismatch { layer, expected_in: prev_out, got_in: in_dim }.into());
        }
        let n_w = in_dim.checked_mul(out_dim).ok_or(RuntimeError::SizeOverflow { layer })?;
        if weights.len() != n_w {
            return Err(RuntimeError::WeightLen { layer, expected: n_w, got: weights.len() }.into());
        }
        if bias.len() != out_dim {
            return Err(RuntimeError::BiasLen { layer, expected: out_dim, got: bias.len() }.into());
        }
        if let Some(index) = weights.iter().position(|v| !v.is_finite()) {
            return Err(RuntimeError::NonFiniteWeight { layer, index }.into());
        }
        if let Some(index) = bias.iter().position(|v| !v.is_finite()) {
            return Err(RuntimeError::NonFiniteBias { layer, index }.into());
        }
        num_params = num_params.saturating_add(n_w).saturating_add(out_dim);
        max_width = max_width.max(out_dim);
        prev_out = out_dim;
        on_layer(layer, raw)?;
    }
    if prev_out != act_dim {
        return Err(PolicyError::Len { field: "act_dim", expected: act_dim, got: prev_out });
    }

    let n_names = r.len("action_names")?;
    if n_names != act_dim {
        return Err(PolicyError::Len { field: "action_names", expected: act_dim, got: n_names });
    }
    let names_start = r.pos;
    for index in 0..n_names {
        r.name("action_names", index)?;
    }
    let action_names = Names { raw: payload.get(names_start..r.pos).unwrap_or(&[]), count: n_names };

    let action_scale = r.f32s("action_scale")?;
    action_scale.check_len("action_scale", act_dim)?;
    action_scale.check_finite("action_scale")?;
    let action_offset = r.f32s("action_offset")?;
    action_offset.check_len("action_offset", act_dim)?;
    action_offset.check_finite("action_offset")?;

    let unused = payload.len().saturating_sub(r.pos);
    if unused != 0 {
        return Err(PolicyError::TrailingPayload { unused });
    }

    let storage_len =
        num_params.saturating_add(obs_dim.saturating_mul(2)).saturating_add(act_dim.saturating_mul(2));
    let info = PolicyInfo {
        format_version: version,
        checksum,
        provenance,
        control_hz,
        obs_dim,
        act_dim,
        obs_layout,
        obs_clip,
        action_names,
        num_layers,
        max_width,
        num_params,
        storage_len,
    };
    Ok((info, Vectors { obs_mean, obs_std, action_scale, action_offset }))
}

/// Validates a whole policy file (framing, checksum, every field) without copying anything,
/// and returns its description; `info.storage_len` sizes the storage for [`Policy::load`].
pub fn inspect(bytes: &[u8]) -> Result<PolicyInfo<'_>, PolicyError> {
    parse(bytes, |_, _| Ok(())).map(|(info, _)| info)
}

/// Validates a policy file and calls `f` on each layer record (parameters still in the file).
pub fn for_each_layer<'a>(
    bytes: &'a [u8],
    mut f: impl FnMut(usize, RawLayer<'a>),
) -> Result<PolicyInfo<'a>, PolicyError> {
    parse(bytes, |i, l| {
        f(i, l);
        Ok(())
    })
    .map(|(info, _)| info)
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
    /// dimensions against `MAX_LAYERS` / `MAX_WIDTH`) and decodes the parameters into the
    /// front of `storage`, which must hold at least [`PolicyInfo::storage_len`] `f32`.
    /// Names and provenance stay borrowed from `bytes`.
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
        let parsed = parse(bytes, |i, raw| {
            let weights = raw.weights.copy_into(&mut rest)?;
            let bias = raw.bias.copy_into(&mut rest)?;
            let layer =
                Layer { in_dim: raw.in_dim, out_dim: raw.out_dim, weights, bias, activation: raw.activation };
            layers.push(layer).map_err(|_| {
                RuntimeError::TooManyLayers { count: i.saturating_add(1), max: MAX_LAYERS }.into()
            })
        });
        let (info, v) = parsed.map_err(totals)?;
        let mut vectors = || -> Result<_, PolicyError> {
            Ok((
                v.obs_mean.copy_into(&mut rest)?,
                v.obs_std.copy_into(&mut rest)?,
                v.action_scale.copy_into(&mut rest)?,
                v.action_offset.copy_into(&mut rest)?,
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
