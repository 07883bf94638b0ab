//! N environments stepped on rayon's threads, writing into numpy arrays allocated once,
//! with Gymnasium 1.x's next-step autoreset: an env whose episode ended on step t is reset
//! on step t+1 (its action ignored; reward 0, not terminated, not truncated) instead of being
//! stepped.
//!
//! Not `vge_sim::VecEnv`: that steps every env every call and returns fresh vectors; here a
//! call may reset some envs and step the others, and the results land in place. Every env
//! has the one hand the `[env]` keys name, so the arrays' widths are that hand's.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use vge_sim::{Env, Observer, SimError};

use crate::env::{Observation, layout_list, tip_forces_n};
use crate::{errors, keys};

/// One env's row of every output array.
struct Row<'a> {
    obs: &'a mut [f32],
    /// The full observation, when the envs observe less (else empty).
    full_obs: &'a mut [f32],
    reward: &'a mut f64,
    terminated: &'a mut bool,
    truncated: &'a mut bool,
    autoreset: &'a mut bool,
    tip_contacts: &'a mut [bool],
    contact_forces_n: &'a mut [f32],
    external_force_n: &'a mut [f32],
    rotation_z_rad: &'a mut f32,
    height_m: &'a mut f32,
    tilt_rad: &'a mut f32,
    dropped: &'a mut bool,
    tipped_over: &'a mut bool,
    step: &'a mut i64,
}

/// What one env does on a call.
#[derive(Debug, Clone, Copy)]
enum Op<'a> {
    Reset(u64),
    Step(&'a [f32]),
}

/// One env and what makes its policy's observation.
#[derive(Debug)]
struct Slot {
    env: Env,
    observer: Observer,
}

fn run(slot: &mut Slot, op: Op<'_>, row: Row<'_>) -> Result<bool, SimError> {
    let env = &mut slot.env;
    let (full, rotation, tilt_rad, dropped, tipped_over, step, ended) = match op {
        Op::Reset(seed) => {
            let (full, _) = env.reset(seed)?;
            row.obs.copy_from_slice(&slot.observer.start(&full));
            *row.reward = 0.0;
            (*row.terminated, *row.truncated, *row.autoreset) = (false, false, true);
            (full, 0.0, 0.0, false, false, 0, false)
        }
        Op::Step(action) => {
            let r = env.step(action)?;
            row.obs.copy_from_slice(&slot.observer.step(&r.obs));
            *row.reward = f64::from(r.reward);
            (*row.terminated, *row.truncated, *row.autoreset) = (r.terminated, r.truncated, false);
            let ended = r.terminated || r.truncated;
            let i = &r.info;
            (
                r.obs,
                i.object_rotation_z_rad,
                i.object_tilt_rad,
                i.dropped,
                i.tipped_over,
                i.step as i64,
                ended,
            )
        }
    };
    if !row.full_obs.is_empty() {
        row.full_obs.copy_from_slice(&full);
    }
    let state = env.privileged().ok_or(SimError::NotReset)?;
    for (t, c) in row.tip_contacts.iter_mut().zip(&state.contacts) {
        *t = c.is_some();
    }
    row.contact_forces_n.copy_from_slice(&tip_forces_n(state));
    let f = env.external_force_n();
    row.external_force_n.copy_from_slice(&[f.x, f.y, f.z]);
    *row.rotation_z_rad = rotation;
    *row.height_m = state.object.pose.translation.vector.dot(&env.config().physics.hand_orientation.up());
    *row.tilt_rad = tilt_rad;
    *row.dropped = dropped;
    *row.tipped_over = tipped_over;
    *row.step = step;
    Ok(ended)
}

/// The output arrays, allocated once (shapes: `n`, `n x obs_dim`, `n x fingers`, `n x 3`;
/// `full_obs` is `n x full obs_dim` when the envs observe less than the full observation,
/// else `n x 0`).
#[derive(Debug)]
struct Buffers {
    obs: Py<PyArray2<f32>>,
    full_obs: Py<PyArray2<f32>>,
    rewards: Py<PyArray1<f64>>,
    terminations: Py<PyArray1<bool>>,
    truncations: Py<PyArray1<bool>>,
    autoreset: Py<PyArray1<bool>>,
    tip_contacts: Py<PyArray2<bool>>,
    contact_forces_n: Py<PyArray2<f32>>,
    external_force_n: Py<PyArray2<f32>>,
    rotation_z_rad: Py<PyArray1<f32>>,
    height_m: Py<PyArray1<f32>>,
    tilt_rad: Py<PyArray1<f32>>,
    dropped: Py<PyArray1<bool>>,
    tipped_over: Py<PyArray1<bool>>,
    step: Py<PyArray1<i64>>,
}

