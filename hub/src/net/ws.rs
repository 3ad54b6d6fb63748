//! FlowProtocol over WebSocket on the HTTP port: binary messages carry frame bytes.

use std::io;

use axum::extract::ws::{Message, WebSocket};
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

/// Receiving half.
#[derive(Debug)]
pub struct WsReader(SplitStream<WebSocket>);

/// Sending half.
#[derive(Debug)]
pub struct WsWriter(SplitSink<WebSocket, Message>);

impl Transport for WsServerTransport {
    type Reader = WsReader;
    type Writer = WsWriter;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (WsReader, WsWriter) {
        let (sink, stream) = self.socket.split();
        (WsReader(stream), WsWriter(sink))
    }
}

impl TransportRead for WsReader {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        loop {
            match self.0.next().await {
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
                    return Err(io::Error::new(
                        io::ErrorKind::InvalidData,
                        "text message on the flow link",
                    ));
                }
                Some(Err(e)) => return Err(io::Error::other(e)),
            }
        }
    }
}

impl TransportWrite for WsWriter {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        // Clients accept messages of at most WS_MESSAGE_MAX bytes; the byte stream is cut to fit.
        for piece in data.chunks(WS_MESSAGE_MAX) {
            self.0
                .feed(Message::Binary(Bytes::copy_from_slice(piece)))
                .await
                .map_err(io::Error::other)?;
        }
        self.0.flush().await.map_err(io::Error::other)
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        self.0.close().await.map_err(io::Error::other)
    }
}
