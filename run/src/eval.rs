//! Evaluation: an exported policy file on the `no_std` runtime (deterministic) in the sim,
//! for N episodes with the env's optional noise and perturbations.
//!
//! **The success test** (`vge eval`'s defaults, training's periodic and final evaluation):
//! [`SUCCESS_TEST_EPISODES`] episodes of [`SUCCESS_TEST_EPISODE_S`] from initial grasps
//! randomised by [`SUCCESS_TEST_GRASP_NOISE_RAD`] (so the deterministic policy meets a
//! different state in each). An episode succeeds when the object turned at least 2π about z
//! (unwrapped rotation at the end of the episode) and the episode was not terminated (no
//! drop), the same notion of drop as `vge controller`. Each episode also reports its
//! fingertip contact switches ([`vge_sim::gait`]), the evidence that it gaits, and its
//! fingertip slip ([`vge_sim::slip`]), the evidence that it does not merely spin the object
//! under fingertips that slide over it. A training
//! seed *learns* when its final policy succeeds in at least [`LEARNED_SUCCESS_RATE`] of the
//! episodes.

use std::cell::RefCell;
use std::path::Path;

use rayon::prelude::*;
use serde::Serialize;
use thiserror::Error;
use vge_runtime::Policy;
use vge_sim::{Env, EnvConfig, EpisodeTracker, ObjectShape, Observer, SimError, StepResult};

/// Episodes of the success test.
pub const SUCCESS_TEST_EPISODES: usize = 20;
/// Length of a success-test episode (s).
pub const SUCCESS_TEST_EPISODE_S: f32 = 30.0;
/// Uniform noise (±rad) on the roll and closing angles of the initial grasp: the training
/// protocol's, so that a policy is judged on the grasps it trained from.
pub const SUCCESS_TEST_GRASP_NOISE_RAD: f32 = vge_sim::env_keys::PROTOCOL_GRASP_POSE_NOISE_RAD;
/// Success rate of a final policy at which its seed counts as having learned.
pub const LEARNED_SUCCESS_RATE: f64 = 0.5;

/// Largest network the evaluator loads: layers and width.
pub const EVAL_MAX_LAYERS: usize = 8;
pub const EVAL_MAX_WIDTH: usize = 1024;

#[derive(Debug, Error)]
pub enum EvalError {
    #[error("reading policy {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("policy: {0}")]
    Policy(String),
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("episodes must be at least 1")]
    NoEpisodes,
    #[error("{0}")]
    InvalidOption(String),
    #[error("recording: {0}")]
    Recording(#[from] vge_sim::RecordingError),
}

/// Figures over the evaluated episodes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    pub episodes: usize,
    pub mean_return: f64,
    /// Mean object rotation about world z (rad, unwrapped; positive = the rewarded sense).
    pub mean_rotation_rad: f64,
    /// Share of episodes turned >= 2π without a drop.
    pub success_rate: f64,
    /// Share of episodes the env terminated: a drop (or, where the env is configured to end
    /// episodes below a number of contacts, too few contacts).
    pub drop_rate: f64,
    pub mean_contacts: f64,
    /// Fingertip contact switches per episode ([`vge_sim::gait`]).
    pub mean_contact_switches: f64,
    /// Fingertip slip per episode (m, [`vge_sim::slip`]): how far the fingertips slid over the
    /// object while touching it; with the contact switches it tells a gait from a spin under
    /// fingertips that never let go.
    pub mean_tip_slip_m: f64,
    /// Mean tilt of the axis the object turned about overall, from world z (rad, 0 to π/2;
    /// [`EpisodeOutcome::rotation_axis_tilt_rad`]): near 0 for a turn in an upright grasp, large
    /// for an object tumbling about a tilted axis, whose turning the success test counts only
    /// in its z part.
    pub mean_rotation_axis_tilt_rad: f64,
    pub mean_length: f64,
    /// Every episode, in order.
    pub per_episode: Vec<EpisodeOutcome>,
}

impl EvalReport {
    /// One JSON object on one line.
    pub fn to_json_line(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }

