//! Helpers shared with the other crates' integration tests: tests/support/runs.rs.
#![allow(dead_code)] // each test binary uses its own subset

#[path = "../../../tests/support/runs.rs"]
mod runs;
#[allow(unused_imports)] // each test binary uses its own subset
pub use runs::*;
