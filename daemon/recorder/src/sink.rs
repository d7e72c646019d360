//! The MCAP files of one recording and their rotation by size.
//!
//! Naming: the first file is the path given (`run.mcap`); when it grows past the size limit
//! it is finished (a complete, indexed MCAP file) and the recording goes on in `run-0001.mcap`,
//! then `run-0002.mcap`, and so on ([`rotated_path`]). Every file is self-contained: the
//! channels and schemas a file uses are written into it again.
//!
//! A write error (a full disk) stops the sink: the files keep every chunk completed before it
//! ([`McapSink::messages_in_files`] counts their messages), the last file has no summary (no
//! room for it), and a reader recovers its chunks by reading it from the start.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use mcap::records::{MessageHeader, Metadata};
use mcap::{McapError, WriteOptions, Writer};
use serde::{Deserialize, Serialize};

use crate::RecordError;

/// Message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every channel.
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// Chunk size, uncompressed bytes of records: small enough that a recording killed by SIGKILL,
/// or stopped by a full disk, loses little (a reader recovers every finished chunk), large
/// enough to keep the index small and to give zstd enough to compress (a 1 kHz run's 256 KiB
/// chunks compress to about 0.36; the whole file at once would reach 0.34). The sink closes the chunks itself (not the MCAP writer), so it knows
/// which messages are in finished chunks.
const CHUNK_BYTES: u64 = 256 * 1024;

/// A message record's bytes besides its data: opcode, length, channel id, sequence, log and
/// publish time (the MCAP spec).
const MESSAGE_RECORD_OVERHEAD: u64 = 1 + 8 + 2 + 4 + 8 + 8;

/// How chunks are compressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    /// zstd at the mcap crate's default level: what Foxglove's own writers use by default and
    /// every MCAP reader reads.
    #[default]
    Zstd,
    /// Uncompressed chunks.
    None,
}

impl Compression {
    /// By the name used on command lines and in config files: `zstd` or `none`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "zstd" => Some(Compression::Zstd),
            "none" => Some(Compression::None),
            _ => None,
        }
    }

    fn mcap(self) -> Option<mcap::Compression> {
        match self {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::None => None,
        }
    }
}

/// The path of file number `index` of a recording to `first` (index 0 is `first` itself):
/// `run.mcap` -> `run-0001.mcap`, `run-0002.mcap`, ...
pub fn rotated_path(first: &Path, index: u32) -> PathBuf {
    if index == 0 {
        return first.to_path_buf();
    }
    let stem = first
        .file_stem()
        .map_or_else(|| "recording".into(), |s| s.to_string_lossy().into_owned());
    let name = match first.extension() {
        Some(ext) => format!("{stem}-{index:04}.{}", ext.to_string_lossy()),
        None => format!("{stem}-{index:04}"),
    };
    first.with_file_name(name)
}

/// A channel as the recording knows it, re-added to each new file on first use.
#[derive(Debug, Clone)]
struct ChannelDef {
    topic: String,
    schema_name: String,
    schema: Vec<u8>,
}

/// A file writer that counts the bytes it has put into the file.
struct Counting {
    inner: BufWriter<File>,
    pos: u64,
    /// Largest position written, shared with [`OpenFile`] (the MCAP writer owns this).
    len: Arc<AtomicU64>,
}

impl Write for Counting {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.pos += n as u64;
        self.len.fetch_max(self.pos, Ordering::Relaxed);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl Seek for Counting {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        self.pos = self.inner.seek(to)?;
        Ok(self.pos)
    }
}

struct OpenFile {
    path: PathBuf,
    writer: Writer<Counting>,
    len: Arc<AtomicU64>,
    /// Channel id in this file per recording-wide channel index.
    ids: BTreeMap<usize, u16>,
    /// Uncompressed bytes of the records in the open chunk (the compressed size grows in
    /// steps, as the compressor emits blocks).
    chunk_bytes: u64,
}

