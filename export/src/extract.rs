//! Reading an actor's parameters out of a `VarStore` into owned, validated layers.

use std::collections::HashMap;

use tch::{Device, Kind, Tensor, nn::VarStore};
use vge_runtime::{Activation, Layer};

use crate::{ActorSpec, ExportError};

/// One dense layer with owned parameters, in the runtime's layout.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedLayer {
    pub in_dim: usize,
    pub out_dim: usize,
    /// Row-major `out_dim × in_dim` (same layout as a tch `Linear` weight).
    pub weights: Vec<f32>,
    pub bias: Vec<f32>,
    pub activation: Activation,
}

impl ExportedLayer {
    /// Borrows this layer for the runtime.
    pub fn as_runtime_layer(&self) -> Layer<'_> {
        Layer {
            in_dim: self.in_dim,
            out_dim: self.out_dim,
            weights: vge_runtime::Weights::F32(&self.weights),
            bias: &self.bias,
            activation: self.activation,
        }
    }
}

/// An actor's deterministic head as owned layers: hidden layers with ReLU, mean layer with tanh.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedActor {
    pub layers: Vec<ExportedLayer>,
}

impl ExportedActor {
    /// Borrows every layer for the runtime, e.g. for `vge_runtime::Mlp::new(&actor.as_runtime_layers())`.
    pub fn as_runtime_layers(&self) -> Vec<Layer<'_>> {
        self.layers.iter().map(ExportedLayer::as_runtime_layer).collect()
    }

    /// Builds a runtime MLP borrowing these layers.
    pub fn to_mlp<const MAX_LAYERS: usize, const MAX_WIDTH: usize>(
        &self,
    ) -> Result<vge_runtime::Mlp<'_, MAX_LAYERS, MAX_WIDTH>, ExportError> {
        Ok(vge_runtime::Mlp::new(&self.as_runtime_layers())?)
    }

    pub fn obs_dim(&self) -> usize {
        self.layers.first().map_or(0, |l| l.in_dim)
    }

    pub fn act_dim(&self) -> usize {
        self.layers.last().map_or(0, |l| l.out_dim)
    }
}

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
    let kind = t.f_kind()?;
    if kind != Kind::Float {
        return Err(ExportError::WrongKind { name: name.to_owned(), kind });
    }
    let flat = tch::no_grad(|| -> Result<Tensor, tch::TchError> {
        t.f_detach()?.f_to_device(Device::Cpu)?.f_contiguous()?.f_flatten(0, -1)
    })?;
    let values = Vec::<f32>::try_from(&flat)?;
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(ExportError::NonFinite { name: name.to_owned(), index });
    }
    Ok(values)
}
