//! VGE as the paper's Algorithm 2, on real components: a controller pick runs one whole
//! contact switch on the real sim, RL+BC clones controller actions it never executed, the
//! BC density stays finite at the action bound, and the success test counts a known 2π
//! episode and rejects a dropped one (the stored gait policy on the no_std runtime).

mod common;

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::{Device, Kind, Tensor};
use vge_controllers::{ControllerInput, IgmConfig};
use vge_run::config::{Config, apply_override, load_config};
use vge_run::eval::{EpisodeOutcome, eval_policy_file, success_test_env, summarise};
use vge_sim::Env;
use vge_sim::gait::ContactSwitches;

/// vge15's observation and action sizes (the shipped config's hand).
const OBS_DIM: usize = 65;
const NUM_JOINTS: usize = 15;
use vge_trainer::behaviour::{Behaviour, BehaviourError, EnvController, StepContext};
use vge_trainer::nets::{GaussianActor, NetSpec};
use vge_trainer::replay::{ReplayBuffer, Source};
use vge_trainer::train::train;

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn shipped_vge_config() -> Config {
    load_config(&repo_root().join("configs/cube-fg-vge.toml"), &[]).expect("configs/cube-fg-vge.toml")
}

/// A critic that prefers the controller's rows (the second half) by 100.
fn prefer_controller(_: &[&[f32]], a: &[&[f32]]) -> Result<Vec<f32>, String> {
    let k = a.len() / 2;
    Ok((0..a.len()).map(|i| if i >= k { 100.0 } else { 0.0 }).collect())
}

#[test]
fn a_controller_pick_under_vge_completes_a_detach_and_reattach_within_h_steps() {
    let config = shipped_vge_config();
    let h = config.vge.horizon;
    let env_config = config.env_config(0).expect("env");
    let mut completed = Vec::new();
    for seed in 0..4u64 {
        let mut env = Env::new(env_config.clone()).expect("env");
        let (mut obs, _) = env.reset(seed).expect("reset");
        let mut behaviour = Behaviour::new(config.method, h, config.vge.hard_stop, config.fge.clone(), 1);
        let mut controllers = vec![EnvController {
            controller: vge_controllers::ControllerKind::Fg.build(
                &env_config,
                IgmConfig::default(),
                config.cs_config(&env_config),
            ),
            rng: ChaCha8Rng::seed_from_u64(seed + 100),
            calls: Vec::new(),
        }];
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let start = env.privileged().expect("state");
        let mut switches = ContactSwitches::new(&start.tip_contacts());
        let learner = [vec![0.0f32; env_config.hand.num_joints()]];
        for step in 0..h as u64 {
            let inputs = [env.privileged().map(ControllerInput::from_privileged)];
            let ctx =
                StepContext { step, obs: std::slice::from_ref(&obs), learner: &learner, inputs: &inputs };
            let d = behaviour.act(&ctx, &mut controllers, &mut prefer_controller, &mut rng).expect("decide");
            assert_eq!(d[0].source, Source::Controller, "seed {seed} step {step}: the pick lasts H steps");
            let r = env.step(&d[0].action).expect("step");
            switches.update(&r.info.tip_contacts);
            obs = r.obs;
            assert!(!r.terminated, "seed {seed}: dropped at step {step}");
        }
        assert_eq!(behaviour.stats.selections, 1, "one draw in H steps");
        completed.push(switches.count);
    }
    // CS's trajectory breaks and remakes the contact in about 9 of 10 draws (controllers::cs).
    let with_switch = completed.iter().filter(|&&c| c >= 1).count();
    assert!(with_switch >= 3, "switches completed per H-step pick, seeds 0-3: {completed:?}");
}

#[test]
fn a_failed_or_non_finite_q_query_stops_vge_instead_of_falling_back() {
    let config = shipped_vge_config();
    let env_config = config.env_config(0).expect("env");
    let mut env = Env::new(env_config.clone()).expect("env");
    let (obs, _) = env.reset(0).expect("reset");
    let inputs = [env.privileged().map(ControllerInput::from_privileged)];
    let learner = [vec![0.0f32; env_config.hand.num_joints()]];
    let ctx = StepContext { step: 7, obs: std::slice::from_ref(&obs), learner: &learner, inputs: &inputs };
    let mut controllers = vec![EnvController {
        controller: vge_controllers::ControllerKind::Fg.build(
            &env_config,
            IgmConfig::default(),
            config.cs_config(&env_config),
        ),
        rng: ChaCha8Rng::seed_from_u64(1),
        calls: Vec::new(),
    }];
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut b = Behaviour::from_config(&Config { num_envs: 1, ..config.clone() });
    let mut failing = |_: &[&[f32]], _: &[&[f32]]| Err("critic gone".to_owned());
    let e = b.act(&ctx, &mut controllers, &mut failing, &mut rng).expect_err("failed query");
    assert!(matches!(e, BehaviourError::QQuery { step: 7, .. }), "{e}");
    let mut b = Behaviour::from_config(&Config { num_envs: 1, ..config });
    let mut nan = |_: &[&[f32]], a: &[&[f32]]| Ok(vec![f32::NAN; a.len()]);
    let e = b.act(&ctx, &mut controllers, &mut nan, &mut rng).expect_err("NaN Q");
    assert!(matches!(e, BehaviourError::QNonFinite { step: 7, env: 0, .. }), "{e}");
}