/// The widths of a row: observation, full observation (0 when it is the observation),
/// fingertips.
#[derive(Debug, Clone, Copy)]
struct Widths {
    obs: usize,
    full_obs: usize,
    fingers: usize,
}

impl Widths {
    fn of(observation: &Observation, fingers: usize) -> Self {
        let full_obs = if observation.is_full() { 0 } else { observation.full_layout.dim() };
        Self { obs: observation.layout.dim(), full_obs, fingers }
    }

    /// One env's row of the output arrays (bytes).
    fn row_bytes(self) -> u64 {
        (4 * self.obs + 4 * self.full_obs + 8 + 3 + self.fingers + 4 * self.fingers + 4 * 3 + 4 + 4 + 1 + 8)
            as u64
    }
}

/// Refuses `num_envs` envs that no machine holds, or this one does not, before any is made,
/// with the memory they would take: as `vge train` refuses its `num_envs`, by the bounds of
/// `vge_config_file::memory`, instead of allocating until the process is killed.
fn check_fits_memory(num_envs: usize, widths: Widths) -> PyResult<()> {
    use vge_config_file::memory::{SIM_ENV_BYTES, bytes_text, refusal};
    let per_env = SIM_ENV_BYTES + widths.row_bytes();
    let total = (num_envs as u64).saturating_mul(per_env);
    let parts = format!(" ({} per env)", bytes_text(per_env));
    match refusal(&format!("VecHandEnv({num_envs})"), total, &parts) {
        Some(why) => Err(errors::value(format!("num_envs: {why}"))),
        None => Ok(()),
    }
}

/// The batch behind `vge.VecHandEnv`.
#[pyclass(module = "vge._vge")]
#[derive(Debug)]
pub struct VecEnvCore {
    slots: Vec<Slot>,
    observation: Observation,
    widths: Widths,
    /// Envs whose episode ended on the last call: the next call resets them.
    pending_reset: Vec<bool>,
    buffers: Buffers,
    training_only_keys: Vec<&'static str>,
}

fn borrow_error(e: impl std::fmt::Display) -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err(format!(
        "the vector env's output arrays are borrowed elsewhere: {e}"
    ))
}

impl VecEnvCore {
    /// Runs `ops[i]` on env `i`, side by side, writing each env's row of the outputs; the
    /// GIL is released meanwhile.
    fn run_all(&mut self, py: Python<'_>, ops: &[Op<'_>]) -> PyResult<()> {
        let b = &self.buffers;
        let w = self.widths;
        macro_rules! rw {
            ($a:expr) => {
                $a.bind(py).try_readwrite().map_err(borrow_error)?
            };
        }
        let (mut obs, mut full_obs, mut rew, mut term, mut trunc, mut auto) = (
            rw!(b.obs),
            rw!(b.full_obs),
            rw!(b.rewards),
            rw!(b.terminations),
            rw!(b.truncations),
            rw!(b.autoreset),
        );
        let (mut tips, mut forces, mut ext) =
            (rw!(b.tip_contacts), rw!(b.contact_forces_n), rw!(b.external_force_n));
        let (mut rot, mut height, mut tilt, mut dropped, mut tipped, mut step) = (
            rw!(b.rotation_z_rad),
            rw!(b.height_m),
            rw!(b.tilt_rad),
            rw!(b.dropped),
            rw!(b.tipped_over),
            rw!(b.step),
        );
        macro_rules! slice {
            ($a:expr) => {
                $a.as_slice_mut().map_err(borrow_error)?
            };
        }
        let n = self.slots.len();
        let full_obs = slice!(full_obs);
        // An empty array has no rows to cut: every env gets an empty one.
        let mut full_obs: Box<dyn Iterator<Item = &mut [f32]>> = if w.full_obs == 0 {
            Box::new(std::iter::repeat_with(<&mut [f32]>::default))
        } else {
            Box::new(full_obs.chunks_exact_mut(w.full_obs))
        };
        let (mut obs, mut rew, mut term, mut trunc, mut auto) = (
            slice!(obs).chunks_exact_mut(w.obs.max(1)),
            slice!(rew).iter_mut(),
            slice!(term).iter_mut(),
            slice!(trunc).iter_mut(),
            slice!(auto).iter_mut(),
        );
        let (mut tips, mut forces, mut ext) = (
            slice!(tips).chunks_exact_mut(w.fingers.max(1)),
            slice!(forces).chunks_exact_mut(w.fingers.max(1)),
            slice!(ext).chunks_exact_mut(3),
        );
        let (mut rot, mut height, mut tilt, mut dropped, mut tipped, mut step) = (
            slice!(rot).iter_mut(),
            slice!(height).iter_mut(),
            slice!(tilt).iter_mut(),
            slice!(dropped).iter_mut(),
            slice!(tipped).iter_mut(),
            slice!(step).iter_mut(),
        );
        let rows = (0..n)
            .map(|_| {
                Some(Row {
                    obs: obs.next()?,
                    full_obs: full_obs.next()?,
                    reward: rew.next()?,
                    terminated: term.next()?,
                    truncated: trunc.next()?,
                    autoreset: auto.next()?,
                    tip_contacts: tips.next()?,
                    contact_forces_n: forces.next()?,
                    external_force_n: ext.next()?,
                    rotation_z_rad: rot.next()?,
                    height_m: height.next()?,
                    tilt_rad: tilt.next()?,
                    dropped: dropped.next()?,
                    tipped_over: tipped.next()?,
                    step: step.next()?,
                })
            })
            .collect::<Option<Vec<Row<'_>>>>()
            .ok_or_else(|| borrow_error("an output array is shorter than the batch"))?;
        let slots = &mut self.slots;
        let ended: Vec<bool> = py
            .detach(|| {
                slots
                    .par_iter_mut()
                    .zip(ops.par_iter())
                    .zip(rows.into_par_iter())
                    .map(|((slot, op), row)| run(slot, *op, row))
                    .collect::<Result<Vec<bool>, SimError>>()
            })
            .map_err(errors::sim)?;
        self.pending_reset = ended;
        Ok(())
    }

    fn seeds(&self, seeds: &PyReadonlyArray1<'_, u64>) -> PyResult<Vec<u64>> {
        let n = self.slots.len();
        let s = seeds.as_slice().map_err(|e| errors::value(format!("seeds: {e}")))?;
        if s.len() != n {
            return Err(errors::sim(SimError::BatchLength { got: s.len(), expected: n }));
        }
        Ok(s.to_vec())
    }

    /// The hand every env simulates and the layout of what they observe (what a policy
    /// that drives them must take).
    pub fn interface(&self) -> PyResult<(std::sync::Arc<vge_hand::Hand>, vge_sim::ObservationLayout)> {
        Ok((self.first()?.config().hand.clone(), self.observation.layout.clone()))
    }

    fn first(&self) -> PyResult<&Env> {
        self.slots.first().map(|s| &s.env).ok_or_else(|| errors::value("the vector env has no envs"))
    }
}

