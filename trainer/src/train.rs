//! The training loop: N envs stepped in parallel (rayon, as `vge_sim::VecEnv` does, but each
//! env may hold its own object), the behaviour policy ([`crate::behaviour`]), the replay
//! buffer, `utd` SAC updates per transition, a metrics CSV written as it goes, checkpoints,
//! resume, a stop flag, and the final actor exported as `DIR/policy.vgep`.
//!
//! Output directory:
//! - `config.toml`: the effective configuration;
//! - `metrics.csv`: one row every `run.log_interval` env steps (flushed);
//! - `tensorboard/`: the metrics rows as TensorBoard scalars (`train/<column>`), one event
//!   file per session (`tensorboard --logdir DIR`);
//! - `eval.csv`: deterministic evaluations of the actor every `run.eval_interval` steps;
//! - `checkpoint/`: `state.toml` (counters, generator state, metric window), `actor.ot`,
//!   `critic.ot`, `target.ot`, `target_actor.ot` (TD3), `optim.ot` (Adam moments, α),
//!   `replay.bin` (optional), and `manifest.json` (every file's length and CRC-32). It is
//!   written to `checkpoint.tmp/` and renamed, so a SIGKILL leaves the previous one whole, and
//!   a resume verifies every file against the manifest first: a damaged, truncated or
//!   unverifiable checkpoint is refused with the file's name, never resumed
//!   ([`crate::checkpoint`]);
//! - `policy.vgep`: the exported actor at the end;
//! - `snapshots/policy-<step>.vgep`: the actor exported at each periodic evaluation;
//! - `policy-best.vgep`, `best-eval.json`: model selection, reported apart from the final
//!   policy. The snapshot with the best periodic evaluation (success, then return; these are
//!   the validation episodes) is run again on held-out test episodes drawn from another
//!   seed, so that the selection does not inflate the number it reports. Training itself is
//!   unchanged by it.
//!
//! Determinism and resume: every random draw comes from the run's ChaCha8 generator (env
//! reset seeds, controller generators, source draws, warm-up actions, replay indices) or
//! from libtorch's generator reseeded from (seed, counter) before each use (behaviour
//! samples per step, updates per update index), so libtorch's generator state need not be
//! saved. Physics state cannot be saved, so a checkpoint ends every env's episode (a
//! truncation: bootstrapped, not terminal) and all envs reset from the generator right after
//! it, in an uninterrupted run exactly as in a resumed one. Resuming from a periodic
//! checkpoint therefore reproduces the uninterrupted run bit for bit (tested). A stop
//! (Ctrl-C) checkpoints at the current step: the resumed run is then the run whose
//! checkpoint boundary fell at that step.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tch::{Device, Tensor};
use thiserror::Error;
use vge_export::Provenance;
use vge_sim::{Env, EnvConfig, NUM_JOINTS, OBS_DIM, SimError};

use crate::behaviour::{Behaviour, BehaviourError, BehaviourStats, StepContext, bc_beta};
use crate::checkpoint::{self, CheckpointError};
use crate::config::{Config, ConfigError};
use crate::controllers::{Controller, ControllerInput, IgmConfig};
use crate::eval::{EpisodeOutcome, EvalError, EvalReport};
use crate::gait::ContactSwitches;
use crate::policy_export::export_hand_actor;
use crate::replay::{ReplayBuffer, ReplayError};
use crate::sac::{Sac, UpdateStats, mix_seed, standard_normal};
use crate::tensorboard::EventWriter;

#[derive(Debug, Error)]
pub enum TrainError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("libtorch: {0}")]
    Tch(#[from] tch::TchError),
    #[error(transparent)]
    Replay(#[from] ReplayError),
    #[error("export: {0}")]
    Export(#[from] vge_export::ExportError),
    #[error(transparent)]
    Eval(#[from] EvalError),
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("resume: {0}")]
    Resume(String),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error("behaviour policy: {0}")]
    Behaviour(#[from] BehaviourError),
    #[error("training step {step}: the learner's action for env {env} is not finite ({value})")]
    NonFiniteAction { step: u64, env: usize, value: f32 },
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> TrainError + '_ {
    move |source| TrainError::Io { path: path.display().to_string(), source }
}

/// What the progress callback sees (every loop iteration, i.e. every `num_envs` steps).
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    pub step: u64,
    pub total_steps: u64,
    /// Env steps per second since this session (start or resume) began.
    pub steps_per_s: f64,
    pub episodes: u64,
    /// Of the last metrics window.
    pub mean_return: f64,
    pub mean_rotation_rad: f64,
    pub controller_share: f64,
    pub updates: u64,
}

/// How a call of [`train`] ended.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainSummary {
    pub steps: u64,
    pub updates: u64,
    pub episodes: u64,
    /// The stop flag ended it (checkpoint saved, no policy exported).
    pub stopped: bool,
    /// `DIR/policy.vgep` when training finished.
    pub policy: Option<PathBuf>,
    pub behaviour: BehaviourStats,
    /// Where this session's wall time went.
    pub times: PhaseTimes,
}

