//! The blocking client against a fake hub that speaks through the SDK's codec (`flow::protocol`) and the line
//! framing: what the client sends is decoded by the SDK, what the SDK encodes is read by the client, in reads of
//! one byte or of many, with damaged packets in between.

use std::collections::VecDeque;

use bytes::{Bytes, BytesMut};
use flow::protocol::{self as fp, frame as fframe};
use flow_lite::client::{Client, Error, Link};
use flow_lite::line::{self, Deframed, Deframer};
use flow_lite::message::{ErrorCode, Event};

/// A hub in a test: answers commands as the real one does, through the SDK's codec.
struct FakeHub {
    deframer: Deframer<Vec<u8>>,
    inbound: VecDeque<u8>,
    /// Bytes handed out per read (1: a byte at a time).
    step: usize,
    /// Commands received, in order.
    got: Vec<fp::Envelope>,
    /// Answer nothing at all.
    silent: bool,
    /// Put a damaged packet before each answer.
    damage: bool,
    /// Say goodbye instead of answering.
    goodbye: bool,
    /// Events to send with the next answer, in the same packet.
    extra: Vec<fp::Event>,
    next_id: i16,
    /// Packets that arrived intact at the hub.
    packets: usize,
}

impl FakeHub {
    fn new(step: usize) -> Self {
        FakeHub {
            deframer: Deframer::new(vec![0; 1 << 16]),
            inbound: VecDeque::new(),
            step,
            got: Vec::new(),
            silent: false,
            damage: false,
            goodbye: false,
            extra: Vec::new(),
            next_id: 3,
            packets: 0,
        }
    }

    /// Sends `events` as one packet.
    fn send(&mut self, events: &[fp::Event]) {
        let mut body = BytesMut::new();
        for event in events {
            fp::encode_event(event, &mut body);
        }
        let mut packet = vec![0; line::max_encoded_len(body.len())];
        let n = line::encode(&body, &mut packet).expect("encodes");
        if self.damage {
            let mut bad = packet[..n].to_vec();
            bad[n / 2] ^= 0x10;
            self.inbound.extend(bad);
        }
        self.inbound.extend(&packet[..n]);
    }

    fn info(&mut self, name: &str, kind: fp::ChannelKind) -> fp::ChannelInfo {
        self.next_id += 1;
        fp::ChannelInfo {
            id: self.next_id,
            hash: fp::channel_hash(name),
            kind,
            name: name.into(),
            owner: "board#1".into(),
            header: "{}".into(),
            stats: fp::ChannelStats::default(),
        }
    }

    fn answer(&mut self, env: fp::Envelope) {
        let req = env.req;
        let result = match &env.command {
            fp::Command::Login { token, .. } if token == "secret" => Ok(fp::Reply::LoginOk {
                version: 1,
                conn: 7,
                admin: false,
                server: "fake".into(),
            }),
            fp::Command::Login { .. } => Err(fp::ErrorReply::new(
                fp::ErrorCode::AuthFailed,
                "wrong token",
            )),
            fp::Command::SetAsync => Ok(fp::Reply::Done),
            fp::Command::AddChannel { kind, name, .. } => {
                Ok(fp::Reply::Channel(self.info(name, *kind)))
            }
            fp::Command::Subscribe {
                chan: fp::ChanRef::Name(name),
            } => Ok(fp::Reply::Channel(self.info(name, fp::ChannelKind::Stream))),
            fp::Command::Call { payload, .. } if payload.is_empty() => Err(fp::ErrorReply::new(
                fp::ErrorCode::ServiceFailed,
                "an empty question",
            )),
            fp::Command::Call { payload, .. } => {
                let mut back = payload.to_vec();
                back.reverse();
                Ok(fp::Reply::Payload(Bytes::from(back)))
            }
            fp::Command::Ping => Ok(fp::Reply::Pong),
            _ => Ok(fp::Reply::Done),
        };
        self.got.push(env);
        if req == 0 || self.silent {
            return;
        }
        let mut events = vec![fp::Event::Reply { req, result }];
        if self.goodbye {
            events = vec![fp::Event::Goodbye {
                reason: "shutting down".into(),
            }];
        }
        events.append(&mut self.extra);
        self.send(&events);
    }
}

impl Link for FakeHub {
    type Error = std::convert::Infallible;

    fn write(&mut self, bytes: &[u8]) -> Result<(), Self::Error> {
        let mut rest = bytes;
        while !rest.is_empty() {
            let (used, out) = self.deframer.push(rest);
            rest = &rest[used..];
            let body = match out {
                Some(Deframed::Packet(body)) => BytesMut::from(body),
                Some(Deframed::Damaged(why)) => panic!("the client sent a damaged packet: {why:?}"),
                None => continue,
            };
            self.packets += 1;
            let mut body = body;
            while !body.is_empty() {
                let Ok(fp::Check::Complete(n)) = fframe::check(&body, fp::DEFAULT_MAX_FRAME) else {
                    panic!("a packet of whole frames");
                };
                let env =
                    fp::decode_command(fframe::parse(&mut body, n)).expect("the SDK decodes it");
                self.answer(env);
            }
        }
        Ok(())
    }

    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let n = self.step.min(buf.len()).min(self.inbound.len());
        for (slot, b) in buf.iter_mut().zip(self.inbound.drain(..n)) {
            *slot = b;
        }
        Ok(n)
    }
}