#[pymethods]
impl VecEnvCore {
    /// `num_envs` envs of the `[env]` keys in `keys` (over those of `config_path`), env `i`
    /// with object `objects[i % len]` as in training.
    #[new]
    #[pyo3(signature = (num_envs, keys=None, config_path=None))]
    fn new(
        py: Python<'_>,
        num_envs: usize,
        keys: Option<&Bound<'_, PyDict>>,
        config_path: Option<&str>,
    ) -> PyResult<Self> {
        if num_envs == 0 {
            return Err(errors::value("num_envs must be at least 1"));
        }
        let (keys, origin) = keys::read(config_path, keys)?;
        let first = keys.env_config(0, &origin).map_err(errors::keys)?;
        let observation = Observation::of(&keys, &first, &origin)?;
        let widths = Widths::of(&observation, first.hand.num_fingers());
        check_fits_memory(num_envs, widths)?;
        let joints = first.hand.num_joints();
        let slots = (0..num_envs)
            .map(|i| {
                keys.env_config(i, &origin)
                    .map_err(errors::keys)
                    .and_then(|c| Env::new(c).map_err(errors::sim))
                    .map(|env| Slot { env, observer: Observer::new(observation.set, joints) })
            })
            .collect::<PyResult<Vec<_>>>()?;
        let n = num_envs;
        let buffers = Buffers {
            obs: PyArray2::zeros(py, [n, widths.obs], false).unbind(),
            full_obs: PyArray2::zeros(py, [n, widths.full_obs], false).unbind(),
            rewards: PyArray1::zeros(py, n, false).unbind(),
            terminations: PyArray1::zeros(py, n, false).unbind(),
            truncations: PyArray1::zeros(py, n, false).unbind(),
            autoreset: PyArray1::zeros(py, n, false).unbind(),
            tip_contacts: PyArray2::zeros(py, [n, widths.fingers], false).unbind(),
            contact_forces_n: PyArray2::zeros(py, [n, widths.fingers], false).unbind(),
            external_force_n: PyArray2::zeros(py, [n, 3], false).unbind(),
            rotation_z_rad: PyArray1::zeros(py, n, false).unbind(),
            height_m: PyArray1::zeros(py, n, false).unbind(),
            tilt_rad: PyArray1::zeros(py, n, false).unbind(),
            dropped: PyArray1::zeros(py, n, false).unbind(),
            tipped_over: PyArray1::zeros(py, n, false).unbind(),
            step: PyArray1::zeros(py, n, false).unbind(),
        };
        Ok(Self {
            slots,
            observation,
            widths,
            pending_reset: vec![false; n],
            buffers,
            training_only_keys: keys.training_only_keys(),
        })
    }

