//! Integration and hardware-in-the-loop tests across the vge crates.
//!
//! Hardware-in-the-loop tests (`tests/hil.rs`) need a SocketCAN interface named by
//! `VGE_HIL_IFACE` (default `vcan0`). Run them with `scripts/hil.sh`, which provides one on
//! any Linux kernel: directly where the kernel has vcan, else inside a user-mode-linux or
//! QEMU guest (`scripts/canvm/run.sh`).

/// The CAN interface hardware-in-the-loop tests use.
pub fn hil_iface() -> String {
    std::env::var("VGE_HIL_IFACE").unwrap_or_else(|_| "vcan0".to_owned())
}
