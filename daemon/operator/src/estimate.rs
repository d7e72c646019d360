//! `estimate --wait`: start an estimation and follow it through the published status.
//!
//! The hard part is telling "this estimation finished" from "a status published before
//! the daemon handled our request". The status inbox may hold one from just before (still
//! Active from the previous model), so a terminal state counts only once the estimation
//! was seen running, or the model version changed, or a grace period passed (an
//! estimation that faulted before we ever saw it run).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Result;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use thruster_protocol::{ControlRequest, DaemonState, ModelMsg, RequestKind, StatusMsg};

use crate::checks::{model_problem, status_problem, Warner};
use crate::client::{wait_latest, Daemon};
use crate::console::{interrupted_during_wait, say};
use crate::exit::{self, Failure};
use crate::render;

/// How long to wait for the status before the request (our baseline model version).
const BASELINE_WAIT: Duration = Duration::from_millis(1000);
/// Poll period of the wait loop (also bounds the Ctrl-C reaction time).
const TICK: Duration = Duration::from_millis(100);

/// What a status says about the estimation we started.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    Running,
    /// Ended in Active or Idle with a new model (or we could not know the old version).
    Succeeded,
    /// Ended in Active or Idle but the model did not change (refused by the quality
    /// checks, or aborted); the status text says why.
    NoNewModel(String),
    /// Ended in Fault; the status text says why.
    Fault(String),
}

/// Follows the estimation through successive statuses. Pure: time is passed in.
#[derive(Debug)]
pub struct Tracker {
    /// Model version before the request, when a status told us.
    baseline_version: Option<u64>,
    /// Seen in MeasureNoise, Pulse, Settle, Solve or Identify since the request.
    seen_running: bool,
    /// Until then a terminal state may predate the request.
    grace_until: Instant,
}

impl Tracker {
    pub fn new(baseline_version: Option<u64>, accepted_at: Instant, grace: Duration) -> Self {
        Self {
            baseline_version,
            seen_running: false,
            grace_until: accepted_at + grace,
        }
    }

    pub fn observe(&mut self, s: &StatusMsg, now: Instant) -> Verdict {
        let state = match s.state() {
            Ok(state) => state,
            Err(_) => return Verdict::Running,
        };
        let new_model = self.baseline_version.is_some_and(|v| s.model_version != v);
        match state {
            DaemonState::MeasureNoise
            | DaemonState::Pulse
            | DaemonState::Settle
            | DaemonState::Solve
            | DaemonState::Identify => {
                self.seen_running = true;
                return Verdict::Running;
            }
            DaemonState::Idle | DaemonState::Active | DaemonState::Fault => {}
        }
        if !self.seen_running && !new_model && now < self.grace_until {
            return Verdict::Running;
        }
        match state {
            DaemonState::Fault => Verdict::Fault(s.text().to_string()),
            _ if self.baseline_version.is_some() && !new_model => {
                Verdict::NoNewModel(s.text().to_string())
            }
            _ => Verdict::Succeeded,
        }
    }
}

/// Progress display: an indicatif bar on a terminal, plain lines on stderr otherwise (logs,
/// CI), so the information is there either way.
struct Progress {
    bar: ProgressBar,
    last_line: String,
}

