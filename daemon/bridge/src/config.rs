//! `thruster-bridge.toml`: every key optional, unknown keys refused, ranges checked, errors in
//! the `file:line:col: key: reason` form of every thrusterd binary (driver-kit's loader).
//! `config/thruster-bridge.toml` documents each key with its default.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use thruster_driver_kit::load::{self, LoadError, Range};
use thruster_protocol::services::DEFAULT_ROOT_BASE;

/// Per-client backlog of the Foxglove server (the SDK's default), messages.
pub const DEFAULT_BACKLOG: usize = 1024;
/// Queue between the draining loop and the WebSocket server, messages: a second of a 1 kHz
/// run with telemetry at every sample.
pub const DEFAULT_LIVE_QUEUE: usize = 4096;
/// How long an operator request waits for the daemon's answer, ms (thrusterctl's default).
pub const DEFAULT_CONTROL_TIMEOUT_MS: u64 = 2000;

/// The file as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    namespace: Option<String>,
    ipc_root: Option<PathBuf>,
    #[serde(default)]
    websocket: WebsocketFile,
    #[serde(default)]
    record: RecordFile,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct WebsocketFile {
    listen: Option<String>,
    services: Option<bool>,
    backlog: Option<usize>,
    queue: Option<usize>,
    control_timeout_ms: Option<u64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RecordFile {
    out: Option<PathBuf>,
    max_mb: Option<f64>,
    queue: Option<usize>,
    compression: Option<String>,
}

/// The bridge's settings, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeConfig {
    pub namespace: Option<String>,
    pub ipc_root: PathBuf,
    /// None: no WebSocket server (the default).
    pub websocket: Option<Websocket>,
    /// None: no recording (the default).
    pub record: Option<Record>,
}

/// The live view's server.
#[derive(Debug, Clone, PartialEq)]
pub struct Websocket {
    pub listen: SocketAddr,
    /// Offer the operator's requests as services.
    pub services: bool,
    pub backlog: usize,
    pub queue: usize,
    pub control_timeout_ms: u64,
}

/// The MCAP recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub out: PathBuf,
    pub max_mb: Option<f64>,
    pub queue: usize,
    pub compression: thruster_recorder::Compression,
}

impl Default for BridgeConfig {
    fn default() -> Self {
        Self {
            namespace: None,
            ipc_root: PathBuf::from(DEFAULT_ROOT_BASE),
            websocket: None,
            record: None,
        }
    }
}

impl Websocket {
    /// The server on `listen` with every other setting at its default.
    pub fn on(listen: SocketAddr) -> Self {
        Self {
            listen,
            services: true,
            backlog: DEFAULT_BACKLOG,
            queue: DEFAULT_LIVE_QUEUE,
            control_timeout_ms: DEFAULT_CONTROL_TIMEOUT_MS,
        }
    }
}

impl Record {
    /// A recording to `out` with every other setting at its default.
    pub fn to(out: PathBuf) -> Self {
        Self {
            out,
            max_mb: None,
            queue: thruster_recorder::DEFAULT_QUEUE,
            compression: thruster_recorder::Compression::default(),
        }
    }
}

/// Reads and checks `path`.
pub fn load(path: &Path) -> Result<BridgeConfig, LoadError> {
    let text = load::read_text(path)?;
    parse(&text, &path.display().to_string())
}

