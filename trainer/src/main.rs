//! `vge`: train, evaluate, export and inspect finger-gaiting policies.

mod closed_output;

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::{Args, Parser, Subcommand};
use tch::{Device, nn};
use vge_export::Provenance;
use vge_sim::{EnvConfig, ObjectShape};
use vge_trainer::controllers::rollout::{self, ControllerKind, RolloutOptions};
use vge_trainer::nets::{GaussianActor, NetSpec};
use vge_trainer::{bench_update, policy_export};

/// Value-guided exploration for dexterous finger-gaiting: SAC whose behaviour policy follows
/// sub-skill controllers where the critic values them, on a simulated 15-DOF hand.
#[derive(Debug, Parser)]
#[command(version, about, long_about = None)]
#[command(after_help = "A closed stdout or stderr (`vge ... | head -1`) ends vge quietly with status 0.")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The episodes of the success test (`vge eval`, `vge robustness`).
#[derive(Debug, Clone, Copy, Args)]
struct EpisodeArgs {
    #[arg(long, default_value_t = ObjectShape::Cube)]
    object: ObjectShape,
    /// Seed of the grasp, noise and perturbation draws (episode k uses seed + k).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Episode length in seconds of sim time.
    #[arg(long, default_value_t = vge_trainer::eval::SUCCESS_TEST_EPISODE_S)]
    episode_s: f32,
    /// Uniform noise (+-rad) on the initial grasp's roll and closing angles; 0 starts
    /// every episode from the same grasp (then, without sensor noise or perturbations,
    /// all episodes are the same).
    #[arg(long, default_value_t = vge_trainer::eval::SUCCESS_TEST_GRASP_NOISE_RAD)]
    grasp_noise_rad: f32,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Train a policy with SAC (or TD3: `algorithm = "td3"`) and the configured behaviour
    /// policy (RL, RL+BC, FGE, VGE, VGE+BC) from a TOML config (see configs/).
    ///
    /// Writes DIR/config.toml, DIR/metrics.csv (step, return, rotation, contacts, controller
    /// share, losses), the same curves for TensorBoard in DIR/tensorboard (`tensorboard
    /// --logdir DIR`), DIR/eval.csv, checkpoints in DIR/checkpoint and, when done, the actor
    /// as DIR/policy.vgep. Ctrl-C saves a checkpoint and exits; `--resume` continues, also
    /// after a kill (from the last periodic checkpoint).
    ///
    /// A run can start from another run's networks (actor, critics, observation
    /// normaliser) with the config key `init_from = "DIR"` or `--set init_from=DIR`: a
    /// second curriculum stage, e.g. configs/cube-fg-fge-robust-finetune.toml, which
    /// fine-tunes a trained gait under sensor noise and pushes.
    Train {
        /// Experiment config (TOML), e.g. configs/cube-fg-vge.toml. Not needed with --resume.
        #[arg(long, required_unless_present = "resume")]
        config: Option<PathBuf>,
        /// Output directory of the run.
        #[arg(long, required_unless_present = "resume")]
        out: Option<PathBuf>,
        /// Continue the run in this directory from its last checkpoint (its config.toml). The
        /// checkpoint's files are checked against its manifest first: a damaged, truncated or
        /// older vge's checkpoint is refused, naming the file.
        #[arg(long, conflicts_with_all = ["config", "out"])]
        resume: Option<PathBuf>,
        /// Override the config's seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Override the config's total env steps.
        #[arg(long)]
        steps: Option<u64>,
        /// Override any config field, e.g. `--set sac.batch=128 --set vge.horizon=20`.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
    },
    /// Train one config for several seeds, one run directory each (DIR/seed-N). A finished
    /// seed (DIR/seed-N/policy.vgep) is skipped and an interrupted one resumed, so the same
    /// command again continues a sweep.
    ///
    /// Three ways to run the seeds: one after the other in this process (the default);
    /// `--jobs N` side by side as N `vge train` processes, each logging to
    /// DIR/seed-N/train.log, with a progress line per seed every 30 s and a summary; or
    /// `--slurm`, a Slurm array job with one task per seed (docs/cluster.md). Ctrl-C or
    /// SIGTERM makes every running seed write a checkpoint and exit.
    ///
    /// Examples:
    ///   vge sweep --config configs/cube-fg-vge.toml --seeds 0..4 --out runs/fg --jobs 2
    ///   vge sweep --config configs/cube-fg-vge.toml --seeds 0..10 --out runs/fg --slurm
    ///       --partition cpu --time 24:00:00 --cpus-per-task 4
    ///   vge plot runs/fg/seed-* --out fg.png
    #[command(verbatim_doc_comment)]
    Sweep(SweepArgs),
    /// Plot training curves of run directories (mean and min-max over runs of the same
    /// experiment) into a PNG, and print a markdown table of final success rates; or, with
    /// --table1, the paper's Table I and Fig. 3 from all runs below the given folders.
    ///
    /// Panels: episode return, rotation, controller share, and the critic's mean Q beside the
    /// discounted Monte-Carlo returns of its data (a sound critic stays within them). A run
    /// learned when its final-eval.json success rate is >= 50% (`vge eval`'s success test).
    /// Runs trained on several objects also get OUT-per-object.png beside OUT: each object's
    /// success in the periodic evaluations, one panel per object.
    ///
    /// --table1 DIR places every run by its config's controller and method and writes
    /// DIR/table1.csv (controller,method,seeds,learned,success_rate_mean,return_mean,
    /// return_std,env_steps), DIR/table1.md (beside the paper's numbers) and
    /// DIR/curves-fg.png, DIR/curves-cs.png (periodic success rate and return against env
    /// steps, one band per method). Runs without final-eval.json are counted as running.
    /// The controllers alone come from DIR/controllers/{fg,cs,igm}.json when present
    /// (`vge controller --kind fg --episodes 20 --episode-s 30 --json`).
    ///
    /// Examples:
    ///   vge plot runs/fg/seed-* --out fg.png --success-csv fg.csv
    ///   vge plot --table1 docs/results/table1 docs/results/table1 docs/results/cube-fg-vge-seeds
    #[command(verbatim_doc_comment)]
    Plot {
        /// Run directories (each with config.toml and metrics.csv); with --table1, folders
        /// searched for runs (three levels down).
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// The PNG of the curves.
        #[arg(long, required_unless_present = "table1", conflicts_with = "table1")]
        out: Option<PathBuf>,
        /// Also write one row per run (learned, success rate, env steps, wall time) here.
        #[arg(long, conflicts_with = "table1")]
        success_csv: Option<PathBuf>,
        /// Write Table I and its curves into this folder instead (see above).
        #[arg(long, value_name = "DIR")]
        table1: Option<PathBuf>,
    },
    /// Score finished runs on many held-out episodes and write DIR/score.json (training
    /// writes it at its end too): the run's selected policy (its own model selection on
    /// validation grasps, policy-best.vgep), its final policy (policy.vgep) and, where the
    /// last 3 periodic snapshots are kept, their mean, all on the same episodes.
    ///
    /// The episodes: --episodes (default 100) of the run's success test (30 s, grasps
    /// randomised by 0.02 rad in every stored config; no training disturbances) from env
    /// seeds --seed + k, the same for every run and apart from the validation and test
    /// episodes training drew. An episode succeeds when the object turns >= 2 pi about z
    /// without a drop. score.json: {"episodes", "seed", "selected", "final",
    /// "last_snapshots"}, each policy's success_rate, mean_return, drop_rate,
    /// mean_rotation_rad, its file, step and CRC-32 (docs/scoring.md).
    ///
    /// A run already scored with the same episodes, seed, definition and policy files is
    /// skipped (--force scores it again). An unfinished run (no final-eval.json) is refused
    /// and nothing is written; a missing, damaged or other-layout policy file fails naming
    /// the file. Runs are scored one after another, their episodes side by side on
    /// --threads threads (default: RAYON_NUM_THREADS, else all cores).
    ///
    /// Examples:
    ///   vge score docs/results/table1/cube-fg-fge/seed-*
    ///   vge score --threads 1 --episodes 200 runs/fg/seed-0
    #[command(verbatim_doc_comment)]
    Score {
        /// Finished run folders (each with config.toml, final-eval.json, policy.vgep).
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// Held-out episodes per policy.
        #[arg(long, default_value_t = vge_trainer::score::DEFAULT_EPISODES)]
        episodes: usize,
        /// Env seed of the first held-out episode (episode k: seed + k).
        #[arg(long, default_value_t = vge_trainer::score::HELD_OUT_SEED)]
        seed: u64,
        /// Score again runs whose score.json already holds this score.
        #[arg(long)]
        force: bool,
        /// Threads the episodes run on (default: RAYON_NUM_THREADS, else all cores).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
        threads: Option<u32>,
    },
    /// Compare groups of scored runs the way the field reports them (rliable's statistics):
    /// per group the IQM and mean of the runs' held-out success (score.json) with 95%
    /// stratified bootstrap intervals, the probability that a run of one group beats a run
    /// of another with its interval, performance profiles and IQM learning curves.
    ///
    /// Each group is NAME=DIR,DIR,... (run folders, or folders with runs below them). Every
    /// run must have its score.json (`vge score`). Writes OUT/compare.csv (group, policy,
    /// runs, iqm, iqm_ci_low, iqm_ci_high, mean, mean_ci_low, mean_ci_high; for the
    /// selected, final and last-snapshot policies), OUT/compare.md, OUT/improvement.csv
    /// (a, b, prob_improvement, ci_low, ci_high; selected policy), OUT/aggregates.png,
    /// OUT/profiles.png and OUT/curves.png (IQM of the periodic success and return against
    /// env steps, with 95% bands). Definitions: docs/scoring.md.
    ///
    /// Example:
    ///   vge compare fge=docs/results/table1/cube-fg-fge vge=docs/results/cube-fg-vge-seeds
    ///       --out cmp/ --pairs vge:fge
    #[command(verbatim_doc_comment)]
    Compare {
        /// Groups: NAME=DIR,DIR,...
        #[arg(required = true, value_parser = vge_trainer::compare::parse_group)]
        groups: Vec<vge_trainer::compare::GroupSpec>,
        /// Output folder (created).
        #[arg(long)]
        out: PathBuf,
        /// Pairs A:B whose probability of improvement P(A > B) to report (default: every
        /// ordered pair of groups).
        #[arg(long, value_delimiter = ',', value_parser = vge_trainer::compare::parse_pair)]
        pairs: Vec<(String, String)>,
        /// Seed of the bootstrap resampling.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Bootstrap resamples per interval (at least 2000).
        #[arg(long, default_value_t = vge_trainer::stats::RESAMPLES)]
        resamples: usize,
    },
    /// Evaluate a policy file on vge-runtime in the simulator (the success test): mean
    /// return, rotation, contact switches, drops and success rate.
    ///
    /// The defaults are the success test that training's evaluations and `vge plot` use:
    /// 20 episodes of 30 s from initial grasps randomised by +-0.02 rad; an episode succeeds
    /// when the object turns >= 2 pi about z without a drop, and a seed has learned when its
    /// policy succeeds in >= 50% of them. Episodes run side by side on all cores.
    Eval(EvalArgs),
    /// The paper's robustness test (Fig. 4): return, success and drops of a policy against the
    /// level of one disturbance at a time.
    ///
    /// Axes, each from 0 to the paper's level in --levels even steps, the others off: noise
    /// on the observed joint positions (0..0.1 rad), error on the contact normals (0..50%),
    /// error on the contact positions (0..3 mm), and a random force on the object redrawn with
    /// probability 0.1 per step, two ways: Gaussian per component with std 0..its weight
    /// (perturbation_force_n; its mean size is 1.6 times the std), and of magnitude 0..its
    /// weight in a random direction (perturbation_magnitude_n, the paper's "forces
    /// equivalent to the full weight of the object"). Every level runs the same --episodes episodes
    /// (same grasps). Writes DIR/robustness.csv (one row per axis and level, with
    /// return_fraction = return / undisturbed return), DIR/robustness.json and
    /// DIR/robustness.png.
    ///
    /// Example: vge robustness --policy runs/fg/seed-0/policy.vgep --episodes 10 --out rob/
    Robustness(RobustnessArgs),
    /// Write a policy file (postcard, see docs/policy-format.md) from an actor.
    ///
    /// The file carries the actor's layers, the hand's observation and action layouts, the
    /// action scaling and control rate of the default env, and provenance. Load it with
    /// `vge-runtime` (no_std) or run it with `vge-bridge`.
    ///
    /// `--format onnx` writes the same policy as one ONNX graph (opset 17) from the raw
    /// observation to the action instead (docs/onnx.md): normalisation, layers, tanh, action
    /// scale, with the layouts, control rate and provenance in its metadata_props.
    Export(ExportArgs),
    /// Import an MLP actor from an ONNX file (e.g. a Stable-Baselines3 actor exported with
    /// torch.onnx.export) as a policy file for the hand, for `vge eval`, `vge-bridge` and the
    /// firmware.
    ///
    /// Accepts Gemm or MatMul + Add layers with Relu or Tanh, Sub/Div normalisation in front,
    /// Mul/Add scaling behind (docs/onnx.md). Refuses anything else, naming the node, its op
    /// and why (an unsupported op, a width that is not the hand's 65 observations or 15
    /// actions, a layer wider than the runtime holds, a non-finite weight), and writes
    /// nothing then.
    ///
    /// Example: vge import --onnx sac_actor.onnx --out sac.vgep --action-scale hand
    Import(ImportArgs),
    /// Check a policy file and print what it holds: format version, dimensions, layers,
    /// parameter count, provenance, checksum status. Exits non-zero if it is not valid.
    Inspect {
        /// The policy file.
        file: PathBuf,
    },
    /// Roll out one sub-skill controller alone on the simulated hand.
    ///
    /// IGM (in-grasp manipulation: contact-force QP + rotation), CS (contact switching: a
    /// detach/re-attach trajectory of one finger) or FG (both). Prints mean return,
    /// mean_rotation_rad (object rotation about z per episode), mean fingertip contacts,
    /// drops (episodes ended early) and the controller's cost per call.
    Controller(ControllerArgs),
    /// Measure vge's hot paths on this machine.
    #[command(subcommand)]
    Bench(Bench),
}

