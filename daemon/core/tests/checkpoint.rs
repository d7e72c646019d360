//! The machine checkpoint (`Machine::checkpoint` / `Machine::restore`): a machine restored
//! from its checkpoint goes on exactly as the original, bit for bit, over the same inputs.
//! Both are fed the same IMU samples (the simulator answers the original's commands) and the
//! same requests; every command must be equal to the bit and every event (model swaps with
//! their matrices, state changes) equal, through an estimation that completes after the
//! checkpoint. Taken idle, mid-pulse, mid-identification under control and while holding.

use std::time::Instant;

use thruster_sim::NoisePreset;
use thrusterd_core::machine::{Command, Machine, MachineSetup, Request, SolverMode, State};

mod common;
use common::Run;

/// The setup `Run` builds its machine with (`common::Run::with_vehicle`).
fn setup(n: usize) -> MachineSetup {
    let mut setup = MachineSetup {
        thrusters: n,
        ..MachineSetup::default()
    };
    setup.machine.deadband = 0.05;
    setup
}

fn same_command(a: &Command, b: &Command) -> bool {
    a.count == b.count
        && a.mode == b.mode
        && a.thrust
            .iter()
            .zip(&b.thrust)
            .all(|(x, y)| x.to_bits() == y.to_bits())
}

/// What one comparison saw.
struct Compared {
    samples: usize,
    swaps: usize,
    bytes: usize,
    encode_us: f64,
}

/// Checkpoints `run.machine` now, restores a copy, then drives both for `samples` samples
/// (handing `requests` to both at their sample) and requires the same commands and events.
fn continue_both(run: &mut Run, samples: usize, requests: &[(usize, Request)]) -> Compared {
    assert!(run.machine.checkpointable());
    let started = Instant::now();
    let bytes = run.machine.checkpoint().unwrap();
    let encode_us = started.elapsed().as_secs_f64() * 1e6;
    // The daemon serialises a copy on its writer thread (thrusterd `checkpoints.rs`), and
    // only in the small state: there the copy must hold every bit of the state. (Mid-run a
    // copy is not a checkpoint: the sample log's copy is a read-only snapshot without the
    // spare room that is part of its behaviour.)
    let started = Instant::now();
    let copied = run.machine.clone();
    let copy_us = started.elapsed().as_secs_f64() * 1e6;
    let same = copied.checkpoint().unwrap() == bytes;
    if run.machine.checkpoint_small() {
        assert!(
            same,
            "in the small state a copy of the machine checkpoints to other bytes than the machine"
        );
    }
    drop(copied);
    println!(
        "  copied in {copy_us:.0} us (small state: {}, same bytes: {same})",
        run.machine.checkpoint_small()
    );
    println!(
        "  state {:?}: {:?}",
        run.machine.state(),
        run.machine.checkpoint_breakdown()
    );
    // Events taken before the checkpoint are outputs already handed out; the copy has none.
    run.machine.take_events();
    let mut copy = Machine::restore(setup(run.sim.thruster_count()), &bytes).unwrap();
    let mut swaps = 0;
    for k in 0..samples {
        for (_, r) in requests.iter().filter(|(at, _)| *at == k) {
            let a = run.machine.on_request(*r);
            let b = copy.on_request(*r);
            assert_eq!(a, b, "request {r:?} at sample {k}");
        }
        let input = run.next_input();
        let a = run.machine.on_imu(&input);
        let b = copy.on_imu(&input);
        assert!(
            same_command(&a, &b),
            "sample {k} after the checkpoint: {a:?} against the restored {b:?}"
        );
        let (ea, eb) = (run.machine.take_events(), copy.take_events());
        assert_eq!(ea, eb, "events at sample {k} after the checkpoint");
        swaps += ea
            .iter()
            .filter(|e| matches!(e, thrusterd_core::machine::Event::ModelSwapped(_)))
            .count();
        run.sim.set_commands(&a.thrust[..a.count]).unwrap();
    }
    assert_eq!(run.machine.status(), copy.status());
    Compared {
        samples,
        swaps,
        bytes: bytes.len(),
        encode_us,
    }
}

