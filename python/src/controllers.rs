//! The sub-skill controllers (IGM, CS, FG) on an env's noise-free state, as `vge controller`
//! and the trainer's behaviour policy query them: the state becomes a `ControllerInput`, the
//! controller's target change is the action.
//!
//! A controller keeps episode state (CS's switching trajectory) and draws from its own
//! generator, so it serves the one env it was built for and refuses any other. When that env
//! has begun a new episode since the controller last acted, the
//! controller is reset first with a generator seeded from the episode's seed, exactly as
//! `vge controller` resets it (`vge_controllers::rollout::run_episode`), so a Python loop
//! reproduces that command's episodes to the bit.

use std::sync::Mutex;

use numpy::PyArray1;
use pyo3::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use vge_controllers::{Controller, ControllerInput, ControllerKind, CsConfig, IgmConfig};

use crate::env::EnvCore;
use crate::errors;

/// `vge_controllers::rollout::run_episode`'s salt on the episode seed.
const CONTROLLER_SEED_SALT: u64 = 0x5eed_c0de_0000_0000;

#[derive(Debug)]
struct State {
    rng: ChaCha8Rng,
    /// The env episode (its reset count) the controller last acted in.
    episode: u64,
    last_error: Option<String>,
}

/// A controller for one env (behind `vge.controllers.IGM / CS / FG`).
#[pyclass(module = "vge._vge")]
pub struct ControllerCore {
    kind: ControllerKind,
    /// The env it was built for: its episode count keys the resets below, which would mean
    /// nothing for another env's count.
    env: Py<EnvCore>,
    controller: Mutex<Box<dyn Controller + Send>>,
    state: Mutex<State>,
}

impl std::fmt::Debug for ControllerCore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControllerCore").field("kind", &self.kind).finish_non_exhaustive()
    }
}

fn poisoned<T>(_: T) -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err("a controller call panicked earlier; build a new controller")
}

#[pymethods]
impl ControllerCore {
    /// `kind` ("igm", "cs" or "fg") for `env`'s hand and control period; CS's trajectory is
    /// `horizon_steps` control steps (default: CS's 50, the configs' `vge.horizon`).
    #[new]
    #[pyo3(signature = (kind, env, horizon_steps=None))]
    fn new(kind: &str, env: PyRef<'_, EnvCore>, horizon_steps: Option<usize>) -> PyResult<Self> {
        let kind: ControllerKind = kind.parse().map_err(errors::value)?;
        let config = env.env.config();
        let mut cs = CsConfig::for_env(config);
        if let Some(h) = horizon_steps {
            if h < 2 {
                return Err(errors::value(format!(
                    "horizon_steps {h}: a switching trajectory needs at least 2 steps"
                )));
            }
            cs.horizon_steps = h;
        }
        let controller = kind.build(config, IgmConfig::default(), cs);
        let state =
            State { rng: ChaCha8Rng::seed_from_u64(CONTROLLER_SEED_SALT), episode: 0, last_error: None };
        Ok(Self { kind, env: env.into(), controller: Mutex::new(controller), state: Mutex::new(state) })
    }

    /// The controller's action (one joint-target change per joint of the env's hand, float32)
    /// for `env`'s current state, or `None` when it has none this step (e.g. too few
    /// contacts; `last_error` says why).
    fn act<'py>(
        &self,
        py: Python<'py>,
        env: PyRef<'py, EnvCore>,
    ) -> PyResult<Option<Bound<'py, PyArray1<f32>>>> {
        if env.as_ptr() != self.env.as_ptr() {
            return Err(errors::value(format!(
                "this {} controller was built for another env; build one for each env",
                self.kind.name()
            )));
        }
        let input = ControllerInput::from_privileged(env.state()?);
        let mut controller = self.controller.lock().map_err(poisoned)?;
        let mut state = self.state.lock().map_err(poisoned)?;
        if state.episode != env.episodes {
            let seed = env.episode_seed.unwrap_or(0);
            state.rng = ChaCha8Rng::seed_from_u64(seed ^ CONTROLLER_SEED_SALT);
            controller.reset(&mut state.rng);
            state.episode = env.episodes;
        }
        let acted = controller.act(&input, &mut state.rng);
        match acted {
            Ok(a) => {
                state.last_error = None;
                Ok(Some(PyArray1::from_slice(py, &a)))
            }
            Err(e) => {
                state.last_error = Some(e.to_string());
                Ok(None)
            }
        }
    }

    /// Why the last `act` had no action (`None` after one that had).
    #[getter]
    fn last_error(&self) -> PyResult<Option<String>> {
        Ok(self.state.lock().map_err(poisoned)?.last_error.clone())
    }

    #[getter]
    fn kind(&self) -> &'static str {
        self.kind.name()
    }
}
