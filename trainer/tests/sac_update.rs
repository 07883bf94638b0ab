//! SAC with α = 0, as the `sac-alpha0` runs configure it (`configs/cube-fg-vge.toml` with
//! `algorithm=sac`), checked update by update against the same update written out from the
//! textbook formulas (Haarnoja et al. 2018; CleanRL's `sac_continuous_action`) in plain f64
//! tch on copies of the learner's weights: the soft target, the twin critics' loss, the
//! reparameterised actor loss, their gradients, Adam and the Polyak target.
//!
//! The networks are the runs' (65 observations, 15 actions, 256x256), on a batch of a few
//! rows; each of two updates is checked from the learner's state just before it.
//!
//! Where the learner departs from textbook SAC the reference does the same, named where it
//! does so: observations normalised with fixed statistics and clipped, critics that see
//! actions in units of their range, layer normalisation in the critics' hidden layers, and
//! log σ squashed into [-5, 2] by a tanh (CleanRL's, not the paper's).

use std::collections::HashMap;
use std::io::Cursor;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::{Device, Kind, Tensor};
use vge_trainer::learner::{self, Batch, EntropyCoef, Learner, LearnerConfig, UpdateStats};
use vge_trainer::nets::OBS_CLIP;

const SEED: u64 = 17;
/// Rows per batch: a few, with terminal and non-terminal ones.
const ROWS: i64 = 16;
/// The salt SAC's update mixes into its per-update noise seed (`soft_actor_critic.rs`).
const SAC_NOISE_SALT: u64 = 0x5ac;
/// Adam as PyTorch's defaults (and `optim.rs`) set it.
const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const ADAM_EPS: f64 = 1e-8;
/// CleanRL's range of log σ.
const LOG_STD_MIN: f64 = -5.0;
const LOG_STD_MAX: f64 = 2.0;
/// libtorch's layer-norm epsilon, which the critics use.
const LAYER_NORM_EPS: f64 = 1e-5;

type Params = HashMap<String, Tensor>;

fn copy_all(params: &Params) -> Params {
    params.iter().map(|(n, t)| (n.clone(), t.copy())).collect()
}

fn max_abs(t: &Tensor) -> f64 {
    t.abs().max().double_value(&[])
}

/// The learner's checkpoint files, parsed: file name → (variable name → f64 copy). Read
/// through `save_to_memory`, the learner's own serialisation, so no test hook is needed for
/// the private critics and their target.
fn snapshot(learner: &dyn Learner) -> HashMap<&'static str, Params> {
    learner
        .save_to_memory()
        .expect("serialise the learner")
        .into_iter()
        .map(|(file, bytes)| {
            let named = Tensor::load_multi_from_stream(Cursor::new(bytes)).expect("parse a saved file");
            let named = named.into_iter().map(|(n, t)| (n, t.to_kind(Kind::Double))).collect();
            (file, named)
        })
        .collect()
}

/// Adam written out (Kingma & Ba, Algorithm 1) over named parameters, in a given order (the
/// order of the learner's flat buffers, so that its saved first moment can be compared).
struct Adam {
    names: Vec<String>,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
    t: i32,
    lr: f64,
}

impl Adam {
    /// The learner's optimiser state (`prefix.m`, `prefix.v` and `prefix.step` of its
    /// saved state), split into the parameters of its flat buffer.
    fn from_saved(names: Vec<String>, params: &Params, optim: &Params, prefix: &str, lr: f64) -> Self {
        let split = |flat: &Tensor| {
            let mut offset = 0;
            let mut parts = Vec::new();
            for n in &names {
                let p = &params[n];
                let len = p.numel() as i64;
                parts.push(flat.narrow(0, offset, len).view(p.size().as_slice()).copy());
                offset += len;
            }
            assert_eq!(offset, flat.size()[0], "{prefix}: the flat buffer holds these parameters only");
            parts
        };
        let (m, v) = (split(&optim[&format!("{prefix}.m")]), split(&optim[&format!("{prefix}.v")]));
        let t = optim[&format!("{prefix}.step")].int64_value(&[0]) as i32;
        Self { names, m, v, t, lr }
    }

