//! One struct per direction owning a transport half and its buffer: frames in,
//! frames out. Framing rules live in [`crate::protocol::frame`]; this is only
//! the loop that feeds bytes to them.

use std::io;

use bytes::BytesMut;
use thiserror::Error;

use crate::protocol::frame::{self, Check, RawFrame};
use crate::protocol::{FrameError, codec};
use crate::transport::{Transport, TransportRead, TransportWrite};

/// Why reading or writing frames stopped.
#[derive(Debug, Error)]
pub enum ConnError {
    #[error("i/o: {0}")]
    Io(#[from] io::Error),
    #[error("bad frame: {0}")]
    Frame(#[from] FrameError),
    #[error("peer closed the connection in the middle of a frame")]
    TruncatedFrame,
}

/// Reads whole frames from a transport.
#[derive(Debug)]
pub struct FrameReader<R> {
    io: R,
    buf: BytesMut,
    max_frame: usize,
}

impl<R: TransportRead> FrameReader<R> {
    pub fn new(io: R, max_frame: usize) -> Self {
        FrameReader {
            io,
            buf: BytesMut::with_capacity(64 * 1024),
            max_frame,
        }
    }

    /// The next frame, or `None` when the peer closed cleanly between frames.
    pub async fn read_frame(&mut self) -> Result<Option<RawFrame>, ConnError> {
        loop {
            if let Some(frame) = self.parse_buffered()? {
                return Ok(Some(frame));
            }
            if self.io.read_into(&mut self.buf).await? == 0 {
                return if self.buf.is_empty() {
                    Ok(None)
                } else {
                    Err(ConnError::TruncatedFrame)
                };
            }
        }
    }

    /// A frame already in the buffer, if any; never waits.
    pub fn parse_buffered(&mut self) -> Result<Option<RawFrame>, FrameError> {
        match frame::check(&self.buf, self.max_frame)? {
            Check::Complete(total) => Ok(Some(frame::parse(&mut self.buf, total))),
            Check::Incomplete(total) => {
                // The length was checked against the maximum, so this reservation is bounded.
                self.buf.reserve(total.saturating_sub(self.buf.len()));
                Ok(None)
            }
        }
    }
}

/// Encodes frames into a buffer and writes them out in batches.
#[derive(Debug)]
pub struct FrameWriter<W> {
    io: W,
    buf: BytesMut,
}

impl<W: TransportWrite> FrameWriter<W> {
    pub fn new(io: W) -> Self {
        FrameWriter {
            io,
            buf: BytesMut::with_capacity(64 * 1024),
        }
    }

    /// The pending output buffer, for encoders to append frames to.
    pub fn buffer(&mut self) -> &mut BytesMut {
        &mut self.buf
    }

    pub fn queue_event(&mut self, event: &crate::protocol::Event) {
        codec::encode_event(event, &mut self.buf);
    }

    pub fn queue_command(&mut self, env: &crate::protocol::Envelope) {
        codec::encode_command(env, &mut self.buf);
    }

    /// Bytes waiting to be written.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// Writes everything queued.
    pub async fn flush(&mut self) -> io::Result<()> {
        if !self.buf.is_empty() {
            self.io.write_all(&self.buf).await?;
            self.buf.clear();
        }
        Ok(())
    }

    pub async fn shutdown(&mut self) -> io::Result<()> {
        self.flush().await?;
        self.io.shutdown().await
    }
}

/// A transport with its framing state in both directions.
#[derive(Debug)]
pub struct Connection<T: Transport> {
    pub peer: String,
    pub reader: FrameReader<T::Reader>,
    pub writer: FrameWriter<T::Writer>,
}

impl<T: Transport> Connection<T> {
    pub fn new(transport: T, max_frame: usize) -> Self {
        let peer = transport.peer();
        let (r, w) = transport.split();
        Connection {
            peer,
            reader: FrameReader::new(r, max_frame),
            writer: FrameWriter::new(w),
        }
    }
}
