//! The per-sample path allocates nothing: a counting global allocator watches the state machine
//! answer IMU samples while idle, pulsing and controlling, and describe each for telemetry.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use thrusterd_core::machine::{Geometry, ImuInput, Machine, MachineSetup, Request, State};
use thrusterd_core::wire;

struct Counting;

thread_local! {
    /// Counting is on for this thread only: the test harness's own threads (another test,
    /// the result printer) allocate whenever they like, and once did inside a counted window.
    /// Const-initialised and without a destructor, so reading it allocates nothing.
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    /// Allocations counted on this thread: the tests run in parallel, and one's decision ticks
    /// must not land in another's window.
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
}

fn counting(on: bool) {
    COUNTING.with(|c| c.set(on));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.try_with(|c| c.get()).unwrap_or(false) {
            let _ = ALLOCS.try_with(|a| a.set(a.get() + 1));
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn sample(k: u64) -> ImuInput {
    ImuInput {
        seq: k,
        t_ns: 1_000_000_000 + k * 5_000_000,
        gyro: [0.001 * (k % 5) as f64, -0.002, 0.001],
        accel: [0.0, 0.01 * (k % 3) as f64, -9.80665],
        mag: Some([20.0, 0.0, 45.0]),
        depth: Some(5.0),
    }
}

/// Allocations made by `ticks` samples starting at `k`, each answered and described as the
/// daemon does with `telemetry.every_n = 1`: the command, the telemetry snapshot and its
/// message.
fn count(machine: &mut Machine, k: &mut u64, ticks: u64) -> u64 {
    ALLOCS.with(|a| a.set(0));
    counting(true);
    for _ in 0..ticks {
        *k += 1;
        let s = sample(*k);
        let cmd = machine.on_imu(&s);
        let sent = wire::thrust_command(*k, s.seq, s.t_ns, &cmd);
        let snapshot = machine.telemetry(&s);
        std::hint::black_box(wire::telemetry_msg(*k, &snapshot, &sent));
    }
    counting(false);
    ALLOCS.with(|a| a.get())
}

fn four_thrusters() -> Geometry {
    Geometry {
        positions: vec![
            [0.0, -0.2, 0.0],
            [0.0, 0.2, 0.0],
            [-0.2, -0.15, 0.0],
            [-0.2, 0.15, 0.0],
        ],
        directions: vec![
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, -1.0],
        ],
    }
}

/// Over `ticks` samples, how many ticks allocated at all.
fn allocating_ticks(machine: &mut Machine, k: &mut u64, ticks: u64) -> u64 {
    (0..ticks).filter(|_| count(machine, k, 1) > 0).count() as u64
}

#[test]
fn answering_a_sample_does_not_allocate() {
    let mut setup = MachineSetup {
        thrusters: 4,
        geometry: Some(four_thrusters()),
        ..MachineSetup::default()
    };
    // Open-loop estimation here (the closed-loop one is below).
    setup.identification.closed_loop = false;
    setup.refinement.enabled = false;
    // The stop gate and the progress ask where the run may stop every sample; with the early
    // stop that is where the pulses span every thruster (an eigendecomposition, done once).
    setup.estimator.stop_once_spanned = true;
    let mut m = Machine::new(setup);
    let mut k = 0;
    count(&mut m, &mut k, 10); // attitude filter initialised
    assert_eq!(count(&mut m, &mut k, 200), 0, "idle");

    m.on_request(Request::Hold).unwrap();
    count(&mut m, &mut k, 2); // first control tick captures the target
    assert_eq!(m.state(), State::Active);
    assert_eq!(count(&mut m, &mut k, 500), 0, "controlling");
    // Commands carried to a reported supply voltage through the T200 table on the way out.
    m.on_supply(Some(13.7));
    assert_eq!(
        count(&mut m, &mut k, 500),
        0,
        "controlling, supply compensated"
    );

    m.on_request(Request::Estimate).unwrap();
    // Through the noise phase into the first pulse; pulse starts and ends allocate (once per
    // pulse), the samples in between must not.
    while m.state() != State::Pulse {
        k += 1;
        m.on_imu(&sample(k));
    }
    assert_eq!(count(&mut m, &mut k, 10), 0, "inside a pulse");
}

/// With the defaults (background refinement while controlling, identification under control):
/// only the decisions (`estimator.segment_s`, every `identification.settle_decision_s` while
/// the stop may wait for a settled estimate and every `late_decision_s` after: the tick that
/// hands out the solve job, and the tick its result is applied at, `machine.solve_budget_s`
/// later) and a window's or run's start allocate; every other tick allocates nothing.
/// The same with the thrust columns instrumented (`identification.instrument = "always"`:
/// the instruments' sums, a ramp per segment, a least-squares twin).
#[test]
fn under_control_only_the_decisions_allocate() {
    use thrusterd_core::adaptation::identification::Instrument;
    for instrument in [Instrument::InASea, Instrument::Always] {
        // One decision a segment: a count that says so.
        let once_a_segment = under_control_with(instrument, Some(1.0));
        assert!(
            once_a_segment.len() <= 10,
            "identifying ({instrument:?}, a decision a segment): {} of 1000 ticks allocated",
            once_a_segment.len()
        );
        // The default, decisions every 0.1 s (20 ticks) from 2 s of dither: DEFAULT_TICKS
        // of 1000. Any four allocating ticks span at least 20 ticks, so no more than a
        // decision's hand-out and its result (and a run's start) allocate in any 0.1 s: the
        // per-sample path, which would allocate on every tick, does not.
        let default = under_control_with(instrument, None);
        assert!(
            default.windows(4).all(|w| w[3] - w[0] >= 20),
            "identifying ({instrument:?}, the default cadence): allocating ticks {default:?}"
        );
        assert!(
            default.len() > once_a_segment.len() && default.len() <= DEFAULT_TICKS,
            "identifying ({instrument:?}, the default cadence): {} of 1000 ticks allocated",
            default.len()
        );
    }
}

/// The most ticks of the 1000 that may allocate with the default cadence: a hand-out and a
/// result for each 0.1 s decision over the 2.5 s of dither from 2 s on, and the run's start.
const DEFAULT_TICKS: usize = 60;

/// The ticks, of 1000 (5 s) identifying after 10 s of control, that allocated; `cadence`:
/// both the settle wait's and the late decisions' spacing, s (None: the defaults).
fn under_control_with(
    instrument: thrusterd_core::adaptation::identification::Instrument,
    cadence: Option<f64>,
) -> Vec<u64> {
    let mut setup = MachineSetup {
        thrusters: 4,
        geometry: Some(four_thrusters()),
        ..MachineSetup::default()
    };
    setup.identification.instrument = instrument;
    if let Some(s) = cadence {
        setup.identification.settle_decision_s = s;
        setup.identification.late_decision_s = s;
    }
    let mut m = Machine::new(setup);
    let mut k = 0;
    count(&mut m, &mut k, 10);
    m.on_request(Request::Hold).unwrap();
    count(&mut m, &mut k, 2);
    assert_eq!(m.state(), State::Active);
    // 10 s at 200 Hz: a window opens after 1 s settled, then at most one decision a second.
    let active = allocating_ticks(&mut m, &mut k, 2000);
    assert!(
        active <= 11,
        "controlling: {active} of 2000 ticks allocated"
    );
    m.on_request(Request::Estimate).unwrap();
    assert_eq!(m.state(), State::Identify);
    // 5 s: the start, the decisions and their results (the status text says how long the
    // dither has run).
    (0..1000).filter(|_| count(&mut m, &mut k, 1) > 0).collect()
}

/// The refinement's per-sample change test (`refinement.change_test`, on by default) adds no
/// allocation: with it on, controlling allocates on exactly as many ticks as without it.
#[test]
fn the_change_test_does_not_allocate() {
    let active = |change_test: bool| {
        let mut setup = MachineSetup {
            thrusters: 4,
            geometry: Some(four_thrusters()),
            ..MachineSetup::default()
        };
        setup.refinement.change_test = change_test;
        // Judge every sample from the first on; never decide (these samples follow no model,
        // and a mismatch would start an estimation, which allocates once).
        setup.refinement.change_warmup_s = 0.0;
        setup.refinement.change_max_error_deg = 180.0;
        setup.refinement.change_chi2 = f64::INFINITY;
        let mut m = Machine::new(setup);
        let mut k = 0;
        count(&mut m, &mut k, 10);
        m.on_request(Request::Hold).unwrap();
        count(&mut m, &mut k, 2);
        assert_eq!(m.state(), State::Active);
        allocating_ticks(&mut m, &mut k, 2000)
    };
    let (with, without) = (active(true), active(false));
    assert_eq!(
        with, without,
        "change test on: {with} allocating ticks, off: {without}"
    );
}

/// The dynamic method's per-sample path (`Estimator::push_dynamic_sample`: navigation, thruster
/// lag, regressors, two segmented least-squares updates) allocates nothing, at the 16-thruster
/// capacity, during a pulse and between pulses, across segment boundaries (every 1 s).
#[test]
fn a_dynamic_sample_does_not_allocate() {
    use nalgebra::Vector3;
    use thrusterd_core::estimator::{Estimator, EstimatorConfig, NoiseLevels};

    let n = 16;
    let mut est = Estimator::new(
        EstimatorConfig::default(),
        n,
        NoiseLevels::isotropic(0.25, 0.5),
    )
    .with_rest_specific_force(Vector3::new(0.0, 0.0, -9.80665));
    let sample = |k: u64| {
        let t = k as f64 * 0.005;
        (
            t,
            Vector3::new(0.2 * (3.0 * t).sin(), -0.1 * (2.0 * t).cos(), 0.05),
            Vector3::new(0.3 * (5.0 * t).sin(), 0.1, -9.80665 + 0.2 * t.cos()),
        )
    };
    let mut k = 0u64;
    // The first pulse builds the dynamic fit (once per run); a few samples warm it up.
    est.begin_pulse_at(0.0);
    for _ in 0..5 {
        k += 1;
        let (t, w, f) = sample(k);
        est.push_dynamic_sample(t, &w, &f, Some(5.0));
    }
    ALLOCS.with(|a| a.set(0));
    counting(true);
    // 3 s inside one pulse: three segment boundaries.
    for _ in 0..600 {
        k += 1;
        let (t, w, f) = sample(k);
        est.push_dynamic_sample(
            std::hint::black_box(t),
            &w,
            &f,
            std::hint::black_box(Some(5.0)),
        );
    }
    counting(false);
    let in_pulse = ALLOCS.with(|a| a.get());
    assert_eq!(in_pulse, 0, "push_dynamic_sample during a pulse");

    est.end_pulse();
    ALLOCS.with(|a| a.set(0));
    counting(true);
    // Between pulses (thrusters at neutral), also without a depth reading.
    for i in 0..300 {
        k += 1;
        let (t, w, f) = sample(k);
        let depth = if i % 2 == 0 { Some(5.0) } else { None };
        est.push_dynamic_sample(t, &w, &f, std::hint::black_box(depth));
    }
    counting(false);
    assert_eq!(
        ALLOCS.with(|a| a.get()),
        0,
        "push_dynamic_sample between pulses"
    );
}