    /// Whether a final policy with this report counts as having learned.
    pub fn learned(&self) -> bool {
        self.success_rate >= LEARNED_SUCCESS_RATE
    }

    /// Share of episodes that pass the success test with the object upright
    /// ([`EpisodeOutcome::upright_success`]: turned about an axis within `max_tilt_rad` of z);
    /// at most `success_rate`.
    pub fn upright_success_rate(&self, max_tilt_rad: f64) -> f64 {
        let upright = self.per_episode.iter().filter(|o| o.upright_success(max_tilt_rad)).count();
        upright as f64 / self.per_episode.len().max(1) as f64
    }
}

pub use vge_sim::EpisodeOutcome;

/// A policy: fills the action (one entry per joint of the env's hand) for an observation
/// (shared by the episodes run side by side).
pub type PolicyFn<'a> = dyn Fn(&[f32], &mut [f32]) -> Result<(), String> + Sync + 'a;

/// The success test's env: `env` with episodes of `episode_s` and initial grasps randomised
/// by `grasp_noise_rad`.
#[must_use]
pub fn success_test_env(env: &EnvConfig, episode_s: f32, grasp_noise_rad: f32) -> EnvConfig {
    let mut env = env.clone();
    env.episode_length_steps = (episode_s * env.control_hz).round().max(1.0) as usize;
    env.grasp.pose_noise_rad = grasp_noise_rad;
    env
}

/// `env` as the success test runs it: without the sensor noise, forces on the object,
/// domain randomisation, drop penalty and early ending on lost contacts that a training
/// config may add for robustness, so that every run is judged by the same test as `vge
/// eval` (the paper's ends: a drop or the time limit). Object, hand, physics, control rate,
/// action bound and upright bound stay: they define the task the policy acts in.
#[must_use]
pub fn without_training_disturbances(env: &EnvConfig) -> EnvConfig {
    let nominal = EnvConfig::default();
    EnvConfig {
        noise: nominal.noise,
        perturbation: nominal.perturbation,
        randomization: nominal.randomization,
        min_contacts: nominal.min_contacts,
        drop_penalty: nominal.drop_penalty,
        ..env.clone()
    }
}

/// Runs `episodes` episodes (env seeds `seed`, `seed + 1`, ...) with `policy(obs, action)`,
/// side by side on rayon's threads (each episode depends on its seed only).
pub fn run_episodes(
    env_config: &EnvConfig,
    episodes: usize,
    seed: u64,
    policy: &PolicyFn<'_>,
) -> Result<EvalReport, EvalError> {
    if episodes == 0 {
        return Err(EvalError::NoEpisodes);
    }
    let outcomes = (0..episodes)
        .into_par_iter()
        .map(|e| run_episode(env_config, seed.wrapping_add(e as u64), policy))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(summarise(&outcomes))
}

/// One episode from env seed `seed`.
pub fn run_episode(
    env_config: &EnvConfig,
    seed: u64,
    policy: &PolicyFn<'_>,
) -> Result<EpisodeOutcome, EvalError> {
    run_episode_traced(env_config, seed, policy, |_, _| {})
}

/// [`run_episode`], with `on_step(tip_contacts, rotation_rad)` after every step (the object's
/// rotation about z so far).
pub fn run_episode_traced(
    env_config: &EnvConfig,
    seed: u64,
    policy: &PolicyFn<'_>,
    mut on_step: impl FnMut(&[bool], f64),
) -> Result<EpisodeOutcome, EvalError> {
    run_episode_observed(env_config, seed, policy, |_, _, r, tracker| {
        on_step(&r.info.tip_contacts, tracker.rotation_rad())
    })
}

