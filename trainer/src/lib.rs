//! vge-trainer: the learner. SAC and TD3 in tch behind one trait ([`learner`]) with value-guided exploration
//! ([`behaviour`]) for finger-gaiting, the replay buffer ([`replay`]), the training loop
//! ([`train`]) and its checkpoints ([`checkpoint`]). The only crate of vge that links
//! libtorch; run configs, the success test and the rest of the lab are vge-lab's.

// Functions of at most 80 lines of code (clippy.toml).
#![warn(clippy::too_many_lines)]

pub mod behaviour;
pub mod bench_train;
pub mod bench_update;
pub mod checkpoint;
pub mod cpu_time;
pub mod heap;
pub mod learner;
pub mod mkl;
pub mod nets;
pub mod optim;
pub mod policy_export;
pub mod replay;
mod saved_state;
pub mod tensorboard;
pub mod toy;
pub mod train;
