//! The other end of the stepping protocol (`thruster-sim run --lockstep --stepped`, served by
//! the driver's `stepping` module): whoever drives a stepped simulator (the lab's demo and
//! experiments, the system tests) lets vehicle time advance a few samples at a time and reads
//! and acts between steps. Every request, setpoint and decision then lands at the same vehicle
//! time in every run of a seed, however loaded the machine is (issue 27); before, the driver
//! acted on its own wall clock while the simulator ran ahead.
//!
//! Protocol: the driver writes `run N`; the simulator takes N more samples, each answered by
//! the daemon, and writes `at SEQ T_NS`.

use std::io::{BufRead, BufReader, Write};
use std::process::{ChildStdin, ChildStdout};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::Duration;

/// Why a step failed: the simulator is gone, stuck or speaking another protocol.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    #[error("starting the stepper's reader: {0}")]
    Reader(std::io::Error),
    #[error("the simulator's standard input is closed: {0}")]
    Closed(std::io::Error),
    #[error("the simulator did not hold within {0} s of a step")]
    Stuck(u64),
    #[error("the simulator closed its standard output (it exited)")]
    Exited,
    #[error("a process the step waited on is gone")]
    PeerGone,
    #[error("the simulator's stepping line {0:?} is not `at SEQ T_NS`")]
    Garbled(String),
}

/// Samples per step. The driver reads every message between steps, so a step must not outrun
/// the smallest inbox it keeps (status: 4 messages; vehicle state and thrust: 16, one per
/// sample); 8 samples is 40 ms of vehicle time at 200 Hz, 8 ms at 1 kHz.
pub const STEP_SAMPLES: u64 = 8;

/// Longest wall time one step may take (the daemon answers each sample within the
/// simulator's lockstep timeout, 2 s by default, or the simulator goes on without it).
const STEP_TIMEOUT: Duration = Duration::from_secs(120);

/// How often a step's wait asks whether the processes it waits on still run: a daemon that
/// died mid-step was otherwise noticed only after `STEP_TIMEOUT`.
const LIVENESS_EVERY: Duration = Duration::from_millis(100);

/// Where the simulator stands: the newest sample, answered, and nothing newer taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Held {
    pub seq: u64,
    pub t_ns: u64,
}

pub struct Stepper {
    to_sim: ChildStdin,
    lines: Receiver<String>,
    held: Option<Held>,
}

impl Stepper {
    /// Takes the simulator's standard input and output (its log goes to standard error).
    pub fn new(to_sim: ChildStdin, from_sim: ChildStdout) -> Result<Stepper, StepError> {
        let (tx, lines) = mpsc::channel();
        std::thread::Builder::new()
            .name("stepper".into())
            .spawn(move || {
                for line in BufReader::new(from_sim).lines() {
                    let Ok(line) = line else { return };
                    if tx.send(line).is_err() {
                        return;
                    }
                }
            })
            .map_err(StepError::Reader)?;
        Ok(Stepper {
            to_sim,
            lines,
            held: None,
        })
    }

    /// Where the simulator was held last (None before its first sample was answered).
    pub fn held(&self) -> Option<Held> {
        self.held
    }

    /// Lets the simulator take `n` more samples and waits until it holds again; the first
    /// call first waits for the answer to the first sample.
    pub fn advance(&mut self, n: u64) -> Result<Held, StepError> {
        self.advance_while(n, || true)
    }

    /// [`Self::advance`], giving up with [`StepError::PeerGone`] as soon as `alive` says a
    /// process the step depends on (the daemon that answers the samples) is gone; asked
    /// every [`LIVENESS_EVERY`] of the wait.
    pub fn advance_while(
        &mut self,
        n: u64,
        mut alive: impl FnMut() -> bool,
    ) -> Result<Held, StepError> {
        if self.held.is_none() {
            self.held = Some(self.next_hold(&mut alive)?);
        }
        writeln!(self.to_sim, "run {n}")
            .and_then(|_| self.to_sim.flush())
            .map_err(StepError::Closed)?;
        let held = self.next_hold(&mut alive)?;
        self.held = Some(held);
        Ok(held)
    }

    fn next_hold(&mut self, alive: &mut impl FnMut() -> bool) -> Result<Held, StepError> {
        let start = std::time::Instant::now();
        let line = loop {
            match self.lines.recv_timeout(LIVENESS_EVERY) {
                Ok(line) => break line,
                Err(RecvTimeoutError::Disconnected) => return Err(StepError::Exited),
                Err(RecvTimeoutError::Timeout) => {
                    if !alive() {
                        return Err(StepError::PeerGone);
                    }
                    if start.elapsed() >= STEP_TIMEOUT {
                        return Err(StepError::Stuck(STEP_TIMEOUT.as_secs()));
                    }
                }
            }
        };
        parse_held(&line).ok_or(StepError::Garbled(line))
    }
}

fn parse_held(line: &str) -> Option<Held> {
    let mut w = line.split_whitespace();
    match (w.next(), w.next(), w.next(), w.next()) {
        (Some("at"), Some(seq), Some(t), None) => Some(Held {
            seq: seq.parse().ok()?,
            t_ns: t.parse().ok()?,
        }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hold_line_is_at_seq_and_time() {
        assert_eq!(
            parse_held("at 17 80000000"),
            Some(Held {
                seq: 17,
                t_ns: 80_000_000
            })
        );
        for bad in ["at 17", "at x 5", "held 1 2", "at 1 2 3", ""] {
            assert_eq!(parse_held(bad), None, "{bad:?}");
        }
    }

    /// A simulator that never holds and a peer that is gone: the step gives up within a
    /// liveness period, not after `STEP_TIMEOUT` (a demo whose daemon died mid-step sat two
    /// minutes silent).
    #[test]
    fn a_step_gives_up_once_its_peer_is_gone() {
        use std::process::{Command, Stdio};
        let mut never = Command::new("sleep")
            .arg("30")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stepper =
            Stepper::new(never.stdin.take().unwrap(), never.stdout.take().unwrap()).unwrap();
        let start = std::time::Instant::now();
        let mut asked = 0;
        let e = stepper
            .advance_while(STEP_SAMPLES, || {
                asked += 1;
                asked < 3
            })
            .unwrap_err();
        let took = start.elapsed();
        let _ = never.kill();
        let _ = never.wait();
        assert!(matches!(e, StepError::PeerGone), "{e}");
        assert_eq!(asked, 3);
        assert!(
            took >= LIVENESS_EVERY * 3 && took < STEP_TIMEOUT / 10,
            "{took:?}"
        );
    }
}