/// Wall-clock seconds per phase of the training loop, this session: what limits its speed.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseTimes {
    /// The actor's behaviour actions (one batched forward per step of all envs).
    pub learner_s: f64,
    /// The behaviour policy: controller calls (QP, kinematics) and the critic's Q queries.
    pub behaviour_s: f64,
    /// Physics: stepping the envs (in parallel), replay pushes, episode resets, logging.
    pub sim_s: f64,
    /// Gradient updates, with minibatch sampling.
    pub update_s: f64,
    /// Periodic deterministic evaluations.
    pub eval_s: f64,
    /// Checkpoints (networks, optimisers, replay buffer).
    pub checkpoint_s: f64,
    pub total_s: f64,
}

impl std::fmt::Display for PhaseTimes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let total = self.total_s.max(1e-9);
        let parts = [
            ("updates", self.update_s),
            ("simulation", self.sim_s),
            ("controllers + Q", self.behaviour_s),
            ("actor", self.learner_s),
            ("evaluation", self.eval_s),
            ("checkpoints", self.checkpoint_s),
        ];
        let shown: Vec<String> =
            parts.iter().map(|(name, t)| format!("{name} {t:.1} s ({:.0}%)", 100.0 * t / total)).collect();
        write!(f, "{:.1} s: {}", self.total_s, shown.join(", "))
    }
}

/// Sums over the current metrics window.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
struct Window {
    episodes: u64,
    ret: f64,
    rotation: f64,
    contacts: f64,
    successes: u64,
    updates: u64,
    critic_loss: f64,
    actor_loss: f64,
    bc_loss: f64,
    alpha: f64,
    mean_q: f64,
    steps: u64,
    controller_steps: u64,
    selections: u64,
    p_psi_sum: f64,
    /// Fingertip contact switches completed ([`crate::gait`]).
    switches: u64,
    /// Discounted Monte-Carlo returns of the visited states of the finished episodes (sum,
    /// count, largest): what the critic's mean Q should stay within.
    mc_return_sum: f64,
    mc_return_count: u64,
    mc_return_max: Option<f64>,
}

/// Everything of a run that is not a tensor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct TrainState {
    step: u64,
    episodes: u64,
    updates_due: f64,
    rng_seed_hex: String,
    rng_stream: u64,
    rng_word_pos: String,
    config_hash: String,
    stats_steps: u64,
    stats_controller_steps: u64,
    stats_controller_queries: u64,
    stats_controller_no_action: u64,
    stats_selections: u64,
    stats_controller_selected: u64,
    stats_p_psi_sum: f64,
    window: Window,
    last_window: Window,
    has_replay: bool,
    /// Wall time of the sessions up to this checkpoint (s).
    #[serde(default)]
    wall_s: f64,
}

fn rng_state(rng: &ChaCha8Rng) -> (String, u64, String) {
    let seed: String = rng.get_seed().iter().map(|b| format!("{b:02x}")).collect();
    (seed, rng.get_stream(), rng.get_word_pos().to_string())
}

fn rng_restore(seed_hex: &str, stream: u64, word_pos: &str) -> Result<ChaCha8Rng, TrainError> {
    let bad = || TrainError::Resume("corrupt generator state in state.toml".to_owned());
    if seed_hex.len() != 64 {
        return Err(bad());
    }
    let mut seed = [0u8; 32];
    for (i, b) in seed.iter_mut().enumerate() {
        *b = u8::from_str_radix(&seed_hex[2 * i..2 * i + 2], 16).map_err(|_| bad())?;
    }
    let mut rng = ChaCha8Rng::from_seed(seed);
    rng.set_stream(stream);
    rng.set_word_pos(word_pos.parse::<u128>().map_err(|_| bad())?);
    Ok(rng)
}

/// Per-env episode accumulators.
#[derive(Debug, Clone, Default)]
struct Running {
    ret: f64,
    rotation: f64,
    contacts: u64,
    length: u64,
    yaw: f32,
    switches: ContactSwitches,
    /// The episode's rewards so far (for its discounted Monte-Carlo returns).
    rewards: Vec<f32>,
}

/// Sum, count and largest of the discounted returns `G_t = r_t + γ G_{t+1}` of every step
/// of an episode (no bootstrap past its end).
fn discounted_returns(rewards: &[f32], gamma: f64) -> (f64, u64, Option<f64>) {
    let mut g = 0.0f64;
    let (mut sum, mut max) = (0.0f64, None::<f64>);
    for &r in rewards.iter().rev() {
        g = f64::from(r) + gamma * g;
        sum += g;
        max = Some(max.map_or(g, |m| m.max(g)));
    }
    (sum, rewards.len() as u64, max)
}

const METRICS_HEADER: &str = "step,episodes,return,rotation,contacts,success,controller_share,p_psi,switches_per_1k,critic_loss,actor_loss,bc_loss,alpha,mean_q,mc_return,mc_return_max,beta,updates,steps_per_s";

/// Salt of the behaviour-noise seeds.
const SALT_ACT: u64 = 0xac7;
/// Smallest std the observation normaliser divides by: a centimetre for contact positions,
/// and nothing that never varied in the warm-up gets amplified more than 100x.
const OBS_MIN_STD: f32 = 1e-2;

/// The effective configuration stored in a run directory (for `--resume DIR`).
pub fn run_config(dir: &Path) -> Result<Config, TrainError> {
    let path = dir.join("config.toml");
    let text = std::fs::read_to_string(&path).map_err(io_err(&path))?;
    let config = Config::from_toml_str(&text)?;
    config.validate()?;
    Ok(config)
}

