//! The MCAP file being written, on a thread of its own: the recorder's async side hands it channels and messages
//! through a bounded queue, and file writes and chunk compression never stall the hub connection's tasks.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;

use agent_contract::channels as ch;
use flow::{ChannelInfo, Data};
use tokio::sync::mpsc;

use crate::annotations;
use crate::encoding::{Form, JSON, OCTET_STREAM};
use crate::error::RecordError;
use crate::schemas;

/// MCAP channel metadata keys.
pub const META_HEADER: &str = "flow.header";
pub const META_KIND: &str = "flow.kind";
pub const META_OWNER: &str = "flow.owner";
/// On derived topics (the detections' annotations): the hub channel they were computed from. Replay skips them.
pub const META_DERIVED: &str = "flow.derived_from";

/// What the recorder's async side sends the writer thread.
#[derive(Debug)]
pub(crate) enum Item {
    /// A channel appeared (or was re-created, or changed its header); its messages follow.
    Channel(ChannelInfo),
    /// A message of a channel, with its log time (the hub's receive time) in ns since the Unix epoch.
    Message {
        name: String,
        data: Data,
        log_ns: u64,
    },
    /// Closes the current chunk so that a crash loses at most what came since.
    Flush,
}

/// How the file is written.
#[derive(Debug, Clone)]
pub struct SinkOptions {
    /// The uncompressed size at which a chunk is compressed and written.
    pub chunk_bytes: u64,
}

impl Default for SinkOptions {
    fn default() -> Self {
        SinkOptions {
            chunk_bytes: 1 << 20,
        }
    }
}

/// Per hub channel: what the file holds.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ChannelTally {
    pub messages: u64,
    pub bytes: u64,
    /// Messages missing from the recording: gaps in the channel's sequence numbers, whether the hub dropped them
    /// for a recorder that fell behind or the recorder's own queue did.
    pub missing: u64,
    /// Messages that did not fit the channel's form and were written as raw bytes beside it.
    pub raw_fallback: u64,
}

/// What a finished recording holds.
#[derive(Debug, Clone, Default)]
pub struct SinkReport {
    pub channels: BTreeMap<String, ChannelTally>,
    pub annotations: u64,
}

impl SinkReport {
    /// Messages written, every channel together.
    pub fn messages(&self) -> u64 {
        self.channels.values().map(|c| c.messages).sum()
    }
}

struct Topic {
    info: ChannelInfo,
    form: Form,
    primary: Option<u16>,
    fallback: Option<u16>,
    last_seq: u64,
}

/// An MCAP file being written: what the recorder's writer thread drives, usable directly to write a recording
/// from known messages (tests, benchmarks).
pub struct Sink {
    writer: mcap::Writer<BufWriter<File>>,
    topics: HashMap<String, Topic>,
    annotations: Option<u16>,
    report: SinkReport,
    /// A second handle on the file (same offset), to cut it back and end it when a write fails.
    file: File,
    path: PathBuf,
    /// Where the last whole chunk ends, and how many messages the file holds up to there.
    good: (u64, u64),
}

impl std::fmt::Debug for Sink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sink")
            .field("report", &self.report)
            .finish()
    }
}

/// Ends the file at `good` (offset, messages) with a data-end record, a footer without summary and the closing
/// magic, and returns the error that says so.
///
/// ```text
/// DataEnd: 0x0F | len u64 = 4  | data_section_crc u32 = 0 (not computed)
/// Footer:  0x02 | len u64 = 20 | summary_start u64 = 0 | summary_offset_start u64 = 0 | summary_crc u32 = 0
/// Magic:   0x89 'M' 'C' 'A' 'P' '0' '\r' '\n'
/// ```
fn end_file(path: &Path, (offset, kept): (u64, u64), cause: &RecordError) -> RecordError {
    let mut end = Vec::with_capacity(50);
    end.push(0x0F);
    end.extend_from_slice(&4u64.to_le_bytes());
    end.extend_from_slice(&0u32.to_le_bytes());
    end.push(0x02);
    end.extend_from_slice(&20u64.to_le_bytes());
    end.extend_from_slice(&[0u8; 20]);
    end.extend_from_slice(&MCAP_MAGIC);
    let ended = (|| -> std::io::Result<()> {
        let mut f = std::fs::OpenOptions::new().write(true).open(path)?;
        f.set_len(offset)?;
        f.seek(SeekFrom::Start(offset))?;
        f.write_all(&end)?;
        f.sync_all()
    })();
    // The OS's own words ("No space left on device") are at the end of the cause's chain.
    let mut why = cause.to_string();
    let mut source = std::error::Error::source(cause);
    while let Some(s) = source {
        why = format!("{why}: {s}");
        source = s.source();
    }
    let reason = match ended {
        Ok(()) => why,
        Err(e) => format!("{why}; ending the file failed too: {e}"),
    };
    RecordError::Interrupted {
        path: path.display().to_string(),
        reason,
        kept,
    }
}

