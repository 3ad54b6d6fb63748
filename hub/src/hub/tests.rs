//! Unit tests of the hub core's semantics, driven without any socket.

use std::time::Duration;

use super::*;

/// The timeout of the tests' service calls: long enough never to pass by itself.
const T: u32 = 60_000;

pub(crate) fn limits(lane_msgs: usize) -> HubLimits {
    HubLimits {
        outbox: OutboxLimits {
            lane_msgs,
            lane_bytes: 1 << 20,
            control_msgs: 1024,
        },
        service_inflight: 4,
        max_channels: MAX_CHANNELS,
    }
}

pub(crate) fn drain(outbox: &Outbox) -> Vec<Event> {
    let mut out = Vec::new();
    outbox.pop_batch(&mut out, usize::MAX);
    out
}

fn async_conn(hub: &Hub, name: &str) -> (ConnId, Arc<Outbox>) {
    let (id, ob) = hub.connect("test");
    hub.login(id, name, false);
    hub.set_async(id);
    (id, ob)
}

#[test]
fn fan_out_reaches_every_subscriber_in_order() {
    let hub = Hub::new(limits(64));
    let (p, _) = async_conn(&hub, "pub");
    let info = hub
        .add_channel(p, ChannelKind::Stream, "A", "{}")
        .expect("add");
    let subs: Vec<_> = (0..3).map(|i| async_conn(&hub, &format!("s{i}"))).collect();
    for (s, ob) in &subs {
        hub.subscribe(*s, &ChanRef::Name("A".into()))
            .expect("subscribe");
        drain(ob);
    }
    for i in 0..5u8 {
        hub.publish(p, info.id, Bytes::from(vec![i]))
            .expect("publish");
    }
    for (_, ob) in &subs {
        let got: Vec<_> = drain(ob)
            .into_iter()
            .filter_map(|e| match e {
                Event::Data { seq, payload, .. } => Some((seq, payload[0])),
                _ => None,
            })
            .collect();
        assert_eq!(got, vec![(1, 0), (2, 1), (3, 2), (4, 3), (5, 4)]);
    }
}

// ---------------------------------------------------------------- helpers

fn hub_with(lane_msgs: usize, service_inflight: usize) -> Hub {
    Hub::new(HubLimits {
        service_inflight,
        ..limits(lane_msgs)
    })
}

fn sync_conn(hub: &Hub, name: &str) -> (ConnId, Arc<Outbox>) {
    let (id, ob) = hub.connect("test");
    hub.login(id, name, false);
    (id, ob)
}

fn admin_conn(hub: &Hub, name: &str) -> (ConnId, Arc<Outbox>) {
    let (id, ob) = hub.connect("test");
    hub.login(id, name, true);
    hub.set_async(id);
    (id, ob)
}

fn by_name(name: &str) -> ChanRef {
    ChanRef::Name(name.into())
}

fn stream(hub: &Hub, owner: ConnId, name: &str) -> ChanId {
    hub.add_channel(owner, ChannelKind::Stream, name, "{}")
        .expect("add stream")
        .id
}

fn service(hub: &Hub, owner: ConnId, name: &str) -> ChanId {
    hub.add_channel(owner, ChannelKind::Service, name, "{}")
        .expect("add service")
        .id
}

/// `(seq, first payload byte)` of every data event, in order.
fn data_seqs(events: &[Event]) -> Vec<u64> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Data { seq, .. } => Some(*seq),
            _ => None,
        })
        .collect()
}

fn code_of(result: HubResult<impl std::fmt::Debug>) -> ErrorCode {
    match result {
        Err(e) => e.code,
        Ok(v) => panic!("expected a refusal, got {v:?}"),
    }
}

/// The reply with request id `req` among `events`.
fn reply_for(events: &[Event], req: ReqId) -> Option<Result<Reply, ErrorReply>> {
    events.iter().find_map(|e| match e {
        Event::Reply { req: r, result } if *r == req => Some(result.clone()),
        _ => None,
    })
}

fn service_requests(events: &[Event]) -> Vec<(ChanId, CallId, Bytes)> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::ServiceRequest {
                chan,
                call,
                payload,
            } => Some((*chan, *call, payload.clone())),
            _ => None,
        })
        .collect()
}

// ---------------------------------------------------------------- channel events