/// Trains `config` into `out_dir`. With `resume`, continues from `out_dir/checkpoint` (the
/// config may raise `total_steps`; other changes make the run a different one). `stop` is
/// polled every iteration: when set, a checkpoint is saved and the call returns with
/// `stopped = true`. `progress` is called every iteration.
pub fn train(
    config: &Config,
    out_dir: &Path,
    resume: bool,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(&Progress),
) -> Result<TrainSummary, TrainError> {
    config.validate()?;
    std::fs::create_dir_all(out_dir).map_err(io_err(out_dir))?;
    if config.sac.threads > 0 {
        tch::set_num_threads(config.sac.threads);
    }
    let n = config.num_envs;
    let seed = config.seed;
    let env_configs: Vec<EnvConfig> = (0..n).map(|i| config.env.env_config(i)).collect();
    let max_action = config.env.max_action_rad;

    let mut sac = Sac::new_seeded(config.sac_config(), Device::Cpu, seed)?;
    let mut replay = ReplayBuffer::new(config.sac.buffer_size, OBS_DIM, NUM_JOINTS)?;
    let mut behaviour = Behaviour::from_config(config);
    let mut controllers: Vec<Box<dyn Controller + Send>> = if config.method.queries_controller() {
        let kind = config.controller.map(|c| c.kind());
        env_configs
            .iter()
            .filter_map(|e| kind.map(|k| k.build(e, IgmConfig::default(), config.cs_config(e))))
            .collect()
    } else {
        Vec::new()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut step = 0u64;
    let mut episodes = 0u64;
    let mut updates_due = 0.0f64;
    let mut window = Window::default();
    let mut last_window = Window::default();
    let mut previous_wall_s = 0.0f64;
    let metrics_path = out_dir.join("metrics.csv");
    let config_hash = config.hash_hex();

    if resume {
        // Every file is checked against the manifest before any is read (crate::checkpoint).
        let ckpt = checkpoint::open(out_dir)?;
        let state: TrainState = toml::from_str(ckpt.state_toml()).map_err(|e| {
            TrainError::Resume(format!("{}: {e}", ckpt.dir().join(checkpoint::STATE_FILE).display()))
        })?;
        ckpt.load(&mut sac, state.has_replay.then_some(&mut replay))?;
        rng = rng_restore(&state.rng_seed_hex, state.rng_stream, &state.rng_word_pos)?;
        step = state.step;
        episodes = state.episodes;
        updates_due = state.updates_due;
        window = state.window;
        last_window = state.last_window;
        previous_wall_s = state.wall_s;
        behaviour.stats = BehaviourStats {
            steps: state.stats_steps,
            controller_steps: state.stats_controller_steps,
            controller_queries: state.stats_controller_queries,
            controller_no_action: state.stats_controller_no_action,
            selections: state.stats_selections,
            controller_selected: state.stats_controller_selected,
            p_psi_sum: state.stats_p_psi_sum,
        };
        truncate_csv(&metrics_path, step)?;
        truncate_csv(&out_dir.join("eval.csv"), step)?;
    } else {
        let text = config.to_toml_string()?;
        let path = out_dir.join("config.toml");
        std::fs::write(&path, text).map_err(io_err(&path))?;
        let path = &metrics_path;
        std::fs::write(path, format!("{METRICS_HEADER}\n")).map_err(io_err(path))?;
    }
    // A new event file per session; a resumed one starts with a session-start marker so that
    // TensorBoard drops the interrupted session's points past the checkpoint.
    let tb_dir = out_dir.join("tensorboard");
    let mut events = EventWriter::create(&tb_dir, &format!(".s{step}")).map_err(io_err(&tb_dir))?;
    if resume {
        events.session_start(step).map_err(io_err(events.path()))?;
    }
    let mut metrics = BufWriter::new(
        File::options().append(true).create(true).open(&metrics_path).map_err(io_err(&metrics_path))?,
    );

    let mut envs: Vec<Env> = env_configs.iter().map(|e| Env::new(e.clone())).collect::<Result<_, _>>()?;
    let mut obs: Vec<[f32; OBS_DIM]> = vec![[0.0; OBS_DIM]; n];
    let mut ctl_rngs: Vec<ChaCha8Rng> = (0..n).map(|_| ChaCha8Rng::seed_from_u64(0)).collect();
    let mut running = vec![Running::default(); n];
    let all: Vec<usize> = (0..n).collect();
    reset_envs(&all, &mut envs, &mut obs, &mut ctl_rngs, &mut running, &mut behaviour, &mut rng)?;

    let session_start = Instant::now();
    let session_first_step = step;
    let mut stopped = false;
    let mut checkpointed_at = if resume { Some(step) } else { None };
    let batch_size = config.sac.batch;
    // The checkpoint state of the loop's counters, generator and windows right now. A macro,
    // because a closure would hold borrows of them across the loop that mutates them.
    macro_rules! train_state {
        () => {
            TrainState::new(
                step,
                episodes,
                updates_due,
                &rng,
                &config_hash,
                &behaviour.stats,
                &window,
                &last_window,
                config.run.save_replay,
                previous_wall_s + session_start.elapsed().as_secs_f64(),
            )
        };
    }
    let mut times = PhaseTimes::default();
    let mut clock = Instant::now();
    // Adds the time since the last call to one phase.
    let mut lap = |phase: &mut f64| {
        let now = Instant::now();
        *phase += (now - clock).as_secs_f64();
        clock = now;
    };
    while step < config.total_steps {
        if stop.load(Ordering::SeqCst) {
            stopped = true;
            break;
        }
        // The learner's behaviour actions.
        let learner: Vec<[f32; NUM_JOINTS]> = if step < config.sac.warmup {
            (0..n).map(|_| std::array::from_fn(|_| rng.random_range(-max_action..=max_action))).collect()
        } else {
            let mut noise_rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, step, SALT_ACT) as u64);
            let eps = standard_normal(&mut noise_rng, n as i64, NUM_JOINTS as i64);
            let t = Tensor::from_slice(obs.as_flattened()).view([n as i64, OBS_DIM as i64]);
            let a = sac.behaviour_action(&t, &eps);
            let v = Vec::<f32>::try_from(a.contiguous().view(-1))?;
            v.chunks_exact(NUM_JOINTS).map(|c| std::array::from_fn(|j| c[j])).collect()
        };
        lap(&mut times.learner_s);
        let inputs: Vec<Option<ControllerInput>> = if behaviour.controller_active(step) {
            envs.iter().map(|e| e.privileged().map(ControllerInput::from_privileged)).collect()
        } else {
            vec![None; n]
        };
        let ctx = StepContext { step, obs: &obs, learner: &learner, inputs: &inputs };
        let mut q = |o: &[[f32; OBS_DIM]], a: &[[f32; NUM_JOINTS]]| -> Result<Vec<f32>, String> {
            let rows = o.len() as i64;
            let ot = Tensor::from_slice(o.as_flattened()).view([rows, OBS_DIM as i64]);
            let at = Tensor::from_slice(a.as_flattened()).view([rows, NUM_JOINTS as i64]);
            Vec::<f32>::try_from(sac.q_of(&ot, &at).view(-1)).map_err(|e| e.to_string())
        };
        let stats_before = behaviour.stats;
        let mut decisions = behaviour.act(&ctx, &mut controllers, &mut ctl_rngs, &mut q, &mut rng)?;
        for (i, d) in decisions.iter_mut().enumerate() {
            if let Some(&value) = d.action.iter().find(|v| !v.is_finite()) {
                return Err(TrainError::NonFiniteAction { step, env: i, value });
            }
            for v in &mut d.action {
                *v = v.clamp(-max_action, max_action);
            }
        }
        lap(&mut times.behaviour_s);
        let results: Vec<_> = envs
            .par_iter_mut()
            .zip(decisions.par_iter())
            .map(|(env, d)| env.step(&d.action))
            .collect::<Result<Vec<_>, SimError>>()?;
        let mut finished = Vec::new();
        for (i, (r, d)) in results.iter().zip(&decisions).enumerate() {
            let bc_target = d.bc_target.as_ref().map(|b| b.as_slice());
            replay.push(&obs[i], &d.action, r.reward, &r.obs, r.terminated, d.source, bc_target)?;
            let run = &mut running[i];
            run.ret += f64::from(r.reward);
            run.rotation += f64::from(vge_sim::wrap_angle_rad(r.info.object_yaw_rad - run.yaw));
            run.yaw = r.info.object_yaw_rad;
            run.contacts += r.info.num_tip_contacts as u64;
            run.length += 1;
            run.rewards.push(r.reward);
            window.switches += u64::from(run.switches.update(r.info.tip_contacts));
            obs[i] = r.obs;
            if r.terminated || r.truncated {
                let outcome = EpisodeOutcome {
                    episode_return: run.ret,
                    rotation_rad: run.rotation,
                    terminated: r.terminated,
                    mean_contacts: run.contacts as f64 / run.length.max(1) as f64,
                    contact_switches: run.switches.count,
                    length: run.length as usize,
                };
                window.episodes += 1;
                window.ret += outcome.episode_return;
                window.rotation += outcome.rotation_rad;
                window.contacts += outcome.mean_contacts;
                window.successes += u64::from(outcome.success());
                let (sum, count, max) = discounted_returns(&run.rewards, config.sac.gamma);
                window.mc_return_sum += sum;
                window.mc_return_count += count;
                window.mc_return_max = match (window.mc_return_max, max) {
                    (Some(a), Some(b)) => Some(a.max(b)),
                    (a, b) => a.or(b),
                };
                episodes += 1;
                finished.push(i);
            }
        }
        if !finished.is_empty() {
            reset_envs(
                &finished,
                &mut envs,
                &mut obs,
                &mut ctl_rngs,
                &mut running,
                &mut behaviour,
                &mut rng,
            )?;
        }
        let s = behaviour.stats;
        window.steps += s.steps - stats_before.steps;
        window.controller_steps += s.controller_steps - stats_before.controller_steps;
        window.selections += s.selections - stats_before.selections;
        window.p_psi_sum += s.p_psi_sum - stats_before.p_psi_sum;
        let prev_step = step;
        step += n as u64;

        lap(&mut times.sim_s);

        // Updates.
        let beta = if config.method.uses_bc() { bc_beta(&config.bc, step) } else { 0.0 };
        if step >= config.sac.warmup && replay.len() >= batch_size {
            if sac.updates() == 0 && config.sac.normalize_obs {
                // Once, before the first update; afterwards the statistics live in the
                // networks' var stores and come back with a checkpoint.
                let (mean, std) = replay.obs_stats(OBS_MIN_STD);
                sac.set_obs_normalisation(&mean, &std);
            }
            updates_due += n as f64 * config.sac.utd;
            while updates_due >= 1.0 {
                updates_due -= 1.0;
                let bc = (beta > 0.0).then_some(beta);
                let batch = replay.sample(batch_size, &mut rng, bc)?;
                let st = sac.update(&batch);
                add_stats(&mut window, &st);
            }
        }
        lap(&mut times.update_s);

        let crossed = |interval: u64| interval > 0 && prev_step / interval != step / interval;
        if crossed(config.run.log_interval) || step >= config.total_steps {
            let elapsed = session_start.elapsed().as_secs_f64();
            let sps = (step - session_first_step) as f64 / elapsed.max(1e-9);
            let values = metrics_values(episodes, &window, beta, sac.updates(), sps);
            write_metrics_row(&mut metrics, step, &values).map_err(io_err(&metrics_path))?;
            // TensorBoard gets the same numbers ("train/return", ...), the empty ones left out.
            let scalars: Vec<(String, f64)> =
                values.iter().filter_map(|(n, v)| v.map(|x| (format!("train/{n}"), x))).collect();
            events.scalars(step, &scalars).map_err(io_err(events.path()))?;
            last_window = std::mem::take(&mut window);
        }
        if crossed(config.run.eval_interval) {
            lap(&mut times.sim_s);
            let bytes = export_actor(config, &sac, step)?;
            let report = evaluate_policy(config, &bytes, EpisodeSet::Validation)?;
            append_eval_row(out_dir, step, &report)?;
            let path = snapshot_path(out_dir, step);
            let dir = out_dir.join(SNAPSHOT_DIR);
            std::fs::create_dir_all(&dir).map_err(io_err(&dir))?;
            std::fs::write(&path, &bytes).map_err(io_err(&path))?;
            lap(&mut times.eval_s);
        }
        let elapsed = session_start.elapsed().as_secs_f64();
        progress(&Progress {
            step,
            total_steps: config.total_steps,
            steps_per_s: (step - session_first_step) as f64 / elapsed.max(1e-9),
            episodes,
            mean_return: last_window.ret / last_window.episodes.max(1) as f64,
            mean_rotation_rad: last_window.rotation / last_window.episodes.max(1) as f64,
            controller_share: last_window.controller_steps as f64 / last_window.steps.max(1) as f64,
            updates: sac.updates(),
        });
        if crossed(config.run.checkpoint_interval) && step < config.total_steps {
            let state = train_state!();
            lap(&mut times.sim_s);
            save_checkpoint(out_dir, &sac, &replay, &state)?;
            lap(&mut times.checkpoint_s);
            checkpointed_at = Some(step);
            // A checkpoint ends every episode (module docs).
            reset_envs(&all, &mut envs, &mut obs, &mut ctl_rngs, &mut running, &mut behaviour, &mut rng)?;
        }
        lap(&mut times.sim_s);
    }
    metrics.flush().map_err(io_err(&metrics_path))?;
    // A checkpoint taken at this very step holds the state before the env resets that
    // followed it: keep it, so that a resume redoes those resets exactly.
    if checkpointed_at != Some(step) {
        let state = train_state!();
        save_checkpoint(out_dir, &sac, &replay, &state)?;
    }
    let policy = if stopped {
        None
    } else {
        let path = out_dir.join("policy.vgep");
        let bytes = export_actor(config, &sac, step)?;
        std::fs::write(&path, &bytes).map_err(io_err(&path))?;
        let eval_start = Instant::now();
        let report = evaluate_policy(config, &bytes, EpisodeSet::Validation)?;
        let wall_s = previous_wall_s + session_start.elapsed().as_secs_f64();
        write_final_eval(out_dir, config, &report, step, wall_s)?;
        select_best_snapshot(out_dir, config)?;
        times.eval_s += eval_start.elapsed().as_secs_f64();
        Some(path)
    };
    Ok(TrainSummary {
        steps: step,
        updates: sac.updates(),
        episodes,
        stopped,
        policy,
        behaviour: behaviour.stats,
        times: PhaseTimes { total_s: session_start.elapsed().as_secs_f64(), ..times },
    })
}

