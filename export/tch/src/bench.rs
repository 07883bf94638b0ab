//! `vge bench runtime`: the runtime's batch-1 forward against tch's, on the same actor.
//!
//! Builds a SAC actor head `65 -> 256 -> 256 -> 15` (ReLU, ReLU, tanh) in tch with a fixed
//! seed, exports it to the runtime, and times single forwards of both on the same random
//! observations, interleaved so that both see the same machine state. Each sample is one
//! forward timed with [`Instant`]; the report gives the median and the 99th percentile.
//!
//! `tch_ns` times `actor.forward(obs)` under `no_grad` on a `[1, 65]` tensor made beforehand,
//! without copying the observation in or the action out (conservative: a deployment would
//! pay for those too). `runtime_ns` times `Mlp::forward(&[f32], &mut [f32])`, which
//! includes its input checks.

use std::hint::black_box;
use std::time::Instant;

use tch::nn::{Module, VarStore};
use tch::{Device, Kind, Tensor};
use vge_runtime::PolicyMlp;

use vge_export::{ActorSpec, ExportError};

use crate::{build_actor, extract_actor, tch_error};

/// Multiply-accumulates per forward of a `dims[0] -> ... -> dims[n]` MLP.
pub fn macs(dims: &[usize]) -> usize {
    dims.windows(2).map(|w| w[0] * w[1]).sum()
}

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchConfig {
    pub obs_dim: usize,
    pub hidden: Vec<usize>,
    pub act_dim: usize,
    /// Timed forwards per implementation.
    pub iters: usize,
    /// Untimed forwards per implementation first.
    pub warmup: usize,
    /// Seed for the actor's initialisation (tch) and the observations.
    pub seed: u64,
}

impl BenchConfig {
    /// An actor of the given shape (the hand and config decide it: `vge bench runtime` takes
    /// the default run's), 20,000 timed forwards after 2,000 untimed, seed 0.
    #[must_use]
    pub fn of_shape(spec: &ActorSpec) -> Self {
        Self {
            obs_dim: spec.obs_dim,
            hidden: spec.hidden.clone(),
            act_dim: spec.act_dim,
            iters: 20_000,
            warmup: 2_000,
            seed: 0,
        }
    }
}

/// Timings in nanoseconds per batch-1 forward.
#[derive(Debug, Clone, PartialEq)]
pub struct RuntimeBench {
    /// `obs -> hidden... -> act`.
    pub dims: Vec<usize>,
    pub iters: usize,
    pub runtime_ns: f64,
    pub runtime_p99_ns: f64,
    pub tch_ns: f64,
    pub tch_p99_ns: f64,
    /// libtorch intra-op threads during the run.
    pub tch_threads: i32,
    /// Largest |runtime - tch| over the timed observations (a sanity check, not a parity test).
    pub max_abs_diff: f32,
}

impl RuntimeBench {
    /// Multiply-accumulates per forward.
    pub fn macs(&self) -> usize {
        macs(&self.dims)
    }

    /// One JSON object on one line (no trailing newline).
    pub fn to_json_line(&self) -> String {
        let macs = self.macs();
        serde_json::json!({
            "bench": "runtime",
            "dims": self.dims,
            "batch": 1,
            "iters": self.iters,
            "runtime_ns": self.runtime_ns,
            "runtime_p99_ns": self.runtime_p99_ns,
            "tch_ns": self.tch_ns,
            "tch_p99_ns": self.tch_p99_ns,
            "speedup": self.tch_ns / self.runtime_ns,
            "macs": macs,
            "runtime_gflops": 2.0 * macs as f64 / self.runtime_ns,
            "tch_threads": self.tch_threads,
            "max_abs_diff": self.max_abs_diff,
        })
        .to_string()
    }
}

/// `n` observations uniform in [-3, 3) as a `[n, dim]` tensor and flattened row-major.
fn uniform_observations(n: i64, dim: i64) -> Result<(Tensor, Vec<f32>), tch::TchError> {
    let obs = Tensor::f_rand([n, dim], (Kind::Float, Device::Cpu))?.f_mul_scalar(6.0)?.f_sub_scalar(3.0)?;
    let flat = Vec::<f32>::try_from(&obs.f_flatten(0, -1)?)?;
    Ok((obs, flat))
}

