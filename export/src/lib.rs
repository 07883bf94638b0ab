//! Exports tch SAC actors to the `vge_runtime` MLP representation.
//!
//! This first piece builds the deterministic head of a SAC actor in a [`tch::nn::VarStore`]
//! ([`build_actor`]) and reads such an actor's parameters back by variable name into owned,
//! validated [`ExportedLayer`]s ([`extract_actor`]), which can be borrowed as
//! [`vge_runtime::Layer`]s for evaluation with [`vge_runtime::Mlp`].

mod actor;
mod error;
mod extract;

pub use actor::{ActorSpec, TchActor, build_actor};
pub use error::ExportError;
pub use extract::{ExportedActor, ExportedLayer, extract_actor};
pub use vge_runtime::Activation;
