//! A small MCAP reader: the channels and messages of one file, every problem named with its
//! byte offset.
//!
//! Why our own and not the `mcap` crate's reader (the recorder writes with that crate): a
//! replay must refuse a truncated or corrupt file and say where it broke, and the crate's
//! errors carry no offset. The format is small (magic, then records `opcode u8, length u64,
//! body`, chunks holding records), so walking it ourselves is a few dozen lines.
//!
//! Compressed chunks (zstd or lz4: what the recorder, Foxglove's writers, Python's `mcap` and
//! the `mcap` CLI write) are decompressed with the `zstd` and `lz4` crates, the libraries the
//! `mcap` crate uses, into at most the size the chunk claims (itself bounded), then checked
//! against the chunk's CRC and walked like an uncompressed chunk. Not through the crate's
//! `ChunkReader`: on a chunk with flipped bytes it reserved a record length read from the
//! corrupt data (1.8e18 bytes) and the process aborted instead of failing. Records inside a
//! compressed chunk are named by the chunk's offset (an offset into the decompressed data
//! would point nowhere in the file).
//!
//! Spec: <https://mcap.dev/spec>.

use std::collections::BTreeMap;

/// The 8 bytes at both ends of an MCAP file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Largest uncompressed chunk a compressed chunk may claim (Foxglove's writers make 4 MiB
/// chunks by default, Python's 1 MiB, ours 256 KiB).
const MAX_CHUNK_BYTES: u64 = 256 * 1024 * 1024;
/// Largest claimed compression ratio of a chunk (JSON recordings reach about 3; a chunk of one
/// repeated byte could reach more, and is refused).
const MAX_RATIO: u64 = 1000;

const OP_FOOTER: u8 = 0x02;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;

/// Why a file cannot be read; `offset` is the byte the problem starts at.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum McapError {
    #[error("byte offset 0: not an MCAP file (no MCAP magic at the start)")]
    NotMcap,
    #[error("byte offset {offset}: {what} needs {need} bytes but the file ends at byte {size}: truncated")]
    Truncated {
        offset: u64,
        what: String,
        need: u64,
        size: u64,
    },
    #[error("byte offset {offset}: the file ends after the footer without the closing MCAP magic: truncated or corrupt")]
    NoClosingMagic { offset: u64 },
    #[error("byte offset {offset}: chunk of {len} bytes fails its CRC (stored {stored:#010x}, computed {computed:#010x}): corrupt")]
    ChunkCrc {
        offset: u64,
        len: u64,
        stored: u32,
        computed: u32,
    },
    #[error("byte offset {offset}: {what}: corrupt")]
    Corrupt { offset: u64, what: String },
    #[error("byte offset {offset}: {compression} chunk of {len} bytes does not decompress ({reason}): corrupt")]
    Compressed {
        offset: u64,
        compression: String,
        len: u64,
        reason: String,
    },
}

/// One message: where its record starts in the file, and its payload.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawMessage {
    pub offset: u64,
    pub sequence: u32,
    pub log_time: u64,
    pub data: Vec<u8>,
}

/// The messages of a file, by channel topic, in file order.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct McapFile {
    pub topics: BTreeMap<String, Vec<RawMessage>>,
}

/// A cursor over a byte range that names what it reads when the range runs out.
struct Cursor<'a> {
    bytes: &'a [u8],
    /// Offset of `bytes[0]` in the file.
    base: u64,
    pos: usize,
    /// The file's size (for the "ends at" of a truncation).
    size: u64,
    /// A short read inside a record whose length fit the file is corruption, not truncation.
    in_record: bool,
    /// Inside a compressed chunk: every offset is the chunk's.
    fixed: Option<u64>,
}

impl<'a> Cursor<'a> {
    fn offset(&self) -> u64 {
        self.fixed.unwrap_or(self.base + self.pos as u64)
    }

