//! A recording: subscribe, drain every topic until told to stop, hand each message to
//! the consumers (the MCAP writer, live views), finish the file with the counts and losses.
//!
//! The caller's thread drains the subscribers (copy out of shared memory, JSON once) and hands
//! each message to every consumer through a bounded queue of its own ([`crate::tap`]): the
//! MCAP writer thread that owns the files, and any live view (the Foxglove bridge). A slow disk
//! (a rotation, a full page cache) or a slow network then delays only its consumer, never the
//! draining of the 128-sample subscriber buffers; when a consumer's queue is full the message
//! is dropped for it alone and counted, so memory stays bounded.
//!
//! A write error (a full disk) stops the writer, and with it the recording: the error comes back
//! as [`RecordError::Stopped`] with the summary of what was received and what reached the
//! files before it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::Serialize;
use thruster_protocol::services::{IpcConfig, IpcNode};

use crate::sink::{Compression, McapSink};
use crate::source::{open_all, Source};
use crate::tap::{self, Message, Tap};
use crate::RecordError;

/// The recorder drains every topic on its own clock, this often, and is never woken by a
/// sample. Woken by each IMU sample (as it was), it competed with the daemon for a core at
/// the very moment the daemon had to answer: on the 2-core bench machine the daemon's median
/// IMU -> thrust latency rose by 20-50 % with the bridge attached (docs/recording.md). Ten
/// samples per topic per drain at 1 kHz, far below the 128 the stream buffers hold, so a
/// drain that comes late by 100 ms still loses nothing.
pub const DRAIN_PERIOD: Duration = Duration::from_millis(10);

/// Default capacity of the queue to the MCAP writer, in messages: 16 s of a 1 kHz run
/// with telemetry at every sample (about 4 000 messages/s, docs/recording.md), about 25 MB of
/// JSON at most. A disk stalled for longer loses messages (counted) instead of growing memory.
pub const DEFAULT_QUEUE: usize = 65_536;

/// What to record, where, for how long.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// The first file; rotated files are named by [`crate::rotated_path`].
    pub out: PathBuf,
    /// Start a new file once one holds this many bytes.
    pub max_bytes: Option<u64>,
    /// Stop after this long (wall clock).
    pub duration: Option<Duration>,
    /// Capacity of the queue to the writer thread, in messages ([`DEFAULT_QUEUE`]).
    pub queue: usize,
    /// How chunks are compressed (zstd unless asked otherwise).
    pub compression: Compression,
}

/// One topic's counts.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub struct TopicSummary {
    pub topic: String,
    pub messages: u64,
    /// Messages missing from sequence-number gaps (lost by this recorder, or never sent).
    pub lost: u64,
    /// Times the sequence went backwards (a sender restarted or a second sender published).
    pub seq_restarts: u64,
    /// Messages received but not written: the writer's queue was full (the disk was behind).
    pub dropped: u64,
}

/// What a live consumer missed.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub struct TapSummary {
    pub name: String,
    /// Messages dropped because its queue was full.
    pub dropped: u64,
}

/// What a recording wrote.
#[derive(Debug, Clone, Serialize)]
pub struct RecordSummary {
    pub files: Vec<PathBuf>,
    pub topics: Vec<TopicSummary>,
    pub messages: u64,
    pub lost: u64,
    /// Messages dropped before the writer (its queue full), over every topic.
    pub dropped: u64,
    /// The live consumers' drops.
    pub taps: Vec<TapSummary>,
    pub wall_s: f64,
    /// Messages in the files: every message handed to the writer (`messages - dropped`) when
    /// it finished; after a write error ([`RecordError::Stopped`]) those in the chunks
    /// finished before it, which a reader recovers (at least these). 0 without files.
    pub written: u64,
}

impl RecordSummary {
    /// One line for the operator: `recorded N messages (imu 1000, ...) in F file(s), lost L;
    /// dropped D (writer queue full)`, plus each live view's drops. When writing failed:
    /// `recorded W of N messages (...) ...; U not written (writing failed)`.
    pub fn line(&self) -> String {
        let per: Vec<String> = self
            .topics
            .iter()
            .filter(|t| t.messages > 0)
            .map(|t| format!("{} {}", t.topic, t.messages))
            .collect();
        let files = match self.files.first() {
            Some(first) => format!("to {} file(s), first {}", self.files.len(), first.display()),
            None => "(no file)".to_string(),
        };
        // What the writer was handed: anything short of it in the files was not written.
        let handed = self.messages.saturating_sub(self.dropped);
        let unwritten = handed.saturating_sub(self.written);
        let (verb, count) = if self.files.is_empty() {
            ("streamed", self.messages.to_string())
        } else if unwritten > 0 {
            ("recorded", format!("{} of {}", self.written, self.messages))
        } else {
            ("recorded", self.messages.to_string())
        };
        let mut line = format!(
            "{verb} {count} messages ({}) in {:.1} s {files}; lost {}; dropped {} (writer queue full)",
            per.join(", "),
            self.wall_s,
            self.lost,
            self.dropped,
        );
        if !self.files.is_empty() && unwritten > 0 {
            line.push_str(&format!("; {unwritten} not written (writing failed)"));
        }
        for t in &self.taps {
            line.push_str(&format!("; {} dropped {} (queue full)", t.name, t.dropped));
        }
        line
    }
}

