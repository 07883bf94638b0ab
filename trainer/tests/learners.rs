//! The learners (SAC and TD3 behind `Learner`): networks and updates on real tch tensors.

use tch::{Device, Kind, Tensor, nn};
use vge_trainer::learner::{self, Algorithm, Batch, BcTerm, EntropyCoef, Learner, LearnerConfig};
use vge_trainer::nets::{GaussianActor, NetSpec, TwinCritic};

fn small_spec() -> NetSpec {
    NetSpec { obs_dim: 6, act_dim: 3, hidden: vec![32, 32] }
}

fn max_abs(t: &Tensor) -> f64 {
    t.abs().max().double_value(&[])
}

#[test]
fn actor_log_prob_matches_the_tanh_gaussian_density() {
    tch::manual_seed(7);
    let vs = nn::VarStore::new(Device::Cpu);
    let scale = [0.5f32, 1.0, 2.0];
    let actor = GaussianActor::new(&vs.root(), &small_spec(), &scale);
    let obs = Tensor::randn([64, 6], (Kind::Float, Device::Cpu));
    let sample = tch::no_grad(|| actor.sample(&obs));
    let log_prob = sample.log_prob.as_ref().expect("sample() computes log π");
    let (mean, log_std) = tch::no_grad(|| actor.distribution(&obs));

    // Recompute log π(a|s) from the action alone: u = atanh(a / scale).
    let scale_t = Tensor::from_slice(&scale);
    let y = (&sample.action / &scale_t).to_kind(Kind::Double);
    let u = y.atanh();
    let (mean, log_std) = (mean.to_kind(Kind::Double), log_std.to_kind(Kind::Double));
    let z = (&u - &mean) / log_std.exp();
    let log_normal = z.square() * -0.5 - &log_std - 0.5 * (2.0 * std::f64::consts::PI).ln();
    let one_minus_y2: Tensor = 1.0 - y.square();
    let log_det = (one_minus_y2 + 1e-6).log(); // density of the unit-range action tanh(u)
    let expected = (log_normal - log_det).sum_dim_intlist(-1, true, Kind::Double);

    assert_eq!(log_prob.size(), vec![64, 1]);
    // atanh cannot invert an f32 action that saturated to ±scale: compare the other rows.
    let invertible = y.abs().lt(0.999).all_dim(-1, true);
    // With PyTorch's initialisation the initial policy is far from saturation.
    let invertible_rows = invertible.sum(Kind::Int64).int64_value(&[]);
    assert!(invertible_rows > 56, "only {invertible_rows} of 64 samples are invertible");
    let diff = max_abs(
        &((log_prob.to_kind(Kind::Double) - expected) * invertible.to_kind(Kind::Double))
            .nan_to_num(0.0, 0.0, 0.0),
    );
    assert!(diff < 2e-3, "log-prob differs by {diff}");
    // Actions stay inside ±scale, and the deterministic head is tanh(mean)·scale.
    assert!(max_abs(&(sample.action.abs() - &scale_t).clamp_min(0.0)) == 0.0);
    let det = tch::no_grad(|| actor.deterministic(&obs));
    let expected_det = mean.tanh().to_kind(Kind::Float) * &scale_t;
    assert!(max_abs(&(det - expected_det)) < 1e-6);
}