#[derive(Debug, Args)]
struct EvalArgs {
    /// The policy file (`DIR/policy.vgep` of a training run, or `vge export`'s output).
    #[arg(long, required_unless_present = "run")]
    policy: Option<PathBuf>,
    /// Instead of --policy: score a finished training run's final policy again, with its
    /// config and the very episodes of its `final-eval.json`, by this vge's success test, and
    /// print the stored figures beside the new ones (for runs scored by an older vge). A run
    /// on several objects is scored on each of them.
    #[arg(long, conflicts_with_all = ["policy", "plot", "record", "noise_q_rad", "noise_normal_frac", "noise_position_m", "perturb_force_n", "perturb_magnitude_n", "objects"])]
    run: Option<PathBuf>,
    /// With --run: replace the run's `final-eval.json` by the new score.
    #[arg(long, requires = "run")]
    write: bool,
    /// Episodes to run (the success test uses 20).
    #[arg(long, default_value_t = vge_trainer::eval::SUCCESS_TEST_EPISODES)]
    episodes: usize,
    #[command(flatten)]
    episode: EpisodeArgs,
    /// Instead of --object: the success test on each of these objects, `all` (the paper's
    /// five: cube, sphere, cylinder, dodecahedron, icosahedron) or a comma-separated list
    /// (e.g. `cube,hexagonal-prism`, the prism being no training object): --episodes episodes
    /// per object, every object on the same seeds; one row per object and the overall
    /// figures (all episodes pooled). With --plot F.png: one gait diagram per object,
    /// F-<object>.png.
    #[arg(long, value_name = "all|NAME,NAME,...", value_parser = parse_object_list, conflicts_with_all = ["object", "record"])]
    objects: Option<ObjectList>,
    /// Gaussian noise on observed joint positions (rad).
    #[arg(long, default_value_t = 0.0)]
    noise_q_rad: f32,
    /// Noise on contact normals, as a fraction of their length.
    #[arg(long, default_value_t = 0.0)]
    noise_normal_frac: f32,
    /// Gaussian noise on contact positions (m).
    #[arg(long, default_value_t = 0.0)]
    noise_position_m: f32,
    /// Random external force on the object, std per axis (N).
    #[arg(long, default_value_t = 0.0)]
    perturb_force_n: f32,
    /// Instead: a random external force of this magnitude (N) in a random direction.
    #[arg(long, default_value_t = 0.0, conflicts_with = "perturb_force_n")]
    perturb_magnitude_n: f32,
    /// Also draw the gait diagram of the first episode (seed --seed) into this PNG: each
    /// finger's contact over time above the object's rotation.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Also record the first episode (seed --seed) into this Rerun file: each finger link's
    /// pose and the object's, the fingertip and link contact points with their normal forces
    /// (arrows, 1 cm per N), the 15 actions and the reward, one row per control step on the
    /// `step` and `sim_time` timelines. Open it with the Rerun viewer: `rerun F.rrd` (from
    /// `pip install rerun-sdk==0.36.3`). Needs a vge built with `--features rerun`.
    #[arg(long, value_name = "F.rrd")]
    record: Option<PathBuf>,
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Args)]
struct RobustnessArgs {
    /// The policy file.
    #[arg(long)]
    policy: PathBuf,
    /// Episodes per level.
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Levels per axis, evenly from 0 to the paper's level (at least 2).
    #[arg(long, default_value_t = 5)]
    levels: usize,
    /// Only these axes, comma-separated (joint_noise_rad, normal_error_frac, position_error_m,
    /// perturbation_force_n, perturbation_magnitude_n), e.g. to screen snapshots on the pushes
    /// alone; all five when left out.
    #[arg(long, value_delimiter = ',', value_parser = parse_robustness_axis)]
    axes: Vec<vge_trainer::robustness::Axis>,
    /// The same episodes (seeds, grasps) run at every level.
    #[command(flatten)]
    episode: EpisodeArgs,
    /// Output folder (created).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Debug, Args)]
struct ControllerArgs {
    #[arg(long, value_parser = parse_controller_kind)]
    kind: ControllerKind,
    #[arg(long, default_value_t = ObjectShape::Cube)]
    object: ObjectShape,
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Seed of the noise and perturbation draws. The grasp itself is not randomised, so
    /// without noise or perturbation every episode (and every seed) is the same.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Episode length in seconds of sim time [default: 10, or with --config the success
    /// test's `run.eval_episode_s`].
    #[arg(long)]
    episode_s: Option<f32>,
    /// Randomise the initial grasp per episode (pose noise, rad); 0 starts every
    /// episode from the same grasp [default: 0.02, or with --config the success test's
    /// `run.eval_grasp_noise_rad`].
    #[arg(long)]
    grasp_noise_rad: Option<f32>,
    /// Experiment config (TOML) whose [env] the controller runs in (object mass and friction,
    /// motors, hand orientation, finger collisions, grasp), as the success test runs it:
    /// without the training disturbances (sensor noise, pushes, randomisation, drop
    /// penalty); CS's trajectory is `vge.horizon` steps. `--object` replaces its object.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override a key of --config, e.g. `--set env.object_mass_kg=0.4` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE", requires = "config")]
    overrides: Vec<String>,
    /// Print one JSON line instead of a summary.
    #[arg(long)]
    json: bool,
}

fn parse_seed_range(s: &str) -> Result<std::ops::Range<u64>, String> {
    let (a, b) = s.split_once("..").ok_or_else(|| format!("`{s}` is not a range like 0..10"))?;
    let a: u64 = a.trim().parse().map_err(|_| format!("`{a}` is not a seed"))?;
    let b: u64 = b.trim().parse().map_err(|_| format!("`{b}` is not a seed"))?;
    if a >= b {
        return Err(format!("empty seed range {s}"));
    }
    Ok(a..b)
}

/// The objects of `vge eval --objects`.
#[derive(Debug, Clone)]
struct ObjectList(Vec<ObjectShape>);

fn parse_object_list(s: &str) -> Result<ObjectList, String> {
    vge_trainer::eval::parse_objects(s).map(ObjectList)
}

fn parse_controller_kind(s: &str) -> Result<ControllerKind, String> {
    s.parse().map_err(|_| format!("unknown controller `{s}` (one of: igm, cs, fg)"))
}

#[derive(Debug, Args)]
struct SweepArgs {
    /// Experiment config (TOML), e.g. configs/cube-fg-vge.toml.
    #[arg(long)]
    config: PathBuf,
    /// Seeds as a range `A..B` (B excluded), e.g. `0..10`.
    #[arg(long, value_parser = parse_seed_range)]
    seeds: std::ops::Range<u64>,
    /// Folder of the sweep: one run directory per seed, DIR/seed-N.
    #[arg(long)]
    out: PathBuf,
    /// Override the config's total env steps (every seed).
    #[arg(long)]
    steps: Option<u64>,
    /// Override any config field for every seed, e.g. `--set sac.batch=128`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Train N seeds at once, each as its own `vge train` process (stdout and stderr in
    /// DIR/seed-N/train.log). Without it the seeds run one after the other in this process.
    /// Give each job its own cores: N x --threads-per-job should not exceed them.
    #[arg(long, value_name = "N", conflicts_with = "slurm", value_parser = clap::value_parser!(u32).range(1..))]
    jobs: Option<u32>,
    /// libtorch threads (sac.threads, unless --set gives it) and env-stepping threads of
    /// each --jobs process.
    #[arg(long, value_name = "K", default_value_t = 1, requires = "jobs", value_parser = clap::value_parser!(u32).range(1..))]
    threads_per_job: u32,
    /// Seconds between progress lines (one per running seed) with --jobs.
    #[arg(long, value_name = "S", default_value_t = 30, requires = "jobs")]
    report_every_s: u64,
    /// Write DIR/sweep.sbatch, a Slurm array job with one task per unfinished seed (task id
    /// = seed), and submit it with sbatch. Each task resumes its seed when its folder holds a
    /// checkpoint, and checkpoints and exits on SIGTERM (scancel, preemption, and 120 s
    /// before --time runs out), so submitting again continues where the tasks stopped.
    /// See docs/cluster.md.
    #[arg(long)]
    slurm: bool,
    /// Slurm partition of the tasks (default: the cluster's default partition).
    #[arg(long, requires = "slurm")]
    partition: Option<String>,
    /// Wall-clock limit per task, e.g. 12:00:00 or 2-00:00:00 (default: the partition's).
    #[arg(long, value_name = "HH:MM:SS", requires = "slurm")]
    time: Option<String>,
    /// CPUs per task; also its libtorch threads (sac.threads, unless --set gives it).
    #[arg(long, value_name = "N", default_value_t = 1, requires = "slurm", value_parser = clap::value_parser!(u32).range(1..))]
    cpus_per_task: u32,
    /// Only write DIR/sweep.sbatch; do not submit it.
    #[arg(long, requires = "slurm")]
    dry_run: bool,
}

#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("source").required(true).args(["actor", "init", "policy"]))]
struct ExportArgs {
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
    /// How the weight matrices are stored (format version 2): f32 (exact), f16 (half the
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
    /// What to write: a vge policy file, or an ONNX model of the same policy.
    #[arg(long, value_enum, default_value_t = ExportFormat::Vgep)]
    format: ExportFormat,
    /// Where to write the policy file (or, with --format onnx, the ONNX model).
    #[arg(long)]
    out: PathBuf,
}

/// `vge export --format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ExportFormat {
    /// A vge policy file (docs/policy-format.md).
    Vgep,
    /// An ONNX model (docs/onnx.md).
    Onnx,
}