/// Records every topic of `ipc`'s namespace with a node of its own (named `recorder`) until
/// `stop` is set or the duration passes. The caller decides about access checks and tidying
/// the namespace (see the operator's `record` verb).
pub fn record(
    ipc: &IpcConfig,
    options: &RecordOptions,
    stop: &AtomicBool,
) -> Result<RecordSummary, RecordError> {
    let node = ipc
        .create_node("recorder")
        .map_err(|source| RecordError::Ipc {
            namespace: ipc.namespace().to_string(),
            source,
        })?;
    record_on(&node, ipc, options, stop, &mut || {})
}

/// As [`record`] on an existing node; `ready` is called once every topic is subscribed and
/// the first file is open (a caller that starts the publishers after it misses nothing).
pub fn record_on(
    node: &IpcNode,
    ipc: &IpcConfig,
    options: &RecordOptions,
    stop: &AtomicBool,
    ready: &mut dyn FnMut(),
) -> Result<RecordSummary, RecordError> {
    stream_on(node, ipc, Some(options), Vec::new(), stop, ready)
}

/// The general recording: every topic of the namespace to the MCAP files of `record` (if any)
/// and to each of `live` (each behind its own bounded queue, see [`crate::tap`]), until `stop`
/// or `record`'s duration. `ready` as in [`record_on`].
pub fn stream_on(
    node: &IpcNode,
    ipc: &IpcConfig,
    record: Option<&RecordOptions>,
    mut live: Vec<Tap<Message>>,
    stop: &AtomicBool,
    ready: &mut dyn FnMut(),
) -> Result<RecordSummary, RecordError> {
    if let Some(options) = record {
        if options.max_bytes == Some(0) {
            return Err(RecordError::Options(
                "the size limit must be above 0".into(),
            ));
        }
        if options.queue == 0 {
            return Err(RecordError::Options(
                "the writer queue must hold at least one message".into(),
            ));
        }
    }
    let mut sources = open_all(node, ipc)?;
    let failed = Arc::new(AtomicBool::new(false));
    let mut writer = match record {
        Some(options) => Some(Writer::start(options, &failed)?),
        None => None,
    };
    ready();
    let start = Instant::now();
    let epoch_ns = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    // Log time: the wall clock at the start plus the monotonic time since, so log times
    // never go backwards when the wall clock is stepped.
    let now_ns = move || epoch_ns + start.elapsed().as_nanos() as u64;
    let deadline = record.and_then(|o| o.duration).map(|d| start + d);
    let mut out = |m: Message| {
        let topic = m.channel.topic;
        for t in live.iter_mut() {
            t.offer(topic, m.clone());
        }
        if let Some(w) = writer.as_mut() {
            // A writer that stopped (an error) has hung up: it reports why.
            w.tap.offer(topic, Command::Write(m));
        }
    };
    let result = run(&mut sources, &mut out, &now_ns, stop, &failed, deadline);
    // One last pass after the stop: what is buffered is recorded too.
    let last = result.and_then(|()| drain_all(&mut sources, &mut out, &now_ns));
    let mut summary = summarise(&sources, start.elapsed(), writer.as_ref().map(|w| &w.tap));
    summary.taps = live
        .iter()
        .map(|t| TapSummary {
            name: t.name().to_string(),
            dropped: t.dropped_total(),
        })
        .collect();
    // Hang up on the live views: their threads end once they have emptied their queues.
    drop(live);
    let mut write_error = None;
    if let Some(w) = writer.take() {
        let written = w.finish(&summary)?;
        summary.files = written.files;
        summary.written = written.messages;
        write_error = written.error;
    }
    // The writer's error first: it is what stopped the recording.
    match write_error.or(last.err()) {
        None => Ok(summary),
        Some(source) => Err(RecordError::Stopped {
            summary: Box::new(summary),
            source: Box::new(source),
        }),
    }
}

/// What the writer thread is told.
enum Command {
    Write(Message),
    /// The end: finish the file with this metadata.
    Finish(BTreeMap<String, String>),
}

/// What the writer thread leaves: every file it created, the messages in them
/// ([`McapSink::messages_in_files`]) and the error that stopped it, if one did.
struct Written {
    files: Vec<PathBuf>,
    messages: u64,
    error: Option<RecordError>,
}

/// The MCAP writer thread and the bounded queue to it.
struct Writer {
    tap: Tap<Command>,
    thread: std::thread::JoinHandle<Written>,
}