#[test]
fn channel_events_reach_async_connections_only() {
    let hub = Hub::new(limits(8));
    let (owner, owner_ob) = async_conn(&hub, "owner");
    let (_other, other_ob) = async_conn(&hub, "other");
    let (_sync, sync_ob) = sync_conn(&hub, "sync");
    let info = hub
        .add_channel(
            owner,
            ChannelKind::Stream,
            "Robot.audio",
            r#"{"rate":22050}"#,
        )
        .expect("add");
    assert_eq!(info.owner, "owner#1");
    hub.set_header(owner, info.id, r#"{"rate":16000}"#)
        .expect("header");
    hub.remove_channel(owner, &by_name("Robot.audio"))
        .expect("remove");
    for ob in [&owner_ob, &other_ob] {
        let events = drain(ob);
        assert_eq!(
            events,
            vec![
                Event::ChannelAdded(info.clone()),
                Event::HeaderChanged {
                    id: info.id,
                    name: "Robot.audio".into(),
                    header: r#"{"rate":16000}"#.into()
                },
                Event::ChannelRemoved {
                    id: info.id,
                    name: "Robot.audio".into()
                },
            ]
        );
    }
    assert!(
        drain(&sync_ob).is_empty(),
        "a synchronous connection got events"
    );
}

#[test]
fn owner_hears_of_the_first_subscriber_and_the_last_one_leaving() {
    let hub = Hub::new(limits(8));
    let (owner, owner_ob) = async_conn(&hub, "owner");
    let id = stream(&hub, owner, "A");
    let (s1, _) = async_conn(&hub, "s1");
    let (s2, _) = async_conn(&hub, "s2");
    drain(&owner_ob);
    let only_publishing = |ob: &Outbox| -> Vec<Event> {
        drain(ob)
            .into_iter()
            .filter(|e| {
                matches!(
                    e,
                    Event::StartPublishing { .. } | Event::StopPublishing { .. }
                )
            })
            .collect()
    };
    hub.subscribe(s1, &by_name("A")).expect("s1");
    assert_eq!(
        only_publishing(&owner_ob),
        vec![Event::StartPublishing { id }]
    );
    // A second subscriber, and a repeated subscription, change nothing for the owner.
    hub.subscribe(s2, &ChanRef::Id(id)).expect("s2");
    hub.subscribe(s1, &by_name("A")).expect("s1 again");
    assert_eq!(only_publishing(&owner_ob), vec![]);
    assert_eq!(
        hub.channel(&by_name("A")).expect("info").stats.subscribers,
        2
    );
    hub.unsubscribe(s1, &by_name("A")).expect("s1 leaves");
    assert_eq!(only_publishing(&owner_ob), vec![]);
    // Unsubscribing when not subscribed is harmless and says nothing.
    hub.unsubscribe(s1, &by_name("A")).expect("s1 leaves twice");
    assert_eq!(only_publishing(&owner_ob), vec![]);
    // The last subscriber leaving by disconnecting counts as leaving.
    hub.disconnect(s2);
    assert_eq!(
        only_publishing(&owner_ob),
        vec![Event::StopPublishing { id }]
    );
    hub.subscribe(s1, &by_name("A")).expect("s1 returns");
    assert_eq!(
        only_publishing(&owner_ob),
        vec![Event::StartPublishing { id }]
    );
}

#[test]
fn data_has_one_sequence_and_timestamp_for_every_subscriber() {
    let hub = Hub::new(limits(64));
    let (p, _) = async_conn(&hub, "pub");
    let a = stream(&hub, p, "A");
    let b = stream(&hub, p, "B");
    let (s1, ob1) = async_conn(&hub, "s1");
    let (s2, ob2) = async_conn(&hub, "s2");
    for s in [s1, s2] {
        hub.subscribe(s, &by_name("A")).expect("sub A");
    }
    hub.subscribe(s1, &by_name("B")).expect("sub B");
    drain(&ob1);
    drain(&ob2);
    hub.publish(p, a, Bytes::from_static(b"a1")).expect("pub");
    hub.publish(p, b, Bytes::from_static(b"b1")).expect("pub");
    hub.publish(p, a, Bytes::from_static(b"a2")).expect("pub");
    let (e1, e2) = (drain(&ob1), drain(&ob2));
    let on = |events: &[Event], chan: ChanId| -> Vec<(u64, u64, Bytes)> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Data {
                    chan: c,
                    seq,
                    ts_us,
                    payload,
                } if *c == chan => Some((*seq, *ts_us, payload.clone())),
                _ => None,
            })
            .collect()
    };
    // Each channel counts from 1 on its own.
    assert_eq!(on(&e1, b).iter().map(|d| d.0).collect::<Vec<_>>(), vec![1]);
    assert_eq!(on(&e1, a), on(&e2, a));
    assert_eq!(
        on(&e1, a).iter().map(|d| d.0).collect::<Vec<_>>(),
        vec![1, 2]
    );
    assert!(on(&e1, a).iter().all(|d| d.1 > 1_600_000_000_000_000));
    assert!(
        on(&e2, b).is_empty(),
        "s2 got data of a channel it did not subscribe to"
    );
    let stats = hub.channel(&by_name("A")).expect("A").stats;
    assert_eq!((stats.msgs, stats.bytes, stats.dropped), (2, 4, 0));
}

// ---------------------------------------------------------------- ownership