#[derive(Debug, Args)]
struct ImportArgs {
    /// The ONNX model of the actor.
    #[arg(long, value_name = "F.onnx")]
    onnx: PathBuf,
    /// Where to write the policy file.
    #[arg(long, value_name = "P.vgep")]
    out: PathBuf,
    /// Observation mean subtracted before the actor (a text file of 65 numbers separated by
    /// whitespace or commas, e.g. np.savetxt of a VecNormalize's obs_rms.mean), for actors
    /// whose graph does not normalise.
    #[arg(long, value_name = "FILE")]
    obs_mean: Option<PathBuf>,
    /// Observation std divided by (65 numbers, e.g. np.sqrt(obs_rms.var + epsilon)).
    #[arg(long, value_name = "FILE")]
    obs_std: Option<PathBuf>,
    /// Clamp the normalised observation to [-C, C] (a VecNormalize's clip_obs).
    #[arg(long, value_name = "C")]
    obs_clip: Option<f32>,
    /// The observation layout the actor was trained on, `name:start..end,...`; refused
    /// unless it is the hand's.
    #[arg(long)]
    obs_layout: Option<String>,
    /// What the graph's output is: `graph` (already the action: rad per control step),
    /// `hand` (Stable-Baselines3's normalised action in [-1, 1]: times the hand's largest
    /// joint-target step) or a factor. Needed when the graph has no Mul after its last layer.
    #[arg(long, value_name = "graph|hand|FACTOR")]
    action_scale: Option<String>,
}