/// [`run_episode`], with `on_step(env, action, result, tracker)` after every step: the env
/// after the step and the action the policy chose for it.
pub fn run_episode_observed(
    env_config: &EnvConfig,
    seed: u64,
    policy: &PolicyFn<'_>,
    mut on_step: impl FnMut(&Env, &[f32], &StepResult, &EpisodeTracker),
) -> Result<EpisodeOutcome, EvalError> {
    let mut env = Env::new(env_config.clone())?;
    // `act` chooses the action and `on_step` sees its outcome: both closures read this.
    let joints = env_config.hand.num_joints();
    let last_action = RefCell::new(vec![0.0f32; joints]);
    // What the policy observes, made from the env's full observation; the first call of the
    // episode starts its history.
    let observer = RefCell::new((Observer::new(env_config.observation, joints), true));
    let act = |_: &Env, obs: &[f32]| {
        let mut action = vec![0.0f32; joints];
        let seen = {
            let (observer, first) = &mut *observer.borrow_mut();
            let seen = if *first { observer.start(obs) } else { observer.step(obs) };
            *first = false;
            seen
        };
        policy(&seen, &mut action).map_err(EvalError::Policy)?;
        last_action.borrow_mut().clone_from(&action);
        Ok::<_, EvalError>(action)
    };
    env.run_episode(seed, act, |env, r, tracker| on_step(env, &last_action.borrow(), r, tracker))
}

/// Means over episode outcomes.
pub fn summarise(outcomes: &[EpisodeOutcome]) -> EvalReport {
    let n = outcomes.len().max(1) as f64;
    let mean = |f: &dyn Fn(&EpisodeOutcome) -> f64| outcomes.iter().map(f).sum::<f64>() / n;
    EvalReport {
        episodes: outcomes.len(),
        mean_return: mean(&|o| o.episode_return),
        mean_rotation_rad: mean(&|o| o.rotation_rad),
        success_rate: mean(&|o| f64::from(u8::from(o.success()))),
        drop_rate: mean(&|o| f64::from(u8::from(o.terminated))),
        mean_contacts: mean(&|o| o.mean_contacts),
        mean_contact_switches: mean(&|o| f64::from(o.contact_switches)),
        mean_tip_slip_m: mean(&|o| o.tip_slip_m),
        mean_rotation_axis_tilt_rad: mean(&EpisodeOutcome::rotation_axis_tilt_rad),
        mean_length: mean(&|o| o.length as f64),
        per_episode: outcomes.to_vec(),
    }
}

/// Evaluates an encoded policy file on the runtime. The env runs at the policy's control
/// rate (`env.control_hz` is replaced by the file's).
pub fn eval_policy_bytes(
    bytes: &[u8],
    env: &EnvConfig,
    episodes: usize,
    seed: u64,
) -> Result<EvalReport, EvalError> {
    with_runtime_policy(bytes, env, |env, policy| run_episodes(env, episodes, seed, policy))
}

/// The objects `vge eval --objects` names: `all` (the paper's five, [`ObjectShape::PAPER`])
/// or a comma-separated list of names, each once.
pub fn parse_objects(s: &str) -> Result<Vec<ObjectShape>, String> {
    if s.trim() == "all" {
        return Ok(ObjectShape::PAPER.to_vec());
    }
    let mut objects = Vec::new();
    for name in s.split(',').map(str::trim) {
        let object: ObjectShape = name.parse()?;
        if objects.contains(&object) {
            return Err(format!("`{name}` is named twice in `{s}`"));
        }
        objects.push(object);
    }
    Ok(objects)
}

/// A success test on several objects: each object's report and the overall one, which
/// pools every object's episodes (with as many episodes per object, the mean over objects).
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectsReport {
    pub overall: EvalReport,
    /// Per object, in the order asked for.
    pub per_object: Vec<(ObjectShape, EvalReport)>,
}

impl ObjectsReport {
    /// Each object's upright success rate ([`EvalReport::upright_success_rate`]), in order.
    pub fn upright_success_rates(&self, max_tilt_rad: f64) -> ByObject<f64> {
        ByObject(self.per_object.iter().map(|(o, r)| (*o, r.upright_success_rate(max_tilt_rad))).collect())
    }

    /// The object with the lowest success rate (the first such) and that rate.
    pub fn worst_object(&self) -> Option<(ObjectShape, f64)> {
        self.per_object.iter().map(|(o, r)| (*o, r.success_rate)).fold(None, |worst, (o, s)| match worst {
            Some((_, w)) if w <= s => worst,
            _ => Some((o, s)),
        })
    }