#[test]
fn only_the_owner_publishes_changes_or_removes_and_an_admin_may_remove() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (intruder, _) = async_conn(&hub, "intruder");
    let (admin, _) = admin_conn(&hub, "admin");
    let id = stream(&hub, owner, "A");
    assert_eq!(
        code_of(hub.publish(intruder, id, Bytes::from_static(b"x"))),
        ErrorCode::NotOwner
    );
    assert_eq!(
        code_of(hub.set_header(intruder, id, "{}")),
        ErrorCode::NotOwner
    );
    assert_eq!(
        code_of(hub.remove_channel(intruder, &by_name("A"))),
        ErrorCode::NotOwner
    );
    assert_eq!(
        code_of(hub.remove_channel(intruder, &ChanRef::Id(id))),
        ErrorCode::NotOwner
    );
    // Admin rights cover removal, not publishing in someone else's name.
    assert_eq!(
        code_of(hub.publish(admin, id, Bytes::from_static(b"x"))),
        ErrorCode::NotOwner
    );
    assert_eq!(
        hub.channel(&by_name("A")).expect("still there").stats.msgs,
        0
    );
    hub.remove_channel(admin, &by_name("A"))
        .expect("admin removes");
    assert_eq!(code_of(hub.channel(&by_name("A"))), ErrorCode::NotFound);
    // The former owner no longer owns it: nothing is removed twice at disconnect.
    hub.disconnect(owner);
    assert!(hub.list_channels().is_empty());
}

#[test]
fn kinds_are_enforced() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (other, _) = async_conn(&hub, "other");
    let (sync, _) = sync_conn(&hub, "sync");
    let s = stream(&hub, owner, "S");
    let v = service(&hub, owner, "V");
    assert_eq!(
        code_of(hub.publish(owner, v, Bytes::new())),
        ErrorCode::WrongKind
    );
    assert_eq!(
        code_of(hub.subscribe(other, &by_name("V"))),
        ErrorCode::WrongKind
    );
    assert_eq!(
        code_of(hub.call(other, 1, &ChanRef::Id(s), Bytes::new(), T)),
        ErrorCode::WrongKind
    );
    // Synchronous connections get no events, so they can neither subscribe nor serve.
    assert_eq!(
        code_of(hub.subscribe(sync, &by_name("S"))),
        ErrorCode::BadRequest
    );
    assert_eq!(
        code_of(hub.add_channel(sync, ChannelKind::Service, "W", "{}")),
        ErrorCode::BadRequest
    );
}

#[test]
fn names_are_validated_and_unique() {
    let hub = Hub::new(HubLimits {
        max_channels: 3,
        ..limits(8)
    });
    let (c, _) = async_conn(&hub, "c");
    let too_long = "x".repeat(256);
    for bad in ["", "has space", "tab\there", "new\nline", too_long.as_str()] {
        assert_eq!(
            code_of(hub.add_channel(c, ChannelKind::Stream, bad, "{}")),
            ErrorCode::BadRequest,
            "{bad:?}"
        );
    }
    stream(&hub, c, "A");
    assert_eq!(
        code_of(hub.add_channel(c, ChannelKind::Service, "A", "{}")),
        ErrorCode::Exists
    );
    stream(&hub, c, "B");
    stream(&hub, c, &"x".repeat(255));
    assert_eq!(
        code_of(hub.add_channel(c, ChannelKind::Stream, "D", "{}")),
        ErrorCode::Limit
    );
    assert_eq!(
        code_of(hub.subscribe(c, &by_name("nope"))),
        ErrorCode::NotFound
    );
    assert_eq!(
        code_of(hub.subscribe(c, &ChanRef::Id(999))),
        ErrorCode::NotFound
    );
}

#[test]
fn ids_are_not_reused_and_names_follow_the_current_channel() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (sub, sub_ob) = async_conn(&hub, "sub");
    let mut seen = std::collections::HashSet::new();
    let mut last = None;
    for _ in 0..50 {
        let id = stream(&hub, owner, "A");
        assert!(seen.insert(id), "id {id} was reused");
        assert_eq!(hub.channel(&by_name("A")).expect("by name").id, id);
        assert_eq!(
            hub.channel(&ChanRef::Id(id)).expect("by id").hash,
            flow::protocol::channel_hash("A")
        );
        hub.remove_channel(owner, &ChanRef::Id(id)).expect("remove");
        last = Some(id);
    }
    let old = last.expect("ran");
    let new = stream(&hub, owner, "A");
    // The old id names nothing: late messages for it cannot land on the new channel.
    assert_eq!(
        code_of(hub.publish(owner, old, Bytes::new())),
        ErrorCode::NotFound
    );
    assert_eq!(
        code_of(hub.subscribe(sub, &ChanRef::Id(old))),
        ErrorCode::NotFound
    );
    assert_eq!(hub.subscribe(sub, &by_name("A")).expect("sub").id, new);
    drain(&sub_ob);
    hub.publish(owner, new, Bytes::from_static(b"n"))
        .expect("pub");
    assert_eq!(data_seqs(&drain(&sub_ob)), vec![1]);
}

