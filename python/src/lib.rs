//! `vge._vge`: the Rust half of the Python package `vge` (the Python half, in `vge/`, makes
//! these into a Gymnasium `Env` and `VectorEnv`).
//!
//! - [`env::EnvCore`]: one `vge_sim::Env` built from `[env]` keys (the hand among them), its
//!   observation the full one or the proprioceptive one the keys name;
//! - [`vec_env::VecEnvCore`]: N of them stepped on rayon's threads into preallocated numpy
//!   arrays, with Gymnasium's next-step autoreset;
//! - [`controllers::ControllerCore`]: IGM, CS or FG acting on an `EnvCore`'s state;
//! - [`policy::PolicyCore`]: a policy file on the no_std runtime, checked against the hand and
//!   observation of the env it drives;
//! - [`hand::HandCore`]: a hand read from its MJCF description, with its kinematics.
//!
//! Nothing here panics on Python input: every value is checked and refused with an
//! exception carrying the Rust error's message ([`errors`]).

use pyo3::prelude::*;

mod controllers;
mod env;
mod errors;
mod hand;
mod keys;
mod policy;
mod vec_env;

#[pymodule]
fn _vge(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<env::EnvCore>()?;
    m.add_class::<vec_env::VecEnvCore>()?;
    m.add_class::<controllers::ControllerCore>()?;
    m.add_class::<policy::PolicyCore>()?;
    m.add_class::<hand::HandCore>()?;
    m.add("PolicyError", m.py().get_type::<errors::PolicyError>())?;
    m.add("HandError", m.py().get_type::<errors::HandError>())?;
    m.add("ENV_KEYS", vge_sim::EnvSection::keys().to_vec())?;
    let objects: Vec<&str> = vge_sim::ObjectShape::ALL.iter().map(|o| o.name()).collect();
    m.add("OBJECTS", objects)?;
    m.add("HANDS", vge_sim::hands::shipped_names())?;
    m.add("VERSION", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
