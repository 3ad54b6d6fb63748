//! Sending a session's burst of datagrams with as few system calls as the kernel allows: `sendmmsg` takes up to
//! [`MAX_BATCH`] datagrams in one call, so a 64 KB JPEG's 44 fragments cost one or two calls instead of 44 `sendto`.
//!
//! The socket's readiness stays tokio's (`try_io`), so a full send buffer waits like any other write. What a
//! datagram socket reports for one datagram (a full buffer after readiness, a route that comes and goes) loses that
//! datagram only, as a lost datagram on the wire would be: the lanes above send again what matters. A refused
//! connection (a connected socket heard that nobody listens any more) ends the session.

use std::io::{self, IoSlice};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};

use rustix::net::{MMsgHdr, SendAncillaryBuffer, SendFlags, SocketAddrAny};
use tokio::io::Interest;
use tokio::net::UdpSocket;

/// The most datagrams one call takes (the kernel's own cap is 1024).
pub const MAX_BATCH: usize = 64;

/// What sending a burst cost.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Sent {
    /// Datagrams handed to the kernel (or lost on the way, as above).
    pub datagrams: usize,
    /// System calls made.
    pub calls: usize,
}

/// Sends `datagrams` in order to `to` (or to the connected peer when `None`); fails only when the peer refused.
pub async fn send_all(
    socket: &UdpSocket,
    to: Option<SocketAddr>,
    datagrams: &[impl AsRef<[u8]>],
) -> io::Result<Sent> {
    let to = to.map(SocketAddrAny::from);
    let mut sent = Sent::default();
    while sent.datagrams < datagrams.len() {
        let rest = &datagrams[sent.datagrams..datagrams.len().min(sent.datagrams + MAX_BATCH)];
        socket.writable().await?;
        let result = socket.try_io(Interest::WRITABLE, || send_some(socket, to.as_ref(), rest));
        match result {
            Ok(n) => {
                sent.calls += 1;
                // sendmmsg reports an error only when the first datagram failed; 0 would mean nothing moved.
                sent.datagrams += n.max(1);
            }
            // The buffer filled between readiness and the call: wait for room again.
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => return Err(e),
            Err(_) => {
                // The first datagram of the batch is lost; the rest go on.
                sent.calls += 1;
                sent.datagrams += 1;
            }
        }
    }
    Ok(sent)
}

/// One `sendmmsg` over `batch`: how many datagrams the kernel took.
fn send_some(
    socket: &UdpSocket,
    to: Option<&SocketAddrAny>,
    batch: &[impl AsRef<[u8]>],
) -> io::Result<usize> {
    let slices: Vec<[IoSlice<'_>; 1]> = batch.iter().map(|d| [IoSlice::new(d.as_ref())]).collect();
    let mut controls: Vec<SendAncillaryBuffer<'_, '_, '_>> = batch
        .iter()
        .map(|_| SendAncillaryBuffer::default())
        .collect();
    let mut headers: Vec<MMsgHdr<'_>> = slices
        .iter()
        .zip(controls.iter_mut())
        .map(|(iov, control)| match to {
            Some(addr) => MMsgHdr::new_with_addr(addr, iov, control),
            None => MMsgHdr::new(iov, control),
        })
        .collect();
    rustix::net::sendmmsg(socket, &mut headers, SendFlags::empty()).map_err(io::Error::from)
}

/// Adds a burst's cost to the session's counters.
pub fn count(sent: Sent, datagrams: &AtomicU64, calls: &AtomicU64) {
    datagrams.fetch_add(sent.datagrams as u64, Ordering::Relaxed);
    calls.fetch_add(sent.calls as u64, Ordering::Relaxed);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_burst_of_a_hundred_datagrams_goes_in_order_in_two_calls() {
        let receiver = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
        let sender = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
        let to = receiver.local_addr().expect("addr");
        // Small datagrams: a hundred of them fit the receiver's socket buffer whatever its size here.
        let burst: Vec<Vec<u8>> = (0..100u32)
            .map(|i| {
                let mut d = i.to_be_bytes().to_vec();
                d.resize(100, i as u8);
                d
            })
            .collect();
        let sent = send_all(&sender, Some(to), &burst).await.expect("send");
        assert_eq!(
            sent,
            Sent {
                datagrams: 100,
                calls: 2
            }
        );
        let mut buf = vec![0u8; 2048];
        for (i, expected) in burst.iter().enumerate() {
            let n =
                tokio::time::timeout(std::time::Duration::from_secs(10), receiver.recv(&mut buf))
                    .await
                    .expect("a datagram within 10 s")
                    .expect("recv");
            assert_eq!(&buf[..n], expected.as_slice(), "datagram {i}");
        }
    }

    #[tokio::test]
    async fn a_connected_socket_sends_without_an_address_and_hears_a_refusal() {
        let receiver = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
        let sender = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
        sender
            .connect(receiver.local_addr().expect("addr"))
            .await
            .expect("connect");
        let sent = send_all(&sender, None, &[b"one".as_slice(), b"two".as_slice()])
            .await
            .expect("send");
        assert_eq!(sent.datagrams, 2);
        let mut buf = [0u8; 16];
        let n = receiver.recv(&mut buf).await.expect("recv");
        assert_eq!(&buf[..n], b"one");
        let n = receiver.recv(&mut buf).await.expect("recv");
        assert_eq!(&buf[..n], b"two");
        // Nobody listens any more: the kernel reports the port unreachable to the connected socket, and a later
        // send says so.
        drop(receiver);
        let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(10);
        let refused = loop {
            match send_all(&sender, None, &[b"three".as_slice()]).await {
                Err(e) => break e,
                Ok(_) if tokio::time::Instant::now() < deadline => {
                    tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                }
                Ok(_) => panic!("no refusal within 10 s"),
            }
        };
        assert_eq!(refused.kind(), io::ErrorKind::ConnectionRefused);
    }
}