/// Parses and checks `text`; `origin` names it in errors.
pub fn parse(text: &str, origin: &str) -> Result<BridgeConfig, LoadError> {
    let file: File = load::parse_toml(text, origin)?;
    let ipc_root = file
        .ipc_root
        .unwrap_or_else(|| PathBuf::from(DEFAULT_ROOT_BASE));
    if !ipc_root.is_absolute() {
        return Err(LoadError::value(
            origin,
            text,
            "ipc_root",
            "must be an absolute path",
        ));
    }
    let count = |key: &str, v: Option<usize>, default: usize, hi: f64| match v {
        None => Ok(default),
        Some(n) if (1.0..=hi).contains(&(n as f64)) => Ok(n),
        Some(n) => Err(LoadError::out_of_range(
            origin,
            text,
            key,
            Range::closed(1.0, hi),
            n,
        )),
    };
    let w = file.websocket;
    let websocket = match w.listen {
        None => {
            // Settings for a server that is off are a mistake worth naming.
            if w.services.is_some()
                || w.backlog.is_some()
                || w.queue.is_some()
                || w.control_timeout_ms.is_some()
            {
                return Err(LoadError::invalid(
                    origin,
                    "websocket.listen",
                    "the [websocket] settings need listen = \"ADDRESS:PORT\" (the server is off without it)",
                ));
            }
            None
        }
        Some(addr) => Some(Websocket {
            listen: addr.parse().map_err(|e| {
                LoadError::value(
                    origin,
                    text,
                    "websocket.listen",
                    format!("must be ADDRESS:PORT, e.g. \"127.0.0.1:8765\" ({e})"),
                )
            })?,
            services: w.services.unwrap_or(true),
            backlog: count("websocket.backlog", w.backlog, DEFAULT_BACKLOG, 1e6)?,
            queue: count("websocket.queue", w.queue, DEFAULT_LIVE_QUEUE, 1e7)?,
            control_timeout_ms: match w.control_timeout_ms {
                None => DEFAULT_CONTROL_TIMEOUT_MS,
                Some(ms) if (10..=60_000).contains(&ms) => ms,
                Some(ms) => {
                    return Err(LoadError::out_of_range(
                        origin,
                        text,
                        "websocket.control_timeout_ms",
                        Range::closed(10.0, 60_000.0),
                        ms,
                    ))
                }
            },
        }),
    };
    let r = file.record;
    let record = match r.out {
        None => {
            if r.max_mb.is_some() || r.queue.is_some() || r.compression.is_some() {
                return Err(LoadError::invalid(
                    origin,
                    "record.out",
                    "the [record] settings need out = \"FILE.mcap\" (recording is off without it)",
                ));
            }
            None
        }
        Some(out) => Some(Record {
            out,
            max_mb: match r.max_mb {
                None => None,
                Some(mb) if mb > 0.0 && mb <= 1024.0 * 1024.0 => Some(mb),
                Some(mb) => {
                    return Err(LoadError::out_of_range(
                        origin,
                        text,
                        "record.max_mb",
                        Range::above_to(0.0, 1024.0 * 1024.0),
                        mb,
                    ))
                }
            },
            queue: count(
                "record.queue",
                r.queue,
                thruster_recorder::DEFAULT_QUEUE,
                1e7,
            )?,
            compression: match r.compression.as_deref() {
                None => thruster_recorder::Compression::default(),
                Some(name) => thruster_recorder::Compression::from_name(name).ok_or_else(|| {
                    LoadError::invalid(
                        origin,
                        "record.compression",
                        format!("must be \"zstd\" or \"none\", got {name:?}"),
                    )
                })?,
            },
        }),
    };
    Ok(BridgeConfig {
        namespace: file.namespace,
        ipc_root,
        websocket,
        record,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_file_turns_everything_off() {
        assert_eq!(parse("", "t").unwrap(), BridgeConfig::default());
    }

    #[test]
    fn the_shipped_file_parses_with_the_documented_values() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/thruster-bridge.toml");
        let c = load(&path).unwrap();
        assert_eq!(c.namespace.as_deref(), Some("thrusterd"));
        assert_eq!(c.ipc_root, Path::new("/run/thrusterd"));
        let w = c.websocket.unwrap();
        assert_eq!(w, Websocket::on("127.0.0.1:8765".parse().unwrap()));
        assert_eq!(c.record, None);
    }

    #[test]
    fn unknown_keys_and_bad_values_are_named() {
        let e = parse("[websocket]\nlisten = \"x\"\n", "f.toml").unwrap_err();
        assert!(e.to_string().contains("websocket.listen"), "{e}");
        let e = parse("[websocket]\nlisen = \"127.0.0.1:1\"\n", "f.toml").unwrap_err();
        assert!(e.to_string().contains("lisen"), "{e}");
        let e = parse(
            "[websocket]\nlisten = \"127.0.0.1:1\"\nbacklog = 0\n",
            "f.toml",
        )
        .unwrap_err();
        assert!(e.to_string().contains("f.toml:3"), "{e}");
        assert!(e.to_string().contains("websocket.backlog"), "{e}");
        let e = parse("[websocket]\nservices = false\n", "f.toml").unwrap_err();
        assert!(e.to_string().contains("listen"), "{e}");
        let e = parse("[record]\nout = \"a.mcap\"\nmax_mb = -1\n", "f.toml").unwrap_err();
        assert!(e.to_string().contains("record.max_mb"), "{e}");
        let e = parse(
            "[record]\nout = \"a.mcap\"\ncompression = \"lz4\"\n",
            "f.toml",
        )
        .unwrap_err();
        assert!(e.to_string().contains("record.compression"), "{e}");
        let c = parse(
            "[record]\nout = \"a.mcap\"\ncompression = \"none\"\n",
            "f.toml",
        )
        .unwrap();
        assert_eq!(
            c.record.unwrap().compression,
            thruster_recorder::Compression::None
        );
        let c = parse("[record]\nout = \"a.mcap\"\n", "f.toml").unwrap();
        assert_eq!(
            c.record.unwrap().compression,
            thruster_recorder::Compression::Zstd
        );
        let e = parse("ipc_root = \"rel\"\n", "f.toml").unwrap_err();
        assert!(e.to_string().contains("absolute"), "{e}");
    }
}
