//! Roll a sub-skill controller out alone on the simulator (the `vge controller` command):
//! every control step the env's privileged state becomes a [`ControllerInput`], the
//! controller's joint-target change is the env's action (zero when the controller has no
//! action that step, e.g. too few contacts), and the episode runs until the env
//! terminates or truncates it.
//!
//! Measured per episode ([`EpisodeStats`]): the return (sum of the env's rewards), the
//! object's rotation about world z (yaw at the end minus yaw after the grasp settled,
//! unwrapped step by step, so several turns add up), the mean number of fingertip
//! contacts over the steps, and whether the env terminated it (the object fell, or fewer
//! than [`EnvConfig::min_contacts`] fingertips held it): a *drop*. Also the wall time of
//! each controller call (the adapter plus [`Controller::act`]), since the behaviour policy
//! queries the controller every step.

use std::fmt;
use std::str::FromStr;
use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use vge_sim::{Env, EnvConfig, ObjectConfig, ObjectShape, SimError, StepResult};

use super::{Controller, ControllerInput, CsConfig, CsController, FgController, IgmConfig, IgmController};

/// Which controller to roll out (or to guide training with). Serialised as [`Self::name`]
/// gives it (`"fg"`, as configs spell it; serde, unlike [`FromStr`], is case-sensitive).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerKind {
    /// In-grasp manipulation.
    Igm,
    /// Contact switching.
    Cs,
    /// Finger-gaiting (IGM + CS).
    Fg,
}

impl ControllerKind {
    /// All kinds, in a fixed order.
    pub const ALL: [Self; 3] = [Self::Igm, Self::Cs, Self::Fg];

    /// Lower-case name ("igm", "cs", "fg").
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Igm => "igm",
            Self::Cs => "cs",
            Self::Fg => "fg",
        }
    }

    /// The controller with the given configurations (`cs.control_period_s` should be the
    /// env's control period: [`CsConfig::for_env`]).
    #[must_use]
    pub fn build(self, env: &EnvConfig, igm: IgmConfig, cs: CsConfig) -> Box<dyn Controller + Send> {
        let hand = env.hand.clone();
        match self {
            Self::Igm => Box::new(IgmController::new(hand, igm)),
            Self::Cs => Box::new(CsController::new(hand, cs)),
            Self::Fg => Box::new(FgController::new(hand, igm, cs)),
        }
    }
}

impl fmt::Display for ControllerKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ControllerKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown controller kind {s:?} (expected igm, cs or fg)"))
    }
}

/// Everything besides kind, object, episodes and seed.
#[derive(Debug, Clone, PartialEq)]
pub struct RolloutOptions {
    /// The env (its `object` is replaced by the object asked for; its
    /// `episode_length_steps` is the episode length).
    pub env: EnvConfig,
    /// IGM parameters (IGM and FG).
    pub igm: IgmConfig,
    /// CS parameters (CS and FG); `control_period_s` is overwritten with the env's.
    pub cs: CsConfig,
}

impl Default for RolloutOptions {
    /// The default env (20 Hz, 400 steps = 20 s) and the tuned controller defaults.
    fn default() -> Self {
        let env = EnvConfig::default();
        let cs = CsConfig::for_env(&env);
        Self { env, igm: IgmConfig::default(), cs }
    }
}

/// One control step as [`run_episode`] saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct StepTrace {
    /// Control step, 1-based (after the step).
    pub step: usize,
    /// The action applied (zero when the controller had none), one entry per joint.
    pub action: Vec<f32>,
    /// Whether the controller had an action.
    pub acted: bool,
    /// Fingertips touching the object after the step.
    pub contacts: usize,
    /// Which fingertips touch after the step, one entry per finger.
    pub in_contact: Vec<bool>,
    /// Object rotation about z since the episode began (rad, unwrapped).
    pub rotation_rad: f32,
    /// Reward of the step.
    pub reward: f32,
    /// Controller call time (s).
    pub controller_s: f64,
}

/// One episode's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeStats {
    /// Sum of rewards.
    pub episode_return: f32,
    /// Object rotation about world z over the episode (rad, unwrapped).
    pub rotation_rad: f32,
    /// Mean fingertip contacts over the steps.
    pub mean_contacts: f32,
    /// Control steps run.
    pub steps: usize,
    /// The env terminated the episode (object fell or too few contacts).
    pub dropped: bool,
    /// Steps on which the controller had no action.
    pub no_action_steps: usize,
    /// Fingertips that broke and remade contact ([`vge_sim::gait::ContactSwitches`]).
    pub contact_switches: u32,
    /// The success test's verdict ([`vge_sim::EpisodeOutcome::success`]): >= 2π about z
    /// without a drop.
    pub success: bool,
    /// Controller call times (s), one per step.
    pub controller_s: Vec<f64>,
}

