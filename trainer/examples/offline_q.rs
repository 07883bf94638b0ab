//! Diagnostic: learner updates on a run's saved replay buffer (`checkpoint/replay.bin`),
//! printing mean Q and the critic loss every 1000 updates, to see whether a configuration's
//! critic stays bounded without running the simulator. Overrides as in `vge train --set`:
//!
//!   cargo run --release -p vge-trainer --example offline_q -- runs/X 6000 sac.critic_lr=3e-4
//!
//! (How the stop-8 divergence was traced: with `sac.actor_lr=1e-12` Q stays bounded.)
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::Device;
use vge_run::config::{Config, apply_override};
use vge_trainer::learner::{self, LearnerConfig};
use vge_trainer::replay::ReplayBuffer;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(args.len() >= 3, "usage: offline_q RUN_DIR UPDATES [key=value ...]");
    let dir = std::path::Path::new(&args[1]);
    let updates: usize = args[2].parse()?;
    let mut config: Config = toml::from_str(&std::fs::read_to_string(dir.join("config.toml"))?)?;
    for o in &args[3..] {
        apply_override(&mut config, o)?;
    }
    tch::set_num_threads(2);
    let learner_config = LearnerConfig::for_hand(&config)?;
    let (rows, actions) = (learner_config.columns.row_dim() as usize, learner_config.net.act_dim as usize);
    let mut replay = ReplayBuffer::new(1_000_000, rows, actions)?;
    replay.load(&dir.join("checkpoint/replay.bin"))?;
    let mut sac = learner::build_seeded(learner_config, Device::Cpu, 0)?;
    if config.sac.normalize_obs {
        let (m, s) = replay.obs_stats(1e-2);
        sac.set_obs_normalisation(&m, &s);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let (mut q, mut l) = (0.0, 0.0);
    for i in 1..=updates {
        let st = sac.update(&replay.sample(256, &mut rng, None)?);
        q += st.mean_q;
        l += st.critic_loss;
        if i % 1000 == 0 {
            println!("{i} mean_q {:.3} critic_loss {:.4}", q / 1000.0, l / 1000.0);
            q = 0.0;
            l = 0.0;
        }
    }
    Ok(())
}
