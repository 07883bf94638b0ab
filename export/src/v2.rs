//! Version-2 and -3 policy files (docs/policy-format.md): a postcard metadata block (version 3
//! ends it with the optional task record), then every array at a 16-byte aligned file offset
//! in the layout `vge_runtime`'s kernels read in place, with the weights as `f32`, `f16` or
//! `i8`. Version 3 is written; both are read.

use serde::Serialize;
use vge_runtime::format::{self, TRAILER_LEN};
use vge_runtime::policy::{RawWeights, TENSOR_ALIGN};
use vge_runtime::{PolicyError, WeightType};

use crate::ExportError;
use crate::policy_file::{LayerRecord, ObsSlice, PolicyFile, PolicyTask, Provenance};
use crate::quantise;

/// The metadata block, field for field in file order.
#[derive(Serialize)]
struct Meta<'a> {
    provenance: &'a Provenance,
    control_hz: f32,
    obs_dim: u32,
    act_dim: u32,
    obs_layout: &'a [ObsSlice],
    obs_clip: Option<f32>,
    weight_type: u8,
    /// `(in_dim, out_dim, activation)` per layer.
    layers: Vec<(u32, u32, u8)>,
    action_names: &'a [String],
    task: Option<&'a PolicyTask>,
}

/// Appends zero bytes until the file offset is a multiple of [`TENSOR_ALIGN`], then `bytes`.
fn push_aligned(out: &mut Vec<u8>, bytes: impl IntoIterator<Item = u8>) {
    out.resize(out.len().next_multiple_of(TENSOR_ALIGN), 0);
    out.extend(bytes);
}

fn f32_bytes(values: &[f32]) -> impl Iterator<Item = u8> + '_ {
    values.iter().flat_map(|v| v.to_le_bytes())
}

/// Encodes `file` as version 3 with `weights`-typed matrices and checks that the `no_std`
/// runtime accepts the result.
pub fn encode(file: &PolicyFile, weights: WeightType) -> Result<Vec<u8>, ExportError> {
    let meta = Meta {
        provenance: &file.provenance,
        control_hz: file.control_hz,
        obs_dim: file.obs_dim,
        act_dim: file.act_dim,
        obs_layout: &file.obs_layout,
        obs_clip: file.obs_clip,
        weight_type: weights.code(),
        layers: file.layers.iter().map(|l| (l.in_dim, l.out_dim, l.activation)).collect(),
        action_names: &file.action_names,
        task: file.task.as_ref(),
    };
    let meta = postcard::to_allocvec(&meta).map_err(ExportError::Encode)?;
    let too_big = |n: usize| ExportError::InvalidSpec(format!("policy of {n} bytes exceeds 4 GiB"));
    let meta_len = u32::try_from(meta.len()).map_err(|_| too_big(meta.len()))?;

    // Header placeholder; the payload length is known at the end.
    let mut out = vec![0u8; format::HEADER_LEN];
    out.extend_from_slice(&meta_len.to_le_bytes());
    out.extend_from_slice(&meta);
    push_aligned(&mut out, f32_bytes(&file.obs_mean));
    push_aligned(&mut out, f32_bytes(&file.obs_std));
    for (i, layer) in file.layers.iter().enumerate() {
        match weights {
            WeightType::F32 => push_aligned(&mut out, f32_bytes(&layer.weights)),
            WeightType::F16 => {
                let halves = quantise::to_f16(&layer.weights, i)?;
                push_aligned(&mut out, halves.iter().flat_map(|h| h.to_le_bytes()));
            }
            WeightType::I8 => {
                let (q, scales) = quantise::to_i8(&layer.weights, layer.in_dim as usize);
                push_aligned(&mut out, q.iter().map(|v| v.to_le_bytes()[0]));
                push_aligned(&mut out, f32_bytes(&scales));
            }
        }
        push_aligned(&mut out, f32_bytes(&layer.bias));
    }
    push_aligned(&mut out, f32_bytes(&file.action_scale));
    push_aligned(&mut out, f32_bytes(&file.action_offset));

    let payload_len = out.len() - format::HEADER_LEN;
    let len = u32::try_from(payload_len).map_err(|_| too_big(payload_len))?;
    out[..format::HEADER_LEN].copy_from_slice(&format::header(format::FORMAT_VERSION, len));
    let crc = format::crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    debug_assert_eq!(out.len(), format::HEADER_LEN + payload_len + TRAILER_LEN);
    vge_runtime::policy::inspect(&out)?;
    Ok(out)
}

/// Decodes a version-2 or -3 file into the owned model (quantised weights as the `f32` values they
/// stand for) and its weight type. Checks every field; the CRC only when `verify_crc`.
pub fn decode(bytes: &[u8], verify_crc: bool) -> Result<(PolicyFile, WeightType), ExportError> {
    let mut layers = Vec::new();
    let (info, v) = vge_runtime::policy::decode(bytes, verify_crc, |_, raw| {
        let weights = match raw.weights {
            RawWeights::F32(w) => w.iter().collect(),
            RawWeights::F16 { bytes, .. } => {
                let (halves, _) = bytes.as_chunks::<2>();
                halves.iter().map(|h| vge_runtime::f16_to_f32(u16::from_le_bytes(*h))).collect()
            }
            RawWeights::I8 { q, row_scale } => {
                let q: Vec<i8> = q.iter().map(|b| i8::from_le_bytes([*b])).collect();
                quantise::from_i8(&q, &row_scale.iter().collect::<Vec<_>>(), raw.in_dim)
            }
        };
        layers.push(LayerRecord {
            in_dim: raw.in_dim as u32,
            out_dim: raw.out_dim as u32,
            activation: crate::policy_file::activation_code(raw.activation),
            weights,
            bias: raw.bias.iter().collect(),
        });
    })?;
    if info.format_version < 2 {
        let found = info.format_version;
        return Err(PolicyError::UnsupportedVersion { found, supported: format::FORMAT_VERSION }.into());
    }
    let file = PolicyFile {
        provenance: Provenance {
            vge_version: info.provenance.vge_version.to_owned(),
            config_hash: info.provenance.config_hash.to_owned(),
            seed: info.provenance.seed,
            steps: info.provenance.steps,
        },
        control_hz: info.control_hz,
        obs_dim: info.obs_dim as u32,
        act_dim: info.act_dim as u32,
        obs_layout: info
            .obs_layout
            .iter()
            .map(|s| ObsSlice::new(s.name, s.start as u32..s.end as u32))
            .collect(),
        obs_mean: v.obs_mean.iter().collect(),
        obs_std: v.obs_std.iter().collect(),
        obs_clip: info.obs_clip,
        layers,
        action_names: info.action_names.iter().map(str::to_owned).collect(),
        action_scale: v.action_scale.iter().collect(),
        action_offset: v.action_offset.iter().collect(),
        task: info.task.as_ref().map(PolicyTask::from_info),
    };
    Ok((file, info.weight_type))
}
