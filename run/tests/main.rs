//! The crate's integration tests: one module per file beside this one, built as one test binary
//! that links the dependencies once rather than once per file (docs/testing.md). Under `cargo
//! nextest run` each test still runs in a process of its own.

mod config_base;
mod env_variants;
mod learner_section;
mod resume_and_episode_sets;
mod reward_reverse;
mod rotation_measure;
mod stored_configs;
mod tip_slip;
