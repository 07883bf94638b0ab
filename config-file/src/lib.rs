//! A vge config file as every reader of it sees it: the file over its `base` chain
//! ([`read_with_bases`]), and its `[env]` section as the sim defines it ([`EnvKeys`]). The
//! lab's configs and the Python package both read files here, so the package does not build
//! the lab and the two cannot drift apart.

mod base_chain;
mod env_keys;

pub use base_chain::{BASE_KEY, BaseChainError, MAX_BASE_CHAIN, read_with_bases};
pub use env_keys::{EnvKeys, EnvKeysError};