#[test]
fn twin_critic_batched_pass_equals_two_separate_mlps() {
    let vs = nn::VarStore::new(Device::Cpu);
    let spec = small_spec();
    let scale = [0.5f32, 2.0, 1.0];
    let mut critic = TwinCritic::new(&vs.root(), &spec, &scale, false);
    let obs_mean = Tensor::from_slice(&[1.0f32, -2.0, 0.0, 0.5, 3.0, 0.0]);
    let obs_std = Tensor::from_slice(&[2.0f32, 0.5, 1.0, 4.0, 1.0, 0.25]);
    critic.obs_norm.set(&obs_mean, &obs_std);
    let obs = Tensor::randn([16, 6], (Kind::Float, Device::Cpu));
    let act = Tensor::randn([16, 3], (Kind::Float, Device::Cpu));
    let q = tch::no_grad(|| critic.q_values(&obs, &act));
    assert_eq!(q.size(), vec![2, 16, 1]);

    // The critic sees normalised observations (clamped) and actions divided by their scale.
    let vars = vs.variables();
    let obs_n =
        ((&obs - &obs_mean) / &obs_std).clamp(-vge_trainer::nets::OBS_CLIP, vge_trainer::nets::OBS_CLIP);
    let x = Tensor::cat(&[obs_n, &act / Tensor::from_slice(&scale)], -1);
    for twin in 0..2 {
        let mut h = x.shallow_clone();
        for layer in 0..3 {
            let w = vars[&format!("critic.w{layer}")].get(twin);
            let b = vars[&format!("critic.b{layer}")].get(twin);
            h = tch::no_grad(|| h.matmul(&w) + b);
            if layer < 2 {
                h = h.relu();
            }
        }
        assert!(max_abs(&(q.get(twin) - h)) < 1e-5, "twin {twin}");
    }
    let min_q = tch::no_grad(|| critic.min_q(&obs, &act));
    assert!(max_abs(&(min_q - q.amin(0, false))) == 0.0);
}

#[test]
fn first_twin_alone_equals_the_batched_pass_with_and_without_layer_norm() {
    for layer_norm in [false, true] {
        let vs = nn::VarStore::new(Device::Cpu);
        let spec = NetSpec { obs_dim: 65, act_dim: 15, hidden: vec![256, 256] };
        let critic = TwinCritic::new(&vs.root(), &spec, &[0.05; 15], layer_norm);
        let obs = Tensor::randn([256, 65], (Kind::Float, Device::Cpu));
        let act = Tensor::randn([256, 15], (Kind::Float, Device::Cpu)) * 0.05;
        let (q, q1) = tch::no_grad(|| (critic.q_values(&obs, &act), critic.q1(&obs, &act)));
        assert_eq!(q1.size(), vec![256, 1]);
        // Same arithmetic up to the matmul kernel's summation order.
        let scale = max_abs(&q.get(0)).max(1e-3);
        assert!(max_abs(&(q1 - q.get(0))) < 1e-5 * scale, "layer norm {layer_norm}");
        // And not the second twin's values (the twins are initialised independently).
        assert!(max_abs(&(critic.q1(&obs, &act) - q.get(1))) > 1e-3);
    }
}

fn fixed_batch(spec: &NetSpec) -> Batch {
    let opts = (Kind::Float, Device::Cpu);
    Batch::new(
        Tensor::randn([128, spec.obs_dim], opts),
        Tensor::rand([128, spec.act_dim], opts) * 2.0 - 1.0,
        Tensor::randn([128, 1], opts),
        Tensor::randn([128, spec.obs_dim], opts),
        Tensor::ones([128, 1], opts),
    )
}

fn config(entropy: EntropyCoef) -> LearnerConfig {
    LearnerConfig {
        algorithm: Algorithm::Sac,
        columns: vge_trainer::learner::ObsColumns::whole(small_spec().obs_dim),
        net: small_spec(),
        action_scale: vec![1.0; 3],
        gamma: 0.9,
        tau: 0.05,
        actor_lr: 1e-3,
        critic_lr: 3e-3,
        entropy,
        critic_layer_norm: false,
        min_policy_std: 0.0,
        actor_hold_updates: 0,
        matmul: vge_trainer::nets::MatmulPrecision::F32,
    }
}

#[test]
fn critic_fits_terminal_rewards_and_fixed_alpha_stays_put() {
    let mut sac = learner::build(config(EntropyCoef::Fixed(0.0)), Device::Cpu).expect("sac");
    let batch = fixed_batch(&sac.config().net);
    let first = sac.update(&batch);
    let mut last = first;
    for _ in 0..300 {
        last = sac.update(&batch);
    }
    // All transitions are terminal, so Q must regress onto the rewards (variance ~1).
    assert!(first.critic_loss > 1.0, "initial loss {}", first.critic_loss);
    assert!(last.critic_loss < 0.2 * first.critic_loss, "{} -> {}", first.critic_loss, last.critic_loss);
    assert_eq!(sac.alpha(), 0.0);
    assert_eq!(last.alpha, 0.0);
}

