//! A vge config file as every reader of it sees it: the file over its `base` chain
//! ([`read_with_bases`]), and its `[env]` section as the sim defines it ([`EnvKeys`]). The
//! lab's configs and the Python package both read files here, so the package does not build
//! the lab and the two cannot drift apart. Files are read whole only when they are regular
//! files within their kind's bound ([`read_bounded`]); [`memory`] is what the Python package
//! and the lab check sizes against.

mod base_chain;
mod bounded;
mod env_keys;
pub mod memory;

pub use base_chain::{BASE_KEY, BaseChainError, MAX_BASE_CHAIN, read_with_bases};
pub use bounded::{MAX_CONFIG_FILE_LEN, read_bounded, read_to_string_bounded};
pub use env_keys::{EnvKeys, EnvKeysError};