impl TrainState {
    #[allow(clippy::too_many_arguments)]
    fn new(
        step: u64,
        episodes: u64,
        updates_due: f64,
        rng: &ChaCha8Rng,
        config_hash: &str,
        s: &BehaviourStats,
        window: &Window,
        last_window: &Window,
        has_replay: bool,
        wall_s: f64,
    ) -> Self {
        let (rng_seed_hex, rng_stream, rng_word_pos) = rng_state(rng);
        Self {
            step,
            episodes,
            updates_due,
            rng_seed_hex,
            rng_stream,
            rng_word_pos,
            config_hash: config_hash.to_owned(),
            stats_steps: s.steps,
            stats_controller_steps: s.controller_steps,
            stats_controller_queries: s.controller_queries,
            stats_controller_no_action: s.controller_no_action,
            stats_selections: s.selections,
            stats_controller_selected: s.controller_selected,
            stats_p_psi_sum: s.p_psi_sum,
            window: window.clone(),
            last_window: last_window.clone(),
            has_replay,
            wall_s,
        }
    }
}

fn add_stats(w: &mut Window, st: &UpdateStats) {
    w.updates += 1;
    w.critic_loss += st.critic_loss;
    w.actor_loss += st.actor_loss;
    w.bc_loss += st.bc_loss;
    w.alpha += st.alpha;
    w.mean_q += st.mean_q;
}