impl Writer {
    fn start(options: &RecordOptions, failed: &Arc<AtomicBool>) -> Result<Self, RecordError> {
        let mut sink = McapSink::create(&options.out, options.max_bytes, options.compression)?;
        let (tap, rx) = tap::bounded("mcap", options.queue);
        let failed = Arc::clone(failed);
        let thread = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || {
                let result = write_all(&mut sink, &rx, &failed).and_then(|m| sink.finish(&m));
                Written {
                    files: sink.files().to_vec(),
                    messages: sink.messages_in_files(),
                    error: result.err(),
                }
            })
            .map_err(|source| RecordError::Io {
                path: options.out.clone(),
                source,
            })?;
        Ok(Self { tap, thread })
    }

    /// Tells the writer to finish with the summary's metadata and waits for it. Err only when
    /// the thread panicked.
    fn finish(self, summary: &RecordSummary) -> Result<Written, RecordError> {
        // Waiting for room is right here: the draining is over. A writer stopped by an error
        // has hung up already (the send fails); its files keep the chunks finished before it.
        self.tap.send_blocking(Command::Finish(metadata(summary)));
        drop(self.tap);
        self.thread
            .join()
            .map_err(|_| RecordError::Options("the MCAP writer thread panicked".into()))
    }
}

/// The writer thread: every message into `sink` until told to finish; returns the metadata
/// to finish with. After an error it sets `failed` (the drainer stops) and returns it.
fn write_all(
    sink: &mut McapSink,
    rx: &mpsc::Receiver<Command>,
    failed: &AtomicBool,
) -> Result<BTreeMap<String, String>, RecordError> {
    let mut declared = BTreeSet::new();
    let mut write = |m: Message| {
        // Declared on the first message the writer sees: the topic's first message may have
        // been dropped (a full queue), every message carries its channel.
        if declared.insert(m.index) {
            let c = &m.channel;
            sink.add_channel(m.index, c.topic, &c.schema_name, &c.schema);
        }
        sink.write(m.index, m.sequence, m.log_ns, m.publish_ns, &m.data)
    };
    for command in rx {
        match command {
            Command::Write(m) => {
                if let Err(e) = write(m) {
                    failed.store(true, Ordering::SeqCst);
                    return Err(e);
                }
            }
            Command::Finish(metadata) => return Ok(metadata),
        }
    }
    Ok(BTreeMap::new())
}

fn run(
    sources: &mut [Box<dyn Source>],
    out: &mut dyn FnMut(Message),
    now_ns: &dyn Fn() -> u64,
    stop: &AtomicBool,
    failed: &AtomicBool,
    deadline: Option<Instant>,
) -> Result<(), RecordError> {
    let mut next = Instant::now();
    loop {
        if stop.load(Ordering::Relaxed)
            || failed.load(Ordering::Relaxed)
            || deadline.is_some_and(|d| Instant::now() >= d)
        {
            return Ok(());
        }
        drain_all(sources, out, now_ns)?;
        // The next tick of a fixed schedule; after a late drain (a busy machine) the next
        // comes one period on, not at once for every tick missed.
        next = (next + DRAIN_PERIOD).max(Instant::now());
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
}

fn drain_all(
    sources: &mut [Box<dyn Source>],
    out: &mut dyn FnMut(Message),
    now_ns: &dyn Fn() -> u64,
) -> Result<(), RecordError> {
    for (index, s) in sources.iter_mut().enumerate() {
        s.drain(index, out, now_ns)?;
    }
    Ok(())
}

fn summarise(
    sources: &[Box<dyn Source>],
    wall: Duration,
    writer: Option<&Tap<Command>>,
) -> RecordSummary {
    let topics: Vec<TopicSummary> = sources
        .iter()
        .map(|s| TopicSummary {
            topic: s.topic().to_string(),
            messages: s.count(),
            lost: s.seq().lost,
            seq_restarts: s.seq().restarts,
            dropped: writer.map_or(0, |w| w.dropped(s.topic())),
        })
        .collect();
    RecordSummary {
        files: Vec::new(),
        messages: topics.iter().map(|t| t.messages).sum(),
        lost: topics.iter().map(|t| t.lost).sum(),
        dropped: topics.iter().map(|t| t.dropped).sum(),
        taps: Vec::new(),
        topics,
        wall_s: wall.as_secs_f64(),
        written: 0,
    }
}

/// The metadata record of the last file: per topic `<topic>.messages`, `<topic>.lost`,
/// `<topic>.seq_restarts`, `<topic>.dropped` (over the whole recording, every file), and the
/// totals.
fn metadata(summary: &RecordSummary) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    for t in &summary.topics {
        m.insert(format!("{}.messages", t.topic), t.messages.to_string());
        m.insert(format!("{}.lost", t.topic), t.lost.to_string());
        m.insert(
            format!("{}.seq_restarts", t.topic),
            t.seq_restarts.to_string(),
        );
        m.insert(format!("{}.dropped", t.topic), t.dropped.to_string());
    }
    m.insert("messages".into(), summary.messages.to_string());
    m.insert("lost".into(), summary.lost.to_string());
    m.insert("dropped".into(), summary.dropped.to_string());
    m.insert("wall_s".into(), format!("{:.3}", summary.wall_s));
    m
}
