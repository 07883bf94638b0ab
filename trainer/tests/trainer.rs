//! The trainer: SAC on a toy task, the behaviour policies, BC, replay, configs, resume.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::{Device, Kind, Tensor};
use vge_controllers::{Controller, ControllerError, ControllerInput};
use vge_run::config::{BcSection, Config, FgeSection, Method, apply_override, load_config};
/// vge15's joints: the behaviour tests' action size (any size would do).
const JOINTS: usize = 15;
use vge_trainer::behaviour::{
    Behaviour, EnvController, QFn, StepContext, bc_beta, fge_probability, p_controller,
};
use vge_trainer::learner::{self, Algorithm, BcTerm, EntropyCoef, Learner, LearnerConfig};
use vge_trainer::nets::NetSpec;
use vge_trainer::replay::{ReplayBuffer, Source};
use vge_trainer::toy::train_point_mass;
use vge_trainer::train::train;

// ---------------------------------------------------------------- SAC on the toy task

#[test]
fn sac_alpha_zero_drives_the_point_to_its_target() {
    let r = train_point_mass(Algorithm::Sac, EntropyCoef::Fixed(0.0), 1, 3000).expect("train");
    assert!(r.zero_return < -10.0, "zero action scores {}", r.zero_return);
    assert!(r.eval_return > -3.0, "alpha 0: eval return {} (zero action {})", r.eval_return, r.zero_return);
}

#[test]
fn sac_auto_alpha_drives_the_point_to_its_target() {
    let r =
        train_point_mass(Algorithm::Sac, EntropyCoef::Auto { target_entropy: -1.0, initial: 0.1 }, 2, 3000)
            .expect("train");
    assert!(
        r.eval_return > -3.0,
        "auto alpha: eval return {} (zero action {})",
        r.eval_return,
        r.zero_return
    );
}

#[test]
fn td3_drives_the_point_to_its_target() {
    let r = train_point_mass(Algorithm::td3(), EntropyCoef::Fixed(0.0), 3, 3000).expect("train");
    assert!(r.eval_return > -3.0, "td3: eval return {} (zero action {})", r.eval_return, r.zero_return);
}

// ---------------------------------------------------------------- behaviour policies

/// A controller that always proposes +0.05 rad on every joint and counts its calls.
#[derive(Debug)]
struct Constant {
    calls: Arc<AtomicUsize>,
}

impl Controller for Constant {
    fn name(&self) -> &'static str {
        "constant"
    }
    fn reset(&mut self, _rng: &mut dyn rand::Rng) {}
    fn act(
        &mut self,
        _input: &ControllerInput,
        _rng: &mut dyn rand::Rng,
    ) -> Result<Vec<f32>, ControllerError> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        Ok(vec![0.05; JOINTS])
    }
}

fn dummy_input() -> ControllerInput {
    ControllerInput {
        q_rad: vec![0.0; JOINTS],
        q_target_rad: vec![0.0; JOINTS],
        contacts: vec![None; 5],
        object_position_m: nalgebra::Vector3::zeros(),
        object_orientation: nalgebra::UnitQuaternion::identity(),
    }
}

struct Rig {
    calls: Arc<AtomicUsize>,
    controllers: Vec<EnvController>,
    rng: ChaCha8Rng,
}

fn rig() -> Rig {
    let calls = Arc::new(AtomicUsize::new(0));
    Rig {
        controllers: vec![EnvController {
            controller: Box::new(Constant { calls: calls.clone() }),
            rng: ChaCha8Rng::seed_from_u64(1),
            calls: Vec::new(),
        }],
        calls,
        rng: ChaCha8Rng::seed_from_u64(2),
    }
}

const LEARNER: [f32; JOINTS] = [-0.05; JOINTS];

fn step_once(b: &mut Behaviour, r: &mut Rig, step: u64, q: &mut QFn<'_>) -> Source {
    let obs = [vec![0.0f32; 65]];
    let learner = [LEARNER.to_vec()];
    let inputs = [Some(dummy_input())];
    let ctx = StepContext { step, obs: &obs, learner: &learner, inputs: &inputs };
    let out = b.act(&ctx, &mut r.controllers, q, &mut r.rng).expect("decide");
    assert_eq!(out.len(), 1);
    if out[0].source == Source::Controller {
        assert_eq!(out[0].action, [0.05; JOINTS]);
    } else {
        assert_eq!(out[0].action, LEARNER);
    }
    out[0].source
}

#[test]
fn vge_follows_a_preferred_controller_for_exactly_h_steps() {
    let h = 7;
    let mut b = Behaviour::new(Method::Vge, h, 1_000_000, FgeSection::default(), 1);
    let mut r = rig();
    // Q = 100 * sum(a) on the first draw (the controller's +0.05s win by 150), then the
    // learner's action wins by as much.
    let draws = Arc::new(AtomicUsize::new(0));
    let d = draws.clone();
    let mut q = move |o: &[&[f32]], a: &[&[f32]]| -> Result<Vec<f32>, String> {
        assert_eq!(o.len(), 2, "one learner row and one controller row");
        assert_eq!(a[0], LEARNER, "learner rows first");
        let sign = if d.fetch_add(1, Ordering::SeqCst) == 0 { 1.0 } else { -1.0 };
        Ok(a.iter().map(|row| sign * 100.0 * row.iter().sum::<f32>()).collect())
    };
    let p = p_controller(f64::from(100.0 * -0.75f32), f64::from(100.0 * 0.75f32));
    assert!(p > 0.5 && p <= 1.0, "p_psi {p}");
    let sources: Vec<Source> = (0..2 * h as u64).map(|s| step_once(&mut b, &mut r, s, &mut q)).collect();
    assert!(sources[..h].iter().all(|s| *s == Source::Controller), "{sources:?}");
    assert!(sources[h..].iter().all(|s| *s == Source::Learner), "{sources:?}");
    assert_eq!(draws.load(Ordering::SeqCst), 2, "one draw every H steps");
    // The controller is queried at both draws and on the H-1 followed steps.
    assert_eq!(r.calls.load(Ordering::SeqCst), h + 1);
    assert_eq!(b.stats.controller_steps, h as u64);
    assert_eq!(b.stats.selections, 2);
}

