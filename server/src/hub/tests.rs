//! Unit tests of the hub core's semantics, driven without any socket.

use super::*;

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
