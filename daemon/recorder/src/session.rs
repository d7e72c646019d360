//! A recording session: subscribe, drain every topic until told to stop, finish the file
//! with the counts and losses.
//!
//! Two threads: the caller's drains the subscribers (copy out of shared memory, JSON) and
//! hands each message over an unbounded channel to a writer thread that owns the files. A
//! slow disk (a rotation, a full page cache) then delays only the writer, never the draining
//! of the 128-sample subscriber buffers; the memory the channel takes meanwhile is the price.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::Serialize;
use thruster_protocol::services::{IpcConfig, IpcNode};

use crate::sink::McapSink;
use crate::source::{open_all, Item, Source};
use crate::RecordError;

/// Longest sleep when nothing came. The IMU's notification wakes the loop earlier; the
/// slower topics wait at most this long. Far below the 128 ms the stream buffers hold at
/// 1 kHz, so a quiet wait never loses a sample.
const IDLE_WAIT: Duration = Duration::from_millis(5);

/// What to record, where, for how long.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// The first file; rotated files are named by [`crate::rotated_path`].
    pub out: PathBuf,
    /// Start a new file once one holds this many bytes.
    pub max_bytes: Option<u64>,
    /// Stop after this long (wall clock).
    pub duration: Option<Duration>,
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
}

/// What a recording wrote.
#[derive(Debug, Clone, Serialize)]
pub struct RecordSummary {
    pub files: Vec<PathBuf>,
    pub topics: Vec<TopicSummary>,
    pub messages: u64,
    pub lost: u64,
    pub wall_s: f64,
}

