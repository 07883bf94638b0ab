//! `vge bench`: vge's hot paths on this machine (updates, training, simulator, firmware,
//! runtime, controllers, idle cores).

use std::path::PathBuf;

use anyhow::Context;
use clap::Subcommand;
use vge_controllers::rollout::{self, ControllerKind, RolloutOptions};
use vge_sim::{EnvConfig, ObjectShape};

#[derive(Debug, Subcommand)]
pub enum Bench {
    /// Full learner updates per second (SAC, or TD3 with --algorithm td3): batch 256, the
    /// default config's actor and twin critics (128 x 128; --hidden for others) on its hand's
    /// observation and joints (vge15: 65 and 15), SAC's alpha 0, critics with layer norm
    /// (the training defaults); also the achieved GFLOP/s and this CPU's matmul GFLOP/s for
    /// comparison. Threads: libtorch's default; set them with `OMP_NUM_THREADS=N` (training
    /// uses `sac.threads`).
    Update {
        /// Print one JSON line instead of a table.
        #[arg(long)]
        json: bool,
        /// Hidden widths of the actor and both critics, e.g. `256,256` (`sac.hidden`; default:
        /// the default config's).
        #[arg(long, value_delimiter = ',')]
        hidden: Option<Vec<i64>>,
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
    /// Training speed: env steps per second after the warm-up, and where the time goes.
    ///
    /// Trains the default config (or --config, with --set) for --steps env steps after its
    /// warm-up at each of --threads libtorch threads (`sac.threads`, the most a run uses: it
    /// fits its threads to the cores other processes leave idle unless
    /// `VGE_FIXED_THREADS=1`), and prints env steps/s with the split of that time: sim
    /// (physics, replay pushes, resets), controllers (the behaviour policy's controller calls
    /// and Q queries), actor (the behaviour actions), update (minibatch sampling and gradient
    /// updates) and other. No periodic evaluation, checkpoint or score; the run folder is a
    /// scratch one, removed afterwards.
    ///
    /// --beside-busy-core measures each configuration a second time beside a process that
    /// keeps one core busy (another job on a shared machine) and prints every rate as a
    /// fraction of the one-thread rate without it. --fixed-threads both measures fixed and
    /// adapting threads. With two threads or more the envs step on a core of their own beside
    /// the updates or on every core between them, whichever the run timed faster (the same
    /// run bit for bit either way); --overlap yes,no,fastest measures each schedule. Rates on a
    /// loaded machine swing: compare within one run (--rounds alternates the configurations).
    Train {
        /// Print one JSON line per measured run instead of a table.
        #[arg(long)]
        json: bool,
        /// Experiment config (TOML); default: the shipped protocol (`Config::default()`).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override a config field, e.g. `--set sac.warmup=2000` (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
        /// Env steps measured after the warm-up (`sac.warmup`).
        #[arg(long, default_value_t = 20_000)]
        steps: u64,
        /// libtorch thread counts to measure, in this order (comma-separated).
        #[arg(long, value_delimiter = ',', default_value = "1,2")]
        threads: Vec<i32>,
        /// Each configuration again beside a process that keeps one core busy (`sh` looping).
        #[arg(long)]
        beside_busy_core: bool,
        /// Rounds over all configurations, alternating them.
        #[arg(long, default_value_t = 1)]
        rounds: usize,
        /// Keep libtorch's threads at --threads instead of fitting them to the idle cores:
        /// no, yes, or both (each configuration measured both ways).
        #[arg(long, default_value = "no", value_parser = ["no", "yes", "both"])]
        fixed_threads: String,
        /// Where the envs step when two cores or more are used, one or more of: fastest (the
        /// schedule the run timed faster, training's default), yes (on a core of their own
        /// beside the updates), no (on every core between the updates; `VGE_SERIAL_LOOP=1`).
        #[arg(long, value_delimiter = ',', default_value = "fastest", value_parser = ["fastest", "yes", "no"])]
        overlap: Vec<String>,
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
        /// The hand: a shipped hand (vge15, allegro) or an MJCF file, on the cube its file
        /// is sized for.
        #[arg(long, default_value = "vge15")]
        hand: String,
        /// Write the benchmarked task as a MuJoCo model instead (MJCF: the same hand, object
        /// and motors, the first world's settled grasp as keyframe `grasp`) and exit; what
        /// scripts/bench-vs-mujoco.sh times MuJoCo on.
        #[arg(long, value_name = "FILE")]
        write_mjcf: Option<PathBuf>,
        /// MuJoCo's time step in the written model (s); default 1/240, the rate of the stored
        /// comparison (docs/results/sim-vs-mujoco/).
        #[arg(long, default_value_t = 1.0 / 240.0, requires = "write_mjcf")]
        mujoco_timestep_s: f32,
        /// With --write-mjcf: also write the first world's actions for --steps control steps
        /// (rows of one little-endian f32 per joint), the table scripts/bench_mujoco.py replays.
        #[arg(long, value_name = "FILE", requires = "write_mjcf")]
        write_actions: Option<PathBuf>,
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
        /// actor of the default run's shape (vge15's observation and joints, 128 x 128).
        #[arg(long, value_name = "FILE")]
        policy: Option<PathBuf>,
        /// Host observations compared with tch.
        #[arg(long, default_value_t = 10_000)]
        observations: usize,
        /// Seed of the untrained actor and of the observations.
        #[arg(long, default_value_t = 0)]
        seed: i64,
        /// The firmware's optimisation level: 3 (default, fastest), 2, or s / z (smaller
        /// flash, more instructions).
        #[arg(long, value_parser = ["3", "2", "s", "z"])]
        opt_level: Option<String>,
    },
    /// Policy forward latency at batch 1 for the default run's actor (vge15's observation
    /// and joints, 128 x 128): the no_std runtime against tch.
    Runtime {
        /// Print one JSON line instead of a summary.
        #[arg(long)]
        json: bool,
        /// Timed forwards per implementation.
        #[arg(long, default_value_t = 20_000)]
        iters: usize,
    },
    /// How busy the cores this process may use are (from /proc/stat, over --window-s), and
    /// how many libtorch threads fit beside that work: the idle cores, rounded, at least 1.
    /// More threads than that stall rather than slow (docs/libtorch.md); `vge train` warns
    /// when `sac.threads` exceeds it, and scripts/demo.sh trains with it (at most 2).
    Cores {
        /// Print one JSON line (cores, busy_cores, idle_cores, threads_that_fit).
        #[arg(long)]
        json: bool,
        /// The window the cores' use is measured over, in seconds.
        #[arg(long, default_value_t = 1.0)]
        window_s: f64,
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

/// `vge bench`.
pub fn run(bench: Bench) -> anyhow::Result<()> {
    match bench {
        Bench::Sim { write_mjcf: Some(path), mujoco_timestep_s, write_actions, steps, hand, .. } => {
            let env = bench_env(&hand)?;
            write_mjcf(&env, &path, mujoco_timestep_s)?;
            match write_actions {
                Some(actions) => write_bench_actions(&env, &actions, steps),
                None => Ok(()),
            }
        }
        Bench::Sim { json, steps, worlds, threads, hand, write_mjcf: None, .. } => {
            bench_sim(bench_env(&hand)?, json, steps, worlds, threads)
        }
        Bench::Controllers { json, episodes } => bench_controllers(json, episodes),
        Bench::Cores { json, window_s } => bench_cores(json, window_s),
        #[cfg(feature = "train")]
        Bench::Train {
            json,
            config,
            overrides,
            steps,
            threads,
            beside_busy_core,
            rounds,
            fixed_threads,
            overlap,
        } => {
            let plan =
                libtorch::TrainPlan { steps, threads, beside_busy_core, rounds, fixed_threads, overlap };
            libtorch::train(json, config, &overrides, &plan)
        }
        #[cfg(feature = "train")]
        Bench::Update { json, hidden, updates, batch, seed, algorithm, layer_norm, matmul } => {
            libtorch::update(json, hidden, updates, batch, seed, &algorithm, layer_norm, &matmul)
        }
        #[cfg(feature = "train")]
        Bench::Firmware { json, policy, observations, seed, opt_level } => {
            libtorch::firmware(json, policy, observations, seed, opt_level.as_deref())
        }
        #[cfg(feature = "train")]
        Bench::Runtime { json, iters } => libtorch::runtime(json, iters),
        #[cfg(not(feature = "train"))]
        Bench::Update { .. } | Bench::Firmware { .. } | Bench::Runtime { .. } => {
            Err(super::without_training("vge bench update/firmware/runtime (they compare with tch)"))
        }
        #[cfg(not(feature = "train"))]
        Bench::Train { .. } => Err(super::without_training("vge bench train")),
    }
}

/// `vge bench sim --write-mjcf`: the benchmarked env's hand, object and first settled grasp
/// (seed 0) as MJCF (`vge_sim::mjcf`, for any hand).
/// The benchmarked task: `hand` on the cube its file is sized for.
fn bench_env(hand: &str) -> anyhow::Result<EnvConfig> {
    let loaded = vge_sim::hands::load(hand).with_context(|| format!("--hand {hand}"))?;
    Ok(EnvConfig::for_hand(loaded)?)
}

fn write_mjcf(env: &EnvConfig, path: &std::path::Path, mujoco_timestep_s: f32) -> anyhow::Result<()> {
    let xml = vge_sim::mjcf::settled_grasp_mjcf(env, 0, mujoco_timestep_s)?;
    std::fs::write(path, xml).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("wrote {} ({} for MuJoCo, time step {mujoco_timestep_s} s)", path.display(), env.hand.name());
    Ok(())
}

/// `vge bench sim --write-actions`.
fn write_bench_actions(env: &EnvConfig, path: &std::path::Path, steps: usize) -> anyhow::Result<()> {
    anyhow::ensure!(steps > 0, "--steps must be at least 1");
    let bytes = vge_sim::bench::first_world_actions_f32_le(steps, env.hand.num_joints(), env.max_action_rad);
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("wrote {} ({steps} control steps of the bench's actions)", path.display());
    Ok(())
}

/// `vge bench sim`.
fn bench_sim(env: EnvConfig, json: bool, steps: usize, worlds: usize, threads: usize) -> anyhow::Result<()> {
    anyhow::ensure!(steps > 0 && worlds > 0, "--steps and --worlds must be at least 1");
    let settings = vge_sim::bench::BenchSettings { env, steps_per_world: steps, num_worlds: worlds, threads };
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
    Ok(())
}

/// `vge bench cores`.
fn bench_cores(json: bool, window_s: f64) -> anyhow::Result<()> {
    anyhow::ensure!(
        window_s.is_finite() && window_s > 0.0 && window_s <= 60.0,
        "--window-s {window_s}: give a time in seconds above 0 and at most 60"
    );
    let used = vge_run::cpu_use::measure(std::time::Duration::from_secs_f64(window_s))
        .context("measuring the cores' use")?;
    if json {
        println!(
            "{}",
            serde_json::json!({
                "cores": used.cores,
                "busy_cores": used.busy_cores,
                "idle_cores": used.idle_cores(),
                "threads_that_fit": used.threads_that_fit(),
                "window_s": window_s,
            })
        );
    } else {
        println!(
            "{} cores this process may use: {:.1} busy, {:.1} idle over {window_s} s; libtorch threads that fit beside that work: {}",
            used.cores,
            used.busy_cores,
            used.idle_cores(),
            used.threads_that_fit()
        );
    }
    Ok(())
}

/// `vge bench controllers`.
fn bench_controllers(json: bool, episodes: usize) -> anyhow::Result<()> {
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    let mut doc = serde_json::Map::new();
    for k in 3..=5usize {
        let us = vge_controllers::qp::bench_contact_force_qp(k, 200)
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

/// The benchmarks that run or compare with libtorch.
#[cfg(feature = "train")]
mod libtorch {
    use std::path::PathBuf;

    use anyhow::Context;
    use vge_trainer::learner::threads::Overlap;

    /// `vge bench update`.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        json: bool,
        hidden: Option<Vec<i64>>,
        updates: usize,
        batch: i64,
        seed: i64,
        algorithm: &str,
        layer_norm: bool,
        matmul: &str,
    ) -> anyhow::Result<()> {
        anyhow::ensure!(updates > 0, "--updates must be at least 1");
        anyhow::ensure!(batch > 0, "--batch must be at least 1");
        // The default run's networks and sizes (vge15), SAC with alpha 0 unless --algorithm td3.
        let mut run_config = vge_run::config::Config::default();
        if let Some(hidden) = hidden {
            run_config.sac.hidden = hidden;
            run_config.validate().map_err(|e| anyhow::anyhow!("--hidden: {e}"))?;
        }
        let mut config = vge_trainer::learner::LearnerConfig::for_hand(&run_config)?;
        config.algorithm = vge_trainer::learner::Algorithm::Sac;
        config.entropy = vge_trainer::learner::EntropyCoef::Fixed(0.0);
        config.critic_layer_norm = layer_norm;
        if matmul == "bf16" {
            config.matmul = vge_trainer::nets::MatmulPrecision::Bf16;
        }
        if algorithm == "td3" {
            config.algorithm = vge_trainer::learner::Algorithm::td3();
        }
        let config_hidden = config.net.hidden.clone();
        let r = vge_trainer::bench_update::run(config, batch, 20, updates, seed)?;
        if json {
            let line = serde_json::json!({
                "bench": "update",
                "algorithm": algorithm,
                "layer_norm": layer_norm,
                "matmul": matmul,
                "hidden": config_hidden,
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
                "{} update, hidden {:?}, batch {}, {} threads, {} updates, critic layer norm {layer_norm}, {matmul} matmuls",
                algorithm.to_uppercase(),
                config_hidden,
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
        Ok(())
    }

    /// What `vge bench train` measures.
    pub struct TrainPlan {
        pub steps: u64,
        pub threads: Vec<i32>,
        pub beside_busy_core: bool,
        pub rounds: usize,
        pub fixed_threads: String,
        pub overlap: Vec<String>,
    }

    /// `vge bench train`.
    pub fn train(
        json: bool,
        config: Option<PathBuf>,
        overrides: &[String],
        plan: &TrainPlan,
    ) -> anyhow::Result<()> {
        use vge_trainer::bench_train::{self, BenchRun, TrainBench};
        let TrainPlan { steps, threads, beside_busy_core, rounds, fixed_threads, overlap } = plan;
        let (steps, threads, rounds) = (*steps, threads.as_slice(), *rounds);
        anyhow::ensure!(steps > 0 && rounds > 0, "--steps and --rounds must be at least 1");
        anyhow::ensure!(
            !threads.is_empty() && threads.iter().all(|&t| t >= 1),
            "--threads: give thread counts of at least 1"
        );
        let config = match &config {
            Some(path) => vge_run::config::load_config(path, overrides)?,
            None => {
                let mut c = vge_run::config::Config::default();
                for o in overrides {
                    vge_run::config::apply_override(&mut c, o)?;
                }
                c.validate()?;
                c
            }
        };
        let loads: &[bool] = if *beside_busy_core { &[false, true] } else { &[false] };
        let modes: &[bool] = match fixed_threads.as_str() {
            "yes" => &[false],
            "both" => &[false, true],
            _ => &[true],
        };
        let overlaps = overlap
            .iter()
            .map(|word| {
                [Overlap::Fastest, Overlap::Always, Overlap::Never]
                    .into_iter()
                    .find(|&o| overlap_name(o) == word)
                    .with_context(|| format!("--overlap {word}: give fastest, yes or no"))
            })
            .collect::<anyhow::Result<Vec<Overlap>>>()?;
        let overlaps = overlaps.as_slice();
        if !json {
            println!(
                "{} {} with {} ({} envs, utd {}, warm-up {}), {steps} env steps after the warm-up",
                config.algorithm.name().to_uppercase(),
                config.method.name(),
                config.controller.map_or("no controller".to_owned(), |c| c.name().to_uppercase()),
                config.num_envs,
                config.sac.utd,
                config.sac.warmup,
            );
            println!(
                "round threads  adapt overlap  busy   steps/s updates/s    sim   ctrl  actor update  other  (shares of the time)"
            );
        }
        let mut results: Vec<TrainBench> = Vec::new();
        for round in 1..=rounds {
            for &beside_busy_core in loads {
                for &adaptive_threads in modes {
                    for &overlap in overlaps {
                        for &threads in threads {
                            if threads == 1 && overlap != overlaps[0] {
                                continue; // one core has one schedule: measured once
                            }
                            let how =
                                BenchRun { threads, steps, beside_busy_core, adaptive_threads, overlap };
                            let r = bench_train::run(&config, how)?;
                            print_train_row(json, round, &r);
                            results.push(r);
                        }
                    }
                }
            }
        }
        if !json {
            print_train_summary(&results, threads, loads, modes, overlaps);
        }
        Ok(())
    }

    /// `--overlap`'s word for a schedule.
    fn overlap_name(overlap: Overlap) -> &'static str {
        match overlap {
            Overlap::Fastest => "fastest",
            Overlap::Always => "yes",
            Overlap::Never => "no",
        }
    }

    fn print_train_row(json: bool, round: usize, r: &vge_trainer::bench_train::TrainBench) {
        let split = r.split();
        let total = r.phases.total_s.max(1e-9);
        if json {
            let mut line = serde_json::json!({
                "bench": "train",
                "round": round,
                "threads": r.threads,
                "beside_busy_core": r.beside_busy_core,
                "adaptive_threads": r.adaptive_threads,
                "overlap": overlap_name(r.overlap),
                "env_steps": r.env_steps,
                "updates": r.updates,
                "wall_s": r.phases.total_s,
                "steps_per_s": r.steps_per_s(),
                "updates_per_s": r.updates_per_s(),
                "sim_beside_updates_s": r.phases.sim_beside_updates_s,
            });
            for (name, s) in split {
                line[format!("{name}_s")] = serde_json::json!(s);
            }
            println!("{line}");
        } else {
            let shares: Vec<String> =
                split.iter().map(|(_, s)| format!("{:>5.0}%", 100.0 * s / total)).collect();
            println!(
                "{round:>5} {:>7} {:>6} {:>7} {:>5} {:>9.1} {:>9.1} {}",
                r.threads,
                if r.adaptive_threads { "yes" } else { "no" },
                overlap_name(r.overlap),
                if r.beside_busy_core { "yes" } else { "no" },
                r.steps_per_s(),
                r.updates_per_s(),
                shares.join(" ")
            );
        }
    }

    /// The median rate of each configuration, and each as a fraction of the one-thread rate
    /// without the busy core (the yardstick: beside a busy core, at least half of it).
    fn print_train_summary(
        results: &[vge_trainer::bench_train::TrainBench],
        threads: &[i32],
        loads: &[bool],
        modes: &[bool],
        overlaps: &[Overlap],
    ) {
        // One thread never overlaps: its runs count for either setting.
        let median = |t: i32, busy: bool, adapt: bool, overlap: Overlap| -> Option<f64> {
            let mut v: Vec<f64> = results
                .iter()
                .filter(|r| r.threads == t && r.beside_busy_core == busy && r.adaptive_threads == adapt)
                .filter(|r| t == 1 || r.overlap == overlap)
                .map(vge_trainer::bench_train::TrainBench::steps_per_s)
                .collect();
            v.sort_by(f64::total_cmp);
            (!v.is_empty()).then(|| v[v.len() / 2])
        };
        let base = median(1, false, modes[0], overlaps[0]);
        println!("median env steps/s:");
        for &busy in loads {
            for &adapt in modes {
                for &overlap in overlaps {
                    for &t in threads {
                        if t == 1 && overlap != overlaps[0] {
                            continue;
                        }
                        let Some(rate) = median(t, busy, adapt, overlap) else { continue };
                        let ratio = base.map_or(String::new(), |b| {
                            format!("  ({:.2} of one thread without the busy core)", rate / b)
                        });
                        let load = if busy { "beside a busy core" } else { "without a busy core" };
                        let mode = if adapt { "at most" } else { "fixed at" };
                        let envs = match overlap {
                            _ if t == 1 => "",
                            Overlap::Fastest => ", the faster schedule",
                            Overlap::Always => ", envs beside the updates",
                            Overlap::Never => ", envs between the updates",
                        };
                        println!("  threads {mode} {t}{envs}, {load}: {rate:.1}{ratio}");
                    }
                }
            }
        }
    }

    /// The default run's actor shape: its hand's observation and joints, its hidden widths.
    fn default_actor() -> anyhow::Result<vge_export::ActorSpec> {
        let net =
            vge_trainer::learner::LearnerConfig::for_hand(&vge_run::config::Config::default())?.actor_net();
        Ok(vge_export::ActorSpec {
            obs_dim: usize::try_from(net.obs_dim)?,
            hidden: net.hidden.iter().map(|&h| usize::try_from(h)).collect::<Result<_, _>>()?,
            act_dim: usize::try_from(net.act_dim)?,
        })
    }

    /// `vge bench runtime`.
    pub fn runtime(json: bool, iters: usize) -> anyhow::Result<()> {
        anyhow::ensure!(iters > 0, "--iters must be at least 1");
        let config = vge_export_tch::bench::BenchConfig {
            iters,
            ..vge_export_tch::bench::BenchConfig::of_shape(&default_actor()?)
        };
        let r = vge_export_tch::bench::run(&config)?;
        if json {
            println!("{}", r.to_json_line());
        } else {
            println!("batch-1 forward, {:?}, {} iterations", r.dims, r.iters);
            println!("  vge-runtime  median {:>8.0} ns", r.runtime_ns);
            println!("  tch          median {:>8.0} ns  ({} threads)", r.tch_ns, r.tch_threads);
            println!("  speedup {:.1}x, max |diff| {:.2e}", r.tch_ns / r.runtime_ns, r.max_abs_diff);
        }
        Ok(())
    }

    /// `vge bench firmware`.
    pub fn firmware(
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
            None => vge_export_tch::firmware_bench::seeded_policy(seed, &default_actor()?)?,
        };
        let target_dir = std::env::temp_dir().join("vge-bench-firmware");
        let rows =
            vge_export_tch::firmware_bench::run(&file, &target_dir, opt_level, observations, seed, |msg| {
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
                r.instructions_per_forward / vge_export_tch::firmware_bench::CLOCK_HZ * 1e3,
                r.max_abs_diff
            );
        }
        println!("(ms at one instruction per cycle: an estimate; RAM = static + stack peak)");
        Ok(())
    }
}