    fn take(&mut self, n: u64, what: &str) -> Result<&'a [u8], McapError> {
        let left = (self.bytes.len() - self.pos) as u64;
        if n > left {
            return Err(if self.in_record {
                McapError::Corrupt {
                    offset: self.offset(),
                    what: format!("{what} of {n} bytes runs past its record ({left} left)"),
                }
            } else {
                McapError::Truncated {
                    offset: self.offset(),
                    what: what.to_string(),
                    need: n,
                    size: self.size,
                }
            });
        }
        let s = &self.bytes[self.pos..self.pos + n as usize];
        self.pos += n as usize;
        Ok(s)
    }

    fn u16(&mut self, what: &str) -> Result<u16, McapError> {
        Ok(u16::from_le_bytes(
            self.take(2, what)?.try_into().unwrap_or_default(),
        ))
    }
    fn u32(&mut self, what: &str) -> Result<u32, McapError> {
        Ok(u32::from_le_bytes(
            self.take(4, what)?.try_into().unwrap_or_default(),
        ))
    }
    fn u64(&mut self, what: &str) -> Result<u64, McapError> {
        Ok(u64::from_le_bytes(
            self.take(8, what)?.try_into().unwrap_or_default(),
        ))
    }
    fn string(&mut self, what: &str) -> Result<String, McapError> {
        let at = self.offset();
        let n = self.u32(what)?;
        let raw = self.take(u64::from(n), what)?;
        String::from_utf8(raw.to_vec()).map_err(|_| McapError::Corrupt {
            offset: at,
            what: format!("{what} is not UTF-8"),
        })
    }
    fn at_end(&self) -> bool {
        self.pos == self.bytes.len()
    }
}

/// Reads every channel and message of `bytes` (a whole file), checking the magic at both
/// ends, every record's length and every chunk's CRC (when the writer stored one).
pub fn read(bytes: &[u8]) -> Result<McapFile, McapError> {
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err(McapError::NotMcap);
    }
    let size = bytes.len() as u64;
    let mut top = Cursor {
        bytes,
        base: 0,
        pos: MAGIC.len(),
        size,
        in_record: false,
        fixed: None,
    };
    let mut reader = Reader::default();
    loop {
        if top.at_end() {
            return Err(McapError::Truncated {
                offset: top.offset(),
                what: "the next record (no footer yet)".into(),
                need: 9,
                size,
            });
        }
        let (opcode, offset, body) = record(&mut top)?;
        if opcode == OP_FOOTER {
            let rest = top.take((bytes.len() - top.pos) as u64, "closing magic")?;
            if rest != MAGIC {
                return Err(McapError::NoClosingMagic {
                    offset: top.offset() - rest.len() as u64,
                });
            }
            return reader.finish();
        }
        reader.record(opcode, offset, body, size)?;
    }
}

/// One record header and its body, as a cursor over the body.
fn record<'a>(c: &mut Cursor<'a>) -> Result<(u8, u64, Cursor<'a>), McapError> {
    let offset = c.offset();
    let opcode = c.take(1, "a record's opcode")?[0];
    let len = c.u64("a record's length")?;
    let left = (c.bytes.len() - c.pos) as u64;
    if len > left && !c.in_record {
        // Named at the record's own start: that is where the file stops making sense.
        return Err(McapError::Truncated {
            offset,
            what: format!("the {} record starting here", record_name(opcode)),
            need: 9 + len,
            size: c.size,
        });
    }
    let what = format!(
        "{} record at byte {offset} ({len} bytes)",
        record_name(opcode)
    );
    let body_base = c.offset();
    let body = c.take(len, &what)?;
    Ok((
        opcode,
        offset,
        Cursor {
            bytes: body,
            base: body_base,
            pos: 0,
            size: c.size,
            in_record: true,
            fixed: c.fixed,
        },
    ))
}

/// The record kinds of the spec, for messages.
fn record_name(opcode: u8) -> String {
    let name = match opcode {
        0x01 => "header",
        OP_FOOTER => "footer",
        0x03 => "schema",
        OP_CHANNEL => "channel",
        OP_MESSAGE => "message",
        OP_CHUNK => "chunk",
        0x07 => "message index",
        0x08 => "chunk index",
        0x09 => "attachment",
        0x0A => "attachment index",
        0x0B => "statistics",
        0x0C => "metadata",
        0x0D => "metadata index",
        0x0E => "summary offset",
        0x0F => "data end",
        _ => return format!("unknown (opcode {opcode:#04x})"),
    };
    name.to_string()
}

