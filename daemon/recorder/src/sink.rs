//! The MCAP files of one recording and their rotation by size.
//!
//! Naming: the first file is the path given (`run.mcap`); when it grows past the size limit
//! it is finished (a complete, indexed MCAP file) and the recording goes on in `run-0001.mcap`,
//! then `run-0002.mcap`, and so on ([`rotated_path`]). Every file is self-contained: the
//! channels and schemas a file uses are written into it again.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use mcap::records::{MessageHeader, Metadata};
use mcap::{WriteOptions, Writer};

use crate::RecordError;

/// Message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every channel.
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// Chunk size: small enough that a recording killed by SIGKILL loses little (a reader
/// recovers every finished chunk), large enough to keep the index small.
const CHUNK_BYTES: u64 = 256 * 1024;

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
}

/// Writes the recording, one file after another.
pub struct McapSink {
    first: PathBuf,
    max_bytes: Option<u64>,
    channels: BTreeMap<usize, ChannelDef>,
    file: Option<OpenFile>,
    index: u32,
    written: Vec<PathBuf>,
}

impl McapSink {
    /// Creates `first` (truncating it) and writes its header. `max_bytes`: rotate once a file
    /// holds more than this.
    pub fn create(first: &Path, max_bytes: Option<u64>) -> Result<Self, RecordError> {
        let mut sink = Self {
            first: first.to_path_buf(),
            max_bytes,
            channels: BTreeMap::new(),
            file: None,
            index: 0,
            written: Vec::new(),
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
            .compression(None)
            .chunk_size(Some(CHUNK_BYTES))
            .profile("")
            .library(concat!("thruster-recorder ", env!("CARGO_PKG_VERSION")))
            .create(counting)
            .map_err(|source| RecordError::Mcap {
                path: path.clone(),
                source,
            })?;
        self.written.push(path.clone());
        self.file = Some(OpenFile {
            path,
            writer,
            len,
            ids: BTreeMap::new(),
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
    /// the sender's time. Rotates first when the file is over the size limit.
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
        let mcap_err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| RecordError::Mcap { path, source }
        };
        let id = match file.ids.get(&channel) {
            Some(id) => *id,
            None => {
                let schema_id = file
                    .writer
                    .add_schema(&def.schema_name, SCHEMA_ENCODING, &def.schema)
                    .map_err(mcap_err(&file.path))?;
                let id = file
                    .writer
                    .add_channel(schema_id, &def.topic, MESSAGE_ENCODING, &BTreeMap::new())
                    .map_err(mcap_err(&file.path))?;
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
            .map_err(mcap_err(&file.path))
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
        let mcap_err = |source| RecordError::Mcap {
            path: file.path.clone(),
            source,
        };
        if !metadata.is_empty() {
            file.writer
                .write_metadata(&Metadata {
                    name: METADATA_NAME.into(),
                    metadata: metadata.clone(),
                })
                .map_err(mcap_err)?;
        }
        file.writer.finish().map_err(mcap_err)?;
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
        Ok(())
    }

    /// Finishes the last file, writing `summary` into it as a metadata record named
    /// [`METADATA_NAME`]; returns every file written, in order.
    pub fn finish(
        mut self,
        summary: &BTreeMap<String, String>,
    ) -> Result<Vec<PathBuf>, RecordError> {
        self.finish_file(summary, true)?;
        Ok(std::mem::take(&mut self.written))
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
}
