//! The work that leaves the control tick: solves (an estimate, a stop decision, a candidate
//! model, a refinement window's fit) taking 0.5-4 ms, a period or more at 1 kHz. The machine
//! stays pure: it hands out a [`SolveJob`], a self-contained value (a snapshot of the estimator
//! and what the decision needs), and takes its [`SolveResult`] back. Who computes it is the
//! caller's business: the daemon's worker thread, or the same thread at once
//! (`SolverMode::Inline`, what tests, replay and the lab use). Two owners submit jobs: the
//! estimation run (`machine::estimation`) and the background refinement (`refinement`).
//!
//! The due-time rule: a job is tagged with the vehicle time its result is due, its submission
//! time plus `machine.solve_budget_s`, and the machine applies a result only at the first
//! sample at or after that time. A result computed at once and one computed on another thread
//! within the budget are therefore applied at the same sample, so the outcome depends on
//! vehicle time only: replay reproduces the daemon's models bit for bit. A result not back by
//! its due sample (real time, a loaded machine) is applied at the first sample after it comes
//! back and counted as late.

use std::collections::VecDeque;

use crate::estimator::{Estimate, Estimator, Settle, StopDecision};
use crate::model::Model;

/// Who runs the machine's solve jobs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SolverMode {
    /// The machine runs each job itself, on the sample that submits it (in-process users:
    /// tests, replay, the lab). Results are still applied at their due sample.
    Inline,
    /// The caller takes the jobs (`Machine::take_job`), runs them elsewhere and hands the
    /// results back (`Machine::deliver`): the daemon's worker thread.
    External,
}

/// Jobs outstanding at most; the queue is allocated once with this capacity so that a control
/// tick never allocates for it. One is the rule (a run waits for its decision); a second or
/// third exists only while a progress estimate is late.
const MAX_PENDING: usize = 8;

/// Owners of solvers (the estimation run, the refinement): job ids are unique across them.
pub(crate) const OWNERS: u64 = 2;

/// Jobs outstanding at most across every owner: what a worker's queue must hold so that a
/// machine within its own limits never finds it full (on a starved worker every owner may
/// have its [`MAX_PENDING`] outstanding at once).
pub const MAX_OUTSTANDING: usize = OWNERS as usize * MAX_PENDING;

/// Which owner a job id belongs to (the `owner` its solver was made with).
pub(crate) fn owner_of(id: u64) -> u64 {
    (id.max(1) - 1) % OWNERS
}

/// What a job computes.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
enum Work {
    /// After a pulse: the estimate and the stop decision.
    Pulse,
    /// At the end of a decision interval under control: the estimate and the decision with
    /// the interval's clock.
    Interval {
        elapsed_s: f64,
        min_s: f64,
        max_s: f64,
        /// The wait for a settled estimate (`IdentificationConfig::settle_rule`).
        settle: Settle,
    },
    /// A refinement window's fit, `elapsed_s` into the window: the estimate only.
    Window { elapsed_s: f64 },
}

/// What the machine does with a result when it is applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub(crate) enum Purpose {
    /// Progress only (the run went on pulsing): the estimate is kept for status.
    Progress,
    /// The open-loop run waits, at neutral, for this decision before it pulses again.
    Decide,
    /// The run has stopped (a limit); the result is its model.
    Conclude,
    /// A decision interval under control ended; the run goes on holding and dithering.
    Interval,
    /// A refinement window's fit: judged against the model in force when applied.
    Window,
}

/// One solve, as a self-contained value: everything needed to compute its result.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SolveJob {
    id: u64,
    due_ns: u64,
    /// The estimator at the moment of submission (its normal equations, noise, prior).
    est: Box<Estimator>,
    work: Work,
    /// Progress only: the estimate does not search the thrusters' lag
    /// (`Estimator::estimate_progress`).
    progress: bool,
    /// The candidate model's geometry key and the vehicle time it is made at.
    geometry_key: Option<u64>,
    made_t_ns: u64,
}

