//! The SAC networks: a tanh-Gaussian actor and twin Q critics evaluated in one batched pass.
//!
//! Parameter paths are part of the export contract (`vge-export` reads the actor by name):
//! `actor.l{i}` hidden layers, `actor.mean`, `actor.log_std`; `critic.w{i}` / `critic.b{i}`.

use tch::nn::{self, Module};
use tch::{Kind, Tensor};

pub use vge_run::config::MatmulPrecision;

/// Runs `op`, which passes each matmul operand through the cast it is given: unchanged in
/// f32, rounded to bf16 in [`MatmulPrecision::Bf16`] (and the result back to f32). One place
/// for the rounding, whatever the layer's op (linear, addmm, baddbmm).
fn precision_matmul(
    precision: MatmulPrecision,
    op: impl FnOnce(&dyn Fn(&Tensor) -> Tensor) -> Tensor,
) -> Tensor {
    match precision {
        MatmulPrecision::F32 => op(&Tensor::shallow_clone),
        MatmulPrecision::Bf16 => op(&|t: &Tensor| t.to_kind(Kind::BFloat16)).to_kind(Kind::Float),
    }
}
/// log σ is squashed into [LOG_STD_MIN, LOG_STD_MAX] (as in CleanRL's SAC) so that the policy
/// can neither collapse to a point nor explode early in training.
pub const LOG_STD_MIN: f64 = -5.0;
pub const LOG_STD_MAX: f64 = 2.0;

/// Normalised observations are clamped to ±this many standard deviations (the policy file
/// records the same clip, so the runtime computes exactly what the actor saw in training).
pub const OBS_CLIP: f64 = 10.0;

/// `clip((obs - mean) / std)` with statistics stored as non-trainable variables
/// (`{path}.obs_mean`, `{path}.obs_std`), so checkpoints and exports carry them. They start
/// as the identity and are set once, from the warm-up data ([`Self::set`]): raw contact
/// positions vary by centimetres while forces reach tens of newtons, and a critic fed both
/// unscaled diverges.
#[derive(Debug)]
pub struct ObsNormaliser {
    mean: Tensor,
    std: Tensor,
}

impl ObsNormaliser {
    pub fn new(p: &nn::Path, obs_dim: i64) -> Self {
        Self { mean: p.zeros_no_train("obs_mean", &[obs_dim]), std: p.ones_no_train("obs_std", &[obs_dim]) }
    }

    pub fn apply(&self, obs: &Tensor) -> Tensor {
        ((obs - &self.mean) / &self.std).clamp(-OBS_CLIP, OBS_CLIP)
    }

    /// Copies `mean` and `std` (each `[obs_dim]`, std > 0) into the stored statistics.
    pub fn set(&mut self, mean: &Tensor, std: &Tensor) {
        tch::no_grad(|| {
            self.mean.copy_(mean);
            self.std.copy_(std);
        });
    }
}

/// Sizes shared by the actor and critics.
#[derive(Debug, Clone, PartialEq)]
pub struct NetSpec {
    pub obs_dim: i64,
    pub act_dim: i64,
    pub hidden: Vec<i64>,
}

/// PyTorch's default `nn.Linear` initialisation bound for a layer with `fan_in` inputs.
fn linear_bound(fan_in: i64) -> f64 {
    1.0 / (fan_in as f64).sqrt()
}

/// A linear layer initialised as PyTorch's `nn.Linear` (U(±1/√fan_in) for weights and bias),
/// as CleanRL's SAC is. tch's default (Kaiming, ReLU gain) is ~2.4x wider, which starts the
/// actor with means of several units: tanh saturates and exploration collapses.
fn torch_linear(path: nn::Path, fan_in: i64, fan_out: i64) -> nn::Linear {
    let b = linear_bound(fan_in);
    let init = nn::Init::Uniform { lo: -b, up: b };
    nn::linear(path, fan_in, fan_out, nn::LinearConfig { ws_init: init, bs_init: Some(init), bias: true })
}