/// The MCAP magic that opens and closes a file.
const MCAP_MAGIC: [u8; 8] = [0x89, b'M', b'C', b'A', b'P', b'0', b'\r', b'\n'];

/// Creates the file and starts the writer thread.
/// The writer thread's input and its result.
pub(crate) type Spawned = (
    mpsc::Sender<Item>,
    JoinHandle<Result<SinkReport, RecordError>>,
);

pub(crate) fn spawn(path: &Path, opts: &SinkOptions, queue: usize) -> Result<Spawned, RecordError> {
    let sink = Sink::create(path, opts)?;
    let (tx, rx) = mpsc::channel(queue);
    let path: PathBuf = path.to_path_buf();
    let handle = std::thread::Builder::new()
        .name("mcap-writer".into())
        .spawn(move || sink.run(rx))
        .map_err(|e| RecordError::file(&path, e))?;
    Ok((tx, handle))
}

impl Sink {
    /// Creates (or replaces) the file.
    pub fn create(path: &Path, opts: &SinkOptions) -> Result<Sink, RecordError> {
        let file = File::create(path).map_err(|e| RecordError::file(path, e))?;
        let spare = file.try_clone().map_err(|e| RecordError::file(path, e))?;
        let mut writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(opts.chunk_bytes))
            // Compression runs on the writing thread alone: zstd's worker threads would compete with the hub
            // for the machine's cores.
            .compression_threads(0)
            .profile("")
            .create(BufWriter::new(file))?;
        // The magic and header on disk: the file is a valid (empty) recording from here.
        writer.flush()?;
        let mut sink = Sink {
            writer,
            topics: HashMap::new(),
            annotations: None,
            report: SinkReport::default(),
            file: spare,
            path: path.to_path_buf(),
            good: (0, 0),
        };
        sink.mark_good()?;
        Ok(sink)
    }

    /// Notes where the file's last whole chunk ends (the shared offset, after a flush).
    fn mark_good(&mut self) -> Result<(), RecordError> {
        let at = (&self.file)
            .stream_position()
            .map_err(|e| RecordError::file(&self.path, e))?;
        self.good = (at, self.report.messages());
        Ok(())
    }

    fn run(mut self, mut rx: mpsc::Receiver<Item>) -> Result<SinkReport, RecordError> {
        while let Some(item) = rx.blocking_recv() {
            let written = match item {
                Item::Channel(info) => {
                    self.channel(info);
                    Ok(())
                }
                Item::Message { name, data, log_ns } => self.message(&name, &data, log_ns),
                Item::Flush => self.flush(),
            };
            if let Err(e) = written {
                return Err(self.end_at_last_chunk(&e));
            }
        }
        let (path, good) = (self.path.clone(), self.good);
        match self.finish() {
            Ok(report) => Ok(report),
            // The summary did not fit: the file still ends after its last whole chunk.
            Err(e) => Err(end_file(&path, good, &e)),
        }
    }

    /// After a failed write: cuts the file back to its last whole chunk and ends it there (without a summary,
    /// which readers do without), freeing the space the broken chunk took.
    fn end_at_last_chunk(self, e: &RecordError) -> RecordError {
        let (path, good) = (self.path.clone(), self.good);
        // The MCAP writer tries to finish the file as it goes; whatever it manages is cut off below.
        drop(self);
        end_file(&path, good, e)
    }

    /// Closes the current chunk and writes it out: a crash after this loses nothing before it.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.writer.flush()?;
        self.mark_good()
    }

    /// Writes the summary and footer (what makes the file indexed, and quick to open) and says what it holds.
    pub fn finish(mut self) -> Result<SinkReport, RecordError> {
        self.writer.finish()?;
        // The buffer's last bytes, with the error a drop would swallow.
        self.writer
            .into_inner()
            .flush()
            .map_err(|e| RecordError::Writer(format!("writing the file's end: {e}")))?;
        Ok(self.report)
    }

    /// Describes a channel (new, re-created or with a new header) before its messages.
    pub fn channel(&mut self, info: ChannelInfo) {
        if let Some(topic) = self.topics.get(&info.name)
            && topic.info.header == info.header
            && topic.info.id == info.id
        {
            return;
        }
        // New, re-created or with a new header: a new MCAP channel on the same topic carries it from here on.
        let form = Form::of(&info.name, &info.header);
        self.topics.insert(
            info.name.clone(),
            Topic {
                info,
                form,
                primary: None,
                fallback: None,
                last_seq: 0,
            },
        );
    }

    /// Writes one message of a described channel; `log_ns` is its log time (ns since the Unix epoch).
    pub fn message(&mut self, name: &str, data: &Data, log_ns: u64) -> Result<(), RecordError> {
        let Some(topic) = self.topics.get_mut(name) else {
            return Ok(());
        };
        let tally = self.report.channels.entry(name.to_string()).or_default();
        if topic.last_seq != 0 && data.seq > topic.last_seq + 1 {
            tally.missing += data.seq - topic.last_seq - 1;
        }
        topic.last_seq = data.seq;
        tally.messages += 1;
        tally.bytes += data.payload.len() as u64;
        if topic.primary.is_none() {
            topic.form = topic.form.clone().settle(&data.payload);
            let (encoding, schema) = topic.form.mcap_kind(name);
            topic.primary = Some(add_channel(
                &mut self.writer,
                &topic.info,
                encoding,
                schema,
            )?);
        }
        let header = |channel_id| mcap::records::MessageHeader {
            channel_id,
            // MCAP's sequence is 32-bit; the hub's wraps into it.
            sequence: data.seq as u32,
            log_time: log_ns,
            publish_time: data.ts_us.saturating_mul(1000),
        };
        match topic.form.encode(name, &data.payload, data.ts_us) {
            Some(bytes) => {
                let id = topic.primary.unwrap_or_default();
                self.writer.write_to_known_channel(&header(id), &bytes)?;
            }
            None => {
                tally.raw_fallback += 1;
                let id = match topic.fallback {
                    Some(id) => id,
                    None => {
                        let id = add_channel(&mut self.writer, &topic.info, OCTET_STREAM, None)?;
                        topic.fallback = Some(id);
                        id
                    }
                };
                self.writer
                    .write_to_known_channel(&header(id), &data.payload)?;
            }
        }
        if name == ch::DETECTIONS.name
            && let Some(bytes) = annotations::from_detections(&data.payload)
        {
            let id = match self.annotations {
                Some(id) => id,
                None => {
                    let id = add_annotation_channel(&mut self.writer)?;
                    self.annotations = Some(id);
                    id
                }
            };
            self.writer.write_to_known_channel(&header(id), &bytes)?;
            self.report.annotations += 1;
        }
        Ok(())
    }
}