// ---------------------------------------------------------------- slow subscribers

#[test]
fn a_subscriber_that_never_reads_loses_its_oldest_while_another_gets_everything() {
    let hub = Hub::new(limits(8));
    let (p, _) = async_conn(&hub, "pub");
    let id = stream(&hub, p, "Robot.video");
    let (slow, slow_ob) = async_conn(&hub, "slow");
    let (fast, fast_ob) = async_conn(&hub, "fast");
    hub.subscribe(slow, &by_name("Robot.video")).expect("slow");
    hub.subscribe(fast, &by_name("Robot.video")).expect("fast");
    drain(&slow_ob);
    drain(&fast_ob);
    let mut fast_seqs = Vec::new();
    for i in 0..1000u32 {
        // Publishing never fails or waits, however far behind `slow` is.
        hub.publish(p, id, Bytes::from(i.to_le_bytes().to_vec()))
            .expect("publish");
        fast_seqs.extend(data_seqs(&drain(&fast_ob)));
    }
    assert_eq!(fast_seqs, (1..=1000).collect::<Vec<_>>());
    // The slow one keeps only the newest `lane_msgs` messages, in order.
    assert_eq!(
        data_seqs(&drain(&slow_ob)),
        (993..=1000).collect::<Vec<_>>()
    );
    let stats = hub.channel(&by_name("Robot.video")).expect("info").stats;
    assert_eq!(stats.dropped, 992);
    assert_eq!(stats.msgs, 1000);
    assert!(
        slow_ob.closed().is_none(),
        "data overflow must not close the connection"
    );
}

#[test]
fn the_byte_cap_drops_oldest_but_keeps_the_newest_message() {
    let hub = Hub::new(HubLimits {
        outbox: OutboxLimits {
            lane_msgs: 1000,
            lane_bytes: 1000,
            control_msgs: 64,
        },
        ..limits(8)
    });
    let (p, _) = async_conn(&hub, "pub");
    let id = stream(&hub, p, "A");
    let (s, ob) = async_conn(&hub, "s");
    hub.subscribe(s, &by_name("A")).expect("sub");
    drain(&ob);
    for _ in 0..10 {
        hub.publish(p, id, Bytes::from(vec![0u8; 300]))
            .expect("pub");
    }
    // Three 300-byte messages fit in 1000 bytes.
    assert_eq!(data_seqs(&drain(&ob)), vec![8, 9, 10]);
    hub.publish(p, id, Bytes::from(vec![0u8; 5000]))
        .expect("pub");
    hub.publish(p, id, Bytes::from(vec![0u8; 5000]))
        .expect("pub");
    assert_eq!(data_seqs(&drain(&ob)), vec![12]);
    assert_eq!(
        hub.channel(&ChanRef::Id(id)).expect("info").stats.dropped,
        8
    );
}

#[test]
fn a_connection_that_reads_no_control_events_is_closed_alone() {
    let hub = Hub::new(HubLimits {
        outbox: OutboxLimits {
            lane_msgs: 8,
            lane_bytes: 1 << 20,
            control_msgs: 16,
        },
        ..limits(8)
    });
    let (deaf, deaf_ob) = async_conn(&hub, "deaf");
    let (busy, busy_ob) = async_conn(&hub, "busy");
    for i in 0..40 {
        stream(&hub, busy, &format!("C{i}"));
        drain(&busy_ob);
    }
    let reason = deaf_ob.closed().expect("deaf connection closed");
    assert!(reason.contains("control queue overflow"), "{reason}");
    assert!(busy_ob.closed().is_none());
    // The transport driver disconnects it; everyone else carries on.
    hub.disconnect(deaf);
    assert_eq!(hub.list_channels().len(), 40);
}

// ---------------------------------------------------------------- disconnects

#[test]
fn disconnect_removes_channels_tells_everyone_and_fails_pending_calls() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (sub, sub_ob) = async_conn(&hub, "sub");
    let (caller, caller_ob) = sync_conn(&hub, "caller");
    let s = stream(&hub, owner, "S");
    let v = service(&hub, owner, "V");
    hub.subscribe(sub, &by_name("S")).expect("sub");
    hub.publish(owner, s, Bytes::from_static(b"queued"))
        .expect("pub");
    hub.call(caller, 77, &by_name("V"), Bytes::from_static(b"req"), T)
        .expect("call");
    assert_eq!(data_seqs(&drain(&sub_ob)), vec![1]);
    hub.publish(owner, s, Bytes::from_static(b"never read"))
        .expect("pub");
    hub.disconnect(owner);
    assert!(hub.list_channels().is_empty());
    let sub_events = drain(&sub_ob);
    // Data the subscriber had queued was published before the removal: it is
    // still delivered, and the removal of its channel comes after it.
    assert_eq!(data_seqs(&sub_events), vec![2], "{sub_events:?}");
    let data_at = sub_events
        .iter()
        .position(|e| matches!(e, Event::Data { .. }));
    let removed_at = sub_events
        .iter()
        .position(|e| matches!(e, Event::ChannelRemoved { id, .. } if *id == s));
    assert!(data_at < removed_at, "{sub_events:?}");
    for (id, name) in [(s, "S"), (v, "V")] {
        assert!(
            sub_events.contains(&Event::ChannelRemoved {
                id,
                name: name.into()
            }),
            "{sub_events:?}"
        );
    }
    let reply = reply_for(&drain(&caller_ob), 77).expect("the caller got an answer");
    assert_eq!(reply.expect_err("failed").code, ErrorCode::ServiceGone);
    // Calls to the gone service now fail at once, and the subscription is over.
    assert_eq!(
        code_of(hub.call(caller, 78, &by_name("V"), Bytes::new(), T)),
        ErrorCode::NotFound
    );
    assert_eq!(
        code_of(hub.unsubscribe(sub, &by_name("S"))),
        ErrorCode::NotFound
    );
    assert_eq!(hub.connection_count(), 2);
}

