//! The raw-TCP baseline's sockets, shared by hub-bench and shm-bench: N loopback pairs, the writer's ends kept, a
//! reader task on each that reads every `u32 LE`-length-prefixed payload whole and hands it to the bench's tally.
//! No hub, no protocol: what the kernel's socket copies cost on their own.

use std::sync::Arc;

use tokio::io::{AsyncReadExt, BufReader, BufWriter};
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinHandle;

/// What a reader hands each payload to (a bench's tally of deliveries).
pub trait Receiver: Send + Sync + 'static {
    /// Subscriber `sub` received `payload`.
    fn record(&self, sub: usize, payload: &[u8]);
    /// Subscriber `sub`'s socket ended.
    fn end(&self, sub: usize);
}

/// Connects `n` loopback socket pairs and starts a reader on each; returns the writers' ends (buffered, 64 KB) and
/// the readers.
pub async fn connect<R: Receiver>(
    n: usize,
    receiver: Arc<R>,
) -> anyhow::Result<(Vec<BufWriter<TcpStream>>, Vec<JoinHandle<()>>)> {
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
        let receiver = receiver.clone();
        readers.push(tokio::spawn(async move {
            let mut reader = BufReader::with_capacity(64 * 1024, reader);
            let mut payload = Vec::new();
            while let Ok(len) = reader.read_u32_le().await {
                payload.resize(len as usize, 0);
                if reader.read_exact(&mut payload).await.is_err() {
                    break;
                }
                receiver.record(i, &payload);
            }
            receiver.end(i);
        }));
    }
    Ok((sockets, readers))
}
