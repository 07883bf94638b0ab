//! Policy-file bytes in a heap buffer aligned for in-place use (`std` feature, host side).
//!
//! A version-2 file's arrays are borrowed in place, which needs the bytes at an address
//! aligned to [`crate::policy::TENSOR_ALIGN`]; `std::fs::read`'s `Vec<u8>` promises only 1.
//! Firmware gets the same from a `#[repr(align(16))]` static around `include_bytes!`.

extern crate alloc;

use alloc::vec;
use alloc::vec::Vec;

/// A copy of some bytes starting at a 16-byte aligned address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlignedBytes {
    /// `u128` has alignment 16 on x86-64 and aarch64 (8 on some 32-bit targets, still enough
    /// for every array type a policy file holds).
    words: Vec<u128>,
    len: usize,
}

impl AlignedBytes {
    /// Copies `bytes`.
    pub fn new(bytes: &[u8]) -> Self {
        let mut words = vec![0u128; bytes.len().div_ceil(16)];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut words);
        if let Some(dst) = dst.get_mut(..bytes.len()) {
            dst.copy_from_slice(bytes);
        }
        Self { words, len: bytes.len() }
    }

    /// The bytes.
    pub fn as_bytes(&self) -> &[u8] {
        let all: &[u8] = bytemuck::cast_slice(&self.words);
        all.get(..self.len).unwrap_or(all)
    }
}

impl core::ops::Deref for AlignedBytes {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        self.as_bytes()
    }
}

impl From<&[u8]> for AlignedBytes {
    fn from(bytes: &[u8]) -> Self {
        Self::new(bytes)
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_bytes_and_aligns_them() {
        let src: alloc::vec::Vec<u8> = (0..37u8).collect();
        // Misaligned on purpose: a sub-slice starting at an odd offset.
        let a = AlignedBytes::new(&src[1..]);
        assert_eq!(a.as_bytes(), &src[1..]);
        assert_eq!(a.as_ptr().align_offset(16), 0);
        assert!(AlignedBytes::new(&[]).is_empty());
    }
}