#[derive(Debug, Subcommand)]
enum Bench {
    /// Full SAC updates per second: batch 256, 256x256 actor and twin critics, obs 65,
    /// action 15, alpha 0, critics with layer norm (the training defaults); also the
    /// achieved GFLOP/s and this CPU's matmul GFLOP/s for comparison.
    Update {
        /// Print one JSON line instead of a table.
        #[arg(long)]
        json: bool,
        /// Timed updates (after 20 warm-up updates).
        #[arg(long, default_value_t = 300)]
        updates: usize,
        /// Minibatch size.
        #[arg(long, default_value_t = 256)]
        batch: i64,
        /// Seed of the network initialisation and random batches.
        #[arg(long, default_value_t = 0)]
        seed: i64,
        /// Learner: sac or td3 (TD3 updates the actor every second step).
        #[arg(long, default_value = "sac", value_parser = ["sac", "td3"])]
        algorithm: String,
        /// Layer norm in the critics' hidden layers (`sac.critic_layer_norm`).
        #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
        layer_norm: bool,
        /// Number format of the hidden layers' matmuls (`sac.matmul`): f32 or bf16 (f32
        /// master weights; pays on CPUs with AVX512_BF16).
        #[arg(long, default_value = "f32", value_parser = ["f32", "bf16"])]
        matmul: String,
    },
    /// Simulator throughput: control steps per second of one world on one thread, and of N
    /// worlds stepped across all cores, at the default env rates.
    Sim {
        /// Print one JSON line instead of a summary.
        #[arg(long)]
        json: bool,
        /// Control steps per world.
        #[arg(long, default_value_t = 2_000)]
        steps: usize,
        /// Worlds in the vectorized run.
        #[arg(long, default_value_t = 8)]
        worlds: usize,
        /// Threads for the vectorized run (0: all cores).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Write the benchmarked task as a MuJoCo model instead (MJCF: the same hand, object
        /// and motors, the first world's settled grasp as keyframe `grasp`) and exit; what
        /// scripts/bench-vs-mujoco.sh times MuJoCo on.
        #[arg(long, value_name = "FILE")]
        write_mjcf: Option<PathBuf>,
        /// MuJoCo's time step in the written model (s); default 1/240, the rate of the stored
        /// comparison (docs/results/sim-vs-mujoco/).
        #[arg(long, default_value_t = 1.0 / 240.0, requires = "write_mjcf")]
        mujoco_timestep_s: f32,
    },
    /// The policy on a Cortex-M4F (runtime/firmware-m4 under qemu-system-arm -icount), as
    /// f32, f16 and i8 weights: flash and RAM of the firmware (linked against the STM32F405's
    /// 1 MiB flash and 128 KiB SRAM), instructions per forward, and the largest action
    /// difference from tch's f32 forward on the host. Needs the thumbv7em-none-eabihf target
    /// and qemu-system-arm (scripts/test.sh installs both); builds three firmwares (minutes).
    Firmware {
        /// Print one JSON line per weight type instead of a table.
        #[arg(long)]
        json: bool,
        /// Policy file to measure (e.g. a run's policy.vgep); default: a seeded untrained
        /// 65-256-256-15 actor.
        #[arg(long, value_name = "FILE")]
        policy: Option<PathBuf>,
        /// Host observations compared with tch.
        #[arg(long, default_value_t = 10_000)]
        observations: usize,
        /// Seed of the untrained actor and of the observations.
        #[arg(long, default_value_t = 0)]
        seed: i64,
        /// The firmware's optimisation level: 3 (default, fastest) or s / z (smaller flash,
        /// more instructions).
        #[arg(long, value_parser = ["3", "2", "s", "z"])]
        opt_level: Option<String>,
    },
    /// Policy forward latency at batch 1 (65-256-256-15): the no_std runtime against tch.
    Runtime {
        /// Print one JSON line instead of a summary.
        #[arg(long)]
        json: bool,
        /// Timed forwards per implementation.
        #[arg(long, default_value_t = 20_000)]
        iters: usize,
    },
    /// The sub-skill controllers' cost per call, which the behaviour policy pays every step
    /// until the hard stop: the contact-force QP alone for 3, 4 and 5 contacts (clarabel),
    /// and IGM, CS and FG on the simulated cube (the adapter from the sim state included;
    /// median and 90th percentile over every step of the rollout).
    Controllers {
        /// Print one JSON line instead of a table.
        #[arg(long)]
        json: bool,
        /// Rollout episodes per controller (10 s each).
        #[arg(long, default_value_t = 2)]
        episodes: usize,
    },
}

/// MKL's vendor check, answered by `vge` so that MKL runs its AVX-512 kernels on AMD CPUs
/// that have them (`vge_trainer::mkl` says why and what it measured). build.rs exports it
/// from the executable, where it takes precedence over libtorch's own copy.
#[unsafe(no_mangle)]
#[allow(unsafe_code)]
pub extern "C" fn mkl_serv_intel_cpu_true() -> std::ffi::c_int {
    vge_trainer::mkl::intel_cpu_answer()
}

fn main() -> ExitCode {
    closed_output::end_quietly_when_closed();
    // Before libtorch allocates anything; a refusal only costs speed (heap.rs).
    if !vge_trainer::heap::keep_freed_memory() {
        eprintln!("vge: note: glibc heap settings not applied; updates may run slower");
    }
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Not eprintln!: with stderr closed the failure must still exit 1, not 0.
            let _ = writeln!(std::io::stderr(), "vge: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Export(args) => export(args),
        Command::Import(args) => import_onnx(args),
        Command::Inspect { file } => {
            let report = vge_export::inspect::report_file(&file)
                .with_context(|| format!("reading policy file {}", file.display()))?;
            print!("{report}");
            if !report.is_valid() {
                bail!("{} is not a valid policy file", file.display());
            }
            Ok(())
        }
        Command::Train { config, out, resume, seed, steps, overrides } => {
            train(config, out, resume, seed, steps, &overrides, &*stop_on_signal()?).map(|_| ())
        }
        Command::Sweep(args) => sweep(args),
        Command::Plot { runs, table1: Some(dir), .. } => {
            let written = vge_trainer::table1::write(&runs, &dir)?;
            print!("{}", vge_trainer::table1::to_markdown_with(&written.rows, &written.improvements));
            for d in &written.skipped {
                eprintln!("not in Table I (not the cube alone, or no controller): {}", d.display());
            }
            for f in &written.files {
                eprintln!("wrote {}", f.display());
            }
            Ok(())
        }
        Command::Plot { runs, out, success_csv, table1: None } => {
            let out = out.context("--out is required without --table1")?;
            let curves =
                runs.iter().map(|d| vge_trainer::plot::read_run(d)).collect::<Result<Vec<_>, _>>()?;
            let table = vge_trainer::plot::plot(&curves, &out)?;
            print!("{table}");
            eprintln!("wrote {}", out.display());
            if let Some(path) = vge_trainer::plot::plot_per_object(&curves, &out)? {
                eprintln!("wrote {} (success per object)", path.display());
            }
            if let Some(path) = success_csv {
                std::fs::write(&path, vge_trainer::plot::success_csv(&curves))
                    .with_context(|| format!("writing {}", path.display()))?;
                eprintln!("wrote {}", path.display());
            }
            Ok(())
        }
        Command::Score { runs, episodes, seed, force, threads } => {
            score(&runs, episodes, seed, force, threads)
        }
        Command::Compare { groups, out, pairs, seed, resamples } => {
            let bootstrap = vge_trainer::stats::Bootstrap { resamples, ..Default::default() };
            let pairs = (!pairs.is_empty()).then_some(pairs.as_slice());
            let written = vge_trainer::compare::write(&groups, pairs, &out, seed, &bootstrap)?;
            print!("{}", std::fs::read_to_string(out.join("compare.md")).unwrap_or_default());
            for f in &written.files {
                eprintln!("wrote {}", f.display());
            }
            Ok(())
        }
        Command::Eval(args) => eval(args),
        Command::Robustness(args) => robustness(args),
        Command::Controller(args) => controller(args),
        Command::Bench(bench) => run_bench(bench),
    }
}

fn eval(args: EvalArgs) -> anyhow::Result<()> {
    let EvalArgs {
        policy,
        episodes,
        episode: EpisodeArgs { object, seed, episode_s, grasp_noise_rad },
        objects,
        noise_q_rad,
        noise_normal_frac,
        noise_position_m,
        perturb_force_n,
        perturb_magnitude_n,
        plot,
        record,
        json,
        run,
        write,
    } = args;
    if let Some(dir) = run {
        return rescore_run(&dir, write, json);
    }
    if record.is_some() && !cfg!(feature = "rerun") {
        return Err(rerun_missing());
    }
    let policy = policy.context("--policy or --run is required")?;
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    anyhow::ensure!(episode_s.is_finite() && episode_s > 0.0, "--episode-s must be positive");
    for (name, v) in [
        ("noise-q-rad", noise_q_rad),
        ("noise-normal-frac", noise_normal_frac),
        ("noise-position-m", noise_position_m),
        ("perturb-force-n", perturb_force_n),
        ("perturb-magnitude-n", perturb_magnitude_n),
        ("grasp-noise-rad", grasp_noise_rad),
    ] {
        anyhow::ensure!(v.is_finite() && v >= 0.0, "--{name} must be >= 0, got {v}");
    }
    // The success test's env for an object, with the robustness test's disturbances set the
    // one way it sets them.
    let env_for = |object: ObjectShape| {
        let env = EnvConfig { object: vge_sim::ObjectConfig::of(object), ..EnvConfig::default() };
        let mut env = vge_trainer::eval::success_test_env(&env, episode_s, grasp_noise_rad);
        use vge_trainer::robustness::Axis;
        for (axis, level) in [
            (Axis::JointNoise, noise_q_rad),
            (Axis::NormalError, noise_normal_frac),
            (Axis::PositionError, noise_position_m),
            (Axis::Perturbation, perturb_force_n),
            (Axis::PerturbationMagnitude, perturb_magnitude_n),
        ] {
            axis.apply(&mut env, level);
        }
        env
    };
    if let Some(ObjectList(objects)) = objects {
        let envs: Vec<EnvConfig> = objects.iter().map(|&o| env_for(o)).collect();
        return eval_objects(&policy, &envs, episodes, seed, episode_s, plot.as_deref(), json);
    }
    let env = env_for(object);
    // Before the evaluation, so that a path that cannot be written fails at once.
    if let Some(rrd) = &record {
        record_episode(&policy, &env, seed, rrd)?;
    }
    let report = vge_trainer::eval::eval_policy_file(&policy, &env, episodes, seed)
        .with_context(|| format!("evaluating {}", policy.display()))?;
    if let Some(png) = &plot {
        draw_gait_diagram(&policy, &env, seed, png)?;
    }
    if json {
        println!("{}", report.to_json_line());
    } else {
        print_eval_report(&report, &policy, episode_s, object);
    }
    Ok(())
}