#[test]
fn a_re_created_channel_has_no_subscribers_from_before() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (sub, sub_ob) = async_conn(&hub, "sub");
    stream(&hub, owner, "A");
    hub.subscribe(sub, &by_name("A")).expect("sub");
    hub.disconnect(owner);
    let (owner2, owner2_ob) = async_conn(&hub, "owner2");
    let id = stream(&hub, owner2, "A");
    hub.publish(owner2, id, Bytes::from_static(b"x"))
        .expect("pub");
    assert!(data_seqs(&drain(&sub_ob)).is_empty());
    assert_eq!(hub.channel(&by_name("A")).expect("A").stats.subscribers, 0);
    // Subscribing again works and tells the new owner.
    hub.subscribe(sub, &by_name("A")).expect("again");
    assert!(drain(&owner2_ob).contains(&Event::StartPublishing { id }));
}

#[test]
fn a_caller_going_away_leaves_the_service_working() {
    let hub = hub_with(8, 1);
    let (owner, owner_ob) = async_conn(&hub, "owner");
    let (caller, _) = sync_conn(&hub, "caller");
    service(&hub, owner, "V");
    let call = hub
        .call(caller, 1, &by_name("V"), Bytes::from_static(b"q"), T)
        .expect("call");
    hub.disconnect(caller);
    // The owner's late answer is accepted quietly.
    hub.respond(owner, call, Ok(Bytes::from_static(b"a")))
        .expect("respond");
    // The in-flight slot was released: a new caller is not told "overloaded".
    let (caller2, caller2_ob) = sync_conn(&hub, "caller2");
    let call2 = hub
        .call(caller2, 2, &by_name("V"), Bytes::new(), T)
        .expect("slot free again");
    assert_eq!(service_requests(&drain(&owner_ob)).len(), 2);
    hub.respond(owner, call2, Ok(Bytes::from_static(b"b")))
        .expect("respond");
    assert_eq!(
        reply_for(&drain(&caller2_ob), 2),
        Some(Ok(Reply::Payload(Bytes::from_static(b"b"))))
    );
}

#[test]
fn shutdown_says_goodbye_to_everyone() {
    let hub = Hub::new(limits(8));
    let (_a, a_ob) = async_conn(&hub, "a");
    let (_b, b_ob) = sync_conn(&hub, "b");
    hub.shutdown("server shutting down");
    for ob in [&a_ob, &b_ob] {
        assert_eq!(
            drain(ob),
            vec![Event::Goodbye {
                reason: "server shutting down".into()
            }]
        );
        assert!(ob.closed().is_some());
    }
}

// ---------------------------------------------------------------- services

#[test]
fn service_calls_are_answered_to_the_right_caller() {
    let hub = Hub::new(limits(8));
    let (owner, owner_ob) = async_conn(&hub, "owner");
    let (sync_caller, sync_ob) = sync_conn(&hub, "sync-caller");
    let (async_caller, async_ob) = async_conn(&hub, "async-caller");
    let v = service(&hub, owner, "Robot.move");
    drain(&owner_ob);
    drain(&async_ob);
    let c1 = hub
        .call(
            sync_caller,
            10,
            &by_name("Robot.move"),
            Bytes::from_static(b"{\"x\":1}"),
            T,
        )
        .expect("call 1");
    let c2 = hub
        .call(
            async_caller,
            10,
            &ChanRef::Id(v),
            Bytes::from_static(b"{\"x\":2}"),
            T,
        )
        .expect("call 2");
    assert_ne!(c1, c2);
    assert_eq!(
        service_requests(&drain(&owner_ob)),
        vec![
            (v, c1, Bytes::from_static(b"{\"x\":1}")),
            (v, c2, Bytes::from_static(b"{\"x\":2}"))
        ]
    );
    // Answers in the opposite order still reach their own callers.
    hub.respond(owner, c2, Err("cannot move there".into()))
        .expect("respond 2");
    hub.respond(owner, c1, Ok(Bytes::from_static(b"{\"ok\":true}")))
        .expect("respond 1");
    assert_eq!(
        drain(&sync_ob),
        vec![Event::Reply {
            req: 10,
            result: Ok(Reply::Payload(Bytes::from_static(b"{\"ok\":true}")))
        }]
    );
    let failed = reply_for(&drain(&async_ob), 10)
        .expect("reply")
        .expect_err("service error");
    assert_eq!(failed.code, ErrorCode::ServiceFailed);
    assert_eq!(failed.message, "cannot move there");
    // A second answer to the same call is ignored, not delivered twice.
    hub.respond(owner, c1, Ok(Bytes::from_static(b"again")))
        .expect("duplicate");
    assert!(drain(&sync_ob).is_empty());
    let stats = hub.channel(&ChanRef::Id(v)).expect("info").stats;
    assert_eq!(stats.msgs, 2);
}