/// Squashed Gaussian policy: a ReLU trunk, then mean and log σ heads; a = tanh(u) · scale.
#[derive(Debug)]
pub struct GaussianActor {
    /// The hidden layers (ReLU after each).
    trunk: Vec<nn::Linear>,
    mean: nn::Linear,
    log_std: nn::Linear,
    pub obs_norm: ObsNormaliser,
    /// Per-dimension half-range of the action (e.g. the max joint-target change per step).
    action_scale: Tensor,
    /// Lower end of log σ's range (default [`LOG_STD_MIN`]).
    log_std_min: f64,
    /// The trunk's matmuls ([`Self::set_matmul_precision`]; f32 unless an update sets it).
    precision: MatmulPrecision,
}

/// An action drawn from the policy with its log-density (after the tanh change of variables),
/// when asked for: with α = 0 and no BC term SAC never reads it, and its ~10 tensor ops
/// (twice, with their backward) are a noticeable share of an update.
#[derive(Debug)]
pub struct PolicySample {
    pub action: Tensor,
    pub log_prob: Option<Tensor>,
}

impl GaussianActor {
    pub fn new(root: &nn::Path, spec: &NetSpec, action_scale: &[f32]) -> Self {
        assert_eq!(action_scale.len() as i64, spec.act_dim, "one action scale per action dimension");
        let p = root / "actor";
        let obs_norm = ObsNormaliser::new(&p, spec.obs_dim);
        let mut trunk = Vec::new();
        let mut width = spec.obs_dim;
        for (i, &h) in spec.hidden.iter().enumerate() {
            trunk.push(torch_linear(&p / format!("l{i}"), width, h));
            width = h;
        }
        let mean = torch_linear(&p / "mean", width, spec.act_dim);
        let log_std = torch_linear(&p / "log_std", width, spec.act_dim);
        let action_scale = Tensor::from_slice(action_scale).to_device(root.device());
        Self {
            trunk,
            mean,
            log_std,
            obs_norm,
            action_scale,
            log_std_min: LOG_STD_MIN,
            precision: MatmulPrecision::F32,
        }
    }

    /// The precision of the trunk's matmuls from now on (see [`MatmulPrecision`]).
    pub fn set_matmul_precision(&mut self, precision: MatmulPrecision) {
        self.precision = precision;
    }

    /// The trunk's features of normalised `obs`.
    fn features(&self, obs: &Tensor) -> Tensor {
        let mut h = self.obs_norm.apply(obs);
        for layer in &self.trunk {
            let affine = |cast: &dyn Fn(&Tensor) -> Tensor| {
                cast(&h).linear(&cast(&layer.ws), layer.bs.as_ref().map(cast))
            };
            h = precision_matmul(self.precision, affine).relu();
        }
        h
    }

    /// Raises the floor of σ to `min_std` (pre-tanh, unit action range; values at or below
    /// `exp(LOG_STD_MIN)` keep the default). With α = 0 nothing else keeps σ from collapsing,
    /// and then SAC's target `Q(s', a')` is that of a point action the actor optimised
    /// against the critic's errors: on the hand its mean Q rose past the largest Monte-Carlo
    /// return in the data. A floor makes the target an average over a ball of actions, as
    /// TD3's target smoothing does.
    #[must_use]
    pub fn with_min_std(mut self, min_std: f64) -> Self {
        if min_std > LOG_STD_MIN.exp() {
            self.log_std_min = min_std.ln().min(LOG_STD_MAX);
        }
        self
    }

    /// Per-dimension half-range of the actions, `[act_dim]`.
    pub fn action_scale(&self) -> &Tensor {
        &self.action_scale
    }

    /// The deployed behaviour: tanh(mean) · scale, no noise.
    pub fn deterministic(&self, obs: &Tensor) -> Tensor {
        self.mean.forward(&self.features(obs)).tanh() * &self.action_scale
    }

    /// Mean and log σ of the pre-tanh Gaussian.
    pub fn distribution(&self, obs: &Tensor) -> (Tensor, Tensor) {
        let h = self.features(obs);
        let min = self.log_std_min;
        let log_std = min + 0.5 * (LOG_STD_MAX - min) * (self.log_std.forward(&h).tanh() + 1.0);
        (self.mean.forward(&h), log_std)
    }

    /// Reparameterised sample a = tanh(μ + σ ε) · scale and log π(a|s), summed over dimensions.
    pub fn sample(&self, obs: &Tensor) -> PolicySample {
        let (mean, log_std) = self.distribution(obs);
        self.sample_from(&mean, &log_std, None, true)
    }