#[test]
fn p_psi_is_a_stable_softmax() {
    assert!((p_controller(0.0, 0.0) - 0.5).abs() < 1e-12);
    assert!(p_controller(1.0, 2.0) > 0.5);
    assert!(p_controller(2.0, 1.0) < 0.5);
    let e = (1.0f64).exp();
    assert!((p_controller(0.0, 1.0) - e / (1.0 + e)).abs() < 1e-12);
    // exp(1000) overflows; the logistic form does not.
    assert_eq!(p_controller(0.0, 1000.0), 1.0);
    assert_eq!(p_controller(1000.0, 0.0), 0.0);
    assert!(p_controller(-1e4, 1e4).is_finite());
}

#[test]
fn after_the_hard_stop_the_controller_is_never_queried() {
    for method in [Method::Vge, Method::VgeBc, Method::Fge] {
        let hard_stop = 50;
        let fge = FgeSection { p_start: 1.0, p_end: 1.0, decay_start: 0, decay_end: 0 };
        let mut b = Behaviour::new(method, 3, hard_stop, fge, 1);
        let mut r = rig();
        let mut q = |_: &[&[f32]], a: &[&[f32]]| -> Result<Vec<f32>, String> {
            Ok(a.iter().map(|row| 100.0 * row.iter().sum::<f32>()).collect())
        };
        for s in 0..hard_stop {
            step_once(&mut b, &mut r, s, &mut q);
        }
        let before = r.calls.load(Ordering::SeqCst);
        assert!(before > 0, "{method:?} queried the controller before the stop");
        for s in hard_stop..hard_stop + 500 {
            assert_eq!(step_once(&mut b, &mut r, s, &mut q), Source::Learner);
        }
        assert_eq!(r.calls.load(Ordering::SeqCst), before, "{method:?} queried after the hard stop");
    }
}

#[test]
fn rl_never_queries_and_fge_follows_its_schedule() {
    let mut r = rig();
    let mut q = |_: &[&[f32]], a: &[&[f32]]| -> Result<Vec<f32>, String> { Ok(vec![0.0; a.len()]) };
    let mut b = Behaviour::new(Method::Rl, 1, u64::MAX, FgeSection::default(), 1);
    for s in 0..100 {
        assert_eq!(step_once(&mut b, &mut r, s, &mut q), Source::Learner);
    }
    assert_eq!(r.calls.load(Ordering::SeqCst), 0);
    let fge = FgeSection { p_start: 0.8, p_end: 0.2, decay_start: 100, decay_end: 300 };
    assert_eq!(fge_probability(&fge, 0), 0.8);
    assert!((fge_probability(&fge, 200) - 0.5).abs() < 1e-12);
    assert_eq!(fge_probability(&fge, 10_000), 0.2);
    // State-independent: the share of controller steps at p = 0.8 is about 0.8.
    let mut b = Behaviour::new(Method::Fge, 1, u64::MAX, fge, 1);
    let n = 4000;
    let followed = (0..n).filter(|_| step_once(&mut b, &mut r, 0, &mut q) == Source::Controller).count();
    let share = followed as f64 / n as f64;
    assert!((share - 0.8).abs() < 0.03, "share {share}");
    assert!((b.stats.controller_share() - share).abs() < 1e-12);
}

// ---------------------------------------------------------------- BC

#[test]
fn bc_beta_decays_linearly_to_zero() {
    let bc = BcSection { beta_start: 0.4, beta_zero_step: 1000 };
    assert_eq!(bc_beta(&bc, 0), 0.4);
    assert!((bc_beta(&bc, 250) - 0.3).abs() < 1e-12);
    assert!((bc_beta(&bc, 500) - 0.2).abs() < 1e-12);
    assert_eq!(bc_beta(&bc, 1000), 0.0);
    assert_eq!(bc_beta(&bc, 5000), 0.0);
}

fn small_sac() -> Box<dyn Learner> {
    small_learner(Algorithm::Sac)
}

fn small_learner(algorithm: Algorithm) -> Box<dyn Learner> {
    tch::manual_seed(3);
    let config = LearnerConfig {
        algorithm,
        net: NetSpec { obs_dim: 4, act_dim: 2, hidden: vec![16, 16] },
        columns: vge_trainer::learner::ObsColumns::whole(4),
        action_scale: vec![0.5, 0.5],
        gamma: 0.9,
        tau: 0.05,
        actor_lr: 1e-3,
        critic_lr: 1e-3,
        entropy: EntropyCoef::Fixed(0.0),
        critic_layer_norm: false,
        min_policy_std: 0.0,
        actor_hold_updates: 0,
        matmul: vge_trainer::nets::MatmulPrecision::F32,
    };
    learner::build(config, Device::Cpu).expect("sac")
}

