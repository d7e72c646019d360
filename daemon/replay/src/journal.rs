//! The daemon's input journal, checked: one session from its start, no entry lost, nothing
//! in it that a replay cannot reproduce. Pure.

use thruster_protocol::validate::Validate;
use thruster_protocol::{DvlSample, InputKind, InputMsg, MAX_THRUSTERS};

/// Why a journal cannot be replayed exactly.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JournalError {
    #[error("the input journal is empty: the recording does not hold the daemon's start")]
    Empty,
    #[error("the input journal starts at entry {0}, not at the daemon's start (0): the recording began after the daemon did, so the machine's state at its start is unknown")]
    StartedLate(u64),
    #[error("input journal entries {from}..{to} are missing (lost by the recorder): replaying without them would not be the daemon's session")]
    Gap { from: u64, to: u64 },
    #[error("input journal entry {seq}: a second daemon start (after IMU sample {imu_count} of the first): replay one daemon session per recording")]
    SecondStart { seq: u64, imu_count: u64 },
    #[error("the daemon started with a model loaded from its state directory; the journal does not hold the file's model, so replay cannot reproduce it")]
    StartedWithModel,
    #[error("input journal entry {seq}: after IMU sample {imu_count} the daemon loaded a model from {path}; the journal does not hold the file's model, so replay cannot reproduce it")]
    LoadedModel {
        seq: u64,
        imu_count: u64,
        path: String,
    },
    #[error("input journal entry {seq}: {why}; the daemon validated it before using it, so the recording is corrupt")]
    Invalid { seq: u64, why: String },
    #[error("input journal entry {seq}: unknown kind {kind} (a newer daemon?)")]
    UnknownKind { seq: u64, kind: u32 },
    #[error("input journal entry {seq} comes after IMU sample {imu_count}, before an earlier entry's {earlier}: out of order")]
    OutOfOrder {
        seq: u64,
        imu_count: u64,
        earlier: u64,
    },
}

/// Checks `inputs` (in recording order) and returns them, ready to replay in order.
pub fn check(inputs: &[InputMsg]) -> Result<&[InputMsg], JournalError> {
    let first = inputs.first().ok_or(JournalError::Empty)?;
    if first.seq != 0 || first.kind() != Ok(InputKind::Start) {
        return Err(JournalError::StartedLate(first.seq));
    }
    if first.code != 0 {
        return Err(JournalError::StartedWithModel);
    }
    check_entries(inputs, 0)
}

/// The entries from a checkpoint on: those with `seq >= journal_next` (the checkpoint holds
/// everything before), checked as `check` checks a whole journal. Every entry from
/// `journal_next` must be in the recording: none may be missing before the first one kept.
pub fn check_after(inputs: &[InputMsg], journal_next: u64) -> Result<&[InputMsg], JournalError> {
    let from = inputs.partition_point(|m| m.seq < journal_next);
    let after = &inputs[from..];
    if let Some(first) = after.first() {
        if first.seq != journal_next {
            return Err(JournalError::Gap {
                from: journal_next,
                to: first.seq - 1,
            });
        }
    }
    check_entries(after, journal_next)
}

/// Every entry numbered from `first_seq` without a gap, in sample order, of a known kind, with
/// a payload the daemon would have taken, and no second start or loaded model.
fn check_entries(inputs: &[InputMsg], first_seq: u64) -> Result<&[InputMsg], JournalError> {
    let mut last_count = inputs.first().map_or(0, |m| m.imu_count);
    for (i, m) in inputs.iter().enumerate() {
        let expected = first_seq + i as u64;
        if m.seq != expected {
            if m.seq == 0 {
                return Err(JournalError::SecondStart {
                    seq: expected,
                    imu_count: last_count,
                });
            }
            return Err(if m.seq > expected {
                JournalError::Gap {
                    from: expected,
                    to: m.seq - 1,
                }
            } else {
                JournalError::SecondStart {
                    seq: expected,
                    imu_count: last_count,
                }
            });
        }
        if m.imu_count < last_count {
            return Err(JournalError::OutOfOrder {
                seq: m.seq,
                imu_count: m.imu_count,
                earlier: last_count,
            });
        }
        last_count = m.imu_count;
        match m.kind() {
            Ok(InputKind::Start) if i > 0 || first_seq > 0 => {
                return Err(JournalError::SecondStart {
                    seq: m.seq,
                    imu_count: m.imu_count,
                })
            }
            Ok(InputKind::Load) => {
                return Err(JournalError::LoadedModel {
                    seq: m.seq,
                    imu_count: m.imu_count,
                    path: m.text.as_str().to_string(),
                })
            }
            Ok(kind) => {
                payload(m, kind).map_err(|why| JournalError::Invalid { seq: m.seq, why })?
            }
            Err(e) => {
                return Err(JournalError::UnknownKind {
                    seq: m.seq,
                    kind: e.value,
                })
            }
        }
    }
    Ok(inputs)
}