#[test]
fn only_the_service_owner_may_respond() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (caller, caller_ob) = sync_conn(&hub, "caller");
    let (forger, _) = async_conn(&hub, "forger");
    service(&hub, owner, "V");
    let call = hub
        .call(caller, 5, &by_name("V"), Bytes::new(), T)
        .expect("call");
    assert_eq!(
        code_of(hub.respond(forger, call, Ok(Bytes::from_static(b"forged")))),
        ErrorCode::NotOwner
    );
    assert!(drain(&caller_ob).is_empty());
    hub.respond(owner, call, Ok(Bytes::from_static(b"real")))
        .expect("respond");
    assert_eq!(
        reply_for(&drain(&caller_ob), 5),
        Some(Ok(Reply::Payload(Bytes::from_static(b"real"))))
    );
}

#[test]
fn an_unanswered_call_times_out_once() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (caller, caller_ob) = sync_conn(&hub, "caller");
    service(&hub, owner, "Slow.svc");
    let start = Instant::now();
    let call = hub
        .call(caller, 3, &by_name("Slow.svc"), Bytes::new(), 250)
        .expect("call");
    // Before its deadline the call stays pending, and the hub says when to look again.
    let next = hub.expire_due(start).expect("a deadline");
    assert!(next >= start + Duration::from_millis(250), "{next:?}");
    assert!(drain(&caller_ob).is_empty());
    assert_eq!(hub.expire_due(next), None);
    let err = reply_for(&drain(&caller_ob), 3)
        .expect("reply")
        .expect_err("timeout");
    assert_eq!(err.code, ErrorCode::Timeout);
    assert!(
        err.message.contains("Slow.svc") && err.message.contains("250 ms"),
        "{}",
        err.message
    );
    // The owner's late answer and a second expiry both go nowhere.
    hub.respond(owner, call, Ok(Bytes::from_static(b"late")))
        .expect("late");
    assert_eq!(hub.expire_due(next + Duration::from_secs(1)), None);
    assert!(drain(&caller_ob).is_empty());
}

#[test]
fn a_timeout_out_of_range_is_clamped() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (caller, caller_ob) = sync_conn(&hub, "caller");
    service(&hub, owner, "V");
    hub.call(caller, 1, &by_name("V"), Bytes::new(), 0)
        .expect("zero");
    hub.call(caller, 2, &by_name("V"), Bytes::new(), u32::MAX)
        .expect("huge");
    // A zero timeout waits 1 ms; a huge one at most MAX_CALL_TIMEOUT_MS.
    let now = Instant::now();
    let longest = now + Duration::from_millis(u64::from(MAX_CALL_TIMEOUT_MS));
    let next = hub
        .expire_due(now + Duration::from_millis(1))
        .expect("the long call is left");
    assert!(next <= longest, "{next:?}");
    assert!(reply_for(&drain(&caller_ob), 1).is_some_and(|r| r.is_err()));
    assert_eq!(hub.expire_due(next), None);
    let err = reply_for(&drain(&caller_ob), 2)
        .expect("reply")
        .expect_err("timeout");
    assert!(err.message.contains("600000 ms"), "{}", err.message);
}

/// A hub whose outboxes hold `n` control events, for floods of calls.
fn roomy_hub(n: usize) -> Hub {
    Hub::new(HubLimits {
        outbox: OutboxLimits {
            control_msgs: n + 16,
            ..limits(8).outbox
        },
        service_inflight: n,
        max_channels: MAX_CHANNELS,
    })
}

