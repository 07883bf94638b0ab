//! The crate's integration tests: one module per file beside this one, built as one test binary
//! that links the dependencies once rather than once per file (docs/testing.md). Under `cargo
//! nextest run` each test still runs in a process of its own.

#[path = "../../tests/support/python.rs"]
mod python_env;

mod allegro;
mod determinism;
mod grasp;
mod mujoco_model;
mod policy_interface;
mod randomization;
mod rapier_kinematics;
mod recording;
mod task_variants;
mod tip_slip;
mod unseen_object;
mod upright;
