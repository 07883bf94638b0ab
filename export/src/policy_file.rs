//! Policy files (`docs/policy-format.md`): the owned, serde-encoded model written by the
//! trainer and read back on the host. The `no_std` reader is `vge_runtime::policy`.

use std::ops::Range;
use std::path::Path;

use serde::{Deserialize, Serialize};
use vge_runtime::format::{self, ACT_IDENTITY, ACT_RELU, ACT_TANH};
use vge_runtime::{Activation, PolicyError, WeightType};

use crate::{ExportError, ExportedActor, ExportedLayer};

/// Who made the policy, from what.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Provenance {
    pub vge_version: String,
    /// Hash of the training configuration (free-form text, typically hex).
    pub config_hash: String,
    pub seed: u64,
    /// Environment steps trained.
    pub steps: u64,
}

/// A named slice `start..end` of the observation vector.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ObsSlice {
    pub name: String,
    pub start: u32,
    pub end: u32,
}

impl ObsSlice {
    /// `ObsSlice::new("q", 0..15)`.
    pub fn new(name: impl Into<String>, range: Range<u32>) -> Self {
        Self { name: name.into(), start: range.start, end: range.end }
    }
}

/// Which hand, observation set and task a policy was trained for: the task record of a
/// version-3 file (`vge_runtime::policy::TaskInfo` is the borrowed view), so that a policy is
/// refused on a hand it was not trained on. A file without one is for vge's own hand `vge15`
/// with the `full` observation set (`vge_runtime::policy::UNRECORDED_HAND`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PolicyTask {
    /// The hand's name (`"vge15"`, `"allegro"`): 1 to 64 bytes.
    pub hand: String,
    /// SHA-256 of the hand's MJCF description (`vge_hand::Hand::description_sha256`).
    pub hand_sha256: [u8; 32],
    /// `"full"`, `"proprio"` or `"proprio:K"` (K 1 to 64).
    pub observation_set: String,
    /// The object manipulated (`"cube"`); empty when unspecified. At most 64 bytes.
    pub object: String,
    /// The hand's orientation (`"palm_down"`); empty when unspecified. At most 64 bytes.
    pub orientation: String,
}

impl PolicyTask {
    /// The borrowed view the runtime reads.
    pub fn info(&self) -> vge_runtime::policy::TaskInfo<'_> {
        vge_runtime::policy::TaskInfo {
            hand: &self.hand,
            hand_sha256: &self.hand_sha256,
            observation_set: &self.observation_set,
            object: &self.object,
            orientation: &self.orientation,
        }
    }

    /// The owned copy of a record read from a file.
    pub fn from_info(t: &vge_runtime::policy::TaskInfo<'_>) -> Self {
        Self {
            hand: t.hand.to_owned(),
            hand_sha256: *t.hand_sha256,
            observation_set: t.observation_set.to_owned(),
            object: t.object.to_owned(),
            orientation: t.orientation.to_owned(),
        }
    }

    /// `hand_sha256` as 64 lowercase hex digits.
    pub fn hand_sha256_hex(&self) -> String {
        self.hand_sha256.iter().map(|b| format!("{b:02x}")).collect()
    }
}

/// One dense layer as stored: `y = act(W x + b)`, `W` row-major `out_dim × in_dim`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayerRecord {
    pub in_dim: u32,
    pub out_dim: u32,
    /// 0 identity, 1 ReLU, 2 tanh (`vge_runtime::format::ACT_*`).
    pub activation: u8,
    pub weights: Vec<f32>,
    pub bias: Vec<f32>,
}

/// The payload of a policy file, field for field in file order (`task`, version 3's, last).
///
/// `action = action_offset + action_scale * mlp(clip((obs - obs_mean) / obs_std))`, where
/// `clip` clamps to `[-obs_clip, obs_clip]` when `obs_clip` is set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolicyFile {
    pub provenance: Provenance,
    /// Control rate the policy was trained at.
    pub control_hz: f32,
    pub obs_dim: u32,
    pub act_dim: u32,
    pub obs_layout: Vec<ObsSlice>,
    pub obs_mean: Vec<f32>,
    pub obs_std: Vec<f32>,
    pub obs_clip: Option<f32>,
    pub layers: Vec<LayerRecord>,
    pub action_names: Vec<String>,
    pub action_scale: Vec<f32>,
    pub action_offset: Vec<f32>,
    /// Which hand and task the policy is for (version 3's task record); `None` for a generic
    /// MLP and for files older than version 3. Not in version 1's payload, whose serde
    /// encoding this struct's is.
    #[serde(skip)]
    pub task: Option<PolicyTask>,
}

