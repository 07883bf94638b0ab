//! Reads tch SAC actors into vge policy files, and measures the runtime against tch.
//!
//! [`build_actor`] builds the deterministic head of a SAC actor in a [`tch::nn::VarStore`];
//! [`extract_actor`] reads such an actor's parameters back by variable name into owned,
//! validated [`ExportedLayer`](vge_export::ExportedLayer)s, and [`export_policy`] encodes them
//! as a policy file. [`bench`] and [`firmware_bench`] time and check the runtime and the
//! Cortex-M4F firmware against tch's forward. The libtorch half of vge-export, in a crate of
//! its own so that crates reading policy files (vge-run, vge-lab, the bridge) never link
//! libtorch, whatever else a build holds.

mod actor;
pub mod bench;
mod extract;
pub mod firmware_bench;

pub use actor::{TchActor, build_actor};
pub use extract::extract_actor;

use tch::nn::VarStore;
use vge_export::{ActorSpec, ExportError, PolicyFile, PolicyMeta};

/// Reads the actor under `prefix` (`"actor"` for the trainer's `GaussianActor`) out of `vs`
/// and encodes it with `meta` as a policy file (version 3, `f32` weights).
pub fn export_policy(
    vs: &VarStore,
    prefix: &str,
    spec: &ActorSpec,
    meta: PolicyMeta,
) -> Result<Vec<u8>, ExportError> {
    let actor = extract_actor(vs, prefix, spec)?;
    PolicyFile::from_actor(&actor, meta)?.to_bytes()
}

/// libtorch's error as an export error.
fn tch_error(e: tch::TchError) -> ExportError {
    ExportError::Tch(Box::new(e))
}