fn report(name: &str, c: &Compared) {
    println!(
        "{name}: checkpoint {} bytes, built in {:.0} us; {} samples after it identical, {} swap(s)",
        c.bytes, c.encode_us, c.samples, c.swaps
    );
}

#[test]
fn a_restored_machine_goes_on_exactly_as_the_original_noise_free() {
    let mut run = Run::new("amour5", NoisePreset::None, 1);
    run.run_for(1.0);
    // Idle: the estimation is asked for after the checkpoint and completes in both.
    let c = continue_both(&mut run, 4000, &[(10, Request::Estimate)]);
    report("idle", &c);
    assert!(
        c.swaps >= 1,
        "the estimation after the checkpoint swapped a model in"
    );
    assert_eq!(run.machine.state(), State::Active);
}

#[test]
fn a_restored_machine_goes_on_exactly_mid_pulse_and_holding_with_realistic_noise() {
    let mut run = Run::new("amour5", NoisePreset::Realistic, 2);
    run.run_for(1.0);
    run.machine.on_request(Request::Estimate).unwrap();
    run.run_until(10.0, |m| m.state() == State::Pulse);
    run.run_for(1.5);
    // Mid-estimation: the estimator's sums and sample log, the noise levels, pending solves.
    assert!(run.machine.state().is_estimating());
    let c = continue_both(&mut run, 3000, &[]);
    report("mid-estimation", &c);
    assert!(c.swaps >= 1, "the run finished after the checkpoint");
    // Holding: the controller, the monitor and the background refinement.
    run.run_for(3.0);
    // Between two refinement windows: the small state the daemon takes its checkpoints in
    // (continue_both then also requires a copy to checkpoint to the same bytes).
    run.run_until(30.0, |m| m.checkpoint_small());
    assert!(
        run.machine.checkpoint_small(),
        "no small state while holding"
    );
    assert_eq!(run.machine.state(), State::Active);
    let c = continue_both(&mut run, 3000, &[(1000, Request::Estimate)]);
    report("holding, then identifying under control", &c);
    // Identifying under control: the dither and the closed-loop run.
    let mut run2 = Run::new("amour5", NoisePreset::Realistic, 3);
    run2.run_for(1.0);
    run2.estimate();
    run2.run_for(1.0);
    run2.machine.on_request(Request::Estimate).unwrap();
    run2.run_until(10.0, |m| m.state() == State::Identify);
    run2.run_for(2.0);
    assert_eq!(run2.machine.state(), State::Identify);
    let c = continue_both(&mut run2, 4000, &[]);
    report("mid-identification", &c);
}

#[test]
fn a_job_out_with_the_caller_makes_the_machine_not_checkpointable() {
    let mut run = Run::new("amour5", NoisePreset::None, 4);
    run.machine.set_solver_mode(SolverMode::External);
    run.run_for(0.5);
    run.machine.on_request(Request::Estimate).unwrap();
    // Run until the machine hands out a job; while it is out the state lacks its work.
    let mut job = None;
    for _ in 0..4000 {
        run.tick();
        if let Some(j) = run.machine.take_job() {
            job = Some(j);
            break;
        }
    }
    let job = job.expect("an estimation hands out a solve job");
    assert!(!run.machine.checkpointable());
    run.machine.deliver(job.run());
    assert!(run.machine.checkpointable());
}

#[test]
fn bytes_that_are_not_a_checkpoint_are_refused_with_the_reason() {
    use thrusterd_core::machine::CheckpointError;
    let s = setup(5);
    assert_eq!(
        Machine::restore(s.clone(), b"JSON{}").err(),
        Some(CheckpointError::NotACheckpoint)
    );
    let mut bytes = Machine::new(s.clone()).checkpoint().unwrap();
    bytes[4] = 99;
    assert!(matches!(
        Machine::restore(s.clone(), &bytes).err(),
        Some(CheckpointError::Format { found: 99 })
    ));
    let mut bytes = Machine::new(s.clone()).checkpoint().unwrap();
    bytes.truncate(bytes.len() / 2);
    assert!(matches!(
        Machine::restore(s, &bytes).err(),
        Some(CheckpointError::Decode(_))
    ));
}