/// `vge eval --objects`: the success test on each of `envs` (one per object).
fn eval_objects(
    policy: &Path,
    envs: &[EnvConfig],
    episodes: usize,
    seed: u64,
    episode_s: f32,
    plot: Option<&Path>,
    json: bool,
) -> anyhow::Result<()> {
    let bytes = vge_trainer::eval::read_policy_file(policy)?;
    let report = vge_trainer::eval::eval_policy_bytes_per_object(&bytes, envs, episodes, seed)
        .with_context(|| format!("evaluating {}", policy.display()))?;
    if let Some(png) = plot {
        for env in envs {
            draw_gait_diagram(policy, env, seed, &per_object_path(png, env.object.shape))?;
        }
    }
    if json {
        /// The overall report with the per-object figures beside it.
        #[derive(serde::Serialize)]
        struct Line<'a> {
            #[serde(flatten)]
            overall: &'a vge_trainer::eval::EvalReport,
            per_object: vge_trainer::eval::PerObjectFigures,
        }
        let line = Line { overall: &report.overall, per_object: report.figures() };
        println!("{}", serde_json::to_string(&line).context("writing the report as JSON")?);
        return Ok(());
    }
    println!("{episodes} episodes of {episode_s} s per object, policy {}", policy.display());
    print_objects_table(&report.per_object, &report.overall);
    let verdict = match report.worst_object() {
        Some(_) if report.every_object_learned() => "learned on every object".to_owned(),
        Some((object, success)) => format!("not learned on every object (worst: the {object}, {success:.2})"),
        None => "no objects".to_owned(),
    };
    println!(
        "verdict: {verdict} (success >= {:.0}% of an object's episodes)",
        100.0 * vge_trainer::eval::LEARNED_SUCCESS_RATE
    );
    Ok(())
}

/// One row per object and the overall figures: success, drops, rotation, return, switches.
fn print_objects_table(
    per_object: &[(ObjectShape, vge_trainer::eval::EvalReport)],
    overall: &vge_trainer::eval::EvalReport,
) {
    println!(
        "  {:<16} {:>8} {:>7} {:>9} {:>9} {:>9} {:>9}",
        "object", "episodes", "success", "drops", "rot_rad", "return", "switches"
    );
    let row = |name: &str, r: &vge_trainer::eval::EvalReport| {
        println!(
            "  {name:<16} {:>8} {:>7.2} {:>9.2} {:>9.2} {:>9.2} {:>9.1}",
            r.episodes,
            r.success_rate,
            r.drop_rate,
            r.mean_rotation_rad,
            r.mean_return,
            r.mean_contact_switches
        );
    };
    for (object, r) in per_object {
        row(object.name(), r);
    }
    row("overall", overall);
}

/// `F.png` -> `F-<object>.png`: an object's file beside the others.
fn per_object_path(path: &Path, object: ObjectShape) -> PathBuf {
    let stem = path.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let name = match path.extension() {
        Some(ext) => format!("{stem}-{}.{}", object.name(), ext.to_string_lossy()),
        None => format!("{stem}-{}", object.name()),
    };
    path.with_file_name(name)
}

/// `vge score`: every run in turn, its episodes on `threads` threads, a progress line per
/// batch of episodes.
fn score(
    runs: &[PathBuf],
    episodes: usize,
    seed: u64,
    force: bool,
    threads: Option<u32>,
) -> anyhow::Result<()> {
    use vge_trainer::score::{ScoreOptions, ScoreOutcome, score_run};
    let options = ScoreOptions { episodes, seed, force };
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        pool = pool.num_threads(n as usize);
    }
    let pool = pool.build().context("starting the scoring threads")?;
    let mut failed = Vec::new();
    for (i, dir) in runs.iter().enumerate() {
        let started = std::time::Instant::now();
        let mut last_shown = std::time::Instant::now();
        let mut show = |p: &vge_trainer::score::ScoreProgress| {
            if p.done == p.total || last_shown.elapsed().as_secs_f64() >= 10.0 {
                eprintln!(
                    "vge score: run {}/{} {}: {} episodes of {} ({}), {:.0} s",
                    i + 1,
                    runs.len(),
                    p.dir.display(),
                    p.done,
                    p.total,
                    p.file,
                    started.elapsed().as_secs_f64()
                );
                last_shown = std::time::Instant::now();
            }
        };
        match pool.install(|| score_run(dir, &options, &mut show)) {
            Ok((outcome, notes)) => {
                for note in notes {
                    eprintln!("vge score: {}: {note}", dir.display());
                }
                let (verb, s) = match &outcome {
                    ScoreOutcome::Scored(s) => ("scored", s),
                    ScoreOutcome::Skipped(s) => ("already scored, skipped", s),
                };
                let selected =
                    s.selected.as_ref().map_or("-".to_owned(), |p| format!("{:.2}", p.success_rate));
                let last =
                    s.last_snapshots.as_ref().map_or("-".to_owned(), |p| format!("{:.2}", p.success_rate));
                println!(
                    "{}: {verb}: success on {} held-out episodes: selected {selected}, final {:.2}, last snapshots {last} ({:.0} s)",
                    dir.display(),
                    s.episodes,
                    s.final_policy.success_rate,
                    started.elapsed().as_secs_f64()
                );
            }
            Err(e) => {
                eprintln!("vge score: {e}");
                failed.push(dir.display().to_string());
            }
        }
    }
    if !failed.is_empty() {
        bail!("{} of {} runs not scored: {}", failed.len(), runs.len(), failed.join(", "));
    }
    Ok(())
}

/// `vge eval --run DIR [--write]`.
fn rescore_run(dir: &Path, write: bool, json: bool) -> anyhow::Result<()> {
    let r = vge_trainer::train::rescore_final_eval(dir, write)
        .with_context(|| format!("scoring the run in {}", dir.display()))?;
    if json {
        println!("{}", r.report.to_json_line());
        return Ok(());
    }
    let stored = |v: Option<f64>, unit: &str| v.map_or("-".to_owned(), |v| format!("{v:.3}{unit}"));
    println!("{}", dir.display());
    println!(
        "  success rate     {:.3} (stored: {})",
        r.report.success_rate,
        stored(r.stored_success_rate, "")
    );
    println!(
        "  rotation         {:.2} rad per episode (stored: {})",
        r.report.mean_rotation_rad,
        stored(r.stored_rotation_rad, " rad")
    );
    println!(
        "  drops {:.2}, contact switches {:.1} per episode, learned: {}",
        r.report.drop_rate,
        r.report.mean_contact_switches,
        r.report.learned()
    );
    if !r.per_object.is_empty() {
        print_objects_table(&r.per_object, &r.report);
    }
    if write {
        println!("  final-eval.json rewritten");
    }
    Ok(())
}

/// `vge eval --plot`: the gait diagram of the episode with seed `seed`.
fn draw_gait_diagram(policy: &Path, env: &EnvConfig, seed: u64, png: &Path) -> anyhow::Result<()> {
    let bytes = vge_trainer::eval::read_policy_file(policy)?;
    let trace = vge_trainer::eval::trace_policy_bytes(&bytes, env, seed)
        .with_context(|| format!("tracing {}", policy.display()))?;
    let o = &trace.outcome;
    let title = format!(
        "{}: the {}, episode seed {seed}, {:.1} rad in {:.0} s, {} contact switches{}",
        policy.display(),
        env.object.shape,
        o.rotation_rad,
        o.length as f32 * trace.dt_s,
        o.contact_switches,
        if o.terminated { ", dropped" } else { "" }
    );
    vge_trainer::gait_diagram::plot(&trace, &title, png)
        .with_context(|| format!("drawing {}", png.display()))?;
    eprintln!("vge eval: gait diagram of episode seed {seed} in {}", png.display());
    Ok(())
}

