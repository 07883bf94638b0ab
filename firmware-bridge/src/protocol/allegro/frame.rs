//! A classic CAN frame as the Allegro protocol uses it: data or remote, 0 to 8 bytes.

use super::AllegroError;

/// An 11-bit id, whether it is a remote (RTR) frame, and 0..=8 data bytes. Unlike vge's own
/// protocol ([`super::super::RawFrame`], always 8 bytes), the Allegro's frames have DLC 0
/// (servo on/off, remote requests), 1, 4, 6, 7 or 8.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AllegroFrame {
    id: u16,
    remote: bool,
    len: u8,
    data: [u8; 8],
}

impl AllegroFrame {
    /// A data frame carrying `payload` (at most 8 bytes).
    pub fn data(id: u16, payload: &[u8]) -> Result<Self, AllegroError> {
        let mut data = [0u8; 8];
        data.get_mut(..payload.len()).ok_or(AllegroError::TooLong(payload.len()))?.copy_from_slice(payload);
        Ok(Self { id, remote: false, len: payload.len() as u8, data })
    }

    /// A remote frame (a request for the data frame with the same id), DLC 0 as the drivers
    /// send it.
    pub fn remote(id: u16) -> Self {
        Self { id, remote: true, len: 0, data: [0; 8] }
    }

    /// The 11-bit id.
    pub fn id(&self) -> u16 {
        self.id
    }

    /// Whether this is a remote (RTR) frame.
    pub fn is_remote(&self) -> bool {
        self.remote
    }

    /// The data bytes (empty for a remote frame).
    pub fn payload(&self) -> &[u8] {
        self.data.get(..usize::from(self.len)).unwrap_or(&[])
    }
}

/// Four little-endian 16-bit words from up to 8 bytes (missing bytes read as zero; callers
/// check the length first).
pub(super) fn le_words(data: &[u8]) -> [u16; 4] {
    let mut buf = [0u8; 8];
    for (b, d) in buf.iter_mut().zip(data) {
        *b = *d;
    }
    let mut words = [0u16; 4];
    for (w, pair) in words.iter_mut().zip(buf.chunks_exact(2)) {
        *w = u16::from_le_bytes([pair[0], pair[1]]);
    }
    words
}

/// Four 16-bit words as 8 little-endian bytes.
pub(super) fn le_bytes(words: [u16; 4]) -> [u8; 8] {
    let mut buf = [0u8; 8];
    for (pair, w) in buf.chunks_exact_mut(2).zip(words) {
        pair.copy_from_slice(&w.to_le_bytes());
    }
    buf
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_hold_up_to_eight_bytes() {
        let f = AllegroFrame::data(0x204, &[3, 0, 0, 0, 0, 0]).expect("six bytes");
        assert_eq!((f.id(), f.is_remote(), f.payload()), (0x204, false, &[3u8, 0, 0, 0, 0, 0][..]));
        assert_eq!(AllegroFrame::data(0x100, &[]).map(|f| f.payload().len()), Ok(0));
        assert_eq!(AllegroFrame::data(0x100, &[0; 9]), Err(AllegroError::TooLong(9)));
        let r = AllegroFrame::remote(0x200);
        assert!(r.is_remote() && r.payload().is_empty());
    }

    #[test]
    fn words_are_little_endian() {
        assert_eq!(le_bytes([0x0201, 0xFFFF, 0, 0x8000]), [1, 2, 0xFF, 0xFF, 0, 0, 0, 0x80]);
        assert_eq!(le_words(&[1, 2, 0xFF, 0xFF, 0, 0, 0, 0x80]), [0x0201, 0xFFFF, 0, 0x8000]);
        assert_eq!(le_words(&[3, 0, 5]), [3, 5, 0, 0]);
    }
}
