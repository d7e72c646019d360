use std::fmt;

use crate::messages::MAX_THRUSTERS;
use crate::StatusMsg;

/// Names a message field, with up to two indices (`gyro[1]`, `position[3][2]`), without
/// allocating, so validation stays cheap in the control loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    name: &'static str,
    idx: [u16; 2],
    n_idx: u8,
}

impl Field {
    /// A field without index, e.g. `depth`.
    pub const fn new(name: &'static str) -> Self {
        Self {
            name,
            idx: [0, 0],
            n_idx: 0,
        }
    }

    /// An array element, e.g. `gyro[1]`.
    pub const fn at(name: &'static str, i: usize) -> Self {
        Self {
            name,
            idx: [i as u16, 0],
            n_idx: 1,
        }
    }

    /// A matrix element, e.g. `position[3][2]`.
    pub const fn at2(name: &'static str, i: usize, j: usize) -> Self {
        Self {
            name,
            idx: [i as u16, j as u16],
            n_idx: 2,
        }
    }

    /// The field name without indices.
    pub const fn name(&self) -> &'static str {
        self.name
    }
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)?;
        for i in &self.idx[..self.n_idx as usize] {
            write!(f, "[{i}]")?;
        }
        Ok(())
    }
}

/// Why a message was rejected. The message names the field, e.g. `gyro[1] is NaN`.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum RejectReason {
    /// A floating-point value is NaN or infinite.
    #[error("{field} is {value}")]
    NonFinite {
        /// The offending field.
        field: Field,
        /// The value (NaN, inf or -inf).
        value: f64,
    },
    /// A value is outside its physical range.
    #[error("{field} = {value}{} is outside [{min}, {max}]", with_space(.unit))]
    OutOfRange {
        /// The offending field.
        field: Field,
        /// The value found.
        value: f64,
        /// Smallest accepted value.
        min: f64,
        /// Largest accepted value.
        max: f64,
        /// Unit of the value, for the message.
        unit: &'static str,
    },
    /// A vector or quaternion that must have unit length does not.
    #[error("{field} has norm {norm}, expected 1 within {tolerance}")]
    NotUnit {
        /// The offending field.
        field: Field,
        /// Its Euclidean norm.
        norm: f64,
        /// Accepted deviation from 1.
        tolerance: f64,
    },
    /// A thruster count exceeds [`MAX_THRUSTERS`].
    #[error("{field} = {count} exceeds MAX_THRUSTERS ({max})", max = MAX_THRUSTERS)]
    CountTooLarge {
        /// The offending field.
        field: Field,
        /// The count found.
        count: u32,
    },
    /// A thruster count is zero where at least one thruster is needed.
    #[error("{field} is 0 but at least one thruster is required")]
    CountZero {
        /// The offending field.
        field: Field,
    },
    /// A thruster count differs from the configured one.
    #[error("{field} = {count} but {expected} thrusters are configured")]
    CountMismatch {
        /// The offending field.
        field: Field,
        /// The count found.
        count: u32,
        /// The count this reader is configured for.
        expected: u32,
    },
    /// A thruster index is not below the thruster count.
    #[error("{field} = {index} is not below the thruster count {count}")]
    IndexOutOfRange {
        /// The offending field.
        field: Field,
        /// The index found.
        index: u32,
        /// The thruster count it must be below.
        count: u32,
    },
    /// An enum field holds a value no variant uses.
    #[error("{field} has unknown value {value}")]
    UnknownEnum {
        /// The offending field.
        field: Field,
        /// The raw value.
        value: u32,
    },
    /// A flags field has bits this protocol version does not define.
    #[error("{field} has unknown bits {bits:#x}")]
    UnknownFlags {
        /// The offending field.
        field: Field,
        /// The undefined bits that were set.
        bits: u64,
    },
    /// A 0/1 field holds another value.
    #[error("{field} = {value} is neither 0 nor 1")]
    InvalidBool {
        /// The offending field.
        field: Field,
        /// The raw value.
        value: u32,
    },
    /// Fields contradict each other.
    #[error("{field}: {detail}")]
    Inconsistent {
        /// The offending field.
        field: Field,
        /// What is wrong.
        detail: &'static str,
    },
    /// A text field is not valid UTF-8.
    #[error("{field} is not valid UTF-8")]
    InvalidText {
        /// The offending field.
        field: Field,
    },
    /// Sample time did not advance.
    #[error("t_ns {t_ns} is not after the previous message's {prev_t_ns}")]
    TimeBackwards {
        /// Time of this message, ns.
        t_ns: u64,
        /// Time of the last accepted message, ns.
        prev_t_ns: u64,
    },
    /// Sample time advanced by more than the configured maximum.
    #[error("t_ns jumped {dt_ns} ns ahead, more than the maximum {max_ns} ns")]
    TimeJump {
        /// Time since the last accepted message, ns.
        dt_ns: u64,
        /// Largest accepted step, ns.
        max_ns: u64,
    },
    /// The sequence number was already received.
    #[error("seq {seq} duplicates the previous message")]
    DuplicateSeq {
        /// The repeated sequence number.
        seq: u64,
    },
    /// The sequence number went backwards.
    #[error("seq {seq} is before the previous message's {prev_seq}")]
    SeqBackwards {
        /// Sequence number of this message.
        seq: u64,
        /// Sequence number of the last accepted message.
        prev_seq: u64,
    },
}

