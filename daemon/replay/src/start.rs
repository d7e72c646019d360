//! Where a replay starts. From the daemon's start when the recording holds its whole journal
//! (entry 0 on) and the daemon started without a model from a file; otherwise from the
//! first checkpoint of the daemon's state (`checkpoint` channel) after which the recording
//! holds every journal entry and no model was loaded from a file: a recording started after
//! the daemon, or a daemon that started with a saved model. Pure.

use thruster_protocol::{CheckpointMsg, InputMsg};
use thrusterd_core::checkpoint_parts::{self, Place};
use thrusterd_core::config::DaemonConfig;
use thrusterd_core::machine::Machine;

use crate::journal::{self, JournalError};
use crate::rerun::Resume;
use crate::ReplayError;

/// A checkpoint the replay started from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Started {
    pub id: u64,
    pub place: Place,
    /// Size of the serialised state, bytes.
    pub bytes: usize,
}

/// What to replay: the journal entries to apply, and the machine to start from (None: a
/// new one, at the daemon's start).
pub struct Start<'a> {
    pub inputs: &'a [InputMsg],
    pub resume: Option<Resume>,
    pub checkpoint: Option<Started>,
}

/// Chooses the start for `inputs` (the recorded journal) and `checkpoints` (every recorded
/// part); a checkpoint's machine is set up from `cfg`.
pub fn choose<'a>(
    inputs: &'a [InputMsg],
    checkpoints: &[CheckpointMsg],
    cfg: &DaemonConfig,
) -> Result<Start<'a>, ReplayError> {
    let why = match journal::check(inputs) {
        Ok(inputs) => {
            return Ok(Start {
                inputs,
                resume: None,
                checkpoint: None,
            })
        }
        Err(
            e @ (JournalError::Empty
            | JournalError::StartedLate(_)
            | JournalError::StartedWithModel
            | JournalError::LoadedModel { .. }),
        ) => e,
        Err(e) => return Err(e.into()),
    };
    let first_entry = inputs.first().map(|m| m.seq);
    let mut passed = Vec::new();
    for (id, parts) in by_id(checkpoints) {
        let (place, bytes) = match checkpoint_parts::join(&parts) {
            Ok(c) => c,
            Err(e) => {
                passed.push(e.to_string());
                continue;
            }
        };
        if first_entry.is_some_and(|first| place.journal_next < first) {
            passed.push(format!(
                "checkpoint {id} precedes the recorded journal (taken before entry {}, the recording's first is {})",
                place.journal_next,
                first_entry.unwrap_or(0)
            ));
            continue;
        }
        let after = match journal::check_after(inputs, place.journal_next) {
            Ok(after) => after,
            Err(e) => {
                passed.push(format!("checkpoint {id}: {e}"));
                continue;
            }
        };
        let machine = Machine::restore(cfg.machine_setup(), &bytes)
            .map_err(|e| ReplayError::Checkpoint { id, why: e })?;
        return Ok(Start {
            inputs: after,
            resume: Some(Resume { machine, place }),
            checkpoint: Some(Started {
                id,
                place,
                bytes: bytes.len(),
            }),
        });
    }
    Err(ReplayError::NoCheckpoint {
        why,
        passed: if passed.is_empty() {
            "the recording holds no checkpoint of the daemon's state to start from instead (a daemon with [checkpoint] enabled = false, one before checkpoints existed, or a recording shorter than checkpoint.period_s)".into()
        } else {
            format!(
                "no checkpoint in the recording to start from instead: {}",
                passed.join("; ")
            )
        },
    })
}

/// The parts of each checkpoint, in the order the checkpoints were recorded.
fn by_id(parts: &[CheckpointMsg]) -> Vec<(u64, Vec<&CheckpointMsg>)> {
    let mut out: Vec<(u64, Vec<&CheckpointMsg>)> = Vec::new();
    for m in parts {
        match out.iter_mut().find(|(id, _)| *id == m.id) {
            Some((_, v)) => v.push(m),
            None => out.push((m.id, vec![m])),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::InputKind;
    use thrusterd_core::checkpoint_parts::split;

    fn entry(seq: u64, kind: InputKind, imu_count: u64) -> InputMsg {
        let mut m = InputMsg {
            seq,
            imu_count,
            imu_seq: imu_count,
            ..InputMsg::default()
        };
        m.set_kind(kind);
        m
    }

    fn checkpoint(id: u64, journal_next: u64, imu_count: u64) -> Vec<CheckpointMsg> {
        let cfg = DaemonConfig::default();
        let bytes = Machine::new(cfg.machine_setup()).checkpoint().unwrap();
        let place = Place {
            imu_count,
            imu_seq: imu_count,
            journal_next,
            ..Place::default()
        };
        split(id, &place, &bytes, 0).unwrap()
    }

    #[test]
    fn a_whole_journal_starts_at_the_daemons_start() {
        let j = [
            entry(0, InputKind::Start, 0),
            entry(1, InputKind::Request, 5),
        ];
        let s = choose(&j, &checkpoint(0, 1, 3), &DaemonConfig::default()).unwrap();
        assert!(s.checkpoint.is_none() && s.resume.is_none());
        assert_eq!(s.inputs.len(), 2);
    }

    #[test]
    fn a_late_journal_starts_at_the_first_checkpoint_it_covers() {
        let cfg = DaemonConfig::default();
        let j = [
            entry(5, InputKind::Request, 100),
            entry(6, InputKind::Request, 300),
        ];
        // Checkpoint 0 was taken before the recording's first entry; 1 covers it; 2 later.
        let parts: Vec<CheckpointMsg> = [
            checkpoint(0, 4, 50),
            checkpoint(1, 6, 200),
            checkpoint(2, 7, 400),
        ]
        .concat();
        let s = choose(&j, &parts, &cfg).unwrap();
        let c = s.checkpoint.unwrap();
        assert_eq!((c.id, c.place.journal_next, c.place.imu_count), (1, 6, 200));
        assert_eq!(s.inputs, &j[1..]);
        assert!(s.resume.is_some());
    }

    #[test]
    fn without_a_usable_checkpoint_the_reason_is_given() {
        let cfg = DaemonConfig::default();
        let j = [entry(5, InputKind::Request, 100)];
        let e = choose(&j, &[], &cfg).err().unwrap().to_string();
        assert!(
            e.contains("starts at entry 5") && e.contains("no checkpoint"),
            "{e}"
        );
        let parts = checkpoint(0, 2, 50);
        let mut later = checkpoint(1, 9, 500);
        later.remove(0);
        let e = choose(&j, &[parts, later].concat(), &cfg)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("precedes the recorded journal"), "{e}");
        assert!(e.contains("checkpoint 1: parts"), "{e}");
    }
}
