//! Conversion between protocol frames and SocketCAN frames.

use socketcan::{CanFrame, EmbeddedFrame, Frame, Id, StandardId};
use thiserror::Error;

use crate::protocol::RawFrame;
use crate::protocol::allegro::AllegroFrame;

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

/// Builds the SocketCAN frame for an Allegro frame: a data frame of its 0-8 bytes, or a remote
/// frame with DLC 0 (as the Allegro drivers send requests).
pub fn allegro_to_can_frame(frame: &AllegroFrame) -> Result<CanFrame, FrameError> {
    let id = StandardId::new(frame.id()).ok_or(FrameError::IdTooLarge(frame.id()))?;
    let built =
        if frame.is_remote() { CanFrame::new_remote(id, 0) } else { CanFrame::new(id, frame.payload()) };
    // An AllegroFrame holds at most 8 bytes, so only the id could be refused.
    built.ok_or(FrameError::IdTooLarge(frame.id()))
}

/// The Allegro frame a received SocketCAN frame carries: a standard-id data frame of any
/// length, or a remote frame (read as its id with no data, whatever DLC it asks for).
pub fn allegro_frame_of(frame: &CanFrame) -> Result<AllegroFrame, FrameError> {
    let id = match frame.id() {
        Id::Standard(id) => id.as_raw(),
        Id::Extended(id) => return Err(FrameError::ExtendedId(id.as_raw())),
    };
    match frame {
        CanFrame::Data(f) => AllegroFrame::data(id, f.data()).map_err(|_| FrameError::NotData(u32::from(id))),
        CanFrame::Remote(_) => Ok(AllegroFrame::remote(id)),
        CanFrame::Error(_) => Err(FrameError::NotData(frame.raw_id())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use socketcan::ExtendedId;

    #[test]
    fn allegro_frames_of_any_length_and_remote_frames_round_trip() {
        for frame in [
            AllegroFrame::data(0x100, &[]).expect("frame"),
            AllegroFrame::data(0x040, &[1]).expect("frame"),
            AllegroFrame::data(0x204, &[3, 0, 0, 0, 0xF4, 1]).expect("frame"),
            AllegroFrame::data(0x180, &[1, 2, 3, 4, 5, 6, 7, 8]).expect("frame"),
            AllegroFrame::remote(0x200),
        ] {
            let can = allegro_to_can_frame(&frame).expect("standard id");
            assert_eq!(can.is_remote_frame(), frame.is_remote());
            assert_eq!(EmbeddedFrame::dlc(&can), frame.payload().len());
            assert_eq!(allegro_frame_of(&can), Ok(frame));
        }
        assert_eq!(
            allegro_to_can_frame(&AllegroFrame::remote(0x800)).map(|_| ()),
            Err(FrameError::IdTooLarge(0x800))
        );
        let ext = CanFrame::new(ExtendedId::new(0x1234).expect("fits"), &[0; 2]).expect("frame");
        assert_eq!(allegro_frame_of(&ext), Err(FrameError::ExtendedId(0x1234)));
    }

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
