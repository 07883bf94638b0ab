//! vge-trainer: Soft Actor-Critic in tch with value-guided exploration (VGE) for
//! finger-gaiting, and the `vge` command.

pub mod bench_update;
pub mod controllers;
pub mod nets;
pub mod policy_export;
pub mod sac;
