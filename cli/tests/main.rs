//! The crate's integration tests: one module per file beside this one, built as one test binary
//! that links the dependencies once rather than once per file (docs/testing.md). Under `cargo
//! nextest run` each test still runs in a process of its own.
//!
//! The tests that link libtorch (checkpoint_integrity, run_folder_crash) and the Slurm test are
//! binaries of their own (Cargo.toml).

mod cli;
mod closed_pipe;
mod common;
mod config_bounds;
mod config_show;
mod facts;
mod hand;
mod mkl_dispatch;
mod multi_object;
mod queue;
mod record;
mod resume_after_kill;
mod score;
mod second_hand;
mod table1_run;
mod time_to_gait;