fn with_space(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

/// Rejection categories, one per `rejected_*` counter of [`StatusMsg`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RejectCategory {
    /// NaN or infinite value.
    NonFinite,
    /// Value outside its physical range, or a vector that is not unit length.
    Range,
    /// Time or sequence order (backwards, duplicate, jump).
    Time,
    /// Thruster count or index.
    Count,
    /// Anything else (unknown enum or flag value, bad text, inconsistent fields).
    Other,
}

impl RejectReason {
    /// Which status counter this rejection counts in.
    pub fn category(&self) -> RejectCategory {
        use RejectReason::*;
        match self {
            NonFinite { .. } => RejectCategory::NonFinite,
            OutOfRange { .. } | NotUnit { .. } => RejectCategory::Range,
            TimeBackwards { .. } | TimeJump { .. } | DuplicateSeq { .. } | SeqBackwards { .. } => {
                RejectCategory::Time
            }
            CountTooLarge { .. }
            | CountZero { .. }
            | CountMismatch { .. }
            | IndexOutOfRange { .. } => RejectCategory::Count,
            UnknownEnum { .. }
            | UnknownFlags { .. }
            | InvalidBool { .. }
            | Inconsistent { .. }
            | InvalidText { .. } => RejectCategory::Other,
        }
    }
}

/// Rejection counters by category; copy them into [`StatusMsg`] with
/// [`RejectCounters::write_to`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RejectCounters {
    /// NaN or infinite values.
    pub nonfinite: u64,
    /// Out-of-range values.
    pub range: u64,
    /// Time or sequence problems.
    pub time: u64,
    /// Count or index problems.
    pub count: u64,
    /// Everything else.
    pub other: u64,
}

impl RejectCounters {
    /// Counts one rejection.
    pub fn record(&mut self, reason: &RejectReason) {
        let c = match reason.category() {
            RejectCategory::NonFinite => &mut self.nonfinite,
            RejectCategory::Range => &mut self.range,
            RejectCategory::Time => &mut self.time,
            RejectCategory::Count => &mut self.count,
            RejectCategory::Other => &mut self.other,
        };
        *c = c.saturating_add(1);
    }

    /// Sum of all counters.
    pub fn total(&self) -> u64 {
        self.nonfinite + self.range + self.time + self.count + self.other
    }

    /// Copies the counters into the `rejected_*` fields of a status message.
    pub fn write_to(&self, status: &mut StatusMsg) {
        status.rejected_nonfinite = self.nonfinite;
        status.rejected_range = self.range;
        status.rejected_time = self.time;
        status.rejected_count = self.count;
        status.rejected_other = self.other;
    }
}
