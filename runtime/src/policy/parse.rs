//! The validating parse of every format version: one pass that checks every field and hands
//! each layer, parameters still in the file, to the caller.

use crate::format::{self, ACT_IDENTITY, ACT_RELU, ACT_TANH, Frame};
use crate::policy::fields::{F32s, Names, ObsLayout, Reader};
use crate::policy::task::{TaskInfo, task};
use crate::policy::{PolicyInfo, Provenance};
use crate::{Activation, PolicyError, RuntimeError, WeightType};

/// A layer's weight matrix, still in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawWeights<'a> {
    F32(F32s<'a>),
    /// binary16 little-endian, with the payload offset of the first byte.
    F16 {
        bytes: &'a [u8],
        offset: usize,
    },
    /// One byte per weight, and the `f32` row scales.
    I8 {
        q: &'a [u8],
        row_scale: F32s<'a>,
    },
}

/// One layer record, parameters still in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawLayer<'a> {
    pub in_dim: usize,
    pub out_dim: usize,
    pub activation: Activation,
    pub weights: RawWeights<'a>,
    pub bias: F32s<'a>,
}

/// The parameter arrays outside the layers, still in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Vectors<'a> {
    pub obs_mean: F32s<'a>,
    pub obs_std: F32s<'a>,
    pub action_scale: F32s<'a>,
    pub action_offset: F32s<'a>,
}

/// Parses and fully validates a policy file of any version (the CRC only when
/// `verify_crc`), handing each layer to `on_layer` in order.
pub(crate) fn parse<'a>(
    bytes: &'a [u8],
    verify_crc: bool,
    on_layer: impl FnMut(usize, RawLayer<'a>) -> Result<(), PolicyError>,
) -> Result<(PolicyInfo<'a>, Vectors<'a>), PolicyError> {
    let frame = format::check_frame_with(bytes, verify_crc)?;
    match frame.version {
        1 => parse_v1(frame, on_layer),
        // 2 or 3: `check_frame` refuses any other.
        _ => parse_v2(frame, on_layer),
    }
}

/// Fields 1-8, the same in every version.
struct Head<'a> {
    provenance: Provenance<'a>,
    control_hz: f32,
    obs_dim: usize,
    act_dim: usize,
    obs_layout: ObsLayout<'a>,
}

fn head<'a>(r: &mut Reader<'a>) -> Result<Head<'a>, PolicyError> {
    let provenance = Provenance {
        vge_version: r.take("vge_version")?,
        config_hash: r.take("config_hash")?,
        seed: r.take("seed")?,
        steps: r.take("steps")?,
    };
    let control_hz: f32 = r.take("control_hz")?;
    positive_scalar(control_hz, "control_hz")?;
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
    let obs_layout = ObsLayout { raw: r.payload.get(layout_start..r.pos).unwrap_or(&[]), count: n_slices };
    Ok(Head { provenance, control_hz, obs_dim, act_dim, obs_layout })
}

fn positive_scalar(v: f32, field: &'static str) -> Result<(), PolicyError> {
    if !v.is_finite() {
        return Err(PolicyError::NonFinite { field, index: 0 });
    }
    if v <= 0.0 {
        return Err(PolicyError::NotPositive { field, index: 0 });
    }
    Ok(())
}

fn obs_clip(r: &mut Reader<'_>) -> Result<Option<f32>, PolicyError> {
    let clip: Option<f32> = r.take("obs_clip")?;
    if let Some(c) = clip {
        positive_scalar(c, "obs_clip")?;
    }
    Ok(clip)
}

fn action_names<'a>(r: &mut Reader<'a>, act_dim: usize) -> Result<Names<'a>, PolicyError> {
    let n_names = r.len("action_names")?;
    if n_names != act_dim {
        return Err(PolicyError::Len { field: "action_names", expected: act_dim, got: n_names });
    }
    let start = r.pos;
    for index in 0..n_names {
        r.name("action_names", index)?;
    }
    Ok(Names { raw: r.payload.get(start..r.pos).unwrap_or(&[]), count: n_names })
}

