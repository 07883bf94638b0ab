//! vge-lab: the experiment tooling around the learner, without libtorch. A run's config
//! ([`config`]) and folder ([`run_dir`]), the success test and its gait diagram ([`eval`],
//! [`gait_diagram`]), a run's periodic and final tests and model selection ([`run_eval`]), a
//! hand policy file's metadata ([`policy_meta`]), robustness ([`robustness`]), held-out scores ([`score`]) and their
//! statistics ([`stats`], [`compare`]), sweeps and Slurm ([`sweep`]), plots ([`plot`]) and
//! Table I ([`table1`]), screening and shipping a policy ([`ship`]). It evaluates exported policies on vge-runtime, as a hand would run
//! them; vge-trainer trains them and uses this crate for its periodic tests.

// Functions of at most 80 lines of code (clippy.toml).
#![warn(clippy::too_many_lines)]

pub mod atomic_file;
pub mod compare;
pub mod config;
pub mod eval;
pub mod gait_diagram;
pub mod object_rows;
pub mod plot;
pub mod policy_meta;
pub mod read_limits;
pub mod robustness;
pub mod run_dir;
pub mod run_eval;
pub mod run_lock;
pub mod score;
pub mod ship;
pub mod stats;
pub mod sweep;
pub mod table1;
