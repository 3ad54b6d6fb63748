//! Round trips through a real file: what the sink writes, the reader reads back and the encodings restore, also
//! from a file cut short.

use bytes::Bytes;
use flow::{ChannelInfo, ChannelKind, ChannelStats, Data};

use crate::encoding;
use crate::reader::{Entry, RecordingReader};
use crate::sink::{META_HEADER, Sink, SinkOptions};

fn info(id: i16, name: &str, header: &str) -> ChannelInfo {
    ChannelInfo {
        id,
        hash: 0,
        kind: ChannelKind::Stream,
        name: name.into(),
        owner: "test#1".into(),
        header: header.into(),
        stats: ChannelStats::default(),
    }
}

fn data(seq: u64, payload: &[u8]) -> Data {
    Data {
        channel: 1,
        seq,
        ts_us: 1_000_000 + seq * 20_000,
        payload: Bytes::copy_from_slice(payload),
    }
}

/// Writes 40 messages on a JSON, a PCM and a binary channel, in chunks of a few kB.
fn write(path: &std::path::Path, finish: bool) -> Vec<(String, Vec<u8>)> {
    let opts = SinkOptions { chunk_bytes: 4096 };
    let mut sink = Sink::create(path, &opts).expect("creates");
    sink.channel(info(1, "T.json", r#"{"format":"json"}"#));
    sink.channel(info(2, "T.pcm", r#"{"format":"s16le","rate":16000}"#));
    sink.channel(info(3, "T.bin", "{}"));
    let mut sent = Vec::new();
    for seq in 1..=40u64 {
        for (name, payload) in [
            ("T.json", format!(r#"{{"n":{seq}}}"#).into_bytes()),
            ("T.pcm", vec![seq as u8; 320]),
            ("T.bin", vec![0xff, seq as u8, 0]),
        ] {
            sink.message(name, &data(seq, &payload), seq * 1000)
                .expect("writes");
            sent.push((name.to_string(), payload));
        }
        if seq == 20 {
            sink.flush().expect("flushes");
        }
    }
    // The non-JSON message on the JSON channel goes to its raw fallback, unchanged.
    sink.message("T.json", &data(41, b"\x00oops"), 41_000)
        .expect("writes");
    sent.push(("T.json".into(), b"\x00oops".to_vec()));
    if finish {
        let report = sink.finish().expect("finishes");
        assert_eq!(report.channels["T.json"].raw_fallback, 1);
        assert_eq!(report.channels["T.pcm"].messages, 40);
    } else {
        // A crash: the writer is never finished (and its buffers never flushed).
        std::mem::forget(sink);
    }
    sent
}

fn read(path: &std::path::Path) -> (Vec<(String, Vec<u8>)>, Option<String>) {
    let mut reader = RecordingReader::open(path).expect("opens");
    let mut channels = std::collections::HashMap::new();
    let mut got = Vec::new();
    while let Some(entry) = reader.next_entry().expect("reads") {
        match entry {
            Entry::Channel(c) => {
                assert!(c.metadata.contains_key(META_HEADER));
                channels.insert(c.id, c);
            }
            Entry::Message(m) => {
                let c = &channels[&m.channel];
                let payload = encoding::decode(&c.message_encoding, c.schema.as_deref(), &m.data)
                    .expect("decodes");
                got.push((c.topic.clone(), payload));
            }
        }
    }
    (got, reader.truncated().map(str::to_string))
}

#[test]
fn every_payload_comes_back_byte_for_byte_from_a_finished_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("whole.mcap");
    let sent = write(&path, true);
    let (got, truncated) = read(&path);
    assert_eq!(truncated, None);
    assert_eq!(got, sent);
}

#[test]
fn a_file_cut_mid_chunk_reads_up_to_its_last_complete_chunk() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("cut.mcap");
    let sent = write(&path, false);
    let (got, truncated) = read(&path);
    assert!(truncated.is_some(), "no footer, yet read as whole");
    // At least the flushed first half is there, and what is there is a prefix of what was sent.
    assert!(got.len() >= 60, "{} messages", got.len());
    assert_eq!(got[..], sent[..got.len()]);
}

#[test]
fn a_file_that_is_not_mcap_is_an_error_not_an_empty_recording() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("junk.mcap");
    std::fs::write(&path, b"definitely not an mcap file").expect("writes");
    let mut reader = RecordingReader::open(&path).expect("opens");
    assert!(reader.next_entry().is_err());
}