    fn step(&mut self, params: &mut Params, grads: &[Tensor]) {
        self.t += 1;
        for (i, name) in self.names.iter().enumerate() {
            let g = &grads[i];
            self.m[i] = &self.m[i] * BETA1 + g * (1.0 - BETA1);
            self.v[i] = &self.v[i] * BETA2 + g.square() * (1.0 - BETA2);
            let m_hat = &self.m[i] / (1.0 - BETA1.powi(self.t));
            let v_hat = &self.v[i] / (1.0 - BETA2.powi(self.t));
            let p = &params[name] - m_hat / (v_hat.sqrt() + ADAM_EPS) * self.lr;
            params.insert(name.clone(), p);
        }
    }

    /// 1 where the step m̂ / (√v̂ + ε) is insensitive to the gradient's f32 rounding: √v̂ at
    /// least 1e-4 of its largest in the tensor, or 0 (a unit no row of the batch activates:
    /// no step). Below that a gradient entry can be as small as ε, and its step then swings
    /// with the last digits of a sum that cancelled (an entry of 2e-8 stepped 0.663·lr here
    /// and 0.657·lr in the learner); those entries are only checked to take an Adam-sized
    /// step.
    fn well_conditioned(&self) -> Params {
        let correction = 1.0 - BETA2.powi(self.t);
        let rms: Vec<Tensor> = self.v.iter().map(|v| (v / correction).sqrt()).collect();
        self.names
            .iter()
            .zip(rms)
            .map(|(n, rms)| {
                let floor = max_abs(&rms) * 1e-4;
                (n.clone(), rms.ge(floor).logical_or(&rms.eq(0.0)).to_kind(Kind::Double))
            })
            .collect()
    }

    fn flat_m(&self) -> Tensor {
        Tensor::cat(&self.m.iter().map(|m| m.reshape([-1])).collect::<Vec<_>>(), 0)
    }
}

/// One batch in f64, for the reference.
struct Batch64 {
    obs: Tensor,
    action: Tensor,
    reward: Tensor,
    next_obs: Tensor,
    done: Tensor,
}

