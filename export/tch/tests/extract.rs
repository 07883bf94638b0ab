//! Extraction layout, and typed errors when the VarStore does not hold the expected actor.
#![allow(clippy::unwrap_used)]

use tch::Device;
use tch::nn::VarStore;
use vge_export::{ActorSpec, ExportError};
use vge_export_tch::{build_actor, extract_actor};

fn store(spec: &ActorSpec) -> VarStore {
    tch::manual_seed(3);
    let vs = VarStore::new(Device::Cpu);
    build_actor(&(vs.root() / "actor"), spec).unwrap();
    vs
}

fn spec() -> ActorSpec {
    ActorSpec { obs_dim: 5, hidden: vec![8], act_dim: 2 }
}

#[test]
fn missing_variable_is_reported_by_name() {
    let vs = store(&spec());
    let two_hidden = ActorSpec { hidden: vec![8, 8], ..spec() };
    match extract_actor(&vs, "actor", &two_hidden) {
        Err(ExportError::MissingVariable { name }) => assert_eq!(name, "actor.l1.weight"),
        other => panic!("expected MissingVariable, got {other:?}"),
    }
    match extract_actor(&vs, "policy", &spec()) {
        Err(ExportError::MissingVariable { name }) => assert_eq!(name, "policy.l0.weight"),
        other => panic!("expected MissingVariable, got {other:?}"),
    }
}

#[test]
fn wrong_shape_is_reported() {
    let vs = store(&spec());
    let wrong_obs = ActorSpec { obs_dim: 6, ..spec() };
    match extract_actor(&vs, "actor", &wrong_obs) {
        Err(ExportError::WrongShape { name, expected, got }) => {
            assert_eq!(name, "actor.l0.weight");
            assert_eq!((expected, got), (vec![8, 6], vec![8, 5]));
        }
        other => panic!("expected WrongShape, got {other:?}"),
    }
    let wrong_act = ActorSpec { act_dim: 3, ..spec() };
    match extract_actor(&vs, "actor", &wrong_act) {
        Err(ExportError::WrongShape { name, .. }) => assert_eq!(name, "actor.mean.weight"),
        other => panic!("expected WrongShape, got {other:?}"),
    }
}

#[test]
fn non_f32_is_reported() {
    let mut vs = store(&spec());
    vs.double();
    match extract_actor(&vs, "actor", &spec()) {
        Err(ExportError::WrongKind { name, kind }) => {
            assert_eq!(name, "actor.l0.weight");
            assert_eq!(kind, format!("{:?}", tch::Kind::Double));
        }
        other => panic!("expected WrongKind, got {other:?}"),
    }
}

#[test]
fn non_finite_is_reported() {
    let vs = store(&spec());
    let vars = vs.variables();
    tch::no_grad(|| {
        let _ = vars["actor.mean.bias"].get(1).fill_(f64::NAN);
        let _ = vars["actor.l0.weight"].get(2).get(3).fill_(f64::INFINITY);
    });
    match extract_actor(&vs, "actor", &spec()) {
        Err(ExportError::NonFinite { name, index }) => {
            assert_eq!(name, "actor.l0.weight");
            assert_eq!(index, 2 * 5 + 3);
        }
        other => panic!("expected NonFinite, got {other:?}"),
    }
}

#[test]
fn invalid_spec_is_reported() {
    let vs = VarStore::new(Device::Cpu);
    let zero = ActorSpec { hidden: vec![0], ..spec() };
    assert!(matches!(build_actor(&(vs.root() / "actor"), &zero), Err(ExportError::InvalidSpec(_))));
    assert!(matches!(extract_actor(&vs, "actor", &zero), Err(ExportError::InvalidSpec(_))));
}

#[test]
fn errors_display() {
    let e = ExportError::MissingVariable { name: "actor.l0.weight".into() };
    assert_eq!(e.to_string(), "variable `actor.l0.weight` not found in the var store");
}

#[test]
fn exported_weights_are_row_major_out_by_in() {
    tch::manual_seed(1);
    let vs = VarStore::new(Device::Cpu);
    let spec = ActorSpec { obs_dim: 3, hidden: vec![4], act_dim: 2 };
    let actor = build_actor(&(vs.root() / "actor"), &spec).unwrap();
    let exported = extract_actor(&vs, "actor", &spec).unwrap();
    let l0 = &exported.layers[0];
    assert_eq!((l0.in_dim, l0.out_dim, l0.weights.len(), l0.bias.len()), (3, 4, 12, 4));
    // weight[o][i] of the tch tensor == weights[o * in + i]
    let w = &actor.hidden[0].ws;
    for o in 0..4 {
        for i in 0..3 {
            let v = w.double_value(&[o, i]) as f32;
            assert_eq!(v, l0.weights[(o * 3 + i) as usize]);
        }
    }
}
