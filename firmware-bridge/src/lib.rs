//! vge-bridge: runs an exported vge policy at a fixed control rate against the simulator or
//! against a hand's joint controllers over SocketCAN.
//!
//! Features (`std` and `sim` by default):
//! - `std`: the bridge for real hands over SocketCAN. It needs the hand's description only
//!   (`vge_hand::Hand`, read by vge-sim's `hands`: joints, fingers, limits, gains; vge-sim's
//!   observation layout and policy checks), without the physics: no rapier3d. Every size
//!   (nodes, joints, observation) comes from the loaded hand ([`protocol_hand`] for vge's own
//!   protocol, [`allegro_hand`] for the Allegro's). A real hand's joint limits may come from a
//!   hand file ([`hand_file`], `--hand FILE`).
//! - `sim`: the simulated hand as well ([`sim_hand`]: `run --backend sim`, `emulate --model
//!   sim`), with vge-sim's rapier3d physics, and `run --record F.jsonl`, the simulated
//!   episode recorded (`SimHand::record_to`, vge-sim's `recording`).
//!
//! Without `std` this crate is only [`protocol`], `no_std`, so joint controller firmware can
//! share the frame definitions. The bridge never links libtorch: it reads policy files with
//! `vge-runtime` only.
#![cfg_attr(not(feature = "std"), no_std)]

pub mod protocol;

#[cfg(feature = "std")]
pub mod allegro_emulator;
#[cfg(feature = "std")]
pub mod allegro_hand;
#[cfg(feature = "std")]
pub mod allegro_link;
#[cfg(feature = "std")]
pub mod allegro_loop;
#[cfg(feature = "sim")]
pub mod allegro_sim;
#[cfg(feature = "std")]
pub mod control_loop;
#[cfg(feature = "std")]
pub mod emulator;
#[cfg(feature = "std")]
pub mod hand_file;
#[cfg(feature = "std")]
pub mod hand_state;
#[cfg(feature = "std")]
pub mod heartbeat;
#[cfg(feature = "std")]
pub mod node_supervisor;
#[cfg(feature = "std")]
pub mod pacing;
#[cfg(feature = "std")]
pub mod policy_runner;
#[cfg(feature = "std")]
pub mod protocol_hand;
#[cfg(feature = "std")]
pub mod realtime;
#[cfg(feature = "std")]
pub mod report;
#[cfg(feature = "std")]
pub mod safety;
#[cfg(feature = "sim")]
pub mod sim_hand;
#[cfg(feature = "sim")]
pub mod sim_policy;
#[cfg(feature = "std")]
pub mod socketcan_io;
#[cfg(feature = "std")]
pub mod stats;
#[cfg(feature = "std")]
pub mod transport;

pub use protocol::{FingerId, Message, ProtocolError, RawFrame};