impl SolveJob {
    /// The job's number (results are matched to jobs by it).
    pub fn id(&self) -> u64 {
        self.id
    }

    /// Vehicle time at which the machine applies the result, ns.
    pub fn due_ns(&self) -> u64 {
        self.due_ns
    }

    /// Compute the result. Pure and deterministic: the same job gives the same result on any
    /// thread.
    pub fn run(self) -> SolveResult {
        self.compute()
    }

    /// [`SolveJob::run`] without giving the job up: a worker hands the spent job back to the
    /// thread that made it, to be freed there (see the daemon's `solver.rs`).
    pub fn compute(&self) -> SolveResult {
        let mut estimate = if self.progress {
            self.est.estimate_progress()
        } else {
            self.est.estimate()
        };
        let (decision, elapsed_s) = match self.work {
            Work::Pulse => (self.est.stop_decision_with(&estimate), 0.0),
            Work::Interval {
                elapsed_s,
                min_s,
                max_s,
                settle,
            } => (
                self.est
                    .closed_loop_decision(&estimate, elapsed_s, [min_s, max_s], settle),
                elapsed_s,
            ),
            // A window never stops a run; the refiner judges the estimate itself.
            Work::Window { elapsed_s } => (StopDecision::Continue, elapsed_s),
        };
        // A run that stops has its configured lag checked against its data where the gyro
        // was too noisy to learn it: only then, since the check searches the lag (~150 ms
        // at 64 pulses, N = 8) and decides nothing but the model's refusal.
        if decision.is_stop() {
            // Where a long rest saw the vehicle move, the model is made again with its steady
            // velocity at the start searched (~120 refits): only here, as the draws below.
            if matches!(self.work, Work::Pulse) {
                self.est.search_start_velocity(&mut estimate);
                // In still water, the dead-reckoned velocity's drift taken out the same way.
                self.est.search_velocity_drift(&mut estimate);
            }
            self.est.check_configured_lag(&mut estimate);
            // The open loop's model has the navigation's errors counted in its bound: drawn
            // only here, since the refits cost a second estimate's worth and the stop rule
            // does not wait on them.
            if matches!(self.work, Work::Pulse) {
                self.est.count_navigation_error(&mut estimate);
            }
        }
        // The model is made here too when the run stops: the control thread only checks it.
        let candidate = decision
            .is_stop()
            .then(|| Model::from_estimate(&estimate, self.geometry_key, self.made_t_ns));
        SolveResult {
            id: self.id,
            estimate,
            decision,
            candidate,
            pulses: self.est.pulses(),
            made_t_ns: self.made_t_ns,
            elapsed_s,
        }
    }
}

/// A job's result.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SolveResult {
    id: u64,
    pub(crate) estimate: Estimate,
    pub(crate) decision: StopDecision,
    /// The candidate model, when the decision stops the run.
    pub(crate) candidate: Option<Model>,
    /// Pulses (or decision intervals) in the data.
    pub(crate) pulses: usize,
    /// Vehicle time of the data's end (the job's submission), ns.
    pub(crate) made_t_ns: u64,
    /// Seconds into the closed-loop run or the refinement window at submission.
    pub(crate) elapsed_s: f64,
}

impl SolveResult {
    /// The number of the job this answers.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// The estimate computed.
    pub fn estimate(&self) -> &Estimate {
        &self.estimate
    }

    /// The model the result would swap in, when its decision stops the run.
    pub fn candidate(&self) -> Option<&Model> {
        self.candidate.as_ref()
    }
}

/// A job submitted and not yet applied.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Pending {
    id: u64,
    due_ns: u64,
    purpose: Purpose,
    result: Option<SolveResult>,
    /// Already counted as late (counted once).
    late: bool,
}

/// The machine's side of the solves: jobs out, results held until due.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) struct Solver {
    mode: SolverMode,
    budget_ns: u64,
    next_id: u64,
    /// Ids go up by this: each owner of a solver takes its own residue, so a result finds its
    /// owner by its id (see `owner_of`).
    id_step: u64,
    /// Jobs for the caller to take (External).
    outbox: VecDeque<SolveJob>,
    pending: VecDeque<Pending>,
    late: u64,
}

