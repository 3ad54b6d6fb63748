//! A session's UDP socket with as few system calls per datagram as the kernel allows, both ways.
//!
//! Sending: a run of equally long datagrams (a picture's fragments; the last may be shorter) goes out as one
//! segmentation-offloaded send (`UDP_SEGMENT`, "GSO": the kernel cuts one buffer into the datagrams, so a 52 KB
//! JPEG's 44 fragments cross the stack once); what is left (acknowledgements, single frames) goes in `sendmmsg`
//! batches of up to [`MAX_BATCH`]. Receiving: `recvmmsg` with `UDP_GRO`, so on the loopback a GSO send arrives as
//! one buffer with its datagrams' stride, and elsewhere the kernel coalesces what it can; [`Received`] splits them
//! again. Both come from `quinn-udp` (the QUIC stack's socket layer, with its own checks for what the kernel
//! supports: a kernel or driver without GSO is found at the first failed send and never asked again).
//!
//! The socket's readiness stays tokio's (`try_io`), so a full send buffer waits like any other write. What a
//! datagram socket reports for one datagram (a full buffer after readiness, a route that comes and goes) loses that
//! datagram only, as a lost datagram on the wire would be: the lanes above send again what matters. A refused
//! connection (a connected socket heard that nobody listens any more) ends the session.

use std::io::{self, IoSlice, IoSliceMut};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};

use quinn_udp::{RecvMeta, Transmit, UdpSockRef, UdpSocketState};
use rustix::net::{MMsgHdr, SendAncillaryBuffer, SendFlags, SocketAddrAny};
use tokio::io::Interest;
use tokio::net::UdpSocket;

/// The most datagrams one `sendmmsg` takes (the kernel's own cap is 1024).
pub const MAX_BATCH: usize = 64;
/// The most bytes one segmented send carries: an IP packet's limit, less its headers.
const MAX_SEGMENTED: usize = 65_000;
/// Receive buffers per `recvmmsg`, each large enough for the most a coalesced receive holds (64 KiB).
pub const RECEIVE_BUFFERS: usize = 4;
const RECEIVE_BUFFER: usize = 64 * 1024;

/// What sending a burst cost.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Sent {
    /// Datagrams handed to the kernel (or lost on the way, as above).
    pub datagrams: usize,
    /// System calls made.
    pub calls: usize,
}

/// A UDP socket and what its kernel offers for batches.
#[derive(Debug)]
pub struct BatchSocket {
    socket: UdpSocket,
    state: UdpSocketState,
    /// The connected peer of a client's socket: a segmented send names its destination.
    peer: Option<SocketAddr>,
}

impl BatchSocket {
    /// Sets `socket` up for batches (`UDP_GRO` on, the don't-fragment bit set, as `quinn-udp` does).
    pub fn new(socket: UdpSocket) -> io::Result<Self> {
        let state = UdpSocketState::new(UdpSockRef::from(&socket))?;
        let peer = socket.peer_addr().ok();
        Ok(BatchSocket {
            socket,
            state,
            peer,
        })
    }

    pub fn socket(&self) -> &UdpSocket {
        &self.socket
    }

