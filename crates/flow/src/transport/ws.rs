//! WebSocket client transport: FlowProtocol bytes in binary messages.

use std::io;

use bytes::{Bytes, BytesMut};
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

use super::traits::{Transport, TransportRead, TransportWrite, WS_MESSAGE_MAX};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// A WebSocket connection to a hub's `/flow` endpoint.
#[derive(Debug)]
pub struct WsClientTransport {
    ws: Ws,
    peer: String,
}

impl WsClientTransport {
    pub async fn connect(url: &str) -> io::Result<Self> {
        let config = WebSocketConfig::default()
            .max_message_size(Some(WS_MESSAGE_MAX))
            .max_frame_size(Some(WS_MESSAGE_MAX));
        let (ws, _response) = tokio_tungstenite::connect_async_with_config(url, Some(config), true)
            .await
            .map_err(ws_error)?;
        Ok(WsClientTransport {
            ws,
            peer: url.to_string(),
        })
    }
}

/// Receiving half.
#[derive(Debug)]
pub struct WsReader(SplitStream<Ws>);

/// Sending half.
#[derive(Debug)]
pub struct WsWriter(SplitSink<Ws, Message>);

impl Transport for WsClientTransport {
    type Reader = WsReader;
    type Writer = WsWriter;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (WsReader, WsWriter) {
        let (sink, stream) = self.ws.split();
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
                // Pings are answered by the library; pongs carry nothing for us.
                Some(Ok(Message::Ping(_) | Message::Pong(_) | Message::Frame(_))) => continue,
                Some(Ok(Message::Text(_))) => {
                    return Err(io::Error::new(
                        io::ErrorKind::InvalidData,
                        "text message on a flow link",
                    ));
                }
                Some(Err(e)) => return Err(ws_error(e)),
            }
        }
    }
}

impl TransportWrite for WsWriter {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        // The hub accepts messages of at most WS_MESSAGE_MAX bytes; the byte stream is cut to fit.
        for piece in data.chunks(WS_MESSAGE_MAX) {
            self.0
                .feed(Message::Binary(Bytes::copy_from_slice(piece)))
                .await
                .map_err(ws_error)?;
        }
        self.0.flush().await.map_err(ws_error)
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        self.0.close().await.map_err(ws_error)
    }
}

fn ws_error(e: tokio_tungstenite::tungstenite::Error) -> io::Error {
    use tokio_tungstenite::tungstenite::Error;
    match e {
        Error::Io(e) => e,
        Error::ConnectionClosed | Error::AlreadyClosed => io::ErrorKind::ConnectionReset.into(),
        other => io::Error::other(other.to_string()),
    }
}
