//! One transport trait, one module per transport: TCP, Unix socket, WebSocket,
//! a serial line, UDP and an in-process pipe all carry the same FlowProtocol frames.
//!
//! A transport only moves bytes; framing lives in [`crate::connection`]. Byte
//! streams (TCP, Unix, the in-process pipe) hand over whatever arrived; the
//! WebSocket transport hands over each binary message's bytes in order, so one
//! message may hold several frames or part of one; a serial line hands over the
//! whole frames of each intact packet (`serial.rs`), and UDP the whole frames its session delivers
//! (`udp/`).

use std::io;

use bytes::{Bytes, BytesMut};

pub mod addr;
pub mod memory;
pub mod serial;
pub mod stream;
pub mod tcp;
mod traits;
pub mod udp;
pub mod unix;
pub mod ws;

pub use addr::FlowAddr;
pub use traits::{Transport, TransportRead, TransportWrite, WS_MESSAGE_MAX};

/// Any client-side transport, chosen at run time from a [`FlowAddr`].
#[derive(Debug)]
pub enum Link {
    Tcp(tcp::TcpTransport),
    Unix(unix::UnixTransport),
    Ws(Box<ws::WsClientTransport>),
    Memory(memory::MemoryTransport),
    Serial(serial::SerialTransport),
    Udp(Box<udp::UdpTransport>),
}

/// Reading half of a [`Link`].
#[derive(Debug)]
pub enum LinkReader {
    Tcp(<tcp::TcpTransport as Transport>::Reader),
    Unix(<unix::UnixTransport as Transport>::Reader),
    Ws(<ws::WsClientTransport as Transport>::Reader),
    Memory(<memory::MemoryTransport as Transport>::Reader),
    Serial(<serial::SerialTransport as Transport>::Reader),
    Udp(<udp::UdpTransport as Transport>::Reader),
}

/// Writing half of a [`Link`].
#[derive(Debug)]
pub enum LinkWriter {
    Tcp(<tcp::TcpTransport as Transport>::Writer),
    Unix(<unix::UnixTransport as Transport>::Writer),
    Ws(<ws::WsClientTransport as Transport>::Writer),
    Memory(<memory::MemoryTransport as Transport>::Writer),
    Serial(<serial::SerialTransport as Transport>::Writer),
    Udp(<udp::UdpTransport as Transport>::Writer),
}

impl Link {
    /// Opens a connection to `addr`.
    pub async fn connect(addr: &FlowAddr) -> io::Result<Link> {
        Ok(match addr {
            FlowAddr::Tcp(hostport) => Link::Tcp(tcp::TcpTransport::connect(hostport).await?),
            FlowAddr::Unix(path) => Link::Unix(unix::UnixTransport::connect(path).await?),
            FlowAddr::Ws(url) => Link::Ws(Box::new(ws::WsClientTransport::connect(url).await?)),
            FlowAddr::Serial { path, baud } => {
                Link::Serial(serial::SerialTransport::open(path, *baud)?)
            }
            FlowAddr::Udp(hostport) => {
                Link::Udp(Box::new(udp::UdpTransport::connect(hostport).await?))
            }
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
            Link::Serial(t) => t.peer(),
            Link::Udp(t) => t.peer(),
        }
    }

    fn passes_fds(&self) -> bool {
        matches!(self, Link::Unix(_))
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
            Link::Serial(t) => {
                let (r, w) = t.split();
                (LinkReader::Serial(r), LinkWriter::Serial(w))
            }
            Link::Udp(t) => {
                let (r, w) = (*t).split();
                (LinkReader::Udp(r), LinkWriter::Udp(w))
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
            LinkReader::Serial(r) => r.read_into(buf).await,
            LinkReader::Udp(r) => r.read_into(buf).await,
        }
    }

    async fn take_exact(&mut self, len: usize) -> io::Result<Option<Bytes>> {
        match self {
            LinkReader::Memory(r) => r.take_exact(len).await,
            _ => Ok(None),
        }
    }

    fn take_fd(&mut self) -> Option<std::os::fd::OwnedFd> {
        match self {
            LinkReader::Unix(r) => r.take_fd(),
            _ => None,
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
            LinkWriter::Serial(w) => w.write_all(data).await,
            LinkWriter::Udp(w) => w.write_all(data).await,
        }
    }

    async fn write_all_chunks(&mut self, chunks: &mut [Bytes]) -> io::Result<()> {
        match self {
            LinkWriter::Tcp(w) => w.write_all_chunks(chunks).await,
            LinkWriter::Unix(w) => w.write_all_chunks(chunks).await,
            LinkWriter::Ws(w) => w.write_all_chunks(chunks).await,
            LinkWriter::Memory(w) => w.write_all_chunks(chunks).await,
            LinkWriter::Serial(w) => w.write_all_chunks(chunks).await,
            LinkWriter::Udp(w) => w.write_all_chunks(chunks).await,
        }
    }

    async fn send_with_fd(
        &mut self,
        data: &[u8],
        fd: std::os::fd::BorrowedFd<'_>,
    ) -> io::Result<()> {
        match self {
            LinkWriter::Unix(w) => w.send_with_fd(data, fd).await,
            _ => Err(io::Error::new(
                io::ErrorKind::Unsupported,
                "only a Unix socket passes descriptors",
            )),
        }
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        match self {
            LinkWriter::Tcp(w) => w.shutdown().await,
            LinkWriter::Unix(w) => w.shutdown().await,
            LinkWriter::Ws(w) => w.shutdown().await,
            LinkWriter::Memory(w) => w.shutdown().await,
            LinkWriter::Serial(w) => w.shutdown().await,
            LinkWriter::Udp(w) => w.shutdown().await,
        }
    }
}
