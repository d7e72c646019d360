//! Stateful checks on message streams: time must advance, sequence numbers must not
//! repeat or go back, and time must not jump further than a configured maximum.

use std::marker::PhantomData;

use super::{RejectReason, Validate};
use crate::{ImuSample, ThrustCommand};

/// Position of a message in its stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp {
    /// Sequence number.
    pub seq: u64,
    /// Time, ns, on the stream's monotonic clock.
    pub t_ns: u64,
}

/// A message type that belongs to a time-ordered stream.
pub trait Sequenced {
    /// Sequence number and time of this message.
    fn stamp(&self) -> Stamp;
}

impl Sequenced for ImuSample {
    fn stamp(&self) -> Stamp {
        Stamp {
            seq: self.seq,
            t_ns: self.t_ns,
        }
    }
}

impl Sequenced for ThrustCommand {
    /// Commands carry the time of the IMU sample they answer, which advances with every
    /// command when the daemon answers each sample once.
    fn stamp(&self) -> Stamp {
        Stamp {
            seq: self.seq,
            t_ns: self.t_ns,
        }
    }
}

/// Settings of a [`SequenceChecker`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SequenceConfig {
    /// Largest accepted time step between consecutive accepted messages, ns. Protects
    /// against a corrupt far-future timestamp, after which every good sample would
    /// look like it went backwards. Default 1 s.
    pub max_time_jump_ns: u64,
    /// After a rejection, this many consecutive messages that are in order among
    /// themselves (but not with the old stream) are taken as a restarted stream: the
    /// last of them is accepted with [`Accepted::resynced`] set. This recovers from a
    /// driver restart or a dropout longer than `max_time_jump_ns`. Values below 2 are
    /// raised to 2 (1 would accept every out-of-order message). Default 3.
    pub resync_after: u32,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        Self {
            max_time_jump_ns: 1_000_000_000,
            resync_after: 3,
        }
    }
}

/// Result of an accepted message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Accepted {
    /// Messages missing between the previous accepted one and this (sequence gap).
    pub missed: u64,
    /// The stream restarted (see [`SequenceConfig::resync_after`]): time is not
    /// continuous with earlier messages, so anything integrating over time must restart.
    pub resynced: bool,
}

/// Rejects time going backwards or standing still, duplicated or backwards sequence
/// numbers and time jumps above the maximum; re-synchronises to a restarted stream.
///
/// State only advances on accepted messages, so one corrupt message cannot poison the
/// stream.
#[derive(Debug, Clone)]
pub struct SequenceChecker {
    config: SequenceConfig,
    last: Option<Stamp>,
    candidate: Option<Stamp>,
    candidate_run: u32,
    consecutive_rejections: u64,
}

impl SequenceChecker {
    /// A checker that accepts any first message.
    pub fn new(config: SequenceConfig) -> Self {
        Self {
            config: SequenceConfig {
                resync_after: config.resync_after.max(2),
                ..config
            },
            last: None,
            candidate: None,
            candidate_run: 0,
            consecutive_rejections: 0,
        }
    }

    /// The settings in use (with `resync_after` raised to at least 2).
    pub fn config(&self) -> &SequenceConfig {
        &self.config
    }

    /// The last accepted message's stamp.
    pub fn last(&self) -> Option<Stamp> {
        self.last
    }

    /// Rejections since the last accepted message.
    pub fn consecutive_rejections(&self) -> u64 {
        self.consecutive_rejections
    }

    /// Forgets the stream: the next message is accepted as the first.
    pub fn reset(&mut self) {
        *self = Self::new(self.config);
    }

    /// Checks the next message's stamp; on success it becomes the reference.
    pub fn check(&mut self, stamp: Stamp) -> Result<Accepted, RejectReason> {
        let Some(last) = self.last else {
            self.accept(stamp);
            return Ok(Accepted::default());
        };
        match follows(last, stamp, self.config.max_time_jump_ns) {
            Ok(missed) => {
                self.accept(stamp);
                Ok(Accepted {
                    missed,
                    resynced: false,
                })
            }
            Err(reason) => {
                // A real discontinuity (driver restart, long dropout) shows up as a run of
                // messages that are in order among themselves but not with `last`.
                let continues_run = self
                    .candidate
                    .is_some_and(|c| follows(c, stamp, self.config.max_time_jump_ns).is_ok());
                self.candidate_run = if continues_run {
                    self.candidate_run + 1
                } else {
                    1
                };
                self.candidate = Some(stamp);
                if self.candidate_run >= self.config.resync_after {
                    self.accept(stamp);
                    return Ok(Accepted {
                        missed: 0,
                        resynced: true,
                    });
                }
                self.consecutive_rejections += 1;
                Err(reason)
            }
        }
    }

    fn accept(&mut self, stamp: Stamp) {
        self.last = Some(stamp);
        self.candidate = None;
        self.candidate_run = 0;
        self.consecutive_rejections = 0;
    }
}

impl Default for SequenceChecker {
    fn default() -> Self {
        Self::new(SequenceConfig::default())
    }
}

/// `Ok(missed)` when `next` may follow `prev`.
fn follows(prev: Stamp, next: Stamp, max_jump_ns: u64) -> Result<u64, RejectReason> {
    if next.seq == prev.seq {
        return Err(RejectReason::DuplicateSeq { seq: next.seq });
    }
    if next.seq < prev.seq {
        return Err(RejectReason::SeqBackwards {
            seq: next.seq,
            prev_seq: prev.seq,
        });
    }
    if next.t_ns <= prev.t_ns {
        return Err(RejectReason::TimeBackwards {
            t_ns: next.t_ns,
            prev_t_ns: prev.t_ns,
        });
    }
    let dt_ns = next.t_ns - prev.t_ns;
    if dt_ns > max_jump_ns {
        return Err(RejectReason::TimeJump {
            dt_ns,
            max_ns: max_jump_ns,
        });
    }
    Ok(next.seq - prev.seq - 1)
}

/// Content validation plus stream order for one message stream, e.g.
/// [`super::ImuSampleValidator`]. Content is checked first, so a corrupt message never
/// advances the stream state.
#[derive(Debug, Clone)]
pub struct StreamValidator<T> {
    sequence: SequenceChecker,
    _message: PhantomData<fn(&T)>,
}

impl<T: Validate + Sequenced> StreamValidator<T> {
    /// A validator with the given stream settings.
    pub fn new(config: SequenceConfig) -> Self {
        Self {
            sequence: SequenceChecker::new(config),
            _message: PhantomData,
        }
    }

    /// Validates `msg` and, if valid, checks and advances the stream order.
    pub fn check(&mut self, msg: &T) -> Result<Accepted, RejectReason> {
        msg.validate()?;
        self.sequence.check(msg.stamp())
    }

    /// The underlying sequence checker (last stamp, consecutive rejections, reset).
    pub fn sequence(&mut self) -> &mut SequenceChecker {
        &mut self.sequence
    }
}

impl<T: Validate + Sequenced> Default for StreamValidator<T> {
    fn default() -> Self {
        Self::new(SequenceConfig::default())
    }
}