/// One metrics row: `(column, value)` in [`METRICS_HEADER`] order after `step`; `None`
/// where the window had nothing to average (no finished episode, no update).
fn metrics_values(
    episodes: u64,
    w: &Window,
    beta: f64,
    updates: u64,
    sps: f64,
) -> Vec<(&'static str, Option<f64>)> {
    let e = w.episodes.max(1) as f64;
    let u = w.updates.max(1) as f64;
    let per_episode = |x: f64| (w.episodes > 0).then_some(x / e);
    let per_update = |x: f64| (w.updates > 0).then_some(x / u);
    vec![
        ("episodes", Some(episodes as f64)),
        ("return", per_episode(w.ret)),
        ("rotation", per_episode(w.rotation)),
        ("contacts", per_episode(w.contacts)),
        ("success", per_episode(w.successes as f64)),
        ("controller_share", Some(w.controller_steps as f64 / w.steps.max(1) as f64)),
        ("p_psi", (w.selections > 0).then(|| w.p_psi_sum / w.selections as f64)),
        ("switches_per_1k", Some(1000.0 * w.switches as f64 / w.steps.max(1) as f64)),
        ("critic_loss", per_update(w.critic_loss)),
        ("actor_loss", per_update(w.actor_loss)),
        ("bc_loss", per_update(w.bc_loss)),
        ("alpha", per_update(w.alpha)),
        ("mean_q", per_update(w.mean_q)),
        ("mc_return", (w.mc_return_count > 0).then(|| w.mc_return_sum / w.mc_return_count as f64)),
        ("mc_return_max", w.mc_return_max),
        ("beta", Some(beta)),
        ("updates", Some(updates as f64)),
        ("steps_per_s", Some(sps)),
    ]
}

