//! The raw-TCP baseline, as hub-bench's: one writer writing each length-prefixed payload to N loopback sockets
//! in turn, N reader tasks that read each payload whole and touch it. No hub, no protocol: what the kernel's
//! socket copies cost on their own.

use std::sync::Arc;

use tokio::io::{AsyncWriteExt, BufWriter};
use tokio::net::TcpStream;
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
    let (sockets, readers) = agent_bench::raw_tcp::connect(n, tally).await?;
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
