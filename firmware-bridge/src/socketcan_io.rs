//! Conversion between protocol frames and SocketCAN frames.

use socketcan::{CanFrame, EmbeddedFrame, Frame, Id, StandardId};
use thiserror::Error;

use crate::protocol::RawFrame;

#[derive(Debug, Error, PartialEq, Eq)]
pub enum FrameError {
    #[error("extended id {0:#x}: the hand protocol uses standard (11-bit) ids")]
    ExtendedId(u32),
    #[error("remote or error frame with id {0:#x}")]
    NotData(u32),
    #[error("id {0:#x} does not fit in 11 bits")]
    IdTooLarge(u16),
}

/// Builds the SocketCAN data frame for a protocol frame.
pub fn to_can_frame(frame: &RawFrame) -> Result<CanFrame, FrameError> {
    let id = StandardId::new(frame.id).ok_or(FrameError::IdTooLarge(frame.id))?;
    // An 8-byte payload always fits a classic frame.
    CanFrame::new(id, &frame.data).ok_or(FrameError::IdTooLarge(frame.id))
}

/// The standard id and payload of a received data frame.
pub fn standard_id_and_data(frame: &CanFrame) -> Result<(u16, &[u8]), FrameError> {
    if !matches!(frame, CanFrame::Data(_)) {
        return Err(FrameError::NotData(frame.raw_id()));
    }
    match frame.id() {
        Id::Standard(id) => Ok((id.as_raw(), frame.data())),
        Id::Extended(id) => Err(FrameError::ExtendedId(id.as_raw())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use socketcan::ExtendedId;

    #[test]
    fn round_trips_through_socketcan_frames() {
        let raw = RawFrame { id: 0x183, data: [1, 2, 3, 4, 5, 6, 7, 8] };
        let frame = to_can_frame(&raw).expect("standard id");
        let (id, data) = standard_id_and_data(&frame).expect("data frame");
        assert_eq!((id, data), (0x183, &raw.data[..]));
    }

    #[test]
    fn rejects_extended_ids_and_large_ids() {
        let ext = CanFrame::new(ExtendedId::new(0x1234).expect("fits"), &[0; 8]).expect("frame");
        assert_eq!(standard_id_and_data(&ext), Err(FrameError::ExtendedId(0x1234)));
        assert!(!ext.is_remote_frame());
        assert_eq!(to_can_frame(&RawFrame { id: 0x800, data: [0; 8] }), Err(FrameError::IdTooLarge(0x800)));
    }
}