/// Writes the recording, one file after another.
pub struct McapSink {
    first: PathBuf,
    max_bytes: Option<u64>,
    compression: Compression,
    channels: BTreeMap<usize, ChannelDef>,
    file: Option<OpenFile>,
    index: u32,
    written: Vec<PathBuf>,
    /// Messages in finished chunks, handed to the OS (every file).
    in_files: u64,
    /// Messages in the open chunk.
    in_chunk: u64,
}

impl McapSink {
    /// Creates `first` (truncating it) and writes its header. `max_bytes`: rotate once a file
    /// holds more than this (compressed bytes, as on disk).
    pub fn create(
        first: &Path,
        max_bytes: Option<u64>,
        compression: Compression,
    ) -> Result<Self, RecordError> {
        let mut sink = Self {
            first: first.to_path_buf(),
            max_bytes,
            compression,
            channels: BTreeMap::new(),
            file: None,
            index: 0,
            written: Vec::new(),
            in_files: 0,
            in_chunk: 0,
        };
        sink.open_next()?;
        Ok(sink)
    }

    fn open_next(&mut self) -> Result<(), RecordError> {
        let path = rotated_path(&self.first, self.index);
        let io = |source| RecordError::Io {
            path: path.clone(),
            source,
        };
        let file = File::create(&path).map_err(io)?;
        let len = Arc::new(AtomicU64::new(0));
        let counting = Counting {
            inner: BufWriter::with_capacity(256 * 1024, file),
            pos: 0,
            len: Arc::clone(&len),
        };
        let writer = WriteOptions::new()
            .compression(self.compression.mcap())
            // Closed by `write` (CHUNK_BYTES), which then counts their messages as written.
            .chunk_size(None)
            .profile("")
            .library(concat!("thruster-recorder ", env!("CARGO_PKG_VERSION")))
            .create(counting)
            .map_err(mcap_error(&path))?;
        self.written.push(path.clone());
        self.file = Some(OpenFile {
            path,
            writer,
            len,
            ids: BTreeMap::new(),
            chunk_bytes: 0,
        });
        self.index += 1;
        Ok(())
    }

    /// Declares channel `index` for `topic` with the JSON Schema `schema` (serialised) named
    /// `schema_name`, for [`McapSink::write`].
    pub fn add_channel(&mut self, index: usize, topic: &str, schema_name: &str, schema: &[u8]) {
        self.channels.insert(
            index,
            ChannelDef {
                topic: topic.to_string(),
                schema_name: schema_name.to_string(),
                schema: schema.to_vec(),
            },
        );
    }

    /// Writes one message on `channel`: `log_ns` when the recorder received it, `publish_ns`
    /// the sender's time. Rotates first when the file is over the size limit; closes the chunk
    /// once it holds [`CHUNK_BYTES`].
    pub fn write(
        &mut self,
        channel: usize,
        sequence: u32,
        log_ns: u64,
        publish_ns: u64,
        data: &[u8],
    ) -> Result<(), RecordError> {
        if let (Some(max), Some(file)) = (self.max_bytes, &self.file) {
            if file.writer_len() >= max {
                self.finish_file(&BTreeMap::new(), false)?;
                self.open_next()?;
            }
        }
        let Some(def) = self.channels.get(&channel) else {
            return Err(RecordError::Options(format!(
                "message on undeclared channel {channel}"
            )));
        };
        let file = self.file.as_mut().expect("a file is open while recording");
        let id = match file.ids.get(&channel) {
            Some(id) => *id,
            None => {
                let schema_id = file
                    .writer
                    .add_schema(&def.schema_name, SCHEMA_ENCODING, &def.schema)
                    .map_err(mcap_error(&file.path))?;
                let id = file
                    .writer
                    .add_channel(schema_id, &def.topic, MESSAGE_ENCODING, &BTreeMap::new())
                    .map_err(mcap_error(&file.path))?;
                file.ids.insert(channel, id);
                id
            }
        };
        let header = MessageHeader {
            channel_id: id,
            sequence,
            log_time: log_ns,
            publish_time: publish_ns,
        };
        file.writer
            .write_to_known_channel(&header, data)
            .map_err(mcap_error(&file.path))?;
        self.in_chunk += 1;
        file.chunk_bytes += MESSAGE_RECORD_OVERHEAD + data.len() as u64;
        if file.chunk_bytes >= CHUNK_BYTES {
            // Finishes the chunk (compressing what the compressor still holds) and hands it to
            // the OS: its messages are in the file.
            file.writer.flush().map_err(mcap_error(&file.path))?;
            self.in_files += std::mem::take(&mut self.in_chunk);
            file.chunk_bytes = 0;
        }
        Ok(())
    }

