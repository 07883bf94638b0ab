//! How frames reach the hand: SocketCAN on a real (or virtual) bus, or an in-process channel
//! pair for unit tests and timing benchmarks.

use std::collections::VecDeque;
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, TryRecvError, channel};
use std::time::Duration;

use socketcan::{CanAnyFrame, CanFdFrame, CanFdSocket, CanSocket, EmbeddedFrame, Frame, Socket, StandardId};
use thiserror::Error;

use crate::protocol::fd::{FdMessage, FdPacker};
use crate::protocol::{Message, RawFrame};
use crate::socketcan_io::{FrameError, standard_id_and_data, to_can_frame};

#[derive(Debug, Error)]
pub enum TransportError {
    #[error("CAN socket")]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Frame(#[from] FrameError),
}

/// A received frame that is not a standard 8-byte data frame, kept for the statistics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Received {
    Frame(RawFrame),
    /// An extended-id, remote, error or short frame: counted and ignored by the bridge.
    Malformed {
        id: u32,
        len: usize,
    },
}

/// A full-duplex frame link to the hand.
pub trait Transport: Send {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError>;
    /// The next frame if one arrives within `timeout` (zero: only what is already queued).
    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError>;
}

/// The next frame within `timeout`, `None` if none came. A zero timeout polls: SocketCAN
/// takes a zero read timeout as "block forever".
fn read_frame<S: Socket>(socket: &S, timeout: Duration) -> Result<Option<S::FrameType>, TransportError> {
    let result = if timeout.is_zero() {
        socket.set_nonblocking(true)?;
        let r = socket.read_frame();
        socket.set_nonblocking(false)?;
        r
    } else {
        socket.read_frame_timeout(timeout)
    };
    match result {
        Ok(frame) => Ok(Some(frame)),
        Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
            Ok(None)
        }
        Err(e) => Err(e.into()),
    }
}

/// SocketCAN (classic frames) on an interface such as `can0` or `vcan0`.
#[derive(Debug)]
pub struct SocketCanTransport {
    socket: CanSocket,
}

impl SocketCanTransport {
    pub fn open(iface: &str) -> Result<Self, TransportError> {
        let socket = CanSocket::open(iface)?;
        Ok(Self { socket })
    }
}

impl Transport for SocketCanTransport {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError> {
        self.socket.write_frame(&to_can_frame(frame)?)?;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
        let Some(frame) = read_frame(&self.socket, timeout)? else { return Ok(None) };
        Ok(Some(match standard_id_and_data(&frame) {
            Ok((id, data)) => match <[u8; 8]>::try_from(data) {
                Ok(data) => Received::Frame(RawFrame { id, data }),
                Err(_) => Received::Malformed { id: u32::from(id), len: data.len() },
            },
            Err(_) => {
                use socketcan::Frame;
                Received::Malformed { id: frame.raw_id(), len: socketcan::EmbeddedFrame::dlc(&frame) }
            }
        }))
    }
}

/// SocketCAN with the CAN FD option (`docs/can-protocol.md`): joint commands and each node's
/// state travel packed in FD frames, everything else as classic frames. To the control loop
/// and the emulators it looks like the classic transport: FD frames are sent once their
/// classic parts are complete and unpacked into classic frames on receipt.
#[derive(Debug)]
pub struct FdSocketCanTransport {
    socket: CanFdSocket,
    packer: FdPacker,
    inbox: VecDeque<Received>,
}

impl FdSocketCanTransport {
    /// Opens `iface`, which must have an FD-capable MTU (72; vcan's default).
    pub fn open(iface: &str) -> Result<Self, TransportError> {
        Ok(Self { socket: CanFdSocket::open(iface)?, packer: FdPacker::default(), inbox: VecDeque::new() })
    }

    fn write_fd(&self, fd: &FdMessage) -> Result<(), TransportError> {
        let raw = fd.encode().map_err(|_| FrameError::IdTooLarge(0))?;
        let id = StandardId::new(raw.id).ok_or(FrameError::IdTooLarge(raw.id))?;
        let frame = CanFdFrame::new(id, raw.payload()).ok_or(FrameError::IdTooLarge(raw.id))?;
        self.socket.write_frame(&frame)?;
        Ok(())
    }
}

