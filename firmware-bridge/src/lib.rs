//! vge-bridge: runs an exported vge policy at a fixed control rate against the simulator or
//! against a hand's joint controllers over SocketCAN.
//!
//! Without the default `std` feature this crate is only [`protocol`], `no_std`, so joint
//! controller firmware can share the frame definitions. The bridge never links libtorch: it
//! reads policy files with `vge-runtime` only.
#![cfg_attr(not(feature = "std"), no_std)]

pub mod protocol;

#[cfg(feature = "std")]
pub mod control_loop;
#[cfg(feature = "std")]
pub mod emulator;
#[cfg(feature = "std")]
pub mod hand_state;
#[cfg(feature = "std")]
pub mod heartbeat;
#[cfg(feature = "std")]
pub mod node_supervisor;
#[cfg(feature = "std")]
pub mod policy_runner;
#[cfg(feature = "std")]
pub mod realtime;
#[cfg(feature = "std")]
pub mod report;
#[cfg(feature = "std")]
pub mod safety;
#[cfg(feature = "std")]
pub mod sim_hand;
#[cfg(feature = "std")]
pub mod socketcan_io;
#[cfg(feature = "std")]
pub mod stats;
#[cfg(feature = "std")]
pub mod transport;

pub use protocol::{FingerId, Message, ProtocolError, RawFrame};
