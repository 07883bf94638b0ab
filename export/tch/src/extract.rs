//! Reading an actor's parameters out of a `VarStore` into owned, validated layers.

use std::collections::HashMap;

use tch::{Device, Kind, Tensor, nn::VarStore};
use vge_runtime::Activation;

use vge_export::{ActorSpec, ExportError, ExportedActor, ExportedLayer};

use crate::tch_error;

/// Reads the actor built by [`build_actor`](crate::build_actor) under `prefix` (e.g. `"actor"`)
/// from `vs`, checking names, shapes, kinds and finiteness against `spec`.
///
/// Variables that are not part of the deterministic head (a log-std head, critics, ...) are
/// ignored.
pub fn extract_actor(vs: &VarStore, prefix: &str, spec: &ActorSpec) -> Result<ExportedActor, ExportError> {
    spec.validate()?;
    let vars = vs.variables();
    let n_hidden = spec.hidden.len();
    let mut layers = Vec::with_capacity(n_hidden + 1);
    for (i, (in_dim, out_dim)) in spec.layer_dims().into_iter().enumerate() {
        let (name, activation) = if i < n_hidden {
            (ActorSpec::hidden_name(i), Activation::Relu)
        } else {
            (ActorSpec::MEAN_NAME.to_owned(), Activation::Tanh)
        };
        let base = if prefix.is_empty() { name } else { format!("{prefix}.{name}") };
        let weights = read_f32(&vars, &format!("{base}.weight"), &[out_dim, in_dim])?;
        let bias = read_f32(&vars, &format!("{base}.bias"), &[out_dim])?;
        layers.push(ExportedLayer { in_dim, out_dim, weights, bias, activation });
    }
    let actor = ExportedActor { layers };
    // Final consistency check through the runtime's own validation (no capacity limit here).
    for (i, l) in actor.as_runtime_layers().iter().enumerate() {
        l.validate(i)?;
    }
    Ok(actor)
}

/// Reads variable `name`, checking it is an f32 tensor of shape `shape`, and returns its
/// values flattened in row-major order.
fn read_f32(vars: &HashMap<String, Tensor>, name: &str, shape: &[usize]) -> Result<Vec<f32>, ExportError> {
    let t = vars.get(name).ok_or_else(|| ExportError::MissingVariable { name: name.to_owned() })?;
    let expected: Vec<i64> = shape
        .iter()
        .map(|&d| {
            i64::try_from(d)
                .map_err(|_| ExportError::InvalidSpec(format!("dimension {d} does not fit in i64")))
        })
        .collect::<Result<_, _>>()?;
    let got = t.size();
    if got != expected {
        return Err(ExportError::WrongShape { name: name.to_owned(), expected, got });
    }
    let kind = t.f_kind().map_err(tch_error)?;
    if kind != Kind::Float {
        return Err(ExportError::WrongKind { name: name.to_owned(), kind: format!("{kind:?}") });
    }
    let flat = tch::no_grad(|| -> Result<Tensor, tch::TchError> {
        t.f_detach()?.f_to_device(Device::Cpu)?.f_contiguous()?.f_flatten(0, -1)
    })
    .map_err(tch_error)?;
    let values = Vec::<f32>::try_from(&flat).map_err(tch_error)?;
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(ExportError::NonFinite { name: name.to_owned(), index });
    }
    Ok(values)
}
