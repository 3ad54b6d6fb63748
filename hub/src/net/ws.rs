//! FlowProtocol over WebSocket on the HTTP port: binary messages carry frame bytes. A WebSocket-level violation (a
//! text message, an oversized message) ends the connection as a misbehaving client's, and the close frame says
//! why with its code, as the page's `/link` does.

use std::io;
use std::sync::{Arc, Mutex, PoisonError};

use axum::extract::ws::{CloseFrame, Message, WebSocket};
use bytes::{Bytes, BytesMut};
use flow::transport::{Transport, TransportRead, TransportWrite, WS_MESSAGE_MAX};
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};

/// A server-side WebSocket connection at `/flow`.
#[derive(Debug)]
pub struct WsServerTransport {
    socket: WebSocket,
    peer: String,
}

impl WsServerTransport {
    pub fn new(socket: WebSocket, peer: String) -> Self {
        WsServerTransport { socket, peer }
    }
}

/// Why the reader gave up, for the writer's close frame: (code, reason).
type CloseReason = Arc<Mutex<Option<(u16, &'static str)>>>;

/// Close code 1003: a data type the endpoint does not accept (text on a binary protocol).
const UNSUPPORTED_DATA: u16 = 1003;
/// Close code 1009: a message too big to process.
const TOO_BIG: u16 = 1009;
/// Close code 1002: a WebSocket protocol error.
const PROTOCOL_ERROR: u16 = 1002;

/// Receiving half.
#[derive(Debug)]
pub struct WsReader {
    stream: SplitStream<WebSocket>,
    close: CloseReason,
}

/// Sending half.
#[derive(Debug)]
pub struct WsWriter {
    sink: SplitSink<WebSocket, Message>,
    close: CloseReason,
}

impl WsReader {
    /// Notes the close frame the writer sends and returns the error that ends the connection as a violation.
    fn violation(&self, code: u16, reason: &'static str) -> io::Error {
        *self.close.lock().unwrap_or_else(PoisonError::into_inner) = Some((code, reason));
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{reason} (closed with {code})"),
        )
    }
}

impl Transport for WsServerTransport {
    type Reader = WsReader;
    type Writer = WsWriter;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (WsReader, WsWriter) {
        let (sink, stream) = self.socket.split();
        let close = CloseReason::default();
        (
            WsReader {
                stream,
                close: close.clone(),
            },
            WsWriter { sink, close },
        )
    }
}

impl TransportRead for WsReader {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        loop {
            match self.stream.next().await {
                None | Some(Ok(Message::Close(_))) => return Ok(0),
                Some(Ok(Message::Binary(data))) => {
                    if data.is_empty() {
                        continue;
                    }
                    buf.extend_from_slice(&data);
                    return Ok(data.len());
                }
                Some(Ok(Message::Ping(_) | Message::Pong(_))) => continue,
                Some(Ok(Message::Text(_))) => {
                    return Err(self.violation(UNSUPPORTED_DATA, "text message on the flow link"));
                }
                Some(Err(e)) => {
                    let text = e.to_string();
                    // tungstenite reports an oversized message as a capacity error.
                    return Err(
                        if text.contains("too long") || text.contains("Space limit") {
                            self.violation(TOO_BIG, "message larger than the flow link accepts")
                        } else if text.contains("Protocol") || text.contains("protocol") {
                            self.violation(PROTOCOL_ERROR, "WebSocket protocol violation")
                        } else {
                            io::Error::other(e)
                        },
                    );
                }
            }
        }
    }
}

impl TransportWrite for WsWriter {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        // Clients accept messages of at most WS_MESSAGE_MAX bytes; the byte stream is cut to fit.
        for piece in data.chunks(WS_MESSAGE_MAX) {
            self.sink
                .feed(Message::Binary(Bytes::copy_from_slice(piece)))
                .await
                .map_err(io::Error::other)?;
        }
        self.sink.flush().await.map_err(io::Error::other)
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        let why = *self.close.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((code, reason)) = why {
            let frame = CloseFrame {
                code,
                reason: reason.into(),
            };
            let _ = self.sink.send(Message::Close(Some(frame))).await;
        }
        self.sink.close().await.map_err(io::Error::other)
    }
}
