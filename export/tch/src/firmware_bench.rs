//! `vge bench firmware`: one policy as f32, f16 and i8, each built into the Cortex-M4F
//! firmware and run under qemu (see [`vge_export::firmware`]): flash, RAM, instructions per
//! forward, and the accuracy of each weight type against tch's f32 forward on the host.

use std::path::Path;
use std::time::Duration;

use tch::{Device, Kind, Tensor};
use vge_runtime::{AlignedBytes, HandPolicy, WeightType};

use vge_export::firmware::{self, FirmwareError};
use vge_export::{ActorSpec, ExportError, PolicyFile, PolicyMeta, Provenance};

use crate::{build_actor, extract_actor};

/// Why the benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum FirmwareBenchError {
    #[error(transparent)]
    Export(#[from] ExportError),
    #[error(transparent)]
    Firmware(#[from] FirmwareError),
    #[error(transparent)]
    Tch(#[from] tch::TchError),
    #[error("the firmware exited {code} on the {weights} file:\n{output}")]
    FirmwareFailed { weights: WeightType, code: i32, output: String },
    #[error("policy: {0}")]
    Policy(#[from] vge_runtime::PolicyError),
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// One weight type's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct FirmwareBenchRow {
    pub weights: WeightType,
    pub file_bytes: usize,
    /// Flash of the whole image (code, the policy file, initial data).
    pub flash_bytes: u64,
    /// Static RAM plus the stack peak.
    pub ram_bytes: u64,
    pub static_ram_bytes: u64,
    pub stack_peak_bytes: u64,
    pub instructions_per_forward: f64,
    /// Largest |runtime - tch f32| over the host observations.
    pub max_abs_diff: f32,
    /// Largest |firmware - host runtime| over the firmware's own observations.
    pub firmware_vs_host_max_abs_diff: f32,
    /// Host observations compared with tch.
    pub observations: usize,
    /// The firmware's `opt-level` (`"3"` unless overridden).
    pub opt_level: String,
}

/// Clock of the STM32F405 the instruction counts are scaled to (an estimate: real cycles per
/// instruction are 1-3 and flash adds wait states).
pub const CLOCK_HZ: f64 = 168e6;

impl FirmwareBenchRow {
    /// One JSON object on one line.
    pub fn to_json_line(&self) -> String {
        serde_json::json!({
            "bench": "firmware",
            "weights": self.weights.name(),
            "file_bytes": self.file_bytes,
            "flash_bytes": self.flash_bytes,
            "ram_bytes": self.ram_bytes,
            "static_ram_bytes": self.static_ram_bytes,
            "stack_peak_bytes": self.stack_peak_bytes,
            "instructions_per_forward": self.instructions_per_forward.round(),
            "ms_at_168mhz_one_instruction_per_cycle": self.instructions_per_forward / CLOCK_HZ * 1e3,
            "max_abs_diff": self.max_abs_diff,
            "firmware_vs_host_max_abs_diff": self.firmware_vs_host_max_abs_diff,
            "observations": self.observations,
            "opt_level": self.opt_level,
        })
        .to_string()
    }
}

/// Runs `policy` as each weight type: builds (with `opt_level`, default 3) and runs the
/// firmware in `target_dir` (a cargo target folder of its own) and compares the host runtime
/// with tch on `observations` observations drawn from `seed` (normalised values uniform in
/// [-3, 3)).
pub fn run(
    policy: &PolicyFile,
    target_dir: &Path,
    opt_level: Option<&str>,
    observations: usize,
    seed: i64,
    mut progress: impl FnMut(&str),
) -> Result<Vec<FirmwareBenchRow>, FirmwareBenchError> {
    std::fs::create_dir_all(target_dir)?;
    let obs = observations_for(policy, observations, seed)?;
    let reference = tch_forward(policy, &obs)?;
    let mut rows = Vec::new();
    for weights in [WeightType::F32, WeightType::F16, WeightType::I8] {
        progress(&format!("{weights}: building the firmware and running it under qemu"));
        let bytes = policy.encode(weights)?;
        let path = target_dir.join(format!("bench-{weights}.vgep"));
        std::fs::write(&path, &bytes)?;
        let elf = firmware::build(&path, target_dir, opt_level)?;
        let fw = firmware::run(&elf, Duration::from_secs(300))?;
        if fw.exit_code != 0 {
            return Err(FirmwareBenchError::FirmwareFailed {
                weights,
                code: fw.exit_code,
                output: fw.output,
            });
        }
        let aligned = AlignedBytes::new(&bytes);
        let host = HandPolicy::load(&aligned, &mut [])?;
        let act_dim = host.act_dim();
        let mut action = vec![0.0f32; act_dim];
        let mut max_abs_diff = 0.0f32;
        for (o, r) in obs.chunks_exact(host.obs_dim()).zip(reference.chunks_exact(act_dim)) {
            host.forward(o, &mut action)?;
            max_abs_diff = action.iter().zip(r).fold(max_abs_diff, |m, (a, b)| m.max((a - b).abs()));
        }
        let mut firmware_vs_host = 0.0f32;
        for (o, a) in fw.vectors("obs")?.iter().zip(fw.vectors("act")?) {
            host.forward(o, &mut action)?;
            firmware_vs_host = action.iter().zip(&a).fold(firmware_vs_host, |m, (h, f)| m.max((h - f).abs()));
        }
        rows.push(FirmwareBenchRow {
            weights,
            file_bytes: bytes.len(),
            flash_bytes: fw.flash_bytes()?,
            ram_bytes: fw.ram_bytes()?,
            static_ram_bytes: fw.value("static_ram_bytes")?,
            stack_peak_bytes: fw.value("stack_peak_bytes")?,
            instructions_per_forward: fw.instructions_per_forward()?,
            max_abs_diff,
            firmware_vs_host_max_abs_diff: firmware_vs_host,
            observations,
            opt_level: opt_level.unwrap_or("3").to_owned(),
        });
    }
    Ok(rows)
}

/// A tch-initialised actor of shape `spec` (the caller's hand and config decide it) from
/// `seed`, with identity normalisation and unit scale: the default subject when no trained
/// policy is given.
pub fn seeded_policy(seed: i64, spec: &ActorSpec) -> Result<PolicyFile, ExportError> {
    tch::manual_seed(seed);
    let vs = tch::nn::VarStore::new(Device::Cpu);
    build_actor(&(vs.root() / "actor"), spec)?;
    let actor = extract_actor(&vs, "actor", spec)?;
    let provenance = Provenance {
        vge_version: env!("CARGO_PKG_VERSION").to_owned(),
        config_hash: "bench-firmware".to_owned(),
        seed: seed.unsigned_abs(),
        steps: 0,
    };
    PolicyFile::from_actor(&actor, PolicyMeta::unnamed(spec.obs_dim, spec.act_dim, 20.0, provenance))
}

/// `n` observations, flat: `mean + std * z`, `z` uniform in [-3, 3) from tch's RNG.
fn observations_for(policy: &PolicyFile, n: usize, seed: i64) -> Result<Vec<f32>, FirmwareBenchError> {
    tch::manual_seed(seed);
    let dim = policy.obs_dim as i64;
    let z =
        Tensor::f_rand([n as i64, dim], (Kind::Float, Device::Cpu))?.f_mul_scalar(6.0)?.f_sub_scalar(3.0)?;
    let obs = z * Tensor::from_slice(&policy.obs_std) + Tensor::from_slice(&policy.obs_mean);
    Ok(Vec::<f32>::try_from(&obs.f_flatten(0, -1)?)?)
}

/// The policy's f32 network in tch (an implementation independent of the runtime's).
fn tch_forward(policy: &PolicyFile, obs: &[f32]) -> Result<Vec<f32>, FirmwareBenchError> {
    let dim = policy.obs_dim as i64;
    let y = tch::no_grad(|| -> Result<Tensor, FirmwareBenchError> {
        let mut x = Tensor::from_slice(obs).f_reshape([-1, dim])?;
        x = (x - Tensor::from_slice(&policy.obs_mean)) / Tensor::from_slice(&policy.obs_std);
        if let Some(c) = policy.obs_clip {
            x = x.f_clamp(-f64::from(c), f64::from(c))?;
        }
        for layer in &policy.layers {
            let w = Tensor::from_slice(&layer.weights)
                .f_reshape([i64::from(layer.out_dim), i64::from(layer.in_dim)])?;
            x = x.f_matmul(&w.f_tr()?)? + Tensor::from_slice(&layer.bias);
            x = match layer.activation {
                vge_runtime::format::ACT_RELU => x.f_relu()?,
                vge_runtime::format::ACT_TANH => x.f_tanh()?,
                _ => x,
            };
        }
        Ok(x * Tensor::from_slice(&policy.action_scale) + Tensor::from_slice(&policy.action_offset))
    })?;
    Ok(Vec::<f32>::try_from(&y.f_flatten(0, -1)?)?)
}
