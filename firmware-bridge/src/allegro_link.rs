//! How Allegro frames reach the hand: SocketCAN frames of any length (DLC 0-8) and remote
//! frames, which vge's own transport ([`crate::transport`], always 8-byte data frames) does
//! not carry. One bus carries one of the two protocols: their ids overlap.

use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::time::Duration;

use socketcan::{CanFilter, CanFrame, CanSocket, EmbeddedFrame, Frame, Socket, SocketOptions};

use crate::protocol::allegro::{AllegroConfig, AllegroFrame};
use crate::socketcan_io::{allegro_frame_of, allegro_to_can_frame};
use crate::transport::{BusCounts, ErrorClass, TransportError};

/// What arrived from the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AllegroReceived {
    /// A standard-id data frame (0-8 bytes) or a remote frame.
    Frame(AllegroFrame),
    /// An extended-id frame: counted and ignored.
    Malformed { id: u32, len: usize },
    /// A SocketCAN error frame; `class` is its `CAN_ERR_*` bits ([`ErrorClass`]).
    Error { class: u32 },
}

/// Which frames a socket lets through.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AllegroRole {
    /// The host (the bridge): this device's position, temperature, info, serial and status
    /// data frames ([`AllegroConfig::host_filters`]), and error frames of every class.
    Host(AllegroConfig),
    /// The hand (the emulator): everything; the hand's decoder refuses what is not a command
    /// to it, so the emulator can count strangers instead of never seeing them.
    Hand,
    /// Everything (tools and tests that watch the bus).
    Monitor,
}

/// A full-duplex link for Allegro frames.
pub trait AllegroLink: Send {
    fn send(&mut self, frame: &AllegroFrame) -> Result<(), TransportError>;
    /// The next frame if one arrives within `timeout` (zero: only what is already queued).
    /// A signal interrupting the wait (Ctrl-C) returns `None`.
    fn recv(&mut self, timeout: Duration) -> Result<Option<AllegroReceived>, TransportError>;
    /// Frames received and sent so far.
    fn bus_counts(&self) -> BusCounts;

    /// Drops what is queued (at most `limit` frames) and returns how many: frames from before
    /// a run must not count as fresh.
    fn flush(&mut self, limit: usize) -> Result<usize, TransportError> {
        for n in 0..limit {
            if self.recv(Duration::ZERO)?.is_none() {
                return Ok(n);
            }
        }
        Ok(limit)
    }
}

/// Classic SocketCAN on an interface such as `can0` or `vcan0`.
#[derive(Debug)]
pub struct AllegroSocketCan {
    socket: CanSocket,
    counts: BusCounts,
}

impl AllegroSocketCan {
    pub fn open(iface: &str, role: AllegroRole) -> Result<Self, TransportError> {
        let socket = CanSocket::open(iface)?;
        // Non-blocking for good: a zero-timeout read is then one system call.
        socket.set_nonblocking(true)?;
        match role {
            AllegroRole::Host(cfg) => {
                let filters: Vec<CanFilter> =
                    cfg.host_filters().iter().map(|&(id, mask)| CanFilter::new(id, mask)).collect();
                socket.set_filters(&filters)?;
                socket.set_error_filter(ErrorClass::ALL)?;
            }
            AllegroRole::Hand | AllegroRole::Monitor => socket.set_filter_accept_all()?,
        }
        Ok(Self { socket, counts: BusCounts::default() })
    }

    /// The socket, for options such as its receive buffer.
    pub fn socket(&self) -> &CanSocket {
        &self.socket
    }
}

impl AllegroLink for AllegroSocketCan {
    fn send(&mut self, frame: &AllegroFrame) -> Result<(), TransportError> {
        let can = allegro_to_can_frame(frame)?;
        self.socket.write_frame(&can).map_err(|e| {
            if e.raw_os_error() == Some(libc::ENOBUFS) || e.kind() == std::io::ErrorKind::WouldBlock {
                TransportError::TxQueueFull { id: frame.id() }
            } else {
                TransportError::Io(e)
            }
        })?;
        self.counts.frames_out += 1;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<AllegroReceived>, TransportError> {
        let result = if timeout.is_zero() {
            self.socket.read_frame()
        } else {
            self.socket.read_frame_timeout(timeout)
        };
        let frame = match result {
            Ok(frame) => frame,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                return Ok(None);
            }
            Err(e) => return Err(e.into()),
        };
        self.counts.frames_in += 1;
        if let CanFrame::Error(e) = &frame {
            return Ok(Some(AllegroReceived::Error { class: e.error_bits() }));
        }
        Ok(Some(match allegro_frame_of(&frame) {
            Ok(f) => AllegroReceived::Frame(f),
            Err(_) => AllegroReceived::Malformed { id: frame.raw_id(), len: EmbeddedFrame::dlc(&frame) },
        }))
    }

    fn bus_counts(&self) -> BusCounts {
        self.counts
    }
}

/// One end of an in-process link (unit tests, benchmarks). Like a bus, sending with nobody
/// listening is not an error: the frame is lost.
#[derive(Debug)]
pub struct AllegroInProcess {
    tx: Sender<AllegroReceived>,
    rx: Receiver<AllegroReceived>,
    counts: BusCounts,
}

impl AllegroInProcess {
    pub fn pair() -> (Self, Self) {
        let (a_tx, b_rx) = channel();
        let (b_tx, a_rx) = channel();
        (
            Self { tx: a_tx, rx: a_rx, counts: BusCounts::default() },
            Self { tx: b_tx, rx: b_rx, counts: BusCounts::default() },
        )
    }

    /// Sends something other than a frame (an error frame, a malformed frame): fault injection.
    pub fn send_received(&mut self, received: AllegroReceived) {
        let _ = self.tx.send(received);
    }
}

impl AllegroLink for AllegroInProcess {
    fn send(&mut self, frame: &AllegroFrame) -> Result<(), TransportError> {
        let _ = self.tx.send(AllegroReceived::Frame(*frame));
        self.counts.frames_out += 1;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<AllegroReceived>, TransportError> {
        let received = if timeout.is_zero() {
            // Empty or disconnected: nothing arrives.
            self.rx.try_recv().ok()
        } else {
            match self.rx.recv_timeout(timeout) {
                Ok(r) => Some(r),
                Err(RecvTimeoutError::Timeout) => None,
                // Nothing can arrive any more: wait out the timeout as a silent bus would.
                Err(RecvTimeoutError::Disconnected) => {
                    std::thread::sleep(timeout);
                    None
                }
            }
        };
        if received.is_some() {
            self.counts.frames_in += 1;
        }
        Ok(received)
    }

    fn bus_counts(&self) -> BusCounts {
        self.counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_process_pair_carries_frames_of_any_length_and_flushes() {
        let (mut a, mut b) = AllegroInProcess::pair();
        let frames =
            [AllegroFrame::remote(0x200), AllegroFrame::data(0x204, &[3, 0, 0, 0, 0xF4, 1]).expect("frame")];
        for f in &frames {
            a.send(f).expect("send");
        }
        assert_eq!(b.recv(Duration::ZERO).expect("recv"), Some(AllegroReceived::Frame(frames[0])));
        a.send(&frames[1]).expect("send");
        assert_eq!(b.flush(100).expect("flush"), 2);
        assert_eq!(b.recv(Duration::from_millis(1)).expect("recv"), None);
        assert_eq!(b.bus_counts(), BusCounts { frames_in: 3, frames_out: 0 });
        drop(b);
        a.send(&frames[0]).expect("a send nobody hears is not an error on a bus");
    }
}
