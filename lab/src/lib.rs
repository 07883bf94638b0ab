//! vge-lab: the experiment tooling above single runs, without libtorch. Runs are read
//! through vge-run (their config, folder, success test and scores); this crate compares them:
//! statistics ([`stats`], [`compare`], [`object_rows`]), plots ([`plot`]) and Table I
//! ([`table1`]), gait diagrams ([`gait_diagram`]), robustness ([`robustness`]), screening and
//! shipping a policy ([`ship`]), sweeps and Slurm ([`sweep`]), queues of runs on fixed binaries
//! ([`queue`]), a finished run's facts ([`run_facts`]) and runs' time to a gait
//! ([`time_to_gait`]). The learner (vge-trainer) does not depend on it.

// Functions of at most 80 lines of code (clippy.toml).
#![warn(clippy::too_many_lines)]

pub mod compare;
pub mod gait_diagram;
pub mod object_rows;
pub mod plot;
pub mod queue;
pub mod robustness;
pub mod run_facts;
pub mod ship;
pub mod stats;
pub mod sweep;
pub mod table1;
pub mod time_to_gait;