impl Progress {
    fn new() -> Self {
        let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
        let style = ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} pulses  {msg}",
        )
        .expect("static template is valid");
        bar.set_style(style);
        bar.enable_steady_tick(Duration::from_millis(200));
        Self {
            bar,
            last_line: String::new(),
        }
    }

    fn update(&mut self, s: &StatusMsg) {
        let done = match s.state() {
            Ok(DaemonState::Pulse) => u64::from(s.pulse),
            Ok(DaemonState::Settle) | Ok(DaemonState::Identify) => u64::from(s.pulse),
            Ok(DaemonState::Solve) => u64::from(s.pulse),
            _ => self.bar.position(),
        };
        let message = format!(
            "{} ({}, power {:.2})",
            render::progress(s),
            crate::json::state_name(s.state),
            s.power
        );
        if self.bar.is_hidden() {
            if message != self.last_line {
                eprintln!("{message}");
            }
        } else {
            // The plan may grow until the stopping rule is met.
            self.bar.set_length(u64::from(s.pulses_planned).max(done));
            self.bar.set_position(done);
            self.bar.set_message(message.clone());
        }
        self.last_line = message;
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// `interrupted`: the Ctrl-C/SIGTERM flag, installed by the caller before it connected.
pub fn run_and_wait(
    daemon: &Daemon,
    power: f64,
    max_wait: Duration,
    interrupted: Arc<AtomicBool>,
) -> Result<()> {
    let statuses = daemon.inbox::<StatusMsg>()?;
    let models = daemon.inbox::<ModelMsg>()?;
    daemon.ensure_running()?;
    let baseline = wait_latest(&statuses, BASELINE_WAIT.min(daemon.timeout()))?;
    if interrupted.load(Ordering::SeqCst) {
        return Err(Failure::new(
            exit::INTERRUPTED,
            "interrupted before the estimation was requested; nothing was started",
        )
        .into());
    }
    let text = daemon.command(ControlRequest::with_value(RequestKind::Estimate, power))?;
    eprintln!(
        "estimation started: {}",
        if text.is_empty() { "ok" } else { &text }
    );

    let started = Instant::now();
    let mut tracker = Tracker::new(baseline.map(|s| s.model_version), started, daemon.timeout());
    let mut progress = Progress::new();
    let mut last_status = started;
    let mut last: Option<StatusMsg> = None;
    let mut warner = Warner::default();
    let result = loop {
        if interrupted.load(Ordering::SeqCst) {
            break Err(Failure::new(
                exit::INTERRUPTED,
                "stopped waiting; the estimation goes on (`thrusterctl abort` stops it)",
            ));
        }
        let now = Instant::now();
        if let Some(s) = statuses.recv_latest()? {
            warner.warn(status_problem(&s));
            last_status = now;
            progress.update(&s);
            match tracker.observe(&s, now) {
                Verdict::Running => {}
                Verdict::Succeeded => {
                    last = Some(s);
                    break Ok(());
                }
                Verdict::NoNewModel(why) => {
                    break Err(Failure::new(
                        exit::ESTIMATION_FAILED,
                        format!(
                            "estimation ended ({}) without a new model: {}",
                            crate::json::state_name(s.state),
                            or_unknown(&why)
                        ),
                    ))
                }
                Verdict::Fault(why) => {
                    break Err(Failure::new(
                        exit::ESTIMATION_FAILED,
                        format!("estimation failed: daemon in Fault: {}", or_unknown(&why)),
                    ))
                }
            }
            last = Some(s);
        } else if now.duration_since(last_status) > daemon.timeout() {
            // Silence: the daemon may have died. A control round trip tells (exit 3).
            if let Err(e) = daemon.ensure_running() {
                progress.finish();
                return Err(e);
            }
            last_status = now;
        }
        if now.duration_since(started) > max_wait {
            break Err(Failure::new(
                exit::TIMEOUT,
                format!(
                    "estimation not finished after {:.0} s (still {}); it goes on",
                    max_wait.as_secs_f64(),
                    last.as_ref().map_or("unknown".into(), render::progress)
                ),
            ));
        }
        if let Err(e) = statuses.wait(TICK) {
            if !interrupted_during_wait(&interrupted) {
                progress.finish();
                return Err(e.into());
            }
        }
    };
    progress.finish();
    result?;

    // Success: report the model now in use, with its own error bounds.
    let status = last.expect("success comes with a status");
    match wait_latest(&models, daemon.timeout())? {
        Some(m) if m.version == status.model_version => {
            warner.warn(model_problem(&m));
            say(&format!(
                "estimation done: model version {} ({}, {}), relative error bound {:.1} % \
                 rotation, {:.1} % translation; daemon {}",
                m.version,
                m.source().map_or("?", |s| s.name()),
                m.method().map_or("?", |s| s.name()),
                100.0 * m.rel_err_rot,
                100.0 * m.rel_err_acc,
                crate::json::state_name(status.state)
            ))
        }
        _ => say(&format!(
            "estimation done: model version {}; daemon {}",
            status.model_version,
            crate::json::state_name(status.state)
        )),
    }
}

fn or_unknown(text: &str) -> &str {
    if text.is_empty() {
        "no reason given"
    } else {
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn status(state: DaemonState, version: u64) -> StatusMsg {
        let mut s = StatusMsg {
            model_version: version,
            ..StatusMsg::default()
        };
        s.set_state(state);
        s
    }

    const GRACE: Duration = Duration::from_secs(2);

    #[test]
    fn stale_active_before_the_request_is_not_success() {
        let t0 = Instant::now();
        let mut t = Tracker::new(Some(3), t0, GRACE);
        assert_eq!(
            t.observe(&status(DaemonState::Active, 3), t0),
            Verdict::Running
        );
        assert_eq!(
            t.observe(&status(DaemonState::Pulse, 3), t0),
            Verdict::Running
        );
        assert_eq!(
            t.observe(&status(DaemonState::Solve, 3), t0),
            Verdict::Running
        );
        assert_eq!(
            t.observe(&status(DaemonState::Active, 4), t0),
            Verdict::Succeeded
        );
    }

    #[test]
    fn a_new_version_is_success_even_if_we_never_saw_it_run() {
        // Faster than real time (lockstep simulator): all of it between two polls.
        let t0 = Instant::now();
        let mut t = Tracker::new(Some(3), t0, GRACE);
        assert_eq!(
            t.observe(&status(DaemonState::Idle, 4), t0),
            Verdict::Succeeded
        );
    }

    #[test]
    fn stale_fault_waits_for_the_grace_period() {
        let t0 = Instant::now();
        let mut fault = status(DaemonState::Fault, 3);
        fault.set_text("IMU stale");
        let mut t = Tracker::new(Some(3), t0, GRACE);
        assert_eq!(t.observe(&fault, t0), Verdict::Running);
        assert_eq!(
            t.observe(&fault, t0 + GRACE),
            Verdict::Fault("IMU stale".into())
        );
        // After running, a fault is reported at once.
        let mut t = Tracker::new(Some(3), t0, GRACE);
        t.observe(&status(DaemonState::Settle, 3), t0);
        assert_eq!(t.observe(&fault, t0), Verdict::Fault("IMU stale".into()));
    }

    #[test]
    fn unchanged_model_after_running_is_a_failure_with_reason() {
        let t0 = Instant::now();
        let mut t = Tracker::new(Some(3), t0, GRACE);
        t.observe(&status(DaemonState::MeasureNoise, 3), t0);
        let mut end = status(DaemonState::Active, 3);
        end.set_text("model refused: error bound 0.4 > 0.25");
        assert_eq!(
            t.observe(&end, t0),
            Verdict::NoNewModel("model refused: error bound 0.4 > 0.25".into())
        );
    }

    #[test]
    fn without_a_baseline_a_finished_run_counts_as_success() {
        let t0 = Instant::now();
        let mut t = Tracker::new(None, t0, GRACE);
        assert_eq!(
            t.observe(&status(DaemonState::Active, 1), t0),
            Verdict::Running
        );
        t.observe(&status(DaemonState::Pulse, 0), t0);
        assert_eq!(
            t.observe(&status(DaemonState::Active, 1), t0),
            Verdict::Succeeded
        );
    }
}
