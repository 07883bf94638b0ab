//! Batch-1 forward latency of a policy file in this build of the runtime, as one JSON line:
//! `cargo run --release -p vge-runtime --features std[,simd] --example forward_bench -- FILE [ITERS]`.
//!
//! Times `Policy::forward` (normalisation, the MLP, action scaling: what the file's ONNX
//! export computes) on seeded observations drawn around the file's observation mean, one
//! forward per sample, and prints the median and 99th percentile. scripts/bench-runtime-vs-onnxruntime.sh
//! sets it beside onnxruntime on the same policy.

use std::hint::black_box;
use std::time::Instant;

use vge_runtime::{AlignedBytes, HandPolicy, float_kernel};

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().ok_or("usage: forward_bench POLICY.vgep [ITERS]")?;
    let iters: usize = match args.get(1) {
        Some(n) => n.parse().map_err(|e| format!("ITERS {n}: {e}"))?,
        None => 20_000,
    };
    if iters == 0 {
        return Err("ITERS must be at least 1".to_owned());
    }
    let bytes = AlignedBytes::new(&std::fs::read(path).map_err(|e| format!("{path}: {e}"))?);
    let info = vge_runtime::policy::inspect(&bytes).map_err(|e| format!("{path}: {e}"))?;
    let mut storage = vec![0.0f32; info.storage_len];
    let policy = HandPolicy::load(&bytes, &mut storage).map_err(|e| format!("{path}: {e}"))?;
    let (n_obs, n_act) = (policy.obs_dim(), policy.act_dim());
    // Observations: a fixed xorshift stream in [-1, 1) per entry (the normalised input then
    // spans a few standard deviations of the file's statistics).
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut draw = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    };
    let observations: Vec<Vec<f32>> = (0..64).map(|_| (0..n_obs).map(|_| draw()).collect()).collect();
    let mut action = vec![0.0f32; n_act];
    for obs in observations.iter().cycle().take(iters / 10 + 100) {
        policy.forward(obs, &mut action).map_err(|e| e.to_string())?;
    }
    let mut ns = Vec::with_capacity(iters);
    for obs in observations.iter().cycle().take(iters) {
        let t = Instant::now();
        policy.forward(black_box(obs), black_box(&mut action)).map_err(|e| e.to_string())?;
        ns.push(t.elapsed().as_nanos() as f64);
    }
    ns.sort_by(f64::total_cmp);
    let at = |q: f64| ns[((ns.len() - 1) as f64 * q).round() as usize];
    let dims: Vec<usize> =
        std::iter::once(n_obs).chain(policy.mlp().layers().iter().map(|l| l.out_dim)).collect();
    println!(
        "{{\"bench\": \"vge_runtime\", \"kernel\": \"{}\", \"dims\": {:?}, \"iters\": {iters}, \"median_ns\": {}, \"p99_ns\": {}}}",
        float_kernel(),
        dims,
        at(0.5),
        at(0.99)
    );
    Ok(())
}
