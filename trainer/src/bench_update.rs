//! `vge bench update`: full SAC (or TD3) updates per second at a learner's sizes, against
//! the CPU's matmul throughput measured in the same run.

use std::time::Instant;

use tch::{Device, Kind, Tensor};

use crate::learner::{self, Batch, LearnerConfig};
use crate::nets::{NetSpec, TwinCritic};

#[derive(Debug, Clone, PartialEq)]
pub struct UpdateBench {
    pub batch: i64,
    pub updates: usize,
    pub threads: i32,
    pub updates_per_s: f64,
    /// Matmul FLOPs of one update (see [`flops_per_update`]) times updates per second.
    pub gflops: f64,
    /// A large single matmul's throughput on this CPU, same threads, same run.
    pub matmul_gflops: f64,
}

/// Multiply-add count of one dense layer stack at batch 1.
fn macs(widths: &[i64]) -> f64 {
    widths.windows(2).map(|w| (w[0] * w[1]) as f64).sum()
}

/// Matmul FLOPs of one SAC update. With A = one actor forward, C = one forward of both twins:
/// target (A + C) + critic step (forward + ~2x backward = 3C) + actor step (A + C forward,
/// ~C for input gradients through the frozen critic, ~2A backward) = 4A + 6C.
pub fn flops_per_update(spec: &NetSpec, batch: i64) -> f64 {
    let mut actor = vec![spec.obs_dim];
    actor.extend(&spec.hidden);
    let trunk = macs(&actor);
    let last = *actor.last().unwrap_or(&spec.obs_dim) as f64;
    let a = 2.0 * batch as f64 * (trunk + 2.0 * last * spec.act_dim as f64);
    let mut critic = vec![spec.obs_dim + spec.act_dim];
    critic.extend(&spec.hidden);
    critic.push(1);
    let c = 2.0 * batch as f64 * macs(&critic) * TwinCritic::TWINS as f64;
    4.0 * a + 6.0 * c
}

fn random_batch(spec: &NetSpec, batch: i64) -> Batch {
    let opts = (Kind::Float, Device::Cpu);
    Batch::new(
        Tensor::randn([batch, spec.obs_dim], opts),
        Tensor::rand([batch, spec.act_dim], opts) * 2.0 - 1.0,
        Tensor::randn([batch, 1], opts),
        Tensor::randn([batch, spec.obs_dim], opts),
        Tensor::zeros([batch, 1], opts),
    )
}

/// Runs `warmup` then `updates` updates of the learner `config` on random batches. The
/// FLOP count is SAC's; TD3's actor step every second update does less.
pub fn run(
    config: LearnerConfig,
    batch: i64,
    warmup: usize,
    updates: usize,
    seed: i64,
) -> Result<UpdateBench, tch::TchError> {
    tch::manual_seed(seed);
    let spec = config.net.clone();
    let mut learner = learner::build(config, Device::Cpu)?;
    let batches: Vec<Batch> = (0..8).map(|_| random_batch(&spec, batch)).collect();
    for i in 0..warmup {
        learner.update(&batches[i % batches.len()]);
    }
    let start = Instant::now();
    for i in 0..updates {
        learner.update(&batches[i % batches.len()]);
    }
    let updates_per_s = updates as f64 / start.elapsed().as_secs_f64();

    Ok(UpdateBench {
        batch,
        updates,
        threads: tch::get_num_threads(),
        updates_per_s,
        gflops: updates_per_s * flops_per_update(&spec, batch) / 1e9,
        matmul_gflops: matmul_gflops(),
    })
}

/// Throughput of a 1024x1024 by 1024x1024 f32 matmul, best of a few runs.
fn matmul_gflops() -> f64 {
    let n = 1024;
    let a = Tensor::randn([n, n], (Kind::Float, Device::Cpu));
    let b = Tensor::randn([n, n], (Kind::Float, Device::Cpu));
    let _ = a.matmul(&b);
    (0..5)
        .map(|_| {
            let start = Instant::now();
            let _ = a.matmul(&b);
            2.0 * (n * n * n) as f64 / start.elapsed().as_secs_f64() / 1e9
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flop_count_matches_hand_arithmetic_for_the_paper_sizes() {
        let spec = NetSpec { obs_dim: 65, act_dim: 15, hidden: vec![256, 256] };
        // A = 2·256·(65·256 + 256·256 + 2·256·15); C = 2·256·2·(80·256 + 256·256 + 256).
        let a = 2.0 * 256.0 * (16_640.0 + 65_536.0 + 7_680.0);
        let c = 2.0 * 256.0 * 2.0 * (20_480.0 + 65_536.0 + 256.0);
        assert_eq!(flops_per_update(&spec, 256), 4.0 * a + 6.0 * c);
    }
}
