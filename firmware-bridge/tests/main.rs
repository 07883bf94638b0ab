//! The crate's integration tests: one module per file beside this one, built as one test binary
//! that links the dependencies once rather than once per file (docs/testing.md). Under `cargo
//! nextest run` each test still runs in a process of its own.
//!
//! The modules that run the simulated hand need the `sim` feature; the rest also build and run
//! in the CAN-only bridge (scripts/test.sh runs `cli` there).

#[path = "../../tests/support/python.rs"]
mod python_env;

mod allegro_loop;
mod allegro_protocol;
mod cli;
#[cfg(feature = "sim")]
mod closed_pipe;
mod control_loop;
mod policies;
mod policy_size;
mod protocol_props;
#[cfg(feature = "sim")]
mod recording;