#[tokio::test(flavor = "current_thread")]
async fn ten_thousand_calls_answered_at_once_leave_no_deadline_and_one_timer_behind() {
    const N: u32 = 10_000;
    let hub = roomy_hub(N as usize);
    let (owner, owner_ob) = async_conn(&hub, "owner");
    let (caller, caller_ob) = sync_conn(&hub, "caller");
    service(&hub, owner, "V");
    drain(&owner_ob);
    let tasks_before = tokio::runtime::Handle::current()
        .metrics()
        .num_alive_tasks();
    for req in 1..=N {
        hub.call(caller, req, &by_name("V"), Bytes::new(), T)
            .expect("call");
    }
    // However many calls wait, the hub keeps one timer task, not one per call.
    assert_eq!(hub.timer.tasks(), 1);
    assert_eq!(
        tokio::runtime::Handle::current()
            .metrics()
            .num_alive_tasks(),
        tasks_before + 1
    );
    assert_eq!(hub.lock().deadlines.len(), N as usize);
    for (_, call, _) in service_requests(&drain(&owner_ob)) {
        hub.respond(owner, call, Ok(Bytes::new())).expect("respond");
    }
    assert!(hub.lock().deadlines.is_empty());
    assert!(hub.lock().calls.is_empty());
    let replies = drain(&caller_ob);
    assert_eq!(replies.len(), N as usize);
    assert!((1..=N).all(|req| reply_for(&replies, req).is_some_and(|r| r.is_ok())));
    // Nothing is left to expire, and the answered calls' deadlines never fire.
    assert_eq!(
        hub.expire_due(Instant::now() + Duration::from_secs(3600)),
        None
    );
    assert!(drain(&caller_ob).is_empty());
    // The timer goes with its hub.
    drop(hub);
    tokio::task::yield_now().await;
    assert_eq!(
        tokio::runtime::Handle::current()
            .metrics()
            .num_alive_tasks(),
        tasks_before
    );
}

#[tokio::test(flavor = "current_thread")]
async fn the_timer_task_fails_a_call_exactly_once_even_behind_a_longer_one() {
    let hub = Hub::new(limits(8));
    let (owner, _) = async_conn(&hub, "owner");
    let (caller, caller_ob) = sync_conn(&hub, "caller");
    service(&hub, owner, "V");
    // The timer first sleeps until the long call's deadline; the short call
    // made after it must wake it to sleep less.
    hub.call(caller, 1, &by_name("V"), Bytes::new(), T)
        .expect("long call");
    tokio::task::yield_now().await;
    let short = hub
        .call(caller, 2, &by_name("V"), Bytes::new(), 20)
        .expect("short call");
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut replies = Vec::new();
    while replies.is_empty() && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(5)).await;
        replies = drain(&caller_ob);
    }
    let err = reply_for(&replies, 2)
        .expect("the short call timed out")
        .expect_err("timeout");
    assert_eq!(err.code, ErrorCode::Timeout);
    assert_eq!(replies.len(), 1, "{replies:?}");
    // Later wake-ups, a late answer: nothing more for the caller.
    tokio::time::sleep(Duration::from_millis(50)).await;
    hub.respond(owner, short, Ok(Bytes::new())).expect("late");
    assert!(drain(&caller_ob).is_empty());
    assert_eq!(hub.lock().deadlines.len(), 1);
}

#[test]
fn too_many_calls_in_flight_are_refused_as_overloaded() {
    let hub = hub_with(8, 4);
    let (owner, owner_ob) = async_conn(&hub, "owner");
    let (caller, caller_ob) = sync_conn(&hub, "caller");
    service(&hub, owner, "V");
    // Call 2 may wait less than the others, so it alone can be expired below.
    let calls: Vec<CallId> = (1..=4)
        .map(|req| {
            let timeout = if req == 2 { 100 } else { T };
            hub.call(caller, req, &by_name("V"), Bytes::new(), timeout)
                .expect("call")
        })
        .collect();
    let refused = hub
        .call(caller, 99, &by_name("V"), Bytes::new(), T)
        .expect_err("fifth call");
    assert_eq!(refused.code, ErrorCode::Overloaded);
    assert!(
        refused.message.contains("4 calls in flight"),
        "{}",
        refused.message
    );
    // The refused call never reached the owner.
    assert_eq!(service_requests(&drain(&owner_ob)).len(), 4);
    // An answer and an expiry each free a slot.
    hub.respond(owner, calls[0], Ok(Bytes::new()))
        .expect("respond");
    hub.expire_due(Instant::now() + Duration::from_millis(100));
    hub.call(caller, 100, &by_name("V"), Bytes::new(), T)
        .expect("slot 1");
    hub.call(caller, 101, &by_name("V"), Bytes::new(), T)
        .expect("slot 2");
    assert_eq!(
        code_of(hub.call(caller, 102, &by_name("V"), Bytes::new(), T)),
        ErrorCode::Overloaded
    );
    let replies = drain(&caller_ob);
    assert!(reply_for(&replies, 1).expect("answered").is_ok());
    assert_eq!(
        reply_for(&replies, 2)
            .expect("expired")
            .expect_err("timeout")
            .code,
        ErrorCode::Timeout
    );
}