    /// Sends `datagrams` in order to `to` (or to the connected peer when `None`); fails only when the peer refused.
    pub async fn send_all(
        &self,
        to: Option<SocketAddr>,
        datagrams: &[impl AsRef<[u8]>],
    ) -> io::Result<Sent> {
        let destination = to.or(self.peer);
        let segments = self.state.max_gso_segments().min(MAX_BATCH);
        let mut sent = Sent::default();
        let mut joined = Vec::new();
        while sent.datagrams < datagrams.len() {
            let rest = &datagrams[sent.datagrams..];
            let run = match destination {
                Some(_) if segments > 1 => segmented_run(rest, segments),
                _ => 1,
            };
            let (result, taken) = match destination {
                Some(destination) if run > 1 => {
                    joined.clear();
                    for d in &rest[..run] {
                        joined.extend_from_slice(d.as_ref());
                    }
                    let transmit = Transmit {
                        destination,
                        ecn: None,
                        contents: &joined,
                        segment_size: Some(rest[0].as_ref().len()),
                        src_ip: None,
                    };
                    self.socket.writable().await?;
                    let result = self.socket.try_io(Interest::WRITABLE, || {
                        self.state
                            .try_send(UdpSockRef::from(&self.socket), &transmit)
                    });
                    (result.map(|()| run), run)
                }
                _ => {
                    // Single datagrams up to the next run worth segmenting, in one `sendmmsg`.
                    let singles = (1..rest.len().min(MAX_BATCH))
                        .find(|&i| {
                            destination.is_some()
                                && segments > 1
                                && segmented_run(&rest[i..], segments) > 1
                        })
                        .unwrap_or(rest.len().min(MAX_BATCH));
                    self.socket.writable().await?;
                    let to = to.map(SocketAddrAny::from);
                    let result = self.socket.try_io(Interest::WRITABLE, || {
                        send_some(&self.socket, to.as_ref(), &rest[..singles])
                    });
                    (result, 1)
                }
            };
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
                    // The run (or the first datagram of the batch) is lost; the rest go on.
                    sent.calls += 1;
                    sent.datagrams += taken;
                }
            }
        }
        Ok(sent)
    }

    /// Waits for datagrams and takes what has arrived into `into` (at least one datagram, or an error).
    pub async fn recv(&self, into: &mut Received) -> io::Result<()> {
        loop {
            self.socket.readable().await?;
            match self.try_recv(into) {
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                other => return other,
            }
        }
    }

    /// Takes what has arrived into `into` without waiting (`WouldBlock` when nothing has).
    pub fn try_recv(&self, into: &mut Received) -> io::Result<()> {
        into.filled = 0;
        let Received {
            buffers,
            meta,
            filled,
        } = into;
        let mut slices: Vec<IoSliceMut<'_>> = buffers
            .iter_mut()
            .map(|b| IoSliceMut::new(b.as_mut_slice()))
            .collect();
        *filled = self.socket.try_io(Interest::READABLE, || {
            self.state
                .recv(UdpSockRef::from(&self.socket), &mut slices, meta)
        })?;
        Ok(())
    }
}

