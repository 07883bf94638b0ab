//! The policy file's framing: magic, version, length, CRC-32 (see `docs/policy-format.md`).
//!
//! ```text
//! offset  size  field
//! 0       8     magic  b"VGEPOLCY"
//! 8       2     format version, u16 little-endian (1, 2 or 3)
//! 10      2     flags, u16 little-endian, must be 0
//! 12      4     payload length N, u32 little-endian
//! 16      N     payload: postcard encoding of the policy (see `policy.rs`)
//! 16+N    4     CRC-32 (IEEE) of bytes [0, 16+N), u32 little-endian
//! ```

use crate::PolicyError;

/// First eight bytes of every policy file.
pub const MAGIC: [u8; 8] = *b"VGEPOLCY";
/// The newest format version: the one `vge-export` writes (arrays aligned, used in place,
/// and an optional task record saying which hand and observation set the policy is for).
pub const FORMAT_VERSION: u16 = 3;
/// The oldest version this runtime still reads (arrays copied into caller storage).
pub const OLDEST_VERSION: u16 = 1;
/// Bytes before the payload: magic, version, flags, payload length.
pub const HEADER_LEN: usize = 16;
/// Bytes after the payload: the CRC-32.
pub const TRAILER_LEN: usize = 4;

/// Activation codes as stored in a layer record (one byte).
pub const ACT_IDENTITY: u8 = 0;
/// ReLU.
pub const ACT_RELU: u8 = 1;
/// tanh.
pub const ACT_TANH: u8 = 2;

const CRC_TABLE: [u32; 256] = crc_table();

// Evaluated at compile time only: an out-of-bounds index would fail the build, not panic.
#[allow(clippy::indexing_slicing)]
const fn crc_table() -> [u32; 256] {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
}

/// Incremental CRC-32 (IEEE 802.3 / zlib / PNG: reflected polynomial 0xEDB88320,
/// initial value and final XOR 0xFFFFFFFF). `crc32(b"123456789") == 0xCBF4_3926`.
#[derive(Debug, Clone, Copy)]
pub struct Crc32 {
    state: u32,
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc32 {
    pub const fn new() -> Self {
        Self { state: 0xFFFF_FFFF }
    }

    pub fn update(&mut self, data: &[u8]) {
        let mut c = self.state;
        for &b in data {
            // `(c ^ b) & 0xFF` is < 256: the index is always in bounds.
            c = CRC_TABLE.get(((c ^ u32::from(b)) & 0xFF) as usize).copied().unwrap_or(0) ^ (c >> 8);
        }
        self.state = c;
    }

    pub const fn finish(&self) -> u32 {
        self.state ^ 0xFFFF_FFFF
    }
}

/// CRC-32 of `data` (see [`Crc32`]).
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = Crc32::new();
    c.update(data);
    c.finish()
}

/// The 16 header bytes of a version-`version` file with a payload of `payload_len` bytes.
pub fn header(version: u16, payload_len: u32) -> [u8; HEADER_LEN] {
    let mut h = [0u8; HEADER_LEN];
    let v = version.to_le_bytes();
    let n = payload_len.to_le_bytes();
    let fields: [&[u8]; 4] = [&MAGIC, &v, &[0, 0], &n];
    let mut i = 0;
    for f in fields {
        for &b in f {
            if let Some(slot) = h.get_mut(i) {
                *slot = b;
            }
            i += 1;
        }
    }
    h
}

/// What [`check_frame`] found: the payload and the stored (verified) checksum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    pub version: u16,
    pub payload: &'a [u8],
    pub checksum: u32,
}

fn le_u16(bytes: &[u8], at: usize) -> Option<u16> {
    let b = bytes.get(at..at.checked_add(2)?)?;
    Some(u16::from_le_bytes([*b.first()?, *b.get(1)?]))
}

fn le_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([*b.first()?, *b.get(1)?, *b.get(2)?, *b.get(3)?]))
}

/// Checks magic, version, flags, length and CRC, in that order, and returns the payload.
/// With `verify_crc == false` the CRC is read but not compared (for `inspect` of a damaged file).
pub fn check_frame_with(bytes: &[u8], verify_crc: bool) -> Result<Frame<'_>, PolicyError> {
    let min = HEADER_LEN + TRAILER_LEN;
    if bytes.len() < min {
        return Err(PolicyError::TooShort { len: bytes.len(), min });
    }
    if bytes.get(..8) != Some(&MAGIC[..]) {
        return Err(PolicyError::BadMagic);
    }
    let version = le_u16(bytes, 8).ok_or(PolicyError::TooShort { len: bytes.len(), min })?;
    if !(OLDEST_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(PolicyError::UnsupportedVersion { found: version, supported: FORMAT_VERSION });
    }
    let flags = le_u16(bytes, 10).ok_or(PolicyError::TooShort { len: bytes.len(), min })?;
    if flags != 0 {
        return Err(PolicyError::UnsupportedFlags { flags });
    }
    let declared = le_u32(bytes, 12).ok_or(PolicyError::TooShort { len: bytes.len(), min })?;
    let expected_len = (declared as usize).checked_add(min);
    if expected_len != Some(bytes.len()) {
        return Err(PolicyError::LengthMismatch { payload_len: declared, file_len: bytes.len() });
    }
    let crc_at = bytes.len() - TRAILER_LEN;
    let covered = bytes.get(..crc_at).ok_or(PolicyError::TooShort { len: bytes.len(), min })?;
    let payload = covered.get(HEADER_LEN..).ok_or(PolicyError::TooShort { len: bytes.len(), min })?;
    let stored = le_u32(bytes, crc_at).ok_or(PolicyError::TooShort { len: bytes.len(), min })?;
    if verify_crc {
        let computed = crc32(covered);
        if computed != stored {
            return Err(PolicyError::ChecksumMismatch { stored, computed });
        }
    }
    Ok(Frame { version, payload, checksum: stored })
}

/// [`check_frame_with`] verifying the CRC.
pub fn check_frame(bytes: &[u8]) -> Result<Frame<'_>, PolicyError> {
    check_frame_with(bytes, true)
}