impl Solver {
    /// A solver whose results are due `budget_s` after submission; its job ids are
    /// `owner + 1`, `owner + 1 + OWNERS`, ... (owner < [`OWNERS`]).
    pub(crate) fn new(budget_s: f64, owner: u64) -> Self {
        let mut s = Solver {
            mode: SolverMode::Inline,
            budget_ns: 0,
            next_id: owner % OWNERS + 1,
            id_step: OWNERS,
            outbox: VecDeque::with_capacity(MAX_PENDING),
            pending: VecDeque::with_capacity(MAX_PENDING),
            late: 0,
        };
        s.set_budget(budget_s);
        s
    }

    pub(crate) fn set_mode(&mut self, mode: SolverMode) {
        self.mode = mode;
    }

    /// Results due `budget_s` after submission (a non-positive or non-finite budget: at once).
    pub(crate) fn set_budget(&mut self, budget_s: f64) {
        self.budget_ns = if budget_s.is_finite() && budget_s > 0.0 {
            (budget_s * 1e9) as u64
        } else {
            0
        };
    }

    /// Whether another job may be submitted now (the queue is bounded).
    pub(crate) fn has_room(&self) -> bool {
        self.pending.len() < MAX_PENDING
    }

    /// Whether a job with this purpose is outstanding.
    pub(crate) fn waiting_for(&self, purpose: Purpose) -> bool {
        self.pending.iter().any(|p| p.purpose == purpose)
    }

    /// Submit a solve of `est` at vehicle time `t_ns`; its result is due a budget later.
    pub(crate) fn submit_pulse(
        &mut self,
        est: &Estimator,
        t_ns: u64,
        purpose: Purpose,
        geometry_key: Option<u64>,
    ) {
        self.submit(est, t_ns, purpose, Work::Pulse, geometry_key);
    }

    /// Submit a refinement window's fit, `elapsed_s` into the window.
    pub(crate) fn submit_window(&mut self, est: &Estimator, t_ns: u64, elapsed_s: f64) {
        let work = Work::Window { elapsed_s };
        self.submit(est, t_ns, Purpose::Window, work, None);
    }

    /// Submit a decision interval's solve under control.
    pub(crate) fn submit_interval(
        &mut self,
        est: &Estimator,
        t_ns: u64,
        (elapsed_s, min_s, max_s, settle): (f64, f64, f64, Settle),
        geometry_key: Option<u64>,
    ) {
        let work = Work::Interval {
            elapsed_s,
            min_s,
            max_s,
            settle,
        };
        self.submit(est, t_ns, Purpose::Interval, work, geometry_key);
    }

    fn submit(
        &mut self,
        est: &Estimator,
        t_ns: u64,
        purpose: Purpose,
        work: Work,
        geometry_key: Option<u64>,
    ) {
        let id = self.next_id;
        self.next_id += self.id_step;
        let due_ns = t_ns.saturating_add(self.budget_ns);
        let job = SolveJob {
            id,
            due_ns,
            est: Box::new(est.clone()),
            work,
            progress: purpose == Purpose::Progress,
            geometry_key,
            made_t_ns: t_ns,
        };
        let result = match self.mode {
            SolverMode::Inline => Some(job.run()),
            SolverMode::External => {
                self.outbox.push_back(job);
                None
            }
        };
        self.pending.push_back(Pending {
            id,
            due_ns,
            purpose,
            result,
            late: false,
        });
    }

    /// The next job for the caller to run (External mode).
    pub(crate) fn take_job(&mut self) -> Option<SolveJob> {
        self.outbox.pop_front()
    }

    /// A result is back; one for a job no longer outstanding (the run was stopped) is dropped.
    pub(crate) fn deliver(&mut self, result: SolveResult) {
        if let Some(p) = self.pending.iter_mut().find(|p| p.id == result.id) {
            p.result = Some(result);
        }
    }

