//! The collector: the training envs side by side, what each env's episode has done so far,
//! and the controllers the behaviour policy may follow in them. It turns actions into
//! replay transitions and finished episodes into the metrics window.

use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use tch::Tensor;
use vge_sim::{Env, EpisodeTracker, NoiseConfig, Observer, PerturbationConfig, SimError, StepResult};

use super::TrainError;
use super::in_progress::{EnvInProgress, EpisodeLog, InProgress};
use super::metrics::{Discount, TrainingObjects, Window};
use crate::behaviour::{Behaviour, ControllerCall, Decision, EnvController, StepContext};
use crate::learner::{Learner, ObsColumns, mix_seed, standard_normal};
use crate::replay::ReplayBuffer;
use vge_controllers::{ControllerInput, IgmConfig};
use vge_run::config::Config;

/// Salt of the behaviour-noise seeds.
const SALT_ACT: u64 = 0xac7;

/// One env's episode so far.
#[derive(Debug, Clone, Default)]
struct EnvEpisode {
    tracker: EpisodeTracker,
    /// The rewards so far (for the episode's discounted Monte-Carlo returns).
    rewards: Vec<f32>,
}

/// An env's random force on the object, sensor noise and drop penalty.
#[derive(Debug, Clone, Copy)]
struct Disturbances {
    noise: NoiseConfig,
    push: PerturbationConfig,
    drop_penalty: f32,
}

/// One training env and what the collector knows of it.
struct EnvSlot {
    env: Env,
    /// Its current observation (the env's full one: what the critic sees).
    obs: Vec<f32>,
    /// What the actor sees of it ([`Observer`]: the same, or joints with their history).
    observer: Observer,
    /// The actor's current observation.
    actor_obs: Vec<f32>,
    episode: EnvEpisode,
    /// What replays its episode so far ([`super::in_progress`]).
    log: EpisodeLog,
    /// Its config's disturbances, which the curricula ramp up to.
    full: Disturbances,
}

pub(super) struct Collector {
    slots: Vec<EnvSlot>,
    /// Env `i`'s controller, for the methods that query one (empty for RL).
    controllers: Vec<EnvController>,
    /// How a stored row splits between the critic and the actor.
    columns: ObsColumns,
    /// Entries of an action (the hand's joints).
    act_dim: usize,
    max_action_rad: f32,
    seed: u64,
    /// The disturbance curricula (`env.perturb_ramp_steps`, `env.noise_ramp_steps`), when on.
    ramp: Option<DisturbanceRamp>,
    /// Which object each env holds, for the per-object metrics.
    objects: TrainingObjects,
    /// Env steps taken so far ([`Self::set_progress`]).
    progress: u64,
    /// The discount of the episodes' returns in the metrics (`sac.gamma`) and their early
    /// steps.
    discount: Discount,
}

/// Raises each env's random force on the object and its drop penalty (over
/// `perturb_ramp_steps`, from step `perturb_ramp_start`) and its sensor noise (over
/// `noise_ramp_steps`, from step 0) linearly from 0 to its config's level; 0 steps: the
/// full level from the start (of the ramp). An env gets the levels of the step its episode
/// starts at.
#[derive(Debug, Clone)]
struct DisturbanceRamp {
    perturb_ramp_steps: u64,
    perturb_ramp_start: u64,
    noise_ramp_steps: u64,
    /// Env steps taken so far.
    step: u64,
}

impl DisturbanceRamp {
    /// How far a ramp of `ramp_steps` that starts at step `start` has come.
    fn fraction(&self, start: u64, ramp_steps: u64) -> f32 {
        match self.step.checked_sub(start) {
            None => 0.0,
            Some(_) if ramp_steps == 0 => 1.0,
            Some(done) => (done as f64 / ramp_steps as f64).min(1.0) as f32,
        }
    }

    /// The ramp as it stood at `step`.
    fn at(&self, step: u64) -> Self {
        Self { step, ..self.clone() }
    }

    /// The disturbances, out of `full`, for an episode starting now (the drop penalty ramps
    /// with the force).
    fn levels(&self, full: Disturbances) -> Disturbances {
        let Disturbances { noise, push, drop_penalty } = full;
        let n = self.fraction(0, self.noise_ramp_steps);
        let p = self.fraction(self.perturb_ramp_start, self.perturb_ramp_steps);
        Disturbances {
            noise: NoiseConfig {
                q_std_rad: noise.q_std_rad * n,
                normal_std_frac: noise.normal_std_frac * n,
                position_std_m: noise.position_std_m * n,
            },
            push: PerturbationConfig {
                force_std_n: push.force_std_n * p,
                force_magnitude_n: push.force_magnitude_n * p,
                ..push
            },
            drop_penalty: drop_penalty * p,
        }
    }
}