fn write_metrics_row(out: &mut impl Write, step: u64, values: &[(&str, Option<f64>)]) -> std::io::Result<()> {
    let mut line = step.to_string();
    for (name, v) in values {
        line.push(',');
        match (*name, v) {
            (_, None) => {}
            ("episodes" | "updates", Some(x)) => line.push_str(&format!("{x:.0}")),
            ("steps_per_s", Some(x)) => line.push_str(&format!("{x:.1}")),
            (_, Some(x)) => line.push_str(&format!("{x:.6}")),
        }
    }
    writeln!(out, "{line}")?;
    out.flush()
}

/// Resets envs `which`, drawing each one's env seed and controller seed from `rng` in order.
fn reset_envs(
    which: &[usize],
    envs: &mut [Env],
    obs: &mut [[f32; OBS_DIM]],
    ctl_rngs: &mut [ChaCha8Rng],
    running: &mut [Running],
    behaviour: &mut Behaviour,
    rng: &mut ChaCha8Rng,
) -> Result<(), TrainError> {
    let mut seeds = vec![None; envs.len()];
    for &i in which {
        seeds[i] = Some(rng.next_u64());
        ctl_rngs[i] = ChaCha8Rng::seed_from_u64(rng.next_u64());
        behaviour.episode_reset(i);
    }
    let resets: Vec<Option<[f32; OBS_DIM]>> = envs
        .par_iter_mut()
        .zip(seeds.par_iter())
        .map(|(env, s)| s.map(|s| env.reset(s).map(|(o, _)| o)).transpose())
        .collect::<Result<_, SimError>>()?;
    for (i, o) in resets.into_iter().enumerate() {
        if let Some(o) = o {
            obs[i] = o;
            let start = envs[i].privileged();
            let yaw = start.map_or(0.0, |p| p.object.yaw_rad());
            let touching = start.map_or([false; vge_sim::NUM_FINGERS], |p| p.contacts.map(|c| c.is_some()));
            running[i] = Running { yaw, switches: ContactSwitches::new(touching), ..Running::default() };
        }
    }
    Ok(())
}

/// Keeps the header and the rows whose first field (step) is <= `step`.
fn truncate_csv(path: &Path, step: u64) -> Result<(), TrainError> {
    if !path.exists() {
        return Ok(());
    }
    let file = File::open(path).map_err(io_err(path))?;
    let mut kept = String::new();
    for (k, line) in BufReader::new(file).lines().enumerate() {
        let line = line.map_err(io_err(path))?;
        let keep =
            k == 0 || line.split(',').next().and_then(|s| s.parse::<u64>().ok()).is_some_and(|s| s <= step);
        if keep {
            kept.push_str(&line);
            kept.push('\n');
        }
    }
    std::fs::write(path, kept).map_err(io_err(path))
}

