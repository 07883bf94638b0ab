//! `vge import`: an MLP actor from ONNX (e.g. Stable-Baselines3's) as a policy file for the
//! hand.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use vge_export::Provenance;
use vge_sim::EnvConfig;

/// Import an MLP actor from an ONNX file (e.g. a Stable-Baselines3 actor exported with
/// torch.onnx.export) as a policy file for the hand, for `vge eval`, `vge-bridge` and the
/// firmware.
///
/// Accepts Gemm or MatMul + Add layers with Relu or Tanh, Sub/Div normalisation in front,
/// Mul/Add scaling behind (docs/onnx.md). Refuses anything else, naming the node, its op
/// and why (an unsupported op, a width that is not the hand's observation or action size
/// (vge15: 65 and 15), a layer wider than the runtime holds, a non-finite weight), and writes
/// nothing then. A file of more than 64 MiB is refused unread, and a model of more than
/// 1024 nodes, or of more Gemm and MatMul nodes than twice the layers the runtime holds, is
/// refused from its encoding before any of it is built.
///
/// Example: vge import --onnx sac_actor.onnx --out sac.vgep --action-scale hand
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The ONNX model of the actor.
    #[arg(long, value_name = "F.onnx")]
    onnx: PathBuf,
    /// Where to write the policy file.
    #[arg(long, value_name = "P.vgep")]
    out: PathBuf,
    /// Observation mean subtracted before the actor (a text file of one number per
    /// observation, 65 for vge15's full set, separated by whitespace or commas, e.g.
    /// np.savetxt of a VecNormalize's obs_rms.mean), for actors whose graph does not normalise.
    #[arg(long, value_name = "FILE")]
    obs_mean: Option<PathBuf>,
    /// Observation std divided by (one number per observation, e.g. np.sqrt(obs_rms.var + epsilon)).
    #[arg(long, value_name = "FILE")]
    obs_std: Option<PathBuf>,
    /// Clamp the normalised observation to [-C, C] (a VecNormalize's clip_obs).
    #[arg(long, value_name = "C")]
    obs_clip: Option<f32>,
    /// The observation layout the actor was trained on, `name:start..end,...`; refused
    /// unless it is the hand's.
    #[arg(long)]
    obs_layout: Option<String>,
    /// The hand the actor drives: a shipped hand (vge15, allegro) or an MJCF file.
    #[arg(long, default_value = "vge15")]
    hand: String,
    /// What the actor observes: full, proprio or proprio:K (its input width follows).
    #[arg(long, default_value = "full")]
    observation: String,
    /// What the graph's output is: `graph` (already the action: rad per control step),
    /// `hand` (Stable-Baselines3's normalised action in [-1, 1]: times the hand's largest
    /// joint-target step) or a factor. Needed when the graph has no Mul after its last layer.
    #[arg(long, value_name = "graph|hand|FACTOR")]
    action_scale: Option<String>,
}

/// `vge import`: an ONNX MLP actor as a policy file for a hand.
pub fn run(args: ImportArgs) -> anyhow::Result<()> {
    use vge_export::onnx::{ActionScale, ImportOptions, ImportTarget};
    let hand = vge_sim::hands::load(&args.hand).with_context(|| format!("--hand {}", args.hand))?;
    let env = EnvConfig::for_hand(hand)?;
    let set = vge_sim::ObservationSet::parse(&args.observation)
        .map_err(|e| anyhow::anyhow!("--observation: {e}"))?;
    let unknown = Provenance { vge_version: String::new(), config_hash: String::new(), seed: 0, steps: 0 };
    let hand = vge_run::policy_meta::hand_policy_meta(&env, set, unknown);
    let target = ImportTarget {
        obs_layout: hand.obs_layout,
        action_names: hand.action_names,
        control_hz: env.control_hz,
        max_layers: vge_runtime::policy::HAND_MAX_LAYERS,
        max_width: vge_runtime::policy::HAND_MAX_WIDTH,
        task: hand.task,
    };
    let obs_dim = target.obs_dim();
    let (mean, std) = (read_numbers(args.obs_mean.as_deref())?, read_numbers(args.obs_std.as_deref())?);
    let given = mean.is_some() || std.is_some() || args.obs_clip.is_some();
    let obs_norm = given.then(|| vge_export::ObsNorm {
        mean: mean.unwrap_or(vec![0.0; obs_dim]),
        std: std.unwrap_or(vec![1.0; obs_dim]),
        clip: args.obs_clip,
    });
    let obs_layout = args.obs_layout.as_deref().map(parse_obs_layout).transpose()?;
    let action_scale = match args.action_scale.as_deref() {
        None => None,
        Some("graph") => Some(ActionScale::Graph),
        Some("hand") => Some(ActionScale::Times(env.max_action_rad)),
        Some(f) => Some(ActionScale::Times(
            f.parse().with_context(|| format!("--action-scale `{f}`: not graph, hand or a number"))?,
        )),
    };
    let options = ImportOptions {
        obs_norm,
        obs_layout,
        action_scale,
        source: args.onnx.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
    };
    let imported = vge_export::onnx::import_file(&args.onnx, &args.out, &target, &options)
        .with_context(|| format!("importing {}", args.onnx.display()))?;
    for note in &imported.notes {
        println!("note: {note}");
    }
    let p = &imported.policy;
    let activation = |code: u8| ["identity", "relu", "tanh"].get(usize::from(code)).copied().unwrap_or("?");
    let layers = p
        .layers
        .iter()
        .map(|l| format!("{} {}", l.out_dim, activation(l.activation)))
        .collect::<Vec<_>>()
        .join(" -> ");
    let scale = p.action_scale.iter().fold(0.0f32, |m, s| m.max(s.abs()));
    println!(
        "wrote {}: {} -> {layers}, action scale up to {scale} (rad per step), {} Hz; run it with \
         `vge eval --policy {0}` or `vge-bridge run --policy {0}`",
        args.out.display(),
        p.obs_dim,
        p.control_hz
    );
    Ok(())
}

/// The numbers of a file, separated by whitespace or commas (`--obs-mean`, `--obs-std`).
fn read_numbers(path: Option<&std::path::Path>) -> anyhow::Result<Option<Vec<f32>>> {
    let Some(path) = path else { return Ok(None) };
    let text = vge_run::read_limits::read_to_string_bounded(path, vge_run::read_limits::MAX_NUMBERS_FILE_LEN)
        .with_context(|| format!("reading {}", path.display()))?;
    let values = text
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
        .map(|t| t.parse::<f32>().with_context(|| format!("{}: `{t}` is not a number", path.display())))
        .collect::<anyhow::Result<Vec<f32>>>()?;
    Ok(Some(values))
}

/// `--obs-layout`: comma-separated `name:start..end` slices.
fn parse_obs_layout(text: &str) -> anyhow::Result<Vec<vge_export::ObsSlice>> {
    text.split(',')
        .map(|slice| {
            let parsed = slice.trim().rsplit_once(':').and_then(|(name, range)| {
                let (a, b) = range.split_once("..")?;
                Some(vge_export::ObsSlice::new(name, a.parse().ok()?..b.parse().ok()?))
            });
            parsed.with_context(|| format!("--obs-layout: `{slice}` is not name:start..end"))
        })
        .collect()
}
