//! How frames reach the hand: SocketCAN on a real (or virtual) bus, or an in-process channel
//! pair for unit tests and timing benchmarks.

use std::collections::VecDeque;
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, TryRecvError, channel};
use std::time::Duration;

use socketcan::{
    CanAnyFrame, CanFdFrame, CanFdSocket, CanFilter, CanFrame, CanSocket, EmbeddedFrame, Frame, Socket,
    SocketOptions, StandardId,
};
use thiserror::Error;

use crate::protocol::fd::{FdMessage, FdPacker};
use crate::protocol::{Message, RawFrame, filters};
use crate::socketcan_io::{FrameError, standard_id_and_data, to_can_frame};

#[derive(Debug, Error)]
pub enum TransportError {
    #[error("CAN socket")]
    Io(#[from] std::io::Error),
    /// The interface's transmit queue is full (ENOBUFS, or EAGAIN on the non-blocking
    /// socket): the frame was not sent. The bus is overloaded or the controller cannot get
    /// on it (bus-off); the caller decides whether to retry, hold or halt.
    #[error("CAN transmit queue full (ENOBUFS): frame {id:#05x} not sent")]
    TxQueueFull { id: u16 },
    #[error(transparent)]
    Frame(#[from] FrameError),
}

/// A received frame that is not a standard 8-byte data frame, kept for the statistics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Received {
    Frame(RawFrame),
    /// An extended-id, remote or short frame: counted and ignored by the bridge.
    Malformed {
        id: u32,
        len: usize,
    },
    /// A SocketCAN error frame: `class` is its error-class bits (`CAN_ERR_*` of
    /// linux/can/error.h, e.g. 0x40 bus-off), see [`ErrorClass`].
    Error {
        class: u32,
    },
}

/// Which frames a socket lets through (the kernel filters the rest, see
/// [`crate::protocol::filters`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The bridge: node frames and heartbeats, plus SocketCAN error frames.
    Host,
    /// The finger nodes (emulators): joint commands and the host's heartbeat.
    Nodes,
    /// Everything on the bus (tools and tests that watch it).
    Monitor,
}

/// SocketCAN error classes (`CAN_ERR_*` in linux/can/error.h).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorClass;

impl ErrorClass {
    pub const TX_TIMEOUT: u32 = 0x001;
    pub const LOST_ARBITRATION: u32 = 0x002;
    /// Controller problems: error-warning or error-passive state, buffer overflows.
    pub const CONTROLLER: u32 = 0x004;
    pub const PROTOCOL: u32 = 0x008;
    pub const TRANSCEIVER: u32 = 0x010;
    pub const NO_ACK: u32 = 0x020;
    pub const BUS_OFF: u32 = 0x040;
    pub const BUS_ERROR: u32 = 0x080;
    pub const RESTARTED: u32 = 0x100;
    /// Every class, for the socket's error filter.
    pub const ALL: u32 = 0x1FF;
}

/// Frames that crossed the wire, as opposed to protocol messages: with the CAN FD option one
/// bus frame carries up to five messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusCounts {
    pub frames_in: u64,
    pub frames_out: u64,
}

/// A full-duplex frame link to the hand.
pub trait Transport: Send {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError>;
    /// The next frame if one arrives within `timeout` (zero: only what is already queued).
    /// A signal interrupting the wait (Ctrl-C) returns `None`, so the caller can check its
    /// stop flag.
    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError>;
    /// Frames received and sent on the wire so far.
    fn bus_counts(&self) -> BusCounts;
}

/// Sets up a SocketCAN socket for `role`: non-blocking for good (a zero-timeout read is then
/// one `read` system call, no `fcntl` around it), the role's receive filters, and, for the
/// host, error frames of every class.
fn configure<S: Socket + SocketOptions>(socket: &S, role: Role) -> Result<(), TransportError> {
    socket.set_nonblocking(true)?;
    let as_filters =
        |f: &[(u32, u32)]| f.iter().map(|&(id, mask)| CanFilter::new(id, mask)).collect::<Vec<_>>();
    match role {
        Role::Host => {
            socket.set_filters(&as_filters(&filters::HOST_RX))?;
            socket.set_error_filter(ErrorClass::ALL)?;
        }
        Role::Nodes => socket.set_filters(&as_filters(&filters::NODE_RX))?,
        Role::Monitor => socket.set_filter_accept_all()?,
    }
    Ok(())
}

/// The next frame within `timeout`, `None` if none came or a signal interrupted the wait.
/// The socket is non-blocking: a zero timeout is one read; otherwise poll, then read.
fn read_frame<S: Socket>(socket: &S, timeout: Duration) -> Result<Option<S::FrameType>, TransportError> {
    let result = if timeout.is_zero() { socket.read_frame() } else { socket.read_frame_timeout(timeout) };
    match result {
        Ok(frame) => Ok(Some(frame)),
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock
                    | std::io::ErrorKind::TimedOut
                    | std::io::ErrorKind::Interrupted
            ) =>
        {
            Ok(None)
        }
        Err(e) => Err(e.into()),
    }
}

/// A failed write as a typed error: a full transmit queue is [`TransportError::TxQueueFull`].
fn write_error(e: std::io::Error, id: u16) -> TransportError {
    if e.raw_os_error() == Some(libc::ENOBUFS) || e.kind() == std::io::ErrorKind::WouldBlock {
        TransportError::TxQueueFull { id }
    } else {
        TransportError::Io(e)
    }
}