fn check_obs_norm(mean: &F32s<'_>, std: &F32s<'_>, obs_dim: usize) -> Result<(), PolicyError> {
    mean.check_len("obs_mean", obs_dim)?;
    mean.check_finite("obs_mean")?;
    std.check_len("obs_std", obs_dim)?;
    std.check_positive("obs_std")
}

fn check_action_map(scale: &F32s<'_>, offset: &F32s<'_>, act_dim: usize) -> Result<(), PolicyError> {
    scale.check_len("action_scale", act_dim)?;
    scale.check_finite("action_scale")?;
    offset.check_len("action_offset", act_dim)?;
    offset.check_finite("action_offset")
}

fn activation_from_code(layer: usize, code: u8) -> Result<Activation, PolicyError> {
    match code {
        ACT_IDENTITY => Ok(Activation::Identity),
        ACT_RELU => Ok(Activation::Relu),
        ACT_TANH => Ok(Activation::Tanh),
        _ => Err(PolicyError::UnknownActivation { layer, code }),
    }
}

/// A layer's shape: non-zero, chained to the previous layer; returns its weight count.
fn check_shape(layer: usize, in_dim: usize, out_dim: usize, prev_out: usize) -> Result<usize, PolicyError> {
    if in_dim == 0 || out_dim == 0 {
        return Err(RuntimeError::ZeroDim { layer }.into());
    }
    if in_dim != prev_out {
        return Err(RuntimeError::DimMismatch { layer, expected_in: prev_out, got_in: in_dim }.into());
    }
    Ok(in_dim.checked_mul(out_dim).ok_or(RuntimeError::SizeOverflow { layer })?)
}

/// Lengths and finiteness of one layer's parameters.
fn check_params(layer: usize, raw: &RawLayer<'_>, n_w: usize) -> Result<(), PolicyError> {
    let n_weights = match raw.weights {
        RawWeights::F32(w) => w.len(),
        RawWeights::F16 { bytes, .. } => bytes.len() / 2,
        RawWeights::I8 { q, .. } => q.len(),
    };
    if n_weights != n_w {
        return Err(RuntimeError::WeightLen { layer, expected: n_w, got: n_weights }.into());
    }
    if raw.bias.len() != raw.out_dim {
        return Err(RuntimeError::BiasLen { layer, expected: raw.out_dim, got: raw.bias.len() }.into());
    }
    let bad_weight = match raw.weights {
        RawWeights::F32(w) => w.iter().position(|v| !v.is_finite()),
        RawWeights::F16 { bytes, .. } => {
            let (halves, _) = bytes.as_chunks::<2>();
            halves.iter().position(|h| !crate::f16_is_finite(u16::from_le_bytes(*h)))
        }
        RawWeights::I8 { row_scale, .. } => {
            if raw.in_dim > crate::I8_MAX_IN_DIM {
                let (in_dim, max) = (raw.in_dim, crate::I8_MAX_IN_DIM);
                return Err(RuntimeError::TooWideForI8 { layer, in_dim, max }.into());
            }
            if row_scale.len() != raw.out_dim {
                return Err(
                    RuntimeError::ScaleLen { layer, expected: raw.out_dim, got: row_scale.len() }.into()
                );
            }
            if let Some(index) = row_scale.iter().position(|s| !(s.is_finite() && s > 0.0)) {
                return Err(RuntimeError::BadScale { layer, index }.into());
            }
            None
        }
    };
    if let Some(index) = bad_weight {
        return Err(RuntimeError::NonFiniteWeight { layer, index }.into());
    }
    if let Some(index) = raw.bias.iter().position(|v| !v.is_finite()) {
        return Err(RuntimeError::NonFiniteBias { layer, index }.into());
    }
    Ok(())
}

/// Running totals over the layers, for [`PolicyInfo`].
struct Totals {
    prev_out: usize,
    max_width: usize,
    num_params: usize,
}

