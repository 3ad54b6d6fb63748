//! One transport trait, one module per transport: TCP, Unix socket, WebSocket
//! and an in-process pipe all carry the same FlowProtocol frames.
//!
//! A transport only moves bytes; framing lives in [`crate::connection`]. Byte
//! streams (TCP, Unix, the in-process pipe) hand over whatever arrived; the
//! WebSocket transport hands over each binary message's bytes in order, so one
//! message may hold several frames or part of one.

use std::future::Future;
use std::io;

use bytes::{Bytes, BytesMut};

pub mod addr;
pub mod memory;
pub mod stream;
pub mod tcp;
pub mod unix;
pub mod ws;

pub use addr::FlowAddr;

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
    fn split(self) -> (Self::Reader, Self::Writer);
}

/// The receiving half.
pub trait TransportRead: Send + 'static {
    /// Appends the next received bytes to `buf`; `Ok(0)` means the peer closed.
    fn read_into(&mut self, buf: &mut BytesMut) -> impl Future<Output = io::Result<usize>> + Send;
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
    /// Closes the sending direction after flushing.
    fn shutdown(&mut self) -> impl Future<Output = io::Result<()>> + Send;
}

/// Any client-side transport, chosen at run time from a [`FlowAddr`].
#[derive(Debug)]
pub enum Link {
    Tcp(tcp::TcpTransport),
    Unix(unix::UnixTransport),
    Ws(Box<ws::WsClientTransport>),
    Memory(memory::MemoryTransport),
}

/// Reading half of a [`Link`].
#[derive(Debug)]
pub enum LinkReader {
    Tcp(<tcp::TcpTransport as Transport>::Reader),
    Unix(<unix::UnixTransport as Transport>::Reader),
    Ws(<ws::WsClientTransport as Transport>::Reader),
    Memory(<memory::MemoryTransport as Transport>::Reader),
}

/// Writing half of a [`Link`].
#[derive(Debug)]
pub enum LinkWriter {
    Tcp(<tcp::TcpTransport as Transport>::Writer),
    Unix(<unix::UnixTransport as Transport>::Writer),
    Ws(<ws::WsClientTransport as Transport>::Writer),
    Memory(<memory::MemoryTransport as Transport>::Writer),
}

impl Link {
    /// Opens a connection to `addr`.
    pub async fn connect(addr: &FlowAddr) -> io::Result<Link> {
        Ok(match addr {
            FlowAddr::Tcp(hostport) => Link::Tcp(tcp::TcpTransport::connect(hostport).await?),
            FlowAddr::Unix(path) => Link::Unix(unix::UnixTransport::connect(path).await?),
            FlowAddr::Ws(url) => Link::Ws(Box::new(ws::WsClientTransport::connect(url).await?)),
        })
    }
}

impl Transport for Link {
    type Reader = LinkReader;
    type Writer = LinkWriter;

    fn peer(&self) -> String {
        match self {
            Link::Tcp(t) => t.peer(),
            Link::Unix(t) => t.peer(),
            Link::Ws(t) => t.peer(),
            Link::Memory(t) => t.peer(),
        }
    }

    fn split(self) -> (LinkReader, LinkWriter) {
        match self {
            Link::Tcp(t) => {
                let (r, w) = t.split();
                (LinkReader::Tcp(r), LinkWriter::Tcp(w))
            }
            Link::Unix(t) => {
                let (r, w) = t.split();
                (LinkReader::Unix(r), LinkWriter::Unix(w))
            }
            Link::Ws(t) => {
                let (r, w) = (*t).split();
                (LinkReader::Ws(r), LinkWriter::Ws(w))
            }
            Link::Memory(t) => {
                let (r, w) = t.split();
                (LinkReader::Memory(r), LinkWriter::Memory(w))
            }
        }
    }
}

impl TransportRead for LinkReader {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        match self {
            LinkReader::Tcp(r) => r.read_into(buf).await,
            LinkReader::Unix(r) => r.read_into(buf).await,
            LinkReader::Ws(r) => r.read_into(buf).await,
            LinkReader::Memory(r) => r.read_into(buf).await,
        }
    }
}

impl TransportWrite for LinkWriter {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        match self {
            LinkWriter::Tcp(w) => w.write_all(data).await,
            LinkWriter::Unix(w) => w.write_all(data).await,
            LinkWriter::Ws(w) => w.write_all(data).await,
            LinkWriter::Memory(w) => w.write_all(data).await,
        }
    }

    async fn write_all_chunks(&mut self, chunks: &mut [Bytes]) -> io::Result<()> {
        match self {
            LinkWriter::Tcp(w) => w.write_all_chunks(chunks).await,
            LinkWriter::Unix(w) => w.write_all_chunks(chunks).await,
            LinkWriter::Ws(w) => w.write_all_chunks(chunks).await,
            LinkWriter::Memory(w) => w.write_all_chunks(chunks).await,
        }
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        match self {
            LinkWriter::Tcp(w) => w.shutdown().await,
            LinkWriter::Unix(w) => w.shutdown().await,
            LinkWriter::Ws(w) => w.shutdown().await,
            LinkWriter::Memory(w) => w.shutdown().await,
        }
    }
}
