//! A machine checkpoint (`machine::checkpoint`) on the wire: its bytes as base64 cut into
//! [`CheckpointMsg`] parts of at most [`CHECKPOINT_PART_CAPACITY`] bytes each, and joined again
//! by a reader. The daemon splits, `thrusterd replay` joins. Pure.

use base64::engine::general_purpose::STANDARD;
use base64::Engine;
use thruster_protocol::{CheckpointMsg, CHECKPOINT_MAX_PARTS, CHECKPOINT_PART_CAPACITY};

/// Where in the daemon's run a checkpoint was taken (see [`CheckpointMsg`]'s fields).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Place {
    pub imu_count: u64,
    pub imu_seq: u64,
    pub t_ns: u64,
    pub journal_next: u64,
    pub model_version: u64,
    pub reason: u32,
}

impl Place {
    /// The place a part carries.
    pub fn of(m: &CheckpointMsg) -> Place {
        Place {
            imu_count: m.imu_count,
            imu_seq: m.imu_seq,
            t_ns: m.t_ns,
            journal_next: m.journal_next,
            model_version: m.model_version,
            reason: m.reason,
        }
    }
}

/// Why a checkpoint cannot go out, or cannot be joined.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PartsError {
    #[error("checkpoint of {bytes} bytes needs {parts} parts, more than {CHECKPOINT_MAX_PARTS}")]
    TooLarge { bytes: usize, parts: usize },
    #[error("checkpoint {id}: parts {got:?} of {parts} (lost by the recorder)")]
    Incomplete { id: u64, parts: u32, got: Vec<u32> },
    #[error("checkpoint {id}: its parts disagree on where it was taken or its size")]
    Inconsistent { id: u64 },
    #[error("checkpoint {id}: not base64 ({why})")]
    NotBase64 { id: u64, why: String },
    #[error("checkpoint {id}: {got} bytes, its parts say {said}")]
    Size { id: u64, got: usize, said: u64 },
}

/// The parts of checkpoint `id` of `bytes` taken at `place`, numbered from `first_seq`.
pub fn split(
    id: u64,
    place: &Place,
    bytes: &[u8],
    first_seq: u64,
) -> Result<Vec<CheckpointMsg>, PartsError> {
    let text = STANDARD.encode(bytes);
    let parts = text.len().div_ceil(CHECKPOINT_PART_CAPACITY).max(1);
    if parts > CHECKPOINT_MAX_PARTS as usize {
        return Err(PartsError::TooLarge {
            bytes: bytes.len(),
            parts,
        });
    }
    let mut out = Vec::with_capacity(parts);
    for part in 0..parts {
        let from = part * CHECKPOINT_PART_CAPACITY;
        let to = (from + CHECKPOINT_PART_CAPACITY).min(text.len());
        let mut m = CheckpointMsg {
            seq: first_seq + part as u64,
            id,
            imu_count: place.imu_count,
            imu_seq: place.imu_seq,
            t_ns: place.t_ns,
            journal_next: place.journal_next,
            model_version: place.model_version,
            bytes: bytes.len() as u64,
            part: part as u32,
            parts: parts as u32,
            reason: place.reason,
            ..CheckpointMsg::default()
        };
        // ASCII: every cut is at a character boundary, and the capacity holds it whole.
        m.data.set(&text[from..to]);
        out.push(m);
    }
    Ok(out)
}

/// The bytes of one checkpoint from its parts (all of one `id`, in any order).
pub fn join(parts: &[&CheckpointMsg]) -> Result<(Place, Vec<u8>), PartsError> {
    let first = parts.first().ok_or(PartsError::Incomplete {
        id: 0,
        parts: 0,
        got: Vec::new(),
    })?;
    let id = first.id;
    let mut sorted: Vec<&CheckpointMsg> = parts.to_vec();
    sorted.sort_by_key(|m| m.part);
    sorted.dedup_by_key(|m| m.part);
    let complete = sorted.len() == first.parts as usize
        && sorted.iter().enumerate().all(|(i, m)| m.part as usize == i);
    if !complete {
        return Err(PartsError::Incomplete {
            id,
            parts: first.parts,
            got: sorted.iter().map(|m| m.part).collect(),
        });
    }
    let place = Place::of(first);
    if sorted
        .iter()
        .any(|m| Place::of(m) != place || m.bytes != first.bytes || m.parts != first.parts)
    {
        return Err(PartsError::Inconsistent { id });
    }
    let text: String = sorted.iter().map(|m| m.data.as_str()).collect();
    let bytes = STANDARD
        .decode(text.as_bytes())
        .map_err(|e| PartsError::NotBase64 {
            id,
            why: e.to_string(),
        })?;
    if bytes.len() as u64 != first.bytes {
        return Err(PartsError::Size {
            id,
            got: bytes.len(),
            said: first.bytes,
        });
    }
    Ok((place, bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn place() -> Place {
        Place {
            imu_count: 2000,
            imu_seq: 2007,
            t_ns: 10_000_000_000,
            journal_next: 3,
            model_version: 1,
            reason: CheckpointMsg::PERIODIC,
        }
    }

    #[test]
    fn parts_join_back_to_the_bytes_in_any_order() {
        let bytes: Vec<u8> = (0..100_000u32).map(|i| (i * 7919 % 251) as u8).collect();
        let parts = split(4, &place(), &bytes, 10).unwrap();
        assert_eq!(
            parts.len(),
            9,
            "100 kB is 133 kB of base64: 9 parts of 16 KiB"
        );
        assert_eq!(parts[0].seq, 10);
        assert!(parts.iter().all(|m| m.parts == 9 && m.id == 4));
        let mut refs: Vec<&CheckpointMsg> = parts.iter().collect();
        refs.reverse();
        assert_eq!(join(&refs).unwrap(), (place(), bytes));
    }

    #[test]
    fn a_lost_part_or_a_damaged_one_is_named() {
        let bytes = vec![7u8; 40_000];
        let parts = split(1, &place(), &bytes, 0).unwrap();
        let refs: Vec<&CheckpointMsg> = parts.iter().filter(|m| m.part != 1).collect();
        assert_eq!(
            join(&refs),
            Err(PartsError::Incomplete {
                id: 1,
                parts: 4,
                got: vec![0, 2, 3]
            })
        );
        let mut bad = parts.clone();
        bad[2].data.set("!!!!");
        let refs: Vec<&CheckpointMsg> = bad.iter().collect();
        assert!(matches!(
            join(&refs),
            Err(PartsError::NotBase64 { id: 1, .. })
        ));
        let mut moved = parts.clone();
        moved[3].imu_count += 1;
        let refs: Vec<&CheckpointMsg> = moved.iter().collect();
        assert_eq!(join(&refs), Err(PartsError::Inconsistent { id: 1 }));
    }

    #[test]
    fn a_checkpoint_beyond_the_parts_limit_is_refused() {
        let bytes = vec![0u8; CHECKPOINT_MAX_PARTS as usize * CHECKPOINT_PART_CAPACITY];
        assert!(matches!(
            split(0, &place(), &bytes, 0),
            Err(PartsError::TooLarge { .. })
        ));
    }
}
