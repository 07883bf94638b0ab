//! The deterministic head of a SAC actor, built from `tch::nn::Linear` layers.

use tch::Tensor;
use tch::nn::{self, Module};

use vge_export::{ActorSpec, ExportError};

/// The deterministic head of a SAC actor: `tanh(mean(relu(... relu(l0(obs)))))`.
///
/// A full SAC actor also has a log-std head; it is not needed for deployment and is not built
/// (nor read) here.
#[derive(Debug)]
pub struct TchActor {
    pub hidden: Vec<nn::Linear>,
    pub mean: nn::Linear,
}

impl Module for TchActor {
    fn forward(&self, obs: &Tensor) -> Tensor {
        let h = self.hidden.iter().fold(obs.shallow_clone(), |x, l| l.forward(&x).relu());
        self.mean.forward(&h).tanh()
    }
}

/// Builds the actor under `path` (e.g. `&(vs.root() / "actor")`), creating the variables
/// `<path>.l0.weight`, `<path>.l0.bias`, ..., `<path>.mean.weight`, `<path>.mean.bias` with
/// tch's default `Linear` initialisation.
pub fn build_actor(path: &nn::Path<'_>, spec: &ActorSpec) -> Result<TchActor, ExportError> {
    spec.validate()?;
    let to_i64 = |d: usize| {
        i64::try_from(d).map_err(|_| ExportError::InvalidSpec(format!("dimension {d} does not fit in i64")))
    };
    let dims = spec.layer_dims();
    let mut hidden = Vec::with_capacity(spec.hidden.len());
    let mut mean = None;
    for (i, &(n_in, n_out)) in dims.iter().enumerate() {
        let name =
            if i < spec.hidden.len() { ActorSpec::hidden_name(i) } else { ActorSpec::MEAN_NAME.into() };
        let lin = nn::linear(path / name, to_i64(n_in)?, to_i64(n_out)?, Default::default());
        if i < spec.hidden.len() {
            hidden.push(lin);
        } else {
            mean = Some(lin);
        }
    }
    let mean = mean.ok_or_else(|| ExportError::InvalidSpec("no mean layer".into()))?;
    Ok(TchActor { hidden, mean })
}
