//! Random FlowProtocol values for round-trip tests: every command, event and
//! reply variant, with strings that include multi-byte characters and payloads
//! of random sizes.

// Each test file uses a different part of this module.
#![allow(dead_code)]

use bytes::Bytes;
use flow::protocol::{
    ChanRef, ChannelInfo, ChannelKind, ChannelStats, Command, Envelope, ErrorCode, ErrorReply,
    Event, Reply, SegmentInfo, SlotRef,
};
use rand::Rng;
use rand::rngs::StdRng;

/// Number of `Command` variants; `command` picks one of them by index.
pub const COMMAND_VARIANTS: usize = 25;
/// Number of `Event` variants plus reply kinds, so every reply shape is drawn often.
pub const EVENT_VARIANTS: usize = 24;

/// A string of up to `max` characters mixing ASCII, accented letters, CJK and emoji.
pub fn string(rng: &mut StdRng, max: usize) -> String {
    let len = rng.random_range(0..=max);
    (0..len)
        .map(|_| match rng.random_range(0..4) {
            0 => char::from(rng.random_range(b' '..=b'~')),
            1 => rng.random_range('à'..='ÿ'),
            2 => rng.random_range('一'..='龥'),
            _ => rng.random_range('😀'..='🙏'),
        })
        .collect()
}

/// A JSON-looking text; the codec carries any UTF-8, so only the shape matters.
pub fn text(rng: &mut StdRng) -> String {
    format!(
        "{{\"k\":\"{}\",\"n\":{}}}",
        string(rng, 20),
        rng.random::<u32>()
    )
}

pub fn payload(rng: &mut StdRng) -> Bytes {
    // Mostly small, sometimes a video-frame-sized payload.
    let len = if rng.random_ratio(1, 20) {
        rng.random_range(10_000..200_000)
    } else {
        rng.random_range(0..300)
    };
    let mut v = vec![0u8; len];
    rng.fill(&mut v[..]);
    Bytes::from(v)
}

pub fn chan_id(rng: &mut StdRng) -> i16 {
    rng.random_range(0..=i16::MAX)
}

pub fn chan_ref(rng: &mut StdRng) -> ChanRef {
    if rng.random() {
        ChanRef::Id(chan_id(rng))
    } else {
        ChanRef::Name(string(rng, 40))
    }
}

pub fn kind(rng: &mut StdRng) -> ChannelKind {
    if rng.random() {
        ChannelKind::Stream
    } else {
        ChannelKind::Service
    }
}

/// Finite floats only: NaN would make `PartialEq` fail on a perfect round trip.
fn finite_f32(rng: &mut StdRng) -> f32 {
    rng.random_range(-1e9f32..1e9f32)
}

pub fn channel_info(rng: &mut StdRng) -> ChannelInfo {
    ChannelInfo {
        id: chan_id(rng),
        hash: rng.random(),
        kind: kind(rng),
        name: string(rng, 40),
        owner: string(rng, 40),
        header: text(rng),
        stats: ChannelStats {
            subscribers: rng.random(),
            msgs: rng.random(),
            bytes: rng.random(),
            dropped: rng.random(),
            msgs_per_s: finite_f32(rng),
            bytes_per_s: finite_f32(rng),
        },
    }
}

pub fn error_reply(rng: &mut StdRng) -> ErrorReply {
    ErrorReply::new(
        ErrorCode::ALL[rng.random_range(0..ErrorCode::ALL.len())],
        string(rng, 60),
    )
}