/// Saves a checkpoint ([`crate::checkpoint::save`]) of `sac`, `state` and, when
/// `state.has_replay`, `replay`.
fn save_checkpoint(
    out_dir: &Path,
    sac: &Sac,
    replay: &ReplayBuffer,
    state: &TrainState,
) -> Result<(), TrainError> {
    let text = toml::to_string(state).map_err(|e| TrainError::Resume(format!("serialising state: {e}")))?;
    Ok(checkpoint::save(out_dir, sac, state.has_replay.then_some(replay), &text)?)
}

/// The actor of `sac` encoded as a policy file (hand metadata from
/// [`crate::policy_export`], provenance with the config hash, seed and steps).
pub fn export_actor(config: &Config, sac: &Sac, steps: u64) -> Result<Vec<u8>, TrainError> {
    let hidden: Vec<usize> = config.sac.hidden.iter().map(|&h| h as usize).collect();
    let provenance = Provenance {
        vge_version: env!("CARGO_PKG_VERSION").to_owned(),
        config_hash: config.hash_hex(),
        seed: config.seed,
        steps,
    };
    Ok(export_hand_actor(&sac.actor_vs, &hidden, &config.env.env_config(0), provenance)?)
}

/// The success test ([`crate::eval`]) of an exported actor (policy-file bytes) on the
/// runtime: `run.eval_episodes` episodes of `run.eval_episode_s` from grasps randomised by
/// `run.eval_grasp_noise_rad`, seeded from the config's seed only (training is not
/// perturbed).
fn evaluate_policy(config: &Config, bytes: &[u8], set: EpisodeSet) -> Result<EvalReport, TrainError> {
    let run = &config.run;
    let env = crate::eval::success_test_env(
        &config.env.env_config(0),
        run.eval_episode_s,
        run.eval_grasp_noise_rad,
    );
    let eval_seed = match set {
        EpisodeSet::Validation => config.seed.wrapping_mul(1_000_003).wrapping_add(0xe7a1),
        EpisodeSet::Test => config.seed.wrapping_mul(1_000_033).wrapping_add(0x7e57),
    };
    Ok(crate::eval::eval_policy_bytes(bytes, &env, run.eval_episodes.max(1), eval_seed)?)
}

/// Which grasps an evaluation draws: the periodic (and final) evaluations share one set, the
/// validation episodes a snapshot is selected on; the selected snapshot is then reported on
/// the test set, which nothing was selected on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum EpisodeSet {
    Validation,
    Test,
}

const SNAPSHOT_DIR: &str = "snapshots";

fn snapshot_path(out_dir: &Path, step: u64) -> PathBuf {
    out_dir.join(SNAPSHOT_DIR).join(format!("policy-{step}.vgep"))
}

/// One row of `eval.csv`, as model selection reads it.
#[derive(Debug, Clone, Copy)]
struct EvalRow {
    step: u64,
    mean_return: f64,
    success: f64,
}

/// The evaluation row model selection picks: highest success rate, then highest return, then
/// the earlier step.
fn best_eval_row(rows: &[EvalRow]) -> Option<EvalRow> {
    rows.iter().copied().fold(None, |best: Option<EvalRow>, r| match best {
        Some(b) if (b.success, b.mean_return) >= (r.success, r.mean_return) => Some(b),
        _ => Some(r),
    })
}

/// What `best-eval.json` holds: which snapshot was selected on the validation episodes, and
/// its success test on the held-out test episodes.
#[derive(Debug, Serialize)]
struct BestEval<'a> {
    selected_step: u64,
    validation_success_rate: f64,
    validation_mean_return: f64,
    /// Whether the selected policy learned on the test episodes.
    learned: bool,
    success_rate: f64,
    episodes: usize,
    mean_return: f64,
    mean_rotation_rad: f64,
    drop_rate: f64,
    mean_contact_switches: f64,
    per_episode: &'a [EpisodeOutcome],
}

/// Model selection ([module docs](self)): copies the best snapshot to `policy-best.vgep` and
/// writes its test-set evaluation to `best-eval.json`. A run without periodic evaluations
/// (or without their snapshots, as runs older than this rule) has nothing to select from.
fn select_best_snapshot(out_dir: &Path, config: &Config) -> Result<(), TrainError> {
    let csv_path = out_dir.join("eval.csv");
    if !csv_path.exists() {
        return Ok(());
    }
    let text = std::fs::read_to_string(&csv_path).map_err(io_err(&csv_path))?;
    let rows = parse_eval_rows(&text).map_err(|e| io_err(&csv_path)(std::io::Error::other(e)))?;
    let Some(best) = best_eval_row(&rows) else { return Ok(()) };
    let snapshot = snapshot_path(out_dir, best.step);
    let bytes = match std::fs::read(&snapshot) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            eprintln!("model selection skipped: {} is missing", snapshot.display());
            return Ok(());
        }
        Err(e) => return Err(io_err(&snapshot)(e)),
    };
    let r = evaluate_policy(config, &bytes, EpisodeSet::Test)?;
    let path = out_dir.join("policy-best.vgep");
    std::fs::write(&path, &bytes).map_err(io_err(&path))?;
    let doc = BestEval {
        selected_step: best.step,
        validation_success_rate: best.success,
        validation_mean_return: best.mean_return,
        learned: r.learned(),
        success_rate: r.success_rate,
        episodes: r.episodes,
        mean_return: r.mean_return,
        mean_rotation_rad: r.mean_rotation_rad,
        drop_rate: r.drop_rate,
        mean_contact_switches: r.mean_contact_switches,
        per_episode: &r.per_episode,
    };
    let path = out_dir.join("best-eval.json");
    let text = serde_json::to_string_pretty(&doc).map_err(|e| io_err(&path)(std::io::Error::other(e)))?;
    std::fs::write(&path, text + "\n").map_err(io_err(&path))
}