fn add_channel(
    writer: &mut mcap::Writer<BufWriter<File>>,
    info: &ChannelInfo,
    encoding: &str,
    schema: Option<(String, String)>,
) -> Result<u16, RecordError> {
    let schema_id = match schema {
        Some((name, text)) => {
            writer.add_schema(&name, schemas::SCHEMA_ENCODING, text.as_bytes())?
        }
        None => 0,
    };
    let metadata = BTreeMap::from([
        (META_HEADER.to_string(), info.header.clone()),
        (META_KIND.to_string(), info.kind.as_str().to_string()),
        (META_OWNER.to_string(), info.owner.clone()),
    ]);
    Ok(writer.add_channel(schema_id, &info.name, encoding, &metadata)?)
}

fn add_annotation_channel(writer: &mut mcap::Writer<BufWriter<File>>) -> Result<u16, RecordError> {
    let schema_id = writer.add_schema(
        schemas::IMAGE_ANNOTATIONS,
        schemas::SCHEMA_ENCODING,
        schemas::IMAGE_ANNOTATIONS_SCHEMA.as_bytes(),
    )?;
    let metadata = BTreeMap::from([(META_DERIVED.to_string(), ch::DETECTIONS.name.to_string())]);
    let topic = format!("{}{}", ch::DETECTIONS.name, annotations::SUFFIX);
    Ok(writer.add_channel(schema_id, &topic, JSON, &metadata)?)
}
