//! One environment: `vge_sim::Env` behind the calls `vge.HandEnv` makes, on the hand its
//! `[env]` keys name, observed as their `observation` key says.

use std::sync::Arc;

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use vge_hand::Hand;
use vge_sim::{Env, ObservationLayout, ObservationSet, Observer, PrivilegedState};

use crate::hand::HandCore;
use crate::{errors, keys};

/// Per-fingertip normal force (N), 0 where a fingertip does not touch.
pub fn tip_forces_n(state: &PrivilegedState) -> Vec<f32> {
    state.contacts.iter().map(|c| c.as_ref().map_or(0.0, |c| c.normal_force_n)).collect()
}

/// Gymnasium's step tuple: `(obs, reward, terminated, truncated, info)`.
type StepTuple<'py> = (Bound<'py, PyArray1<f32>>, f64, bool, bool, Bound<'py, PyDict>);

/// What a policy observes of an env: its observation set, that set's layout on the env's
/// hand, and the env's full layout (what the critic and the controllers see).
#[derive(Debug, Clone)]
pub struct Observation {
    pub set: ObservationSet,
    pub layout: ObservationLayout,
    pub full_layout: ObservationLayout,
}

impl Observation {
    /// The observation the `[env]` keys name, on the hand of `config`.
    pub fn of(keys: &vge_config_file::EnvKeys, config: &vge_sim::EnvConfig, origin: &str) -> PyResult<Self> {
        let set = keys.0.observation_set().map_err(|e| errors::value(format!("{origin}: {e}")))?;
        let hand = &config.hand;
        Ok(Self {
            set,
            layout: ObservationLayout::new(set, hand.num_joints(), hand.num_fingers()),
            full_layout: config.observation_layout(),
        })
    }

    pub fn is_full(&self) -> bool {
        self.set == ObservationSet::Full
    }
}

/// A layout as Python's `[(name, start, end), ...]`.
pub fn layout_list(layout: &ObservationLayout) -> Vec<(&'static str, usize, usize)> {
    layout.slices().iter().map(|(n, r)| (*n, r.start, r.end)).collect()
}

/// The `[env]` keys given, the env built from them, and the current episode.
#[pyclass(module = "vge._vge")]
#[derive(Debug)]
pub struct EnvCore {
    pub env: Env,
    pub observation: Observation,
    /// Makes the policy's observation from the env's full one.
    observer: Observer,
    /// Seed of the episode the last reset began (`None` before the first).
    pub episode_seed: Option<u64>,
    /// Resets so far: a controller compares it with the episode it last acted in.
    pub episodes: u64,
    training_only_keys: Vec<&'static str>,
}

impl EnvCore {
    /// The noise-free state, or the error a step before reset gets.
    pub fn state(&self) -> PyResult<&PrivilegedState> {
        self.env.privileged().ok_or_else(|| errors::sim(vge_sim::SimError::NotReset))
    }

    pub fn hand(&self) -> &Arc<Hand> {
        &self.env.config().hand
    }
}

#[pymethods]
impl EnvCore {
    /// Env `index` (its object `objects[index % len]`) of the `[env]` keys in `keys`, over
    /// those of the config file `config_path` when given.
    #[new]
    #[pyo3(signature = (keys=None, index=0, config_path=None))]
    fn new(keys: Option<&Bound<'_, PyDict>>, index: usize, config_path: Option<&str>) -> PyResult<Self> {
        let (keys, origin) = keys::read(config_path, keys)?;
        let config = keys.env_config(index, &origin).map_err(errors::keys)?;
        let observation = Observation::of(&keys, &config, &origin)?;
        let observer = Observer::new(observation.set, config.hand.num_joints());
        let env = Env::new(config).map_err(errors::sim)?;
        Ok(Self {
            env,
            observation,
            observer,
            episode_seed: None,
            episodes: 0,
            training_only_keys: keys.training_only_keys(),
        })
    }