    /// Messages in finished chunks handed to the OS, over every file: after a write error,
    /// what a reader recovers from the files (at least; the chunk being closed when the disk
    /// filled may be complete too). After [`McapSink::finish`], every message written.
    pub fn messages_in_files(&self) -> u64 {
        self.in_files
    }

    /// Every file created so far, in order.
    pub fn files(&self) -> &[PathBuf] {
        &self.written
    }

    /// Finishes the open file with a metadata record holding `metadata` (if any); `sync`:
    /// wait until it is on disk (only at the end: an fsync can take long on a busy disk).
    fn finish_file(
        &mut self,
        metadata: &BTreeMap<String, String>,
        sync: bool,
    ) -> Result<(), RecordError> {
        let Some(mut file) = self.file.take() else {
            return Ok(());
        };
        if !metadata.is_empty() {
            file.writer
                .write_metadata(&Metadata {
                    name: METADATA_NAME.into(),
                    metadata: metadata.clone(),
                })
                .map_err(mcap_error(&file.path))?;
        }
        file.writer.finish().map_err(mcap_error(&file.path))?;
        let mut inner = file.writer.into_inner();
        inner
            .flush()
            .and_then(|()| {
                if sync {
                    inner.inner.get_ref().sync_data()
                } else {
                    Ok(())
                }
            })
            .map_err(|source| RecordError::Io {
                path: file.path.clone(),
                source,
            })?;
        self.in_files += std::mem::take(&mut self.in_chunk);
        Ok(())
    }

    /// Finishes the last file, writing `summary` into it as a metadata record named
    /// [`METADATA_NAME`]. [`McapSink::files`] are then every file written, in order.
    pub fn finish(&mut self, summary: &BTreeMap<String, String>) -> Result<(), RecordError> {
        self.finish_file(summary, true)
    }
}

/// An error of the MCAP writer on `path`: an I/O error (a full disk) as [`RecordError::Io`],
/// which names the file and the OS error; anything else as [`RecordError::Mcap`]. The writer
/// reports a failed write of a record's bytes as a parse error wrapping the I/O error
/// (`McapError::Parse(binrw::Error::Io)`, "Record parse failed: No space left on device"):
/// found when a disk filled while a file was being finished; it is the same full disk.
fn mcap_error(path: &Path) -> impl FnOnce(McapError) -> RecordError + '_ {
    move |error| match error {
        McapError::Io(source) | McapError::Parse(binrw::Error::Io(source)) => RecordError::Io {
            path: path.to_path_buf(),
            source,
        },
        source => RecordError::Mcap {
            path: path.to_path_buf(),
            source,
        },
    }
}

/// Name of the metadata record with the recording's counts and losses (in the last file).
pub const METADATA_NAME: &str = "thruster-recorder";

