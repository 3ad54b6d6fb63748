//! A FlowProtocol connection driven by hand over TCP, for tests that must send
//! what the SDK never would (malformed frames, commands before login) or must
//! control exactly when bytes are read.

use std::net::SocketAddr;
use std::time::Duration;

use anyhow::{Context, bail};
use bytes::BytesMut;
use flow::connection::FrameReader;
use flow::protocol::{
    Command, DEFAULT_MAX_FRAME, Envelope, Event, PROTOCOL_VERSION, Reply, decode_event,
    encode_command,
};
use flow::transport::stream::StreamReader;
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};

/// How a connection ended when the test waited for it to close.
#[derive(Debug)]
pub struct Closed {
    /// Events received before the end.
    pub events: Vec<Event>,
}

/// A raw TCP FlowProtocol connection.
#[derive(Debug)]
pub struct RawConn {
    reader: FrameReader<StreamReader<OwnedReadHalf>>,
    writer: OwnedWriteHalf,
    next_req: u32,
}

impl RawConn {
    pub async fn connect(addr: SocketAddr) -> anyhow::Result<RawConn> {
        let stream = TcpStream::connect(addr).await.context("connecting")?;
        stream.set_nodelay(true)?;
        let (r, w) = stream.into_split();
        Ok(RawConn {
            reader: FrameReader::new(StreamReader(r), DEFAULT_MAX_FRAME),
            writer: w,
            next_req: 1,
        })
    }

    /// Connects and logs in with `token`, synchronously or not.
    pub async fn login(
        addr: SocketAddr,
        token: &str,
        asynchronous: bool,
    ) -> anyhow::Result<RawConn> {
        let mut conn = Self::connect(addr).await?;
        let reply = conn
            .request(Command::Login {
                version: PROTOCOL_VERSION,
                token: token.into(),
                name: "raw".into(),
            })
            .await?;
        if !matches!(reply, Ok(Reply::LoginOk { .. })) {
            bail!("login refused: {reply:?}");
        }
        if asynchronous {
            conn.request(Command::SetAsync)
                .await?
                .map_err(|e| anyhow::anyhow!("set async: {e}"))?;
        }
        Ok(conn)
    }

    /// Sends bytes exactly as given.
    pub async fn send_bytes(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        self.writer.write_all(bytes).await.context("sending")?;
        Ok(())
    }

    /// Closes the sending direction, as a peer that stops in the middle of a frame does.
    pub async fn shutdown_write(&mut self) -> anyhow::Result<()> {
        self.writer.shutdown().await.context("shutting down")?;
        Ok(())
    }

    /// Sends a command with a fresh request id and returns the id.
    pub async fn send(&mut self, command: Command) -> anyhow::Result<u32> {
        let req = self.next_req;
        self.next_req += 1;
        let mut buf = BytesMut::new();
        encode_command(&Envelope { req, command }, &mut buf);
        self.send_bytes(&buf).await?;
        Ok(req)
    }

    /// The next event, or `None` if the hub closed the connection.
    pub async fn next_event(&mut self, timeout: Duration) -> anyhow::Result<Option<Event>> {
        let frame = tokio::time::timeout(timeout, self.reader.read_frame())
            .await
            .context("no event in time")?;
        match frame {
            Ok(Some(raw)) => Ok(Some(decode_event(raw)?)),
            Ok(None) => Ok(None),
            // A reset after the hub closed its side is a close too.
            Err(_) => Ok(None),
        }
    }

    /// Sends a command and waits for its reply, skipping other events.
    pub async fn request(
        &mut self,
        command: Command,
    ) -> anyhow::Result<Result<Reply, flow::protocol::ErrorReply>> {
        let req = self.send(command).await?;
        // One deadline for the reply, however many other events (data of a subscription) come first.
        let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
        let mut skipped = 0usize;
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            if left.is_zero() {
                bail!("no reply to request {req} within 10 s ({skipped} other event(s) came)");
            }
            match self.next_event(left).await.with_context(|| {
                format!("no reply to request {req} within 10 s ({skipped} other event(s) came)")
            })? {
                Some(Event::Reply { req: r, result }) if r == req => return Ok(result),
                Some(_) => skipped += 1,
                None => bail!("connection closed before the reply to request {req}"),
            }
        }
    }

    /// Reads until the hub closes the connection; fails if it stays open.
    pub async fn expect_closed(&mut self, timeout: Duration) -> anyhow::Result<Closed> {
        let mut events = Vec::new();
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            if left.is_zero() {
                bail!("the hub kept the connection open past {timeout:?}; events: {events:?}");
            }
            match self.next_event(left).await {
                Ok(Some(e)) => events.push(e),
                Ok(None) => return Ok(Closed { events }),
                Err(e) => bail!("the hub kept the connection open: {e}; events: {events:?}"),
            }
        }
    }
}
