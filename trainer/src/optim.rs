//! The optimiser: Adam over a network's parameters kept in one flat buffer, with state that
//! checkpoints can save (tch's `nn::Optimizer` hides its state inside libtorch).

use tch::{Device, Kind, Tensor};

/// Moves the data of `params` into one contiguous buffer and returns it. Each parameter
/// stays the same leaf tensor (the var store's, saved and exported by name), but its data
/// now aliases a slice of the buffer, so that one tensor op on the buffer updates them all:
/// Adam's step and the Polyak averages become seven ops and one op per network instead of
/// seven and one per weight and bias.
pub fn flatten_storage(params: &[Tensor]) -> Tensor {
    let total: i64 = params.iter().map(|p| p.numel() as i64).sum();
    let device = params.first().map_or(Device::Cpu, Tensor::device);
    let flat = Tensor::zeros([total], (Kind::Float, device));
    let mut offset = 0;
    tch::no_grad(|| {
        for p in params {
            let n = p.numel() as i64;
            let mut view = flat.narrow(0, offset, n).view(p.size().as_slice());
            view.copy_(p);
            p.shallow_clone().set_data(&view);
            offset += n;
        }
    });
    flat
}

/// Adam (Kingma & Ba; PyTorch's defaults β = (0.9, 0.999), ε = 1e-8) over parameters whose
/// data it keeps in one flat buffer ([`flatten_storage`]), with its moments as plain
/// tensors, so that checkpoints can save and restore them (tch's `nn::Optimizer` keeps its
/// state inside libtorch with no way to read it).
#[derive(Debug)]
pub struct Adam {
    params: Vec<Tensor>,
    flat: Tensor,
    m: Tensor,
    v: Tensor,
    step: i64,
    lr: f64,
}

impl Adam {
    const BETA1: f64 = 0.9;
    const BETA2: f64 = 0.999;
    const EPS: f64 = 1e-8;

    /// Takes over `params` (moving their data into one buffer, see [`flatten_storage`]).
    pub fn new(params: Vec<Tensor>, lr: f64) -> Self {
        let flat = flatten_storage(&params);
        let m = flat.zeros_like();
        let v = flat.zeros_like();
        Self { params, flat, m, v, step: 0, lr }
    }

    /// The parameters' data, one flat tensor (in the order given to [`Self::new`]).
    pub fn flat(&self) -> &Tensor {
        &self.flat
    }

    /// Gradients of `loss` with respect to the parameters only (no `.grad` accumulation,
    /// so no zeroing), then one Adam step.
    pub fn backward_step(&mut self, loss: &Tensor) {
        let grads = Tensor::run_backward(&[loss], &self.params, false, false);
        self.step += 1;
        if self.lr == 0.0 {
            return;
        }
        // Past i32::MAX steps both corrections are 1 to f64 precision, so saturating is exact.
        let t = i32::try_from(self.step).unwrap_or(i32::MAX);
        let bc1 = 1.0 - Self::BETA1.powi(t);
        let bc2 = 1.0 - Self::BETA2.powi(t);
        // p ← p − (lr / bc1) · m / (√(v / bc2) + ε), written as p ← p + m / d with
        // d = √v · k + ε / c, c = −lr / bc1, k = 1 / (c √bc2): seven ops, two temporaries.
        let c = -self.lr / bc1;
        let k = 1.0 / (c * bc2.sqrt());
        let eps_over_c = Self::EPS / c;
        tch::no_grad(|| {
            // A parameter the loss does not reach (TD3 never uses the log σ head) has an
            // undefined gradient: it counts as zero, and with zero moments its step is 0.
            let g: Vec<Tensor> = grads
                .iter()
                .zip(&self.params)
                .map(|(g, p)| if g.defined() { g.reshape([-1]) } else { p.zeros_like().reshape([-1]) })
                .collect();
            let g = Tensor::cat(&g, 0);
            let _ = self.m.lerp_(&g, 1.0 - Self::BETA1);
            let _ = self.v.lerp_(&g.square(), 1.0 - Self::BETA2);
            let mut d = self.v.sqrt();
            let _ = d.g_mul_scalar_(k);
            let _ = d.g_add_scalar_(eps_over_c);
            let _ = self.flat.addcdiv_(&self.m, &d);
        });
    }

    pub(crate) fn state(&self, prefix: &str) -> Vec<(String, Tensor)> {
        vec![
            (format!("{prefix}.step"), Tensor::from_slice(&[self.step])),
            (format!("{prefix}.m"), self.m.shallow_clone()),
            (format!("{prefix}.v"), self.v.shallow_clone()),
        ]
    }

    pub(crate) fn restore(
        &mut self,
        prefix: &str,
        named: &std::collections::HashMap<String, Tensor>,
    ) -> Result<(), tch::TchError> {
        use crate::saved_state::{restore_into, saved_i64};
        let key = format!("{prefix}.step");
        let step = saved_i64(named, &key)?;
        if step < 0 {
            // Adam's bias corrections divide by 1 - beta^t: t = 0 would give NaN parameters.
            return Err(tch::TchError::FileFormat(format!("the checkpoint's {key} is {step}, below 0")));
        }
        self.step = step;
        restore_into(&mut self.m, named, &format!("{prefix}.m"))?;
        restore_into(&mut self.v, named, &format!("{prefix}.v"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_checkpoint_with_a_negative_step_is_refused_and_a_good_one_restores() {
        let param = Tensor::zeros([3], (Kind::Float, Device::Cpu)).set_requires_grad(true);
        let mut adam = Adam::new(vec![param.shallow_clone()], 1e-3);
        adam.backward_step(&(&param * 2.0).sum(Kind::Float));
        let mut named: std::collections::HashMap<String, Tensor> =
            adam.state("actor_opt").into_iter().collect();
        let mut restored = Adam::new(vec![param.shallow_clone()], 1e-3);
        restored.restore("actor_opt", &named).expect("its own state");
        assert_eq!(restored.step, 1);
        // Step -1 would make the first bias correction 1 - beta^0 = 0: NaN parameters.
        named.insert("actor_opt.step".to_owned(), Tensor::from_slice(&[-1i64]));
        let err = restored.restore("actor_opt", &named).expect_err("a negative step").to_string();
        assert!(err.contains("the checkpoint's actor_opt.step is -1, below 0"), "{err}");
    }
}
