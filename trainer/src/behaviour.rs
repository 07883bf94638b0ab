//! The behaviour policies of the paper's five methods: which action each env takes, the
//! learner's or the controller's.
//!
//! - RL: the learner's action, always; the controller is never queried.
//! - RL+BC: the learner's action, always; the controller is queried on every visited state
//!   (until the hard stop) and its action is returned beside the learner's as the BC target,
//!   never executed.
//! - FGE: every H steps an env draws its source: the controller with probability
//!   [`fge_probability`] (a fixed decay in training steps, independent of the state), else
//!   the learner, and follows it for H steps. The controller is queried only when chosen.
//! - VGE, VGE+BC: every H steps an env queries the controller for `a_psi` and computes
//!   `p_psi = exp(Q(s,a_psi)) / (exp(Q(s,a_pi)) + exp(Q(s,a_psi)))` with Q = min of the twin
//!   critics (the pessimistic estimate SAC itself trusts), evaluated as the logistic of the
//!   difference `sigmoid(Q(s,a_psi) - Q(s,a_pi))` (the same number, without overflow), draws
//!   the source and follows it for H steps.
//!
//! H is also the length of the contact-switching trajectory (config: `vge.horizon`), and a
//! controller picked at a draw starts afresh, so one controller segment runs one whole
//! detach and re-attach.
//!
//! From the hard stop on, the controller is never queried again (all methods). When the
//! controller has no action on a step (too few contacts, QP failure) the learner's action is
//! taken for that step and recorded as the learner's; the segment goes on.
//!
//! A Q query that fails or returns a non-finite value is an error ([`BehaviourError`]): VGE
//! must not quietly fall back to the learner.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use thiserror::Error;

use crate::replay::Source;
use vge_controllers::{Controller, ControllerInput};
use vge_run::config::{BcSection, Config, FgeSection, Method};

/// FGE's probability of following the controller at training step `step`: `p_start` until
/// `decay_start`, linear to `p_end` at `decay_end`, `p_end` after.
pub fn fge_probability(fge: &FgeSection, step: u64) -> f64 {
    if step <= fge.decay_start {
        return fge.p_start;
    }
    if step >= fge.decay_end {
        return fge.p_end;
    }
    let f = (step - fge.decay_start) as f64 / (fge.decay_end - fge.decay_start) as f64;
    fge.p_start + f * (fge.p_end - fge.p_start)
}

/// BC's β at training step `step`: `beta_start` at 0, linear to 0 at `beta_zero_step`, 0 after.
pub fn bc_beta(bc: &BcSection, step: u64) -> f64 {
    if bc.beta_zero_step == 0 || step >= bc.beta_zero_step {
        return 0.0;
    }
    bc.beta_start * (1.0 - step as f64 / bc.beta_zero_step as f64)
}

/// `p_psi` of the paper, as a numerically stable two-way softmax.
pub fn p_controller(q_learner: f64, q_controller: f64) -> f64 {
    let d = q_controller - q_learner;
    if d >= 0.0 {
        1.0 / (1.0 + (-d).exp())
    } else {
        let e = d.exp();
        e / (1.0 + e)
    }
}

/// Counters since the start of training (or a reset of the counters).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BehaviourStats {
    /// Env steps decided.
    pub steps: u64,
    /// Steps whose action was the controller's.
    pub controller_steps: u64,
    /// Calls of `Controller::act`.
    pub controller_queries: u64,
    /// Calls that returned no action.
    pub controller_no_action: u64,
    /// Source draws.
    pub selections: u64,
    /// Draws that chose the controller.
    pub controller_selected: u64,
    /// Sum of p_psi over the VGE draws (mean = sum / selections).
    pub p_psi_sum: f64,
}

impl BehaviourStats {
    /// Share of steps that followed the controller.
    pub fn controller_share(&self) -> f64 {
        if self.steps == 0 { 0.0 } else { self.controller_steps as f64 / self.steps as f64 }
    }
}

