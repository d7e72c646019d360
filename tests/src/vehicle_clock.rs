//! Vehicle time for the system tests (issue 27): the simulator runs stepped
//! (`thruster-sim run --lockstep --stepped`) and the test lets vehicle time pass a few samples
//! at a time, reading the daemon's topics and acting only between steps. A request, setpoint
//! or reconfiguration then lands at the same vehicle time in every run, however loaded the
//! machine is, so a test can assert what happens exactly instead of accepting whichever of
//! several outcomes the process scheduling produced. Wall-clock limits stay only as the
//! deadline of a wait (a hung process), never as the schedule.

use std::process::{ChildStdin, ChildStdout};
use std::time::{Duration, Instant};

use thruster_protocol::services::{Inbox, TopicMessage};
use thruster_sim::stepper::{Stepper, STEP_SAMPLES};

use crate::{Proc, World};

/// How far behind its schedule a paced clock may make up by stepping unpaced (the
/// simulator's pacing allows the same, `thruster-sim`'s `MAX_CATCH_UP`).
const MAX_CATCH_UP: Duration = Duration::from_millis(20);

/// The test's hand on a stepped simulator's clock.
pub struct VehicleClock {
    stepper: Stepper,
    /// At most this many vehicle seconds per wall second, counted from the wall instant and
    /// vehicle time it was set at, or last fell behind at (None: as fast as the processes go).
    pace: Option<(f64, Instant, f64)>,
}

impl VehicleClock {
    fn new(to_sim: ChildStdin, from_sim: ChildStdout) -> VehicleClock {
        VehicleClock {
            stepper: Stepper::new(to_sim, from_sim).expect("the stepper's reader starts"),
            pace: None,
        }
    }

    /// From now on, at most `factor` vehicle seconds per wall second: for a reader that must
    /// keep up (`thrusterctl watch` of every telemetry message). Pacing changes when things
    /// happen in wall time only; vehicle time, and every figure, is the same paced or not.
    pub fn pace(&mut self, factor: f64) {
        self.pace = Some((factor, Instant::now(), self.now_s()));
    }

    /// Vehicle seconds of the newest answered sample (0 before the first).
    pub fn now_s(&self) -> f64 {
        self.stepper.held().map_or(0.0, |h| h.t_ns as f64 * 1e-9)
    }

    /// One step of [`STEP_SAMPLES`] samples, each answered by the daemon.
    pub fn step(&mut self) {
        if let Err(e) = self.stepper.advance(STEP_SAMPLES) {
            panic!(
                "stepping the simulator at {:.3} vehicle-s: {e}",
                self.now_s()
            );
        }
        if let Some((factor, wall0, vehicle0)) = self.pace {
            let due = Duration::from_secs_f64(((self.now_s() - vehicle0) / factor).max(0.0));
            match due.checked_sub(wall0.elapsed()) {
                Some(wait) => std::thread::sleep(wait),
                // Behind the schedule by more than a step's worth: the schedule moves to now
                // instead of the stall being made up unpaced, as the simulator's own pacing
                // does (`MAX_CATCH_UP`). Why: the daemon's stopping job (the velocity's drift
                // searched at a realistic IMU, ~0.3 s) held the lockstep, and the catch-up ran
                // at the daemon's speed and overran the late recorder's 128-sample buffers:
                // 11-153 messages lost in 3 of 3 runs of the late-recording test.
                None if wall0.elapsed() - due > MAX_CATCH_UP => {
                    self.pace = Some((factor, Instant::now(), self.now_s()));
                }
                None => {}
            }
        }
    }

    /// Lets `seconds` of vehicle time pass.
    pub fn run_for(&mut self, seconds: f64) {
        self.step();
        let end = self.now_s() + seconds;
        while self.now_s() < end {
            self.step();
        }
    }

    /// Lets vehicle time pass up to `t_s` (vehicle seconds; at once if already past).
    pub fn run_to(&mut self, t_s: f64) {
        while self.stepper.held().is_none() || self.now_s() < t_s {
            self.step();
        }
    }

    /// Every message on `inbox` from those waiting now up to vehicle time `t_s` (the inbox's
    /// buffer must hold what comes between two calls).
    pub fn collect_until<T: TopicMessage>(&mut self, inbox: &Inbox<T>, t_s: f64) -> Vec<T> {
        let mut got = Vec::new();
        loop {
            while let Some(m) = inbox.recv().expect("reading a topic") {
                got.push(m);
            }
            if self.stepper.held().is_some() && self.now_s() >= t_s {
                return got;
            }
            self.step();
        }
    }

    /// Every message on `inbox` over the next `seconds` of vehicle time (those waiting before
    /// are dropped).
    pub fn collect_for<T: TopicMessage>(&mut self, inbox: &Inbox<T>, seconds: f64) -> Vec<T> {
        while inbox.recv().expect("reading a topic").is_some() {}
        let mut got = Vec::new();
        self.step();
        let end = self.now_s() + seconds;
        loop {
            while let Some(m) = inbox.recv().expect("reading a topic") {
                got.push(m);
            }
            if self.now_s() >= end {
                return got;
            }
            self.step();
        }
    }

    /// Steps until a message on `inbox` satisfies `pred` (the messages already waiting are
    /// judged first); None if `within_s` vehicle seconds pass first. The daemon publishes what
    /// a sample changed before it answers the sample, so the first step that makes `pred`
    /// true is the same in every run.
    pub fn run_until<T: TopicMessage>(
        &mut self,
        inbox: &Inbox<T>,
        within_s: f64,
        pred: impl Fn(&T) -> bool,
    ) -> Option<T> {
        let end = self.now_s() + within_s;
        loop {
            while let Some(m) = inbox.recv().expect("reading a topic") {
                if pred(&m) {
                    return Some(m);
                }
            }
            if self.stepper.held().is_some() && self.now_s() >= end {
                return None;
            }
            self.step();
        }
    }
}

impl World {
    /// `thruster-sim run --lockstep --stepped` on this namespace and the clock that steps it.
    /// The daemon beside it should run with [`STEPPED_DAEMON`]'s flags.
    pub fn stepped_sim(&self, vehicle: &str, extra: &[&str]) -> (Proc, VehicleClock) {
        let args = self.sim_args(vehicle, &[&["--lockstep", "--stepped"], extra].concat());
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (proc, to_sim, from_sim) = Proc::spawn_piped("thruster-sim", &args, self.dir.path());
        (proc, VehicleClock::new(to_sim, from_sim))
    }
}

/// The daemon's flags beside a stepped simulator: lockstep, and a wait for a due solve long
/// enough that no load makes it give up (as the lab runs it).
pub const STEPPED_DAEMON: [&str; 3] = ["--lockstep", "--lockstep-wait-ms", "300000"];
