//! The training loop: N envs stepped in parallel, the behaviour policy ([`crate::behaviour`]),
//! the replay buffer, `utd` SAC/TD3 updates per transition, a metrics CSV written as it
//! goes, checkpoints, resume, a stop flag, and the final actor exported as `DIR/policy.vgep`.
//!
//! [`train`] is the loop and reads as the paper's Algorithm 2; each concept it uses has its
//! own module: `collector` (the envs, their episodes, acting and storing transitions),
//! `metrics` (the window behind each `metrics.csv` row), `run_folder` (the files a run
//! writes as it goes, the checkpoint), `state` (`state.toml`: counters and the generator),
//! `in_progress` (`episodes.bin`: what replays the envs' episodes through a stop),
//! `evaluation` (periodic and final evaluations, model selection), `clock` (the run's wall
//! and CPU time across sessions).
//!
//! Output directory:
//! - `vge.lock`: held by the one process writing the folder, with its pid
//!   ([`vge_run::run_dir::lock`]);
//! - `config.toml`: the effective configuration;
//! - `metrics.csv`: one row every `run.log_interval` env steps (flushed);
//! - `tensorboard/`: the metrics rows as TensorBoard scalars (`train/<column>`), one event
//!   file per session (`tensorboard --logdir DIR`);
//! - `eval.csv`: deterministic evaluations of the actor every `run.eval_interval` steps;
//! - `checkpoint/`: `state.toml` (counters, generator state, metric window), `actor.ot`,
//!   `critic.ot`, `target.ot`, `target_actor.ot` (TD3), `optim.ot` (Adam moments, α),
//!   `replay.bin` (optional), `episodes.bin` (the envs' episodes in progress, when it keeps
//!   them: a stop, the end), and `manifest.json` (every file's length and CRC-32). It is
//!   written to `checkpoint.tmp/` and renamed, so a SIGKILL leaves the previous one whole, and
//!   a resume verifies every file against the manifest first: a damaged, truncated or
//!   unverifiable checkpoint is refused with the file's name, never resumed
//!   ([`crate::checkpoint`]);
//! - `policy.vgep`: the exported actor at the end, and `final-eval.json` its evaluation,
//!   written last: a run is finished when both read back whole
//!   ([`vge_run::run_dir::check_finished`]);
//! - `snapshots/policy-<step>.vgep`: the actor exported at each periodic evaluation;
//! - `policy-best.vgep`, `best-eval.json`: model selection, reported apart from the final
//!   policy. The snapshot with the best periodic evaluation (success, then return; a run on
//!   several objects: the worst object's success first, see `evaluation`; these are
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
//! it, in an uninterrupted run exactly as in a resumed one. A checkpoint written by a stop
//! (Ctrl-C, SIGTERM) or at the end is the same state by the same path, but the envs'
//! episodes go on through it: it also saves what replays each env's episode so far (its
//! reset seed, actions and controller calls, `in_progress`), and a resume makes them again.
//! Resuming from either kind reproduces the uninterrupted run bit for bit (tested), whatever
//! step the stop came at.
//!
//! Schedule: an iteration's updates sample the replay as it was before the iteration's env
//! step, and its transitions are stored after both. So the envs may step on a core of their
//! own while the updates run ([`learner::ThreadGovernor::overlaps`]) or between them, with
//! the same draws in the same order and the same run bit for bit (tested).

mod clock;
mod collector;
mod in_progress;
mod memory;
mod metrics;
mod run_folder;
mod state;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::Device;
use thiserror::Error;
use vge_sim::{SimError, StepResult};

