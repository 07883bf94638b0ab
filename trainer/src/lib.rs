//! vge-trainer: Soft Actor-Critic and TD3 in tch ([`sac`]) with value-guided exploration
//! ([`behaviour`]) for finger-gaiting, the training loop ([`train`]), the success test
//! ([`eval`]), and the `vge` command.

pub mod atomic_file;
pub mod behaviour;
pub mod bench_update;
pub mod checkpoint;
pub mod compare;
pub mod config;
pub mod eval;
pub mod gait_diagram;
pub mod heap;
pub mod mkl;
pub mod nets;
pub mod optim;
pub mod plot;
pub mod policy_export;
pub mod replay;
pub mod robustness;
pub mod run_lock;
pub mod sac;
pub mod score;
pub mod stats;
pub mod sweep;
pub mod table1;
pub mod tensorboard;
pub mod toy;
pub mod train;

/// The sub-skill controllers live in their own crate (no libtorch); re-exported so that
/// `vge_trainer::controllers::...` keeps naming them.
pub use vge_controllers as controllers;
/// Contact-switch counting lives in vge-sim (shared with the bridge and the rollouts).
pub use vge_sim::gait;
