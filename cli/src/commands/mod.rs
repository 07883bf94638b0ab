//! One module per `vge` subcommand: its arguments (their doc comments are its `--help`) and
//! what it runs.

pub mod bench;
pub mod compare;
pub mod config;
pub mod controller;
pub mod eval;
pub mod export;
pub mod facts;
pub mod hand;
pub mod import;
pub mod inspect;
pub mod plot;
pub mod queue;
pub mod robustness;
pub mod score;
pub mod screen;
pub mod ship;
pub mod sweep;
pub mod table1;
pub mod time_to_gait;
pub mod train;

/// Why a command that needs libtorch cannot run in a vge built without the `train` feature.
#[cfg(not(feature = "train"))]
pub(crate) fn without_training(what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{what}: needs libtorch, and this vge was built without its `train` feature; build it with \
         the default features (cargo build --release -p vge-cli)"
    )
}