/// Observation normalisation `(obs - mean) / std`, then optionally clamp to `[-clip, clip]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ObsNorm {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
    pub clip: Option<f32>,
}

impl ObsNorm {
    /// No normalisation: mean 0, std 1, no clip.
    pub fn identity(obs_dim: usize) -> Self {
        Self { mean: vec![0.0; obs_dim], std: vec![1.0; obs_dim], clip: None }
    }
}

/// Everything in a policy file besides the network.
#[derive(Debug, Clone, PartialEq)]
pub struct PolicyMeta {
    /// Named, contiguous slices covering `0..obs_dim`.
    pub obs_layout: Vec<ObsSlice>,
    /// One name per action dimension (e.g. `"index.flex1"`).
    pub action_names: Vec<String>,
    pub obs_norm: ObsNorm,
    /// Per-dimension scale of the network's tanh output (e.g. max joint-target delta, rad).
    pub action_scale: Vec<f32>,
    /// Added after scaling (zeros for the SAC actor).
    pub action_offset: Vec<f32>,
    pub control_hz: f32,
    pub provenance: Provenance,
    /// Which hand, observation set and task the policy was trained for; `None` for a policy
    /// that drives no particular hand (written as a version-3 file without a task record).
    pub task: Option<PolicyTask>,
}

impl PolicyMeta {
    /// Placeholder metadata: one slice `"obs"`, actions `"a0"`.., identity normalisation,
    /// scale 1, offset 0, no task.
    pub fn unnamed(obs_dim: usize, act_dim: usize, control_hz: f32, provenance: Provenance) -> Self {
        let obs_end = u32::try_from(obs_dim).unwrap_or(u32::MAX);
        Self {
            obs_layout: vec![ObsSlice::new("obs", 0..obs_end)],
            action_names: (0..act_dim).map(|i| format!("a{i}")).collect(),
            obs_norm: ObsNorm::identity(obs_dim),
            action_scale: vec![1.0; act_dim],
            action_offset: vec![0.0; act_dim],
            control_hz,
            provenance,
            task: None,
        }
    }
}

pub(crate) fn activation_code(a: Activation) -> u8 {
    match a {
        Activation::Identity => ACT_IDENTITY,
        Activation::Relu => ACT_RELU,
        Activation::Tanh => ACT_TANH,
    }
}

fn u32_dim(d: usize) -> Result<u32, ExportError> {
    u32::try_from(d).map_err(|_| ExportError::InvalidSpec(format!("dimension {d} does not fit in u32")))
}

impl PolicyFile {
    /// Combines an extracted actor with its metadata. The result is validated when encoded.
    pub fn from_actor(actor: &ExportedActor, meta: PolicyMeta) -> Result<Self, ExportError> {
        let layers = actor
            .layers
            .iter()
            .map(|l| {
                Ok(LayerRecord {
                    in_dim: u32_dim(l.in_dim)?,
                    out_dim: u32_dim(l.out_dim)?,
                    activation: activation_code(l.activation),
                    weights: l.weights.clone(),
                    bias: l.bias.clone(),
                })
            })
            .collect::<Result<Vec<_>, ExportError>>()?;
        Ok(Self {
            provenance: meta.provenance,
            control_hz: meta.control_hz,
            obs_dim: u32_dim(actor.obs_dim())?,
            act_dim: u32_dim(actor.act_dim())?,
            obs_layout: meta.obs_layout,
            obs_mean: meta.obs_norm.mean,
            obs_std: meta.obs_norm.std,
            obs_clip: meta.obs_norm.clip,
            layers,
            action_names: meta.action_names,
            action_scale: meta.action_scale,
            action_offset: meta.action_offset,
            task: meta.task,
        })
    }