/// Resets `env` with `seed`, resets `controller` with a generator seeded from `seed`,
/// and runs one episode through the env's episode loop ([`Env::run_episode`]); `on_step`
/// sees every step.
pub fn run_episode(
    env: &mut Env,
    controller: &mut dyn Controller,
    seed: u64,
    mut on_step: impl FnMut(&StepTrace, &Env),
) -> Result<EpisodeStats, SimError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_c0de_0000_0000);
    controller.reset(&mut rng);
    let mut controller_s = Vec::with_capacity(env.config().episode_length_steps);
    let mut no_action_steps = 0;
    // What the controller did this step, for the trace.
    let joints = env.config().hand.num_joints();
    let last = std::cell::RefCell::new((vec![0.0f32; joints], false, 0.0f64));
    let act = |env: &Env, _: &[f32]| {
        let state = env.privileged().ok_or(SimError::NotReset)?;
        let start = Instant::now();
        let acted = controller.act(&ControllerInput::from_privileged(state), &mut rng);
        let elapsed = start.elapsed().as_secs_f64();
        controller_s.push(elapsed);
        no_action_steps += usize::from(acted.is_err());
        let action = acted.as_ref().map_or_else(|_| vec![0.0; joints], Clone::clone);
        *last.borrow_mut() = (action.clone(), acted.is_ok(), elapsed);
        Ok::<_, SimError>(action)
    };
    let trace = |env: &Env, r: &StepResult, tracker: &vge_sim::EpisodeTracker| {
        let (action, acted, controller_s) = last.borrow().clone();
        on_step(
            &StepTrace {
                step: r.info.step,
                action,
                acted,
                contacts: r.info.num_tip_contacts,
                in_contact: r.info.tip_contacts.clone(),
                rotation_rad: tracker.rotation_rad() as f32,
                reward: r.reward,
                controller_s,
            },
            env,
        );
    };
    let outcome = env.run_episode(seed, act, trace)?;
    Ok(EpisodeStats {
        episode_return: outcome.episode_return as f32,
        rotation_rad: outcome.rotation_rad as f32,
        mean_contacts: outcome.mean_contacts as f32,
        steps: outcome.length,
        dropped: outcome.terminated,
        no_action_steps,
        contact_switches: outcome.contact_switches,
        success: outcome.success(),
        controller_s,
    })
}

/// Mean figures over a rollout.
#[derive(Debug, Clone, PartialEq)]
pub struct RolloutSummary {
    /// Controller rolled out.
    pub kind: ControllerKind,
    /// Object.
    pub object: ObjectShape,
    /// Episodes run.
    pub episodes: usize,
    /// First seed (episode i uses `seed + i`).
    pub seed: u64,
    /// Mean return (sum of rewards, i.e. of the object's z angular velocity in rad/s while
    /// >= 3 fingertips touch, per control step).
    pub mean_return: f32,
    /// Mean object rotation about z per episode (rad).
    pub mean_rotation_rad: f32,
    /// Largest |rotation| of any episode (rad).
    pub max_abs_rotation_rad: f32,
    /// Mean fingertip contacts (over all steps of all episodes).
    pub mean_contacts: f32,
    /// Episodes the env terminated (object fell, or fewer than 3 fingertips held it).
    pub drops: usize,
    /// Share of episodes that passed the success test (>= 2π about z without a drop), the
    /// figure `vge eval` reports for a policy.
    pub success_rate: f32,
    /// Mean contact switches per episode (a fingertip that broke and remade contact).
    pub mean_contact_switches: f32,
    /// Mean episode length (control steps).
    pub mean_steps: f32,
    /// Fraction of steps on which the controller had no action (zero action applied).
    pub no_action_fraction: f32,
    /// Median controller cost per call (adapter + act), microseconds.
    pub controller_median_us: f64,
    /// 90th percentile of the controller cost per call, microseconds.
    pub controller_p90_us: f64,
}

/// Nearest-rank percentile of sorted samples, as vge-export's bench and the bridge's
/// statistics compute it (three copies of four lines: those crates share no crate of ours
/// but the no_std runtime, where a std helper does not belong).
fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

impl RolloutSummary {
    /// One JSON object on one line (no trailing newline), keys: `kind`, `object`,
    /// `episodes`, `seed`, `mean_return`, `mean_rotation_rad`, `max_abs_rotation_rad`,
    /// `mean_contacts`, `drops`, `success_rate`, `mean_contact_switches`, `mean_steps`, `no_action_fraction`,
    /// `controller_median_us`, `controller_p90_us`. Non-finite numbers are `null`.
    #[must_use]
    pub fn to_json_line(&self) -> String {
        // serde_json writes a non-finite number as null.
        serde_json::json!({
            "kind": self.kind.name(),
            "object": self.object.name(),
            "episodes": self.episodes,
            "seed": self.seed,
            "mean_return": self.mean_return,
            "mean_rotation_rad": self.mean_rotation_rad,
            "max_abs_rotation_rad": self.max_abs_rotation_rad,
            "mean_contacts": self.mean_contacts,
            "drops": self.drops,
            "success_rate": self.success_rate,
            "mean_contact_switches": self.mean_contact_switches,
            "mean_steps": self.mean_steps,
            "no_action_fraction": self.no_action_fraction,
            "controller_median_us": self.controller_median_us,
            "controller_p90_us": self.controller_p90_us,
        })
        .to_string()
    }
}

