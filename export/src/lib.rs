//! Exports tch SAC actors to vge policy files and the `vge_runtime` MLP representation.
//!
//! [`build_actor`] builds the deterministic head of a SAC actor in a [`tch::nn::VarStore`];
//! [`extract_actor`] reads such an actor's parameters back by variable name into owned,
//! validated [`ExportedLayer`]s. [`export_policy`] / [`PolicyFile`] write and read policy
//! files (`docs/policy-format.md`), and [`inspect::report`] describes one. [`onnx`] writes a
//! policy as an ONNX model and imports MLP actors from ONNX (`docs/onnx.md`).

mod actor;
pub mod bench;
mod error;
mod extract;
pub mod firmware;
pub mod firmware_bench;
pub mod inspect;
pub mod onnx;
mod policy_file;
pub mod quantise;
mod v2;

pub use actor::{ActorSpec, TchActor, build_actor};
pub use error::ExportError;
pub use extract::{ExportedActor, ExportedLayer, extract_actor};
pub use policy_file::{
    LayerRecord, MAX_FILE_LEN, ObsNorm, ObsSlice, PolicyFile, PolicyMeta, Provenance, export_policy,
    read_policy_bytes,
};
pub use vge_runtime::{Activation, WeightType};