    /// Resets env `i` with `seeds[i]`, every env side by side.
    fn reset(&mut self, py: Python<'_>, seeds: PyReadonlyArray1<'_, u64>) -> PyResult<()> {
        let ops: Vec<Op<'_>> = self.seeds(&seeds)?.into_iter().map(Op::Reset).collect();
        self.run_all(py, &ops)
    }

    /// Steps every env with its row of `actions` (float32, `n x joints`), except those whose
    /// episode ended on the last call, which are reset with their entry of `seeds`. Every
    /// action is checked before any env moves.
    fn step(
        &mut self,
        py: Python<'_>,
        actions: PyReadonlyArray2<'_, f32>,
        seeds: PyReadonlyArray1<'_, u64>,
    ) -> PyResult<()> {
        let n = self.slots.len();
        let joints = self.first()?.config().hand.num_joints();
        let shape = actions.shape().to_vec();
        if shape != [n, joints] {
            return Err(errors::value(format!("actions have shape {shape:?}, expected [{n}, {joints}]")));
        }
        let seeds = self.seeds(&seeds)?;
        let a = actions.as_slice().map_err(|e| errors::value(format!("actions: {e}")))?;
        let mut ops = Vec::with_capacity(n);
        for (i, (row, slot)) in a.chunks_exact(joints.max(1)).zip(&self.slots).enumerate() {
            ops.push(if self.pending_reset[i] {
                Op::Reset(seeds[i])
            } else {
                slot.env.check_action(row).map_err(|e| errors::value(format!("actions row {i}: {e}")))?;
                Op::Step(row)
            });
        }
        self.run_all(py, &ops)
    }

    /// Envs whose episode ended on the last call (the next step resets them).
    fn pending_resets(&self) -> Vec<bool> {
        self.pending_reset.clone()
    }

    /// The output arrays (the same objects on every call; each call overwrites them).
    /// `full_obs` is there when the envs observe less than the full observation.
    fn buffers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let b = &self.buffers;
        let d = PyDict::new(py);
        d.set_item("obs", b.obs.bind(py))?;
        if !self.observation.is_full() {
            d.set_item("full_obs", b.full_obs.bind(py))?;
        }
        d.set_item("rewards", b.rewards.bind(py))?;
        d.set_item("terminations", b.terminations.bind(py))?;
        d.set_item("truncations", b.truncations.bind(py))?;
        d.set_item("autoreset", b.autoreset.bind(py))?;
        d.set_item("tip_contacts", b.tip_contacts.bind(py))?;
        d.set_item("contact_forces_n", b.contact_forces_n.bind(py))?;
        d.set_item("external_force_n", b.external_force_n.bind(py))?;
        d.set_item("object_rotation_z_rad", b.rotation_z_rad.bind(py))?;
        d.set_item("object_height_m", b.height_m.bind(py))?;
        d.set_item("object_tilt_rad", b.tilt_rad.bind(py))?;
        d.set_item("dropped", b.dropped.bind(py))?;
        d.set_item("tipped_over", b.tipped_over.bind(py))?;
        d.set_item("step", b.step.bind(py))?;
        Ok(d)
    }

    #[getter]
    fn num_envs(&self) -> usize {
        self.slots.len()
    }

    /// The hand every env simulates.
    #[getter]
    fn hand(&self) -> PyResult<crate::hand::HandCore> {
        Ok(crate::hand::HandCore::from_arc(self.first()?.config().hand.clone()))
    }

    /// Entries of each env's observation.
    #[getter]
    fn obs_dim(&self) -> usize {
        self.widths.obs
    }

    /// Entries of each env's action: one per joint.
    #[getter]
    fn act_dim(&self) -> PyResult<usize> {
        Ok(self.first()?.config().hand.num_joints())
    }

    #[getter]
    fn obs_layout(&self) -> Vec<(&'static str, usize, usize)> {
        layout_list(&self.observation.layout)
    }

    #[getter]
    fn full_obs_layout(&self) -> Vec<(&'static str, usize, usize)> {
        layout_list(&self.observation.full_layout)
    }

    #[getter]
    fn observation(&self) -> String {
        self.observation.set.name()
    }

    /// Largest action entry of each env (rad).
    #[getter]
    fn max_action_rad(&self) -> Vec<f32> {
        self.slots.iter().map(|s| s.env.config().max_action_rad).collect()
    }

    #[getter]
    fn control_hz(&self) -> Vec<f32> {
        self.slots.iter().map(|s| s.env.config().control_hz).collect()
    }

    #[getter]
    fn objects(&self) -> Vec<&'static str> {
        self.slots.iter().map(|s| s.env.config().object.shape.name()).collect()
    }

    #[getter]
    fn training_only_keys(&self) -> Vec<&'static str> {
        self.training_only_keys.clone()
    }
}