/// SocketCAN (classic frames) on an interface such as `can0` or `vcan0`.
#[derive(Debug)]
pub struct SocketCanTransport {
    socket: CanSocket,
    counts: BusCounts,
}

impl SocketCanTransport {
    pub fn open(iface: &str, role: Role) -> Result<Self, TransportError> {
        let socket = CanSocket::open(iface)?;
        configure(&socket, role)?;
        Ok(Self { socket, counts: BusCounts::default() })
    }
}

impl Transport for SocketCanTransport {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError> {
        self.socket.write_frame(&to_can_frame(frame)?).map_err(|e| write_error(e, frame.id))?;
        self.counts.frames_out += 1;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
        let Some(frame) = read_frame(&self.socket, timeout)? else { return Ok(None) };
        self.counts.frames_in += 1;
        if let CanFrame::Error(e) = &frame {
            return Ok(Some(Received::Error { class: e.error_bits() }));
        }
        Ok(Some(match standard_id_and_data(&frame) {
            Ok((id, data)) => match <[u8; 8]>::try_from(data) {
                Ok(data) => Received::Frame(RawFrame { id, data }),
                Err(_) => Received::Malformed { id: u32::from(id), len: data.len() },
            },
            Err(_) => Received::Malformed { id: frame.raw_id(), len: EmbeddedFrame::dlc(&frame) },
        }))
    }

    fn bus_counts(&self) -> BusCounts {
        self.counts
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
    counts: BusCounts,
}

impl FdSocketCanTransport {
    /// Opens `iface`, which must have an FD-capable MTU (72; vcan's default).
    pub fn open(iface: &str, role: Role) -> Result<Self, TransportError> {
        let socket = CanFdSocket::open(iface)?;
        configure(&socket, role)?;
        Ok(Self { socket, packer: FdPacker::default(), inbox: VecDeque::new(), counts: BusCounts::default() })
    }

    fn write_fd(&mut self, fd: &FdMessage) -> Result<(), TransportError> {
        let raw = fd.encode().map_err(|_| FrameError::IdTooLarge(0))?;
        let id = StandardId::new(raw.id).ok_or(FrameError::IdTooLarge(raw.id))?;
        let frame = CanFdFrame::new(id, raw.payload()).ok_or(FrameError::IdTooLarge(raw.id))?;
        self.socket.write_frame(&frame).map_err(|e| write_error(e, raw.id))?;
        self.counts.frames_out += 1;
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
                self.socket.write_frame(&to_can_frame(frame)?).map_err(|e| write_error(e, frame.id))?;
                self.counts.frames_out += 1;
                Ok(())
            }
        }
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
        if let Some(r) = self.inbox.pop_front() {
            return Ok(Some(r));
        }
        let Some(frame) = read_frame(&self.socket, timeout)? else { return Ok(None) };
        self.counts.frames_in += 1;
        let received = match frame {
            CanAnyFrame::Fd(fd) => match (fd.id(), FdMessage::decode(standard_raw(&fd), fd.data())) {
                (socketcan::Id::Standard(_), Ok(message)) => {
                    // Decoded counts always encode again (the fields' ranges are the whole
                    // integer ranges); were one not to, the frame is counted, not lost.
                    for m in message.to_classic() {
                        self.inbox.push_back(match m.encode() {
                            Ok(raw) => Received::Frame(raw),
                            Err(_) => Received::Malformed { id: fd.raw_id(), len: fd.data().len() },
                        });
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
            CanAnyFrame::Error(f) => Received::Error { class: f.error_bits() },
        };
        Ok(Some(received))
    }

    fn bus_counts(&self) -> BusCounts {
        self.counts
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
    counts: BusCounts,
}

impl InProcessTransport {
    pub fn pair() -> (Self, Self) {
        let (a_tx, b_rx) = channel();
        let (b_tx, a_rx) = channel();
        (
            Self { tx: a_tx, rx: a_rx, counts: BusCounts::default() },
            Self { tx: b_tx, rx: b_rx, counts: BusCounts::default() },
        )
    }

    /// Sends something that is not a valid protocol frame, or an error frame (for
    /// fault-injection tests).
    pub fn send_received(&mut self, received: Received) -> Result<(), TransportError> {
        let _ = self.tx.send(received);
        Ok(())
    }
}

impl Transport for InProcessTransport {
    fn send(&mut self, frame: &RawFrame) -> Result<(), TransportError> {
        let _ = self.tx.send(Received::Frame(*frame));
        self.counts.frames_out += 1;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
        let received = self.recv_inner(timeout);
        if let Ok(Some(_)) = received {
            self.counts.frames_in += 1;
        }
        received
    }

    fn bus_counts(&self) -> BusCounts {
        self.counts
    }
}

impl InProcessTransport {
    fn recv_inner(&mut self, timeout: Duration) -> Result<Option<Received>, TransportError> {
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
        b.send_received(Received::Malformed { id: 0x1234_5678, len: 3 }).expect("send");
        assert_eq!(
            a.recv(Duration::ZERO).expect("recv"),
            Some(Received::Malformed { id: 0x1234_5678, len: 3 })
        );
        drop(b);
        assert_eq!(a.recv(Duration::ZERO).expect("recv"), None);
        a.send(&f).expect("a send nobody hears is not an error on a bus");
        assert_eq!(a.bus_counts(), BusCounts { frames_in: 1, frames_out: 2 });
    }
}
