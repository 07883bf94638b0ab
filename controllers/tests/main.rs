//! The crate's integration tests: one module per file beside this one, built as one test binary
//! that links the dependencies once rather than once per file (docs/testing.md). Under `cargo
//! nextest run` each test still runs in a process of its own.

mod controllers;
mod controllers_sim;