use crate::behaviour::{Behaviour, BehaviourError, BehaviourStats, Decision, bc_beta};
use crate::checkpoint::CheckpointError;
use crate::learner::{self, Learner, LearnerConfig};
pub use crate::policy_export::export_actor;
use crate::replay::{ReplayBuffer, ReplayError};
use clock::{RunClock, RunCost};
use collector::Collector;
use run_folder::RunFolder;
pub use run_folder::{RUN_FILES, check_no_run};
use state::{Counters, TrainState};
use vge_run::config::{Config, ConfigError};
use vge_run::eval::EvalError;
use vge_run::run_dir::lock::RunLock;
use vge_run::run_eval as evaluation;
pub use vge_run::run_eval::{Rescored, rescore_final_eval};

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
    #[error("init_from {path}: {what}")]
    InitFrom { path: String, what: String },
    #[error("{path}: not a finished run's file: {what}")]
    NotFinished { path: String, what: String },
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error("{dir} already holds a run (found {found}): {advice}")]
    RunExists { dir: String, found: String, advice: String },
    #[error(transparent)]
    Lock(#[from] vge_run::run_dir::lock::LockError),
    #[error("behaviour policy: {0}")]
    Behaviour(#[from] BehaviourError),
    #[error("training step {step}: the learner's action for env {env} is not finite ({value})")]
    NonFiniteAction { step: u64, env: usize, value: f32 },
    #[error(transparent)]
    Score(#[from] vge_run::score::ScoreError),
    #[error(transparent)]
    RunEval(#[from] vge_run::run_eval::RunEvalError),
    #[error(transparent)]
    RunFile(#[from] vge_run::run_dir::RunFileError),
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> TrainError + '_ {
    move |source| TrainError::Io { path: path.display().to_string(), source }
}

/// What the progress callback sees (every loop iteration, i.e. every `num_envs` steps).
#[derive(Debug, Clone, PartialEq)]
pub struct Progress<'a> {
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
    /// A `metrics.csv` row was written at this step (every `run.log_interval`): where no
    /// progress bar can be drawn (a log file, a batch job), this is when to print a line.
    pub logged: bool,
    /// The periodic success test that ran at this step, if one did (`eval.csv`'s new row).
    pub evaluation: Option<&'a vge_run::eval::ObjectsReport>,
    /// Where this session's wall time went so far (`vge bench train` takes the difference
    /// between two steps).
    pub times: PhaseTimes,
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
    /// Gradient updates, with minibatch sampling; with the envs stepping beside them, the
    /// wall time of both.
    pub update_s: f64,
    /// Stepping the envs on a core of their own beside the updates (inside `update_s`, not
    /// added to the total).
    pub sim_beside_updates_s: f64,
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
        write!(f, "{:.1} s: {}", self.total_s, shown.join(", "))?;
        if self.sim_beside_updates_s > 0.0 {
            write!(f, "; beside the updates the envs stepped {:.1} s", self.sim_beside_updates_s)?;
        }
        Ok(())
    }
}

/// Smallest std the observation normaliser divides by: a centimetre for contact positions,
/// and nothing that never varied in the warm-up gets amplified more than 100x.
const OBS_MIN_STD: f32 = 1e-2;

/// The effective configuration stored in a run directory (for `--resume DIR`).
pub fn run_config(dir: &Path) -> Result<Config, TrainError> {
    Ok(vge_run::run_eval::run_config(dir)?)
}

/// Trains `config` into `out_dir`. With `resume`, continues from `out_dir/checkpoint` (the
/// config may raise `total_steps`; other changes make the run a different one). `stop` is
/// polled every iteration: when set, a checkpoint is saved and the call returns with
/// `stopped = true`. `progress` is called every iteration.
///
/// The loop is the paper's Algorithm 2: the learner proposes an action in every env, the
/// behaviour policy follows the learner or the controller (every H steps, by a softmax over
/// the critic's Q, until the hard stop), the transitions go to the replay buffer with the
/// controller's action beside them for BC, and `utd` updates per env step are made on the
/// replay as it was before the step (module docs, "Schedule").
pub fn train(
    config: &Config,
    out_dir: &Path,
    resume: bool,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(&Progress<'_>),
) -> Result<TrainSummary, TrainError> {
    let mut t = Trainer::new(config, out_dir, resume)?;
    match t.run(stop, progress) {
        Ok(stopped) => t.finish(stopped),
        Err(e) => {
            t.abandon_if_unsaved();
            Err(e)
        }
    }
}

impl Trainer<'_> {
    /// The training loop to `total_steps` or a stop; whether the stop flag ended it.
    fn run(
        &mut self,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(&Progress<'_>),
    ) -> Result<bool, TrainError> {
        let t = self;
        let config = t.config;
        // Uniform random actions fill the warm-up, unless the run starts from trained networks.
        let random_steps = if config.init_from.is_some() { 0 } else { config.sac.warmup };
        while t.c.step < config.total_steps {
            if stop.load(Ordering::SeqCst) {
                return Ok(true);
            }
            let iteration = Instant::now();
            t.collector.set_progress(t.c.step);
            let proposals =
                t.collector.learner_actions(t.learner.as_ref(), t.c.step, random_steps, &mut t.rng)?;
            t.lap(Phase::Learner);
            let stats_before = t.behaviour.stats;
            let decisions = t.collector.behaviour_actions(
                &mut t.behaviour,
                t.learner.as_ref(),
                t.c.step,
                &proposals,
                &mut t.rng,
            )?;
            t.lap(Phase::Behaviour);
            let results = t.step_and_update(&decisions)?;
            let (replay, window) = (&mut t.replay, &mut t.c.window);
            let finished =
                t.collector.record(&results, &decisions, replay, window, &mut t.behaviour, &mut t.rng)?;
            t.c.episodes += finished;
            t.c.window.add_behaviour(&stats_before, &t.behaviour.stats);
            let prev_step = t.c.step;
            t.c.step += t.collector.len() as u64;
            t.lap(Phase::Sim);
            // Timed only once updates run: in the warm-up the envs alone are timed, and they
            // step faster between no updates than beside them.
            if t.learner.updates() > 0 {
                t.threads.iteration_took(iteration.elapsed().as_secs_f64());
            }
            t.threads.adapt();
            t.periodic(prev_step, progress)?;
        }
        Ok(false)
    }

    /// After an error: a new run without a checkpoint yet has nothing to resume, and what it
    /// wrote would refuse a new start in its folder, so it is removed (the folder is left as
    /// the run found it). A run with a checkpoint keeps everything: it resumes.
    fn abandon_if_unsaved(&self) {
        if !self.resumed && self.checkpointed_at.is_none() {
            run_folder::remove_run_files(self.folder.dir());
        }
    }
}

/// `utd` gradient updates for each of the `envs` steps of an iteration once the warm-up is
/// over, on minibatches of `replay` with BC weight `beta` (the observation statistics fixed
/// before the first).
fn update(
    config: &Config,
    c: &mut Counters,
    replay: &ReplayBuffer,
    learner: &mut dyn Learner,
    rng: &mut ChaCha8Rng,
    envs: usize,
    beta: f64,
) -> Result<(), TrainError> {
    let batch_size = config.sac.batch;
    if c.step < config.sac.warmup || replay.len() < batch_size {
        return Ok(());
    }
    if learner.updates() == 0 && config.sac.normalize_obs && config.init_from.is_none() {
        // Once; afterwards the statistics live in the networks' var stores and come back
        // with a checkpoint.
        let (mean, std) = replay.obs_stats(OBS_MIN_STD);
        learner.set_obs_normalisation(&mean, &std);
    }
    c.updates_due += envs as f64 * config.sac.utd;
    while c.updates_due >= 1.0 {
        c.updates_due -= 1.0;
        let batch = replay.sample(batch_size, rng, (beta > 0.0).then_some(beta))?;
        let st = learner.update(&batch);
        c.window.add_update(&st);
    }
    Ok(())
}

/// Loads the networks of the run folder `source` into `learner` ([`Config::init_from`]), after
/// checking that its algorithm and network sizes are this run's.
fn init_networks(config: &Config, source: &Path, learner: &mut dyn Learner) -> Result<(), TrainError> {
    let theirs = run_config(source).map_err(|e| TrainError::InitFrom {
        path: source.display().to_string(),
        what: format!("its config.toml: {e}"),
    })?;
    // What the networks' shapes and inputs depend on, as each config spells it.
    let shape = |c: &Config| {
        [
            ("algorithm", c.algorithm.name().to_owned()),
            ("sac.hidden", format!("{:?}", c.sac.hidden)),
            ("sac.critic_layer_norm", c.sac.critic_layer_norm.to_string()),
            ("sac.normalize_obs", c.sac.normalize_obs.to_string()),
        ]
    };
    for ((key, ours), (_, there)) in shape(config).into_iter().zip(shape(&theirs)) {
        if ours != there {
            return Err(TrainError::InitFrom {
                path: source.display().to_string(),
                what: format!("{key} is {there} there and {ours} here"),
            });
        }
    }
    Ok(crate::checkpoint::open(source)?.load_networks(learner)?)
}

/// What a checkpoint does with the envs' episodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Episodes {
    /// They end at it: every env resets right after it, in this run as in a resumed one.
    EndHere,
    /// They go on: the checkpoint saves what replays them (`in_progress`).
    GoOn,
}

/// A line on stderr that is dropped where stderr is gone (a closed pipe): training goes on.
fn note_line(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{line}");
}

/// A phase of [`PhaseTimes`].
#[derive(Debug, Clone, Copy)]
enum Phase {
    Learner,
    Behaviour,
    Sim,
    Update,
    Eval,
    Checkpoint,
}

/// A training session: the learner, its data, the envs and the run's folder.
struct Trainer<'a> {
    config: &'a Config,
    learner: Box<dyn Learner>,
    replay: ReplayBuffer,
    behaviour: Behaviour,
    collector: Collector,
    rng: ChaCha8Rng,
    c: Counters,
    folder: RunFolder,
    config_hash: String,
    /// Wall and CPU time of this run, its earlier sessions included.
    cost: RunClock,
    session_first_step: u64,
    /// The step of the last checkpoint written or resumed from.
    checkpointed_at: Option<u64>,
    /// This session resumed the run (else it started it).
    resumed: bool,
    times: PhaseTimes,
    clock: Instant,
    /// libtorch's threads, fitted to the cores other processes leave idle.
    threads: learner::ThreadGovernor,
    /// This session's latest periodic evaluation (step, report).
    last_evaluation: Option<(u64, vge_run::eval::ObjectsReport)>,
}

/// One writer per folder: a resume reads the checkpoint under the folder's lock, and a new
/// run takes it before looking for signs of a run there (a folder being written is refused
/// naming its writer, not as a run to resume). `None`: no folder yet, for a new run.
fn lock_existing_folder(out_dir: &Path, resume: bool) -> Result<Option<RunLock>, TrainError> {
    if out_dir.is_dir() {
        let lock = RunLock::acquire(out_dir)?;
        if !resume {
            run_folder::check_no_run(out_dir)?;
        }
        Ok(Some(lock))
    } else if resume {
        Err(CheckpointError::NoCheckpoint { out_dir: out_dir.to_owned() }.into())
    } else {
        Ok(None)
    }
}

impl<'a> Trainer<'a> {
    /// A fresh run, or the run in `out_dir` resumed from its checkpoint; envs reset.
    fn new(config: &'a Config, out_dir: &Path, resume: bool) -> Result<Self, TrainError> {
        config.validate()?;
        // Before anything is allocated: what the run needs must fit this machine.
        config.check_fits_memory(&memory::learner_memory_estimate(config)?)?;
        let lock = lock_existing_folder(out_dir, resume)?;
        if config.sac.threads > 0 {
            tch::set_num_threads(config.sac.threads);
        }
        let learner_config = LearnerConfig::for_hand(config)?;
        let (row_dim, act_dim) =
            (learner_config.columns.row_dim() as usize, learner_config.net.act_dim as usize);
        let mut learner = learner::build_seeded(learner_config, Device::Cpu, config.seed)?;
        let mut replay = ReplayBuffer::new(config.sac.buffer_size, row_dim, act_dim)?;
        let mut behaviour = Behaviour::from_config(config);
        let mut collector = Collector::new(config)?;
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let (mut c, mut before) = (Counters::default(), RunCost { wall_s: 0.0, cpu_s: Some(0.0) });
        let mut in_progress = None;
        if resume {
            // Every file is checked against the manifest before any is read.
            let (state, episodes) = run_folder::load_checkpoint(out_dir, learner.as_mut(), &mut replay)?;
            in_progress = episodes;
            rng = state.rng()?;
            c = state.counters();
            behaviour.stats = state.behaviour_stats();
            before = state.cost();
        } else if let Some(source) = config.init_from_dir() {
            init_networks(config, &source, learner.as_mut())?;
        }
        // Only now: a run refused above (a bad init_from, say) leaves no folder behind.
        std::fs::create_dir_all(out_dir).map_err(io_err(out_dir))?;
        let lock = match lock {
            Some(lock) => lock,
            None => {
                let lock = RunLock::acquire(out_dir)?;
                run_folder::check_no_run(out_dir)?;
                lock
            }
        };
        let opened = RunFolder::open(out_dir, config, c.step, resume, lock).and_then(|folder| {
            collector.set_progress(c.step);
            match &in_progress {
                // A checkpoint that kept its episodes (a stop, the end): every env goes on
                // with the episode it was in, as it would have without the stop.
                Some(saved) => {
                    for note in collector.restore(saved, &mut behaviour)? {
                        note_line(&format!("vge: note: {note}"));
                    }
                }
                // A periodic checkpoint: every env resets right after it (module docs).
                None => collector.reset_all(&mut behaviour, &mut rng)?,
            }
            Ok(folder)
        });
        let folder = match opened {
            Ok(folder) => folder,
            Err(e) => {
                if !resume {
                    run_folder::remove_run_files(out_dir);
                }
                return Err(e);
            }
        };
        let now = Instant::now();
        Ok(Self {
            config,
            learner,
            replay,
            behaviour,
            collector,
            rng,
            session_first_step: c.step,
            checkpointed_at: resume.then_some(c.step),
            resumed: resume,
            c,
            folder,
            config_hash: config.hash_hex(),
            cost: RunClock::start(before),
            times: PhaseTimes::default(),
            clock: now,
            threads: learner::ThreadGovernor::start(),
            last_evaluation: None,
        })
    }

    /// Adds the time since the last lap to `phase`.
    fn lap(&mut self, phase: Phase) {
        let now = Instant::now();
        let t = &mut self.times;
        let slot = match phase {
            Phase::Learner => &mut t.learner_s,
            Phase::Behaviour => &mut t.behaviour_s,
            Phase::Sim => &mut t.sim_s,
            Phase::Update => &mut t.update_s,
            Phase::Eval => &mut t.eval_s,
            Phase::Checkpoint => &mut t.checkpoint_s,
        };
        *slot += (now - self.clock).as_secs_f64();
        self.clock = now;
    }

    /// Steps the envs with `decisions` and makes this iteration's updates, which sample the
    /// replay as it was before the step: on a core each when the governor gives the envs one
    /// ([`learner::ThreadGovernor::overlaps`]), else one after the other. The same draws in the
    /// same order either way, so the same run bit for bit.
    fn step_and_update(&mut self, decisions: &[Decision]) -> Result<Vec<StepResult>, TrainError> {
        let beta = self.beta();
        if !self.threads.overlaps() {
            let results = self.collector.step_envs(decisions, true)?;
            self.lap(Phase::Sim);
            let envs = self.collector.len();
            update(self.config, &mut self.c, &self.replay, self.learner.as_mut(), &mut self.rng, envs, beta)?;
            self.lap(Phase::Update);
            return Ok(results);
        }
        let Self { config, collector, learner, replay, rng, c, .. } = self;
        let envs = collector.len();
        let (stepped, updated) = std::thread::scope(|scope| {
            let sim = scope.spawn(|| {
                let started = Instant::now();
                (collector.step_envs(decisions, false), started.elapsed())
            });
            let updated = update(config, c, replay, learner.as_mut(), rng, envs, beta);
            (sim.join(), updated)
        });
        let (results, sim_time) = stepped.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        self.times.sim_beside_updates_s += sim_time.as_secs_f64();
        self.lap(Phase::Update);
        updated?;
        Ok(results?)
    }

    /// BC's weight at the current step (0 for methods without BC).
    fn beta(&self) -> f64 {
        if self.config.method.uses_bc() { bc_beta(&self.config.bc, self.c.step) } else { 0.0 }
    }

    /// What happens on intervals of env steps, after the step from `prev_step`: a metrics
    /// row, an evaluation, progress, a checkpoint.
    fn periodic(
        &mut self,
        prev_step: u64,
        progress: &mut dyn FnMut(&Progress<'_>),
    ) -> Result<(), TrainError> {
        let (config, step) = (self.config, self.c.step);
        let crossed = |interval: u64| interval > 0 && prev_step / interval != step / interval;
        let steps_per_s = (step - self.session_first_step) as f64 / self.cost.session_wall_s().max(1e-9);
        let logged = crossed(config.run.log_interval) || step >= config.total_steps;
        if logged {
            // At the envs' current observations: no draw from any generator, so logging it
            // changes nothing of the run.
            let log_std = self.learner.actor_mean_log_std(&self.collector.actor_observation_tensor());
            let mut values: Vec<(String, Option<f64>)> = self
                .c
                .window
                .values(self.c.episodes, log_std, self.beta(), self.learner.updates(), steps_per_s)
                .into_iter()
                .map(|(name, v)| (name.to_owned(), v))
                .collect();
            if self.folder.object_columns() {
                values.extend(self.c.window.object_values(self.collector.objects()));
            }
            let values: Vec<(&str, Option<f64>)> = values.iter().map(|(n, v)| (n.as_str(), *v)).collect();
            self.folder.log(step, &values)?;
            self.c.last_window = std::mem::take(&mut self.c.window);
        }
        let evaluated = crossed(config.run.eval_interval);
        if evaluated {
            self.lap(Phase::Sim);
            let bytes = export_actor(config, self.learner.as_ref(), step)?;
            let report = evaluation::periodic(self.folder.dir(), config, step, &bytes)?;
            self.last_evaluation = Some((step, report));
            self.lap(Phase::Eval);
        }
        let (mean_return, mean_rotation_rad) = self.c.last_window.mean_return_and_rotation();
        let last = &self.c.last_window;
        progress(&Progress {
            step,
            total_steps: config.total_steps,
            steps_per_s,
            episodes: self.c.episodes,
            mean_return,
            mean_rotation_rad,
            controller_share: last.controller_share(),
            updates: self.learner.updates(),
            logged,
            evaluation: self.last_evaluation.as_ref().filter(|_| evaluated).map(|(_, report)| report),
            times: PhaseTimes { total_s: self.cost.session_wall_s(), ..self.times },
        });
        if crossed(config.run.checkpoint_interval) && step < config.total_steps {
            self.lap(Phase::Sim);
            self.checkpoint(Episodes::EndHere)?;
            self.lap(Phase::Checkpoint);
            // A checkpoint ends every episode (module docs).
            self.collector.set_progress(step);
            self.collector.reset_all(&mut self.behaviour, &mut self.rng)?;
        }
        self.lap(Phase::Sim);
        Ok(())
    }

    /// Saves the run's whole state at this step: one path for the periodic checkpoints, a
    /// stop and the end, which differ only in what becomes of the envs' episodes.
    fn checkpoint(&mut self, episodes: Episodes) -> Result<(), TrainError> {
        let state = TrainState::capture(
            &self.c,
            &self.rng,
            &self.config_hash,
            &self.behaviour.stats,
            self.config.run.save_replay,
            self.cost.now(),
        );
        let in_progress = match episodes {
            Episodes::EndHere => None,
            Episodes::GoOn => Some(self.collector.in_progress(&self.behaviour).to_bytes()),
        };
        self.folder.checkpoint(self.learner.as_ref(), &self.replay, &state, in_progress.as_deref())?;
        self.checkpointed_at = Some(self.c.step);
        Ok(())
    }

    /// Ends the session: a checkpoint, and unless stopped, the exported policy with its
    /// evaluations.
    fn finish(mut self, stopped: bool) -> Result<TrainSummary, TrainError> {
        // A checkpoint taken at this very step holds the state before the env resets that
        // followed it: keep it, so that a resume redoes those resets exactly. Any other step
        // is mid-episode for the envs: the checkpoint keeps their episodes, so that a resume
        // (after a stop, or with more steps after the end) goes on as if nothing had stopped.
        if self.checkpointed_at != Some(self.c.step)
            && let Err(e) = self.checkpoint(Episodes::GoOn)
        {
            self.abandon_if_unsaved();
            return Err(e);
        }
        let policy = if stopped {
            None
        } else {
            let eval_start = Instant::now();
            let bytes = export_actor(self.config, self.learner.as_ref(), self.c.step)?;
            let cost = self.cost.now();
            // The periodic evaluation at this very step ran the same actor on the same episodes.
            let evaluated = self.last_evaluation.take().filter(|(at, _)| *at == self.c.step).map(|(_, r)| r);
            let path =
                evaluation::finish(self.folder.dir(), self.config, &bytes, self.c.step, cost, evaluated)?;
            // The run's score on held-out episodes (`score.json`, vge_run::score), now that every
            // policy it scores is written.
            if self.config.run.score_episodes > 0 {
                let options = vge_run::score::ScoreOptions {
                    episodes: self.config.run.score_episodes,
                    ..Default::default()
                };
                vge_run::score::score_run(self.folder.dir(), &options, &mut |_| {})?;
            }
            self.times.eval_s += eval_start.elapsed().as_secs_f64();
            Some(path)
        };
        Ok(TrainSummary {
            steps: self.c.step,
            updates: self.learner.updates(),
            episodes: self.c.episodes,
            stopped,
            policy,
            behaviour: self.behaviour.stats,
            times: PhaseTimes { total_s: self.cost.session_wall_s(), ..self.times },
        })
    }
}
