//! Matmul throughput of the update's shapes in f32 and bf16 on this CPU (whether
//! bf16 matmuls with f32 master weights could pay). `cargo run --release --example
//! matmul_dtypes`.
use std::time::Instant;
use tch::{Device, Kind, Tensor};

fn rate(a: &Tensor, b: &Tensor, reps: usize) -> f64 {
    let _ = a.matmul(b);
    let start = Instant::now();
    for _ in 0..reps {
        let _ = a.matmul(b);
    }
    let (m, k) = (a.size()[a.dim() - 2], a.size()[a.dim() - 1]);
    let n = b.size()[b.dim() - 1];
    let batch: i64 = a.size()[..a.dim() - 2].iter().product();
    2.0 * (batch * m * k * n) as f64 * reps as f64 / start.elapsed().as_secs_f64() / 1e9
}

fn main() {
    for threads in [1, 2] {
        tch::set_num_threads(threads);
        for (m, k, n) in
            [(256, 80, 256), (256, 256, 256), (256, 256, 1), (2 * 256, 256, 256), (1024, 1024, 1024)]
        {
            let a = Tensor::randn([m, k], (Kind::Float, Device::Cpu));
            let b = Tensor::randn([k, n], (Kind::Float, Device::Cpu));
            let reps = (2e10 / (2.0 * (m * k * n) as f64)).clamp(20.0, 20000.0) as usize;
            let f32_rate = rate(&a, &b, reps);
            let (ab, bb) = (a.to_kind(Kind::BFloat16), b.to_kind(Kind::BFloat16));
            let bf16_rate = rate(&ab, &bb, reps);
            let cast = {
                let start = Instant::now();
                for _ in 0..reps {
                    let _ = a.to_kind(Kind::BFloat16);
                }
                start.elapsed().as_secs_f64() / reps as f64 * 1e6
            };
            println!(
                "threads {threads} [{m}x{k}]x[{k}x{n}]: f32 {f32_rate:.1} GFLOP/s, bf16 {bf16_rate:.1} GFLOP/s ({:.2}x), cast of a to bf16 {cast:.1} us",
                bf16_rate / f32_rate
            );
        }
    }
}