/// What one reference update computed, with losses under deliberately wrong formulas that
/// the learner's must be told apart from.
struct Reference {
    critic_loss: f64,
    actor_loss: f64,
    mean_q: f64,
    wrong_critic: Vec<(&'static str, f64)>,
    wrong_actor: Vec<(&'static str, f64)>,
}

/// Textbook SAC with α = 0 on copies of the learner's weights.
struct TextbookSac {
    hidden_layers: usize,
    actor: Params,
    critic: Params,
    target: Params,
    actor_adam: Adam,
    critic_adam: Adam,
    obs_mean: Tensor,
    obs_std: Tensor,
    scale: Tensor,
    gamma: f64,
    tau: f64,
}

fn linear(x: &Tensor, weight: &Tensor, bias: &Tensor) -> Tensor {
    x.matmul(&weight.tr()) + bias
}

/// (h − mean) / √(var + ε) over the features, biased variance, no affine part.
fn layer_norm(h: &Tensor) -> Tensor {
    let mean = h.mean_dim(-1, true, Kind::Double);
    let centred = h - mean;
    let var = centred.square().mean_dim(-1, true, Kind::Double);
    centred / (var + LAYER_NORM_EPS).sqrt()
}

impl TextbookSac {
    /// The learner's parameters, statistics and optimiser state, copied, and its
    /// hyperparameters.
    fn from_learner(learner: &dyn Learner) -> Self {
        let mut files = snapshot(learner);
        let optim = files.remove(learner::OPTIM_FILE).expect("optimiser state");
        let actor = files.remove(learner::ACTOR_FILE).expect("actor file");
        let critic = files.remove(learner::CRITIC_FILE).expect("critic file");
        let target = files.remove(learner::TARGET_FILE).expect("target file");
        let config = learner.config();
        let hidden_layers = config.net.hidden.len();
        // The learner's flat buffers: the actor's trainable variables by name, the critics'
        // layer by layer, weight then bias.
        let mut actor_names: Vec<String> = actor.keys().filter(|n| !n.contains("obs_")).cloned().collect();
        actor_names.sort();
        let critic_names: Vec<String> =
            (0..=hidden_layers).flat_map(|i| [format!("critic.w{i}"), format!("critic.b{i}")]).collect();
        // Observation statistics: the three networks hold the same ones.
        let obs_mean = actor["actor.obs_mean"].copy();
        let obs_std = actor["actor.obs_std"].copy();
        for stats in [&critic, &target] {
            assert_eq!(max_abs(&(&stats["critic.obs_mean"] - &obs_mean)), 0.0);
            assert_eq!(max_abs(&(&stats["critic.obs_std"] - &obs_std)), 0.0);
        }
        Self {
            hidden_layers,
            actor_adam: Adam::from_saved(actor_names, &actor, &optim, "actor_opt", config.actor_lr),
            critic_adam: Adam::from_saved(critic_names, &critic, &optim, "critic_opt", config.critic_lr),
            actor,
            critic,
            target,
            obs_mean,
            obs_std,
            scale: Tensor::from_slice(&config.action_scale).to_kind(Kind::Double),
            gamma: config.gamma,
            tau: config.tau,
        }
    }

    /// Not textbook SAC: observations are standardised by statistics fixed after the warm-up
    /// and clipped.
    fn normalise(&self, obs: &Tensor) -> Tensor {
        ((obs - &self.obs_mean) / &self.obs_std).clamp(-OBS_CLIP, OBS_CLIP)
    }

    /// Mean and log σ of the pre-tanh Gaussian: a ReLU MLP with two heads, log σ squashed
    /// into [LOG_STD_MIN, LOG_STD_MAX] by a tanh (CleanRL).
    fn policy(&self, actor: &Params, obs: &Tensor) -> (Tensor, Tensor) {
        let p = |name: &str| &actor[&format!("actor.{name}")];
        let mut h = self.normalise(obs);
        for l in 0..self.hidden_layers {
            h = linear(&h, p(&format!("l{l}.weight")), p(&format!("l{l}.bias"))).relu();
        }
        let mean = linear(&h, p("mean.weight"), p("mean.bias"));
        let raw = linear(&h, p("log_std.weight"), p("log_std.bias"));
        let log_std = (raw.tanh() + 1.0) * (0.5 * (LOG_STD_MAX - LOG_STD_MIN)) + LOG_STD_MIN;
        (mean, log_std)
    }

    /// a = tanh(u)·scale with u = μ + σ ε, and log π(a|s) of the unit-range action tanh(u):
    /// the Gaussian log-density of u minus log(1 − tanh²u) (+1e-6, CleanRL's guard).
    fn sample(&self, actor: &Params, obs: &Tensor, eps: &Tensor) -> (Tensor, Tensor) {
        let (mean, log_std) = self.policy(actor, obs);
        let sigma = log_std.exp();
        let u = &mean + &sigma * eps;
        let y = u.tanh();
        let z = (&u - &mean) / &sigma;
        let log_gauss = z.square() * -0.5 - &log_std - 0.5 * (2.0 * std::f64::consts::PI).ln();
        let one_minus_y2: Tensor = 1.0 - y.square();
        let log_prob = (log_gauss - (one_minus_y2 + 1e-6).log()).sum_dim_intlist(-1, true, Kind::Double);
        (y * &self.scale, log_prob)
    }

    /// Q of twin `twin` (`[batch, 1]`): a ReLU MLP on (normalised obs, action / scale), layer
    /// norm before each hidden ReLU (not textbook SAC: RLPD's remedy, on in the runs).
    fn q(&self, critic: &Params, obs: &Tensor, action: &Tensor, twin: i64) -> Tensor {
        let mut h = Tensor::cat(&[self.normalise(obs), action / &self.scale], -1);
        for i in 0..=self.hidden_layers {
            let w = critic[&format!("critic.w{i}")].get(twin);
            let b = critic[&format!("critic.b{i}")].get(twin);
            h = h.matmul(&w) + b;
            if i < self.hidden_layers {
                h = layer_norm(&h).relu();
            }
        }
        h
    }

    fn min_q(&self, critic: &Params, obs: &Tensor, action: &Tensor) -> Tensor {
        self.q(critic, obs, action, 0).minimum(&self.q(critic, obs, action, 1))
    }

    /// Leaves requiring gradients, in `names`' order, and a parameter map over them.
    fn leaves(params: &Params, names: &[String]) -> (Vec<Tensor>, Params) {
        let leaves: Vec<Tensor> =
            names.iter().map(|n| params[n].detach().copy().set_requires_grad(true)).collect();
        let map = names.iter().cloned().zip(leaves.iter().map(Tensor::shallow_clone)).collect();
        (leaves, map)
    }

    /// One SAC update: critics, then the actor against the stepped critics (CleanRL's and
    /// the paper's order), then the Polyak target.
    fn update(&mut self, b: &Batch64, eps_next: &Tensor, eps_pi: &Tensor) -> Reference {
        // Target: y = r + γ (1 − d) (min_i Q'_i(s', a') − α log π(a'|s')), a' ~ π(·|s') from
        // the current actor; α = 0 drops the entropy term.
        let (y, y_entropy, y_no_done) = tch::no_grad(|| {
            let (a_next, log_prob_next) = self.sample(&self.actor, &b.next_obs, eps_next);
            let q_next = self.min_q(&self.target, &b.next_obs, &a_next);
            let not_done: Tensor = 1.0 - &b.done;
            let y = &b.reward + &not_done * &q_next * self.gamma;
            let y_entropy = &b.reward + &not_done * (&q_next - &log_prob_next * 0.2) * self.gamma;
            let y_no_done = &b.reward + &q_next * self.gamma;
            (y, y_entropy, y_no_done)
        });

        // Critic loss: MSE of each twin against y (mean over the batch), summed over the twins:
        // CleanRL's qf1_loss + qf2_loss. The paper minimises each critic's J_Q on its own; the
        // sum has the same gradient for each twin's weights. Halving it (a mean over the
        // twins) would halve the gradients, which Adam's step hides but its moments do not.
        let names = self.critic_adam.names.clone();
        let (leaves, critic) = Self::leaves(&self.critic, &names);
        let q1 = self.q(&critic, &b.obs, &b.action, 0);
        let q2 = self.q(&critic, &b.obs, &b.action, 1);
        let mse = |y: &Tensor| (&q1 - y).square().mean(Kind::Double) + (&q2 - y).square().mean(Kind::Double);
        let critic_loss = mse(&y);
        let mean_q = ((q1.mean(Kind::Double) + q2.mean(Kind::Double)) * 0.5).double_value(&[]);
        let wrong_critic = tch::no_grad(|| {
            vec![
                ("mean, not sum, over the twins", critic_loss.double_value(&[]) * 0.5),
                ("an entropy term with alpha 0.2 in the target", mse(&y_entropy).double_value(&[])),
                ("bootstrapping through terminal rows", mse(&y_no_done).double_value(&[])),
            ]
        });
        let critic_grads = Tensor::run_backward(&[&critic_loss], &leaves, false, false);
        let critic_before = copy_all(&self.critic);
        tch::no_grad(|| self.critic_adam.step(&mut self.critic, &critic_grads));

        // Actor loss: mean(α log π(a|s) − min_i Q_i(s, a)), a = tanh(μ + σ ε)·scale
        // reparameterised, Q from the critics just stepped; α = 0 leaves −mean(min Q).
        let names = self.actor_adam.names.clone();
        let (leaves, actor) = Self::leaves(&self.actor, &names);
        let (a_pi, log_prob) = self.sample(&actor, &b.obs, eps_pi);
        let q_pi = self.min_q(&self.critic, &b.obs, &a_pi);
        let actor_loss = -q_pi.mean(Kind::Double);
        let wrong_actor = tch::no_grad(|| {
            vec![
                (
                    "an entropy term with alpha 0.2",
                    (&log_prob * 0.2 - &q_pi).mean(Kind::Double).double_value(&[]),
                ),
                (
                    "Q from the critics before their step",
                    -self.min_q(&critic_before, &b.obs, &a_pi).mean(Kind::Double).double_value(&[]),
                ),
                (
                    "Q1 alone (TD3's actor loss)",
                    -self.q(&self.critic, &b.obs, &a_pi, 0).mean(Kind::Double).double_value(&[]),
                ),
            ]
        });
        let actor_grads = Tensor::run_backward(&[&actor_loss], &leaves, false, false);
        tch::no_grad(|| self.actor_adam.step(&mut self.actor, &actor_grads));

        // Target ← τ θ + (1 − τ) target, with the critics just stepped.
        for (name, theta) in &self.critic {
            let t = &self.target[name] * (1.0 - self.tau) + theta * self.tau;
            self.target.insert(name.clone(), t);
        }
        Reference {
            critic_loss: critic_loss.double_value(&[]),
            actor_loss: actor_loss.double_value(&[]),
            mean_q,
            wrong_critic,
            wrong_actor,
        }
    }
}

/// A batch with both terminal and non-terminal rows; observations spread enough that the
/// normaliser's clip acts on some entries. Actions inside the action bound.
fn batch(obs_dim: i64, act_dim: i64, scale: &Tensor, seed: i64) -> Batch {
    tch::manual_seed(seed);
    let opts = (Kind::Float, Device::Cpu);
    let done: Vec<f32> = (0..ROWS).map(|i| if i % 3 == 1 { 1.0 } else { 0.0 }).collect();
    Batch::new(
        Tensor::randn([ROWS, obs_dim], opts) * 3.0,
        (Tensor::rand([ROWS, act_dim], opts) * 2.0 - 1.0) * scale * 0.9,
        Tensor::randn([ROWS, 1], opts),
        Tensor::randn([ROWS, obs_dim], opts) * 3.0,
        Tensor::from_slice(&done).view([ROWS, 1]),
    )
}

fn batch64(b: &Batch) -> Batch64 {
    let d = |t: &Tensor| t.to_kind(Kind::Double);
    Batch64 {
        obs: d(&b.obs),
        action: d(&b.action),
        reward: d(&b.reward),
        next_obs: d(&b.next_obs),
        done: d(&b.done),
    }
}

/// How closely the learner's parameters follow the reference's after an update.
#[derive(Debug, Default)]
struct Agreement {
    /// Largest |learner − reference| over the entries whose Adam step is well conditioned.
    off: f64,
    /// The same over the other entries (see [`Adam::well_conditioned`]).
    off_ill: f64,
    ill: i64,
    total: i64,
    /// Largest move of a reference parameter in this update.
    moved: f64,
}

fn compare(learner: &Params, reference: &Params, before: &Params, well: &Params) -> Agreement {
    let mut a = Agreement::default();
    for (name, r) in reference {
        let diff = (&learner[name] - r).abs();
        a.moved = a.moved.max(max_abs(&(r - &before[name])));
        a.total += r.numel() as i64;
        match well.get(name) {
            Some(mask) => {
                a.off = a.off.max(max_abs(&(&diff * mask)));
                let ill: Tensor = 1.0 - mask;
                a.off_ill = a.off_ill.max(max_abs(&(&diff * &ill)));
                a.ill += ill.sum(Kind::Double).double_value(&[]) as i64;
            }
            // The observation statistics, which no update touches.
            None => a.off = a.off.max(max_abs(&diff)),
        }
    }
    a
}

fn relative(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-12)
}

#[test]
fn one_sac_alpha0_update_equals_the_textbook_update() {
    // One intra-op thread: a matmul split differently from call to call rounds differently.
    tch::set_num_threads(1);
    let runs_config = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/cube-fg-vge.toml");
    let config =
        vge_run::config::load_config(std::path::Path::new(runs_config), &["algorithm=sac".to_owned()])
            .expect("the runs' config");
    let learner_config = LearnerConfig::for_hand(&config).expect("sizes");
    assert_eq!(learner_config.entropy, EntropyCoef::Fixed(0.0), "the runs' SAC has a fixed alpha of 0");
    let mut sac = learner::build_seeded(learner_config, Device::Cpu, SEED).expect("sac");
    let (obs_dim, act_dim) = (sac.config().net.obs_dim, sac.config().net.act_dim);
    let scale = Tensor::from_slice(&sac.config().action_scale);

    // Statistics as the warm-up would fix them; one dimension's small std makes the clip act.
    let mean: Vec<f32> = (0..obs_dim).map(|i| (i % 5) as f32 * 0.3 - 0.6).collect();
    let std: Vec<f32> = (0..obs_dim).map(|i| if i % 7 == 3 { 0.1 } else { 0.5 + (i % 4) as f32 }).collect();
    sac.set_obs_normalisation(&mean, &std);

    // Two updates, each checked from the learner's state before it (weights and Adam's
    // moments): the second exercises Adam past step 1 and the noise seed of update 1.
    for k in 0..2u64 {
        let mut reference = TextbookSac::from_learner(sac.as_ref());
        assert_eq!((sac.updates(), reference.actor_adam.t as u64, reference.critic_adam.t as u64), (k, k, k));
        let b = batch(obs_dim, act_dim, &scale, 100 + k as i64);
        let b64 = batch64(&b);
        // The update's noise, drawn as the learner documents: a generator seeded by
        // (seed, update index), first ε for a' at s', then ε for a at s.
        let mut rng = ChaCha8Rng::seed_from_u64(learner::mix_seed(SEED, k, SAC_NOISE_SALT) as u64);
        let eps_next = learner::standard_normal(&mut rng, ROWS, act_dim).to_kind(Kind::Double);
        let eps_pi = learner::standard_normal(&mut rng, ROWS, act_dim).to_kind(Kind::Double);
        let (actor_before, critic_before, target_before) =
            (copy_all(&reference.actor), copy_all(&reference.critic), copy_all(&reference.target));

        let expected = reference.update(&b64, &eps_next, &eps_pi);
        let stats: UpdateStats = sac.update(&b);
        let saved = snapshot(sac.as_ref());

        assert_eq!(stats.alpha, 0.0, "update {k}");
        assert_eq!(stats.bc_loss, 0.0, "update {k}");
        let (rc, ra, rq) = (
            relative(stats.critic_loss, expected.critic_loss),
            relative(stats.actor_loss, expected.actor_loss),
            relative(stats.mean_q, expected.mean_q),
        );
        eprintln!(
            "update {k}: critic loss {} vs {} (rel {rc:.1e}), actor loss {} vs {} (rel {ra:.1e}), mean Q rel {rq:.1e}",
            stats.critic_loss, expected.critic_loss, stats.actor_loss, expected.actor_loss
        );
        assert!(rc < 1e-5, "update {k}: critic loss {} vs {}", stats.critic_loss, expected.critic_loss);
        assert!(ra < 1e-5, "update {k}: actor loss {} vs {}", stats.actor_loss, expected.actor_loss);
        assert!(rq < 1e-5, "update {k}: mean Q {} vs {}", stats.mean_q, expected.mean_q);
        // The comparisons can fail: each wrong formula lands far outside the tolerance.
        for (what, wrong) in &expected.wrong_critic {
            let r = relative(stats.critic_loss, *wrong);
            assert!(r > 1e-3, "update {k}: critic loss also matches {what} (rel {r:.1e})");
        }
        for (what, wrong) in &expected.wrong_actor {
            let r = relative(stats.actor_loss, *wrong);
            assert!(r > 1e-3, "update {k}: actor loss also matches {what} (rel {r:.1e})");
        }

        // Gradients, magnitude included (Adam's step hides a gradient's scale): the learner's
        // saved first moment against the reference's.
        let optim = &saved[learner::OPTIM_FILE];
        for (which, adam) in [("actor", &reference.actor_adam), ("critic", &reference.critic_adam)] {
            let m = adam.flat_m();
            let off = max_abs(&(&optim[&format!("{which}_opt.m")] - &m)) / max_abs(&m);
            eprintln!("update {k}: {which} Adam first moment off by {off:.1e} of its largest entry");
            assert!(off < 1e-5, "update {k}: {which} gradients off by {off:.1e}");
        }

        // The stepped weights and the target. Adam moves a weight by up to about lr, so the
        // bound on the weights is 1e-3 of that; the target moves by τ times that (1.5e-6),
        // below the resolution of such a fraction in f32 (weights under 0.12 are spaced under
        // 1e-8 apart), so its bound is two such spacings, about 1% of its move.
        let (actor_lr, critic_lr, tau) = (sac.config().actor_lr, sac.config().critic_lr, sac.config().tau);
        let actor_well = reference.actor_adam.well_conditioned();
        let critic_well = reference.critic_adam.well_conditioned();
        for (file, reference_params, before, well, bound, ill_bound) in [
            (
                learner::ACTOR_FILE,
                &reference.actor,
                &actor_before,
                &actor_well,
                1e-3 * actor_lr,
                2.0 * actor_lr,
            ),
            (
                learner::CRITIC_FILE,
                &reference.critic,
                &critic_before,
                &critic_well,
                1e-3 * critic_lr,
                2.0 * critic_lr,
            ),
            (
                learner::TARGET_FILE,
                &reference.target,
                &target_before,
                &critic_well,
                2e-8,
                2.0 * tau * critic_lr,
            ),
        ] {
            let a = compare(&saved[file], reference_params, before, well);
            eprintln!("update {k}: {file} {a:?}");
            assert!(a.moved > 0.0, "update {k}: {file} did not move");
            assert!(
                a.off < bound,
                "update {k}: {file} off by {:.1e} (bound {bound:.1e}, moved {:.1e})",
                a.off,
                a.moved
            );
            assert!(
                a.off_ill < ill_bound,
                "update {k}: {file} ill-conditioned entries off by {:.1e}",
                a.off_ill
            );
            assert!(
                a.ill * 100 < a.total,
                "update {k}: {file}: {} of {} entries ill-conditioned",
                a.ill,
                a.total
            );
        }
    }
}
