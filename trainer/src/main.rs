//! `vge`: train, evaluate, export and inspect finger-gaiting policies.

use std::path::PathBuf;
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
struct Cli {
    #[command(subcommand)]
    command: Command,
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
    Train {
        /// Experiment config (TOML), e.g. configs/cube-fg-vge.toml. Not needed with --resume.
        #[arg(long, required_unless_present = "resume")]
        config: Option<PathBuf>,
        /// Output directory of the run.
        #[arg(long, required_unless_present = "resume")]
        out: Option<PathBuf>,
        /// Continue the run in this directory from its last checkpoint (its config.toml).
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
    /// Train one config for several seeds, one run directory each (DIR/seed-N), one after
    /// the other; a finished seed is skipped, an interrupted one resumed.
    Sweep {
        #[arg(long)]
        config: PathBuf,
        /// Seeds as a range `A..B` (B excluded), e.g. `0..10`.
        #[arg(long, value_parser = parse_seed_range)]
        seeds: std::ops::Range<u64>,
        #[arg(long)]
        out: PathBuf,
        #[arg(long)]
        steps: Option<u64>,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
    },
    /// Plot training curves of run directories (mean and min-max over runs of the same
    /// experiment) into a PNG, and print a markdown table of final success rates.
    Plot {
        /// Run directories (each with config.toml and metrics.csv).
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        #[arg(long)]
        out: PathBuf,
    },
    /// Evaluate a policy file on vge-runtime in the simulator (the success test): mean
    /// return, rotation, contact switches, drops and success rate.
    ///
    /// The defaults are the success test that training's evaluations and `vge plot` use:
    /// 20 episodes of 30 s from initial grasps randomised by +-0.02 rad; an episode succeeds
    /// when the object turns >= 2 pi about z without a drop, and a seed has learned when its
    /// policy succeeds in >= 50% of them. Episodes run side by side on all cores.
    Eval {
        #[arg(long)]
        policy: PathBuf,
        #[arg(long, default_value_t = vge_trainer::eval::SUCCESS_TEST_EPISODES)]
        episodes: usize,
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
        #[arg(long)]
        json: bool,
    },
    /// Write a policy file (postcard, see docs/policy-format.md) from an actor.
    ///
    /// The file carries the actor's layers, the hand's observation and action layouts, the
    /// action scaling and control rate of the default env, and provenance. Load it with
    /// `vge-runtime` (no_std) or run it with `vge-bridge`.
    Export(ExportArgs),
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
    Controller {
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
        /// Episode length in seconds of sim time.
        #[arg(long, default_value_t = 10.0)]
        episode_s: f32,
        /// Randomise the initial grasp per episode (pose noise, rad); 0 starts every
        /// episode from the same grasp.
        #[arg(long, default_value_t = 0.02)]
        grasp_noise_rad: f32,
        /// Print one JSON line instead of a summary.
        #[arg(long)]
        json: bool,
    },
    /// Measure vge's hot paths on this machine.
    #[command(subcommand)]
    Bench(Bench),
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

fn parse_controller_kind(s: &str) -> Result<ControllerKind, String> {
    s.parse().map_err(|_| format!("unknown controller `{s}` (one of: igm, cs, fg)"))
}

#[derive(Debug, Args)]
struct ExportArgs {
    /// Actor variables saved by tch (`VarStore::save`, names `actor.l{i}`, `actor.mean`, ...).
    #[arg(long, conflicts_with = "init", required_unless_present = "init")]
    actor: Option<PathBuf>,
    /// Export a freshly initialised (untrained) actor instead, e.g. to test a deployment path.
    #[arg(long)]
    init: bool,
    /// Seed of the initialisation (--init) and recorded as provenance.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Hidden layer widths of the actor.
    #[arg(long, value_delimiter = ',', default_value = "256,256")]
    hidden: Vec<usize>,
    /// Environment steps the actor was trained for (provenance).
    #[arg(long, default_value_t = 0)]
    steps: u64,
    /// Where to write the policy file.
    #[arg(long)]
    out: PathBuf,
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
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vge: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Export(args) => export(args),
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
        Command::Sweep { config, seeds, out, steps, overrides } => {
            let stop = stop_on_signal()?;
            for seed in seeds.clone() {
                let dir = out.join(format!("seed-{seed}"));
                if dir.join("policy.vgep").exists() {
                    eprintln!("seed {seed}: done already ({})", dir.display());
                    continue;
                }
                let stopped = if dir.join("checkpoint").exists() {
                    train(None, None, Some(dir), Some(seed), steps, &overrides, &stop)?
                } else {
                    train(Some(config.clone()), Some(dir), None, Some(seed), steps, &overrides, &stop)?
                };
                if stopped {
                    break;
                }
            }
            Ok(())
        }
        Command::Plot { runs, out } => {
            let curves =
                runs.iter().map(|d| vge_trainer::plot::read_run(d)).collect::<Result<Vec<_>, _>>()?;
            let table = vge_trainer::plot::plot(&curves, &out)?;
            print!("{table}");
            eprintln!("wrote {}", out.display());
            Ok(())
        }
        Command::Eval {
            policy,
            episodes,
            object,
            seed,
            episode_s,
            grasp_noise_rad,
            noise_q_rad,
            noise_normal_frac,
            noise_position_m,
            perturb_force_n,
            json,
        } => {
            anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
            anyhow::ensure!(episode_s.is_finite() && episode_s > 0.0, "--episode-s must be positive");
            for (name, v) in [
                ("noise-q-rad", noise_q_rad),
                ("noise-normal-frac", noise_normal_frac),
                ("noise-position-m", noise_position_m),
                ("perturb-force-n", perturb_force_n),
                ("grasp-noise-rad", grasp_noise_rad),
            ] {
                anyhow::ensure!(v.is_finite() && v >= 0.0, "--{name} must be >= 0, got {v}");
            }
            let mut env = EnvConfig::default();
            env.object.shape = object;
            let mut env = vge_trainer::eval::success_test_env(&env, episode_s, grasp_noise_rad);
            env.noise.q_std_rad = noise_q_rad;
            env.noise.normal_std_frac = noise_normal_frac;
            env.noise.position_std_m = noise_position_m;
            env.perturbation.force_std_n = perturb_force_n;
            if perturb_force_n > 0.0 && env.perturbation.change_probability == 0.0 {
                env.perturbation.change_probability = 0.1;
            }
            let report = vge_trainer::eval::eval_policy_file(&policy, &env, episodes, seed)
                .with_context(|| format!("evaluating {}", policy.display()))?;
            if json {
                println!("{}", report.to_json_line());
            } else {
                println!(
                    "{} episodes of {episode_s} s on the {object}, policy {}",
                    report.episodes,
                    policy.display()
                );
                println!("  mean return        {:.3}", report.mean_return);
                println!("  mean rotation      {:.3} rad about z", report.mean_rotation_rad);
                println!("  success rate       {:.2} (turned >= 2 pi without a drop)", report.success_rate);
                println!("  dropped            {:.2} of episodes", report.drop_rate);
                println!("  contact switches   {:.1} per episode (a fingertip let go and touched again)", report.mean_contact_switches);
                println!(
                    "  mean contacts      {:.2}; mean length {:.0} steps",
                    report.mean_contacts, report.mean_length
                );
                let verdict = if report.learned() { "learned" } else { "not learned" };
                println!(
                    "  verdict            {verdict} (success >= {:.0}% of episodes)",
                    100.0 * vge_trainer::eval::LEARNED_SUCCESS_RATE
                );
            }
            Ok(())
        }
        Command::Controller { kind, object, episodes, seed, episode_s, grasp_noise_rad, json } => {
            anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
            anyhow::ensure!(episode_s.is_finite() && episode_s > 0.0, "--episode-s must be positive");
            anyhow::ensure!(
                grasp_noise_rad.is_finite() && grasp_noise_rad >= 0.0,
                "--grasp-noise-rad must be >= 0"
            );
            let mut options = RolloutOptions::default();
            options.env.episode_length_steps = (episode_s * options.env.control_hz).round().max(1.0) as usize;
            options.env.grasp.pose_noise_rad = grasp_noise_rad;
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
        Command::Bench(bench) => run_bench(bench),
    }
}

fn export(args: ExportArgs) -> anyhow::Result<()> {
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
    std::fs::write(&args.out, &bytes).with_context(|| format!("writing {}", args.out.display()))?;
    println!("wrote {} ({} bytes)", args.out.display(), bytes.len());
    Ok(())
}

fn run_bench(bench: Bench) -> anyhow::Result<()> {
    match bench {
        Bench::Update { json, updates, batch, seed, algorithm, layer_norm } => {
            anyhow::ensure!(updates > 0, "--updates must be at least 1");
            anyhow::ensure!(batch > 0, "--batch must be at least 1");
            let mut config = vge_trainer::sac::SacConfig::hand_default(0.05);
            config.entropy = vge_trainer::sac::EntropyCoef::Fixed(0.0);
            config.critic_layer_norm = layer_norm;
            if algorithm == "td3" {
                config.algorithm = vge_trainer::sac::Algorithm::TD3;
            }
            let r = bench_update::run(config, batch, 20, updates, seed)?;
            if json {
                println!(
                    "{{\"bench\":\"update\",\"algorithm\":\"{algorithm}\",\"layer_norm\":{layer_norm},\"updates_per_s\":{:.1},\"gflops\":{:.2},\"matmul_gflops\":{:.2},\"ratio_to_matmul\":{:.3},\"batch\":{},\"updates\":{},\"threads\":{}}}",
                    r.updates_per_s,
                    r.gflops,
                    r.matmul_gflops,
                    r.gflops / r.matmul_gflops,
                    r.batch,
                    r.updates,
                    r.threads
                );
            } else {
                println!(
                    "{} update, batch {}, {} threads, {} updates, critic layer norm {layer_norm}",
                    algorithm.to_uppercase(),
                    r.batch,
                    r.threads,
                    r.updates
                );
                println!("  updates/s        {:>8.1}", r.updates_per_s);
                println!("  achieved GFLOP/s {:>8.2}", r.gflops);
                println!("  matmul GFLOP/s   {:>8.2}  (1024^3 f32 matmul, same run)", r.matmul_gflops);
            }
        }
        Bench::Sim { json, steps, worlds, threads } => {
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
                println!("control steps/s, one world, one thread: {:>8.0}", r.control_steps_per_s_single);
                println!(
                    "control steps/s, {worlds} worlds, {} threads: {:>8.0}  ({:.2}x)",
                    r.threads_used,
                    r.control_steps_per_s_vec,
                    r.speedup()
                );
            }
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

fn train(
    config: Option<PathBuf>,
    out: Option<PathBuf>,
    resume: Option<PathBuf>,
    seed: Option<u64>,
    steps: Option<u64>,
    overrides: &[String],
    stop: &std::sync::atomic::AtomicBool,
) -> anyhow::Result<bool> {
    use vge_trainer::{config as cfg, train as tr};
    let mut overrides = overrides.to_vec();
    if let Some(seed) = seed {
        overrides.push(format!("seed={seed}"));
    }
    if let Some(steps) = steps {
        overrides.push(format!("total_steps={steps}"));
    }
    let (config, out_dir, resuming) = match (resume, config, out) {
        (Some(dir), _, _) => {
            let text = std::fs::read_to_string(dir.join("config.toml"))
                .with_context(|| format!("{} is not a vge run directory (no config.toml)", dir.display()))?;
            let config =
                cfg::parse_with_overrides(&text, &dir.join("config.toml").display().to_string(), &overrides)?;
            config.validate()?;
            (config, dir, true)
        }
        (None, Some(path), Some(out)) => {
            if out.join("checkpoint").exists() {
                bail!(
                    "{} already holds a run: continue it with --resume {0} or choose another --out",
                    out.display()
                );
            }
            (cfg::load_config(&path, &overrides)?, out, false)
        }
        _ => bail!("give --config and --out, or --resume DIR"),
    };
    let bar = indicatif::ProgressBar::new(config.total_steps);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} steps ({eta} left) {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    eprintln!(
        "training {} ({:?} + {:?}, {:?}, seed {}) into {}{}",
        config.name,
        config.method,
        config.controller,
        config.algorithm,
        config.seed,
        out_dir.display(),
        if resuming { ", resuming" } else { "" }
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
