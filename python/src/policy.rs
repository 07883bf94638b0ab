//! A policy file on the no_std runtime, loaded as `vge eval` loads it: refused unread when
//! longer than the largest policy the runtime can hold, its bytes copied to a 16-byte
//! aligned buffer so that a version-2 file's arrays are used in place, a `Policy<8, 1024>`.
//!
//! The runtime's policy borrows the file's bytes; the Python object owns both, through a
//! self-referential cell ([`self_cell`]). A version-1 file's arrays must be decoded into
//! separate storage the policy borrows mutably at load, which such a cell cannot lend, so a
//! version-1 file is loaded (and checked) again on every call: it is the legacy format.
//!
//! Given the env it will drive, a policy is checked against that env's hand and observation
//! layout as `vge eval` checks it ([`vge_sim::check_policy_interface`]).

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use vge_hand::Hand;
use vge_runtime::policy::{UNRECORDED_HAND, UNRECORDED_OBSERVATION_SET, inspect, max_file_len};
use vge_runtime::{AlignedBytes, Policy, PolicyError};
use vge_sim::ObservationLayout;

use crate::env::EnvCore;
use crate::errors;
use crate::vec_env::VecEnvCore;

/// `vge eval`'s runtime capacity (`vge_run::eval::EVAL_MAX_LAYERS`, `EVAL_MAX_WIDTH`).
const MAX_LAYERS: usize = 8;
const MAX_WIDTH: usize = 1024;
type EvalPolicy<'a> = Policy<'a, MAX_LAYERS, MAX_WIDTH>;

self_cell::self_cell!(
    struct InPlace {
        owner: AlignedBytes,
        #[covariant]
        dependent: EvalPolicy,
    }
    impl {Debug}
);

#[derive(Debug)]
enum Loaded {
    /// Version 2: the policy borrows the bytes in place.
    InPlace(InPlace),
    /// Version 1: loaded from the bytes on each call into storage of this many `f32`.
    Decoded { bytes: AlignedBytes, storage_len: usize },
}

impl Loaded {
    fn with<T>(&self, f: impl FnOnce(&EvalPolicy<'_>) -> T) -> Result<T, PolicyError> {
        match self {
            Self::InPlace(cell) => Ok(f(cell.borrow_dependent())),
            Self::Decoded { bytes, storage_len } => {
                let mut storage = vec![0.0f32; *storage_len];
                let policy = EvalPolicy::load(bytes, &mut storage)?;
                Ok(f(&policy))
            }
        }
    }
}

/// A loaded policy (behind `vge.Policy`).
#[pyclass(module = "vge._vge")]
#[derive(Debug)]
pub struct PolicyCore {
    path: String,
    loaded: Loaded,
    obs_dim: usize,
    act_dim: usize,
}

fn policy_error(path: &str, e: PolicyError) -> PyErr {
    errors::PolicyError::new_err(format!("{path}: {e}"))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl PolicyCore {
    /// [`vge_sim::check_policy_interface`] of the file against `hand` observed as `layout`.
    fn check(&self, hand: &Hand, layout: &ObservationLayout) -> Result<(), String> {
        self.loaded
            .with(|p| vge_sim::check_policy_interface(p.info(), hand, layout))
            .map_err(|e| e.to_string())?
    }
}

#[pymethods]
impl PolicyCore {
    /// Reads and checks the policy file at `path` (every check of the runtime: framing,
    /// checksum, fields, dimensions, finite parameters).
    #[staticmethod]
    fn load(path: &str) -> PyResult<Self> {
        let max = max_file_len(MAX_LAYERS, MAX_WIDTH);
        let io = |e: std::io::Error| match e.kind() {
            std::io::ErrorKind::NotFound => {
                pyo3::exceptions::PyFileNotFoundError::new_err(format!("reading policy file {path}: {e}"))
            }
            _ => pyo3::exceptions::PyOSError::new_err(format!("reading policy file {path}: {e}")),
        };
        let len = std::fs::metadata(path).map_err(io)?.len();
        if len > max as u64 {
            return Err(errors::PolicyError::new_err(format!(
                "{path}: {len} bytes, longer than the largest policy the runtime holds ({max} bytes)"
            )));
        }
        let bytes = AlignedBytes::new(&std::fs::read(path).map_err(io)?);
        let info = inspect(&bytes).map_err(|e| policy_error(path, e))?;
        let (obs_dim, act_dim, storage_len) = (info.obs_dim, info.act_dim, info.storage_len);
        let loaded = if storage_len == 0 {
            Loaded::InPlace(
                InPlace::try_new(bytes, |b| EvalPolicy::load(b, &mut []))
                    .map_err(|e| policy_error(path, e))?,
            )
        } else {
            let loaded = Loaded::Decoded { bytes, storage_len };
            loaded.with(|_| ()).map_err(|e| policy_error(path, e))?;
            loaded
        };
        Ok(Self { path: path.to_owned(), loaded, obs_dim, act_dim })
    }

    /// Checks that the policy drives `env` (a `HandEnv`'s or a `VecHandEnv`'s core) as it
    /// is observed: the hand it was trained for (name and description), its observation
    /// layout, its action names ([`vge_sim::check_policy_interface`]); a `vge.PolicyError`
    /// names what differs.
    fn check_env(&self, env: &Bound<'_, PyAny>) -> PyResult<()> {
        let checked = if let Ok(env) = env.cast::<EnvCore>() {
            let env = env.try_borrow()?;
            self.check(env.hand(), &env.observation.layout)
        } else if let Ok(env) = env.cast::<VecEnvCore>() {
            let env = env.try_borrow()?;
            let (hand, layout) = env.interface()?;
            self.check(&hand, &layout)
        } else {
            let type_name = env.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".to_owned());
            return Err(pyo3::exceptions::PyTypeError::new_err(format!(
                "expected a vge env core (EnvCore or VecEnvCore), got {type_name}"
            )));
        };
        checked.map_err(|e| errors::PolicyError::new_err(format!("{}: {e}", self.path)))
    }

    /// The action (float32, `act_dim`) for one float32 observation (`obs_dim`).
    fn act_one<'py>(
        &self,
        py: Python<'py>,
        obs: PyReadonlyArray1<'py, f32>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let obs = obs.as_slice().map_err(|e| errors::value(format!("observation: {e}")))?;
        let mut action = vec![0.0f32; self.act_dim];
        self.loaded
            .with(|p| p.forward(obs, &mut action))
            .and_then(|r| r)
            .map_err(|e| errors::value(format!("{}: {e}", self.path)))?;
        Ok(PyArray1::from_vec(py, action))
    }

    /// The actions (float32, `n x act_dim`) for a batch of float32 observations
    /// (`n x obs_dim`); the GIL is released meanwhile.
    fn act_batch<'py>(
        &self,
        py: Python<'py>,
        obs: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let n = obs.shape()[0];
        let width = obs.shape()[1];
        if width != self.obs_dim {
            return Err(errors::value(format!(
                "observations have {width} columns, the policy {} takes {}",
                self.path, self.obs_dim
            )));
        }
        let obs = obs.as_slice().map_err(|e| errors::value(format!("observations: {e}")))?;
        let act_dim = self.act_dim;
        let mut actions = vec![0.0f32; n * act_dim];
        let loaded = &self.loaded;
        py.detach(|| {
            loaded.with(|p| {
                obs.chunks_exact(width.max(1))
                    .zip(actions.chunks_exact_mut(act_dim.max(1)))
                    .enumerate()
                    .try_for_each(|(i, (o, a))| p.forward(o, a).map_err(|e| (i, e)))
            })
        })
        .map_err(|e| errors::value(format!("{}: {e}", self.path)))?
        .map_err(|(i, e)| errors::value(format!("{}: observation row {i}: {e}", self.path)))?;
        PyArray1::from_vec(py, actions).reshape([n, act_dim])
    }