/// `vge eval --record`: the episode with seed `seed` written to the Rerun file `rrd`.
#[cfg(feature = "rerun")]
fn record_episode(policy: &Path, env: &EnvConfig, seed: u64, rrd: &Path) -> anyhow::Result<()> {
    let bytes = vge_trainer::eval::read_policy_file(policy)?;
    let outcome = vge_trainer::eval::record_policy_bytes(&bytes, env, seed, rrd)
        .with_context(|| format!("recording {} into {}", policy.display(), rrd.display()))?;
    eprintln!(
        "vge eval: episode seed {seed} ({} steps) recorded in {}; open it with `rerun {}`",
        outcome.length,
        rrd.display(),
        rrd.display()
    );
    Ok(())
}

/// Stand-in without the Rerun SDK: refuses.
#[cfg(not(feature = "rerun"))]
fn record_episode(_: &Path, _: &EnvConfig, _: u64, _: &Path) -> anyhow::Result<()> {
    Err(rerun_missing())
}

/// Why `--record` cannot run in this build.
fn rerun_missing() -> anyhow::Error {
    anyhow::anyhow!(
        "--record writes a Rerun recording, and this vge was built without the Rerun SDK: rebuild it with \
         `--features rerun` (cargo build --release -p vge-trainer --features rerun)"
    )
}

fn print_eval_report(
    report: &vge_trainer::eval::EvalReport,
    policy: &Path,
    episode_s: f32,
    object: ObjectShape,
) {
    println!("{} episodes of {episode_s} s on the {object}, policy {}", report.episodes, policy.display());
    println!("  mean return        {:.3}", report.mean_return);
    println!("  mean rotation      {:.3} rad about z", report.mean_rotation_rad);
    println!("  success rate       {:.2} (turned >= 2 pi without a drop)", report.success_rate);
    println!("  dropped            {:.2} of episodes", report.drop_rate);
    println!(
        "  contact switches   {:.1} per episode (a fingertip let go and touched again)",
        report.mean_contact_switches
    );
    println!("  mean contacts      {:.2}; mean length {:.0} steps", report.mean_contacts, report.mean_length);
    let verdict = if report.learned() { "learned" } else { "not learned" };
    println!(
        "  verdict            {verdict} (success >= {:.0}% of episodes)",
        100.0 * vge_trainer::eval::LEARNED_SUCCESS_RATE
    );
}

fn robustness(args: RobustnessArgs) -> anyhow::Result<()> {
    let RobustnessArgs {
        policy,
        episodes,
        levels,
        axes,
        episode: EpisodeArgs { object, seed, episode_s, grasp_noise_rad },
        out,
    } = args;
    use vge_trainer::robustness::{self, RobustnessOptions};
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    anyhow::ensure!(levels >= 2, "--levels must be at least 2 (0 and the paper's level)");
    anyhow::ensure!(episode_s.is_finite() && episode_s > 0.0, "--episode-s must be positive");
    anyhow::ensure!(grasp_noise_rad.is_finite() && grasp_noise_rad >= 0.0, "--grasp-noise-rad must be >= 0");
    let bytes = vge_trainer::eval::read_policy_file(&policy)?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let mut base = EnvConfig::default();
    base.object.shape = object;
    let axes = if axes.is_empty() { robustness::Axis::ALL.to_vec() } else { axes };
    for (i, axis) in axes.iter().enumerate() {
        anyhow::ensure!(!axes[..i].contains(axis), "--axes names {} twice", axis.name());
    }
    let total = 1 + axes.len() * (levels - 1);
    let options = RobustnessOptions { episodes, episode_s, grasp_noise_rad, seed, levels, axes };
    eprintln!("vge robustness: {total} evaluations of {episodes} episodes x {episode_s} s on the {object}");
    let report = robustness::run(&bytes, &base, &options, |r| {
        eprintln!(
            "  {:<22} {:>9.4}  return {:>8.3} ({:>5.1}% of clean)  success {:.2}  drops {:.2}",
            r.axis,
            r.level,
            r.mean_return,
            100.0 * r.return_fraction,
            r.success_rate,
            r.drop_rate
        );
    })
    .with_context(|| format!("evaluating {}", policy.display()))?;
    let csv = out.join("robustness.csv");
    std::fs::write(&csv, robustness::to_csv(&report))
        .with_context(|| format!("writing {}", csv.display()))?;
    let json = out.join("robustness.json");
    let text = serde_json::to_string_pretty(&report).context("serialising the report")?;
    std::fs::write(&json, text).with_context(|| format!("writing {}", json.display()))?;
    let png = out.join("robustness.png");
    robustness::plot(&report, &png).with_context(|| format!("drawing {}", png.display()))?;
    println!("wrote {}, {} and {}", csv.display(), json.display(), png.display());
    Ok(())
}

fn parse_robustness_axis(name: &str) -> Result<vge_trainer::robustness::Axis, String> {
    use vge_trainer::robustness::Axis;
    Axis::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = Axis::ALL.iter().map(|a| a.name()).collect();
        format!("unknown axis {name:?}; the axes are {}", names.join(", "))
    })
}

fn controller(args: ControllerArgs) -> anyhow::Result<()> {
    let ControllerArgs { kind, object, episodes, seed, episode_s, grasp_noise_rad, config, overrides, json } =
        args;
    let mut options = RolloutOptions::default();
    let (mut default_episode_s, mut default_grasp_noise_rad) = (10.0, 0.02);
    if let Some(path) = &config {
        let config = vge_trainer::config::load_config(path, &overrides)?;
        let env = vge_trainer::eval::without_training_disturbances(&config.env.env_config(0));
        options.cs = config.cs_config(&env);
        options.env = env;
        (default_episode_s, default_grasp_noise_rad) =
            (config.run.eval_episode_s, config.run.eval_grasp_noise_rad);
    }
    let episode_s = episode_s.unwrap_or(default_episode_s);
    let grasp_noise_rad = grasp_noise_rad.unwrap_or(default_grasp_noise_rad);
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    anyhow::ensure!(episode_s.is_finite() && episode_s > 0.0, "--episode-s must be positive");
    anyhow::ensure!(grasp_noise_rad.is_finite() && grasp_noise_rad >= 0.0, "--grasp-noise-rad must be >= 0");
    options.env = vge_trainer::eval::success_test_env(&options.env, episode_s, grasp_noise_rad);
    let summary = rollout::run_with(kind, object, episodes, seed, &options, |i, e| {
        if !json {
            eprintln!(
                "episode {}/{episodes}: return {:.3}, rotation {:.3} rad, {:.2} contacts{}",
                i + 1,
                e.episode_return,
                e.rotation_rad,
                e.mean_contacts,
                if e.dropped { ", ended early" } else { "" }
            );
        }
    })?;
    if json {
        println!("{}", summary.to_json_line());
    } else {
        println!("{summary}");
    }
    Ok(())
}

/// `vge bench controllers`.
fn bench_controllers(json: bool, episodes: usize) -> anyhow::Result<()> {
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    let mut doc = serde_json::Map::new();
    for k in 3..=5usize {
        let us = vge_trainer::controllers::qp::bench_contact_force_qp(k, 200)
            .with_context(|| format!("contact-force QP with {k} contacts"))?;
        doc.insert(format!("qp_{k}_contacts_us"), serde_json::json!(us));
        if !json {
            println!("contact-force QP, {k} contacts: {us:>8.1} us per call");
        }
    }
    let mut options = RolloutOptions::default();
    options.env.episode_length_steps = (10.0 * options.env.control_hz).round() as usize;
    for kind in ControllerKind::ALL {
        let s = rollout::run_with(kind, ObjectShape::Cube, episodes, 0, &options, |_, _| {})?;
        doc.insert(format!("{kind}_median_us"), serde_json::json!(s.controller_median_us));
        doc.insert(format!("{kind}_p90_us"), serde_json::json!(s.controller_p90_us));
        if !json {
            println!(
                "{:<3} on the cube: median {:>8.1} us, p90 {:>8.1} us per call",
                kind.name().to_uppercase(),
                s.controller_median_us,
                s.controller_p90_us
            );
        }
    }
    if json {
        println!("{}", serde_json::Value::Object(doc));
    }
    Ok(())
}

/// `vge export --weights`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Weights {
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