    /// Whether every object's success rate reaches [`LEARNED_SUCCESS_RATE`]: a policy for
    /// several objects has learned only when it turns each of them.
    pub fn every_object_learned(&self) -> bool {
        self.per_object.iter().all(|(_, r)| r.learned())
    }

    /// The figures `per_object` of `final-eval.json`, `best-eval.json` and `vge eval --json`
    /// hold, keyed by object name in the order asked for.
    pub fn figures(&self) -> PerObjectFigures {
        PerObjectFigures(self.per_object.iter().map(|(o, r)| (*o, ObjectFigures::of(r))).collect())
    }
}

/// One object's figures in a per-object report (its episodes are in the overall report).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct ObjectFigures {
    pub success_rate: f64,
    pub drop_rate: f64,
    pub mean_return: f64,
    pub mean_rotation_rad: f64,
    pub mean_contact_switches: f64,
    pub episodes: usize,
}

impl ObjectFigures {
    pub fn of(r: &EvalReport) -> Self {
        Self {
            success_rate: r.success_rate,
            drop_rate: r.drop_rate,
            mean_return: r.mean_return,
            mean_rotation_rad: r.mean_rotation_rad,
            mean_contact_switches: r.mean_contact_switches,
            episodes: r.episodes,
        }
    }
}

/// Per-object figures, serialised as a JSON object keyed by object name in their order.
#[derive(Debug, Clone, PartialEq)]
pub struct PerObjectFigures(pub Vec<(ObjectShape, ObjectFigures)>);

impl PerObjectFigures {
    /// The objects, in order.
    pub fn objects(&self) -> Vec<ObjectShape> {
        self.0.iter().map(|(o, _)| *o).collect()
    }

    /// `object`'s figures, if it is one of these.
    pub fn of(&self, object: ObjectShape) -> Option<&ObjectFigures> {
        self.0.iter().find(|(o, _)| *o == object).map(|(_, f)| f)
    }

    /// The lowest success rate among the objects (None for none).
    pub fn worst_success_rate(&self) -> Option<f64> {
        self.0.iter().map(|(_, f)| f.success_rate).reduce(f64::min)
    }
}

impl<'de> serde::Deserialize<'de> for PerObjectFigures {
    /// Reads the map back in its order; an unknown object name is an error naming it.
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct InOrder;
        impl<'de> serde::de::Visitor<'de> for InOrder {
            type Value = PerObjectFigures;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a map from object name to its figures")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut figures = Vec::new();
                while let Some((name, f)) = map.next_entry::<String, ObjectFigures>()? {
                    figures.push((name.parse::<ObjectShape>().map_err(serde::de::Error::custom)?, f));
                }
                Ok(PerObjectFigures(figures))
            }
        }
        deserializer.deserialize_map(InOrder)
    }
}

impl Serialize for PerObjectFigures {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serialize_by_object(&self.0, serializer)
    }
}

/// One value per object, serialised as a JSON object keyed by object name in their order.
#[derive(Debug, Clone, PartialEq)]
pub struct ByObject<T>(pub Vec<(ObjectShape, T)>);

impl<T: Serialize> Serialize for ByObject<T> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serialize_by_object(&self.0, serializer)
    }
}

/// `entries` as a map keyed by object name, in their order (a JSON object; serde_json's own
/// map would sort the names).
fn serialize_by_object<S: serde::Serializer, T: Serialize>(
    entries: &[(ObjectShape, T)],
    serializer: S,
) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeMap;
    let mut map = serializer.serialize_map(Some(entries.len()))?;
    for (object, value) in entries {
        map.serialize_entry(object.name(), value)?;
    }
    map.end()
}

