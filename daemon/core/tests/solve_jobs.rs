//! The machine's solves as jobs (`thrusterd_core::solve`): a machine whose solves run on another
//! thread reaches the same commands and the same models at the same samples as one that
//! solves inline, whenever the results come back before they are due (the due-time rule);
//! a result not back in time is applied late, counted, and the machine never blocks; a lost
//! solver faults to neutral.

mod common;

use std::sync::mpsc;
use std::time::Duration;

use common::{vehicle, Run};
use thruster_sim::NoisePreset;
use thrusterd_core::machine::{
    Command, ImuInput, Machine, Reconfig, Request, SolveJob, SolveResult, SolverMode, State,
    ThrusterChange,
};

/// A solver thread as the daemon has one: jobs in, results out, each result held back a
/// pseudo-random 0-3 ms of wall time (so they come back at varying samples).
struct Worker {
    jobs: Option<mpsc::Sender<SolveJob>>,
    results: mpsc::Receiver<SolveResult>,
    handle: Option<std::thread::JoinHandle<()>>,
}

impl Worker {
    fn spawn() -> Worker {
        let (jobs, job_rx) = mpsc::channel::<SolveJob>();
        let (tx, results) = mpsc::channel();
        let handle = std::thread::spawn(move || {
            for job in job_rx {
                let delay_us = job.id().wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 61 << 10;
                std::thread::sleep(Duration::from_micros(delay_us));
                if tx.send(job.run()).is_err() {
                    break;
                }
            }
        });
        Worker {
            jobs: Some(jobs),
            results,
            handle: Some(handle),
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.jobs = None;
        if let Some(h) = self.handle.take() {
            h.join().unwrap();
        }
    }
}

fn apply(run: &mut Run, cmd: &Command) {
    for v in &cmd.thrust[..cmd.count] {
        assert!(v.is_finite() && v.abs() <= 1.0, "command {v}");
    }
    run.sim.set_commands(&cmd.thrust[..cmd.count]).unwrap();
}

/// One sample through a machine whose solves go to `worker`, the way the daemon does it in
/// lockstep: results back so far are handed over, a result due by this sample is waited for.
/// The number of jobs handed out.
fn tick_external(run: &mut Run, worker: &Worker, s: &ImuInput) -> (Command, usize) {
    while let Ok(r) = worker.results.try_recv() {
        run.machine.deliver(r);
    }
    while run.machine.awaiting_result(s.t_ns).is_some() {
        let r = worker
            .results
            .recv_timeout(Duration::from_secs(30))
            .expect("the worker answers");
        run.machine.deliver(r);
    }
    let cmd = run.machine.on_imu(s);
    let mut jobs = 0;
    while let Some(job) = run.machine.take_job() {
        worker.jobs.as_ref().unwrap().send(job).unwrap();
        jobs += 1;
    }
    (cmd, jobs)
}

/// Inline and on a thread, tick by tick: the same commands, the same events (model swaps with
/// their versions, times and numbers), for `seconds` of vehicle time. Returns the model swaps
/// seen and the jobs the external machine handed out.
fn lockstep_pair(
    inline: &mut Run,
    external: &mut Run,
    worker: &Worker,
    seconds: f64,
) -> (usize, usize) {
    let (mut swaps, mut jobs) = (0, 0);
    let start = inline.sim.time_s();
    while inline.sim.time_s() - start < seconds {
        let a = inline.next_input();
        let b = external.next_input();
        assert_eq!(format!("{a:?}"), format!("{b:?}"), "the same vehicle");
        let ca = inline.machine.on_imu(&a);
        let (cb, j) = tick_external(external, worker, &b);
        jobs += j;
        assert_eq!(
            format!("{ca:?}"),
            format!("{cb:?}"),
            "commands differ at t = {:.3} s",
            a.t_ns as f64 * 1e-9
        );
        let (ea, eb) = (inline.machine.take_events(), external.machine.take_events());
        // Debug text compares floats exactly (shortest round-trip form) and NaN equal to NaN.
        assert_eq!(
            format!("{ea:?}"),
            format!("{eb:?}"),
            "events differ at t = {:.3} s",
            a.t_ns as f64 * 1e-9
        );
        swaps += ea
            .iter()
            .filter(|e| matches!(e, thrusterd_core::machine::Event::ModelSwapped(_)))
            .count();
        apply(inline, &ca);
        apply(external, &cb);
    }
    (swaps, jobs)
}

#[test]
fn a_solver_thread_and_inline_solving_give_the_same_models_at_the_same_samples() {
    let v = vehicle("amour5");
    let mut inline = Run::new("amour5", NoisePreset::Realistic, 3);
    let mut external = Run::new("amour5", NoisePreset::Realistic, 3);
    external.machine.set_solver_mode(SolverMode::External);
    let worker = Worker::spawn();

    // From scratch: the open-loop estimation (a solve after every pulse), then control.
    lockstep_pair(&mut inline, &mut external, &worker, 0.05);
    for run in [&mut inline, &mut external] {
        run.machine.on_request(Request::Estimate).unwrap();
    }
    let (swaps, jobs) = lockstep_pair(&mut inline, &mut external, &worker, 25.0);
    assert_eq!(
        inline.machine.state(),
        State::Active,
        "estimated and holding"
    );
    assert!(swaps >= 1 && jobs >= 20, "{swaps} swaps, {jobs} jobs");

    // The top thruster turned and announced: identification under control with the other
    // thrusters' columns carried over (the slowest solve, with a prior), a decision a second.
    for run in [&mut inline, &mut external] {
        run.sim
            .apply(&thruster_sim::Action::Rotate {
                thruster: "T".into(),
                axis: [1.0, 0.0, 0.0],
                angle_deg: 45.0,
            })
            .unwrap();
        run.machine.on_reconfig(Reconfig {
            count: v.thrusters.len(),
            geometry: None,
            change: ThrusterChange::Moved(0),
            what: "top thruster rotated".into(),
        });
    }
    assert_eq!(inline.machine.state(), State::Identify);
    let before = inline.machine.model().map(|m| m.version);
    let (swaps, jobs) = lockstep_pair(&mut inline, &mut external, &worker, 30.0);
    assert!(jobs >= 4, "{jobs} interval solves");
    assert!(
        swaps >= 1 && inline.machine.model().map(|m| m.version) > before,
        "identified under control: {swaps} swaps"
    );
    assert_eq!(external.machine.late_solves(), 0, "lockstep: nothing late");
    assert_eq!(
        format!("{:?}", inline.machine.model()),
        format!("{:?}", external.machine.model())
    );
}

/// A machine at rest at 200 Hz, asked to estimate; results held back as the test says.
fn estimating_machine() -> (Machine, u64) {
    let mut m = Machine::new(thrusterd_core::machine::MachineSetup {
        thrusters: 4,
        ..Default::default()
    });
    m.set_solver_mode(SolverMode::External);
    let s = rest(1);
    m.on_imu(&s);
    m.on_request(Request::Estimate).unwrap();
    (m, 1)
}

fn rest(k: u64) -> ImuInput {
    let h = |i: u64| {
        let x = k
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(i.wrapping_mul(0xBF58_476D_1CE4_E5B9));
        (x >> 40) as f64 / (1u64 << 24) as f64 - 0.5
    };
    ImuInput {
        seq: k,
        t_ns: k * 5_000_000,
        gyro: [0.01 * h(1), 0.01 * h(2), 0.01 * h(3)],
        accel: [0.05 * h(4), 0.05 * h(5), -9.80665 + 0.05 * h(6)],
        mag: None,
        depth: Some(2.0 + 0.001 * h(7)),
    }
}

#[test]
fn a_late_result_is_applied_when_it_comes_counted_and_nothing_blocks() {
    let (mut m, mut k) = estimating_machine();
    // Up to the first job (the first pulse's end).
    let job = loop {
        k += 1;
        m.on_imu(&rest(k));
        if let Some(job) = m.take_job() {
            break job;
        }
        assert!(k < 2_000, "no job");
    };
    let due = job.due_ns();
    // Past its due time without the result: every sample is still answered (finite, in
    // range), the result is counted late once.
    let mut past_due = 0;
    while past_due < 20 {
        k += 1;
        let s = rest(k);
        let cmd = m.on_imu(&s);
        assert!(cmd.thrust.iter().all(|v| v.is_finite() && v.abs() <= 1.0));
        while let Some(later) = m.take_job() {
            drop(later);
        }
        if s.t_ns >= due {
            past_due += 1;
            assert_eq!(m.awaiting_result(s.t_ns), Some(job.id()));
        }
    }
    assert_eq!(m.late_solves(), 1, "counted once");
    assert!(m.last_estimate().is_none(), "nothing applied yet");
    // Back now: applied at the next sample.
    let id = job.id();
    m.deliver(job.run());
    k += 1;
    m.on_imu(&rest(k));
    assert!(m.last_estimate().is_some(), "applied on the next sample");
    assert_ne!(m.awaiting_result(rest(k).t_ns), Some(id));
}

#[test]
fn results_are_applied_at_their_due_sample_not_when_they_come() {
    let (mut m, mut k) = estimating_machine();
    let job = loop {
        k += 1;
        m.on_imu(&rest(k));
        if let Some(job) = m.take_job() {
            break job;
        }
        assert!(k < 2_000, "no job");
    };
    let due = job.due_ns();
    // Delivered at once (before it is due): held until the due sample.
    m.deliver(job.run());
    loop {
        k += 1;
        let s = rest(k);
        m.on_imu(&s);
        if s.t_ns < due {
            assert!(
                m.last_estimate().is_none(),
                "applied before due at {}",
                s.t_ns
            );
        } else {
            assert!(m.last_estimate().is_some(), "not applied at the due sample");
            break;
        }
    }
    assert_eq!(m.late_solves(), 0);
}

#[test]
fn a_lost_solver_faults_to_neutral_and_does_not_restart_the_estimation() {
    let (mut m, mut k) = estimating_machine();
    loop {
        k += 1;
        m.on_imu(&rest(k));
        if m.take_job().is_some() {
            break;
        }
    }
    m.on_solver_lost("the solver thread panicked: test");
    assert_eq!(m.state(), State::Fault);
    assert!(m.status().text.contains("the solver thread panicked"));
    for _ in 0..100 {
        k += 1;
        let cmd = m.on_imu(&rest(k));
        assert!(cmd.thrust.iter().all(|v| *v == 0.0) || m.state() != State::Fault);
    }
    // Recovered on good samples, but idle: the estimation would need the solver again.
    assert_eq!(m.state(), State::Idle);
    assert!(m.take_job().is_none());
}