impl Collector {
    /// The envs of `config`, not reset yet ([`Self::reset_all`]).
    pub fn new(config: &Config) -> Result<Self, TrainError> {
        let n = config.num_envs;
        let env_configs = (0..n).map(|i| config.env_config(i)).collect::<Result<Vec<_>, _>>()?;
        let set = config.env.observation_set().map_err(|e| SimError::InvalidConfig(e.to_string()))?;
        let first = env_configs.first().ok_or_else(|| SimError::InvalidConfig("no envs".to_owned()))?;
        let columns = ObsColumns::of(first, set);
        let act_dim = first.hand.num_joints();
        let controllers = match config.controller.filter(|_| config.method.queries_controller()) {
            Some(kind) => env_configs
                .iter()
                .map(|e| {
                    EnvController::new(
                        kind.build(e, IgmConfig::default(), config.cs_config(e)),
                        // Reseeded at each episode's start (`reset`).
                        ChaCha8Rng::seed_from_u64(0),
                    )
                })
                .collect(),
            None => Vec::new(),
        };
        let e = &config.env;
        let ramp = (e.perturb_ramp_steps > 0 || e.perturb_ramp_start > 0 || e.noise_ramp_steps > 0)
            .then_some(DisturbanceRamp {
                perturb_ramp_steps: e.perturb_ramp_steps,
                perturb_ramp_start: e.perturb_ramp_start,
                noise_ramp_steps: e.noise_ramp_steps,
                step: 0,
            });
        let slots = env_configs
            .into_iter()
            .map(|c| {
                let full =
                    Disturbances { noise: c.noise, push: c.perturbation, drop_penalty: c.drop_penalty };
                let observer = Observer::new(set, c.hand.num_joints());
                Ok(EnvSlot {
                    env: Env::new(c)?,
                    obs: Vec::new(),
                    observer,
                    actor_obs: Vec::new(),
                    episode: EnvEpisode::default(),
                    log: EpisodeLog::default(),
                    full,
                })
            })
            .collect::<Result<_, SimError>>()?;
        Ok(Self {
            ramp,
            slots,
            controllers,
            columns,
            act_dim,
            max_action_rad: config.env.max_action_rad,
            seed: config.seed,
            objects: TrainingObjects::new(&config.env.objects, n),
            progress: 0,
            discount: Discount::new(config.sac.gamma, config.env.episode_length),
        })
    }

    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Which object each env holds.
    pub fn objects(&self) -> &TrainingObjects {
        &self.objects
    }

    /// Every env's current actor observation as one `[envs, actor obs]` tensor.
    pub fn actor_observation_tensor(&self) -> Tensor {
        let flat: Vec<f32> = self.slots.iter().flat_map(|s| s.actor_obs.iter().copied()).collect();
        Tensor::from_slice(&flat).view([self.len() as i64, self.columns.actor_dim()])
    }

    /// Tells the disturbance curricula how many env steps training has taken: episodes
    /// that start from now on get that step's levels.
    pub fn set_progress(&mut self, step: u64) {
        self.progress = step;
        if let Some(ramp) = &mut self.ramp {
            ramp.step = step;
        }
    }

    pub fn reset_all(&mut self, behaviour: &mut Behaviour, rng: &mut ChaCha8Rng) -> Result<(), TrainError> {
        let all: Vec<usize> = (0..self.len()).collect();
        self.reset(&all, behaviour, rng)
    }

