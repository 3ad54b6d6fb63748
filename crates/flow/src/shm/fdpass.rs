//! A descriptor beside the bytes of a Unix stream (`SCM_RIGHTS`): the hub sends a segment's descriptor with the
//! frame that introduces it, and the client's reader keeps every descriptor that came, in order, for the frame that
//! names it. No `unsafe` here: `rustix` wraps `sendmsg` / `recvmsg`.

use std::collections::VecDeque;
use std::io::{self, IoSlice, IoSliceMut};
use std::mem::MaybeUninit;
use std::os::fd::{BorrowedFd, OwnedFd};

use bytes::BytesMut;
use rustix::net::{
    RecvAncillaryBuffer, RecvAncillaryMessage, RecvFlags, ReturnFlags, SendAncillaryBuffer,
    SendAncillaryMessage, SendFlags,
};
use tokio::io::Interest;
use tokio::net::UnixStream;

/// Descriptors one read can take; the hub sends one per frame, so more only arrive when several segments are
/// introduced back to back.
const FDS_PER_READ: usize = 8;
/// The scratch a reader keeps for `recvmsg`: what one read takes at most.
pub const READ_CHUNK: usize = 64 * 1024;

/// Sends the first bytes of `data` with `fd` beside them; returns how many bytes went (at least one). The caller
/// sends the rest as ordinary bytes.
pub async fn send_with_fd(
    stream: &UnixStream,
    data: &[u8],
    fd: BorrowedFd<'_>,
) -> io::Result<usize> {
    if data.is_empty() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "a descriptor must travel with at least one byte",
        ));
    }
    loop {
        stream.writable().await?;
        let sent = stream.try_io(Interest::WRITABLE, || {
            let mut space = [MaybeUninit::uninit(); rustix::cmsg_space!(ScmRights(1))];
            let mut control = SendAncillaryBuffer::new(&mut space);
            let fds = [fd];
            if !control.push(SendAncillaryMessage::ScmRights(&fds)) {
                return Err(io::Error::other("no room for a descriptor"));
            }
            Ok(rustix::net::sendmsg(
                stream,
                &[IoSlice::new(data)],
                &mut control,
                SendFlags::NOSIGNAL,
            )?)
        });
        match sent {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            Ok(n) => return Ok(n),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => continue,
            Err(e) => return Err(e),
        }
    }
}

/// Appends the next received bytes to `buf` and the descriptors that came with them to `fds`; `Ok(0)` means the peer
/// closed. `scratch` is where `recvmsg` writes (it takes initialised bytes, and zeroing the room of `buf` before every
/// read cost more than the small frames of the shared-memory path themselves); its length bounds one read. A read
/// whose descriptors did not all fit is an error: a frame would later miss its descriptor.
pub async fn recv_with_fds(
    stream: &UnixStream,
    scratch: &mut [u8],
    buf: &mut BytesMut,
    fds: &mut VecDeque<OwnedFd>,
) -> io::Result<usize> {
    loop {
        stream.readable().await?;
        let got = stream.try_io(Interest::READABLE, || {
            let mut space = [MaybeUninit::uninit(); rustix::cmsg_space!(ScmRights(FDS_PER_READ))];
            let mut control = RecvAncillaryBuffer::new(&mut space);
            let mut iov = [IoSliceMut::new(scratch)];
            let msg =
                rustix::net::recvmsg(stream, &mut iov, &mut control, RecvFlags::CMSG_CLOEXEC)?;
            for message in control.drain() {
                if let RecvAncillaryMessage::ScmRights(received) = message {
                    fds.extend(received);
                }
            }
            if msg.flags.contains(ReturnFlags::CTRUNC) {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    "more descriptors came with one read than it can take",
                ));
            }
            Ok(msg.bytes)
        });
        match got {
            Ok(n) => {
                buf.extend_from_slice(&scratch[..n]);
                return Ok(n);
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => continue,
            Err(e) => return Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::fd::AsFd;

    #[tokio::test]
    async fn a_descriptor_arrives_with_its_bytes_and_in_order() {
        let (a, b) = UnixStream::pair().expect("pair");
        let first = crate::shm::Mapping::create("flow-shm-test", 4096).expect("segment");
        let second = crate::shm::Mapping::create("flow-shm-test", 8192).expect("segment");
        assert_eq!(send_with_fd(&a, b"one", first.fd()).await.expect("send"), 3);
        assert_eq!(
            send_with_fd(&a, b"two", second.fd()).await.expect("send"),
            3
        );
        let mut buf = BytesMut::with_capacity(16);
        let mut fds = VecDeque::new();
        let mut scratch = vec![0u8; 4];
        // One deadline for the whole read: a lost byte must fail the test, not hang it.
        tokio::time::timeout(std::time::Duration::from_secs(30), async {
            while buf.len() < 6 {
                assert!(
                    recv_with_fds(&b, &mut scratch, &mut buf, &mut fds)
                        .await
                        .expect("recv")
                        > 0
                );
            }
        })
        .await
        .expect("both messages within 30 s");
        assert_eq!(&buf[..], b"onetwo");
        assert_eq!(fds.len(), 2);
        let sizes: Vec<i64> = fds
            .iter()
            .map(|fd| rustix::fs::fstat(fd.as_fd()).expect("fstat").st_size)
            .collect();
        assert_eq!(sizes, [4096, 8192]);
    }
}
