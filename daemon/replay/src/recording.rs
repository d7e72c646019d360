//! The channels a replay needs, decoded from one recording (a file and its rotations).

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use thruster_protocol::{ConfigMsg, ImuSample, InputMsg, ModelMsg, ThrustCommand};

use crate::mcap_read::{self, McapError, RawMessage};

/// Why a recording cannot be replayed as read.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    // The causes are part of the message, not error sources: `thrusterd` prints the chain,
    // and each would appear twice.
    #[error("{path}: {reason}")]
    Io {
        path: PathBuf,
        reason: std::io::Error,
    },
    #[error("{path}: {reason}")]
    Mcap { path: PathBuf, reason: McapError },
    #[error("{path}: byte offset {offset}: message on channel {topic:?} is not a {ty} ({reason}): corrupt")]
    Json {
        path: PathBuf,
        offset: u64,
        topic: &'static str,
        ty: &'static str,
        reason: serde_json::Error,
    },
    #[error("{files}: no {topic:?} channel: {why}")]
    MissingChannel {
        files: String,
        topic: &'static str,
        why: &'static str,
    },
}

/// What a replay reads from a recording, every channel in recording order.
#[derive(Debug, Default, Clone)]
pub struct Recording {
    /// The IMU samples the driver published.
    pub imu: Vec<ImuSample>,
    /// The daemon's input journal.
    pub inputs: Vec<InputMsg>,
    /// The daemon's effective configuration, when recorded (the last one).
    pub config: Option<ConfigMsg>,
    /// Every model the daemon swapped in.
    pub models: Vec<ModelMsg>,
    /// The daemon's thrust commands (which IMU sample each answered, and the count).
    pub thrust: Vec<ThrustCommand>,
}

/// The channels without which nothing can be replayed, and what each one is.
const NEEDED: [(&str, &str); 3] = [
    ("imu", "the IMU samples the machine was fed"),
    (
        "input",
        "the daemon's input journal (recorded from a thrusterd that publishes one, from its start)",
    ),
    (
        "thrust",
        "the daemon's answers, which show whether the recording holds every IMU sample it got",
    ),
];

/// Reads `paths` (a recording and its rotations, in order).
pub fn read(paths: &[PathBuf]) -> Result<Recording, RecordingError> {
    let mut rec = Recording::default();
    let mut seen = std::collections::BTreeSet::new();
    for path in paths {
        let bytes = std::fs::read(path).map_err(|reason| RecordingError::Io {
            path: path.clone(),
            reason,
        })?;
        let file = mcap_read::read(&bytes).map_err(|reason| RecordingError::Mcap {
            path: path.clone(),
            reason,
        })?;
        for (topic, messages) in &file.topics {
            seen.insert(topic.clone());
            match topic.as_str() {
                "imu" => decode(path, "imu", messages, &mut rec.imu)?,
                "input" => decode(path, "input", messages, &mut rec.inputs)?,
                "model" => decode(path, "model", messages, &mut rec.models)?,
                "thrust" => decode(path, "thrust", messages, &mut rec.thrust)?,
                "config" => {
                    let mut configs = Vec::new();
                    decode(path, "config", messages, &mut configs)?;
                    rec.config = configs.pop().or(rec.config);
                }
                _ => {}
            }
        }
    }
    for (topic, why) in NEEDED {
        if !seen.contains(topic) {
            return Err(RecordingError::MissingChannel {
                files: names(paths),
                topic,
                why,
            });
        }
    }
    Ok(rec)
}

/// The files, for messages.
pub fn names(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

fn decode<T: DeserializeOwned>(
    path: &Path,
    topic: &'static str,
    messages: &[RawMessage],
    out: &mut Vec<T>,
) -> Result<(), RecordingError> {
    for m in messages {
        let value = serde_json::from_slice(&m.data).map_err(|reason| RecordingError::Json {
            path: path.to_path_buf(),
            offset: m.offset,
            topic,
            ty: std::any::type_name::<T>()
                .rsplit("::")
                .next()
                .unwrap_or("message"),
            reason,
        })?;
        out.push(value);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mcap_read::tests::file_with;

    fn write(name: &str, bytes: &[u8]) -> PathBuf {
        let path =
            std::env::temp_dir().join(format!("thrusterd-replay-{}-{name}", std::process::id()));
        std::fs::write(&path, bytes).unwrap();
        path
    }

    #[test]
    fn a_missing_channel_is_named() {
        let imu = serde_json::to_string(&ImuSample::default()).unwrap();
        let thrust = serde_json::to_string(&ThrustCommand::default()).unwrap();
        let path = write(
            "no-input.mcap",
            &file_with(&[("imu", &[imu.as_str()]), ("thrust", &[thrust.as_str()])]),
        );
        let err = read(std::slice::from_ref(&path)).unwrap_err();
        let _ = std::fs::remove_file(&path);
        let text = err.to_string();
        assert!(text.contains("no \"input\" channel"), "{text}");
        assert!(text.contains("input journal"), "{text}");
    }

    #[test]
    fn a_message_that_is_not_its_type_is_named_with_its_offset() {
        let path = write("bad-json.mcap", &file_with(&[("imu", &["{\"seq\": 1}"])]));
        let err = read(std::slice::from_ref(&path)).unwrap_err();
        let _ = std::fs::remove_file(&path);
        match err {
            RecordingError::Json { offset, topic, .. } => {
                assert_eq!(topic, "imu");
                assert!(offset > 8);
            }
            e => panic!("{e}"),
        }
    }

    #[test]
    fn an_unreadable_file_is_named() {
        let path = PathBuf::from("/nonexistent/thrusterd-replay.mcap");
        let err = read(std::slice::from_ref(&path)).unwrap_err();
        assert!(err
            .to_string()
            .starts_with("/nonexistent/thrusterd-replay.mcap: "));
    }
}