fn export(args: ExportArgs) -> anyhow::Result<()> {
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
    println!("wrote {} ({} bytes, {weights} weights, format version 2)", args.out.display(), bytes.len());
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

/// `vge import`: an ONNX MLP actor as a policy file for the default env's hand.
fn import_onnx(args: ImportArgs) -> anyhow::Result<()> {
    use vge_export::onnx::{ActionScale, ImportOptions, ImportTarget};
    let env = EnvConfig::default();
    let unknown = Provenance { vge_version: String::new(), config_hash: String::new(), seed: 0, steps: 0 };
    let hand = policy_export::hand_policy_meta(&env, unknown);
    let target = ImportTarget {
        obs_layout: hand.obs_layout,
        action_names: hand.action_names,
        control_hz: env.control_hz,
        max_layers: vge_runtime::policy::HAND_MAX_LAYERS,
        max_width: vge_runtime::policy::HAND_MAX_WIDTH,
    };
    let numbers = |path: &Option<PathBuf>| -> anyhow::Result<Option<Vec<f32>>> {
        let Some(path) = path else { return Ok(None) };
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let values = text
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
            .map(|t| t.parse::<f32>().with_context(|| format!("{}: `{t}` is not a number", path.display())))
            .collect::<anyhow::Result<Vec<f32>>>()?;
        Ok(Some(values))
    };
    let obs_dim = target.obs_dim();
    let (mean, std) = (numbers(&args.obs_mean)?, numbers(&args.obs_std)?);
    let given = mean.is_some() || std.is_some() || args.obs_clip.is_some();
    let obs_norm = given.then(|| vge_export::ObsNorm {
        mean: mean.unwrap_or(vec![0.0; obs_dim]),
        std: std.unwrap_or(vec![1.0; obs_dim]),
        clip: args.obs_clip,
    });
    let obs_layout = args
        .obs_layout
        .as_deref()
        .map(|text| {
            text.split(',')
                .map(|slice| {
                    let parsed = slice.trim().rsplit_once(':').and_then(|(name, range)| {
                        let (a, b) = range.split_once("..")?;
                        Some(vge_export::ObsSlice::new(name, a.parse().ok()?..b.parse().ok()?))
                    });
                    parsed.with_context(|| format!("--obs-layout: `{slice}` is not name:start..end"))
                })
                .collect::<anyhow::Result<Vec<_>>>()
        })
        .transpose()?;
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

/// The policy file of a saved (`--actor`) or fresh (`--init`) actor.
fn export_actor(args: &ExportArgs, weights: vge_export::WeightType) -> anyhow::Result<Vec<u8>> {
    anyhow::ensure!(args.hidden.iter().all(|&h| h > 0), "--hidden widths must be positive");
    let env = EnvConfig::default();
    let mut vs = nn::VarStore::new(Device::Cpu);
    let spec = NetSpec {
        obs_dim: vge_sim::OBS_DIM as i64,
        act_dim: vge_sim::NUM_JOINTS as i64,
        hidden: args.hidden.iter().map(|&h| h as i64).collect(),
    };
    tch::manual_seed(args.seed as i64);
    let _actor = GaussianActor::new(&vs.root(), &spec, &[env.max_action_rad; vge_sim::NUM_JOINTS]);
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
    let bytes = policy_export::export_hand_actor(&vs, &args.hidden, &env, provenance)?;
    if weights == vge_export::WeightType::F32 {
        return Ok(bytes);
    }
    Ok(vge_export::PolicyFile::from_bytes(&bytes)?.encode(weights)?)
}

fn run_bench(bench: Bench) -> anyhow::Result<()> {
    match bench {
        Bench::Update { json, updates, batch, seed, algorithm, layer_norm, matmul } => {
            anyhow::ensure!(updates > 0, "--updates must be at least 1");
            anyhow::ensure!(batch > 0, "--batch must be at least 1");
            let mut config = vge_trainer::sac::SacConfig::hand_default(0.05);
            config.entropy = vge_trainer::sac::EntropyCoef::Fixed(0.0);
            config.critic_layer_norm = layer_norm;
            if matmul == "bf16" {
                config.matmul = vge_trainer::nets::MatmulPrecision::Bf16;
            }
            if algorithm == "td3" {
                config.algorithm = vge_trainer::sac::Algorithm::TD3;
            }
            let r = bench_update::run(config, batch, 20, updates, seed)?;
            if json {
                let line = serde_json::json!({
                    "bench": "update",
                    "algorithm": algorithm,
                    "layer_norm": layer_norm,
                    "matmul": matmul,
                    "updates_per_s": r.updates_per_s,
                    "gflops": r.gflops,
                    "matmul_gflops": r.matmul_gflops,
                    "ratio_to_matmul": r.gflops / r.matmul_gflops,
                    "batch": r.batch,
                    "updates": r.updates,
                    "threads": r.threads,
                    "mkl_code_branch": vge_trainer::mkl::code_branch(),
                });
                println!("{line}");
            } else {
                println!(
                    "{} update, batch {}, {} threads, {} updates, critic layer norm {layer_norm}, {matmul} matmuls",
                    algorithm.to_uppercase(),
                    r.batch,
                    r.threads,
                    r.updates
                );
                println!("  updates/s        {:>8.1}", r.updates_per_s);
                println!("  achieved GFLOP/s {:>8.2}", r.gflops);
                println!("  matmul GFLOP/s   {:>8.2}  (1024^3 f32 matmul, same run)", r.matmul_gflops);
                println!(
                    "  MKL code branch  {:>8}  (see VGE_MKL_VENDOR_CHECK in vge_trainer::mkl)",
                    vge_trainer::mkl::code_branch().unwrap_or("no MKL")
                );
            }
        }
        Bench::Sim { write_mjcf: Some(path), mujoco_timestep_s, .. } => {
            let xml = vge_sim::mjcf::settled_grasp_mjcf(&EnvConfig::default(), 0, mujoco_timestep_s)?;
            std::fs::write(&path, xml).with_context(|| format!("writing {}", path.display()))?;
            eprintln!("wrote {} (MuJoCo, time step {mujoco_timestep_s} s)", path.display());
        }
        Bench::Sim { json, steps, worlds, threads, write_mjcf: None, .. } => {
            anyhow::ensure!(steps > 0 && worlds > 0, "--steps and --worlds must be at least 1");
            let settings = vge_sim::bench::BenchSettings {
                env: EnvConfig::default(),
                steps_per_world: steps,
                num_worlds: worlds,
                threads,
            };
            if !json {
                eprintln!("stepping 1 world then {worlds} worlds, {steps} control steps each...");
            }
            let r = vge_sim::bench::run(&settings)?;
            if json {
                println!("{}", r.to_json_line());
            } else {
                println!(
                    "control steps/s, one world, one thread: {:>8.0}  ({:.0} simulated s per s)",
                    r.control_steps_per_s_single,
                    r.sim_seconds_per_s()
                );
                println!(
                    "control steps/s, {worlds} worlds, {} threads: {:>8.0}  ({:.2}x)",
                    r.threads_used,
                    r.control_steps_per_s_vec,
                    r.speedup()
                );
            }
        }
        Bench::Controllers { json, episodes } => bench_controllers(json, episodes)?,
        Bench::Firmware { json, policy, observations, seed, opt_level } => {
            bench_firmware(json, policy, observations, seed, opt_level.as_deref())?
        }
        Bench::Runtime { json, iters } => {
            anyhow::ensure!(iters > 0, "--iters must be at least 1");
            let config = vge_export::bench::BenchConfig { iters, ..Default::default() };
            let r = vge_export::bench::run(&config)?;
            if json {
                println!("{}", r.to_json_line());
            } else {
                println!("batch-1 forward, {:?}, {} iterations", r.dims, r.iters);
                println!("  vge-runtime  median {:>8.0} ns", r.runtime_ns);
                println!("  tch          median {:>8.0} ns  ({} threads)", r.tch_ns, r.tch_threads);
                println!("  speedup {:.1}x, max |diff| {:.2e}", r.tch_ns / r.runtime_ns, r.max_abs_diff);
            }
        }
    }
    Ok(())
}

fn bench_firmware(
    json: bool,
    policy: Option<PathBuf>,
    observations: usize,
    seed: i64,
    opt_level: Option<&str>,
) -> anyhow::Result<()> {
    anyhow::ensure!(observations > 0, "--observations must be at least 1");
    let file = match &policy {
        Some(path) => vge_export::PolicyFile::read(path)
            .with_context(|| format!("reading policy file {}", path.display()))?,
        None => vge_export::firmware_bench::seeded_policy(seed)?,
    };
    let target_dir = std::env::temp_dir().join("vge-bench-firmware");
    let rows = vge_export::firmware_bench::run(&file, &target_dir, opt_level, observations, seed, |msg| {
        eprintln!("{msg}")
    })?;
    if json {
        for r in &rows {
            println!("{}", r.to_json_line());
        }
        return Ok(());
    }
    println!(
        "Cortex-M4F (qemu mps2-an386, STM32F405 memory sizes), opt-level {}, policy {}",
        opt_level.unwrap_or("3"),
        match &policy {
            Some(p) => p.display().to_string(),
            None => format!("untrained, seed {seed}"),
        }
    );
    println!(
        "weights  file B   flash B   RAM B  instructions  ms@168MHz  max|diff| vs tch ({observations} obs)"
    );
    for r in &rows {
        println!(
            "{:<6} {:>8} {:>9} {:>7} {:>13.0} {:>10.2}  {:.2e}",
            r.weights.name(),
            r.file_bytes,
            r.flash_bytes,
            r.ram_bytes,
            r.instructions_per_forward,
            r.instructions_per_forward / vge_export::firmware_bench::CLOCK_HZ * 1e3,
            r.max_abs_diff
        );
    }
    println!("(ms at one instruction per cycle: an estimate; RAM = static + stack peak)");
    Ok(())
}

fn sweep(args: SweepArgs) -> anyhow::Result<()> {
    let sweep = vge_trainer::sweep::Sweep {
        config: args.config.clone(),
        seeds: args.seeds.clone(),
        out: args.out.clone(),
        steps: args.steps,
        overrides: args.overrides.clone(),
    };
    if args.slurm {
        return sweep_slurm(&args, &sweep);
    }
    match args.jobs {
        Some(jobs) => sweep_parallel(&args, &sweep, jobs),
        None => sweep_in_process(&sweep),
    }
}

/// The seeds one after the other in this process.
fn sweep_in_process(sweep: &vge_trainer::sweep::Sweep) -> anyhow::Result<()> {
    use vge_trainer::sweep::{SeedState, seed_state};
    let stop = stop_on_signal()?;
    for seed in sweep.seeds.clone() {
        let dir = sweep.seed_dir(seed);
        let (steps, overrides) = (sweep.steps, &sweep.overrides);
        let stopped = match seed_state(&dir) {
            SeedState::Done => {
                eprintln!("seed {seed}: done already ({})", dir.display());
                continue;
            }
            SeedState::Interrupted => train(None, None, Some(dir), Some(seed), steps, overrides, &stop)?,
            SeedState::New => {
                train(Some(sweep.config.clone()), Some(dir), None, Some(seed), steps, overrides, &stop)?
            }
        };
        if stopped {
            break;
        }
    }
    Ok(())
}

/// The seeds as child processes, `jobs` at a time.
fn sweep_parallel(args: &SweepArgs, sweep: &vge_trainer::sweep::Sweep, jobs: u32) -> anyhow::Result<()> {
    use vge_trainer::sweep::{Outcome, Parallel, run_parallel, summary_line};
    let exe = std::env::current_exe().context("finding the vge binary to start the jobs")?;
    // Checked here so that a typo fails once, not once per seed in each log.
    vge_trainer::config::load_config(&sweep.config, &sweep.overrides)?;
    let opts = Parallel {
        jobs: jobs as usize,
        threads_per_job: args.threads_per_job as usize,
        report_every: std::time::Duration::from_secs(args.report_every_s.max(1)),
    };
    let stop = stop_on_signal()?;
    eprintln!(
        "sweep: seeds {}..{}, {jobs} at a time, logs in {}/seed-N/train.log",
        sweep.seeds.start,
        sweep.seeds.end,
        sweep.out.display()
    );
    let outcomes = run_parallel(&exe, sweep, &opts, &stop, &mut |line| eprintln!("{line}"));
    for (seed, outcome) in &outcomes {
        println!("{}", summary_line(sweep, *seed, outcome));
    }
    let failed: Vec<String> = outcomes
        .iter()
        .filter_map(|(seed, o)| match o {
            Outcome::Failed { log, .. } => Some(format!("seed {seed} (log {})", log.display())),
            _ => None,
        })
        .collect();
    if !failed.is_empty() {
        bail!("{} of {} seeds failed: {}", failed.len(), outcomes.len(), failed.join(", "));
    }
    Ok(())
}

/// Writes DIR/sweep.sbatch and, unless --dry-run, submits it.
fn sweep_slurm(args: &SweepArgs, sweep: &vge_trainer::sweep::Sweep) -> anyhow::Result<()> {
    use vge_trainer::sweep::{Slurm, array_spec, on_path, submit, write_sbatch};
    // Before any file is written: a login node without Slurm is the likely mistake.
    if !args.dry_run && !on_path("sbatch") {
        bail!(vge_trainer::sweep::SweepError::NoSbatch);
    }
    vge_trainer::config::load_config(&sweep.config, &sweep.overrides)?;
    let slurm = Slurm {
        partition: args.partition.clone(),
        time: args.time.clone(),
        cpus_per_task: args.cpus_per_task as usize,
    };
    let exe = std::env::current_exe()
        .and_then(|p| p.canonicalize())
        .context("finding the vge binary the tasks run")?;
    let (script, seeds) = write_sbatch(&exe, sweep, &slurm)?;
    if seeds.is_empty() {
        println!("every seed is done already (DIR/seed-N/policy.vgep): nothing to submit");
        return Ok(());
    }
    let dir = script.parent().unwrap_or(&sweep.out).display().to_string();
    if args.dry_run {
        println!("wrote {} (seeds {}); submit it with: sbatch {0}", script.display(), array_spec(&seeds));
        return Ok(());
    }
    let job = submit(&script)?;
    println!("submitted array job {job}: seeds {} from {}", array_spec(&seeds), script.display());
    println!("follow it:    squeue -j {job}    (task id = seed)");
    println!("logs:         {dir}/seed-N/train.log");
    println!("curves:       vge plot {dir}/seed-* --out {dir}/curves.png");
    println!("interrupted?  the same `vge sweep --slurm` again resumes unfinished seeds");
    Ok(())
}

/// The run `vge train` works on: a new one (`--config`, `--out`, refused where a run already
/// is) or the one in `--resume DIR`, with the overrides applied.
fn train_target(
    resume: Option<PathBuf>,
    config: Option<PathBuf>,
    out: Option<PathBuf>,
    overrides: &[String],
) -> anyhow::Result<(vge_trainer::config::Config, PathBuf, bool)> {
    use vge_trainer::config as cfg;
    Ok(match (resume, config, out) {
        (Some(dir), _, _) => {
            let text = std::fs::read_to_string(dir.join("config.toml"))
                .with_context(|| format!("{} is not a vge run directory (no config.toml)", dir.display()))?;
            let origin = dir.join("config.toml").display().to_string();
            cfg::check_resumable(&text, &origin)?;
            let config = cfg::parse_with_overrides(&text, &origin, overrides)?;
            config.validate()?;
            (config, dir, true)
        }
        // A folder holding a run, or being written, is refused by `train` (naming what it found).
        (None, Some(path), Some(out)) => (cfg::load_config(&path, overrides)?, out, false),
        _ => bail!("give --config and --out, or --resume DIR"),
    })
}

fn progress_bar(total_steps: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(total_steps);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} steps ({eta} left) {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar
}

fn train(
    config: Option<PathBuf>,
    out: Option<PathBuf>,
    resume: Option<PathBuf>,
    seed: Option<u64>,
    steps: Option<u64>,
    overrides: &[String],
    stop: &std::sync::atomic::AtomicBool,
) -> anyhow::Result<bool> {
    use vge_trainer::train as tr;
    let mut overrides = overrides.to_vec();
    if let Some(seed) = seed {
        overrides.push(format!("seed={seed}"));
    }
    if let Some(steps) = steps {
        overrides.push(format!("total_steps={steps}"));
    }
    let (config, out_dir, resuming) = train_target(resume, config, out, &overrides)?;
    let bar = progress_bar(config.total_steps);
    let resumed_from = if resuming { vge_trainer::sweep::checkpoint_step(&out_dir) } else { None };
    // The controller only where the method queries it (rl runs ignore `controller`).
    let controller = config.controller.filter(|_| config.method.queries_controller());
    eprintln!(
        "training {} ({}{}, {}, seed {}){} into {}{}",
        config.name,
        config.method.name(),
        controller.map_or(String::new(), |c| format!(" + {}", c.name())),
        config.algorithm.name(),
        config.seed,
        config.init_from_dir().map_or(String::new(), |d| format!(" from the networks of {}", d.display())),
        out_dir.display(),
        match (resuming, resumed_from) {
            (true, Some(step)) => format!(", resuming from step {step}"),
            (true, None) => ", resuming".to_owned(),
            _ => String::new(),
        }
    );
    let summary = tr::train(&config, &out_dir, resuming, stop, &mut |p: &tr::Progress| {
        bar.set_position(p.step);
        bar.set_message(format!(
            "{:.0} steps/s, return {:.2}, rotation {:.2} rad, controller {:.0}%, {} episodes",
            p.steps_per_s,
            p.mean_return,
            p.mean_rotation_rad,
            100.0 * p.controller_share,
            p.episodes
        ));
    })?;
    bar.finish();
    println!("time this session: {}", summary.times);
    if summary.stopped {
        println!(
            "stopped at step {}: checkpoint saved; continue with `vge train --resume {}`",
            summary.steps,
            out_dir.display()
        );
    } else if let Some(policy) = summary.policy {
        println!(
            "done: {} steps, {} updates; policy written to {}",
            summary.steps,
            summary.updates,
            policy.display()
        );
    }
    Ok(summary.stopped)
}

/// A flag raised by Ctrl-C or SIGTERM: training saves a checkpoint and returns.
fn stop_on_signal() -> anyhow::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, std::sync::atomic::Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    Ok(stop)
}
