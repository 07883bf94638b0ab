//! `vge inspect FILE`: a printable description of a policy file.

use std::fmt;
use std::path::Path;

use vge_runtime::format::{self, ACT_IDENTITY, ACT_RELU, ACT_TANH};
use vge_runtime::policy::{UNRECORDED_HAND, UNRECORDED_OBSERVATION_SET};
use vge_runtime::{PolicyError, WeightType};

use crate::{ExportError, PolicyFile};

/// What `vge inspect` prints (see its `Display`).
#[derive(Debug, Clone, PartialEq)]
pub struct InspectReport {
    pub file_len: usize,
    pub format_version: u16,
    pub checksum_stored: u32,
    pub checksum_computed: u32,
    /// `None` when the runtime accepts the file; else why it does not (checksum, a field).
    pub runtime_error: Option<PolicyError>,
    /// How the weight matrices are stored (`f32` in version 1).
    pub weight_type: WeightType,
    /// The decoded payload (quantised weights as the values they stand for).
    pub policy: PolicyFile,
}

impl InspectReport {
    pub fn checksum_ok(&self) -> bool {
        self.checksum_stored == self.checksum_computed
    }

    /// The file is loadable by `vge_runtime` (checksum and all fields valid).
    pub fn is_valid(&self) -> bool {
        self.runtime_error.is_none()
    }

    /// Weights and biases of all layers.
    pub fn num_params(&self) -> usize {
        self.policy.num_params()
    }

    /// Bytes of RAM `vge_runtime::Policy::load` needs for the parameters: none for versions
    /// 2 and 3 (read in place), every `f32` for version 1 (copied).
    pub fn storage_bytes(&self) -> usize {
        if self.format_version >= 2 {
            return 0;
        }
        let p = &self.policy;
        (self.num_params()
            + p.obs_mean.len()
            + p.obs_std.len()
            + p.action_scale.len()
            + p.action_offset.len())
            * 4
    }
}

/// Describes the policy file `bytes`. A checksum mismatch or an invalid field is reported in
/// the result rather than as an error, as long as the header is sound and the payload decodes.
pub fn report(bytes: &[u8]) -> Result<InspectReport, ExportError> {
    let frame = format::check_frame_with(bytes, false)?;
    let covered = bytes.get(..bytes.len() - format::TRAILER_LEN).unwrap_or(&[]);
    let computed = format::crc32(covered);
    let runtime_error = vge_runtime::policy::inspect(bytes).err();
    let (policy, weight_type) = PolicyFile::decode(bytes, false)?;
    Ok(InspectReport {
        file_len: bytes.len(),
        format_version: frame.version,
        checksum_stored: frame.checksum,
        checksum_computed: computed,
        runtime_error,
        weight_type,
        policy,
    })
}

/// [`report`] on the file at `path`.
pub fn report_file(path: impl AsRef<Path>) -> Result<InspectReport, ExportError> {
    let path = path.as_ref();
    report(&crate::read_policy_bytes(path, crate::MAX_FILE_LEN)?)
}

fn act_name(code: u8) -> &'static str {
    match code {
        ACT_IDENTITY => "identity",
        ACT_RELU => "relu",
        ACT_TANH => "tanh",
        _ => "unknown",
    }
}

fn range(v: &[f32]) -> String {
    let lo = v.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    if v.is_empty() { "[]".into() } else { format!("[{lo:.4}, {hi:.4}]") }
}

impl fmt::Display for InspectReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = &self.policy;
        writeln!(f, "vge policy file, format version {}, {} bytes", self.format_version, self.file_len)?;
        if self.checksum_ok() {
            writeln!(f, "checksum:   CRC-32 {:#010x} ok", self.checksum_stored)?;
        } else {
            writeln!(
                f,
                "checksum:   CRC-32 MISMATCH: stored {:#010x}, computed {:#010x}",
                self.checksum_stored, self.checksum_computed
            )?;
        }
        match self.runtime_error {
            None => writeln!(f, "validation: ok (loadable by vge-runtime)")?,
            Some(e) => writeln!(f, "validation: FAILED: {e}")?,
        }
        let pv = &p.provenance;
        writeln!(
            f,
            "provenance: vge {}, config {}, seed {}, {} steps",
            pv.vge_version, pv.config_hash, pv.seed, pv.steps
        )?;
        match &p.task {
            Some(t) => {
                writeln!(f, "hand:       {} (MJCF sha256 {})", t.hand, t.hand_sha256_hex())?;
                let named = |s: &str| if s.is_empty() { "unspecified".to_owned() } else { s.to_owned() };
                writeln!(
                    f,
                    "task:       observation set {}, object {}, orientation {}",
                    t.observation_set,
                    named(&t.object),
                    named(&t.orientation)
                )?;
            }
            None => {
                let why =
                    if self.format_version < 3 { "file predates hand records" } else { "no hand record" };
                writeln!(
                    f,
                    "hand:       {UNRECORDED_HAND} ({why}), observation set: {UNRECORDED_OBSERVATION_SET}"
                )?;
            }
        }
        writeln!(f, "control:    {} Hz", p.control_hz)?;
        let dims: Vec<String> = std::iter::once(p.obs_dim)
            .chain(p.layers.iter().map(|l| l.out_dim))
            .map(|d| d.to_string())
            .collect();
        writeln!(
            f,
            "network:    {} ({} layers, {} parameters)",
            dims.join(" -> "),
            p.layers.len(),
            self.num_params()
        )?;
        for (i, l) in p.layers.iter().enumerate() {
            writeln!(
                f,
                "  layer {i}: {} -> {} {:<8} weights {} bias {}",
                l.in_dim,
                l.out_dim,
                act_name(l.activation),
                range(&l.weights),
                range(&l.bias)
            )?;
        }
        writeln!(f, "weights:    {}", self.weight_type)?;
        if self.format_version >= 2 {
            writeln!(
                f,
                "runtime RAM for parameters: none (read in place from the {}-byte file)",
                self.file_len
            )?;
        } else {
            writeln!(f, "runtime RAM for parameters: {} bytes (version 1: copied)", self.storage_bytes())?;
        }
        let layout: Vec<String> =
            p.obs_layout.iter().map(|s| format!("{} {}..{}", s.name, s.start, s.end)).collect();
        writeln!(f, "obs ({}):   {}", p.obs_dim, layout.join(", "))?;
        let clip = p.obs_clip.map_or_else(|| "none".to_owned(), |c| format!("±{c}"));
        writeln!(f, "obs norm:   mean {} std {} clip {clip}", range(&p.obs_mean), range(&p.obs_std))?;
        writeln!(f, "actions ({}): action = offset + scale * net(obs_norm)", p.act_dim)?;
        for (i, name) in p.action_names.iter().enumerate() {
            let s = p.action_scale.get(i).copied().unwrap_or(f32::NAN);
            let o = p.action_offset.get(i).copied().unwrap_or(f32::NAN);
            writeln!(f, "  {i:>2} {name:<16} scale {s} offset {o}")?;
        }
        Ok(())
    }
}