/// The `variant`-th command shape (modulo the number of variants) with random contents.
pub fn command(rng: &mut StdRng, variant: usize) -> Command {
    match variant % COMMAND_VARIANTS {
        0 => Command::Login {
            version: rng.random(),
            token: string(rng, 64),
            name: string(rng, 40),
        },
        1 => Command::SetAsync,
        2 => Command::AddChannel {
            kind: kind(rng),
            name: string(rng, 40),
            header: text(rng),
        },
        3 => Command::RemoveChannel {
            chan: chan_ref(rng),
        },
        4 => Command::SetHeader {
            chan: chan_id(rng),
            header: text(rng),
        },
        5 => Command::Subscribe {
            chan: chan_ref(rng),
        },
        6 => Command::Unsubscribe {
            chan: chan_ref(rng),
        },
        7 => Command::Publish {
            chan: chan_id(rng),
            payload: payload(rng),
        },
        8 => Command::Call {
            chan: chan_ref(rng),
            timeout_ms: rng.random(),
            payload: payload(rng),
        },
        9 => Command::Respond {
            call: rng.random(),
            result: if rng.random() {
                Ok(payload(rng))
            } else {
                Err(string(rng, 80))
            },
        },
        10 => Command::ListChannels,
        11 => Command::GetChannel {
            chan: chan_ref(rng),
        },
        12 => Command::DbSelect {
            name: string(rng, 30),
        },
        13 => Command::DbCreate {
            name: string(rng, 30),
        },
        14 => Command::DbRemove {
            name: string(rng, 30),
        },
        15 => Command::DbList,
        16 => Command::VarSet {
            key: string(rng, 30),
            value: text(rng),
        },
        17 => Command::VarGet {
            key: string(rng, 30),
        },
        18 => Command::VarDel {
            key: string(rng, 30),
        },
        19 => Command::VarList,
        20 => Command::ShmAccept,
        21 => Command::ShmOpen {
            chan: chan_id(rng),
            slot_size: rng.random(),
        },
        22 => Command::PublishRef {
            chan: chan_id(rng),
            slot: slot_ref(rng),
        },
        23 => {
            let n = rng.random_range(0..20);
            Command::Release {
                slots: (0..n).map(|_| slot_ref(rng)).collect(),
            }
        }
        _ => Command::Ping,
    }
}

pub fn envelope(rng: &mut StdRng, variant: usize) -> Envelope {
    Envelope {
        req: rng.random(),
        command: command(rng, variant),
    }
}

fn slot_ref(rng: &mut StdRng) -> SlotRef {
    SlotRef {
        segment: rng.random(),
        slot: rng.random(),
        len: rng.random(),
    }
}

fn segment_info(rng: &mut StdRng) -> SegmentInfo {
    SegmentInfo {
        id: rng.random(),
        chan: chan_id(rng),
        slots: rng.random(),
        slot_size: rng.random(),
    }
}

fn reply(rng: &mut StdRng, variant: usize) -> Reply {
    match variant % 10 {
        0 => Reply::Done,
        1 => Reply::LoginOk {
            version: rng.random(),
            conn: rng.random(),
            admin: rng.random(),
            server: string(rng, 30),
        },
        2 => Reply::Channel(channel_info(rng)),
        3 => {
            let n = rng.random_range(0..20);
            Reply::Channels((0..n).map(|_| channel_info(rng)).collect())
        }
        4 => Reply::Value(text(rng)),
        5 => {
            let n = rng.random_range(0..30);
            Reply::Names((0..n).map(|_| string(rng, 20)).collect())
        }
        6 => Reply::Payload(payload(rng)),
        7 => Reply::Pong,
        8 => Reply::Shm {
            threshold: rng.random(),
        },
        _ => Reply::Segment(segment_info(rng)),
    }
}

/// The `variant`-th event shape (replies count as eleven shapes: ten successes and an error).
pub fn event(rng: &mut StdRng, variant: usize) -> Event {
    match variant % EVENT_VARIANTS {
        v @ 18..=19 => Event::Reply {
            req: rng.random(),
            result: Ok(reply(rng, v - 10)),
        },
        20 => Event::Segment(segment_info(rng)),
        21 => Event::DataRef {
            chan: chan_id(rng),
            seq: rng.random(),
            ts_us: rng.random(),
            slot: slot_ref(rng),
        },
        23 => Event::ReleaseRing {
            capacity: rng.random(),
        },
        v @ 0..=7 => Event::Reply {
            req: rng.random(),
            result: Ok(reply(rng, v)),
        },
        8 => Event::Reply {
            req: rng.random(),
            result: Err(error_reply(rng)),
        },
        9 => Event::ChannelAdded(channel_info(rng)),
        10 => Event::ChannelRemoved {
            id: chan_id(rng),
            name: string(rng, 40),
        },
        11 => Event::HeaderChanged {
            id: chan_id(rng),
            name: string(rng, 40),
            header: text(rng),
        },
        12 => Event::StartPublishing { id: chan_id(rng) },
        13 => Event::StopPublishing { id: chan_id(rng) },
        14 => Event::ServiceRequest {
            chan: chan_id(rng),
            call: rng.random(),
            payload: payload(rng),
        },
        15 => Event::Data {
            chan: chan_id(rng),
            seq: rng.random(),
            ts_us: rng.random(),
            payload: payload(rng),
        },
        16 => Event::DbChanged {
            name: string(rng, 30),
        },
        17 => Event::Goodbye {
            reason: string(rng, 80),
        },
        _ => Event::Data {
            chan: chan_id(rng),
            seq: rng.random(),
            ts_us: rng.random(),
            payload: Bytes::new(),
        },
    }
}