#[test]
fn a_call_to_an_owner_that_stopped_reading_fails_as_gone() {
    let hub = Hub::new(limits(8));
    let (owner, owner_ob) = async_conn(&hub, "owner");
    let (caller, _) = sync_conn(&hub, "caller");
    service(&hub, owner, "V");
    owner_ob.close("write failed");
    assert_eq!(
        code_of(hub.call(caller, 1, &by_name("V"), Bytes::new(), T)),
        ErrorCode::ServiceGone
    );
    // The failed call does not hold an in-flight slot.
    let limit = limits(8).service_inflight;
    for i in 0..limit as u32 * 2 {
        assert_eq!(
            code_of(hub.call(caller, i, &by_name("V"), Bytes::new(), T)),
            ErrorCode::ServiceGone
        );
    }
}

#[test]
fn the_graph_has_every_connection_and_an_edge_per_channel_to_its_subscribers() {
    let hub = Hub::new(limits(64));
    let (camera, _) = hub.connect("ws:127.0.0.1:5000");
    hub.login(camera, "browser", false);
    let (vision, _) = hub.connect("module:vision");
    hub.login(vision, "vision", false);
    hub.set_async(vision);
    let (ears, _) = hub.connect("tcp:127.0.0.1:6000");
    hub.login(ears, "whisper-sat", false);
    hub.set_async(ears);
    hub.add_channel(
        camera,
        ChannelKind::Stream,
        "Cam.video",
        r#"{"format":"jpeg"}"#,
    )
    .expect("add video");
    hub.add_channel(camera, ChannelKind::Stream, "Cam.audio", "{}")
        .expect("add audio");
    hub.add_channel(ears, ChannelKind::Service, "Ears.submit", "{}")
        .expect("add service");
    hub.subscribe(vision, &ChanRef::Name("Cam.video".into()))
        .expect("vision subscribes");
    hub.subscribe(ears, &ChanRef::Name("Cam.audio".into()))
        .expect("ears subscribe");
    let g = hub.graph();
    let names: Vec<_> = g
        .nodes
        .iter()
        .map(|n| (n.name.as_str(), n.transport.as_str()))
        .collect();
    assert_eq!(
        names,
        vec![
            ("browser", "ws"),
            ("vision", "module"),
            ("whisper-sat", "tcp")
        ]
    );
    let edges: Vec<_> = g
        .channels
        .iter()
        .map(|c| (c.name.as_str(), c.kind, c.from, c.to.clone()))
        .collect();
    assert_eq!(
        edges,
        vec![
            ("Cam.audio", "stream", camera, vec![ears]),
            ("Cam.video", "stream", camera, vec![vision]),
            ("Ears.submit", "service", ears, vec![]),
        ]
    );
    // The page's layout tests read this very snapshot.
    let value = serde_json::to_value(&g).expect("graph as JSON");
    agent_contract::vectors::check_or_write("graph", &value)
        .expect("crates/contract/vectors/graph.json");
}

#[test]
fn call_outcomes_are_counted_by_service_and_kept_after_it_goes() {
    let hub = Hub::new(limits(64));
    let (owner, owner_box) = async_conn(&hub, "svc");
    let (caller, _) = async_conn(&hub, "caller");
    hub.add_channel(owner, ChannelKind::Service, "S", "{}")
        .expect("add");
    let name = ChanRef::Name("S".into());
    let ok = hub.call(caller, 1, &name, Bytes::new(), T).expect("call 1");
    hub.respond(owner, ok, Ok(Bytes::new())).expect("answer");
    let bad = hub.call(caller, 2, &name, Bytes::new(), T).expect("call 2");
    hub.respond(owner, bad, Err("no".into())).expect("refuse");
    hub.call(caller, 3, &name, Bytes::new(), 1).expect("call 3");
    hub.expire_due(Instant::now() + Duration::from_secs(1));
    hub.call(caller, 4, &name, Bytes::new(), T).expect("call 4");
    drain(&owner_box);
    hub.disconnect(owner);
    let calls = hub.service_calls();
    assert_eq!(calls.len(), 1);
    assert_eq!(
        calls[0].1,
        CallOutcomes {
            answered: 1,
            failed: 1,
            timeout: 1,
            gone: 1,
            overloaded: 0
        }
    );
    assert_eq!(calls[0].0, "S");
}

#[test]
fn a_subscription_is_acknowledged_before_its_first_message_can_be_queued() {
    let hub = Hub::new(limits(64));
    let (p, _) = async_conn(&hub, "pub");
    let id = stream(&hub, p, "A");
    let (s, ob) = async_conn(&hub, "s");
    hub.subscribe_acked(s, &by_name("A"), 7).expect("sub");
    // The reply is already queued when the owner could first publish, so no data event can overtake it.
    let queued = drain(&ob);
    assert!(
        matches!(queued.as_slice(), [Event::Reply { req: 7, result: Ok(Reply::Channel(info)) }] if info.id == id),
        "{queued:?}"
    );
    hub.publish(p, id, Bytes::from_static(b"x")).expect("pub");
    assert_eq!(data_seqs(&drain(&ob)), vec![1]);
}