impl Totals {
    fn new(obs_dim: usize) -> Self {
        Self { prev_out: obs_dim, max_width: obs_dim, num_params: 0 }
    }

    fn add(&mut self, n_w: usize, out_dim: usize) {
        self.num_params = self.num_params.saturating_add(n_w).saturating_add(out_dim);
        self.max_width = self.max_width.max(out_dim);
        self.prev_out = out_dim;
    }
}

/// Version 1: every array a postcard `seq<f32>` in field order (docs/policy-format.md).
fn parse_v1<'a>(
    frame: Frame<'a>,
    mut on_layer: impl FnMut(usize, RawLayer<'a>) -> Result<(), PolicyError>,
) -> Result<(PolicyInfo<'a>, Vectors<'a>), PolicyError> {
    let mut r = Reader::new(frame.payload);
    let head = head(&mut r)?;
    let obs_mean = r.f32s("obs_mean")?;
    let obs_std = r.f32s("obs_std")?;
    check_obs_norm(&obs_mean, &obs_std, head.obs_dim)?;
    let obs_clip = obs_clip(&mut r)?;

    let num_layers = r.len("layers")?;
    if num_layers == 0 {
        return Err(PolicyError::Runtime(RuntimeError::NoLayers));
    }
    let mut totals = Totals::new(head.obs_dim);
    for layer in 0..num_layers {
        let in_dim = r.len("layer.in_dim")?;
        let out_dim = r.len("layer.out_dim")?;
        let activation = activation_from_code(layer, r.take("layer.activation")?)?;
        let weights = RawWeights::F32(r.f32s("layer.weights")?);
        let bias = r.f32s("layer.bias")?;
        let raw = RawLayer { in_dim, out_dim, activation, weights, bias };
        let n_w = check_shape(layer, in_dim, out_dim, totals.prev_out)?;
        check_params(layer, &raw, n_w)?;
        totals.add(n_w, out_dim);
        on_layer(layer, raw)?;
    }
    if totals.prev_out != head.act_dim {
        return Err(PolicyError::Len { field: "act_dim", expected: head.act_dim, got: totals.prev_out });
    }
    let action_names = action_names(&mut r, head.act_dim)?;
    let action_scale = r.f32s("action_scale")?;
    let action_offset = r.f32s("action_offset")?;
    check_action_map(&action_scale, &action_offset, head.act_dim)?;
    end_of_payload(&r)?;

    let storage_len = totals
        .num_params
        .saturating_add(head.obs_dim.saturating_mul(2))
        .saturating_add(head.act_dim.saturating_mul(2));
    let info =
        info(frame, head, obs_clip, action_names, None, num_layers, &totals, WeightType::F32, storage_len);
    Ok((info, Vectors { obs_mean, obs_std, action_scale, action_offset }))
}

