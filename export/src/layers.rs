//! An actor's shape and its layers as owned data, in the runtime's layout: what a policy
//! file holds, whichever way it was made (from tch's variables, from ONNX, from a file).

use vge_runtime::{Activation, Layer};

use crate::ExportError;

/// Shape of an actor MLP: `obs_dim -> hidden[0] -> ... -> act_dim`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ActorSpec {
    pub obs_dim: usize,
    pub hidden: Vec<usize>,
    pub act_dim: usize,
}

impl ActorSpec {
    /// Variable-path name of hidden layer `i` relative to the actor prefix (`"l0"`, `"l1"`, ...).
    pub fn hidden_name(i: usize) -> String {
        format!("l{i}")
    }

    /// Variable-path name of the mean layer relative to the actor prefix.
    pub const MEAN_NAME: &'static str = "mean";

    /// `(in_dim, out_dim)` of every linear layer, hidden layers first, mean layer last.
    pub fn layer_dims(&self) -> Vec<(usize, usize)> {
        let mut dims = Vec::with_capacity(self.hidden.len() + 1);
        let mut prev = self.obs_dim;
        for &h in &self.hidden {
            dims.push((prev, h));
            prev = h;
        }
        dims.push((prev, self.act_dim));
        dims
    }

    /// Checks that every dimension is non-zero and fits in `i64`.
    pub fn validate(&self) -> Result<(), ExportError> {
        let all = std::iter::once(self.obs_dim).chain(self.hidden.iter().copied()).chain([self.act_dim]);
        for d in all {
            if d == 0 {
                return Err(ExportError::InvalidSpec(format!("zero dimension in {self:?}")));
            }
            if i64::try_from(d).is_err() {
                return Err(ExportError::InvalidSpec(format!("dimension {d} does not fit in i64")));
            }
        }
        Ok(())
    }
}

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