/// An env's H-step segment: whom it follows and for how many more steps. A checkpoint taken
/// with episodes in progress keeps it ([`Behaviour::segment`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub source: Source,
    pub remaining: usize,
    /// The controller's state is stale (it was not followed last step, or a new episode).
    pub controller_stale: bool,
}

const FRESH: Segment = Segment { source: Source::Learner, remaining: 0, controller_stale: true };

/// One env's controller and the generator it draws from (reseeded at each of the env's
/// episodes, so that a controller's choices do not depend on the other envs').
pub struct EnvController {
    pub controller: Box<dyn Controller + Send>,
    pub rng: ChaCha8Rng,
    /// The calls made since the collector last took them: a controller's state cannot be
    /// saved, so an episode in progress at a checkpoint is rebuilt by making them again.
    pub calls: Vec<ControllerCall>,
}

impl EnvController {
    pub fn new(controller: Box<dyn Controller + Send>, rng: ChaCha8Rng) -> Self {
        Self { controller, rng, calls: Vec::new() }
    }
}

impl std::fmt::Debug for EnvController {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EnvController").field("calls", &self.calls).finish_non_exhaustive()
    }
}

/// A call of an env's controller that changed its state or drew from its generator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerCall {
    /// `Controller::reset`.
    Reset,
    /// `Controller::act` on the env's state before the step it was made at.
    Act,
}

/// Min-twin Q-values of `(obs, action)` rows, one per row.
pub type QFn<'a> = dyn FnMut(&[&[f32]], &[&[f32]]) -> Result<Vec<f32>, String> + 'a;

/// Why the behaviour policy cannot decide.
#[derive(Debug, Error, PartialEq)]
pub enum BehaviourError {
    #[error("training step {step}: the critic's Q query failed: {message}")]
    QQuery { step: u64, message: String },
    #[error("training step {step}: the critic returned {got} Q-values for {expected} rows")]
    QCount { step: u64, got: usize, expected: usize },
    #[error("training step {step}: non-finite Q (learner {learner}, controller {controller}) in env {env}")]
    QNonFinite { step: u64, env: usize, learner: f32, controller: f32 },
}

/// One env's decision: the action to execute, who chose it, and the controller action the
/// BC loss clones at this state (VGE+BC: the executed controller action; RL+BC: the
/// controller's proposal; otherwise none).
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub action: Vec<f32>,
    pub source: Source,
    pub bc_target: Option<Vec<f32>>,
}

/// What the behaviour policy needs to know at one step.
#[derive(Debug)]
pub struct StepContext<'a> {
    /// Training step (env transitions so far, all envs together).
    pub step: u64,
    /// The critic's observations, one per env.
    pub obs: &'a [Vec<f32>],
    /// The learner's (behaviour) action per env.
    pub learner: &'a [Vec<f32>],
    /// The controllers' view of each env (privileged state); `None` if unavailable.
    pub inputs: &'a [Option<ControllerInput>],
}

/// The behaviour policy over a vector of envs.
#[derive(Debug)]
pub struct Behaviour {
    method: Method,
    horizon: usize,
    hard_stop: u64,
    fge: FgeSection,
    segments: Vec<Segment>,
    pub stats: BehaviourStats,
}

impl Behaviour {
    pub fn new(method: Method, horizon: usize, hard_stop: u64, fge: FgeSection, num_envs: usize) -> Self {
        Self {
            method,
            horizon: horizon.max(1),
            hard_stop,
            fge,
            segments: vec![FRESH; num_envs],
            stats: BehaviourStats::default(),
        }
    }

    pub fn from_config(config: &Config) -> Self {
        Self::new(
            config.method,
            config.vge.horizon,
            config.vge.hard_stop,
            config.fge.clone(),
            config.num_envs,
        )
    }

    /// A new episode in env `i`: the next step draws a source afresh.
    pub fn episode_reset(&mut self, i: usize) {
        if let Some(s) = self.segments.get_mut(i) {
            *s = FRESH;
        }
    }

