//! The raw-TCP baseline, as hub-bench's: one writer writing each length-prefixed payload to N loopback sockets
//! in turn, N reader tasks that read each payload whole and touch it. No hub, no protocol: what the kernel's
//! socket copies cost on their own.

use std::sync::Arc;

use tokio::io::{AsyncReadExt, AsyncWriteExt, BufReader, BufWriter};
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinHandle;

use crate::stamp;
use crate::tally::Tally;

/// The writer's ends of the sockets, with the readers running.
#[derive(Debug)]
pub struct RawRig {
    sockets: Vec<BufWriter<TcpStream>>,
    readers: Vec<JoinHandle<()>>,
    frame: Vec<u8>,
}

/// Connects `n` loopback socket pairs and starts a reader on each.
pub async fn connect(n: usize, tally: Arc<Tally>) -> anyhow::Result<RawRig> {
    let listener = TcpListener::bind(("127.0.0.1", 0)).await?;
    let addr = listener.local_addr()?;
    let mut sockets = Vec::new();
    let mut readers = Vec::new();
    for i in 0..n {
        let reader = TcpStream::connect(addr).await?;
        let (writer, _) = listener.accept().await?;
        // As on the hub's sockets: frames are written whole, so Nagle only adds delay.
        writer.set_nodelay(true)?;
        reader.set_nodelay(true)?;
        sockets.push(BufWriter::with_capacity(64 * 1024, writer));
        let tally = tally.clone();
        readers.push(tokio::spawn(async move {
            let mut reader = BufReader::with_capacity(64 * 1024, reader);
            let mut payload = Vec::new();
            while let Ok(len) = reader.read_u32_le().await {
                payload.resize(len as usize, 0);
                if reader.read_exact(&mut payload).await.is_err() {
                    break;
                }
                tally.record(i, &payload);
            }
            tally.end(i);
        }));
    }
    Ok(RawRig {
        sockets,
        readers,
        frame: Vec::new(),
    })
}

impl RawRig {
    /// Writes `template`, stamped and preceded by its `u32 LE` length, to every socket.
    pub async fn send(&mut self, template: &[u8], seq: u64) -> anyhow::Result<()> {
        let len = u32::try_from(template.len())?;
        self.frame.clear();
        self.frame.extend_from_slice(&len.to_le_bytes());
        self.frame.extend_from_slice(template);
        stamp::write(&mut self.frame[4..], seq);
        for socket in &mut self.sockets {
            socket.write_all(&self.frame).await?;
        }
        Ok(())
    }

    /// Pushes out what the writers buffer (small frames are batched, as the SDK batches them).
    pub async fn flush(&mut self) -> anyhow::Result<()> {
        for socket in &mut self.sockets {
            socket.flush().await?;
        }
        Ok(())
    }

    pub fn close(self) {
        for task in &self.readers {
            task.abort();
        }
    }
}
