//! The four modes under comparison behind one face: connect a publisher and N subscribers, send a stamped
//! payload, flush, and close; plus which processes' CPU time a mode's figures include.

use std::sync::Arc;

use crate::flow_rig::{self, FlowRig};
use crate::hub::Hub;
use crate::iceoryx::{self, IceRig};
use crate::raw_tcp::{self, RawRig};
use crate::tally::Tally;

/// What carries the messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Through the hub, every client on its Unix socket (the shared-memory data path once the SDK negotiates it).
    Shm,
    /// As `Shm`, but the subscribers give slots back in `Release` frames, not through the hub's release ring: the
    /// path before the ring, in the same run.
    ShmFrames,
    /// Through the hub over loopback TCP.
    HubTcp,
    /// One writer to N loopback sockets, no hub.
    RawTcp,
    /// A plain iceoryx2 publisher and subscribers, no hub: the floor.
    Iceoryx2,
}

impl Mode {
    pub const ALL: [Mode; 5] = [
        Mode::Shm,
        Mode::ShmFrames,
        Mode::HubTcp,
        Mode::RawTcp,
        Mode::Iceoryx2,
    ];

    pub fn label(self) -> &'static str {
        match self {
            Mode::Shm => "shm",
            Mode::ShmFrames => "shm-frames",
            Mode::HubTcp => "hub-tcp",
            Mode::RawTcp => "raw-tcp",
            Mode::Iceoryx2 => "iceoryx2",
        }
    }
}

#[derive(Debug)]
enum Sender {
    Flow(FlowRig),
    Raw(RawRig),
    // Boxed: the iceoryx2 ports are large, the other senders small.
    Ice(Box<IceRig>),
}

/// A connected publisher with its subscribers running.
#[derive(Debug)]
pub struct Rig {
    sender: Sender,
    pub tally: Arc<Tally>,
    /// The hub process relaying the messages, whose CPU time counts with this process's.
    pub hub_pid: Option<u32>,
}

/// Everything a rig needs to know to connect.
#[derive(Debug, Clone, Copy)]
pub struct Target<'a> {
    pub hub: &'a Hub,
    /// A name unique to the cell: the hub channel, or the iceoryx2 service.
    pub name: &'a str,
    pub subscribers: usize,
    pub payload_len: usize,
    /// Samples each iceoryx2 subscriber's buffer holds (above the publisher's window).
    pub buffer: usize,
}

impl Rig {
    pub async fn connect(mode: Mode, t: Target<'_>) -> anyhow::Result<Rig> {
        let tally = Arc::new(Tally::new(t.subscribers));
        let (sender, hub_pid) = match mode {
            Mode::Shm | Mode::ShmFrames | Mode::HubTcp => {
                let addr = if mode == Mode::HubTcp {
                    &t.hub.tcp
                } else {
                    &t.hub.unix
                };
                let ring = mode != Mode::ShmFrames;
                let rig = flow_rig::connect(
                    addr,
                    &t.hub.token,
                    t.name,
                    t.subscribers,
                    ring,
                    tally.clone(),
                )
                .await?;
                (Sender::Flow(rig), Some(t.hub.pid))
            }
            Mode::RawTcp => (
                Sender::Raw(raw_tcp::connect(t.subscribers, tally.clone()).await?),
                None,
            ),
            Mode::Iceoryx2 => (
                Sender::Ice(Box::new(iceoryx::connect(
                    t.name,
                    t.payload_len,
                    t.subscribers,
                    t.buffer,
                    tally.clone(),
                )?)),
                None,
            ),
        };
        Ok(Rig {
            sender,
            tally,
            hub_pid,
        })
    }

    /// Publishes `template` stamped with `seq`, waiting only for what the mode makes a producer wait for.
    pub async fn send(&mut self, template: &[u8], seq: u64) -> anyhow::Result<()> {
        match &mut self.sender {
            Sender::Flow(r) => r.send(template, seq).await,
            Sender::Raw(r) => r.send(template, seq).await,
            Sender::Ice(r) => r.send(template, seq),
        }
    }

    /// Pushes out anything the sender holds back (only the raw-TCP writer buffers).
    pub async fn flush(&mut self) -> anyhow::Result<()> {
        match &mut self.sender {
            Sender::Raw(r) => r.flush().await,
            Sender::Flow(_) | Sender::Ice(_) => Ok(()),
        }
    }

    pub fn close(self) {
        match self.sender {
            Sender::Flow(r) => r.close(),
            Sender::Raw(r) => r.close(),
            Sender::Ice(r) => r.close(),
        }
    }
}
