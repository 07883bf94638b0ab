//! `vge export`: a policy file (or an ONNX model) from an actor's variables, a fresh actor,
//! or another policy file.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
#[cfg(feature = "train")]
use tch::{Device, nn};
#[cfg(feature = "train")]
use vge_export::Provenance;
#[cfg(feature = "train")]
use vge_sim::EnvConfig;

/// Write a policy file (postcard, see docs/policy-format.md) from an actor.
///
/// The file carries the actor's layers, the hand's observation and action layouts, the
/// action scaling and control rate of the default env, and provenance. Load it with
/// `vge-runtime` (no_std) or run it with `vge-bridge`.
///
/// `--format onnx` writes the same policy as one ONNX graph (opset 17) from the raw
/// observation to the action instead (docs/onnx.md): normalisation, layers, tanh, action
/// scale, with the layouts, control rate and provenance in its metadata_props.
#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("source").required(true).args(["actor", "init", "policy"]))]
pub struct ExportArgs {
    /// Actor variables saved by tch (`VarStore::save`, names `actor.l{i}`, `actor.mean`, ...).
    #[arg(long)]
    actor: Option<PathBuf>,
    /// Export a freshly initialised (untrained) actor instead, e.g. to test a deployment path.
    #[arg(long)]
    init: bool,
    /// Re-encode an existing policy file (any version) instead, e.g. a trained run's
    /// policy.vgep as i8 for a microcontroller; its provenance is kept.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["seed", "hidden", "steps"])]
    policy: Option<PathBuf>,
    /// How the weight matrices are stored (format version 3): f32 (exact), f16 (half the
    /// flash, ~3 significant digits) or i8 (a quarter, per-row scales; inputs quantised per
    /// layer). See docs/policy-format.md.
    #[arg(long, value_enum, default_value_t = Weights::F32)]
    weights: Weights,
    /// Seed of the initialisation (--init) and recorded as provenance.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Hidden layer widths of the actor.
    #[arg(long, value_delimiter = ',', default_value = "256,256")]
    hidden: Vec<usize>,
    /// Environment steps the actor was trained for (provenance).
    #[arg(long, default_value_t = 0)]
    steps: u64,
    /// The hand the actor drives (--actor, --init): a shipped hand (vge15, allegro) or an
    /// MJCF file; it sets the action's joints and the observation's sizes.
    #[arg(long, default_value = "vge15", conflicts_with = "policy")]
    hand: String,
    /// What the actor observes (--actor, --init): full, proprio or proprio:K.
    #[arg(long, default_value = "full", conflicts_with = "policy")]
    observation: String,
    /// What to write: a vge policy file, or an ONNX model of the same policy.
    #[arg(long, value_enum, default_value_t = ExportFormat::Vgep)]
    format: ExportFormat,
    /// Where to write the policy file (or, with --format onnx, the ONNX model).
    #[arg(long)]
    out: PathBuf,
}

/// `vge export --format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// A vge policy file (docs/policy-format.md).
    Vgep,
    /// An ONNX model (docs/onnx.md).
    Onnx,
}

/// `vge export --weights`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Weights {
    F32,
    F16,
    I8,
}

impl From<Weights> for vge_export::WeightType {
    fn from(w: Weights) -> Self {
        match w {
            Weights::F32 => Self::F32,
            Weights::F16 => Self::F16,
            Weights::I8 => Self::I8,
        }
    }
}

pub fn run(args: ExportArgs) -> anyhow::Result<()> {
    let weights = vge_export::WeightType::from(args.weights);
    let bytes = match &args.policy {
        Some(path) => vge_export::PolicyFile::read(path)
            .with_context(|| format!("reading policy file {}", path.display()))?
            .encode(weights)?,
        None => export_actor(&args, weights)?,
    };
    if args.format == ExportFormat::Onnx {
        return export_onnx(&args, &bytes);
    }
    std::fs::write(&args.out, &bytes).with_context(|| format!("writing {}", args.out.display()))?;
    let version = vge_runtime::format::FORMAT_VERSION;
    println!(
        "wrote {} ({} bytes, {weights} weights, format version {version})",
        args.out.display(),
        bytes.len()
    );
    Ok(())
}