    /// Rebuilds the world from `seed`: `(obs, info)`.
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seed: u64,
    ) -> PyResult<(Bound<'py, PyArray1<f32>>, Bound<'py, PyDict>)> {
        let env = &mut self.env;
        let (full, reset_info) = py.detach(|| env.reset(seed)).map_err(errors::sim)?;
        let obs = self.observer.start(&full);
        self.episode_seed = Some(seed);
        self.episodes += 1;
        let info = PyDict::new(py);
        info.set_item("grasping_fingers", PyArray1::from_slice(py, &reset_info.grasping_fingers))?;
        info.set_item("episode_seed", seed)?;
        state_info(py, &info, self)?;
        info.set_item("object_height_m", reset_info.object_height_m)?;
        if !self.observation.is_full() {
            info.set_item("full_obs", PyArray1::from_vec(py, full))?;
        }
        Ok((PyArray1::from_vec(py, obs), info))
    }

    /// One control step with a float32 action of one entry per joint: `(obs, reward,
    /// terminated, truncated, info)`.
    fn step<'py>(&mut self, py: Python<'py>, action: PyReadonlyArray1<'py, f32>) -> PyResult<StepTuple<'py>> {
        let action = action.as_slice().map_err(|e| errors::value(format!("action: {e}")))?;
        let env = &mut self.env;
        let r = py.detach(|| env.step(action)).map_err(errors::sim)?;
        let obs = self.observer.step(&r.obs);
        let info = PyDict::new(py);
        info.set_item("object_rotation_z_rad", r.info.object_rotation_z_rad)?;
        info.set_item("object_rotation_rad", r.info.object_rotation_rad)?;
        info.set_item("object_angvel_z_rad_per_s", r.info.object_angvel_z_rad_per_s)?;
        info.set_item("object_height_m", r.info.object_height_m)?;
        info.set_item("object_tilt_rad", r.info.object_tilt_rad)?;
        info.set_item("dropped", r.info.dropped)?;
        info.set_item("tipped_over", r.info.tipped_over)?;
        info.set_item("step", r.info.step)?;
        state_info(py, &info, self)?;
        if !self.observation.is_full() {
            info.set_item("full_obs", PyArray1::from_vec(py, r.obs))?;
        }
        Ok((PyArray1::from_vec(py, obs), f64::from(r.reward), r.terminated, r.truncated, info))
    }

    /// The noise-free state: object pose and velocity, joint angles and targets, contacts.
    fn privileged<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.state()?;
        let d = PyDict::new(py);
        let p = s.object.pose.translation.vector;
        let q = s.object.pose.rotation.coords;
        d.set_item("object_position_m", PyArray1::from_slice(py, &[p.x, p.y, p.z]))?;
        d.set_item("object_quaternion_xyzw", PyArray1::from_slice(py, &[q.x, q.y, q.z, q.w]))?;
        let v = s.object.linvel_m_per_s;
        d.set_item("object_linvel_m_per_s", PyArray1::from_slice(py, &[v.x, v.y, v.z]))?;
        let w = s.object.angvel_rad_per_s;
        d.set_item("object_angvel_rad_per_s", PyArray1::from_slice(py, &[w.x, w.y, w.z]))?;
        d.set_item("q_rad", PyArray1::from_slice(py, &s.q_rad))?;
        d.set_item("q_target_rad", PyArray1::from_slice(py, &s.q_target_rad))?;
        state_info(py, &d, self)?;
        Ok(d)
    }

    /// The hand the env simulates.
    #[getter(hand)]
    fn hand_core(&self) -> HandCore {
        HandCore::from_arc(self.hand().clone())
    }

    /// Entries of the observation the env returns (its observation set's, on its hand).
    #[getter]
    fn obs_dim(&self) -> usize {
        self.observation.layout.dim()
    }

    /// Entries of an action: one per joint.
    #[getter]
    fn act_dim(&self) -> usize {
        self.hand().num_joints()
    }

    /// The observation's named slices: `[(name, start, end), ...]`.
    #[getter]
    fn obs_layout(&self) -> Vec<(&'static str, usize, usize)> {
        layout_list(&self.observation.layout)
    }

    /// The full observation's named slices (what `info["full_obs"]` holds when the env
    /// observes less).
    #[getter]
    fn full_obs_layout(&self) -> Vec<(&'static str, usize, usize)> {
        layout_list(&self.observation.full_layout)
    }

    /// The observation set's name: `full`, `proprio` or `proprio:K`.
    #[getter]
    fn observation(&self) -> String {
        self.observation.set.name()
    }

    #[getter]
    fn max_action_rad(&self) -> f32 {
        self.env.config().max_action_rad
    }

    #[getter]
    fn control_hz(&self) -> f32 {
        self.env.config().control_hz
    }

    #[getter]
    fn episode_length(&self) -> usize {
        self.env.config().episode_length_steps
    }

    #[getter]
    fn object(&self) -> &'static str {
        self.env.config().object.shape.name()
    }

    #[getter]
    fn episode_seed(&self) -> Option<u64> {
        self.episode_seed
    }

    /// Training curricula among the keys given (accepted, not applied).
    #[getter]
    fn training_only_keys(&self) -> Vec<&'static str> {
        self.training_only_keys.clone()
    }

    /// The simulator's configuration as Rust prints it (for bug reports and tests).
    fn config_debug(&self) -> String {
        format!("{:?}", self.env.config())
    }
}

/// Contacts and forces of the current state into `info`.
fn state_info(py: Python<'_>, info: &Bound<'_, PyDict>, core: &EnvCore) -> PyResult<()> {
    let s = core.state()?;
    info.set_item("tip_contacts", PyArray1::from_vec(py, s.tip_contacts()))?;
    info.set_item("num_tip_contacts", s.num_tip_contacts())?;
    info.set_item("contact_forces_n", PyArray1::from_vec(py, tip_forces_n(s)))?;
    let f = core.env.external_force_n();
    info.set_item("external_force_n", PyArray1::from_slice(py, &[f.x, f.y, f.z]))?;
    Ok(())
}