impl Transport for FdSocketCanTransport {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError> {
        match Message::decode_frame(frame) {
            Ok(m) if FdPacker::carries(&m) => {
                if let Some(fd) = self.packer.push(&m) {
                    self.write_fd(&fd)?;
                }
                Ok(())
            }
            _ => {
                self.socket.write_frame(&to_can_frame(frame)?)?;
                Ok(())
            }
        }
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
        if let Some(r) = self.inbox.pop_front() {
            return Ok(Some(r));
        }
        let Some(frame) = read_frame(&self.socket, timeout)? else { return Ok(None) };
        let received = match frame {
            CanAnyFrame::Fd(fd) => match (fd.id(), FdMessage::decode(standard_raw(&fd), fd.data())) {
                (socketcan::Id::Standard(_), Ok(message)) => {
                    for m in message.to_classic() {
                        if let Ok(raw) = m.encode() {
                            self.inbox.push_back(Received::Frame(raw));
                        }
                    }
                    return Ok(self.inbox.pop_front());
                }
                _ => Received::Malformed { id: fd.raw_id(), len: fd.data().len() },
            },
            CanAnyFrame::Normal(f) => match (f.id(), <[u8; 8]>::try_from(f.data())) {
                (socketcan::Id::Standard(id), Ok(data)) => {
                    Received::Frame(RawFrame { id: id.as_raw(), data })
                }
                _ => Received::Malformed { id: f.raw_id(), len: f.data().len() },
            },
            CanAnyFrame::Remote(f) => Received::Malformed { id: f.raw_id(), len: 0 },
            CanAnyFrame::Error(f) => Received::Malformed { id: f.raw_id(), len: 0 },
        };
        Ok(Some(received))
    }
}

/// The 11-bit id of an FD frame (0 for extended ids, which the caller then rejects).
fn standard_raw(frame: &CanFdFrame) -> u16 {
    match frame.id() {
        socketcan::Id::Standard(id) => id.as_raw(),
        socketcan::Id::Extended(_) => 0,
    }
}

/// One end of an in-process link; frames sent on one end arrive at the other. Like a CAN
/// bus, it does not fail when nobody listens: once the other end is gone, sends are dropped
/// and nothing arrives (the bridge's watchdog, not an I/O error, notices a silent hand).
#[derive(Debug)]
pub struct InProcessTransport {
    tx: Sender<Received>,
    rx: Receiver<Received>,
}

impl InProcessTransport {
    pub fn pair() -> (Self, Self) {
        let (a_tx, b_rx) = channel();
        let (b_tx, a_rx) = channel();
        (Self { tx: a_tx, rx: a_rx }, Self { tx: b_tx, rx: b_rx })
    }

    /// Sends something that is not a valid protocol frame (for fault-injection tests).
    pub fn send_malformed(&mut self, id: u32, len: usize) -> Result<(), TransportError> {
        let _ = self.tx.send(Received::Malformed { id, len });
        Ok(())
    }
}

impl Transport for InProcessTransport {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError> {
        let _ = self.tx.send(Received::Frame(*frame));
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
        if timeout.is_zero() {
            return match self.rx.try_recv() {
                Ok(r) => Ok(Some(r)),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => Ok(None),
            };
        }
        match self.rx.recv_timeout(timeout) {
            Ok(r) => Ok(Some(r)),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            // Nothing can arrive any more: wait out the timeout as a silent bus would.
            Err(RecvTimeoutError::Disconnected) => {
                std::thread::sleep(timeout);
                Ok(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_process_pair_is_full_duplex_and_silent_after_hangup() {
        let (mut a, mut b) = InProcessTransport::pair();
        let f = RawFrame { id: 0x101, data: [1; 8] };
        a.send(&f).expect("send");
        assert_eq!(b.recv(Duration::ZERO).expect("recv"), Some(Received::Frame(f)));
        assert_eq!(b.recv(Duration::from_millis(1)).expect("recv"), None);
        b.send_malformed(0x1234_5678, 3).expect("send");
        assert_eq!(
            a.recv(Duration::ZERO).expect("recv"),
            Some(Received::Malformed { id: 0x1234_5678, len: 3 })
        );
        drop(b);
        assert_eq!(a.recv(Duration::ZERO).expect("recv"), None);
        a.send(&f).expect("a send nobody hears is not an error on a bus");
    }
}