fn login(client: &mut Client<'_, FakeHub>) {
    let session = client.login("secret", "board").expect("logs in");
    assert_eq!(
        (session.version, session.conn, session.admin),
        (1, 7, false)
    );
}

#[test]
fn a_sensor_logs_in_creates_its_publisher_and_publishes_what_the_sdk_reads() {
    for step in [1, 3, 64] {
        let (mut rx, mut tx) = ([0u8; 1024], [0u8; 1024]);
        let mut client = Client::new(FakeHub::new(step), &mut rx, &mut tx);
        login(&mut client);
        let chan = client
            .publisher("Sensor.temperature", r#"{"mime":"application/json"}"#)
            .expect("creates");
        assert_eq!(chan, 4);
        for i in 0..20 {
            let reading = format!(r#"{{"celsius":{}.5}}"#, 20 + i);
            client.publish(chan, reading.as_bytes()).expect("sends");
        }
        client.ping().expect("pong");
        let hub = client.into_link();
        assert_eq!(hub.packets, 1 + 1 + 20 + 1, "one packet per command");
        assert_eq!(
            hub.got[0].command,
            fp::Command::Login {
                version: 1,
                token: "secret".into(),
                name: "board".into()
            }
        );
        assert_eq!(
            hub.got[1].command,
            fp::Command::AddChannel {
                kind: fp::ChannelKind::Stream,
                name: "Sensor.temperature".into(),
                header: r#"{"mime":"application/json"}"#.into()
            }
        );
        for (i, env) in hub.got[2..22].iter().enumerate() {
            assert_eq!(env.req, 0, "publish asks for no reply");
            assert_eq!(
                env.command,
                fp::Command::Publish {
                    chan: 4,
                    payload: Bytes::from(format!(r#"{{"celsius":{}.5}}"#, 20 + i))
                }
            );
        }
        assert_eq!(hub.got[22].command, fp::Command::Ping);
        // Request ids are fresh and never 0.
        let reqs: Vec<u32> = [0, 1, 22].iter().map(|&i| hub.got[i].req).collect();
        assert_eq!(reqs, [1, 2, 3]);
    }
}

#[test]
fn a_damaged_packet_is_counted_and_the_reply_after_it_arrives() {
    let (mut rx, mut tx) = ([0u8; 1024], [0u8; 1024]);
    let mut hub = FakeHub::new(5);
    hub.damage = true;
    let mut client = Client::new(hub, &mut rx, &mut tx);
    login(&mut client);
    client.set_async().expect("async");
    assert_eq!(client.call("Echo", b"abc", 1000).expect("answers"), b"cba");
    assert_eq!(client.damaged(), 3);
}

#[test]
fn subscribed_data_and_service_requests_come_to_poll_in_order() {
    let (mut rx, mut tx) = ([0u8; 2048], [0u8; 512]);
    let mut client = Client::new(FakeHub::new(7), &mut rx, &mut tx);
    login(&mut client);
    client.set_async().expect("async");
    let service = client.service("Board.led", "{}").expect("creates");
    // The hub sends the subscription's reply with its first data, a channel event and a request, in one packet.
    let payloads: Vec<Vec<u8>> = (0..3u8).map(|i| vec![i, 0, 0xFF, i]).collect();
    let mut extra: Vec<fp::Event> = payloads
        .iter()
        .enumerate()
        .map(|(i, p)| fp::Event::Data {
            chan: 5,
            seq: i as u64 + 1,
            ts_us: 1_700_000_000_000_000 + i as u64,
            payload: Bytes::from(p.clone()),
        })
        .collect();
    extra.push(fp::Event::HeaderChanged {
        id: 5,
        name: "Robot.pose".into(),
        header: "{}".into(),
    });
    extra.push(fp::Event::ServiceRequest {
        chan: service,
        call: 99,
        payload: Bytes::from_static(b"on"),
    });
    client.link_mut().extra = extra;
    let chan = client.subscribe("Robot.pose").expect("subscribes");
    assert_eq!(chan, 5);
    let mut data = Vec::new();
    let mut call = None;
    let mut others = 0;
    for _ in 0..1000 {
        match client.poll().expect("valid") {
            Some(Event::Data {
                chan: 5,
                seq,
                payload,
                ..
            }) => data.push((seq, payload.to_vec())),
            Some(Event::ServiceRequest {
                call: id, payload, ..
            }) => call = Some((id, payload.to_vec())),
            Some(Event::Other { op: 0x83, .. }) => others += 1,
            Some(other) => panic!("unexpected {other:?}"),
            None => {}
        }
    }
    let want: Vec<(u64, Vec<u8>)> = payloads
        .into_iter()
        .enumerate()
        .map(|(i, p)| (i as u64 + 1, p))
        .collect();
    assert_eq!(data, want);
    assert_eq!(others, 1);
    assert_eq!(call, Some((99, b"on".to_vec())));
    client.respond(99, Ok(b"done")).expect("sends");
    client.respond(100, Err("no such led")).expect("sends");
    let hub = client.into_link();
    let n = hub.got.len();
    assert_eq!(
        hub.got[n - 2].command,
        fp::Command::Respond {
            call: 99,
            result: Ok(Bytes::from_static(b"done"))
        }
    );
    assert_eq!(
        hub.got[n - 1].command,
        fp::Command::Respond {
            call: 100,
            result: Err("no such led".into())
        }
    );
}

#[test]
fn a_refusal_is_an_error_with_its_code_and_message() {
    let (mut rx, mut tx) = ([0u8; 512], [0u8; 512]);
    let mut client = Client::new(FakeHub::new(64), &mut rx, &mut tx);
    assert_eq!(
        client.login("guess", "board"),
        Err(Error::Refused(ErrorCode::AuthFailed))
    );
    assert_eq!(client.last_message(), "wrong token");
    login(&mut client);
    assert_eq!(
        client.call("Echo", b"", 10),
        Err(Error::Refused(ErrorCode::ServiceFailed))
    );
    assert_eq!(client.last_message(), "an empty question");
}

#[test]
fn a_silent_hub_costs_the_read_limit_and_no_more() {
    let (mut rx, mut tx) = ([0u8; 512], [0u8; 512]);
    let mut hub = FakeHub::new(64);
    hub.silent = true;
    let mut client = Client::new(hub, &mut rx, &mut tx);
    client.set_read_limit(10);
    assert_eq!(client.ping(), Err(Error::NoReply));
    assert_eq!(client.poll(), Ok(None));
}

#[test]
fn a_goodbye_while_waiting_ends_the_wait_with_its_reason() {
    let (mut rx, mut tx) = ([0u8; 512], [0u8; 512]);
    let mut client = Client::new(FakeHub::new(64), &mut rx, &mut tx);
    login(&mut client);
    client.link_mut().goodbye = true;
    assert_eq!(client.ping(), Err(Error::Goodbye));
    assert_eq!(client.last_message(), "shutting down");
}

#[test]
fn events_that_come_while_a_request_waits_are_skipped_and_counted() {
    let (mut rx, mut tx) = ([0u8; 512], [0u8; 512]);
    let mut hub = FakeHub::new(64);
    hub.send(&[
        fp::Event::StartPublishing { id: 1 },
        fp::Event::Reply {
            req: 0,
            result: Err(fp::ErrorReply::new(fp::ErrorCode::NotOwner, "not yours")),
        },
    ]);
    let mut client = Client::new(hub, &mut rx, &mut tx);
    login(&mut client);
    assert_eq!(client.skipped(), 2);
}

#[test]
fn a_packet_larger_than_the_rx_buffer_is_dropped_and_the_next_one_read() {
    let mut rx = [0u8; Client::<FakeHub>::rx_len(100)];
    let mut tx = [0u8; 512];
    let mut hub = FakeHub::new(64);
    hub.send(&[fp::Event::Data {
        chan: 1,
        seq: 1,
        ts_us: 1,
        payload: Bytes::from(vec![7u8; 300]),
    }]);
    let mut client = Client::new(hub, &mut rx, &mut tx);
    login(&mut client);
    assert_eq!(client.damaged(), 1);
    assert_eq!(client.skipped(), 0);
}

#[test]
fn buffers_sized_by_rx_len_and_tx_len_carry_frames_of_that_size() {
    let frame = 200;
    let mut rx = vec![0u8; Client::<FakeHub>::rx_len(frame)];
    let mut tx = vec![0u8; Client::<FakeHub>::tx_len(frame)];
    let mut client = Client::new(FakeHub::new(64), &mut rx, &mut tx);
    assert!(client.max_frame() >= frame);
    login(&mut client);
    client.set_async().expect("async");
    // A call of exactly `frame` bytes: header 9, chref 1 + 2 + 4 name, timeout 4.
    let payload = vec![0x5A; frame - 9 - 7 - 4];
    let back = client.call("Echo", &payload, 100).expect("fits both ways");
    assert_eq!(back.len(), payload.len());
    let too_big = vec![0; frame * 2];
    assert!(matches!(client.publish(1, &too_big), Err(Error::Encode(_))));
}

#[test]
fn tiny_buffers_fail_cleanly() {
    for len in [0, 1, 5, 9, 20] {
        let (mut rx, mut tx) = (vec![0u8; len], vec![0u8; len]);
        let mut client = Client::new(FakeHub::new(1), &mut rx, &mut tx);
        assert!(matches!(client.ping(), Err(Error::Encode(_))), "{len}");
        assert!(client.poll().is_ok());
    }
}
