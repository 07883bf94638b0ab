//! End to end on real components: a short training run (SAC + VGE + FG on the rapier hand)
//! -> the exported policy file -> parity of vge-runtime with tch on that actor -> the policy
//! driving the simulated hand through vge-bridge's control loop and CAN protocol.

use std::sync::atomic::AtomicBool;
use std::thread;
use std::time::Duration;

use rand::{RngExt, SeedableRng};
use tch::{Device, Kind, Tensor, nn};
use vge_bridge::control_loop::{self, LoopConfig, StopReason};
use vge_bridge::policy_runner::{RuntimePolicy, storage_for};
use vge_bridge::sim_hand::{self, SimHand};
use vge_bridge::transport::InProcessTransport;
use vge_run::config::{Config, apply_override};
use vge_sim::EnvConfig;
use vge_trainer::nets::{GaussianActor, NetSpec};

fn short_run_config() -> Config {
    let mut c = Config::default();
    for o in [
        "num_envs=2",
        "method=vge",
        "controller=fg",
        "env.episode_length=40",
        "sac.hidden=[64, 64]",
        "sac.batch=64",
        "sac.warmup=100",
        "sac.buffer_size=5000",
        "vge.horizon=5",
        "vge.hard_stop=300",
        "run.log_interval=100",
        "run.checkpoint_interval=200",
        "run.eval_interval=400",
        "run.eval_episodes=1",
        "run.score_episodes=0",
        "sac.threads=1",
    ] {
        apply_override(&mut c, o).expect(o);
    }
    c.total_steps = 400;
    c.validate().expect("valid config");
    c
}

#[test]
fn train_export_runtime_parity_and_bridge_on_the_sim() {
    let dir = std::env::temp_dir().join(format!("vge-e2e-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = short_run_config();

    // 1. Train.
    let summary = vge_trainer::train::train(&config, &dir, false, &AtomicBool::new(false), &mut |_| {})
        .expect("training runs");
    assert_eq!(summary.steps, 400);
    assert!(summary.updates > 0);
    assert!(summary.behaviour.controller_steps > 0, "VGE followed the controller at some point");
    let policy_path = summary.policy.expect("a finished run exports its policy");

    // 2. The policy file is what vge-runtime loads.
    let bytes = vge_runtime::AlignedBytes::new(&std::fs::read(&policy_path).expect("policy file"));
    let vge15 = vge_sim::hands::vge15().expect("vge15");
    let (_, mut storage) = storage_for(&bytes, &vge15, true).expect("valid policy file for the hand");
    let mut runner = RuntimePolicy::load(&bytes, &mut storage).expect("loads");
    assert_eq!(runner.control_hz(), config.env.control_hz);

    // 3. Parity: the runtime's forward equals tch's deterministic head of the trained actor
    //    (the final checkpoint holds it).
    let mut vs = nn::VarStore::new(Device::Cpu);
    let env = config.env_config(0).expect("env");
    let (obs_dim, joints) = (env.observation_layout().dim(), env.hand.num_joints());
    let spec = NetSpec { obs_dim: obs_dim as i64, act_dim: joints as i64, hidden: vec![64, 64] };
    let actor = GaussianActor::new(&vs.root(), &spec, &vec![config.env.max_action_rad; joints]);
    vs.load(dir.join("checkpoint").join("actor.ot")).expect("final actor checkpoint");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut max_diff = 0.0f32;
    for _ in 0..500 {
        let obs: Vec<f32> = (0..obs_dim).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut action = vec![0.0f32; joints];
        runner.policy.forward(&obs, &mut action).expect("finite observation");
        let expected = tch::no_grad(|| actor.deterministic(&Tensor::from_slice(&obs).unsqueeze(0)));
        let expected: Vec<f32> = Vec::try_from(expected.to_kind(Kind::Float).flatten(0, -1)).expect("f32");
        for (a, e) in action.iter().zip(&expected) {
            max_diff = max_diff.max((a - e).abs());
        }
    }
    assert!(max_diff <= 1e-5, "runtime vs tch: {max_diff}");

    // 4. The bridge runs it against the simulated hand, over the protocol, at 20 Hz.
    let (mut bridge, mut nodes) = InProcessTransport::pair();
    let stop_nodes = std::sync::Arc::new(AtomicBool::new(false));
    let flag = stop_nodes.clone();
    let env = EnvConfig::default();
    let protocol_hand =
        vge_bridge::protocol_hand::ProtocolHand::of(&env.hand).expect("vge15 on vge's protocol");
    let rate_hz = f64::from(env.control_hz);
    let hand = SimHand::new(env, 9, Duration::from_secs(1)).expect("simulated hand");
    let sim = thread::spawn(move || {
        let mut hand = hand;
        sim_hand::serve(&mut nodes, &mut hand, Duration::from_secs(5), &flag).map(|_| hand.summary())
    });
    let loop_config = LoopConfig {
        duration: Some(Duration::from_secs(2)),
        halt_hold_periods: 2,
        max_delta_rad: config.env.max_action_rad,
        ..LoopConfig::new(rate_hz, protocol_hand)
    };
    let report = control_loop::run(&mut bridge, &mut runner, &loop_config, &AtomicBool::new(false))
        .expect("bridge loop runs");
    stop_nodes.store(true, std::sync::atomic::Ordering::Relaxed);
    let sim_summary = sim.join().expect("sim thread").expect("sim served");
    let _ = std::fs::remove_dir_all(&dir);

    assert_eq!(report.stop_reason, StopReason::DurationReached);
    assert!((38..=41).contains(&report.pace.steps), "{} steps in 2 s at 20 Hz", report.pace.steps);
    assert_eq!((report.link.bad_frames, report.safety.non_finite_holds), (0, 0));
    assert!(sim_summary.steps >= report.pace.steps, "{sim_summary:?}");
    assert!(sim_summary.rotation_rad.is_finite());
    eprintln!("e2e: runtime vs tch max diff {max_diff:.2e}; bridge {report:?}; object {sim_summary:?}");
}