/// The success test of an encoded policy file on each of `envs` (one per object, each
/// `episodes` episodes from env seeds `seed`, `seed + 1`, ...: every object meets the same
/// seeds), all episodes side by side on rayon's threads. The env runs at the policy's
/// control rate as in [`eval_policy_bytes`].
pub fn eval_policy_bytes_per_object(
    bytes: &[u8],
    envs: &[EnvConfig],
    episodes: usize,
    seed: u64,
) -> Result<ObjectsReport, EvalError> {
    if episodes == 0 || envs.is_empty() {
        return Err(EvalError::NoEpisodes);
    }
    let first = &envs[0];
    with_runtime_policy(bytes, first, |at_rate, policy| {
        // Every env at the policy's rate, as `with_runtime_policy` set the first.
        let envs: Vec<EnvConfig> = envs.iter().map(|e| at_control_rate(e, at_rate.control_hz)).collect();
        let outcomes = (0..envs.len() * episodes)
            .into_par_iter()
            .map(|i| run_episode(&envs[i / episodes], seed.wrapping_add((i % episodes) as u64), policy))
            .collect::<Result<Vec<_>, _>>()?;
        let per_object = envs
            .iter()
            .zip(outcomes.chunks(episodes))
            .map(|(env, chunk)| (env.object.shape, summarise(chunk)))
            .collect();
        Ok(ObjectsReport { overall: summarise(&outcomes), per_object })
    })
}

/// One episode of an encoded policy file on the runtime, step by step: each finger's
/// contact and the object's rotation (for `vge eval --plot`'s gait diagram).
pub fn trace_policy_bytes(bytes: &[u8], env: &EnvConfig, seed: u64) -> Result<GaitTrace, EvalError> {
    with_runtime_policy(bytes, env, |env, policy| {
        let finger_names = env.hand.fingers().iter().map(|f| f.name.clone()).collect();
        let mut trace = GaitTrace { dt_s: 1.0 / env.control_hz, finger_names, ..GaitTrace::default() };
        let outcome = run_episode_traced(env, seed, policy, |contacts, rotation| {
            trace.tip_contacts.push(contacts.to_vec());
            trace.rotation_rad.push(rotation);
        })?;
        trace.outcome = outcome;
        Ok(trace)
    })
}

/// One episode of an encoded policy file on the runtime, recorded into `path` step by step
/// (`vge eval --record`; what it holds: [`vge_sim::recording`]).
pub fn record_policy_bytes(
    bytes: &[u8],
    env: &EnvConfig,
    seed: u64,
    path: &Path,
) -> Result<EpisodeOutcome, EvalError> {
    with_runtime_policy(bytes, env, |env, policy| {
        let mut recorder = vge_sim::EpisodeRecorder::create(path, env)?;
        // The episode loop's callback cannot fail: keep the first error and report it after.
        let mut failure = None;
        let outcome = run_episode_observed(env, seed, policy, |env, action, r, _| {
            if failure.is_none() {
                failure = recorder.record_step(env, action, r).err();
            }
        })?;
        if let Some(e) = failure {
            return Err(e.into());
        }
        recorder.finish()?;
        Ok(outcome)
    })
}

/// One episode's contacts and rotation, step by step.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaitTrace {
    /// Control period (s).
    pub dt_s: f32,
    /// The hand's fingers, in finger order.
    pub finger_names: Vec<String>,
    /// Which fingertips touch the object after each step.
    pub tip_contacts: Vec<Vec<bool>>,
    /// The object's rotation about z since the start, after each step (rad).
    pub rotation_rad: Vec<f64>,
    pub outcome: EpisodeOutcome,
}

