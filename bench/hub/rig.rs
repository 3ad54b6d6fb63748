//! One publisher and N subscribers wired to one of the three systems under
//! comparison: our hub through the flow SDK, Redis pub/sub through the Rust
//! Redis client, and raw TCP writes from one writer to N sockets.
//!
//! Every subscriber is its own connection and its own task, feeding a shared
//! [`Tally`]; the publisher stamps each payload just before handing it over.

use std::sync::Arc;

use anyhow::Context;
use futures_util::StreamExt;
use tokio::io::{AsyncWriteExt, BufWriter};
use tokio::net::TcpStream;
use tokio::task::JoinHandle;

use crate::servers;
use crate::stamp;
use crate::tally::Tally;

/// Which system carries the messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum System {
    Hub,
    Redis,
    RawTcp,
}

impl System {
    pub fn label(self) -> &'static str {
        match self {
            System::Hub => "hub",
            System::Redis => "redis",
            System::RawTcp => "raw tcp",
        }
    }
}

/// Where the servers listen.
#[derive(Debug, Clone)]
pub struct Endpoints {
    pub hub: flow::FlowAddr,
    pub hub_token: String,
    pub redis_url: String,
}

/// The sending side of a rig.
#[derive(Debug)]
enum Sender {
    Hub {
        publisher: flow::Publisher,
        client: flow::Client,
        channel: String,
    },
    Redis {
        conn: redis::aio::MultiplexedConnection,
        channel: String,
    },
    RawTcp {
        sockets: Vec<BufWriter<TcpStream>>,
    },
}

/// A connected publisher with its subscribers running.
#[derive(Debug)]
pub struct Rig {
    sender: Sender,
    subscribers: Vec<JoinHandle<()>>,
    clients: Vec<flow::Client>,
    pub tally: Arc<Tally>,
    /// The server process relaying the messages, whose CPU time is measured.
    server_pid: Option<u32>,
}

impl Rig {
    /// Connects a publisher and `n` subscribers on channel `channel`; returns
    /// once every subscription is in place.
    pub async fn connect(
        system: System,
        ends: &Endpoints,
        channel: &str,
        n: usize,
    ) -> anyhow::Result<Rig> {
        let tally = Arc::new(Tally::new(n));
        match system {
            System::Hub => hub(ends, channel, n, tally).await,
            System::Redis => redis_pubsub(ends, channel, n, tally).await,
            System::RawTcp => raw_tcp(n, tally).await,
        }
    }

    /// Publishes `template` stamped with `seq`. Like a real producer, it waits
    /// only for what the system's client makes it wait for (a full send queue
    /// or socket buffer), never for the subscribers.
    pub async fn send(&mut self, template: &[u8], seq: u64) -> anyhow::Result<()> {
        match &mut self.sender {
            Sender::Hub { publisher, .. } => {
                publisher.publish(stamp::stamped(template, seq)).await?;
            }
            Sender::Redis { conn, channel } => {
                let mut cmd = redis::cmd("PUBLISH");
                cmd.arg(channel.as_str())
                    .arg(&stamp::stamped(template, seq)[..]);
                // Fire and forget, as the hub's publish is: the reply (the
                // receiver count) is read and discarded by the connection.
                cmd.set_no_response(true);
                conn.send_packed_command(&cmd).await?;
            }
            Sender::RawTcp { sockets } => {
                let frame = stamp::framed(template, seq);
                for socket in sockets.iter_mut() {
                    socket.write_all(&frame).await?;
                }
            }
        }
        Ok(())
    }

    /// Pushes out anything the sender holds back. Only the raw-TCP writer
    /// buffers (to batch small frames into fewer system calls, as the flow and
    /// Redis clients do on their own); the modes call this before they wait.
    pub async fn flush(&mut self) -> anyhow::Result<()> {
        if let Sender::RawTcp { sockets } = &mut self.sender {
            for socket in sockets.iter_mut() {
                socket.flush().await?;
            }
        }
        Ok(())
    }