    /// [`Self::sample`] with given standard-normal noise ε (`[batch, act_dim]`) instead of
    /// libtorch's global generator (which other threads may draw from).
    pub fn sample_with(&self, obs: &Tensor, eps: Option<&Tensor>) -> PolicySample {
        self.sample_opt(obs, eps, true)
    }

    /// [`Self::sample_with`], computing log π only when `with_log_prob`.
    pub fn sample_opt(&self, obs: &Tensor, eps: Option<&Tensor>, with_log_prob: bool) -> PolicySample {
        let (mean, log_std) = self.distribution(obs);
        self.sample_from(&mean, &log_std, eps, with_log_prob)
    }

    /// A sample for `obs` (with its log π when `with_log_prob`) and log π(a|s) of given
    /// actions `action` (e.g. replayed ones), from one pass of the trunk. Actions are clamped
    /// just inside ±scale before `atanh`.
    pub fn sample_and_log_prob_of(
        &self,
        obs: &Tensor,
        action: &Tensor,
        eps: Option<&Tensor>,
        with_log_prob: bool,
    ) -> (PolicySample, Tensor) {
        let (mean, log_std) = self.distribution(obs);
        let sample = self.sample_from(&mean, &log_std, eps, with_log_prob);
        let y = (action / &self.action_scale).clamp(-1.0 + 1e-6, 1.0 - 1e-6);
        let u = y.atanh();
        let z = (u - &mean) * (-&log_std).exp();
        let log_normal = z.square() * -0.5 - &log_std - 0.5 * (2.0 * std::f64::consts::PI).ln();
        let one_minus_y2: Tensor = 1.0 - y.square();
        let log_det = (one_minus_y2 + 1e-6).log();
        let log_prob = (log_normal - log_det).sum_dim_intlist(-1, true, Kind::Float);
        (sample, log_prob)
    }

    fn sample_from(
        &self,
        mean: &Tensor,
        log_std: &Tensor,
        eps: Option<&Tensor>,
        with_log_prob: bool,
    ) -> PolicySample {
        let std = log_std.exp();
        let eps = eps.map_or_else(|| mean.randn_like(), Tensor::shallow_clone);
        let u = mean + &std * &eps;
        let y = u.tanh();
        if !with_log_prob {
            return PolicySample { action: y * &self.action_scale, log_prob: None };
        }
        // log N(u; μ, σ) = -ε²/2 - log σ - log √(2π); then the Jacobian of y = tanh(u).
        // The density is that of the unit-range action y, not of y·scale: with the hand's
        // 0.05 rad scale the latter is shifted by -15·ln 0.05 ≈ +45 nats, and an entropy
        // target of -act_dim (CleanRL's) then drives α up without bound.
        let log_normal = eps.square() * -0.5 - log_std - 0.5 * (2.0 * std::f64::consts::PI).ln();
        let one_minus_y2: Tensor = 1.0 - y.square();
        let log_det = (one_minus_y2 + 1e-6).log();
        let log_prob = (log_normal - log_det).sum_dim_intlist(-1, true, Kind::Float);
        PolicySample { action: y * &self.action_scale, log_prob: Some(log_prob) }
    }
}

/// Twin Q networks Q₁, Q₂ stored as stacked weights `[2, in, out]`, so one batched matmul
/// per layer evaluates both: half the kernel launches of two separate critics.
#[derive(Debug)]
pub struct TwinCritic {
    weights: Vec<Tensor>,
    biases: Vec<Tensor>,
    pub obs_norm: ObsNormaliser,
    /// 1 / the actor's action scale: the critic sees actions in [-1, 1], as large as its
    /// normalised observations (raw joint-target changes are a few hundredths of a radian).
    inv_action_scale: Tensor,
    /// Layer normalisation (no affine parameters) after each hidden layer's matmul: it
    /// bounds the features the last layer extrapolates from, the remedy for Q divergence
    /// under off-policy bootstrapping that Ball et al. (RLPD, 2023) measured.
    layer_norm: bool,
    /// The hidden layers' matmuls (the last, 1 wide, is always f32).
    precision: MatmulPrecision,
}

impl TwinCritic {
    pub const TWINS: i64 = 2;

