//! `watch`: a line per meaningful status change, and the daemon's telemetry live, until Ctrl-C.
//!
//! The daemon publishes status every ~100 ms with counters and clocks that always move;
//! printing each would bury the changes an operator cares about. [`ChangeFilter`] decides.
//! Telemetry (attitude, setpoint, error, depth, thrust, estimation) comes at the daemon's
//! `telemetry.every_n`: on a terminal it is a small dashboard redrawn in place below the status
//! lines, otherwise one plain line at most every `--interval-ms` (1 s by default, so a log
//! stays readable). A change of the setpoint the daemon holds always prints at once.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use thruster_protocol::{StatusMsg, TelemetryMsg, Validate};

use crate::checks::{status_problem, Warner};
use crate::client::{not_running, Daemon};
use crate::console::{interrupted_during_wait, say};
use crate::exit::{self, Failure};
use crate::json::{StatusJson, TelemetryLineJson};
use crate::render;
use crate::telemetry::{self, HeldSetpoint};

/// Longest wait between looks at status (also bounds the Ctrl-C reaction time). Telemetry
/// wakes the loop earlier whenever it comes.
const TICK: Duration = Duration::from_millis(100);
/// New rejections alone print a line at most this often (a driver sending garbage at
/// 400 Hz must not flood the terminal).
const REJECTION_LINE_PERIOD: Duration = Duration::from_secs(1);
/// Telemetry shown at most this often on a terminal (the eye reads no faster) ...
const DASHBOARD_INTERVAL: Duration = Duration::from_millis(100);
/// ... and into a pipe or file, where every line stays.
const LINE_INTERVAL: Duration = Duration::from_secs(1);
/// Longest `--interval-ms`.
const MAX_INTERVAL_MS: u64 = 3_600_000;
/// A reader of every message (`--interval-ms 0`) buffers a burst this long at 1 kHz.
const EVERY_MESSAGE_BUFFER: usize = 128;

/// How `watch` shows what it gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Options {
    /// JSON lines instead of text.
    pub json: bool,
    /// Redraw a dashboard in place (stdout is a terminal, not JSON).
    pub dashboard: bool,
    /// Telemetry shown at most this often (zero: every message).
    pub interval: Duration,
}

impl Options {
    /// From the command line, for this process's stdout.
    pub fn new(json: bool, interval_ms: Option<u64>) -> Result<Self, Failure> {
        Self::for_output(json, interval_ms, std::io::stdout().is_terminal())
    }

    /// As [`Options::new`] for an output that is a terminal or not.
    pub fn for_output(
        json: bool,
        interval_ms: Option<u64>,
        terminal: bool,
    ) -> Result<Self, Failure> {
        let dashboard = terminal && !json;
        let interval = match interval_ms {
            Some(ms) if ms > MAX_INTERVAL_MS => {
                return Err(Failure::usage(format!(
                    "--interval-ms must be in 0..={MAX_INTERVAL_MS}, got {ms}"
                )))
            }
            Some(ms) => Duration::from_millis(ms),
            None if dashboard => DASHBOARD_INTERVAL,
            None => LINE_INTERVAL,
        };
        Ok(Self {
            json,
            dashboard,
            interval,
        })
    }
}

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

/// Which daemon a status comes from, compared with the last one seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Life {
    /// The daemon seen before (or the first one seen).
    Same,
    /// Another daemon instance: its status sequence started again below the last one, or it
    /// came after the last one's "stopped". What was drawn for the old one is stale.
    Restarted,
    /// The daemon's last status: it exited.
    Stopped,
}

/// Follows the daemon instance through its statuses' sequence numbers (a daemon starts at 0
/// and counts up; a restarted one starts again).
#[derive(Debug, Default)]
pub struct Instance {
    last_seq: Option<u64>,
    stopped: bool,
}