#[test]
fn rl_bc_stores_and_clones_controller_actions_it_did_not_execute() {
    let mut c = shipped_vge_config();
    for o in [
        "method=rl-bc",
        "num_envs=2",
        "env.episode_length=30",
        "sac.hidden=[32, 32]",
        "sac.batch=32",
        "sac.warmup=60",
        "sac.buffer_size=1000",
        "sac.threads=1",
        "run.log_interval=40",
        "run.checkpoint_interval=0",
        "run.eval_interval=0",
        "run.eval_episodes=1",
        "run.eval_episode_s=1.0",
        "run.score_episodes=0",
    ] {
        apply_override(&mut c, o).expect(o);
    }
    c.total_steps = 160;
    c.validate().expect("valid");
    let dir = common::temp_dir("faithful-rl-bc");
    let summary = train(&c, &dir, false, &AtomicBool::new(false), &mut |_| {}).expect("train");
    assert_eq!(summary.behaviour.controller_steps, 0, "RL+BC never executes a controller action");
    assert_eq!(summary.behaviour.controller_queries, 160, "the controller labels every visited state");
    let mut replay = ReplayBuffer::new(1000, OBS_DIM, NUM_JOINTS).expect("buffer");
    replay.load(&dir.join("checkpoint/replay.bin")).expect("replay");
    let (mut labelled, mut differ) = (0, 0);
    for i in 0..replay.len() {
        assert_eq!(replay.source(i), Some(Source::Learner), "row {i}");
        if let Some(target) = replay.bc_target(i) {
            labelled += 1;
            let executed = replay.gather(&[i], None).action;
            let executed = Vec::<f32>::try_from(executed.view(-1)).expect("action");
            differ += usize::from(executed.iter().zip(target).any(|(a, b)| (a - b).abs() > 1e-6));
        }
    }
    assert!(labelled > 100, "{labelled} of {} rows carry a controller action", replay.len());
    assert!(differ > labelled / 2, "the cloned actions are not the executed ones ({differ} of {labelled})");
    // The BC term is in the actor's loss: a non-zero bc_loss column once updates run.
    let metrics = std::fs::read_to_string(dir.join("metrics.csv")).expect("metrics");
    let header: Vec<&str> = metrics.lines().next().expect("header").split(',').collect();
    let col = header.iter().position(|h| *h == "bc_loss").expect("bc_loss column");
    let last = metrics.lines().last().expect("row").split(',').nth(col).expect("field");
    assert!(last.parse::<f64>().expect("bc_loss").abs() > 0.0, "bc_loss {last}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bc_log_density_stays_finite_and_moderate_for_actions_at_the_bound() {
    let vs = tch::nn::VarStore::new(Device::Cpu);
    let spec = NetSpec { obs_dim: OBS_DIM as i64, act_dim: NUM_JOINTS as i64, hidden: vec![32, 32] };
    let actor = GaussianActor::new(&vs.root(), &spec, &[0.05; NUM_JOINTS]);
    let obs = Tensor::zeros([4, OBS_DIM as i64], (Kind::Float, Device::Cpu));
    // Controller actions are clipped to exactly +-max_action; the BC target is pulled inside.
    let at_bound = Tensor::full([4, NUM_JOINTS as i64], 0.05, (Kind::Float, Device::Cpu));
    let scale = Tensor::full([NUM_JOINTS as i64], 0.05, (Kind::Float, Device::Cpu));
    let target = (&at_bound / &scale)
        .clamp(-vge_trainer::learner::BC_TARGET_MAX_UNIT, vge_trainer::learner::BC_TARGET_MAX_UNIT)
        * &scale;
    let (_, log_prob) = actor.sample_and_log_prob_of(&obs, &target, None, true);
    let lp = Vec::<f32>::try_from(log_prob.view(-1)).expect("log prob");
    assert!(lp.iter().all(|v| v.is_finite()), "{lp:?}");
    // At the initial sigma (~0.2) each of the 15 dimensions is ~15 sigma out at most.
    assert!(lp.iter().all(|v| *v > -15.0 * 200.0), "{lp:?}");
}

fn gait_policy() -> PathBuf {
    repo_root().join("tests/fixtures/policies/td3-gait-90min.vgep")
}

#[test]
fn the_success_test_counts_a_known_two_pi_episode_and_rejects_a_dropped_one() {
    // The stored TD3 gait from the default grasp turns the cube 8 rad in 40 s without a drop.
    let env = success_test_env(&vge_sim::EnvConfig::default(), 40.0, 0.0);
    let report = eval_policy_file(&gait_policy(), &env, 1, 0).expect("eval");
    let ep = report.per_episode[0];
    assert!(ep.rotation_rad >= std::f64::consts::TAU && !ep.terminated, "{ep:?}");
    assert_eq!(report.success_rate, 1.0);
    assert!(ep.contact_switches >= 10, "it gaits: {ep:?}");
    // Pushed by 5 N forces it drops: not a success, whatever it turned before.
    let mut pushed = env.clone();
    pushed.perturbation.force_std_n = 5.0;
    pushed.perturbation.change_probability = 0.2;
    let report = eval_policy_file(&gait_policy(), &pushed, 2, 0).expect("eval");
    assert!(report.per_episode.iter().all(|e| e.terminated), "{:?}", report.per_episode);
    assert_eq!(report.success_rate, 0.0);
    assert_eq!(report.drop_rate, 1.0);
    // A dropped episode never counts, even past 2π; a whole one below 2π does not either.
    let dropped = EpisodeOutcome { rotation_rad: 7.0, terminated: true, ..EpisodeOutcome::default() };
    let short = EpisodeOutcome { rotation_rad: 6.2, ..EpisodeOutcome::default() };
    let whole = EpisodeOutcome { rotation_rad: 6.3, ..EpisodeOutcome::default() };
    let s = summarise(&[dropped, short, whole, whole]);
    assert_eq!(s.success_rate, 0.5);
    assert!(s.learned(), "2 of 4 is the 50% that counts as learned");
    assert!(!summarise(&[dropped, short, whole]).learned());
}
