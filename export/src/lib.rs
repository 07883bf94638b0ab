//! Writes and reads vge policy files and the `vge_runtime` MLP representation.
//!
//! [`PolicyFile`] writes and reads policy files (`docs/policy-format.md`) from an
//! [`ExportedActor`] (owned, validated [`ExportedLayer`]s), and [`inspect::report`] describes
//! one. [`onnx`] writes a policy as an ONNX model and imports MLP actors from ONNX
//! (`docs/onnx.md`). Reading an actor out of libtorch is vge-export-tch's: this crate never
//! links libtorch, so every build of the workspace shares one build of it.

mod error;
pub mod firmware;
pub mod inspect;
mod layers;
pub mod onnx;
mod policy_file;
pub mod quantise;
mod v2;

pub use error::ExportError;
pub use layers::{ActorSpec, ExportedActor, ExportedLayer};
pub use policy_file::{
    LayerRecord, MAX_FILE_LEN, ObsNorm, ObsSlice, PolicyFile, PolicyMeta, PolicyTask, Provenance,
    read_policy_bytes,
};
pub use vge_runtime::{Activation, WeightType};