/// The daemon's own checks on an entry's payload, so a damaged recording cannot hand the
/// machine what the daemon never would.
fn payload(m: &InputMsg, kind: InputKind) -> Result<(), String> {
    match kind {
        InputKind::Setpoint => m.setpoint.validate().map_err(|r| format!("setpoint {r}")),
        InputKind::Reconfig => {
            m.reconfig
                .validate()
                .map_err(|r| format!("reconfiguration {r}"))?;
            let n = m.reconfig.count as usize;
            if !(1..=MAX_THRUSTERS).contains(&n) {
                return Err(format!(
                    "reconfiguration count {n} not in 1..={MAX_THRUSTERS}"
                ));
            }
            Ok(())
        }
        InputKind::Dvl => DvlSample {
            velocity: m.dvl,
            ..DvlSample::default()
        }
        .validate()
        .map_err(|r| format!("DVL velocity {r}")),
        // As the daemon took it from a validated driver report.
        InputKind::Supply if m.code > 1 => Err(format!("supply code {} not 0 or 1", m.code)),
        InputKind::Supply
            if m.code == 1
                && !(m.value.is_finite()
                    && (0.0..=thruster_protocol::validate::limits::MAX_SUPPLY_VOLTAGE_V)
                        .contains(&m.value)) =>
        {
            Err(format!("supply voltage {} V out of range", m.value))
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(seq: u64, kind: InputKind, imu_count: u64) -> InputMsg {
        let mut m = InputMsg {
            seq,
            imu_count,
            ..InputMsg::default()
        };
        m.set_kind(kind);
        m
    }

    fn journal() -> Vec<InputMsg> {
        vec![
            entry(0, InputKind::Start, 0),
            entry(1, InputKind::Request, 25),
            entry(2, InputKind::Setpoint, 900),
            entry(3, InputKind::Setpoint, 900),
        ]
    }

    #[test]
    fn a_whole_journal_passes() {
        assert_eq!(check(&journal()).unwrap().len(), 4);
    }

    #[test]
    fn a_lost_entry_is_named() {
        let mut j = journal();
        j.remove(2);
        assert_eq!(check(&j), Err(JournalError::Gap { from: 2, to: 2 }));
    }

    #[test]
    fn a_late_start_is_refused() {
        assert_eq!(check(&journal()[1..]), Err(JournalError::StartedLate(1)));
        assert_eq!(check(&[]), Err(JournalError::Empty));
    }

    #[test]
    fn after_a_checkpoint_every_entry_from_its_place_must_be_there() {
        let j = journal();
        // The recording began at entry 1; the checkpoint came before entry 2.
        assert_eq!(check_after(&j[1..], 2).unwrap(), &j[2..]);
        // Nothing after it: nothing to apply.
        assert!(check_after(&j[1..], 4).unwrap().is_empty());
        // Entry 2 lost: the replay would miss it.
        let lost = [j[1], j[3]];
        assert_eq!(
            check_after(&lost, 2),
            Err(JournalError::Gap { from: 2, to: 2 })
        );
        // A start after the checkpoint is a second session.
        let mut again = j.clone();
        again.push(entry(4, InputKind::Start, 900));
        assert!(matches!(
            check_after(&again, 2),
            Err(JournalError::SecondStart { seq: 4, .. })
        ));
    }

    #[test]
    fn a_second_session_is_refused() {
        let mut j = journal();
        j.push(entry(0, InputKind::Start, 0));
        assert_eq!(
            check(&j),
            Err(JournalError::SecondStart {
                seq: 4,
                imu_count: 900
            })
        );
    }

    #[test]
    fn models_from_files_are_refused() {
        let mut j = journal();
        j[0].code = 1;
        assert_eq!(check(&j), Err(JournalError::StartedWithModel));
        let mut j = journal();
        let mut load = entry(4, InputKind::Load, 1000);
        load.text.set("/tmp/m.json");
        j.push(load);
        assert!(matches!(
            check(&j),
            Err(JournalError::LoadedModel {
                seq: 4,
                imu_count: 1000,
                ..
            })
        ));
    }

    #[test]
    fn a_payload_the_daemon_would_not_have_taken_is_refused() {
        let mut j = journal();
        j[2].setpoint.attitude = [f64::NAN, 0.0, 0.0, 0.0];
        assert!(matches!(
            check(&j),
            Err(JournalError::Invalid { seq: 2, .. })
        ));
        let mut j = journal();
        j[2].set_kind(InputKind::Reconfig);
        j[2].reconfig.count = 0;
        assert!(matches!(
            check(&j),
            Err(JournalError::Invalid { seq: 2, .. })
        ));
    }

    #[test]
    fn an_unknown_kind_is_refused() {
        let mut j = journal();
        j[1].kind = 99;
        assert_eq!(
            check(&j),
            Err(JournalError::UnknownKind { seq: 1, kind: 99 })
        );
    }
}