/// `vge export --format onnx`: the policy file `vgep` as an ONNX model.
fn export_onnx(args: &ExportArgs, vgep: &[u8]) -> anyhow::Result<()> {
    // A stored i8 file re-encoded as f32 above would export the weights it stands for, not
    // the quantised forward the runtime runs: refused like `--weights i8`.
    if let Some(path) = &args.policy
        && vge_export::inspect::report_file(path)?.weight_type == vge_export::WeightType::I8
    {
        bail!("{}: {}", path.display(), vge_export::onnx::OnnxError::Quantised);
    }
    let bytes = vge_export::onnx::policy_bytes_to_onnx(vgep)?;
    std::fs::write(&args.out, &bytes).with_context(|| format!("writing {}", args.out.display()))?;
    let policy = vge_export::PolicyFile::from_bytes(vgep)?;
    println!(
        "wrote {} ({} bytes, ONNX opset {}: obs [batch, {}] -> action [batch, {}], {} layers)",
        args.out.display(),
        bytes.len(),
        vge_export::onnx::OPSET_VERSION,
        policy.obs_dim,
        policy.act_dim,
        policy.layers.len()
    );
    Ok(())
}

/// The policy file of a saved (`--actor`) or fresh (`--init`) actor.
#[cfg(feature = "train")]
fn export_actor(args: &ExportArgs, weights: vge_export::WeightType) -> anyhow::Result<Vec<u8>> {
    // Checked before libtorch allocates the layers: the runtime runs at most these.
    let (max_layers, max_width) = (vge_runtime::policy::HAND_MAX_LAYERS, vge_runtime::policy::HAND_MAX_WIDTH);
    anyhow::ensure!(
        args.hidden.iter().all(|&h| (1..=max_width).contains(&h)) && args.hidden.len() < max_layers,
        "--hidden {:?}: the runtime runs at most {} hidden layers of 1 to {max_width} units",
        args.hidden,
        max_layers - 1
    );
    let hand = vge_sim::hands::load(&args.hand).with_context(|| format!("--hand {}", args.hand))?;
    let env = EnvConfig::for_hand(hand)?;
    let set = vge_sim::ObservationSet::parse(&args.observation)
        .map_err(|e| anyhow::anyhow!("--observation: {e}"))?;
    let layout = vge_sim::ObservationLayout::new(set, env.hand.num_joints(), env.hand.num_fingers());
    let mut vs = nn::VarStore::new(Device::Cpu);
    let spec = vge_trainer::nets::NetSpec {
        obs_dim: layout.dim() as i64,
        act_dim: env.hand.num_joints() as i64,
        hidden: args.hidden.iter().map(|&h| h as i64).collect(),
    };
    tch::manual_seed(args.seed as i64);
    let _actor = vge_trainer::nets::GaussianActor::new(
        &vs.root(),
        &spec,
        &vec![env.max_action_rad; env.hand.num_joints()],
    );
    let config_hash = match &args.actor {
        Some(path) => {
            vs.load(path).with_context(|| format!("loading actor variables from {}", path.display()))?;
            format!("actor:{}", path.display())
        }
        None => "untrained".to_owned(),
    };
    let provenance = Provenance {
        vge_version: env!("CARGO_PKG_VERSION").to_owned(),
        config_hash,
        seed: args.seed,
        steps: args.steps,
    };
    let bytes = vge_trainer::policy_export::export_hand_actor(&vs, &args.hidden, &env, set, provenance)?;
    if weights == vge_export::WeightType::F32 {
        return Ok(bytes);
    }
    Ok(vge_export::PolicyFile::from_bytes(&bytes)?.encode(weights)?)
}

/// Without libtorch there is no actor to export: only `--policy` works.
#[cfg(not(feature = "train"))]
fn export_actor(_: &ExportArgs, _: vge_export::WeightType) -> anyhow::Result<Vec<u8>> {
    Err(super::without_training("vge export --actor/--init"))
}
