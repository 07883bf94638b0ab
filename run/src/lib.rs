//! vge-run: one training run as every tool sees it, without libtorch or plots. Its config
//! ([`config`]), its folder with every file's name, reader and writer ([`run_dir`]), the
//! success test ([`eval`]) and the episodes it is run on ([`episode_sets`]), its periodic and
//! final tests and model selection ([`run_eval`]), its held-out score ([`score`]), and a hand
//! policy file's metadata ([`policy_meta`]). Every file vge reads whole is read within its
//! kind's bound ([`read_limits`]). How busy the machine's cores are ([`cpu_use`]) is here
//! too: `vge train` and `vge bench cores` measure it, and the learner fits its threads to it.
//!
//! The learner (vge-trainer) trains a run through this crate and the lab (vge-lab: statistics,
//! comparisons, Table I, plots, sweeps) reads runs through it; neither knows the other.

// Functions of at most 80 lines of code (clippy.toml).
#![warn(clippy::too_many_lines)]

pub mod config;
pub mod cpu_use;
pub mod episode_sets;
pub mod eval;
pub mod policy_meta;
pub mod read_limits;
pub mod run_dir;
pub mod run_eval;
pub mod score;