/// How many of `datagrams`' first ones make one segmented send: equally long ones, and one shorter at the end,
/// within `segments` and [`MAX_SEGMENTED`] bytes.
fn segmented_run(datagrams: &[impl AsRef<[u8]>], segments: usize) -> usize {
    let Some(first) = datagrams.first().map(|d| d.as_ref().len()) else {
        return 0;
    };
    if first == 0 {
        return 1;
    }
    let most = segments.min(MAX_SEGMENTED / first).max(1);
    let mut run = 1;
    for d in datagrams.iter().skip(1).take(most - 1) {
        let len = d.as_ref().len();
        if len > first {
            break;
        }
        run += 1;
        if len < first {
            break;
        }
    }
    run
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

/// The buffers one receive fills: several messages, each of one datagram or of several coalesced ones.
#[derive(Debug)]
pub struct Received {
    buffers: Vec<Vec<u8>>,
    meta: Vec<RecvMeta>,
    /// How many messages the last receive filled.
    filled: usize,
}

impl Default for Received {
    fn default() -> Self {
        Received::with_buffers(RECEIVE_BUFFERS)
    }
}

impl Received {
    /// `buffers` receive buffers of 64 KiB (0 for a session that never reads a socket).
    pub fn with_buffers(buffers: usize) -> Self {
        Received {
            buffers: vec![vec![0u8; RECEIVE_BUFFER]; buffers],
            meta: vec![RecvMeta::default(); buffers],
            filled: 0,
        }
    }

    /// Adds the last receive to `datagrams` and `calls`.
    pub fn count(&self, datagrams: &AtomicU64, calls: &AtomicU64) {
        datagrams.fetch_add(self.datagrams().count() as u64, Ordering::Relaxed);
        calls.fetch_add(1, Ordering::Relaxed);
    }

    /// The datagrams of the last receive, in order, with their sources.
    pub fn datagrams(&self) -> impl Iterator<Item = (SocketAddr, &[u8])> {
        self.buffers
            .iter()
            .zip(&self.meta)
            .take(self.filled)
            .flat_map(|(buffer, meta)| {
                let stride = if meta.stride == 0 {
                    meta.len
                } else {
                    meta.stride
                };
                buffer[..meta.len.min(buffer.len())]
                    .chunks(stride.max(1))
                    .map(move |d| (meta.addr, d))
            })
    }
}

/// Adds a burst's cost to the session's counters.
pub fn count(sent: Sent, datagrams: &AtomicU64, calls: &AtomicU64) {
    datagrams.fetch_add(sent.datagrams as u64, Ordering::Relaxed);
    calls.fetch_add(sent.calls as u64, Ordering::Relaxed);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch_socket(socket: UdpSocket) -> BatchSocket {
        BatchSocket::new(socket).expect("a socket set up for batches")
    }

    /// A picture's worth of fragments (44 of 1200 bytes, the last shorter) and an acknowledgement after them.
    fn fragments() -> Vec<Vec<u8>> {
        let mut burst: Vec<Vec<u8>> = (0..44u8)
            .map(|i| {
                let mut d = vec![i; 1200];
                d[1] = 0xA5;
                d
            })
            .collect();
        burst[43].truncate(700);
        burst.push(vec![99; 30]);
        burst
    }

    #[tokio::test]
    async fn a_run_of_fragments_goes_out_segmented_and_a_coalescing_receiver_splits_it_in_order() {
        let receiver = batch_socket(UdpSocket::bind("127.0.0.1:0").await.expect("bind"));
        let sender = batch_socket(UdpSocket::bind("127.0.0.1:0").await.expect("bind"));
        let from = sender.socket().local_addr().expect("addr");
        let burst = fragments();
        let sent = sender
            .send_all(Some(receiver.socket().local_addr().expect("addr")), &burst)
            .await
            .expect("send");
        assert_eq!(sent.datagrams, burst.len());
        if sender.state.max_gso_segments() > 1 {
            // The 44 fragments in one segmented send, the acknowledgement in a second call.
            assert_eq!(sent.calls, 2, "{sent:?}");
        }
        let mut got: Vec<Vec<u8>> = Vec::new();
        let mut calls = 0;
        let mut received = Received::default();
        let all = tokio::time::timeout(std::time::Duration::from_secs(10), async {
            while got.len() < burst.len() {
                receiver.recv(&mut received).await.expect("recv");
                calls += 1;
                for (source, d) in received.datagrams() {
                    assert_eq!(source, from);
                    got.push(d.to_vec());
                }
            }
        })
        .await;
        assert!(
            all.is_ok(),
            "{} of {} datagrams within 10 s",
            got.len(),
            burst.len()
        );
        assert!(
            got == burst,
            "the datagrams arrived changed or out of order"
        );
        println!("{} datagrams received in {calls} calls", got.len());
        assert!(calls < burst.len(), "one call per datagram");
    }

    #[test]
    fn runs_end_at_a_longer_datagram_after_a_shorter_one_and_within_the_segment_limit() {
        let sizes =
            |lens: &[usize]| -> Vec<Vec<u8>> { lens.iter().map(|&n| vec![0u8; n]).collect() };
        assert_eq!(segmented_run(&sizes(&[1200, 1200, 700, 1200]), 64), 3);
        assert_eq!(segmented_run(&sizes(&[1200, 1300]), 64), 1);
        assert_eq!(segmented_run(&sizes(&[30, 1200]), 64), 1);
        assert_eq!(segmented_run(&sizes(&[1200; 100]), 64), 54);
        assert_eq!(segmented_run(&sizes(&[100; 100]), 64), 64);
        assert_eq!(segmented_run(&sizes(&[]), 64), 0);
    }

    #[tokio::test]
    async fn a_burst_of_a_hundred_datagrams_goes_in_order_in_two_calls() {
        let receiver = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
        let sender = batch_socket(UdpSocket::bind("127.0.0.1:0").await.expect("bind"));
        let to = receiver.local_addr().expect("addr");
        // Small datagrams: a hundred of them fit the receiver's socket buffer whatever its size here.
        let burst: Vec<Vec<u8>> = (0..100u32)
            .map(|i| {
                let mut d = i.to_be_bytes().to_vec();
                d.resize(100, i as u8);
                d
            })
            .collect();
        let sent = sender.send_all(Some(to), &burst).await.expect("send");
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
        let sender = batch_socket(sender);
        let sent = sender
            .send_all(None, &[b"one".as_slice(), b"two".as_slice()])
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
            match sender.send_all(None, &[b"three".as_slice()]).await {
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