    /// Env `i`'s segment (a fresh one past the envs).
    pub fn segment(&self, i: usize) -> Segment {
        self.segments.get(i).copied().unwrap_or(FRESH)
    }

    /// Puts env `i` back in `segment` (an episode in progress, from a checkpoint).
    pub fn set_segment(&mut self, i: usize, segment: Segment) {
        if let Some(s) = self.segments.get_mut(i) {
            *s = segment;
        }
    }

    /// Whether the controller may be queried at `step`.
    pub fn controller_active(&self, step: u64) -> bool {
        self.method.queries_controller() && step < self.hard_stop
    }

    /// The decision of every env. `q(obs, actions)` returns min-twin Q-values row by row
    /// (only called by VGE, once per step, for the envs drawing a source, learner rows first
    /// then controller rows). `controllers[i]` is env `i`'s (none for RL); every source draw
    /// comes from `rng`, env by env.
    #[allow(clippy::too_many_arguments)]
    pub fn act(
        &mut self,
        ctx: &StepContext<'_>,
        controllers: &mut [EnvController],
        q: &mut QFn<'_>,
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<Decision>, BehaviourError> {
        let n = ctx.obs.len();
        let mut out: Vec<Decision> = ctx
            .learner
            .iter()
            .map(|a| Decision { action: a.clone(), source: Source::Learner, bc_target: None })
            .collect();
        self.stats.steps += n as u64;
        if !self.controller_active(ctx.step) {
            return Ok(out);
        }
        if self.method == Method::RlBc {
            // The learner acts; the controller only labels the visited states.
            for (i, d) in out.iter_mut().enumerate() {
                d.bc_target = self.query(i, ctx, controllers);
            }
            return Ok(out);
        }
        let drawn = self.draw_sources(ctx, controllers, q, rng, &mut out)?;
        self.continue_segments(ctx, controllers, &drawn, &mut out);
        let bc = self.method.uses_bc();
        for d in &mut out {
            if d.source == Source::Controller {
                self.stats.controller_steps += 1;
                if bc {
                    d.bc_target = Some(d.action.clone());
                }
            }
        }
        Ok(out)
    }

    /// The envs whose segment ended draw their source (VGE: by the softmax over Q of the
    /// learner's and the controller's action, one Q query for all; FGE: by the schedule) and
    /// start a segment of H steps; returns which envs drew.
    fn draw_sources(
        &mut self,
        ctx: &StepContext<'_>,
        controllers: &mut [EnvController],
        q: &mut QFn<'_>,
        rng: &mut ChaCha8Rng,
        out: &mut [Decision],
    ) -> Result<Vec<usize>, BehaviourError> {
        let n = ctx.obs.len();
        let vge = matches!(self.method, Method::Vge | Method::VgeBc);
        // Envs drawing a source this step, and for VGE the controller's proposal.
        let mut drawing: Vec<(usize, Option<Vec<f32>>)> = Vec::new();
        for i in 0..n.min(self.segments.len()) {
            if self.segments[i].remaining > 0 {
                continue;
            }
            let proposal = if vge {
                // A draw starts a fresh controller segment (a whole switch of H steps).
                self.segments[i].controller_stale = true;
                self.query(i, ctx, controllers)
            } else {
                None
            };
            drawing.push((i, proposal));
        }
        let probs = if vge {
            self.vge_probabilities(ctx, &drawing, q)?
        } else {
            let p = fge_probability(&self.fge, ctx.step);
            drawing.iter().map(|_| p).collect()
        };
        let drawn: Vec<usize> = drawing.iter().map(|d| d.0).collect();
        for ((i, proposal), &p) in drawing.into_iter().zip(&probs) {
            let u: f64 = rng.random();
            self.stats.selections += 1;
            if vge {
                self.stats.p_psi_sum += p;
            }
            let seg = &mut self.segments[i];
            seg.remaining = self.horizon;
            if u < p {
                self.stats.controller_selected += 1;
                seg.source = Source::Controller;
                // VGE already has this step's controller action; FGE asks now, afresh.
                let action = if vge {
                    proposal
                } else {
                    seg.controller_stale = true;
                    self.query(i, ctx, controllers)
                };
                if let Some(a) = action {
                    out[i].action = a;
                    out[i].source = Source::Controller;
                }
            } else {
                seg.source = Source::Learner;
                seg.controller_stale = true;
            }
            self.segments[i].remaining -= 1;
        }
        Ok(drawn)
    }

    /// The envs inside a segment follow its source for one more step.
    fn continue_segments(
        &mut self,
        ctx: &StepContext<'_>,
        controllers: &mut [EnvController],
        drawn: &[usize],
        out: &mut [Decision],
    ) {
        let n = ctx.obs.len();
        // Envs continuing a segment.
        #[allow(clippy::needless_range_loop)]
        for i in 0..n.min(self.segments.len()) {
            if drawn.contains(&i) {
                continue;
            }
            let seg = self.segments[i];
            if seg.source == Source::Controller
                && let Some(a) = self.query(i, ctx, controllers)
            {
                out[i].action = a;
                out[i].source = Source::Controller;
            }
            self.segments[i].remaining -= 1;
        }
    }

    /// `p_psi` of each drawing env (0 where the controller had no action), from one Q query.
    fn vge_probabilities(
        &self,
        ctx: &StepContext<'_>,
        drawing: &[(usize, Option<Vec<f32>>)],
        q: &mut QFn<'_>,
    ) -> Result<Vec<f64>, BehaviourError> {
        let rows: Vec<usize> = drawing.iter().filter(|d| d.1.is_some()).map(|d| d.0).collect();
        let k = rows.len();
        let mut values = Vec::new();
        if k > 0 {
            let mut obs: Vec<&[f32]> = rows.iter().map(|&i| ctx.obs[i].as_slice()).collect();
            obs.extend_from_within(..);
            let mut acts: Vec<&[f32]> = rows.iter().map(|&i| ctx.learner[i].as_slice()).collect();
            acts.extend(drawing.iter().filter_map(|d| d.1.as_deref()));
            values = q(&obs, &acts).map_err(|message| BehaviourError::QQuery { step: ctx.step, message })?;
            if values.len() != 2 * k {
                return Err(BehaviourError::QCount { step: ctx.step, got: values.len(), expected: 2 * k });
            }
        }
        let mut next = 0;
        drawing
            .iter()
            .map(|(env, proposal)| {
                let env = *env;
                if proposal.is_none() {
                    return Ok(0.0);
                }
                let (learner, controller) = (values[next], values[k + next]);
                next += 1;
                if !(learner.is_finite() && controller.is_finite()) {
                    return Err(BehaviourError::QNonFinite { step: ctx.step, env, learner, controller });
                }
                Ok(p_controller(f64::from(learner), f64::from(controller)))
            })
            .collect()
    }

    /// Queries controller `i` (resetting it first when its state is stale).
    fn query(
        &mut self,
        i: usize,
        ctx: &StepContext<'_>,
        controllers: &mut [EnvController],
    ) -> Option<Vec<f32>> {
        let (Some(EnvController { controller, rng, calls }), Some(Some(input))) =
            (controllers.get_mut(i), ctx.inputs.get(i))
        else {
            return None;
        };
        if self.segments[i].controller_stale {
            controller.reset(rng);
            calls.push(ControllerCall::Reset);
            self.segments[i].controller_stale = false;
        }
        self.stats.controller_queries += 1;
        calls.push(ControllerCall::Act);
        match controller.act(input, rng) {
            Ok(a) if a.iter().all(|v| v.is_finite()) => Some(a),
            _ => {
                self.stats.controller_no_action += 1;
                None
            }
        }
    }
}