    /// Everything the file says about the policy besides its parameters.
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        self.loaded
            .with(|p| -> PyResult<()> {
                let info = p.info();
                d.set_item("format_version", info.format_version)?;
                d.set_item("checksum", info.checksum)?;
                let prov = PyDict::new(py);
                prov.set_item("vge_version", info.provenance.vge_version)?;
                prov.set_item("config_hash", info.provenance.config_hash)?;
                prov.set_item("seed", info.provenance.seed)?;
                prov.set_item("steps", info.provenance.steps)?;
                d.set_item("provenance", prov)?;
                d.set_item("control_hz", info.control_hz)?;
                d.set_item("obs_dim", info.obs_dim)?;
                d.set_item("act_dim", info.act_dim)?;
                let layout: Vec<(&str, usize, usize)> =
                    info.obs_layout.iter().map(|s| (s.name, s.start, s.end)).collect();
                d.set_item("obs_layout", layout)?;
                d.set_item("obs_clip", info.obs_clip)?;
                let names: Vec<&str> = info.action_names.iter().collect();
                d.set_item("action_names", names)?;
                d.set_item("num_layers", info.num_layers)?;
                d.set_item("max_width", info.max_width)?;
                d.set_item("num_params", info.num_params)?;
                d.set_item("weight_type", format!("{:?}", info.weight_type).to_lowercase())?;
                match &info.task {
                    None => d.set_item("task", py.None())?,
                    Some(task) => {
                        let t = PyDict::new(py);
                        t.set_item("hand", task.hand)?;
                        t.set_item("hand_sha256", hex(task.hand_sha256))?;
                        t.set_item("observation_set", task.observation_set)?;
                        t.set_item("object", task.object)?;
                        t.set_item("orientation", task.orientation)?;
                        d.set_item("task", t)?;
                    }
                }
                Ok(())
            })
            .map_err(|e| policy_error(&self.path, e))??;
        Ok(d)
    }

    /// The hand the policy drives: its task record's, else vge's own (a file from before
    /// task records).
    #[getter]
    fn hand(&self) -> PyResult<String> {
        self.loaded
            .with(|p| p.info().task.map_or(UNRECORDED_HAND, |t| t.hand).to_owned())
            .map_err(|e| policy_error(&self.path, e))
    }

    /// The observation set the policy observes: its task record's, else `full`.
    #[getter]
    fn observation_set(&self) -> PyResult<String> {
        self.loaded
            .with(|p| p.info().task.map_or(UNRECORDED_OBSERVATION_SET, |t| t.observation_set).to_owned())
            .map_err(|e| policy_error(&self.path, e))
    }

    #[getter]
    fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    #[getter]
    fn act_dim(&self) -> usize {
        self.act_dim
    }

    #[getter]
    fn path(&self) -> &str {
        &self.path
    }
}