#[test]
fn bc_loss_is_value_weighted_and_only_on_non_learner_actions() {
    // A buffer of 8 transitions, rows 1, 4, 6 from the controller.
    let mut replay = ReplayBuffer::new(16, 4, 2).expect("buffer");
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for i in 0..8 {
        let o: Vec<f32> = (0..4).map(|k| ((i * 4 + k) as f32 * 0.37).sin()).collect();
        let a = [0.3 * ((i as f32) * 0.9).cos(), -0.2 * ((i as f32) * 0.4).sin()];
        let source = if [1, 4, 6].contains(&i) { Source::Controller } else { Source::Learner };
        let bc_target = (source == Source::Controller).then_some(&a[..]);
        replay.push(&o, &a, 0.1 * i as f32, &o, false, source, bc_target).expect("push");
    }
    let idx: Vec<usize> = (0..8).collect();
    let beta = 0.7;
    let batch = replay.gather(&idx, Some(beta));
    let mask = Vec::<f32>::try_from(batch.bc.as_ref().expect("bc").mask.view(-1)).expect("mask");
    assert_eq!(mask, vec![0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
    let _ = replay.sample(4, &mut rng, None).expect("sample");

    let mut sac = small_sac();
    // At initialisation Q is below 0 on the cloned rows, where the weight is 0: fit the
    // critics to the (positive) rewards first.
    let plain = replay.gather(&idx, None);
    for _ in 0..50 {
        sac.update(&plain);
    }
    // Expected: -beta * mean(mask * max(minQ(s,a), 0) * log pi(a|s)), with Q and pi before
    // the step.
    let q_raw = sac.q_of(&batch.obs, &batch.action);
    let q = q_raw.clamp_min(0.0);
    let masked_q =
        Vec::<f32>::try_from((&q_raw * Tensor::from_slice(&mask).view([8, 1])).view(-1)).expect("q");
    assert!(masked_q.iter().any(|&v| v > 0.0), "{masked_q:?}");
    let (_, log_prob) =
        tch::no_grad(|| sac.actor().sample_and_log_prob_of(&batch.obs, &batch.action, None, false));
    let mask_t = Tensor::from_slice(&mask).view([8, 1]);
    let expected = (&q * &log_prob * &mask_t).mean(Kind::Float).double_value(&[]) * -beta;
    // The same rows with the learner's flags flipped give a different value: the weight is
    // Q row by row, not a constant.
    let flipped_mask: Tensor = 1.0 - &mask_t;
    let flipped =
        ((&q * &log_prob * flipped_mask).mean(Kind::Float).double_value(&[]) * -beta - expected).abs();
    assert!(flipped > 1e-4, "the mask must select rows");
    let stats = sac.update(&batch);
    assert!(
        (stats.bc_loss - expected).abs() < 1e-5 * (1.0 + expected.abs()),
        "{} vs {expected}",
        stats.bc_loss
    );

    // All-learner batch: no BC.
    let mut sac = small_sac();
    let mut learner_only = replay.gather(&[0, 2, 3, 5, 7], Some(beta));
    assert_eq!(sac.update(&learner_only).bc_loss, 0.0);
    // beta 0: none either.
    learner_only.bc = Some(BcTerm {
        beta: 0.0,
        mask: Tensor::ones([5, 1], (Kind::Float, Device::Cpu)),
        action: learner_only.action.shallow_clone(),
    });
    assert_eq!(sac.update(&learner_only).bc_loss, 0.0);

    // TD3's deterministic actor: beta * mean(mask * max(minQ(s,a), 0) * |(a - mu(s)) /
    // scale|^2), on the updates that step the actor (every second one); the critics fitted
    // first, as above (an even number of updates, so the next one steps no actor).
    let mut td3 = small_learner(Algorithm::td3());
    for _ in 0..50 {
        td3.update(&plain);
    }
    assert_eq!(td3.update(&batch).bc_loss, 0.0, "no actor step on this update");
    let q = td3.q_of(&batch.obs, &batch.action).clamp_min(0.0);
    let mu = tch::no_grad(|| td3.actor().deterministic(&batch.obs));
    let sq = ((&batch.action - mu) / 0.5).square().sum_dim_intlist(-1, true, Kind::Float);
    let expected = (&q * &sq * &mask_t).mean(Kind::Float).double_value(&[]) * beta;
    assert!(expected.abs() > 1e-6);
    let stats = td3.update(&batch);
    assert!(
        (stats.bc_loss - expected).abs() < 1e-5 * (1.0 + expected.abs()),
        "{} vs {expected}",
        stats.bc_loss
    );
}

#[test]
fn bc_raises_the_likelihood_of_valuable_controller_actions() {
    // Critic's Q > 0 everywhere after fitting positive rewards; BC must then raise
    // log pi(a_controller | s), i.e. minimise -beta * Q * log pi.
    let mut sac = small_sac();
    let obs = Tensor::randn([64, 4], (Kind::Float, Device::Cpu));
    let action = Tensor::full([64, 2], 0.3, (Kind::Float, Device::Cpu));
    let fit = vge_trainer::learner::Batch::new(
        obs.shallow_clone(),
        action.shallow_clone(),
        Tensor::full([64, 1], 2.0, (Kind::Float, Device::Cpu)),
        obs.shallow_clone(),
        Tensor::ones([64, 1], (Kind::Float, Device::Cpu)),
    );
    for _ in 0..200 {
        sac.update(&fit);
    }
    let lp = |sac: &dyn Learner| {
        tch::no_grad(|| sac.actor().sample_and_log_prob_of(&obs, &action, None, false).1)
            .mean(Kind::Float)
            .double_value(&[])
    };
    let before = lp(sac.as_ref());
    let mut bc_batch = fit;
    bc_batch.bc = Some(BcTerm {
        beta: 5.0,
        mask: Tensor::ones([64, 1], (Kind::Float, Device::Cpu)),
        action: action.shallow_clone(),
    });
    for _ in 0..50 {
        sac.update(&bc_batch);
    }
    let after = lp(sac.as_ref());
    assert!(after > before + 0.5, "log pi of the cloned actions {before} -> {after}");
}

// ---------------------------------------------------------------- replay

#[test]
fn replay_sampling_is_deterministic_and_the_ring_wraps() {
    let mut replay = ReplayBuffer::new(5, 3, 2).expect("buffer");
    for i in 0..8 {
        let v = i as f32;
        let ctl = [0.1 * v; 2];
        let bc_target = (i % 2 == 1).then_some(&ctl[..]);
        replay
            .push(&[v; 3], &[v; 2], v, &[v + 1.0; 3], i % 3 == 0, Source::Learner, bc_target)
            .expect("push");
    }
    assert_eq!(replay.len(), 5);
    let draw = |seed| {
        let b = replay.sample(16, &mut ChaCha8Rng::seed_from_u64(seed), None).expect("sample");
        Vec::<f32>::try_from(b.reward.view(-1)).expect("rewards")
    };
    assert_eq!(draw(9), draw(9));
    assert_ne!(draw(9), draw(10));
    // Rows 0..3 were overwritten by transitions 5, 6, 7: rewards 3..=7 remain.
    assert!(draw(9).iter().all(|r| (3.0..=7.0).contains(r)), "{:?}", draw(9));
    let b = replay.gather(&[0, 1, 2, 3, 4], None);
    assert_eq!(Vec::<f32>::try_from(b.reward.view(-1)).expect("r"), vec![5.0, 6.0, 7.0, 3.0, 4.0]);
    assert_eq!(Vec::<f32>::try_from(b.done.view(-1)).expect("d"), vec![0.0, 1.0, 0.0, 1.0, 0.0]);
    assert_eq!(b.obs.size(), vec![5, 3]);
    assert!(b.bc.is_none());
    // Save and load round trip.
    let dir = tempdir("replay");
    let path = dir.join("r.bin");
    replay.save(&path).expect("save");
    let mut back = ReplayBuffer::new(5, 3, 2).expect("buffer");
    back.load(&path).expect("load");
    let d2 = Vec::<f32>::try_from(
        back.sample(16, &mut ChaCha8Rng::seed_from_u64(9), None).expect("s").reward.view(-1),
    )
    .expect("r");
    assert_eq!(d2, draw(9));
    // The BC targets come back too: rows 0..5 hold transitions 5, 6, 7, 3, 4.
    for (row, transition) in [5u8, 6, 7, 3, 4].into_iter().enumerate() {
        let expected = (transition % 2 == 1).then(|| vec![0.1 * f32::from(transition); 2]);
        assert_eq!(back.bc_target(row).map(<[f32]>::to_vec), expected, "row {row}");
    }
    let mut wrong = ReplayBuffer::new(6, 3, 2).expect("buffer");
    assert!(wrong.load(&path).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------- configs

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn every_shipped_config_loads_and_validates() {
    // Every TOML under configs/, folders included: a config that no test loads can rot.
    let mut pending = vec![repo_root().join("configs")];
    let mut names = Vec::new();
    while let Some(dir) = pending.pop() {
        for entry in std::fs::read_dir(&dir).expect("configs/") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                pending.push(path);
                continue;
            }
            assert_eq!(path.extension().and_then(|e| e.to_str()), Some("toml"), "{}", path.display());
            let c = load_config(&path, &[]).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            names.push(c.name.clone());
        }
    }
    for ctl in ["igm", "cs", "fg"] {
        for m in Method::ALL {
            assert!(names.contains(&format!("cube-{ctl}-{}", m.name())), "missing cube-{ctl}-{}", m.name());
        }
    }
    assert!(names.contains(&"multi-object-fg-vge".to_owned()));
    assert!(names.contains(&"cube-fg-vge-td3".to_owned()));
    assert!(names.contains(&"cube-fg-fge-robust".to_owned()));
    assert!(names.contains(&"cube-fg-fge-robust-ramp".to_owned()));
    assert!(names.contains(&"cube-fg-fge-robust-finetune".to_owned()));
    assert!(names.contains(&"cube-fg-vge-robust".to_owned()));
    assert!(names.contains(&"cube-fg-vge-robust-4tips".to_owned()));
    assert!(names.contains(&"cube-fg-vge-robust-hold4".to_owned()));
    assert!(names.contains(&"cube-fg-vge-robust-4tips-magnitude".to_owned()));
    assert!(names.contains(&"cube-fg-vge-robust-4tips-droppenalty".to_owned()));
    for variant in
        ["heavy-cube", "low-friction", "torque-2x", "side-on", "fixed-start-paper-reward", "sac-alpha0"]
    {
        assert!(names.iter().any(|n| n.contains(variant)), "missing variant {variant}: {names:?}");
    }
    // The Table I grid's base (configs/cube-base.toml) is a whole config of its own.
    assert!(names.contains(&"cube-base".to_owned()));
    // The Allegro's, on its own hand with a proprioceptive actor.
    assert!(names.contains(&"allegro-cube-fg-vge".to_owned()));
    assert!(names.contains(&"allegro-cube-fg-rl".to_owned()));
    assert_eq!(names.len(), 35, "{names:?}");
}

#[test]
fn overrides_apply_and_bad_configs_are_refused_clearly() {
    let path = repo_root().join("configs/cube-fg-vge.toml");
    let c = load_config(
        &path,
        &[
            "sac.batch=128".into(),
            "method=fge".into(),
            "sac.hidden=[64, 64]".into(),
            "algorithm=\"sac\"".into(),
            "sac.alpha=\"auto\"".into(),
        ],
    )
    .expect("overrides");
    assert_eq!(c.sac.batch, 128);
    assert_eq!(c.method, Method::Fge);
    assert_eq!(c.sac.hidden, vec![64, 64]);
    assert!(matches!(
        vge_trainer::learner::LearnerConfig::for_hand(&c).expect("sizes").entropy,
        EntropyCoef::Auto { .. }
    ));
    let mut d = Config::default();
    apply_override(&mut d, "vge.horizon=3").expect("override");
    assert_eq!(d.vge.horizon, 3);
    assert!(apply_override(&mut d, "no_equals_sign").is_err());
    let err = apply_override(&mut d, "sac.batchh=3").expect_err("unknown key");
    assert!(err.to_string().contains("batchh"), "{err}");
    assert!(apply_override(&mut d, "sac.batch=\"many\"").is_err());

    let refuse_all = |o: &[String], needle: &str| {
        let e = load_config(&path, o).expect_err("refused");
        assert!(e.to_string().contains(needle), "{o:?}: {e}");
    };
    let refuse = |o: &str, needle: &str| refuse_all(&[o.to_owned()], needle);
    refuse("vge.horizon=0", "vge.horizon");
    refuse("sac.buffer_size=10", "buffer_size");
    refuse("sac.gamma=1.5", "sac.gamma");
    refuse("fge.p_start=2.0", "fge.p_start");
    refuse("num_envs=0", "num_envs");
    refuse("env.control_hz=7", "control");
    refuse("algorithm=\"ppo\"", "algorithm");
    // A noise ramp would leave a freshly fitted normaliser without noise; from trained
    // networks (whose normaliser is kept) it is allowed.
    refuse("env.noise_ramp_steps=1000", "init_from");
    let ramp_from = ["env.noise_ramp_steps=1000".to_owned(), "init_from=\"runs/stage-1\"".to_owned()];
    load_config(&path, &ramp_from).expect("noise ramp from trained networks");
    // A force ramp with no force to ramp would silently do nothing.
    refuse("env.perturb_ramp_start=1000", "perturb_force_std_n");
    refuse("env.perturb_ramp_steps=1000", "perturb_force_std_n");
    let pushed = |o: &str| vec!["env.perturb_force_std_n=1.0".to_owned(), o.to_owned()];
    assert_eq!(
        load_config(&path, &pushed("env.perturb_ramp_start=1000")).expect("ramp").env.perturb_ramp_start,
        1000
    );
    // A force of fixed magnitude ramps too, reaches the sim, and excludes the Gaussian one.
    let magnitude =
        ["env.perturb_force_magnitude_n=1.47".to_owned(), "env.perturb_ramp_steps=1000".to_owned()];
    let loaded = load_config(&path, &magnitude).expect("a ramped magnitude");
    assert_eq!(loaded.env.env_config(0).expect("env").perturbation.force_magnitude_n, 1.47);
    refuse_all(&pushed("env.perturb_force_magnitude_n=1.0"), "set one");
    // Left out of the serialised config when off, so older configs keep their hash.
    assert!(!Config::default().to_toml_string().expect("toml").contains("perturb_ramp_start"));
    assert!(!Config::default().to_toml_string().expect("toml").contains("perturb_force_magnitude_n"));
    // The reward's contact threshold reaches the sim; the paper's 3 is not written out.
    let four = load_config(&path, &["env.reward_min_contacts=4".to_owned()]).expect("4 contacts");
    assert_eq!(four.env.env_config(0).expect("env").reward_min_contacts, 4);
    assert!(four.to_toml_string().expect("toml").contains("reward_min_contacts = 4"));
    assert_eq!(Config::default().env.env_config(0).expect("env").reward_min_contacts, 3);
    assert!(!Config::default().to_toml_string().expect("toml").contains("reward_min_contacts"));
    refuse("env.reward_min_contacts=6", "env.reward_min_contacts = 6");
    refuse("env.terminate_below_contacts=6", "env.terminate_below_contacts = 6");
    // bf16 matmuls: named in lower case, left out of the serialised config at f32 (so the
    // hashes of configs from before the key stay), written when chosen.
    let bf16 = load_config(&path, &["sac.matmul=\"bf16\"".to_owned()]).expect("bf16");
    assert_eq!(
        vge_trainer::learner::LearnerConfig::for_hand(&bf16).expect("sizes").matmul,
        vge_trainer::nets::MatmulPrecision::Bf16
    );
    assert!(bf16.to_toml_string().expect("toml").contains("matmul = \"bf16\""));
    assert!(!Config::default().to_toml_string().expect("toml").contains("matmul"));
    refuse("sac.matmul=\"f16\"", "matmul");
    let td3 = |o: &str| vec!["algorithm=\"td3\"".to_owned(), o.to_owned()];
    let e = load_config(&path, &td3("td3.policy_delay=0")).expect_err("delay 0");
    assert!(e.to_string().contains("td3.policy_delay"), "{e}");
    let e = load_config(&path, &td3("sac.alpha=\"auto\"")).expect_err("td3 with an entropy coefficient");
    assert!(e.to_string().contains("sac.alpha"), "{e}");
    let mut no_ctl = Config { controller: None, ..Config::default() };
    assert!(no_ctl.validate().expect_err("vge needs a controller").to_string().contains("controller"));
    no_ctl.method = Method::Rl;
    no_ctl.validate().expect("rl needs no controller");
}

// ---------------------------------------------------------------- training, resume

fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vge-trainer-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

fn tiny_config_with(total: u64, extra: &[&str]) -> Config {
    let mut c = Config::default();
    for o in [
        // SAC from the exact grasp: the settings the stored fingerprints were taken with.
        "algorithm=\"sac\"",
        "env.grasp_pose_noise_rad=0.0",
        "num_envs=2",
        "method=vge-bc",
        "controller=fg",
        "env.episode_length=25",
        "sac.hidden=[32, 32]",
        "sac.batch=32",
        "sac.warmup=40",
        "sac.buffer_size=1000",
        "sac.utd=0.5",
        "vge.horizon=4",
        "vge.hard_stop=100",
        "bc.beta_zero_step=200",
        "run.log_interval=20",
        "run.checkpoint_interval=60",
        "run.eval_episodes=2",
        "run.eval_episode_s=1.0",
        "run.eval_interval=70",
        "run.score_episodes=0",
    ]
    .iter()
    .chain(extra)
    {
        apply_override(&mut c, o).expect(o);
    }
    c.total_steps = total;
    c.validate().expect("valid");
    c
}

fn metrics_without_speed(dir: &std::path::Path) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("metrics.csv")).expect("metrics");
    text.lines().map(|l| l.rsplit_once(',').map_or(l, |(a, _)| a).to_owned()).collect()
}