/// The records of a chunk compressed with `compression` (`zstd` or `lz4`, the names the MCAP
/// spec registers), which claims `claimed` bytes uncompressed: decompressed into at most that
/// many bytes, and exactly that many or an error.
fn decompress(compression: &str, data: &[u8], claimed: u64) -> Result<Vec<u8>, String> {
    // A corrupt size field must not become a huge allocation. No recording of ours comes near
    // either bound (chunks of 256 KiB, compressed about 3x).
    if claimed > MAX_CHUNK_BYTES || claimed > MAX_RATIO * data.len() as u64 + 64 * 1024 {
        return Err(format!(
            "it claims {claimed} bytes uncompressed, more than this reader takes \
             ({MAX_CHUNK_BYTES} bytes, {MAX_RATIO}x its compressed size)"
        ));
    }
    let out = match compression {
        "zstd" => zstd::bulk::decompress(data, claimed as usize).map_err(|e| e.to_string())?,
        "lz4" => {
            use std::io::Read;
            let mut out = Vec::with_capacity(claimed as usize);
            lz4::Decoder::new(data)
                .and_then(|d| d.take(claimed + 1).read_to_end(&mut out))
                .map_err(|e| e.to_string())?;
            out
        }
        other => {
            return Err(format!(
                "unknown compression {other:?} (zstd and lz4 are read)"
            ))
        }
    };
    if out.len() as u64 != claimed {
        return Err(format!(
            "it decompresses to {} bytes, not the {claimed} it claims",
            out.len()
        ));
    }
    Ok(out)
}

#[derive(Default)]
struct Reader {
    /// Channel id -> topic; a channel record repeats in the summary and in every file.
    channels: BTreeMap<u16, String>,
    /// Channel id and message, in file order.
    messages: Vec<(u16, RawMessage)>,
}

impl Reader {
    fn record(
        &mut self,
        opcode: u8,
        offset: u64,
        mut body: Cursor<'_>,
        size: u64,
    ) -> Result<(), McapError> {
        match opcode {
            OP_CHANNEL => {
                let id = body.u16("channel id")?;
                let _schema = body.u16("channel schema id")?;
                let topic = body.string("channel topic")?;
                self.channels.insert(id, topic);
            }
            OP_MESSAGE => {
                let channel = body.u16("message channel id")?;
                let sequence = body.u32("message sequence")?;
                let log_time = body.u64("message log time")?;
                let _publish = body.u64("message publish time")?;
                let data = body.take((body.bytes.len() - body.pos) as u64, "message data")?;
                // Resolved at the end: a writer may declare channels only in the summary.
                self.messages.push((
                    channel,
                    RawMessage {
                        offset,
                        sequence,
                        log_time,
                        data: data.to_vec(),
                    },
                ));
            }
            OP_CHUNK => {
                let _start = body.u64("chunk start time")?;
                let _end = body.u64("chunk end time")?;
                let uncompressed = body.u64("chunk uncompressed size")?;
                let crc = body.u32("chunk CRC")?;
                let compression = body.string("chunk compression")?;
                let len = body.u64("chunk records length")?;
                let records_base = body.offset();
                let records = body.take(len, "chunk records")?;
                let decompressed;
                let (records, fixed) = if compression.is_empty() {
                    (records, body.fixed)
                } else {
                    decompressed =
                        decompress(&compression, records, uncompressed).map_err(|reason| {
                            McapError::Compressed {
                                offset,
                                compression: compression.clone(),
                                len,
                                reason,
                            }
                        })?;
                    (decompressed.as_slice(), Some(offset))
                };
                // 0: the writer computed none.
                if crc != 0 {
                    let computed = crc32fast::hash(records);
                    if computed != crc {
                        return Err(McapError::ChunkCrc {
                            offset,
                            len,
                            stored: crc,
                            computed,
                        });
                    }
                }
                let mut inner = Cursor {
                    bytes: records,
                    base: records_base,
                    pos: 0,
                    size,
                    in_record: true,
                    fixed,
                };
                while !inner.at_end() {
                    let (op, at, rec) = record(&mut inner)?;
                    self.record(op, at, rec, size)?;
                }
            }
            // Header, schemas, indexes, statistics, metadata, attachments, data end: nothing
            // a replay needs (their lengths were checked by `record`).
            _ => {}
        }
        Ok(())
    }