    /// Resets envs `which`, drawing each one's env seed and controller seed from `rng` in
    /// order (the controller seed is drawn for RL too, so that the env seeds are the same
    /// for every method).
    fn reset(
        &mut self,
        which: &[usize],
        behaviour: &mut Behaviour,
        rng: &mut ChaCha8Rng,
    ) -> Result<(), TrainError> {
        let mut seeds = vec![None; self.len()];
        for &i in which {
            let env_seed = rng.next_u64();
            seeds[i] = Some(env_seed);
            let controller_seed = rng.next_u64();
            if let Some(c) = self.controllers.get_mut(i) {
                c.rng = ChaCha8Rng::seed_from_u64(controller_seed);
                c.calls.clear();
            }
            self.slots[i].log =
                EpisodeLog { env_seed, controller_seed, ramp_step: self.progress, ..EpisodeLog::default() };
            behaviour.episode_reset(i);
            if let Some(ramp) = &self.ramp {
                let slot = &mut self.slots[i];
                let d = ramp.levels(slot.full);
                slot.env.set_disturbances(d.noise, d.push)?;
                slot.env.set_drop_penalty(d.drop_penalty)?;
            }
        }
        self.slots.par_iter_mut().zip(seeds.par_iter()).try_for_each(
            |(slot, seed)| -> Result<(), SimError> {
                if let Some(seed) = seed {
                    slot.obs = slot.env.reset(*seed)?.0;
                    slot.actor_obs = slot.observer.start(&slot.obs);
                    slot.episode = EnvEpisode { tracker: slot.env.episode_tracker()?, rewards: Vec::new() };
                }
                Ok(())
            },
        )?;
        Ok(())
    }