impl OpenFile {
    /// Bytes in the file so far; the open chunk (at most about `CHUNK_BYTES`) and the
    /// summary come on top, so a file ends at most that much over the limit.
    fn writer_len(&self) -> u64 {
        self.len.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotated_names_number_from_one_beside_the_first() {
        let first = Path::new("/tmp/out/run.mcap");
        assert_eq!(rotated_path(first, 0), first);
        assert_eq!(rotated_path(first, 1), Path::new("/tmp/out/run-0001.mcap"));
        assert_eq!(rotated_path(first, 12), Path::new("/tmp/out/run-0012.mcap"));
        assert_eq!(rotated_path(Path::new("run"), 2), Path::new("run-0002"));
    }

    /// The error and its sources, as `anyhow`'s `{:#}` prints them.
    fn chain(e: &dyn std::error::Error) -> String {
        let mut text = e.to_string();
        let mut source = e.source();
        while let Some(s) = source {
            text.push_str(&format!(": {s}"));
            source = s.source();
        }
        text
    }

    #[test]
    fn a_full_disk_inside_a_record_write_is_the_same_io_error() {
        let path = Path::new("/rec/session-0003.mcap");
        let full = || std::io::Error::from_raw_os_error(28);
        for error in [
            McapError::Io(full()),
            McapError::Parse(binrw::Error::Io(full())),
        ] {
            let e = mcap_error(path)(error);
            assert_eq!(
                chain(&e),
                "cannot write /rec/session-0003.mcap: No space left on device (os error 28)"
            );
        }
        // Anything else stays the writer's own error.
        let e = mcap_error(path)(McapError::ConflictingSchemas("s".into()));
        assert!(matches!(e, RecordError::Mcap { .. }), "{e:?}");
    }

    #[test]
    fn a_full_disk_is_an_io_error_naming_the_file_and_the_os_error_once() {
        // /dev/full: every write fails with ENOSPC, for any user.
        let full = Path::new("/dev/full");
        let mut sink = McapSink::create(full, None, Compression::None).expect("opening /dev/full");
        sink.add_channel(0, "imu", "thrusterd.ImuSample", b"{}");
        let e = (0..10_000)
            .find_map(|i| sink.write(0, i, 1, 1, b"{\"seq\":1}").err())
            .expect("a write to /dev/full fails");
        assert!(
            matches!(&e, RecordError::Io { path, source }
                if path == full && source.raw_os_error() == Some(28)),
            "{e:?}"
        );
        assert_eq!(
            chain(&e),
            "cannot write /dev/full: No space left on device (os error 28)"
        );
        assert_eq!(sink.messages_in_files(), 0);
        assert_eq!(sink.files(), [full]);
    }

    #[test]
    fn messages_count_as_in_the_file_once_their_chunk_is_finished() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.mcap");
        let mut sink = McapSink::create(&path, None, Compression::None).unwrap();
        sink.add_channel(0, "imu", "thrusterd.ImuSample", b"{}");
        let data = [b' '; 1000];
        for i in 0..100 {
            sink.write(0, i, 1, 1, &data).unwrap();
        }
        // 100 kB: the first chunk is still open.
        assert_eq!(sink.messages_in_files(), 0);
        for i in 100..1000 {
            sink.write(0, i, 1, 1, &data).unwrap();
        }
        // Three chunks of 256 KiB finished, each handed to the OS.
        let finished = sink.messages_in_files();
        assert!((700..800).contains(&finished), "{finished}");
        assert!(std::fs::metadata(&path).unwrap().len() >= finished * 1000);
        sink.finish(&BTreeMap::new()).unwrap();
        assert_eq!(sink.messages_in_files(), 1000);
        assert_eq!(sink.files(), [path]);
    }

    #[test]
    fn zstd_chunks_read_back_with_the_mcap_crate_and_are_smaller() {
        let dir = tempfile::tempdir().unwrap();
        let mut sizes = Vec::new();
        for compression in [Compression::None, Compression::Zstd] {
            let path = dir.path().join(format!("{compression:?}.mcap"));
            let mut sink = McapSink::create(&path, None, compression).unwrap();
            sink.add_channel(0, "imu", "thrusterd.ImuSample", b"{}");
            for i in 0..10_000u32 {
                let data = format!("{{\"seq\":{i},\"gyro\":[0.0012,-0.0034,{}]}}", i % 7);
                sink.write(0, i, u64::from(i), u64::from(i), data.as_bytes())
                    .unwrap();
            }
            // The chunks close on uncompressed bytes, compressed or not.
            assert!(sink.messages_in_files() > 0, "{compression:?}");
            sink.finish(&BTreeMap::new()).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            let seqs: Vec<u32> = mcap::MessageStream::new(&bytes)
                .unwrap()
                .map(|m| m.unwrap().sequence)
                .collect();
            assert_eq!(seqs, (0..10_000).collect::<Vec<_>>(), "{compression:?}");
            sizes.push(bytes.len());
        }
        assert!(
            sizes[1] * 3 < sizes[0],
            "zstd {} vs none {}",
            sizes[1],
            sizes[0]
        );
    }
}
