//! vge-bridge: runs an exported vge policy at a fixed control rate against the simulator or
//! against a hand's joint controllers over SocketCAN.
//!
//! This crate never links libtorch: it reads policy files with `vge-runtime` only.

pub mod emulator;
pub mod protocol;
pub mod socketcan_io;

pub use protocol::{FingerId, JointCommand, JointState, ProtocolError, RawFrame};