    /// The learner's behaviour action in every env: uniform for the first `random_steps`
    /// (the warm-up of a fresh run), else the actor's exploration action with noise seeded
    /// from (seed, step).
    pub fn learner_actions(
        &self,
        learner: &dyn Learner,
        step: u64,
        random_steps: u64,
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<Vec<f32>>, TrainError> {
        let (n, max, act) = (self.len(), self.max_action_rad, self.act_dim);
        if step < random_steps {
            return Ok((0..n).map(|_| (0..act).map(|_| rng.random_range(-max..=max)).collect()).collect());
        }
        let mut noise_rng = ChaCha8Rng::seed_from_u64(mix_seed(self.seed, step, SALT_ACT) as u64);
        let eps = standard_normal(&mut noise_rng, n as i64, act as i64);
        let t = self.actor_observation_tensor();
        let v = Vec::<f32>::try_from(learner.behaviour_action(&t, &eps).contiguous().view(-1))?;
        Ok(v.chunks_exact(act).map(<[f32]>::to_vec).collect())
    }

    /// The executed action of every env: the behaviour policy's choice between the learner's
    /// action and the controller's (Q from `learner`'s critic), clipped to the action bound. A
    /// non-finite action stops the run.
    pub fn behaviour_actions(
        &mut self,
        behaviour: &mut Behaviour,
        learner: &dyn Learner,
        step: u64,
        proposals: &[Vec<f32>],
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<Decision>, TrainError> {
        let inputs: Vec<Option<ControllerInput>> = if behaviour.controller_active(step) {
            self.slots.iter().map(|s| s.env.privileged().map(ControllerInput::from_privileged)).collect()
        } else {
            vec![None; self.len()]
        };
        let obs: Vec<Vec<f32>> = self.slots.iter().map(|s| s.obs.clone()).collect();
        let ctx = StepContext { step, obs: &obs, learner: proposals, inputs: &inputs };
        let (critic_dim, act_dim) = (self.columns.critic_dim, self.act_dim as i64);
        let mut q = |o: &[&[f32]], a: &[&[f32]]| -> Result<Vec<f32>, String> {
            let rows = o.len() as i64;
            let flat = |v: &[&[f32]]| v.iter().flat_map(|r| r.iter().copied()).collect::<Vec<f32>>();
            let ot = Tensor::from_slice(&flat(o)).view([rows, critic_dim]);
            let at = Tensor::from_slice(&flat(a)).view([rows, act_dim]);
            Vec::<f32>::try_from(learner.q_of(&ot, &at).view(-1)).map_err(|e| e.to_string())
        };
        let mut decisions = behaviour.act(&ctx, &mut self.controllers, &mut q, rng)?;
        for (env, d) in decisions.iter_mut().enumerate() {
            if let Some(&value) = d.action.iter().find(|v| !v.is_finite()) {
                return Err(TrainError::NonFiniteAction { step, env, value });
            }
            for v in &mut d.action {
                *v = v.clamp(-self.max_action_rad, self.max_action_rad);
            }
        }
        Ok(decisions)
    }

    /// Steps every env with its decision: the physics alone, touching nothing but the envs,
    /// so that it may run beside the learner's updates ([`super::Trainer`]'s schedule). In
    /// parallel on rayon's pool, or one env after another on the calling thread; each env's
    /// step is the same either way.
    pub fn step_envs(&mut self, decisions: &[Decision], parallel: bool) -> Result<Vec<StepResult>, SimError> {
        let step = |(slot, d): (&mut EnvSlot, &Decision)| slot.env.step(&d.action);
        if parallel {
            self.slots.par_iter_mut().zip(decisions.par_iter()).map(step).collect()
        } else {
            self.slots.iter_mut().zip(decisions).map(step).collect()
        }
    }

    /// Takes the envs' steps ([`Self::step_envs`]): stores the transitions, accounts the
    /// steps and the finished episodes in `window`, and resets the finished envs. Returns the
    /// number of episodes that finished.
    pub fn record(
        &mut self,
        results: &[StepResult],
        decisions: &[Decision],
        replay: &mut ReplayBuffer,
        window: &mut Window,
        behaviour: &mut Behaviour,
        rng: &mut ChaCha8Rng,
    ) -> Result<u64, TrainError> {
        let discount = self.discount;
        let mut finished = Vec::new();
        for (i, ((r, d), slot)) in results.iter().zip(decisions).zip(&mut self.slots).enumerate() {
            let at = u32::try_from(slot.log.actions.len()).unwrap_or(u32::MAX);
            if let Some(c) = self.controllers.get_mut(i) {
                slot.log.calls.extend(c.calls.drain(..).map(|call| (at, call)));
            }
            slot.log.actions.push(d.action.clone());
            let bc_target = d.bc_target.as_deref();
            let next_actor_obs = slot.observer.step(&r.obs);
            let row = self.columns.row(&slot.obs, &slot.actor_obs);
            let next_row = self.columns.row(&r.obs, &next_actor_obs);
            replay.push(&row, &d.action, r.reward, &next_row, r.terminated, d.source, bc_target)?;
            let episode = &mut slot.episode;
            window.switches += u64::from(episode.tracker.record(
                r.reward,
                r.info.object_rotation_rad,
                &r.info.tip_contacts,
                r.info.tip_slip_m,
            ));
            episode.rewards.push(r.reward);
            slot.obs = r.obs.clone();
            slot.actor_obs = next_actor_obs;
            if r.terminated || r.truncated {
                let outcome = episode.tracker.outcome(r.terminated);
                window.add_episode(&outcome, &episode.rewards, discount);
                window.add_object_episode(&self.objects, i, &outcome);
                finished.push(i);
            }
        }
        if !finished.is_empty() {
            self.reset(&finished, behaviour, rng)?;
        }
        Ok(finished.len() as u64)
    }

    /// Every env's episode in progress, for a checkpoint that does not end them.
    pub fn in_progress(&self, behaviour: &Behaviour) -> InProgress {
        let envs = self
            .slots
            .iter()
            .enumerate()
            .map(|(i, s)| EnvInProgress {
                log: s.log.clone(),
                segment: behaviour.segment(i),
                obs: s.obs.clone(),
            })
            .collect();
        InProgress { obs_dim: self.columns.critic_dim as usize, act_dim: self.act_dim, envs }
    }

    /// Puts every env back into its episode in progress at a checkpoint (in place of a
    /// reset): the same reset, actions and controller calls again, in parallel
    /// ([`super::in_progress`]). Returns a note per env whose replay did not arrive at the
    /// observation saved with it (another binary or CPU model than the one that stopped): it
    /// goes on from where the replay took it, or from a new episode where the replay ended
    /// its episode early.
    pub fn restore(
        &mut self,
        saved: &InProgress,
        behaviour: &mut Behaviour,
    ) -> Result<Vec<String>, TrainError> {
        let n = self.len();
        if saved.envs.len() != n {
            return Err(TrainError::Resume(format!(
                "the checkpoint holds {} envs' episodes in progress, the run has {n} envs",
                saved.envs.len()
            )));
        }
        for (i, e) in saved.envs.iter().enumerate() {
            if !e.log.calls.is_empty() && self.controllers.get(i).is_none() {
                return Err(TrainError::Resume(format!(
                    "env {i}'s episode in progress has controller calls, and this run has no controller"
                )));
            }
            if let Some(ramp) = &self.ramp {
                let slot = &mut self.slots[i];
                let d = ramp.at(e.log.ramp_step).levels(slot.full);
                slot.env.set_disturbances(d.noise, d.push)?;
                slot.env.set_drop_penalty(d.drop_penalty)?;
            }
            if let Some(c) = self.controllers.get_mut(i) {
                c.rng = ChaCha8Rng::seed_from_u64(e.log.controller_seed);
                c.calls.clear();
            }
            behaviour.set_segment(i, e.segment);
        }
        let mut controllers: Vec<Option<&mut EnvController>> =
            self.controllers.iter_mut().map(Some).collect();
        controllers.resize_with(n, || None);
        let replayed = self
            .slots
            .par_iter_mut()
            .zip(saved.envs.par_iter())
            .zip(controllers.into_par_iter())
            .enumerate()
            .map(|(i, ((slot, e), controller))| replay(i, slot, e, controller))
            .collect::<Result<Vec<_>, TrainError>>()?;
        let mut notes = Vec::new();
        for (i, r) in replayed.into_iter().enumerate() {
            let steps = saved.envs[i].log.actions.len();
            match r {
                Replayed::Same => {}
                Replayed::Different => notes.push(format!(
                    "env {i}'s episode in progress ({steps} steps) replayed to another state than the \
                     one it stopped in (another vge binary or CPU model?): the run goes on from the \
                     replayed state, no longer bit for bit"
                )),
                Replayed::Ended(k) => {
                    behaviour.episode_reset(i);
                    notes.push(format!(
                        "env {i}'s episode in progress ended at step {k} of {steps} when replayed \
                         (another vge binary or CPU model?): it starts a new episode, and the run is \
                         no longer bit for bit"
                    ));
                }
            }
        }
        Ok(notes)
    }
}

/// How an env's replay went.
enum Replayed {
    /// It arrived at the saved observation, bit for bit.
    Same,
    /// It arrived elsewhere.
    Different,
    /// Its episode ended at this step of the replay; the env starts a new one.
    Ended(usize),
}

/// Env `i`'s episode made again from its log: its reset, then before each step the
/// controller calls made there (on the state that step starts from), then the step.
fn replay(
    i: usize,
    slot: &mut EnvSlot,
    saved: &EnvInProgress,
    mut controller: Option<&mut EnvController>,
) -> Result<Replayed, TrainError> {
    let log = &saved.log;
    let bad = |what: String| TrainError::Resume(format!("env {i}'s episode in progress: {what}"));
    slot.obs = slot.env.reset(log.env_seed)?.0;
    slot.actor_obs = slot.observer.start(&slot.obs);
    slot.episode =
        EnvEpisode { tracker: slot.env.episode_tracker()?, rewards: Vec::with_capacity(log.actions.len()) };
    let mut calls = log.calls.iter().peekable();
    for (k, action) in log.actions.iter().enumerate() {
        while let Some(&(_, call)) = calls.next_if(|(at, _)| *at as usize == k) {
            let c = controller
                .as_deref_mut()
                .ok_or_else(|| bad("a controller call without a controller".into()))?;
            let input = slot
                .env
                .privileged()
                .map(ControllerInput::from_privileged)
                .ok_or_else(|| bad(format!("no state for the controller at step {k}")))?;
            match call {
                ControllerCall::Reset => c.controller.reset(&mut c.rng),
                // Its action was taken or not when it was made; what matters here is the
                // state the call leaves behind (a switching plan, the generator).
                ControllerCall::Act => {
                    let _ = c.controller.act(&input, &mut c.rng);
                }
            }
        }
        if slot.episode.rewards.len() != k {
            return Err(bad(format!("step {k} out of order")));
        }
        let r = slot.env.step(action)?;
        slot.episode.tracker.record(
            r.reward,
            r.info.object_rotation_rad,
            &r.info.tip_contacts,
            r.info.tip_slip_m,
        );
        slot.episode.rewards.push(r.reward);
        slot.actor_obs = slot.observer.step(&r.obs);
        slot.obs = r.obs;
        if r.terminated || r.truncated {
            // The trainer's generator must not move here (that would change every draw after
            // it): the new episode's seeds come from the old one's.
            let (env_seed, controller_seed) = (log.env_seed ^ REPLAY_ENDED_SALT, log.controller_seed);
            slot.obs = slot.env.reset(env_seed)?.0;
            slot.actor_obs = slot.observer.start(&slot.obs);
            slot.episode = EnvEpisode { tracker: slot.env.episode_tracker()?, rewards: Vec::new() };
            if let Some(c) = controller {
                c.rng = ChaCha8Rng::seed_from_u64(controller_seed);
            }
            slot.log =
                EpisodeLog { env_seed, controller_seed, ramp_step: log.ramp_step, ..EpisodeLog::default() };
            return Ok(Replayed::Ended(k + 1));
        }
    }
    if calls.next().is_some() {
        return Err(bad("controller calls past its last step".into()));
    }
    slot.log = log.clone();
    let same = slot.obs.iter().zip(&saved.obs).all(|(a, b)| a.to_bits() == b.to_bits());
    Ok(if same { Replayed::Same } else { Replayed::Different })
}

/// Salt of the seed of the new episode an env starts when its replayed one ended early.
const REPLAY_ENDED_SALT: u64 = 0x5eed_e9d5;

#[cfg(test)]
mod tests {
    use tch::Device;

    use crate::learner::{self, LearnerConfig};

    use super::*;
    use vge_run::config::apply_override;

    /// An actor that outputs NaN (here: weights poisoned) stops the run with an error naming
    /// the step and the env; the NaN is never clipped into a valid action.
    #[test]
    fn a_non_finite_learner_action_stops_the_run_naming_the_step() {
        let mut config = Config::default();
        for o in ["num_envs=2", "method=rl", "sac.hidden=[16, 16]"] {
            apply_override(&mut config, o).expect(o);
        }
        config.validate().expect("valid");
        let learner = learner::build_seeded(LearnerConfig::for_hand(&config).expect("sizes"), Device::Cpu, 0)
            .expect("learner");
        tch::no_grad(|| {
            for (_, mut t) in learner.actor_vs().variables() {
                let _ = t.fill_(f64::NAN);
            }
        });
        let mut behaviour = Behaviour::from_config(&config);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut collector = Collector::new(&config).expect("envs");
        collector.reset_all(&mut behaviour, &mut rng).expect("reset");
        let step = 12_345;
        let proposals = collector.learner_actions(learner.as_ref(), step, 0, &mut rng).expect("forward");
        assert!(proposals.iter().flatten().all(|v| v.is_nan()), "the poisoned actor outputs NaN");
        let err = collector.behaviour_actions(&mut behaviour, learner.as_ref(), step, &proposals, &mut rng);
        match err {
            Err(TrainError::NonFiniteAction { step: s, env: 0, value }) => {
                assert_eq!(s, step);
                assert!(value.is_nan());
            }
            other => panic!("expected NonFiniteAction at step {step}, got {other:?}"),
        }
        let message = TrainError::NonFiniteAction { step, env: 0, value: f32::NAN }.to_string();
        assert!(message.contains("12345") && message.contains("not finite"), "{message}");
    }

    /// With `env.perturb_ramp_steps`, an episode starting at step t gets t / ramp of the
    /// configured force on the object (all of it from the ramp's end on) while the sensor
    /// noise stays at its level throughout, unless `env.noise_ramp_steps` ramps it too;
    /// without either, the env keeps its config's levels.
    #[test]
    fn the_push_curriculum_ramps_the_force_by_the_step_an_episode_starts() {
        let levels = |c: &Collector, i: usize| {
            let e = c.slots[i].env.config();
            (e.noise.q_std_rad, e.noise.normal_std_frac, e.noise.position_std_m, e.perturbation.force_std_n)
        };
        let mut config = Config::default();
        for o in [
            "num_envs=2",
            "method=rl",
            "env.noise_q_std_rad=0.08",
            "env.noise_normal_std_frac=0.4",
            "env.noise_position_std_m=0.002",
            "env.perturb_force_std_n=1.2",
            "env.perturb_change_probability=0.1",
        ] {
            apply_override(&mut config, o).expect(o);
        }
        let full = (0.08, 0.4, 0.002, 1.2);
        let no_push = (0.08, 0.4, 0.002, 0.0);
        let mut behaviour = Behaviour::from_config(&config);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut plain = Collector::new(&config).expect("envs");
        plain.set_progress(0);
        plain.reset_all(&mut behaviour, &mut rng).expect("reset");
        assert_eq!(levels(&plain, 1), full, "no ramp: the config's levels from the start");

        apply_override(&mut config, "env.perturb_ramp_steps=1000").expect("ramp");
        let mut ramped = Collector::new(&config).expect("envs");
        ramped.set_progress(0);
        ramped.reset_all(&mut behaviour, &mut rng).expect("reset");
        assert_eq!(levels(&ramped, 0), no_push);
        ramped.set_progress(250);
        // Only an episode that starts now gets the new level.
        assert_eq!(levels(&ramped, 0), no_push);
        ramped.reset(&[1], &mut behaviour, &mut rng).expect("reset env 1");
        let quarter = levels(&ramped, 1);
        assert_eq!((quarter.0, quarter.1, quarter.2), (0.08, 0.4, 0.002), "noise is not ramped");
        assert!((quarter.3 - 0.3).abs() < 1e-6, "{quarter:?}");
        assert_eq!(levels(&ramped, 0), no_push);
        ramped.set_progress(5000);
        ramped.reset_all(&mut behaviour, &mut rng).expect("reset");
        assert_eq!(levels(&ramped, 0), full, "past the ramp: the full force");
        assert_eq!(ramped.slots[0].env.config().perturbation.change_probability, 0.1);

        // A run from trained networks may ramp the sensor noise too, on its own schedule.
        config.init_from = Some("elsewhere".into());
        apply_override(&mut config, "env.noise_ramp_steps=500").expect("noise ramp");
        let mut both = Collector::new(&config).expect("envs");
        both.set_progress(250);
        both.reset_all(&mut behaviour, &mut rng).expect("reset");
        let (q, n, p, f) = levels(&both, 0);
        for (got, want) in [(q, 0.04), (n, 0.2), (p, 0.001), (f, 0.3)] {
            assert!((got - want).abs() < 1e-6, "{:?}", (q, n, p, f));
        }
        both.set_progress(600);
        both.reset_all(&mut behaviour, &mut rng).expect("reset");
        let (q, n, p, f) = levels(&both, 1);
        assert_eq!((q, n, p), (0.08, 0.4, 0.002), "noise ramp over");
        assert!((f - 0.72).abs() < 1e-6, "force still ramping: {f}");
    }

    /// `env.perturb_ramp_start` holds the force at 0 until its step, then ramps it over
    /// `perturb_ramp_steps` (or switches it on at once with no ramp); the noise is untouched.
    #[test]
    fn a_delayed_push_ramp_starts_at_its_step() {
        let force_at = |config: &Config, step: u64| {
            let mut c = Collector::new(config).expect("envs");
            let mut behaviour = Behaviour::from_config(config);
            c.set_progress(step);
            c.reset_all(&mut behaviour, &mut ChaCha8Rng::seed_from_u64(0)).expect("reset");
            let e = c.slots[0].env.config();
            assert_eq!(e.noise.normal_std_frac, 0.4, "noise at its level at step {step}");
            e.perturbation.force_std_n
        };
        let mut config = Config::default();
        for o in [
            "num_envs=1",
            "method=rl",
            "env.noise_normal_std_frac=0.4",
            "env.perturb_force_std_n=1.2",
            "env.perturb_change_probability=0.1",
            "env.perturb_ramp_start=1000",
        ] {
            apply_override(&mut config, o).expect(o);
        }
        assert_eq!(force_at(&config, 999), 0.0, "no ramp steps: off before the start");
        assert_eq!(force_at(&config, 1000), 1.2, "no ramp steps: full from the start");
        apply_override(&mut config, "env.perturb_ramp_steps=400").expect("ramp");
        assert_eq!(force_at(&config, 0), 0.0);
        assert_eq!(force_at(&config, 1000), 0.0);
        assert!((force_at(&config, 1100) - 0.3).abs() < 1e-6);
        assert_eq!(force_at(&config, 1400), 1.2);
        assert_eq!(force_at(&config, 9000), 1.2);

        // The drop penalty ramps with the force: what it is for is holding under pushes.
        apply_override(&mut config, "env.drop_penalty=40").expect("penalty");
        let penalty_at = |step: u64| {
            let mut c = Collector::new(&config).expect("envs");
            let mut behaviour = Behaviour::from_config(&config);
            c.set_progress(step);
            c.reset_all(&mut behaviour, &mut ChaCha8Rng::seed_from_u64(0)).expect("reset");
            c.slots[0].env.config().drop_penalty
        };
        assert_eq!(penalty_at(999), 0.0);
        assert!((penalty_at(1100) - 10.0).abs() < 1e-5, "{}", penalty_at(1100));
        assert_eq!(penalty_at(9000), 40.0);
    }
}