#[test]
fn stop_and_resume_equals_an_uninterrupted_run() {
    check_stop_and_resume("sac", &[]);
}

#[test]
fn td3_stop_and_resume_equals_an_uninterrupted_run() {
    check_stop_and_resume("td3", &["algorithm=\"td3\""]);
}

fn check_stop_and_resume(name: &str, extra: &[&str]) {
    let tiny_config = |total| tiny_config_with(total, extra);
    let tempdir = |what: &str| tempdir(&format!("{name}-{what}"));
    let never = AtomicBool::new(false);
    let full_dir = tempdir("full");
    let full = train(&tiny_config(140), &full_dir, false, &never, &mut |_| {}).expect("full run");
    assert_eq!(full.steps, 140);
    assert!(!full.stopped);
    assert!(full.behaviour.controller_queries > 0);
    assert!(full.updates > 0);
    // The time breakdown covers the phases that ran and adds up to no more than the total.
    let t = full.times;
    assert!(t.update_s > 0.0 && t.sim_s > 0.0 && t.behaviour_s > 0.0 && t.learner_s > 0.0, "{t}");
    let parts = t.learner_s + t.behaviour_s + t.sim_s + t.update_s + t.eval_s + t.checkpoint_s;
    assert!(parts <= t.total_s * 1.001 && parts > 0.5 * t.total_s, "{t}");
    let full_policy = std::fs::read(full_dir.join("policy.vgep")).expect("policy");
    check_fingerprint(&full_dir, &format!("fingerprint-{name}.csv"));
    // The warm-up statistics normalise the observations, and the file carries them.
    let file = vge_export::PolicyFile::from_bytes(&full_policy).expect("policy file");
    assert!(file.obs_std.iter().any(|&s| (s - 1.0).abs() > 1e-3), "obs std left at identity");
    assert!(file.obs_std.iter().all(|&s| s >= 1e-2));
    assert_eq!(file.obs_clip, Some(vge_trainer::nets::OBS_CLIP as f32));

    // Stopped by the flag, then resumed: at step 120 (a checkpoint boundary: the periodic
    // checkpoint stays); at 86 (mid-episode, mid-segment, mid-metrics-window, controllers
    // still queried) and once more at 106 after that resume (past the hard stop); and at 24,
    // in the warm-up. Each resumed run ends as the uninterrupted run: the stop path's
    // checkpoint keeps the envs' episodes, which the resume replays.
    for stops in [&[120][..], &[86, 106], &[24]] {
        let part_dir = tempdir(&format!("part-{}", stops[0]));
        for (k, &at) in stops.iter().enumerate() {
            let stop = AtomicBool::new(false);
            let part = train(&tiny_config(140), &part_dir, k > 0, &stop, &mut |p| {
                if p.step >= at {
                    stop.store(true, Ordering::SeqCst);
                }
            })
            .expect("interrupted run");
            assert!(part.stopped && part.policy.is_none());
            assert_eq!(part.steps, at);
            assert!(!part_dir.join("policy.vgep").exists());
            let kept = part_dir.join("checkpoint/episodes.bin").exists();
            assert_eq!(kept, at % 60 != 0, "episodes in progress saved at {at} (checkpoint interval 60)");
        }
        let state: toml::Value = toml::from_str(
            &std::fs::read_to_string(part_dir.join("checkpoint/state.toml")).expect("state.toml"),
        )
        .expect("toml");
        let first = |key: &str| state[key].as_float().unwrap_or_else(|| panic!("{key} in state.toml"));
        let (first_wall_s, first_cpu_s) = (first("wall_s"), first("cpu_s"));
        assert!(first_wall_s > 0.0 && first_cpu_s > 0.0, "{first_wall_s} {first_cpu_s}");
        let resumed = train(&tiny_config(140), &part_dir, true, &never, &mut |_| {}).expect("resumed run");
        assert_eq!(resumed.steps, 140);
        assert_eq!(resumed.updates, full.updates, "stops at {stops:?}");
        assert_eq!(resumed.behaviour, full.behaviour, "stops at {stops:?}");
        assert_eq!(metrics_without_speed(&part_dir), metrics_without_speed(&full_dir), "stops at {stops:?}");
        check_resumed(&part_dir, &full_dir, &full_policy, (first_wall_s, first_cpu_s));
        let _ = std::fs::remove_dir_all(part_dir);
    }
    check_model_selection(&full_dir, &full_policy);

    // Same seed, same run; the exported policy runs on the runtime.
    let again_dir = tempdir("again");
    train(&tiny_config(140), &again_dir, false, &never, &mut |_| {}).expect("again");
    assert!(std::fs::read(again_dir.join("policy.vgep")).expect("policy") == full_policy);
    let report = vge_run::eval::eval_policy_file(
        &full_dir.join("policy.vgep"),
        &tiny_config(140).env.env_config(0).expect("env"),
        1,
        0,
    )
    .expect("eval");
    assert_eq!(report.episodes, 1);
    assert!(report.mean_return.is_finite());
    assert!(report.to_json_line().starts_with("{\"episodes\":1,"));
    for d in [full_dir, again_dir] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// The envs stepping on a core of their own beside the updates change nothing of a run: the
/// same metrics, model selection and policy as the loop that steps them between the updates
/// (also across a stop and resume, which the overlapping run takes).
#[test]
fn stepping_the_envs_beside_the_updates_trains_the_same_run() {
    use vge_trainer::learner::threads::{Overlap, set_adapting, set_overlap};
    // Two cores, fixed: the governor's choice is then the switch's alone.
    set_adapting(false);
    let config = tiny_config_with(140, &["algorithm=\"td3\"", "sac.threads=2"]);
    let never = AtomicBool::new(false);
    set_overlap(Overlap::Never);
    let serial_dir = tempdir("serial-loop");
    let serial = train(&config, &serial_dir, false, &never, &mut |_| {}).expect("serial run");
    assert_eq!(serial.times.sim_beside_updates_s, 0.0, "{}", serial.times);
    set_overlap(Overlap::Always);
    let beside_dir = tempdir("overlapping-loop");
    let stop = AtomicBool::new(false);
    let part = train(&config, &beside_dir, false, &stop, &mut |p| {
        if p.step >= 86 {
            stop.store(true, Ordering::SeqCst);
        }
    })
    .expect("overlapping run, first session");
    assert!(part.stopped && part.times.sim_beside_updates_s > 0.0, "{}", part.times);
    let beside = train(&config, &beside_dir, true, &never, &mut |_| {}).expect("overlapping run, resumed");
    assert!(beside.times.sim_beside_updates_s > 0.0, "the envs never stepped beside the updates");
    assert_eq!((beside.steps, beside.updates), (serial.steps, serial.updates));
    assert_eq!(beside.behaviour, serial.behaviour);
    assert_eq!(metrics_without_speed(&beside_dir), metrics_without_speed(&serial_dir));
    let read = |d: &std::path::Path, f: &str| std::fs::read(d.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
    assert!(read(&beside_dir, "policy.vgep") == read(&serial_dir, "policy.vgep"), "the policies differ");
    assert_eq!(read(&beside_dir, "best-eval.json"), read(&serial_dir, "best-eval.json"));
    for d in [serial_dir, beside_dir] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// A run resumed to its end against the uninterrupted one (`full`): the same policy and
/// model selection, and a cost counting both sessions (after `first` = (wall, CPU) s).
fn check_resumed(
    part_dir: &std::path::Path,
    full_dir: &std::path::Path,
    full_policy: &[u8],
    first: (f64, f64),
) {
    let (first_wall_s, first_cpu_s) = first;
    // The run's cost counts both sessions: wall time, and CPU time (which pauses do not add to).
    let cost = |d: &std::path::Path| -> (f64, f64) {
        let text = std::fs::read_to_string(d.join("final-eval.json")).expect("final-eval.json");
        let doc: serde_json::Value = serde_json::from_str(&text).expect("json");
        (doc["wall_s"].as_f64().expect("wall_s"), doc["cpu_s"].as_f64().expect("cpu_s"))
    };
    let (wall_s, cpu_s) = cost(part_dir);
    assert!(
        wall_s > first_wall_s && cpu_s > first_cpu_s,
        "{wall_s} {cpu_s} after {first_wall_s} {first_cpu_s}"
    );
    let resumed_policy = std::fs::read(part_dir.join("policy.vgep")).expect("policy");
    assert!(resumed_policy == full_policy, "resumed actor differs from the uninterrupted one");
    let best =
        |d: &std::path::Path| std::fs::read_to_string(d.join("best-eval.json")).expect("best-eval.json");
    assert_eq!(best(part_dir), best(full_dir), "model selection differs after a resume");
}

#[test]
fn a_finished_run_extended_with_more_steps_records_them_in_its_config() {
    let never = AtomicBool::new(false);
    let dir = tempdir("extended");
    train(&tiny_config_with(120, &[]), &dir, false, &never, &mut |_| {}).expect("first run");
    let total = |d: &std::path::Path| -> i64 {
        let text = std::fs::read_to_string(d.join("config.toml")).expect("config.toml");
        let doc: toml::Value = toml::from_str(&text).expect("toml");
        doc["total_steps"].as_integer().expect("total_steps")
    };
    assert_eq!(total(&dir), 120);
    // `vge train --resume DIR --steps 140`: the run goes on from its last checkpoint.
    let extended = train(&tiny_config_with(140, &[]), &dir, true, &never, &mut |_| {}).expect("extended");
    assert_eq!(extended.steps, 140);
    assert_eq!(total(&dir), 140, "config.toml still names the first session's budget");
    let text = std::fs::read_to_string(dir.join("final-eval.json")).expect("final-eval.json");
    let doc: serde_json::Value = serde_json::from_str(&text).expect("json");
    assert_eq!(doc["env_steps"].as_u64(), Some(140));
    let _ = std::fs::remove_dir_all(dir);
}

/// The metrics of the short run against the stored ones (`tests/fixtures/`): refactors must
/// not change what training does. Counts must match exactly; real numbers to a relative
/// 1e-3, because libtorch's kernels round differently on other CPUs (the stored file was
/// written on an AMD EPYC; `VGE_BLESS=1` rewrites it after an intended change of behaviour).
fn check_fingerprint(dir: &std::path::Path, fixture: &str) {
    let fixture = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(fixture);
    let got = metrics_without_speed(dir).join("\n") + "\n";
    if std::env::var_os("VGE_BLESS").is_some() {
        std::fs::create_dir_all(fixture.parent().expect("parent")).expect("fixtures dir");
        std::fs::write(&fixture, &got).expect("write fingerprint");
    }
    let want = std::fs::read_to_string(&fixture).expect("stored fingerprint (VGE_BLESS=1 writes it)");
    let (got, want): (Vec<&str>, Vec<&str>) = (got.lines().collect(), want.lines().collect());
    assert_eq!(got.len(), want.len(), "metrics rows differ from {}", fixture.display());
    assert_eq!(got[0], want[0], "metrics header");
    for (g, w) in got.iter().zip(&want).skip(1) {
        let (gc, wc): (Vec<&str>, Vec<&str>) = (g.split(',').collect(), w.split(',').collect());
        assert_eq!(gc.len(), wc.len(), "{g}\n{w}");
        for ((a, b), column) in gc.iter().zip(&wc).zip(want[0].split(',')) {
            let same = match (a.parse::<f64>(), b.parse::<f64>()) {
                _ if a.is_empty() || b.is_empty() || !a.contains('.') => a == b,
                (Ok(x), Ok(y)) => (x - y).abs() <= 1e-3 * y.abs().max(1e-3),
                _ => false,
            };
            assert!(same, "{column}: {a} now, {b} stored in {}\nnow:    {g}\nstored: {w}", fixture.display());
        }
    }
}

/// The actor is kept at each periodic evaluation, and the one with the best evaluation
/// (success, then return) is `policy-best.vgep`, reported on other episodes than it was
/// selected on.
fn check_model_selection(dir: &std::path::Path, final_policy: &[u8]) {
    let snapshot = |step: u64| std::fs::read(dir.join(format!("snapshots/policy-{step}.vgep")));
    assert!(snapshot(70).is_ok(), "snapshot at the first evaluation");
    assert!(snapshot(140).expect("snapshot at the last evaluation") == final_policy);
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("best-eval.json")).expect("best-eval.json"))
            .expect("json");
    let selected = doc["selected_step"].as_u64().expect("selected_step");
    let eval = std::fs::read_to_string(dir.join("eval.csv")).expect("eval.csv");
    let rows: Vec<(u64, f64, f64)> = eval
        .lines()
        .skip(1)
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            (c[0].parse().expect("step"), c[4].parse().expect("success"), c[2].parse().expect("return"))
        })
        .collect();
    assert_eq!(rows.iter().map(|r| r.0).collect::<Vec<_>>(), vec![70, 140]);
    let best = rows.iter().max_by(|a, b| (a.1, a.2).partial_cmp(&(b.1, b.2)).expect("finite")).expect("rows");
    assert_eq!(selected, best.0, "{eval}");
    assert!(
        std::fs::read(dir.join("policy-best.vgep")).expect("policy-best")
            == snapshot(selected).expect("snapshot")
    );
    let validation = doc["validation_mean_return"].as_f64().expect("validation return");
    assert!((validation - best.2).abs() < 1e-5);
    // The test episodes are other grasps than the validation ones, so the return differs.
    assert!(doc["mean_return"].as_f64().expect("test return") != validation, "{doc}");
}

