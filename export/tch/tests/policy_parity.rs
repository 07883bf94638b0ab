//! Parity of a policy file run by the no_std runtime with tch's forward of the same actor
//! (normalisation, tanh head and action scaling included), plus file size and load time.
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use tch::nn::{Module, VarStore};
use tch::{Device, Kind, Tensor};
use vge_export::{ActorSpec, ObsNorm, ObsSlice, PolicyMeta, Provenance};
use vge_export_tch::{build_actor, export_policy};
use vge_runtime::HandPolicy;

#[test]
fn runtime_policy_matches_tch_on_10000_observations() {
    // Alone in this test binary: the global torch RNG is not shared with other tests.
    tch::manual_seed(11);
    let vs = VarStore::new(Device::Cpu);
    let spec = ActorSpec { obs_dim: 65, hidden: vec![256, 256], act_dim: 15 };
    let actor = build_actor(&(vs.root() / "actor"), &spec).unwrap();
    let _log_std = tch::nn::linear(vs.root() / "actor" / "log_std", 256, 15, Default::default());

    let mean: Vec<f32> = (0..65).map(|i| (i as f32 * 0.7).sin()).collect();
    let std: Vec<f32> = (0..65).map(|i| 0.3 + (i as f32 * 0.3).cos().abs()).collect();
    let scale: Vec<f32> = (0..15).map(|i| 0.01 * (i + 1) as f32).collect();
    let offset: Vec<f32> = (0..15).map(|i| 0.001 * i as f32 - 0.005).collect();
    let clip = 4.0f32;
    let meta = PolicyMeta {
        obs_layout: vec![ObsSlice::new("q", 0..15), ObsSlice::new("rest", 15..65)],
        action_names: (0..15).map(|i| format!("j{i}")).collect(),
        obs_norm: ObsNorm { mean: mean.clone(), std: std.clone(), clip: Some(clip) },
        action_scale: scale.clone(),
        action_offset: offset.clone(),
        control_hz: 20.0,
        provenance: Provenance { vge_version: "0.1.0".into(), config_hash: "x".into(), seed: 11, steps: 1 },
        task: None,
    };
    // In a 16-byte aligned buffer, as the bridge and the firmware hold it: version 2's arrays
    // are read in place.
    let bytes = vge_runtime::AlignedBytes::new(&export_policy(&vs, "actor", &spec, meta).unwrap());

    let mut storage: Vec<f32> = Vec::new();
    let t0 = Instant::now();
    let reps = 20;
    for _ in 0..reps {
        let _ = HandPolicy::load(&bytes, &mut storage).unwrap();
    }
    let load_us = t0.elapsed().as_secs_f64() * 1e6 / f64::from(reps);
    let t0 = Instant::now();
    for _ in 0..reps {
        let _ = vge_runtime::policy::inspect(&bytes).unwrap();
    }
    let check_us = t0.elapsed().as_secs_f64() * 1e6 / f64::from(reps);
    eprintln!(
        "65-256-256-15 policy file: {} bytes; Policy::load {load_us:.0} us (validate-only inspect {check_us:.0} us)",
        bytes.len()
    );
    let policy = HandPolicy::load(&bytes, &mut storage).unwrap();

    let n = 10_000;
    // Wide enough that some observations hit the clip and many outputs saturate tanh.
    let obs = Tensor::randn([n, 65], (Kind::Float, Device::Cpu)) * 3.0;
    let expected = tch::no_grad(|| {
        let m = Tensor::from_slice(&mean);
        let s = Tensor::from_slice(&std);
        let x = ((&obs - m) / s).clamp(-f64::from(clip), f64::from(clip));
        actor.forward(&x) * Tensor::from_slice(&scale) + Tensor::from_slice(&offset)
    });
    let obs_v = Vec::<f32>::try_from(&obs.flatten(0, -1)).unwrap();
    let exp_v = Vec::<f32>::try_from(&expected.flatten(0, -1)).unwrap();

    let mut action = [0.0f32; 15];
    let mut max_diff = 0.0f32;
    let mut near_limit = 0usize;
    for (o, e) in obs_v.chunks_exact(65).zip(exp_v.chunks_exact(15)) {
        policy.forward(o, &mut action).unwrap();
        for ((a, b), s) in action.iter().zip(e).zip(&scale) {
            max_diff = max_diff.max((a - b).abs());
            near_limit += usize::from(b.abs() > 0.5 * s);
        }
    }
    eprintln!("max |tch - runtime| over {n} obs: {max_diff:e} ({near_limit} outputs beyond half scale)");
    assert!(max_diff <= 1e-5, "max abs diff {max_diff}");
    assert!(near_limit > 0);
}