impl Instance {
    pub fn observe(&mut self, s: &StatusMsg) -> Life {
        let restarted = self.stopped || self.last_seq.is_some_and(|last| s.seq < last);
        self.last_seq = Some(s.seq);
        self.stopped = s.is_stopped();
        if self.stopped {
            Life::Stopped
        } else if restarted {
            Life::Restarted
        } else {
            Life::Same
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

/// Decides which telemetry `watch` shows: every message, or one per interval; a change of
/// the held setpoint always, at once.
#[derive(Debug)]
pub struct TelemetryFilter {
    interval: Duration,
    last_shown: Option<Instant>,
    held: Option<HeldSetpoint>,
}

/// What to do with one telemetry message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Show {
    /// The setpoint the daemon holds changed (or control began).
    pub setpoint_changed: bool,
    /// Show the telemetry itself.
    pub telemetry: bool,
}

impl TelemetryFilter {
    pub fn new(interval: Duration) -> Self {
        Self {
            interval,
            last_shown: None,
            held: None,
        }
    }

    pub fn decide(&mut self, t: &TelemetryMsg, now: Instant) -> Show {
        let held = HeldSetpoint::of(t);
        let setpoint_changed = held.is_some() && held != self.held;
        self.held = held;
        let due = self
            .last_shown
            .is_none_or(|last| now.duration_since(last) >= self.interval);
        let telemetry = due || setpoint_changed;
        if telemetry {
            self.last_shown = Some(now);
        }
        Show {
            setpoint_changed,
            telemetry,
        }
    }
}

/// stdout: lines, and on a terminal the dashboard kept below them.
struct Screen {
    dashboard: bool,
    /// Lines of the dashboard on screen now (the cursor is on the line below them).
    drawn: usize,
    board: Vec<String>,
}

impl Screen {
    fn new(dashboard: bool) -> Self {
        Self {
            dashboard,
            drawn: 0,
            board: Vec::new(),
        }
    }

    /// A line that stays (status, setpoint), above the dashboard.
    fn line(&mut self, text: &str) -> Result<()> {
        if !self.dashboard {
            return say(text);
        }
        let mut frame = self.erase();
        frame.push_str(text);
        frame.push('\n');
        self.draw_into(&mut frame);
        write_out(&frame)
    }

    /// Takes the dashboard off the screen (its daemon stopped or was replaced).
    fn clear(&mut self) -> Result<()> {
        self.board.clear();
        let frame = self.erase();
        if frame.is_empty() {
            return Ok(());
        }
        write_out(&frame)
    }

    /// Replaces the dashboard.
    fn show(&mut self, board: Vec<String>) -> Result<()> {
        self.board = board;
        let mut frame = self.erase();
        self.draw_into(&mut frame);
        write_out(&frame)
    }

    /// Cursor up over the dashboard and clear to the end of the screen (ANSI), as one write
    /// with what follows, so the terminal never shows it half drawn.
    fn erase(&mut self) -> String {
        let n = std::mem::take(&mut self.drawn);
        if n == 0 {
            String::new()
        } else {
            format!("\x1b[{n}A\r\x1b[J")
        }
    }

    fn draw_into(&mut self, frame: &mut String) {
        for l in &self.board {
            frame.push_str(l);
            frame.push('\n');
        }
        self.drawn = self.board.len();
    }
}

fn write_out(frame: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(frame.as_bytes())
        .context("writing to stdout")?;
    out.flush().context("writing to stdout")
}

pub fn run(daemon: &Daemon, options: Options, interrupted: Arc<AtomicBool>) -> Result<()> {
    let inbox = daemon.inbox::<StatusMsg>()?;
    daemon.ensure_running()?;
    let telemetry_in = if options.interval.is_zero() {
        daemon.inbox_with_buffer::<TelemetryMsg>(EVERY_MESSAGE_BUFFER)?
    } else {
        daemon.inbox::<TelemetryMsg>()?
    };
    let mut filter = ChangeFilter::default();
    let mut instance = Instance::default();
    let mut shown = TelemetryFilter::new(options.interval);
    let mut screen = Screen::new(options.dashboard);
    let mut warner = Warner::default();
    let mut telemetry_warner = Warner::default();
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
            match instance.observe(&s) {
                Life::Same => {}
                // The old daemon's dashboard, setpoint and last status say nothing of the new
                // one (issue 27: a dead daemon's "Active, model v8" stayed drawn).
                Life::Restarted => {
                    screen.clear()?;
                    filter = ChangeFilter::default();
                    shown = TelemetryFilter::new(options.interval);
                    if !options.json {
                        screen.line("thrusterd restarted: a new instance, showing its state")?;
                    }
                }
                Life::Stopped => {
                    screen.clear()?;
                    shown = TelemetryFilter::new(options.interval);
                }
            }
            if filter.should_print(&s, now) {
                if options.json {
                    screen.line(&serde_json::to_string(&StatusJson::from(&s))?)?;
                } else {
                    screen.line(&render::status_line(&s))?;
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
        // Oldest first, so with `--interval-ms 0` every buffered message is shown; otherwise
        // the buffer holds one, the newest.
        while let Some(t) = telemetry_in.recv()? {
            if let Err(reason) = t.validate() {
                telemetry_warner.warn(Some(format!("telemetry ignored: {reason}")));
                continue;
            }
            let show = shown.decide(&t, now);
            if show.setpoint_changed && !options.json {
                screen.line(&telemetry::setpoint_line(&t))?;
            }
            if !show.telemetry {
                continue;
            }
            if options.json {
                screen.line(&serde_json::to_string(&TelemetryLineJson::from(&t))?)?;
            } else if options.dashboard {
                screen.show(telemetry::dashboard(&t))?;
            } else {
                screen.line(&telemetry::line(&t))?;
            }
        }
        if let Err(e) = telemetry_in.wait(TICK) {
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

    /// Issue 27: after a restart `watch` went on drawing the dead daemon's dashboard.
    #[test]
    fn a_restart_and_a_stop_are_told_from_the_sequence_and_the_last_text() {
        let mut life = Instance::default();
        let at = |seq: u64, text: &str| {
            let mut s = status(DaemonState::Active, 0);
            s.seq = seq;
            s.set_text(text);
            s
        };
        assert_eq!(life.observe(&at(40, "")), Life::Same);
        assert_eq!(life.observe(&at(41, "")), Life::Same);
        // A new daemon counts from 0 again.
        assert_eq!(life.observe(&at(2, "")), Life::Restarted);
        assert_eq!(life.observe(&at(3, "")), Life::Same);
        assert_eq!(life.observe(&at(4, StatusMsg::STOPPED_TEXT)), Life::Stopped);
        // Whatever comes after a stop is another daemon, even with a higher number.
        assert_eq!(life.observe(&at(9, "")), Life::Restarted);
    }

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

    #[test]
    fn options_default_by_output_and_bound_the_interval() {
        let tty = Options::for_output(false, None, true).unwrap();
        assert!(tty.dashboard);
        assert_eq!(tty.interval, DASHBOARD_INTERVAL);
        let piped = Options::for_output(false, None, false).unwrap();
        assert!(!piped.dashboard);
        assert_eq!(piped.interval, LINE_INTERVAL);
        // JSON is lines even on a terminal.
        assert!(!Options::for_output(true, None, true).unwrap().dashboard);
        assert_eq!(
            Options::for_output(false, Some(0), false).unwrap().interval,
            Duration::ZERO
        );
        let e = Options::for_output(false, Some(MAX_INTERVAL_MS + 1), false).unwrap_err();
        assert_eq!(e.code, exit::USAGE);
    }

    #[test]
    fn telemetry_once_per_interval_and_every_setpoint_change_at_once() {
        let t0 = Instant::now();
        let mut f = TelemetryFilter::new(Duration::from_secs(1));
        let mut t = TelemetryMsg::default();
        // Not controlling: the first is shown, the next only a second later.
        assert_eq!(
            f.decide(&t, t0),
            Show {
                setpoint_changed: false,
                telemetry: true
            }
        );
        assert!(!f.decide(&t, t0 + Duration::from_millis(50)).telemetry);
        assert!(f.decide(&t, t0 + Duration::from_millis(1000)).telemetry);
        // Control begins: a setpoint appears, shown at once.
        t.flags = TelemetryMsg::HAS_SETPOINT;
        let s = f.decide(&t, t0 + Duration::from_millis(1050));
        assert!(s.setpoint_changed && s.telemetry);
        // Held: nothing new until due.
        let s = f.decide(&t, t0 + Duration::from_millis(1100));
        assert!(!s.setpoint_changed && !s.telemetry);
        // The operator moves it.
        t.setpoint_euler[1] = 0.17;
        let s = f.decide(&t, t0 + Duration::from_millis(1150));
        assert!(s.setpoint_changed && s.telemetry);
        // Control ends and begins again with the same setpoint: a change again.
        t.flags = 0;
        assert!(
            !f.decide(&t, t0 + Duration::from_millis(1200))
                .setpoint_changed
        );
        t.flags = TelemetryMsg::HAS_SETPOINT;
        assert!(
            f.decide(&t, t0 + Duration::from_millis(1250))
                .setpoint_changed
        );
        // Zero interval: every message.
        let mut every = TelemetryFilter::new(Duration::ZERO);
        assert!(every.decide(&t, t0).telemetry);
        assert!(every.decide(&t, t0).telemetry);
    }
}