#[test]
fn auto_alpha_moves_and_target_critic_trails_the_critic() {
    let mut sac =
        learner::build(config(EntropyCoef::Auto { target_entropy: 10.0, initial: 0.1 }), Device::Cpu)
            .expect("sac");
    let batch = fixed_batch(&sac.config().net);
    for _ in 0..50 {
        sac.update(&batch);
    }
    // A target entropy far above what the policy has drives α up.
    assert!(sac.alpha() > 0.1, "alpha {}", sac.alpha());
    assert!(sac.alpha().is_finite());

    let dir = std::env::temp_dir().join(format!("vge-auto-alpha-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    // The target critic trails the critic by Polyak averaging: after one more update,
    // target = target_before + tau (critic - target_before), parameter by parameter.
    let saved = |sac: &dyn Learner, tag: &str| {
        let at = dir.join(tag);
        std::fs::create_dir_all(&at).expect("dir");
        sac.save(&at).expect("save");
        let read = |file: &str| {
            let mut named = Tensor::load_multi(at.join(file)).expect("a saved var store");
            named.sort_by(|a, b| a.0.cmp(&b.0));
            named
        };
        (read(learner::CRITIC_FILE), read(learner::TARGET_FILE))
    };
    let (_, target_before) = saved(sac.as_ref(), "before");
    sac.update(&batch);
    let (critic, target) = saved(sac.as_ref(), "after");
    let tau = sac.config().tau;
    assert_eq!(critic.len(), target.len());
    let (mut off, mut trailed, mut behind) = (0.0f64, 0.0f64, 0.0f64);
    for ((c, t0), t) in critic.iter().zip(&target_before).zip(&target) {
        assert_eq!((&c.0, &t0.0), (&t.0, &t.0), "the same parameters in the same order");
        off = off.max(max_abs(&(&t.1 - (&t0.1 + (&c.1 - &t0.1) * tau))));
        trailed = trailed.max(max_abs(&(&t.1 - &t0.1)));
        behind = behind.max(max_abs(&(&c.1 - &t.1)));
    }
    assert!(off < 1e-6, "target - (target_before + tau (critic - target_before)) up to {off}");
    assert!(
        trailed > 0.0 && behind > 0.0,
        "the target moved ({trailed}), yet not onto the critic ({behind})"
    );

    // Saved and loaded into a fresh learner, α and the update count come back.
    sac.save(&dir).expect("save");
    let mut again =
        learner::build(config(EntropyCoef::Auto { target_entropy: 10.0, initial: 0.1 }), Device::Cpu)
            .expect("sac");
    again.load(&dir).expect("load");
    assert_eq!((again.alpha(), again.updates()), (sac.alpha(), sac.updates()));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn adam_matches_libtorchs_adam_step_for_step() {
    use tch::nn::OptimizerConfig;
    // Two copies of the same parameters; one trained by our checkpointable Adam, one by
    // libtorch's (PyTorch's defaults: betas 0.9 / 0.999, eps 1e-8, no weight decay).
    let init = Tensor::randn([7, 5], (Kind::Float, Device::Cpu));
    let target = Tensor::randn([7, 5], (Kind::Float, Device::Cpu));
    let ours_p = init.copy().set_requires_grad(true);
    let mut ours = vge_trainer::optim::Adam::new(vec![ours_p.shallow_clone()], 1e-2);
    let vs = nn::VarStore::new(Device::Cpu);
    let theirs_p = vs.root().var_copy("p", &init);
    let mut theirs = nn::Adam::default().build(&vs, 1e-2).expect("adam");
    let loss = |p: &Tensor| (p - &target).pow_tensor_scalar(4).sum(Kind::Float);
    for _ in 0..50 {
        ours.backward_step(&loss(&ours_p));
        theirs.backward_step(&loss(&theirs_p));
    }
    let moved = max_abs(&(&ours_p - &init));
    assert!(moved > 0.1, "parameters barely moved ({moved})");
    let diff = max_abs(&(&ours_p - &theirs_p));
    assert!(diff < 1e-5, "ours and libtorch's Adam differ by {diff} after 50 steps");
}

/// `actor_hold_updates`: the first updates train only the critics (their targets keep
/// following), then the actor learns as usual; for both learners.
#[test]
fn a_held_actor_stays_put_while_the_critics_learn() {
    let td3 =
        Algorithm::Td3 { explore_std: 0.1, target_noise_std: 0.2, target_noise_clip: 0.5, policy_delay: 1 };
    for algorithm in [Algorithm::Sac, td3] {
        let held = LearnerConfig { algorithm, actor_hold_updates: 3, ..config(EntropyCoef::Fixed(0.0)) };
        let mut sac = learner::build_seeded(held, Device::Cpu, 1).expect("sac");
        let batch = fixed_batch(&sac.config().net);
        let probe = Tensor::randn([16, 6], (Kind::Float, Device::Cpu));
        let zeros = Tensor::zeros([16, 3], (Kind::Float, Device::Cpu));
        let action = |s: &dyn Learner| s.behaviour_action(&probe, &zeros);
        let q = |s: &dyn Learner| s.q_of(&probe, &zeros);
        let (action_0, q_0) = (action(sac.as_ref()), q(sac.as_ref()));
        for _ in 0..3 {
            sac.update(&batch);
        }
        assert_eq!(max_abs(&(action(sac.as_ref()) - &action_0)), 0.0, "{algorithm:?}: the held actor moved");
        assert!(max_abs(&(q(sac.as_ref()) - &q_0)) > 0.0, "{algorithm:?}: the critics did not learn");
        sac.update(&batch);
        assert!(max_abs(&(action(sac.as_ref()) - &action_0)) > 0.0, "{algorithm:?}: the actor never learned");
    }
}

/// Loaded networks are what the optimisers step from: an update after `load_networks`
/// moves the loaded weights a little, never back to the fresh learner's own.
#[test]
fn updates_after_load_networks_start_from_the_loaded_weights() {
    let dir = std::env::temp_dir().join(format!("vge-sac-load-networks-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let td3 =
        Algorithm::Td3 { explore_std: 0.1, target_noise_std: 0.2, target_noise_clip: 0.5, policy_delay: 1 };
    for algorithm in [Algorithm::Sac, td3] {
        let cfg =
            LearnerConfig { algorithm, actor_lr: 1e-6, critic_lr: 1e-6, ..config(EntropyCoef::Fixed(0.0)) };
        let mut source = learner::build_seeded(cfg.clone(), Device::Cpu, 1).expect("sac");
        let batch = fixed_batch(&source.config().net);
        for _ in 0..5 {
            source.update(&batch);
        }
        source.save(&dir).expect("save");
        let probe = Tensor::randn([16, 6], (Kind::Float, Device::Cpu));
        let zeros = Tensor::zeros([16, 3], (Kind::Float, Device::Cpu));
        let loaded_action = source.behaviour_action(&probe, &zeros);
        let mut fresh = learner::build_seeded(cfg, Device::Cpu, 2).expect("sac");
        let own_action = fresh.behaviour_action(&probe, &zeros);
        assert!(max_abs(&(&own_action - &loaded_action)) > 1e-3, "the two learners start alike");
        fresh.load_networks(&dir).expect("load");
        assert_eq!(max_abs(&(fresh.behaviour_action(&probe, &zeros) - &loaded_action)), 0.0);
        for _ in 0..3 {
            fresh.update(&batch);
        }
        let after = fresh.behaviour_action(&probe, &zeros);
        assert!(max_abs(&(&after - &loaded_action)) < 1e-3, "{algorithm:?}: updates left the loaded weights");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Enough updates for Q to move well away from its start on the test's batches.
const BF16_UPDATES: usize = 40;

/// `sac.matmul = "bf16"` with SAC: see [`bf16_updates_track_f32_ones_and_acting_stays_f32`].
#[test]
fn bf16_matmul_updates_track_f32_ones_and_acting_stays_f32_in_sac() {
    bf16_updates_track_f32_ones_and_acting_stays_f32(Algorithm::Sac);
}

/// `sac.matmul = "bf16"` with TD3 (a test of its own: bf16 matmuls are slow on CPUs without
/// bf16 instructions, and two tests run side by side).
#[test]
fn bf16_matmul_updates_track_f32_ones_and_acting_stays_f32_in_td3() {
    bf16_updates_track_f32_ones_and_acting_stays_f32(Algorithm::td3());
}

/// Updates at the hand's sizes with bf16 matmuls follow the f32 ones to within bf16's
/// rounding (the same seed, the same batches), while acting stays f32 as deployed.
fn bf16_updates_track_f32_ones_and_acting_stays_f32(algorithm: Algorithm) {
    use vge_trainer::nets::MatmulPrecision;
    // One intra-op thread: with libtorch's default (every core) two f32 forwards of the same
    // weights once differed by 7.3e-7 on a loaded machine (once in seven runs; suspected:
    // MKL's dynamic threading splitting a matmul differently from call to call).
    tch::set_num_threads(1);
    {
        let learner = |matmul| {
            let config = LearnerConfig {
                algorithm,
                matmul,
                entropy: EntropyCoef::Fixed(0.0),
                ..LearnerConfig::for_hand(&vge_run::config::Config::default())
                    .expect("the default run's sizes")
            };
            learner::build_seeded(config, Device::Cpu, 3).expect("learner")
        };
        let (mut f32_learner, mut bf16_learner) =
            (learner(MatmulPrecision::F32), learner(MatmulPrecision::Bf16));
        let spec = f32_learner.config().net.clone();
        tch::manual_seed(11);
        let batches: Vec<Batch> = (0..4)
            .map(|_| {
                let opts = (Kind::Float, Device::Cpu);
                Batch::new(
                    Tensor::randn([256, spec.obs_dim], opts),
                    (Tensor::rand([256, spec.act_dim], opts) * 2.0 - 1.0) * 0.05,
                    Tensor::rand([256, 1], opts),
                    Tensor::randn([256, spec.obs_dim], opts),
                    Tensor::zeros([256, 1], opts),
                )
            })
            .collect();
        let obs = &batches[0].obs;
        let eps = Tensor::randn([256, spec.act_dim], (Kind::Float, Device::Cpu));
        // Same weights, f32 acting: the same actions to the bit.
        let before =
            max_abs(&(f32_learner.behaviour_action(obs, &eps) - bf16_learner.behaviour_action(obs, &eps)));
        assert_eq!(before, 0.0, "{algorithm:?}");

        let (mut worst_q, mut largest_q) = (0.0f64, 0.0f64);
        for i in 0..BF16_UPDATES {
            let (a, b) = (f32_learner.update(&batches[i % 4]), bf16_learner.update(&batches[i % 4]));
            worst_q = worst_q.max((a.mean_q - b.mean_q).abs());
            largest_q = largest_q.max(a.mean_q.abs());
        }
        // Q climbs from ~0 towards r / (1 - γ) ≈ 50 on these batches; bf16 keeps ~3 significant
        // digits per product, so the two runs agree closely but not exactly.
        eprintln!("{algorithm:?}: mean Q apart by at most {worst_q} of {largest_q}");
        assert!(largest_q > 0.3, "{algorithm:?}: Q did not move ({largest_q})");
        assert!(worst_q > 0.0, "{algorithm:?}: bf16 updates computed exactly the f32 ones");
        assert!(worst_q < 0.02 * largest_q, "{algorithm:?}: mean Q apart by {worst_q} of {largest_q}");

        // After updates the learner acts in f32: with zero noise (SAC's sample is then its
        // mean, TD3 adds nothing) its actions are those of an f32 forward of its weights,
        // not of a bf16 one.
        let zero = Tensor::zeros([256, spec.act_dim], (Kind::Float, Device::Cpu));
        let acted = bf16_learner.behaviour_action(obs, &zero);
        let deterministic = |learner: &mut dyn Learner, precision| {
            learner.core_mut().actor.set_matmul_precision(precision);
            let out = tch::no_grad(|| learner.actor().deterministic(obs));
            learner.core_mut().actor.set_matmul_precision(MatmulPrecision::F32);
            out
        };
        let f32_out = deterministic(bf16_learner.as_mut(), MatmulPrecision::F32);
        let bf16_out = deterministic(bf16_learner.as_mut(), MatmulPrecision::Bf16);
        assert!(max_abs(&(&f32_out - &bf16_out)) > 0.0, "{algorithm:?}");
        assert_eq!(max_abs(&(acted - f32_out)), 0.0, "{algorithm:?}");
    }
}

/// A batch of terminal transitions with reward `reward` and a BC term (beta 1) cloning one
/// fixed controller action per row.
fn bc_batch(spec: &NetSpec, reward: f64) -> Batch {
    let opts = (Kind::Float, Device::Cpu);
    let mut batch = fixed_batch(spec);
    batch.reward = Tensor::full([128, 1], reward, opts);
    batch.bc = Some(BcTerm {
        beta: 1.0,
        mask: Tensor::ones([128, 1], opts),
        action: Tensor::rand([128, spec.act_dim], opts) * 1.6 - 0.8,
    });
    batch
}

/// Mean squared distance of the deployed actions from the batch's controller actions.
fn distance_to_controller(learner: &dyn Learner, batch: &Batch) -> f64 {
    let bc = batch.bc.as_ref().expect("bc term");
    (learner.actor().deterministic(&batch.obs) - &bc.action).square().mean(Kind::Float).double_value(&[])
}

/// Value-weighted BC clones controller actions the critic values (the actor moves towards
/// them) and leaves alone those it values below 0: a negative weight would push the policy
/// away without bound (SAC's log-likelihood has none) or to the action bound (TD3's).
#[test]
fn value_weighted_bc_clones_valued_actions_and_ignores_negative_ones() {
    // TD3 as the configs run it: the actor learns every second update.
    let td3 =
        Algorithm::Td3 { explore_std: 0.1, target_noise_std: 0.2, target_noise_clip: 0.5, policy_delay: 2 };
    for algorithm in [Algorithm::Sac, td3] {
        tch::manual_seed(7);
        let mut cfg = config(EntropyCoef::Fixed(0.0));
        cfg.algorithm = algorithm;
        // Valued: terminal rewards of +1, so Q(s, a_controller) -> 1 > 0.
        let mut valued = learner::build(cfg.clone(), Device::Cpu).expect("learner");
        let batch = bc_batch(&valued.config().net, 1.0);
        let before = distance_to_controller(valued.as_ref(), &batch);
        for _ in 0..400 {
            valued.update(&batch);
        }
        let after = distance_to_controller(valued.as_ref(), &batch);
        assert!(after < 0.7 * before, "{algorithm:?}: cloning valued actions, distance {before} -> {after}");

        // Unvalued: rewards of -1, so Q -> -1 < 0 and the BC term weighs nothing.
        let mut unvalued = learner::build(cfg, Device::Cpu).expect("learner");
        let batch = bc_batch(&unvalued.config().net, -1.0);
        let mut lowest_bc_loss = f64::INFINITY;
        let mut last = None;
        for _ in 0..400 {
            let stats = unvalued.update(&batch);
            lowest_bc_loss = lowest_bc_loss.min(stats.bc_loss);
            last = Some(stats);
        }
        let last = last.expect("updates ran");
        assert!(last.critic_loss < 0.1, "{algorithm:?}: the critic fits Q = -1 ({})", last.critic_loss);
        assert!(lowest_bc_loss > -1.0, "{algorithm:?}: BC loss fell to {lowest_bc_loss}");
        assert_eq!(last.bc_loss, 0.0, "{algorithm:?}: negative values weigh nothing");
        let actions = unvalued.actor().deterministic(&batch.obs);
        assert!(max_abs(&actions) < 0.999, "{algorithm:?}: actions pushed to the bound");
    }
}
