//! The transport traits every transport implements, and the WebSocket message cap. A leaf, so that each transport
//! (`tcp.rs`, `unix.rs`, `ws.rs`, `memory.rs`, `stream.rs`) and the run-time choice among them (`mod.rs`) share it
//! without a cycle.

use std::future::Future;
use std::io;
use std::os::fd::{BorrowedFd, OwnedFd};

use bytes::{Bytes, BytesMut};

/// The largest WebSocket message either side of a `/flow` link sends or accepts. FlowProtocol over WebSocket is a
/// byte stream cut into binary messages, so a large frame travels as several messages; the cap keeps what a peer
/// can make the other side buffer before a single frame is checked small (WebSocket libraries collect a whole
/// message before handing it over).
pub const WS_MESSAGE_MAX: usize = 256 * 1024;

/// A bidirectional link that can be split into independent halves, so that
/// reading and writing run in separate tasks.
pub trait Transport: Send + 'static {
    type Reader: TransportRead;
    type Writer: TransportWrite;
    /// Who is on the other side, for logs.
    fn peer(&self) -> String;
    /// Whether descriptors can travel beside the bytes (a Unix socket): what shared memory needs.
    fn passes_fds(&self) -> bool {
        false
    }
    fn split(self) -> (Self::Reader, Self::Writer);
}

/// The receiving half.
pub trait TransportRead: Send + 'static {
    /// Appends the next received bytes to `buf`; `Ok(0)` means the peer closed.
    fn read_into(&mut self, buf: &mut BytesMut) -> impl Future<Output = io::Result<usize>> + Send;
    /// The next `len` bytes as one shared buffer, when the transport received them so (an in-process link whose
    /// writer handed a payload over); `None` otherwise, with nothing consumed, and the bytes are then read with
    /// [`TransportRead::read_into`]. Byte streams never hold such buffers: the default is `None` at once.
    fn take_exact(&mut self, len: usize) -> impl Future<Output = io::Result<Option<Bytes>>> + Send {
        let _ = len;
        async { Ok(None) }
    }
    /// The oldest descriptor received beside the bytes and not taken yet (a Unix socket's `SCM_RIGHTS`, which a
    /// client's link keeps for the frame that introduces a shared-memory segment); `None` on every other transport.
    fn take_fd(&mut self) -> Option<OwnedFd> {
        None
    }
}

/// The sending half.
pub trait TransportWrite: Send + 'static {
    /// Sends all of `data` (one or more whole frames).
    fn write_all(&mut self, data: &[u8]) -> impl Future<Output = io::Result<()>> + Send;
    /// Sends `chunks` in order as if they were one buffer (together one or
    /// more whole frames). This default joins them and makes one
    /// [`TransportWrite::write_all`], so a message-based transport still sends
    /// one message per flush; byte streams override it with vectored writes,
    /// so that large payloads go out from their shared buffers uncopied.
    /// The chunks may be left partly consumed.
    fn write_all_chunks(
        &mut self,
        chunks: &mut [Bytes],
    ) -> impl Future<Output = io::Result<()>> + Send {
        async move {
            match chunks {
                [] => Ok(()),
                [one] => self.write_all(one).await,
                many => self.write_all(&many.concat()).await,
            }
        }
    }
    /// Sends `data` (whole frames) with `fd` beside its first byte; only a Unix socket can.
    fn send_with_fd(
        &mut self,
        data: &[u8],
        fd: BorrowedFd<'_>,
    ) -> impl Future<Output = io::Result<()>> + Send {
        let _ = (data, fd);
        async {
            Err(io::Error::new(
                io::ErrorKind::Unsupported,
                "only a Unix socket passes descriptors",
            ))
        }
    }
    /// Closes the sending direction after flushing.
    fn shutdown(&mut self) -> impl Future<Output = io::Result<()>> + Send;
}