/// `eval.csv` as written by [`append_eval_row`] (columns found by name in the header).
fn parse_eval_rows(text: &str) -> Result<Vec<EvalRow>, String> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).ok_or(format!("no column {name}"));
    let (step_i, return_i, success_i) = (col("step")?, col("return")?, col("success")?);
    lines
        .filter(|l| !l.trim().is_empty())
        .enumerate()
        .map(|(i, line)| {
            let cells: Vec<&str> = line.split(',').collect();
            let cell = |j: usize| cells.get(j).copied().ok_or(format!("row {}: too few cells", i + 1));
            let bad = |e: &dyn std::fmt::Display| format!("row {}: {e}", i + 1);
            Ok(EvalRow {
                step: cell(step_i)?.parse().map_err(|e| bad(&e))?,
                mean_return: cell(return_i)?.parse().map_err(|e| bad(&e))?,
                success: cell(success_i)?.parse().map_err(|e| bad(&e))?,
            })
        })
        .collect()
}

const EVAL_HEADER: &str = "step,episodes,return,rotation,success,drops,contacts,contact_switches";

/// Appends one evaluation to `eval.csv`.
fn append_eval_row(out_dir: &Path, step: u64, r: &EvalReport) -> Result<(), TrainError> {
    let path = out_dir.join("eval.csv");
    let new = !path.exists();
    let mut f = File::options().append(true).create(true).open(&path).map_err(io_err(&path))?;
    let mut text = String::new();
    if new {
        text.push_str(EVAL_HEADER);
        text.push('\n');
    }
    text.push_str(&format!(
        "{step},{},{:.6},{:.6},{:.4},{:.4},{:.4},{:.4}\n",
        r.episodes,
        r.mean_return,
        r.mean_rotation_rad,
        r.success_rate,
        r.drop_rate,
        r.mean_contacts,
        r.mean_contact_switches
    ));
    f.write_all(text.as_bytes()).map_err(io_err(&path))
}

/// What `final-eval.json` holds: the final policy's success test, and what it cost.
#[derive(Debug, Serialize)]
struct FinalEval<'a> {
    /// Whether the seed learned (success rate >= [`crate::eval::LEARNED_SUCCESS_RATE`]).
    learned: bool,
    success_rate: f64,
    episodes: usize,
    episode_s: f32,
    grasp_noise_rad: f32,
    mean_return: f64,
    mean_rotation_rad: f64,
    drop_rate: f64,
    mean_contact_switches: f64,
    env_steps: u64,
    wall_s: f64,
    per_episode: &'a [EpisodeOutcome],
}

fn write_final_eval(
    out_dir: &Path,
    config: &Config,
    r: &EvalReport,
    env_steps: u64,
    wall_s: f64,
) -> Result<(), TrainError> {
    let path = out_dir.join("final-eval.json");
    let doc = FinalEval {
        learned: r.learned(),
        success_rate: r.success_rate,
        episodes: r.episodes,
        episode_s: config.run.eval_episode_s,
        grasp_noise_rad: config.run.eval_grasp_noise_rad,
        mean_return: r.mean_return,
        mean_rotation_rad: r.mean_rotation_rad,
        drop_rate: r.drop_rate,
        mean_contact_switches: r.mean_contact_switches,
        env_steps,
        wall_s,
        per_episode: &r.per_episode,
    };
    let text = serde_json::to_string_pretty(&doc).map_err(|e| io_err(&path)(std::io::Error::other(e)))?;
    std::fs::write(&path, text + "\n").map_err(io_err(&path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_columns_match_the_csv_header() {
        let names: Vec<&str> =
            metrics_values(0, &Window::default(), 0.0, 0, 0.0).iter().map(|(n, _)| *n).collect();
        assert_eq!(format!("step,{}", names.join(",")), METRICS_HEADER);
    }

    #[test]
    fn model_selection_takes_success_then_return_then_the_earlier_step() {
        let row = |step, mean_return, success| EvalRow { step, mean_return, success };
        assert!(best_eval_row(&[]).is_none());
        let rows =
            [row(1, 50.0, 0.2), row(2, 40.0, 0.8), row(3, 90.0, 0.8), row(4, 90.0, 0.8), row(5, 300.0, 0.1)];
        assert_eq!(best_eval_row(&rows).map(|r| r.step), Some(3));
        let parsed = parse_eval_rows(&format!(
            "{EVAL_HEADER}\n100,20,14.5,1.1,0.0500,0.3,3.0,6.8\n200,20,26.8,0.9,0.8000,1.0,3.1,11.6\n"
        ));
        let steps: Vec<(u64, f64)> = parsed.expect("parses").iter().map(|r| (r.step, r.success)).collect();
        assert_eq!(steps, vec![(100, 0.05), (200, 0.8)]);
        assert!(parse_eval_rows(&format!("{EVAL_HEADER}\n100,20,x,1,0,0,0,0\n")).is_err());
    }
}
