//! Exports tch SAC actors to vge policy files and the `vge_runtime` MLP representation.
//!
//! [`build_actor`] builds the deterministic head of a SAC actor in a [`tch::nn::VarStore`];
//! [`extract_actor`] reads such an actor's parameters back by variable name into owned,
//! validated [`ExportedLayer`]s. [`export_policy`] / [`PolicyFile`] write and read policy
//! files (`docs/policy-format.md`), and [`inspect::report`] describes one. [`onnx`] writes a
//! policy as an ONNX model and imports MLP actors from ONNX (`docs/onnx.md`).

// The tch half (feature `tch`, on by default): actors built and read in libtorch, and the
// benchmarks against tch's forward. Everything else reads and writes policy files without it.
#[cfg(feature = "tch")]
mod actor;
#[cfg(feature = "tch")]
pub mod bench;
mod error;
#[cfg(feature = "tch")]
mod extract;
pub mod firmware;
#[cfg(feature = "tch")]
pub mod firmware_bench;
pub mod inspect;
mod layers;
pub mod onnx;
mod policy_file;
pub mod quantise;
mod v2;

#[cfg(feature = "tch")]
pub use actor::{TchActor, build_actor};
pub use error::ExportError;
#[cfg(feature = "tch")]
pub use extract::extract_actor;
pub use layers::{ActorSpec, ExportedActor, ExportedLayer};
#[cfg(feature = "tch")]
pub use policy_file::export_policy;
pub use policy_file::{
    LayerRecord, MAX_FILE_LEN, ObsNorm, ObsSlice, PolicyFile, PolicyMeta, PolicyTask, Provenance,
    read_policy_bytes,
};
pub use vge_runtime::{Activation, WeightType};
