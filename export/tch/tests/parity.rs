//! Parity between a real tch actor and the no_std runtime evaluating its exported layers.
#![allow(clippy::unwrap_used)]

use tch::nn::{Module, VarStore};
use tch::{Device, Kind, Tensor};
use vge_export::{Activation, ActorSpec};
use vge_export_tch::{build_actor, extract_actor};
use vge_runtime::PolicyMlp;

fn spec() -> ActorSpec {
    ActorSpec { obs_dim: 65, hidden: vec![256, 256], act_dim: 15 }
}

#[test]
fn runtime_matches_tch_on_1000_observations() {
    // Alone in this test binary: the global torch RNG is not shared with other tests.
    tch::manual_seed(7);
    let vs = VarStore::new(Device::Cpu);
    let spec = spec();
    let actor = build_actor(&(vs.root() / "actor"), &spec).unwrap();
    // Extra variables (another head, a critic) must be ignored by the exporter.
    let _log_std = tch::nn::linear(vs.root() / "actor" / "log_std", 256, 15, Default::default());
    let _critic = tch::nn::linear(vs.root() / "critic" / "l0", 80, 256, Default::default());

    let n = 1000;
    // Scaled so that many pre-activations land in tanh's non-linear range.
    let obs = Tensor::randn([n, 65], (Kind::Float, Device::Cpu)) * 3.0;
    let expected = tch::no_grad(|| actor.forward(&obs));
    assert_eq!(expected.size(), vec![n, 15]);
    let obs_v = Vec::<f32>::try_from(&obs.flatten(0, -1)).unwrap();
    let exp_v = Vec::<f32>::try_from(&expected.flatten(0, -1)).unwrap();

    let exported = extract_actor(&vs, "actor", &spec).unwrap();
    assert_eq!(exported.layers.len(), 3);
    assert_eq!((exported.obs_dim(), exported.act_dim()), (65, 15));
    let acts: Vec<_> = exported.layers.iter().map(|l| l.activation).collect();
    assert_eq!(acts, [Activation::Relu, Activation::Relu, Activation::Tanh]);
    let mlp: PolicyMlp<'_> = exported.to_mlp().unwrap();

    let mut action = [0.0f32; 15];
    let mut max_diff = 0.0f32;
    let mut saturated = 0usize;
    for (o, e) in obs_v.chunks_exact(65).zip(exp_v.chunks_exact(15)) {
        mlp.forward(o, &mut action).unwrap();
        for (a, b) in action.iter().zip(e) {
            max_diff = max_diff.max((a - b).abs());
            saturated += usize::from(b.abs() > 0.5);
        }
    }
    eprintln!("max |tch - runtime| over {n} obs: {max_diff:e} ({saturated} outputs with |a| > 0.5)");
    assert!(max_diff <= 1e-5, "max abs diff {max_diff}");
    // The comparison is not vacuous: outputs are not all ~0.
    assert!(saturated > 0);
}
