//! The channels a replay needs, decoded from one recording (a file and its rotations).

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use thruster_protocol::{CheckpointMsg, ConfigMsg, ImuSample, InputMsg, ModelMsg, ThrustCommand};

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
    /// Every part of every checkpoint of the daemon's state (where a late recording's
    /// replay starts).
    pub checkpoints: Vec<CheckpointMsg>,
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
                "checkpoint" => decode(path, "checkpoint", messages, &mut rec.checkpoints)?,
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

/// serde_json writes a non-finite f64 as `null` (JSON has no NaN): a model's unknown bound, a
/// driver's NaN the daemon rejected. Such a message is read with every `null` as this
/// sentinel, which `NonFinite::restore` turns back into NaN (no field of a valid message comes
/// near it: the protocol bounds every value far below).
const NULL_F64: f64 = f64::MAX;

/// Messages whose floats may have been written as `null`.
pub trait NonFinite {
    /// Turns the sentinel back into NaN.
    fn restore(&mut self) {}
}

fn nan(x: &mut f64) {
    if *x == NULL_F64 {
        *x = f64::NAN;
    }
}

impl NonFinite for ImuSample {
    fn restore(&mut self) {
        self.gyro
            .iter_mut()
            .chain(&mut self.accel)
            .chain(&mut self.mag)
            .chain(std::iter::once(&mut self.depth))
            .for_each(nan);
    }
}

impl NonFinite for ModelMsg {
    fn restore(&mut self) {
        self.effectiveness
            .iter_mut()
            .chain(&mut self.std_err)
            .flatten()
            .chain(self.allocation.iter_mut().flatten())
            .chain([&mut self.rel_err_rot, &mut self.rel_err_acc])
            .for_each(nan);
    }
}

// The daemon validated these before sending or journaling them: always finite.
impl NonFinite for InputMsg {}
impl NonFinite for ThrustCommand {}
impl NonFinite for ConfigMsg {}
impl NonFinite for CheckpointMsg {}

/// Every `null` in `v` (at any depth) replaced by the sentinel.
fn nulls_to_sentinel(v: &mut serde_json::Value) -> bool {
    use serde_json::Value;
    match v {
        Value::Null => {
            *v = Value::from(NULL_F64);
            true
        }
        Value::Array(a) => a
            .iter_mut()
            .fold(false, |any, x| nulls_to_sentinel(x) | any),
        Value::Object(o) => o
            .values_mut()
            .fold(false, |any, x| nulls_to_sentinel(x) | any),
        _ => false,
    }
}

fn decode_one<T: DeserializeOwned + NonFinite>(data: &[u8]) -> Result<T, serde_json::Error> {
    match serde_json::from_slice(data) {
        Ok(v) => Ok(v),
        Err(first) => {
            let mut value: serde_json::Value = serde_json::from_slice(data)?;
            // Matrices are recorded as arrays of row objects (thruster_recorder::schema);
            // recordings made before that hold arrays of arrays, which pass unchanged.
            thruster_recorder::schema::from_recorded(&mut value);
            if let Ok(v) = serde_json::from_value::<T>(value.clone()) {
                return Ok(v);
            }
            if !nulls_to_sentinel(&mut value) {
                return Err(first);
            }
            let mut msg: T = serde_json::from_value(value).map_err(|_| first)?;
            msg.restore();
            Ok(msg)
        }
    }
}

fn decode<T: DeserializeOwned + NonFinite>(
    path: &Path,
    topic: &'static str,
    messages: &[RawMessage],
    out: &mut Vec<T>,
) -> Result<(), RecordingError> {
    for m in messages {
        let value = decode_one(&m.data).map_err(|reason| RecordingError::Json {
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
    fn non_finite_floats_written_as_null_come_back_as_nan() {
        let mut m = ModelMsg {
            count: 2,
            ..ModelMsg::default()
        };
        m.std_err[1][1] = f64::NAN;
        m.rel_err_acc = f64::INFINITY;
        m.effectiveness[0][1] = 0.1 + 0.2;
        let json = serde_json::to_vec(&m).unwrap();
        let back: ModelMsg = decode_one(&json).unwrap();
        assert!(back.std_err[1][1].is_nan() && back.rel_err_acc.is_nan());
        assert_eq!(back.effectiveness[0][1], 0.1 + 0.2);
        assert_eq!(back.std_err[0][0], 0.0);
        // Other damage is still refused.
        assert!(decode_one::<ModelMsg>(b"{\"seq\": null}").is_err());
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