    pub fn new(root: &nn::Path, spec: &NetSpec, action_scale: &[f32], layer_norm: bool) -> Self {
        assert_eq!(action_scale.len() as i64, spec.act_dim, "one action scale per action dimension");
        let p = root / "critic";
        let obs_norm = ObsNormaliser::new(&p, spec.obs_dim);
        let inv: Vec<f32> = action_scale.iter().map(|s| 1.0 / s).collect();
        let inv_action_scale = Tensor::from_slice(&inv).to_device(root.device());
        let mut widths = vec![spec.obs_dim + spec.act_dim];
        widths.extend(&spec.hidden);
        widths.push(1);
        let (mut weights, mut biases) = (Vec::new(), Vec::new());
        for (i, pair) in widths.windows(2).enumerate() {
            let (fan_in, fan_out) = (pair[0], pair[1]);
            let b = linear_bound(fan_in);
            let init = nn::Init::Uniform { lo: -b, up: b };
            weights.push(p.var(&format!("w{i}"), &[Self::TWINS, fan_in, fan_out], init));
            biases.push(p.var(&format!("b{i}"), &[Self::TWINS, 1, fan_out], init));
        }
        Self { weights, biases, obs_norm, inv_action_scale, layer_norm, precision: MatmulPrecision::F32 }
    }

    /// The precision of the hidden layers' matmuls from now on (see [`MatmulPrecision`]).
    pub fn set_matmul_precision(&mut self, precision: MatmulPrecision) {
        self.precision = precision;
    }

    /// Q-values of both twins, shape `[2, batch, 1]`.
    pub fn q_values(&self, obs: &Tensor, action: &Tensor) -> Tensor {
        let x = self.input(obs, action);
        let batch = x.size()[0];
        let x = x.unsqueeze(0).expand([Self::TWINS, batch, -1], false);
        self.forward(x, |p, h, w, b| {
            precision_matmul(p, |cast| cast(b).baddbmm(&cast(h), &cast(w), 1.0, 1.0))
        })
    }

    /// Q-values of the first twin alone, shape `[batch, 1]` (TD3's actor loss reads only
    /// Q₁: evaluating one twin halves that forward and its backward). Twin 0's slice of
    /// each stacked weight, in the same layer order as [`Self::q_values`].
    pub fn q1(&self, obs: &Tensor, action: &Tensor) -> Tensor {
        self.forward(self.input(obs, action), |p, h, w, b| {
            precision_matmul(p, |cast| cast(&b.get(0)).addmm(&cast(h), &cast(&w.get(0))))
        })
    }

    /// The critics' input: normalised observations beside actions in units of their range.
    fn input(&self, obs: &Tensor, action: &Tensor) -> Tensor {
        Tensor::cat(&[self.obs_norm.apply(obs), action * &self.inv_action_scale], -1)
    }

    /// The layer stack from input `x`, with `affine(precision, h, weight, bias)` applying
    /// one layer's stacked weights (both twins, or a slice); layer norm (over the last
    /// dimension) and ReLU after each hidden layer.
    fn forward(
        &self,
        x: Tensor,
        affine: impl Fn(MatmulPrecision, &Tensor, &Tensor, &Tensor) -> Tensor,
    ) -> Tensor {
        let mut h = x;
        let last = self.weights.len() - 1;
        for (i, (w, b)) in self.weights.iter().zip(&self.biases).enumerate() {
            let precision = if i < last { self.precision } else { MatmulPrecision::F32 };
            h = affine(precision, &h, w, b);
            if i < last {
                if self.layer_norm {
                    let width = h.size()[h.dim() - 1];
                    h = h.layer_norm([width], None::<Tensor>, None::<Tensor>, 1e-5, false);
                }
                h = h.relu();
            }
        }
        h
    }

    /// Weight and bias tensors, layer by layer (shallow handles sharing storage).
    pub fn parameters(&self) -> impl Iterator<Item = Tensor> + '_ {
        self.weights.iter().zip(&self.biases).flat_map(|(w, b)| [w.shallow_clone(), b.shallow_clone()])
    }

    /// min(Q₁, Q₂), shape `[batch, 1]`: the pessimistic estimate SAC uses against
    /// overestimation.
    pub fn min_q(&self, obs: &Tensor, action: &Tensor) -> Tensor {
        self.q_values(obs, action).amin(0, false)
    }
}