    /// The network as owned layers (e.g. for `ExportedActor::to_mlp`).
    pub fn actor(&self) -> Result<ExportedActor, ExportError> {
        let layers = self
            .layers
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let activation = match l.activation {
                    ACT_IDENTITY => Activation::Identity,
                    ACT_RELU => Activation::Relu,
                    ACT_TANH => Activation::Tanh,
                    code => return Err(PolicyError::UnknownActivation { layer: i, code }.into()),
                };
                Ok(ExportedLayer {
                    in_dim: l.in_dim as usize,
                    out_dim: l.out_dim as usize,
                    weights: l.weights.clone(),
                    bias: l.bias.clone(),
                    activation,
                })
            })
            .collect::<Result<Vec<_>, ExportError>>()?;
        Ok(ExportedActor { layers })
    }

    /// Weights and biases of all layers.
    pub fn num_params(&self) -> usize {
        self.layers.iter().map(|l| l.weights.len() + l.bias.len()).sum()
    }

    /// Encodes the file in the current format (version 3, `f32` weights) and checks that the
    /// `no_std` runtime accepts it; invalid metadata (a layout that does not cover the
    /// observation, a non-positive std, ...) is reported as [`ExportError::Format`].
    pub fn to_bytes(&self) -> Result<Vec<u8>, ExportError> {
        self.encode(WeightType::F32)
    }

    /// Encodes the file as version 3 (version 2's aligned arrays, and the task record when
    /// `task` is set) with the weight matrices stored as `weights` (`f16` rounds to nearest,
    /// `i8` quantises each row with its own scale; biases, normalisation and action scaling
    /// stay `f32`).
    pub fn encode(&self, weights: WeightType) -> Result<Vec<u8>, ExportError> {
        crate::v2::encode(self, weights)
    }

    /// Encodes the file as version 1 (postcard payload, every array copied on load), for
    /// readers that predate version 2. Refused for a file with a task record, which version 1
    /// cannot hold: read back, it would claim vge's own hand.
    pub fn to_bytes_v1(&self) -> Result<Vec<u8>, ExportError> {
        if let Some(task) = &self.task {
            return Err(ExportError::InvalidSpec(format!(
                "version 1 has no task record: a policy for hand `{}` cannot be written as version 1",
                task.hand
            )));
        }
        let payload = postcard::to_allocvec(self).map_err(ExportError::Encode)?;
        let len = u32::try_from(payload.len()).map_err(|_| {
            ExportError::InvalidSpec(format!("payload of {} bytes exceeds 4 GiB", payload.len()))
        })?;
        let mut out = Vec::with_capacity(payload.len() + format::HEADER_LEN + format::TRAILER_LEN);
        out.extend_from_slice(&format::header(1, len));
        out.extend_from_slice(&payload);
        let crc = format::crc32(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        vge_runtime::policy::inspect(&out)?;
        Ok(out)
    }

    /// Decodes and fully validates a policy file of any version (the same checks as the
    /// runtime). Quantised weights come back as the `f32` values they stand for.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, ExportError> {
        Self::decode(bytes, true).map(|(file, _)| file)
    }

    /// [`PolicyFile::from_bytes`] that also returns the stored weight type, and checks the
    /// CRC only when `verify_crc` (so that `vge inspect` can still show a damaged file).
    pub fn decode(bytes: &[u8], verify_crc: bool) -> Result<(Self, WeightType), ExportError> {
        let frame = format::check_frame_with(bytes, verify_crc)?;
        if frame.version == 1 {
            vge_runtime::policy::decode(bytes, verify_crc, |_, _| ())?;
            let file = postcard::from_bytes(frame.payload).map_err(ExportError::Decode)?;
            return Ok((file, WeightType::F32));
        }
        crate::v2::decode(bytes, verify_crc)
    }

    /// Writes the encoded file to `path`.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), ExportError> {
        let path = path.as_ref();
        let bytes = self.to_bytes()?;
        std::fs::write(path, bytes).map_err(|source| ExportError::Io { path: path.to_owned(), source })
    }

    /// Reads ([`read_policy_bytes`], at most [`MAX_FILE_LEN`]) and validates the file at `path`.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, ExportError> {
        Self::from_bytes(&read_policy_bytes(path.as_ref(), MAX_FILE_LEN)?)
    }
}

/// The longest policy file the host tools read: [`vge_runtime::policy::max_file_len`] of the
/// largest actor `vge eval` loads (8 layers of width 1024).
pub const MAX_FILE_LEN: usize = vge_runtime::policy::max_file_len(8, 1024);

/// The bytes of the policy file at `path`, refused unread ([`ExportError::TooLarge`]) when
/// its length (from its metadata) exceeds `max_len`, and never more than `max_len` read (a
/// file that grows meanwhile is refused too). Only a regular file is opened
/// ([`check_regular_file`]).
pub fn read_policy_bytes(path: &Path, max_len: usize) -> Result<Vec<u8>, ExportError> {
    use std::io::Read;
    let io = |source| ExportError::Io { path: path.to_owned(), source };
    let too_large = |len: u64| ExportError::TooLarge { path: path.to_owned(), len, max: max_len };
    check_regular_file(path).map_err(io)?;
    let file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    if len > max_len as u64 {
        return Err(too_large(len));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(max_len as u64 + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() > max_len {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Refuses, before it is opened, a path that is not a regular file: opening a FIFO would block
/// until a writer comes, and a device such as `/dev/zero` has no length to check.
pub(crate) fn check_regular_file(path: &Path) -> std::io::Result<()> {
    if std::fs::metadata(path)?.is_file() {
        Ok(())
    } else {
        Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file: vge reads regular files only (not read)",
        ))
    }
}