impl fmt::Display for RolloutSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "controller {} on {}: {} episodes from seed {}",
            self.kind,
            self.object.name(),
            self.episodes,
            self.seed
        )?;
        writeln!(f, "  mean return          {:.3}", self.mean_return)?;
        writeln!(
            f,
            "  mean rotation about z {:.3} rad ({:.1} deg), largest |rotation| {:.3} rad",
            self.mean_rotation_rad,
            self.mean_rotation_rad.to_degrees(),
            self.max_abs_rotation_rad
        )?;
        writeln!(f, "  mean fingertip contacts {:.2}", self.mean_contacts)?;
        writeln!(f, "  drops                {} of {}", self.drops, self.episodes)?;
        writeln!(f, "  success (2 pi, no drop) {:.0} %", 100.0 * self.success_rate)?;
        writeln!(f, "  contact switches     {:.1} per episode", self.mean_contact_switches)?;
        writeln!(
            f,
            "  mean episode length  {:.1} steps; no action on {:.1} % of steps",
            self.mean_steps,
            100.0 * self.no_action_fraction
        )?;
        write!(
            f,
            "  controller cost      {:.1} us median, {:.1} us p90 per call",
            self.controller_median_us, self.controller_p90_us
        )
    }
}

/// Rolls `kind` out for `episodes` episodes on `object` (episode i resets the env with
/// `seed + i`); `on_episode` sees each episode's figures as it ends (for progress).
pub fn run_with(
    kind: ControllerKind,
    object: ObjectShape,
    episodes: usize,
    seed: u64,
    options: &RolloutOptions,
    mut on_episode: impl FnMut(usize, &EpisodeStats),
) -> Result<RolloutSummary, SimError> {
    if episodes == 0 {
        return Err(SimError::InvalidConfig("a rollout needs at least one episode".to_owned()));
    }
    let mut env_config = options.env.clone();
    env_config.object = ObjectConfig { shape: object, ..env_config.object };
    let mut cs = options.cs;
    cs.control_period_s = env_config.control_dt_s();
    let mut controller = kind.build(&env_config, options.igm, cs);
    let mut env = Env::new(env_config)?;
    let (mut ret, mut rot, mut max_rot, mut contacts, mut steps, mut drops, mut no_action) =
        (0.0f64, 0.0f64, 0.0f32, 0.0f64, 0usize, 0usize, 0usize);
    let mut switches = 0u64;
    let mut successes = 0usize;
    let mut costs = Vec::new();
    for i in 0..episodes {
        let stats = run_episode(&mut env, controller.as_mut(), seed.wrapping_add(i as u64), |_, _| {})?;
        ret += f64::from(stats.episode_return);
        rot += f64::from(stats.rotation_rad);
        max_rot = max_rot.max(stats.rotation_rad.abs());
        contacts += f64::from(stats.mean_contacts) * stats.steps as f64;
        steps += stats.steps;
        drops += usize::from(stats.dropped);
        no_action += stats.no_action_steps;
        switches += u64::from(stats.contact_switches);
        successes += usize::from(stats.success);
        costs.extend_from_slice(&stats.controller_s);
        on_episode(i, &stats);
    }
    costs.sort_by(f64::total_cmp);
    let n = episodes as f64;
    Ok(RolloutSummary {
        kind,
        object,
        episodes,
        seed,
        mean_return: (ret / n) as f32,
        mean_rotation_rad: (rot / n) as f32,
        max_abs_rotation_rad: max_rot,
        mean_contacts: (contacts / steps.max(1) as f64) as f32,
        drops,
        success_rate: (successes as f64 / n) as f32,
        mean_contact_switches: (switches as f64 / n) as f32,
        mean_steps: (steps as f64 / n) as f32,
        no_action_fraction: (no_action as f64 / steps.max(1) as f64) as f32,
        controller_median_us: percentile(&costs, 0.5) * 1e6,
        controller_p90_us: percentile(&costs, 0.9) * 1e6,
    })
}

/// [`run_with`] without progress.
pub fn run(
    kind: ControllerKind,
    object: ObjectShape,
    episodes: usize,
    seed: u64,
    options: &RolloutOptions,
) -> Result<RolloutSummary, SimError> {
    run_with(kind, object, episodes, seed, options, |_, _| {})
}