/// Loads `bytes` on the runtime and runs `f` with the env at the policy's control rate
/// (`env.control_hz` is replaced by the file's, the episode duration kept) and the policy.
fn with_runtime_policy<T>(
    bytes: &[u8],
    env: &EnvConfig,
    f: impl FnOnce(&EnvConfig, &PolicyFn<'_>) -> Result<T, EvalError>,
) -> Result<T, EvalError> {
    let info = vge_runtime::policy::inspect(bytes).map_err(|e| EvalError::Policy(e.to_string()))?;
    vge_sim::check_policy_interface(&info, &env.hand, &env.policy_layout()).map_err(EvalError::Policy)?;
    let env = at_control_rate(env, info.control_hz);
    // Aligned, so that a version-2 file's arrays are used in place (as on the robot).
    let aligned = vge_runtime::AlignedBytes::new(bytes);
    let mut storage = vec![0.0f32; info.storage_len];
    let policy = Policy::<EVAL_MAX_LAYERS, EVAL_MAX_WIDTH>::load(&aligned, &mut storage)
        .map_err(|e| EvalError::Policy(e.to_string()))?;
    f(&env, &|obs, action| policy.forward(obs, action).map_err(|e| e.to_string()))
}

/// `env` stepped at `control_hz`, its episodes as long in seconds as before.
fn at_control_rate(env: &EnvConfig, control_hz: f32) -> EnvConfig {
    let duration_s = env.episode_length_steps as f32 / env.control_hz;
    let mut env = env.clone();
    env.control_hz = control_hz;
    env.episode_length_steps = (duration_s * env.control_hz).round().max(1.0) as usize;
    env
}

/// [`eval_policy_bytes`] of the file at `path`.
pub fn eval_policy_file(
    path: &Path,
    env: &EnvConfig,
    episodes: usize,
    seed: u64,
) -> Result<EvalReport, EvalError> {
    eval_policy_bytes(&read_policy_file(path)?, env, episodes, seed)
}

/// The longest policy file an evaluation loads ([`vge_runtime::policy::max_file_len`] of
/// [`EVAL_MAX_LAYERS`] and [`EVAL_MAX_WIDTH`]).
pub const EVAL_MAX_FILE_LEN: usize = vge_runtime::policy::max_file_len(EVAL_MAX_LAYERS, EVAL_MAX_WIDTH);

/// The bytes of the policy file at `path`; a file longer than [`EVAL_MAX_FILE_LEN`] (its
/// length from its metadata) is refused unread.
pub fn read_policy_file(path: &Path) -> Result<Vec<u8>, EvalError> {
    vge_export::read_policy_bytes(path, EVAL_MAX_FILE_LEN).map_err(|e| match e {
        vge_export::ExportError::Io { path, source } => {
            EvalError::Io { path: path.display().to_string(), source }
        }
        other => EvalError::Policy(other.to_string()),
    })
}

/// The task a policy file was trained for, as an env: its hand (`hand`, a shipped hand's
/// name or an MJCF path, replaces the recorded one: a hand that is not shipped is found
/// only so), the hand's orientation, the observation set its layout declares, on `object`.
/// A file without a task record is vge's own hand with the full observation. The policy is
/// checked against the env before anything runs.
pub fn policy_task_env(
    bytes: &[u8],
    hand: Option<&str>,
    object: ObjectShape,
) -> Result<EnvConfig, EvalError> {
    let info = vge_runtime::policy::inspect(bytes).map_err(|e| EvalError::Policy(e.to_string()))?;
    let recorded = info.task.as_ref().map_or(vge_runtime::policy::UNRECORDED_HAND, |t| t.hand);
    let spec = hand.unwrap_or(recorded);
    let hand = vge_sim::hands::load(spec).map_err(|e| {
        EvalError::Policy(format!("the policy's hand {spec}: {e} (name its file with --hand PATH)"))
    })?;
    // The hand first: its name says more than a layout that does not fit it.
    vge_sim::policy_interface::check_task(&info, &hand).map_err(EvalError::Policy)?;
    let mut env = EnvConfig::for_hand(hand)?;
    env.object.shape = object;
    if let Some(task) = &info.task
        && !task.orientation.is_empty()
    {
        env.physics.hand_orientation = task.orientation.parse().map_err(EvalError::Policy)?;
    }
    let slices: Vec<(&str, usize, usize)> =
        info.obs_layout.iter().map(|s| (s.name, s.start, s.end)).collect();
    env.observation =
        vge_sim::ObservationSet::of_layout(&slices, env.hand.num_joints(), env.hand.num_fingers())
            .map_err(EvalError::Policy)?;
    vge_sim::check_policy_interface(&info, &env.hand, &env.policy_layout()).map_err(EvalError::Policy)?;
    Ok(env)
}
