//! The SDK against event orders the real hub can produce but rarely does, played
//! by a scripted peer over the in-process transport so the order is exact.
//!
//! The hub announces a new channel to everyone before the creating command's
//! reply is queued; a quick subscriber can therefore make the hub send the owner
//! `StartPublishing` ahead of the reply that tells the owner its channel id.

use std::time::Duration;

use bytes::BytesMut;
use flow::connection::Connection;
use flow::protocol::{
    ChannelInfo, ChannelKind, ChannelStats, Command, Envelope, Event, PROTOCOL_VERSION, Reply,
    channel_hash, decode_command, encode_event,
};
use flow::transport::Link;
use flow::transport::memory::{self, MemoryTransport};
use flow::{Client, ConnectOptions};

/// The scripted hub's side of the link.
struct ScriptedHub {
    conn: Connection<MemoryTransport>,
}

impl ScriptedHub {
    async fn next_command(&mut self) -> Envelope {
        let raw = tokio::time::timeout(Duration::from_secs(10), self.conn.reader.read_frame())
            .await
            .expect("a command in time")
            .expect("readable")
            .expect("not closed");
        decode_command(raw).expect("a valid command")
    }

    async fn send(&mut self, events: &[Event]) {
        let mut buf = BytesMut::new();
        for e in events {
            encode_event(e, &mut buf);
        }
        self.conn.writer.buffer().extend_from_slice(&buf);
        self.conn.writer.flush().await.expect("write");
    }

    /// Answers login and set-async the way the hub does.
    async fn accept_login(&mut self) {
        let login = self.next_command().await;
        assert!(matches!(login.command, Command::Login { .. }));
        self.send(&[Event::Reply {
            req: login.req,
            result: Ok(Reply::LoginOk {
                version: PROTOCOL_VERSION,
                conn: 1,
                admin: false,
                server: "scripted".into(),
            }),
        }])
        .await;
        let set_async = self.next_command().await;
        assert_eq!(set_async.command, Command::SetAsync);
        self.send(&[Event::Reply {
            req: set_async.req,
            result: Ok(Reply::Done),
        }])
        .await;
    }
}

fn info(id: i16, name: &str) -> ChannelInfo {
    ChannelInfo {
        id,
        hash: channel_hash(name),
        kind: ChannelKind::Stream,
        name: name.into(),
        owner: "owner#1".into(),
        header: "{}".into(),
        stats: ChannelStats::default(),
    }
}

async fn connected() -> (Client, ScriptedHub) {
    let (hub_end, client_end) = memory::pair("scripted");
    let mut hub = ScriptedHub {
        conn: Connection::new(hub_end, flow::protocol::DEFAULT_MAX_FRAME),
    };
    let opts = ConnectOptions::new("owner", "token");
    let (client, ()) = tokio::join!(
        async {
            Client::connect_link(Link::Memory(client_end), opts)
                .await
                .expect("connect")
        },
        hub.accept_login()
    );
    (client, hub)
}

#[tokio::test]
async fn start_publishing_ahead_of_the_add_channel_reply_is_not_lost() {
    let (client, mut hub) = connected().await;
    let script = tokio::spawn(async move {
        let add = hub.next_command().await;
        let Command::AddChannel { name, .. } = &add.command else {
            panic!("expected AddChannel, got {add:?}");
        };
        let channel = info(7, name);
        // Someone subscribed between the announcement and the reply.
        hub.send(&[
            Event::ChannelAdded(channel.clone()),
            Event::StartPublishing { id: 7 },
            Event::Reply {
                req: add.req,
                result: Ok(Reply::Channel(channel)),
            },
        ])
        .await;
        hub
    });
    let publisher = client
        .publisher("Early.news", "{}")
        .await
        .expect("publisher");
    let hub = script.await.expect("script");
    assert_eq!(publisher.id(), Some(7));
    let mut watch = publisher.subscribers();
    tokio::time::timeout(Duration::from_secs(10), watch.wait_for(|on| *on))
        .await
        .expect("the early StartPublishing was lost: the publisher waits forever")
        .expect("client alive");
    drop(hub);
}

#[tokio::test]
async fn news_for_a_channel_that_is_gone_does_not_leak_into_its_successor() {
    let (client, mut hub) = connected().await;
    let script = tokio::spawn(async move {
        // Stale news about channel 9 (say, one this client released), then
        // its removal; later a new channel of ours gets id 9 again.
        hub.send(&[
            Event::StartPublishing { id: 9 },
            Event::ChannelRemoved {
                id: 9,
                name: "Old".into(),
            },
        ])
        .await;
        let add = hub.next_command().await;
        let Command::AddChannel { name, .. } = &add.command else {
            panic!("expected AddChannel, got {add:?}");
        };
        hub.send(&[Event::Reply {
            req: add.req,
            result: Ok(Reply::Channel(info(9, name))),
        }])
        .await;
        hub
    });
    // Let the stale events arrive first.
    let mut events = client.events();
    tokio::time::timeout(Duration::from_secs(10), async {
        while !matches!(
            events.recv().await,
            Ok(flow::ClientEvent::ChannelRemoved { id: 9, .. })
        ) {}
    })
    .await
    .expect("removal seen");
    let publisher = client.publisher("New", "{}").await.expect("publisher");
    let mut hub = script.await.expect("script");
    assert_eq!(publisher.id(), Some(9));
    assert!(
        !publisher.has_subscribers(),
        "stale news applied to a new channel"
    );
    let _ = hub.conn.writer.shutdown().await;
}