/// Versions 2 and 3: a `u32` metadata length, the postcard metadata (no arrays; version 3
/// ends it with the optional task record), then every array at a 16-byte aligned file offset
/// in the layout the kernels read (docs/policy-format.md).
fn parse_v2<'a>(
    frame: Frame<'a>,
    mut on_layer: impl FnMut(usize, RawLayer<'a>) -> Result<(), PolicyError>,
) -> Result<(PolicyInfo<'a>, Vectors<'a>), PolicyError> {
    let mut r = Reader::new(frame.payload);
    let bad_meta_len = PolicyError::Malformed { field: "meta_len", offset: 0 };
    let meta_len = <[u8; 4]>::try_from(r.bytes(4, "meta_len")?).map_err(|_| bad_meta_len)?;
    let meta_end = usize::try_from(u32::from_le_bytes(meta_len))
        .ok()
        .and_then(|n| n.checked_add(4))
        .ok_or(bad_meta_len)?;

    // Metadata: everything but the arrays. Layer shapes are read twice: here to validate the
    // chain, then again beside their arrays.
    let head = head(&mut r)?;
    let obs_clip = obs_clip(&mut r)?;
    let code: u8 = r.take("weight_type")?;
    let weight_type = WeightType::from_code(code).ok_or(PolicyError::UnknownWeightType { code })?;
    let num_layers = r.len("layers")?;
    if num_layers == 0 {
        return Err(PolicyError::Runtime(RuntimeError::NoLayers));
    }
    let shapes = r.clone();
    for layer in 0..num_layers {
        layer_shape(&mut r, layer)?;
    }
    let action_names = action_names(&mut r, head.act_dim)?;
    let task = if frame.version >= 3 { task(&mut r)? } else { None };
    if r.pos != meta_end {
        return Err(bad_meta_len);
    }

    // Arrays.
    let obs_mean = r.f32_tensor(head.obs_dim, "obs_mean")?;
    let obs_std = r.f32_tensor(head.obs_dim, "obs_std")?;
    check_obs_norm(&obs_mean, &obs_std, head.obs_dim)?;
    let mut shapes = shapes;
    let mut totals = Totals::new(head.obs_dim);
    for layer in 0..num_layers {
        let (in_dim, out_dim, activation) = layer_shape(&mut shapes, layer)?;
        let n_w = check_shape(layer, in_dim, out_dim, totals.prev_out)?;
        let weights = match weight_type {
            WeightType::F32 => RawWeights::F32(r.f32_tensor(n_w, "layer.weights")?),
            WeightType::F16 => {
                let (bytes, offset) = r.tensor(n_w, 2, "layer.weights")?;
                RawWeights::F16 { bytes, offset }
            }
            WeightType::I8 => {
                let (q, _) = r.tensor(n_w, 1, "layer.weights")?;
                RawWeights::I8 { q, row_scale: r.f32_tensor(out_dim, "layer.row_scale")? }
            }
        };
        let bias = r.f32_tensor(out_dim, "layer.bias")?;
        let raw = RawLayer { in_dim, out_dim, activation, weights, bias };
        check_params(layer, &raw, n_w)?;
        totals.add(n_w, out_dim);
        on_layer(layer, raw)?;
    }
    if totals.prev_out != head.act_dim {
        return Err(PolicyError::Len { field: "act_dim", expected: head.act_dim, got: totals.prev_out });
    }
    let action_scale = r.f32_tensor(head.act_dim, "action_scale")?;
    let action_offset = r.f32_tensor(head.act_dim, "action_offset")?;
    check_action_map(&action_scale, &action_offset, head.act_dim)?;
    end_of_payload(&r)?;

    let info = info(frame, head, obs_clip, action_names, task, num_layers, &totals, weight_type, 0);
    Ok((info, Vectors { obs_mean, obs_std, action_scale, action_offset }))
}

fn layer_shape(r: &mut Reader<'_>, layer: usize) -> Result<(usize, usize, Activation), PolicyError> {
    let in_dim = r.len("layer.in_dim")?;
    let out_dim = r.len("layer.out_dim")?;
    let activation = activation_from_code(layer, r.take("layer.activation")?)?;
    Ok((in_dim, out_dim, activation))
}

fn end_of_payload(r: &Reader<'_>) -> Result<(), PolicyError> {
    let unused = r.payload.len().saturating_sub(r.pos);
    if unused != 0 {
        return Err(PolicyError::TrailingPayload { unused });
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn info<'a>(
    frame: Frame<'a>,
    head: Head<'a>,
    obs_clip: Option<f32>,
    action_names: Names<'a>,
    task: Option<TaskInfo<'a>>,
    num_layers: usize,
    totals: &Totals,
    weight_type: WeightType,
    storage_len: usize,
) -> PolicyInfo<'a> {
    PolicyInfo {
        format_version: frame.version,
        checksum: frame.checksum,
        provenance: head.provenance,
        control_hz: head.control_hz,
        obs_dim: head.obs_dim,
        act_dim: head.act_dim,
        obs_layout: head.obs_layout,
        obs_clip,
        action_names,
        task,
        num_layers,
        max_width: totals.max_width,
        num_params: totals.num_params,
        weight_type,
        storage_len,
    }
}