    /// The id of the oldest job due at `t_ns` whose result is not back. Every job due by then
    /// counts, not only the oldest: `take_due` applies all of them at this sample, in order,
    /// and one missing behind a delivered one would be applied at whichever later sample its
    /// result happened to come back by (a lockstep run then varied with the machine's load).
    pub(crate) fn awaiting(&self, t_ns: u64) -> Option<u64> {
        first_awaited(
            self.pending
                .iter()
                .map(|p| (p.id, p.due_ns, p.result.is_some())),
            t_ns,
        )
    }

    /// Jobs the caller took (External) whose result has not come back: their work is on the
    /// caller's worker, not in this state, so a checkpoint taken now would lack it.
    pub(crate) fn out_with_caller(&self) -> usize {
        let waiting = self.pending.iter().filter(|p| p.result.is_none()).count();
        waiting.saturating_sub(self.outbox.len())
    }

    /// The oldest result due at `t_ns`, in submission order. A due job without its result
    /// holds the queue (and is counted late once): results are applied in order.
    pub(crate) fn take_due(&mut self, t_ns: u64) -> Option<(Purpose, SolveResult)> {
        let front = self.pending.front_mut()?;
        if front.due_ns > t_ns {
            return None;
        }
        if front.result.is_none() {
            if !front.late {
                front.late = true;
                self.late += 1;
            }
            return None;
        }
        let p = self.pending.pop_front()?;
        Some((p.purpose, p.result?))
    }

    /// Solves whose result was not back by their due sample, since start.
    pub(crate) fn late(&self) -> u64 {
        self.late
    }

    /// Forget every outstanding job (the run they belong to ended): their results, should
    /// they still come, are dropped.
    pub(crate) fn cancel(&mut self) {
        self.pending.clear();
        self.outbox.clear();
    }
}

/// Of jobs `(id, due_ns, result back)` in submission order (so in order of due time), the
/// first due at `t_ns` whose result is not back.
fn first_awaited(jobs: impl Iterator<Item = (u64, u64, bool)>, t_ns: u64) -> Option<u64> {
    jobs.take_while(|(_, due_ns, _)| *due_ns <= t_ns)
        .find(|(_, _, back)| !back)
        .map(|(id, _, _)| id)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_owner_numbers_its_jobs_apart_and_finds_its_results_by_id() {
        for owner in 0..OWNERS {
            let mut s = Solver::new(0.03, owner);
            let ids: Vec<u64> = (0..5)
                .map(|_| {
                    let id = s.next_id;
                    s.next_id += s.id_step;
                    id
                })
                .collect();
            assert!(
                ids.iter().all(|id| owner_of(*id) == owner),
                "{owner}: {ids:?}"
            );
        }
        assert_ne!(Solver::new(0.0, 0).next_id, Solver::new(0.0, 1).next_id);
    }

    #[test]
    fn every_due_job_without_its_result_is_awaited_not_only_the_oldest() {
        let jobs = |back: [bool; 3]| [(1, 10, back[0]), (2, 20, back[1]), (3, 40, back[2])];
        let none = [false; 3];
        assert_eq!(
            first_awaited(jobs(none).into_iter(), 5),
            None,
            "nothing due"
        );
        assert_eq!(first_awaited(jobs(none).into_iter(), 30), Some(1));
        // The oldest is back, the second (also due at 30) is not: it is awaited (before, only
        // the oldest was looked at, and the second was applied whenever it came).
        let first_back = [true, false, false];
        assert_eq!(first_awaited(jobs(first_back).into_iter(), 30), Some(2));
        let two_back = [true, true, false];
        assert_eq!(
            first_awaited(jobs(two_back).into_iter(), 30),
            None,
            "third not due"
        );
        assert_eq!(first_awaited(jobs(two_back).into_iter(), 40), Some(3));
    }

    #[test]
    fn a_budget_that_is_not_a_positive_number_means_at_once() {
        for b in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(Solver::new(b, 0).budget_ns, 0, "{b}");
        }
        assert_eq!(Solver::new(0.03, 0).budget_ns, 30_000_000);
    }
}