impl RecordSummary {
    /// One line for the operator: `recorded N messages (imu 1000, ...) in F file(s), lost L`.
    pub fn line(&self) -> String {
        let per: Vec<String> = self
            .topics
            .iter()
            .filter(|t| t.messages > 0)
            .map(|t| format!("{} {}", t.topic, t.messages))
            .collect();
        format!(
            "recorded {} messages ({}) in {:.1} s to {} file(s), first {}; lost {}",
            self.messages,
            per.join(", "),
            self.wall_s,
            self.files.len(),
            self.files
                .first()
                .map_or_else(String::new, |p| p.display().to_string()),
            self.lost,
        )
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
    if options.max_bytes == Some(0) {
        return Err(RecordError::Options(
            "the size limit must be above 0".into(),
        ));
    }
    let mut sources = open_all(node, ipc)?;
    let mut sink = McapSink::create(&options.out, options.max_bytes)?;
    let (tx, rx) = mpsc::channel::<Command>();
    let failed = Arc::new(AtomicBool::new(false));
    let writer_failed = Arc::clone(&failed);
    let writer = std::thread::Builder::new()
        .name("mcap-writer".into())
        .spawn(move || write_all(&mut sink, &rx, &writer_failed).and_then(|m| sink.finish(&m)))
        .map_err(|source| RecordError::Io {
            path: options.out.clone(),
            source,
        })?;
    ready();
    let start = Instant::now();
    let epoch_ns = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    // Log time: the wall clock at the start plus the monotonic time since, so log times
    // never go backwards when the wall clock is stepped.
    let now_ns = move || epoch_ns + start.elapsed().as_nanos() as u64;
    let deadline = options.duration.map(|d| start + d);
    let mut out = |item: Item| {
        // A writer that stopped (an error) has dropped its receiver: it reports why.
        let _ = tx.send(Command::Write(item));
    };
    let result = run(&mut sources, &mut out, &now_ns, stop, &failed, deadline);
    // One last pass after the stop: what is buffered is recorded too.
    let last = result.and_then(|()| drain_all(&mut sources, &mut out, &now_ns).map(|_| ()));
    let summary = summarise(&sources, start.elapsed());
    // The writer finishes the file even after an error, so what was written stays readable.
    let _ = tx.send(Command::Finish(metadata(&summary)));
    drop(tx);
    let files = writer
        .join()
        .map_err(|_| RecordError::Options("the MCAP writer thread panicked".into()))?;
    last?;
    Ok(RecordSummary {
        files: files?,
        ..summary
    })
}

/// What the writer thread is told.
enum Command {
    Write(Item),
    /// The end: finish the file with this metadata.
    Finish(BTreeMap<String, String>),
}

/// The writer thread: every item into `sink` until told to finish; returns the metadata to
/// finish with. After an error it sets `failed` (the drainer stops) and returns it.
fn write_all(
    sink: &mut McapSink,
    rx: &mpsc::Receiver<Command>,
    failed: &AtomicBool,
) -> Result<BTreeMap<String, String>, RecordError> {
    let mut write = |item: Item| match item {
        Item::Channel {
            index,
            topic,
            schema_name,
            schema,
        } => {
            sink.add_channel(index, topic, &schema_name, &schema);
            Ok(())
        }
        Item::Message {
            index,
            sequence,
            log_ns,
            publish_ns,
            data,
        } => sink.write(index, sequence, log_ns, publish_ns, &data),
    };
    for command in rx {
        match command {
            Command::Write(item) => {
                if let Err(e) = write(item) {
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
    out: &mut dyn FnMut(Item),
    now_ns: &dyn Fn() -> u64,
    stop: &AtomicBool,
    failed: &AtomicBool,
    deadline: Option<Instant>,
) -> Result<(), RecordError> {
    loop {
        if stop.load(Ordering::Relaxed)
            || failed.load(Ordering::Relaxed)
            || deadline.is_some_and(|d| Instant::now() >= d)
        {
            return Ok(());
        }
        if drain_all(sources, out, now_ns)? == 0 {
            // Sleep on the IMU, the fastest stream.
            if let Err(e) = sources[0].wait(IDLE_WAIT) {
                if interrupted(stop) {
                    return Ok(());
                }
                return Err(e);
            }
        }
    }
}

fn drain_all(
    sources: &mut [Box<dyn Source>],
    out: &mut dyn FnMut(Item),
    now_ns: &dyn Fn() -> u64,
) -> Result<usize, RecordError> {
    let mut n = 0;
    for (index, s) in sources.iter_mut().enumerate() {
        n += s.drain(index, out, now_ns)?;
    }
    Ok(n)
}

/// After a failed wait: true when SIGINT/SIGTERM caused it. The signal makes the wait fail
/// (EINTR) at once, but ctrlc sets the stop flag from its own thread a moment later.
fn interrupted(stop: &AtomicBool) -> bool {
    let deadline = Instant::now() + Duration::from_millis(200);
    while Instant::now() < deadline {
        if stop.load(Ordering::SeqCst) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    stop.load(Ordering::SeqCst)
}

fn summarise(sources: &[Box<dyn Source>], wall: Duration) -> RecordSummary {
    let topics: Vec<TopicSummary> = sources
        .iter()
        .map(|s| TopicSummary {
            topic: s.topic().to_string(),
            messages: s.count(),
            lost: s.seq().lost,
            seq_restarts: s.seq().restarts,
        })
        .collect();
    RecordSummary {
        files: Vec::new(),
        messages: topics.iter().map(|t| t.messages).sum(),
        lost: topics.iter().map(|t| t.lost).sum(),
        topics,
        wall_s: wall.as_secs_f64(),
    }
}

/// The metadata record of the last file: per topic `<topic>.messages`, `<topic>.lost`,
/// `<topic>.seq_restarts` (over the whole recording, every file), and the totals.
fn metadata(summary: &RecordSummary) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    for t in &summary.topics {
        m.insert(format!("{}.messages", t.topic), t.messages.to_string());
        m.insert(format!("{}.lost", t.topic), t.lost.to_string());
        m.insert(
            format!("{}.seq_restarts", t.topic),
            t.seq_restarts.to_string(),
        );
    }
    m.insert("messages".into(), summary.messages.to_string());
    m.insert("lost".into(), summary.lost.to_string());
    m.insert("wall_s".into(), format!("{:.3}", summary.wall_s));
    m
}
