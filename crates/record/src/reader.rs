//! Reading a recording from start to end in bounded memory (one chunk at a time), leniently: a file cut short (the
//! recorder killed, the disk full) yields everything up to where it is cut, then ends with
//! [`RecordingReader::truncated`] set, instead of failing.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::RecordError;

/// The largest record a recording may hold: far above the hub's largest frame.
const RECORD_LIMIT: usize = 256 << 20;

/// A channel of the recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordedChannel {
    pub id: u16,
    pub topic: String,
    pub message_encoding: String,
    /// The schema's name, if the channel has one.
    pub schema: Option<String>,
    pub metadata: BTreeMap<String, String>,
}

/// A message of the recording, as stored.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordedMessage {
    pub channel: u16,
    pub sequence: u32,
    pub log_ns: u64,
    pub publish_ns: u64,
    pub data: Vec<u8>,
}

/// What the file holds, in file order: a channel always comes before its messages.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Entry {
    Channel(RecordedChannel),
    Message(RecordedMessage),
}

/// Reads a recording entry by entry.
pub struct RecordingReader {
    path: PathBuf,
    file: File,
    reader: LinearReader,
    schemas: HashMap<u16, String>,
    records: u64,
    truncated: Option<String>,
}

impl std::fmt::Debug for RecordingReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordingReader")
            .field("path", &self.path)
            .field("records", &self.records)
            .field("truncated", &self.truncated)
            .finish()
    }
}

impl RecordingReader {
    pub fn open(path: &Path) -> Result<RecordingReader, RecordError> {
        let file = File::open(path).map_err(|e| RecordError::file(path, e))?;
        Ok(RecordingReader {
            path: path.to_path_buf(),
            file,
            reader: LinearReader::new_with_options(
                LinearReaderOptions::default()
                    .with_validate_chunk_crcs(true)
                    // A corrupt length must not make the reader reserve memory for it.
                    .with_record_length_limit(RECORD_LIMIT),
            ),
            schemas: HashMap::new(),
            records: 0,
            truncated: None,
        })
    }

    /// Why the file ended early, if it did: it was cut off after the entries read so far.
    pub fn truncated(&self) -> Option<&str> {
        self.truncated.as_deref()
    }

    /// The next entry; `None` at the end of the file or where it is cut.
    pub fn next_entry(&mut self) -> Result<Option<Entry>, RecordError> {
        while self.truncated.is_none() {
            let event = match self.reader.next_event() {
                None => return Ok(None),
                Some(Ok(event)) => event,
                Some(Err(e)) => {
                    self.cut(e.to_string())?;
                    continue;
                }
            };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    let buf = self.reader.insert(need);
                    let read = self
                        .file
                        .read(buf)
                        .map_err(|e| RecordError::file(&self.path, e))?;
                    self.reader.notify_read(read);
                }
                LinearReadEvent::Record { opcode, data } => {
                    let record = match mcap::parse_record(opcode, data) {
                        Ok(record) => record,
                        Err(e) => {
                            let reason = e.to_string();
                            self.cut(reason)?;
                            continue;
                        }
                    };
                    self.records += 1;
                    if let Some(entry) = entry(&mut self.schemas, record) {
                        return Ok(Some(entry));
                    }
                }
            }
        }
        Ok(None)
    }

    /// Notes where the file is cut; a file with no readable record at all is not a recording.
    fn cut(&mut self, reason: String) -> Result<(), RecordError> {
        if self.records == 0 {
            return Err(RecordError::NotMcap(format!(
                "{} ({reason})",
                self.path.display()
            )));
        }
        self.truncated = Some(reason);
        Ok(())
    }
}

/// The entry a record is, if any; schemas are kept for the channels that name them.
fn entry(schemas: &mut HashMap<u16, String>, record: Record<'_>) -> Option<Entry> {
    match record {
        Record::Schema { header, .. } => {
            schemas.insert(header.id, header.name);
            None
        }
        Record::Channel(c) => Some(Entry::Channel(RecordedChannel {
            id: c.id,
            schema: schemas.get(&c.schema_id).cloned(),
            topic: c.topic,
            message_encoding: c.message_encoding,
            metadata: c.metadata,
        })),
        Record::Message { header, data } => Some(Entry::Message(RecordedMessage {
            channel: header.channel_id,
            sequence: header.sequence,
            log_ns: header.log_time,
            publish_ns: header.publish_time,
            data: data.into_owned(),
        })),
        _ => None,
    }
}

impl Iterator for RecordingReader {
    type Item = Result<Entry, RecordError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_entry().transpose()
    }
}