    fn finish(self) -> Result<McapFile, McapError> {
        let mut topics: BTreeMap<String, Vec<RawMessage>> = BTreeMap::new();
        for (channel, message) in self.messages {
            let Some(topic) = self.channels.get(&channel) else {
                return Err(McapError::Corrupt {
                    offset: message.offset,
                    what: format!("message on channel {channel}, which no channel record declares"),
                });
            };
            topics.entry(topic.clone()).or_default().push(message);
        }
        Ok(McapFile { topics })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A whole file: one chunk with a channel per topic and its messages (JSON text).
    pub(crate) fn file_with(topics: &[(&str, &[&str])]) -> Vec<u8> {
        let mut inner = Vec::new();
        for (id, (topic, messages)) in topics.iter().enumerate() {
            inner.extend(channel(id as u16, topic));
            for (seq, m) in messages.iter().enumerate() {
                inner.extend(message(id as u16, seq as u32, m));
            }
        }
        let mut f = MAGIC.to_vec();
        f.extend(chunk(&inner, None));
        f.extend(rec(OP_FOOTER, &[0u8; 20]));
        f.extend_from_slice(MAGIC);
        f
    }

    /// A record: opcode, length, body.
    fn rec(op: u8, body: &[u8]) -> Vec<u8> {
        let mut v = vec![op];
        v.extend_from_slice(&(body.len() as u64).to_le_bytes());
        v.extend_from_slice(body);
        v
    }

    fn string(s: &str) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s.as_bytes());
        v
    }

    fn channel(id: u16, topic: &str) -> Vec<u8> {
        let mut b = id.to_le_bytes().to_vec();
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend(string(topic));
        b.extend(string("json"));
        b.extend_from_slice(&0u32.to_le_bytes());
        rec(OP_CHANNEL, &b)
    }

    fn message(id: u16, seq: u32, data: &str) -> Vec<u8> {
        let mut b = id.to_le_bytes().to_vec();
        b.extend_from_slice(&seq.to_le_bytes());
        b.extend_from_slice(&7u64.to_le_bytes());
        b.extend_from_slice(&7u64.to_le_bytes());
        b.extend_from_slice(data.as_bytes());
        rec(OP_MESSAGE, &b)
    }

    fn chunk(records: &[u8], crc: Option<u32>) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(&0u64.to_le_bytes());
        b.extend_from_slice(&0u64.to_le_bytes());
        b.extend_from_slice(&(records.len() as u64).to_le_bytes());
        b.extend_from_slice(
            &crc.unwrap_or_else(|| crc32fast::hash(records))
                .to_le_bytes(),
        );
        b.extend(string(""));
        b.extend_from_slice(&(records.len() as u64).to_le_bytes());
        b.extend_from_slice(records);
        rec(OP_CHUNK, &b)
    }

    /// magic, header, a chunk with a channel and two messages, footer, magic.
    fn file() -> Vec<u8> {
        let mut f = MAGIC.to_vec();
        f.extend(rec(0x01, &[string("").as_slice(), &string("")].concat()));
        let mut inner = channel(3, "imu");
        inner.extend(message(3, 1, "{\"seq\":1}"));
        inner.extend(message(3, 2, "{\"seq\":2}"));
        f.extend(chunk(&inner, None));
        f.extend(rec(OP_FOOTER, &[0u8; 20]));
        f.extend_from_slice(MAGIC);
        f
    }

    #[test]
    fn reads_the_messages_of_a_chunk_with_their_offsets() {
        let f = read(&file()).unwrap();
        let imu = &f.topics["imu"];
        assert_eq!(imu.len(), 2);
        assert_eq!(imu[1].data, b"{\"seq\":2}");
        assert_eq!(imu[1].sequence, 2);
        // The second message record starts where its bytes are in the file.
        let whole = file();
        let at = imu[1].offset as usize;
        assert_eq!(whole[at], OP_MESSAGE);
    }

    #[test]
    fn every_truncation_is_refused_with_an_offset_inside_the_file() {
        let whole = file();
        for cut in 0..whole.len() {
            let err = read(&whole[..cut]).unwrap_err();
            let text = err.to_string();
            assert!(text.starts_with("byte offset "), "cut {cut}: {text}");
            let offset: u64 = text["byte offset ".len()..]
                .split(':')
                .next()
                .unwrap()
                .parse()
                .unwrap();
            assert!(offset <= cut as u64, "cut {cut}: {text}");
        }
    }

    #[test]
    fn a_flipped_byte_in_a_chunk_fails_its_crc_at_the_chunk() {
        let mut whole = file();
        let chunk_at = MAGIC.len() + 9 + 8;
        assert_eq!(whole[chunk_at], OP_CHUNK);
        let last = whole.len() - MAGIC.len() - 29 - 3;
        whole[last] ^= 0x40;
        match read(&whole).unwrap_err() {
            McapError::ChunkCrc { offset, .. } => assert_eq!(offset, chunk_at as u64),
            e => panic!("{e}"),
        }
    }

    #[test]
    fn a_length_that_overruns_a_chunk_is_corruption() {
        let mut inner = channel(3, "imu");
        let mut bad = message(3, 1, "{}");
        bad[1] = 200; // the message claims 200 + bytes inside a chunk that holds fewer
        inner.extend(bad);
        let mut f = MAGIC.to_vec();
        f.extend(chunk(&inner, Some(0)));
        f.extend(rec(OP_FOOTER, &[0u8; 20]));
        f.extend_from_slice(MAGIC);
        let err = read(&f).unwrap_err();
        assert!(matches!(err, McapError::Corrupt { .. }), "{err}");
    }

    /// A file the `mcap` crate's writer makes with `compression`: 300 messages on `imu` in
    /// chunks of about 4 KiB.
    fn written_by_the_crate(compression: mcap::Compression) -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new()
            .compression(Some(compression))
            .chunk_size(Some(4096))
            .create(&mut out)
            .unwrap();
        let schema = w.add_schema("s", "jsonschema", b"{}").unwrap();
        let ch = w
            .add_channel(schema, "imu", "json", &Default::default())
            .unwrap();
        for seq in 1..=300u32 {
            let header = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: seq,
                log_time: u64::from(seq),
                publish_time: u64::from(seq),
            };
            let data = format!("{{\"seq\":{seq},\"gyro\":[0.25,-0.5,{seq}]}}");
            w.write_to_known_channel(&header, data.as_bytes()).unwrap();
        }
        w.finish().unwrap();
        drop(w);
        out.into_inner()
    }

    #[test]
    fn zstd_and_lz4_chunks_are_read_through_the_crate() {
        for compression in [mcap::Compression::Zstd, mcap::Compression::Lz4] {
            let bytes = written_by_the_crate(compression);
            let f = read(&bytes).unwrap_or_else(|e| panic!("{compression:?}: {e}"));
            let imu = &f.topics["imu"];
            assert_eq!(imu.len(), 300, "{compression:?}");
            assert_eq!(imu[299].sequence, 300);
            assert_eq!(imu[0].data, b"{\"seq\":1,\"gyro\":[0.25,-0.5,1]}");
            // A message in a compressed chunk is named by its chunk's offset.
            assert_eq!(bytes[imu[0].offset as usize], OP_CHUNK, "{compression:?}");
        }
    }

    #[test]
    fn a_flipped_byte_in_a_compressed_chunk_is_named_at_the_chunk() {
        let clean = written_by_the_crate(mcap::Compression::Zstd);
        let first_chunk = read(&clean).unwrap().topics["imu"][0].offset as usize;
        // A byte in the middle of the first chunk's compressed records.
        let len = u64::from_le_bytes(clean[first_chunk + 1..first_chunk + 9].try_into().unwrap());
        let mut bad = clean.clone();
        bad[first_chunk + 9 + len as usize - 20] ^= 0x55;
        // It no longer decompresses, or decompresses to bytes that fail the chunk's CRC.
        match read(&bad).unwrap_err() {
            McapError::Compressed {
                offset,
                compression,
                ..
            } => {
                assert_eq!(offset, first_chunk as u64);
                assert_eq!(compression, "zstd");
            }
            McapError::ChunkCrc { offset, .. } => assert_eq!(offset, first_chunk as u64),
            e => panic!("{e}"),
        }
        // Truncated anywhere: refused, with an offset inside what is left.
        for cut in (0..clean.len()).step_by(97) {
            let text = read(&clean[..cut]).unwrap_err().to_string();
            assert!(text.starts_with("byte offset "), "cut {cut}: {text}");
        }
    }

    #[test]
    fn flipped_bytes_anywhere_in_a_compressed_file_never_crash_the_reader() {
        // A corrupt length or size must be refused, not trusted: a flipped chunk header once
        // made the reader try to allocate 1.8e18 bytes (an abort, not an error).
        for compression in [mcap::Compression::Zstd, mcap::Compression::Lz4] {
            let clean = written_by_the_crate(compression);
            for at in (0..clean.len() - 16).step_by(5) {
                let mut bad = clean.clone();
                for b in &mut bad[at..at + 16] {
                    *b ^= 0x5a;
                }
                if let Err(e) = read(&bad) {
                    assert!(e.to_string().starts_with("byte offset "), "{at}: {e}");
                }
            }
        }
    }

    #[test]
    fn garbage_is_not_mcap() {
        assert_eq!(
            read(b"hello world, not mcap").unwrap_err(),
            McapError::NotMcap
        );
    }
}