#[test]
fn a_network_the_deployed_runtime_cannot_hold_is_refused_before_training() {
    let with_hidden = |hidden: &str| {
        let mut c = Config::default();
        apply_override(&mut c, &format!("sac.hidden={hidden}")).expect("parses");
        c.validate()
    };
    assert!(
        with_hidden("[256, 256, 256]").is_ok(),
        "3 hidden layers of 256: 4 layers, the most HandPolicy holds"
    );
    for too_big in ["[512, 512]", "[64, 64, 64, 64]"] {
        let err = with_hidden(too_big).expect_err(too_big).to_string();
        assert!(err.contains("vge-bridge") && err.contains("256"), "{err}");
    }
}

#[test]
fn a_run_started_from_another_runs_networks_keeps_them_and_trains_on() {
    let never = AtomicBool::new(false);
    let td3 = ["algorithm=\"td3\"", "method=rl"];
    let source = tempdir("init-seed-0");
    train(&tiny_config_with(100, &td3), &source, false, &never, &mut |_| {}).expect("source run");
    let policy = |dir: &std::path::Path| {
        let bytes = std::fs::read(dir.join("policy.vgep")).expect("policy.vgep");
        vge_export::PolicyFile::from_bytes(&bytes).expect("policy file")
    };
    let theirs = policy(&source);
    // Stage 2 under pushes and noise, from the source's networks.
    // `{seed}` names the stage-1 run of the same seed (the tiny config's seed is 0).
    let init = format!("init_from=\"{}\"", source.display().to_string().replace("seed-0", "seed-{seed}"));
    let stage2 = |total: u64, more: &[&str]| {
        let mut extra: Vec<&str> = td3.to_vec();
        extra.extend([init.as_str(), "env.perturb_force_std_n=0.5", "env.perturb_change_probability=0.1"]);
        extra.extend(more);
        tiny_config_with(total, &extra)
    };
    // Shorter than the 40-step warm-up: no update, so the exported actor is the loaded one.
    let short = tempdir("init-short");
    let s = train(&stage2(20, &[]), &short, false, &never, &mut |_| {}).expect("stage 2, no update");
    assert_eq!(s.updates, 0);
    let loaded = policy(&short);
    assert!(loaded.layers == theirs.layers, "the loaded actor differs from the source's");
    assert_eq!((&loaded.obs_mean, &loaded.obs_std), (&theirs.obs_mean, &theirs.obs_std));
    let fresh = tempdir("init-fresh");
    let mut no_init = stage2(20, &[]);
    no_init.init_from = None;
    train(&no_init, &fresh, false, &never, &mut |_| {}).expect("fresh run");
    assert!(
        policy(&fresh).layers != theirs.layers,
        "a fresh actor equals the source's: the check proves nothing"
    );
    // Past the warm-up it learns, and keeps the source's observation normaliser.
    let long = tempdir("init-long");
    let l = train(&stage2(80, &[]), &long, false, &never, &mut |_| {}).expect("stage 2");
    assert!(l.updates > 0);
    let trained = policy(&long);
    assert!(trained.layers != theirs.layers, "updates left the actor unchanged");
    assert_eq!((&trained.obs_mean, &trained.obs_std), (&theirs.obs_mean, &theirs.obs_std));
    // Networks of another shape or algorithm, or no run at all, are refused by name.
    let refused = |config: Config| {
        let dir = tempdir("init-refused").join("run");
        let err = train(&config, &dir, false, &never, &mut |_| {}).expect_err("refused").to_string();
        assert!(!dir.exists(), "a refused run left {}", dir.display());
        err
    };
    let err = refused(stage2(20, &["sac.hidden=[16, 16]"]));
    assert!(err.contains("sac.hidden") && err.contains(&source.display().to_string()), "{err}");
    let mut sac = stage2(20, &[]);
    sac.algorithm = vge_run::config::AlgorithmName::Sac;
    sac.td3 = Default::default();
    assert!(refused(sac).contains("algorithm"));
    let mut nowhere = stage2(20, &[]);
    nowhere.init_from = Some(source.join("no-such-run"));
    assert!(refused(nowhere).contains("no-such-run"));
    for d in [source, short, fresh, long, tempdir("init-refused")] {
        let _ = std::fs::remove_dir_all(d);
    }
}