/// Runs the benchmark (a few seconds with the default config).
pub fn run(config: &BenchConfig) -> Result<RuntimeBench, ExportError> {
    let spec = ActorSpec { obs_dim: config.obs_dim, hidden: config.hidden.clone(), act_dim: config.act_dim };
    spec.validate()?;
    let seed = i64::try_from(config.seed)
        .map_err(|_| ExportError::InvalidSpec(format!("seed {} does not fit in i64", config.seed)))?;
    tch::manual_seed(seed);
    let vs = VarStore::new(Device::Cpu);
    let actor = build_actor(&(vs.root() / "actor"), &spec)?;
    let exported = extract_actor(&vs, "actor", &spec)?;
    let mlp: PolicyMlp<'_> = exported.to_mlp()?;

    let n_obs = 64;
    let obs_dim = i64::try_from(config.obs_dim)
        .map_err(|_| ExportError::InvalidSpec(format!("obs_dim {} does not fit in i64", config.obs_dim)))?;
    let (obs_t, obs_flat) = uniform_observations(n_obs, obs_dim).map_err(tch_error)?;
    let obs_rows: Vec<&[f32]> = obs_flat.chunks_exact(config.obs_dim).collect();
    let obs_tensors: Vec<Tensor> = (0..n_obs).map(|i| obs_t.narrow(0, i, 1)).collect();

    let mut action = vec![0.0f32; config.act_dim];
    let mut runtime = Vec::with_capacity(config.iters);
    let mut torch = Vec::with_capacity(config.iters);
    let mut max_abs_diff = 0.0f32;
    tch::no_grad(|| -> Result<(), ExportError> {
        for i in 0..config.warmup + config.iters {
            let k = i % obs_rows.len();
            let t0 = Instant::now();
            mlp.forward(black_box(obs_rows[k]), black_box(&mut action))?;
            let t1 = Instant::now();
            let y = actor.forward(black_box(&obs_tensors[k]));
            let t2 = Instant::now();
            if i >= config.warmup {
                runtime.push((t1 - t0).as_nanos() as f64);
                torch.push((t2 - t1).as_nanos() as f64);
                let y = y.f_flatten(0, -1).and_then(|y| Vec::<f32>::try_from(&y)).map_err(tch_error)?;
                for (a, b) in action.iter().zip(&y) {
                    max_abs_diff = max_abs_diff.max((a - b).abs());
                }
            }
        }
        Ok(())
    })?;
    let mut dims = vec![config.obs_dim];
    dims.extend(&config.hidden);
    dims.push(config.act_dim);
    Ok(RuntimeBench {
        dims,
        iters: config.iters,
        runtime_ns: percentile(&mut runtime, 0.5),
        runtime_p99_ns: percentile(&mut runtime, 0.99),
        tch_ns: percentile(&mut torch, 0.5),
        tch_p99_ns: percentile(&mut torch, 0.99),
        tch_threads: tch::get_num_threads(),
        max_abs_diff,
    })
}

/// Nearest-rank percentile; NaN for no samples.
// The same definition as vge-controllers' rollout and the bridge's statistics (no shared crate).
fn percentile(samples: &mut [f64], q: f64) -> f64 {
    if samples.is_empty() {
        return f64::NAN;
    }
    samples.sort_by(f64::total_cmp);
    let rank = ((q * samples.len() as f64).ceil() as usize).clamp(1, samples.len());
    samples[rank - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn macs_of_the_policy_net() {
        // 65*256 + 256*256 + 256*15 = 16_640 + 65_536 + 3_840.
        assert_eq!(macs(&[65, 256, 256, 15]), 86_016);
    }

    #[test]
    fn percentile_is_nearest_rank() {
        let mut v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(&mut v, 0.5), 50.0);
        assert_eq!(percentile(&mut v, 0.99), 99.0);
        assert!(percentile(&mut [], 0.5).is_nan());
    }

    /// vge15's default actor: 65 observations, 15 joints.
    fn vge15_actor() -> ActorSpec {
        ActorSpec { obs_dim: 65, hidden: vec![256, 256], act_dim: 15 }
    }

    #[test]
    fn small_run_reports_consistent_json() {
        let config = BenchConfig { iters: 50, warmup: 5, ..BenchConfig::of_shape(&vge15_actor()) };
        let bench = run(&config).expect("bench runs");
        assert!(bench.runtime_ns > 0.0 && bench.tch_ns > 0.0);
        assert!(bench.runtime_p99_ns >= bench.runtime_ns && bench.tch_p99_ns >= bench.tch_ns);
        assert!(bench.max_abs_diff < 1e-5, "runtime and tch disagree: {}", bench.max_abs_diff);
        let line = bench.to_json_line();
        assert!(!line.contains('\n'));
        for key in ["\"runtime_ns\":", "\"runtime_p99_ns\":", "\"tch_ns\":", "\"tch_p99_ns\":"] {
            assert!(line.contains(key), "{line}");
        }
    }

    /// The full benchmark, for measuring before `vge bench runtime` is wired:
    /// `cargo test --release -p vge-export --lib bench::tests::full -- --ignored --nocapture`.
    #[test]
    #[ignore = "a few seconds of timing; run by hand"]
    fn full_benchmark_prints_json() {
        let bench = run(&BenchConfig::of_shape(&vge15_actor())).expect("bench runs");
        println!("{}", bench.to_json_line());
    }
}