    /// Deliveries the server itself dropped (the hub's per-channel drop
    /// counter); `None` for systems that do not count drops.
    pub async fn server_dropped(&self) -> Option<u64> {
        match &self.sender {
            Sender::Hub {
                client, channel, ..
            } => client.channel(channel).await.ok().map(|c| c.stats.dropped),
            _ => None,
        }
    }

    /// Sets the server process whose CPU time [`Rig::server_cpu_ns`] reads.
    pub fn watch_server(&mut self, pid: Option<u32>) {
        self.server_pid = pid;
    }

    /// CPU time used so far by the relaying server, if there is one.
    pub fn server_cpu_ns(&self) -> Option<u64> {
        self.server_pid.and_then(servers::cpu_ns)
    }

    /// Disconnects everyone.
    pub async fn close(self) {
        for task in &self.subscribers {
            task.abort();
        }
        for client in &self.clients {
            client.close();
        }
        if let Sender::Hub {
            client, publisher, ..
        } = self.sender
        {
            drop(publisher);
            client.close();
        }
    }
}

fn hub_options(name: &str, token: &str) -> flow::ConnectOptions {
    let mut opts = flow::ConnectOptions::new(name, token);
    opts.reconnect = false;
    opts
}

async fn hub(ends: &Endpoints, channel: &str, n: usize, tally: Arc<Tally>) -> anyhow::Result<Rig> {
    let client = flow::Client::connect(&ends.hub, hub_options("bench-pub", &ends.hub_token))
        .await
        .context("publisher connecting to robot-agent")?;
    let publisher = client
        .publisher(channel, r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let mut clients = Vec::new();
    let mut subscribers = Vec::new();
    for i in 0..n {
        let name = format!("bench-sub-{i}");
        let sub_client = flow::Client::connect(&ends.hub, hub_options(&name, &ends.hub_token))
            .await
            .context("subscriber connecting to robot-agent")?;
        let sub = sub_client.subscribe(channel).await?;
        let tally = tally.clone();
        subscribers.push(tokio::spawn(async move {
            while let Some(data) = sub.recv().await {
                tally.record(i, &data.payload);
            }
            tally.end(i);
        }));
        clients.push(sub_client);
    }
    Ok(Rig {
        sender: Sender::Hub {
            publisher,
            client,
            channel: channel.to_string(),
        },
        subscribers,
        clients,
        tally,
        server_pid: None,
    })
}

async fn redis_pubsub(
    ends: &Endpoints,
    channel: &str,
    n: usize,
    tally: Arc<Tally>,
) -> anyhow::Result<Rig> {
    let client = redis::Client::open(ends.redis_url.as_str())?;
    let conn = client
        .get_multiplexed_async_connection()
        .await
        .context("publisher connecting to redis-server")?;
    let mut subscribers = Vec::new();
    for i in 0..n {
        let mut pubsub = client
            .get_async_pubsub()
            .await
            .context("subscriber connecting to redis-server")?;
        // Returns once Redis has confirmed the subscription.
        pubsub.subscribe(channel).await?;
        let tally = tally.clone();
        subscribers.push(tokio::spawn(async move {
            let mut messages = pubsub.into_on_message();
            while let Some(msg) = messages.next().await {
                tally.record(i, msg.get_payload_bytes());
            }
            tally.end(i);
        }));
    }
    Ok(Rig {
        sender: Sender::Redis {
            conn,
            channel: channel.to_string(),
        },
        subscribers,
        clients: Vec::new(),
        tally,
        server_pid: None,
    })
}

async fn raw_tcp(n: usize, tally: Arc<Tally>) -> anyhow::Result<Rig> {
    let (sockets, subscribers) = agent_bench::raw_tcp::connect(n, tally.clone()).await?;
    Ok(Rig {
        sender: Sender::RawTcp { sockets },
        subscribers,
        clients: Vec::new(),
        tally,
        server_pid: None,
    })
}
