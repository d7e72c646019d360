//! `watch`: a line per meaningful status change until Ctrl-C.
//!
//! The daemon publishes status every ~100 ms with counters and clocks that always move;
//! printing each would bury the changes an operator cares about. [`ChangeFilter`] decides.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Result;
use thruster_protocol::StatusMsg;

use crate::checks::{status_problem, Warner};
use crate::client::{not_running, Daemon};
use crate::console::{interrupted_during_wait, say};
use crate::exit;
use crate::json::StatusJson;
use crate::render;

/// Poll period (also bounds the Ctrl-C reaction time).
const TICK: Duration = Duration::from_millis(100);
/// New rejections alone print a line at most this often (a driver sending garbage at
/// 400 Hz must not flood the terminal).
const REJECTION_LINE_PERIOD: Duration = Duration::from_secs(1);

/// The fields whose change is worth a line. Floats are compared bitwise: the daemon sends
/// the same value again when nothing changed.
#[derive(Debug, Clone, PartialEq)]
struct Key {
    state: u32,
    pulse: u32,
    pulses_planned: u32,
    model_version: u64,
    power: u64,
    error_bound: u64,
    text: String,
}

impl From<&StatusMsg> for Key {
    fn from(s: &StatusMsg) -> Self {
        Self {
            state: s.state,
            pulse: s.pulse,
            pulses_planned: s.pulses_planned,
            model_version: s.model_version,
            power: s.power.to_bits(),
            error_bound: s.error_bound.to_bits(),
            text: s.text().to_string(),
        }
    }
}

/// Decides which statuses `watch` prints.
#[derive(Debug, Default)]
pub struct ChangeFilter {
    last: Option<(Key, u64)>,
    last_rejection_line: Option<Instant>,
}

impl ChangeFilter {
    pub fn should_print(&mut self, s: &StatusMsg, now: Instant) -> bool {
        let key = Key::from(s);
        let rejected = render::total_rejections(s);
        let print = match &self.last {
            None => true,
            Some((k, _)) if *k != key => true,
            Some((_, r)) if *r != rejected => self
                .last_rejection_line
                .is_none_or(|t| now.duration_since(t) >= REJECTION_LINE_PERIOD),
            Some(_) => false,
        };
        if print {
            if self.last.as_ref().is_some_and(|(_, r)| *r != rejected) {
                self.last_rejection_line = Some(now);
            }
            self.last = Some((key, rejected));
        }
        print
    }
}

pub fn run(daemon: &Daemon, json: bool, interrupted: Arc<AtomicBool>) -> Result<()> {
    let inbox = daemon.inbox::<StatusMsg>()?;
    daemon.ensure_running()?;
    let mut filter = ChangeFilter::default();
    let mut warner = Warner::default();
    // Wall-clock silence after which we ask whether the daemon is still there.
    let silence = daemon.timeout().max(Duration::from_secs(1));
    let mut last_heard = Instant::now();
    let mut gone = false;
    while !interrupted.load(Ordering::SeqCst) {
        let now = Instant::now();
        if let Some(s) = inbox.recv_latest()? {
            last_heard = now;
            if gone {
                eprintln!("thrusterd is back on namespace {}", daemon.namespace());
                gone = false;
            }
            warner.warn(status_problem(&s));
            if filter.should_print(&s, now) {
                if json {
                    say(&serde_json::to_string(&StatusJson::from(&s))?)?;
                } else {
                    say(&render::status_line(&s))?;
                }
            }
        } else if now.duration_since(last_heard) > silence {
            last_heard = now;
            match daemon.ensure_running() {
                Ok(_) => eprintln!(
                    "note: no status for {:.1} s, but thrusterd answers",
                    silence.as_secs_f64()
                ),
                Err(e) if exit::code_of(&e) == exit::NOT_RUNNING => {
                    if !gone {
                        eprintln!(
                            "{}; waiting for it (Ctrl-C to stop)",
                            not_running(daemon.namespace(), &daemon.root_dir())
                        );
                        gone = true;
                    }
                }
                Err(e) => eprintln!("warning: {e:#}"),
            }
        }
        if let Err(e) = inbox.wait(TICK) {
            if !interrupted_during_wait(&interrupted) {
                return Err(e.into());
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::DaemonState;

    fn status(state: DaemonState, pulse: u32) -> StatusMsg {
        let mut s = StatusMsg {
            pulse,
            pulses_planned: 8,
            ..StatusMsg::default()
        };
        s.set_state(state);
        s
    }

    #[test]
    fn prints_changes_not_ticks() {
        let t0 = Instant::now();
        let mut f = ChangeFilter::default();
        let mut s = status(DaemonState::Pulse, 0);
        assert!(f.should_print(&s, t0));
        // Clocks and sample counters move every tick: no line.
        s.samples += 40;
        s.vehicle_time_ns += 100_000_000;
        s.imu_rate_hz = 399.7;
        s.sigma_rot = 0.01;
        assert!(!f.should_print(&s, t0));
        s.pulse = 1;
        assert!(f.should_print(&s, t0));
        s.set_state(DaemonState::Settle);
        assert!(f.should_print(&s, t0));
        s.set_text("settling");
        assert!(f.should_print(&s, t0));
        assert!(!f.should_print(&s, t0));
    }

    #[test]
    fn rejections_alone_print_at_most_once_a_second() {
        let t0 = Instant::now();
        let mut f = ChangeFilter::default();
        let mut s = status(DaemonState::Active, 0);
        assert!(f.should_print(&s, t0));
        s.rejected_range = 1;
        assert!(f.should_print(&s, t0));
        s.rejected_range = 2;
        assert!(!f.should_print(&s, t0 + Duration::from_millis(500)));
        s.rejected_range = 3;
        assert!(f.should_print(&s, t0 + Duration::from_millis(1000)));
        // A real change prints regardless.
        s.rejected_range = 4;
        s.set_state(DaemonState::Fault);
        assert!(f.should_print(&s, t0 + Duration::from_millis(1001)));
    }
}
