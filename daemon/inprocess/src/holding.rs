//! Holding attitude with the refinement and the change test on: AMOUR-5 (or another vehicle)
//! learned, then held through pitch steps or level, until a mismatch or for a time; the 1 kHz
//! hold. What the core's refinement tests assert on and the lab's refinement sweeps print.

use nalgebra::UnitQuaternion;
use thruster_sim::NoisePreset;
use thrusterd_core::adaptation::monitor::MismatchAction;
use thrusterd_core::adaptation::refinement::RefinementConfig;
use thrusterd_core::estimator::EstimatorConfig;
use thrusterd_core::machine::{Event, Machine, MachineSetup, State};

use crate::run::Run;

/// The false-alarm flight of the soaks: `seconds` of pitch steps, then (if nothing was
/// reported) as long holding level; the mismatch of each part, if any.
pub type Mismatch = Option<(f64, String)>;

pub fn holding(noise: NoisePreset, seed: u64) -> Run {
    holding_with(noise, seed, RefinementConfig::default())
}

/// [`holding`] with the refinement's settings replaced.
pub fn holding_with(noise: NoisePreset, seed: u64, refinement: RefinementConfig) -> Run {
    holding_on("amour5", noise, seed, refinement)
}

/// [`holding_with`] on another vehicle file.
pub fn holding_on(
    vehicle: &str,
    noise: NoisePreset,
    seed: u64,
    refinement: RefinementConfig,
) -> Run {
    holding_on_prior(vehicle, noise, seed, refinement, None)
}

/// [`holding_on`] with the estimator's terms prior (`term_prior_sd`, default off) replaced:
/// for `detection_bound`'s decisive runs (`DB_TERM_PRIOR`); no asserting test sets it.
pub fn holding_on_prior(
    vehicle: &str,
    noise: NoisePreset,
    seed: u64,
    refinement: RefinementConfig,
    term_prior_sd: Option<f64>,
) -> Run {
    holding_on_learned_with(vehicle, noise, seed, refinement, &|e| {
        if let Some(v) = term_prior_sd {
            e.term_prior_sd = v;
        }
    })
}

/// [`holding_on`] with the estimator's settings changed by `estimator` before the model is
/// learned (`shaped_thrust`'s tests).
pub fn holding_on_learned_with(
    vehicle: &str,
    noise: NoisePreset,
    seed: u64,
    refinement: RefinementConfig,
    estimator: &dyn Fn(&mut EstimatorConfig),
) -> Run {
    let mut run = Run::new(vehicle, noise, seed);
    let mut setup = MachineSetup {
        thrusters: run.sim.thruster_count(),
        refinement,
        ..MachineSetup::default()
    };
    setup.machine.deadband = 0.05;
    estimator(&mut setup.estimator);
    // The monitor's own test never fires (infinite threshold); its action still decides what
    // a mismatch does: re-estimate.
    setup.monitor.action = MismatchAction::Estimate;
    setup.monitor.z = f64::INFINITY;
    run.machine = Machine::new(setup);
    run.run_for(1.0);
    run.estimate();
    run.machine.take_events();
    run
}

/// Pitch steps of +-20 deg every 4 s for `seconds`; the first mismatch's time, if any.
pub fn pitch_until_mismatch(run: &mut Run, seconds: f64) -> Option<(f64, String)> {
    pitch_scored(run, seconds).0
}

/// [`pitch_until_mismatch`], and the mean angle between the true attitude and the setpoint
/// over the samples flown, deg.
pub fn pitch_scored(run: &mut Run, seconds: f64) -> (Option<(f64, String)>, f64) {
    let (mut sum, mut k) = (0.0, 0u64);
    let found = pitch_with(run, seconds, |sp, run| {
        sum += run.sim.attitude().angle_to(sp).to_degrees();
        k += 1;
    });
    (found, sum / k.max(1) as f64)
}

/// The soaks' flight plan: pitch +20 and -20 deg in turn every 4 s at the heading and depth
/// the vehicle had when it began.
pub struct PitchSteps {
    yaw: f64,
    depth: f64,
    step: usize,
    setpoint: UnitQuaternion<f64>,
}

impl PitchSteps {
    pub fn new(run: &Run) -> PitchSteps {
        PitchSteps {
            yaw: run.sim.roll_pitch_yaw()[2],
            depth: run.sim.position_ned().z,
            step: 0,
            setpoint: UnitQuaternion::identity(),
        }
    }

    /// At `t` s into the flight: the next step's setpoint handed to the machine when due; the
    /// setpoint in force.
    pub fn at(&mut self, run: &mut Run, t: f64) -> UnitQuaternion<f64> {
        if t >= 4.0 * self.step as f64 {
            let p: f64 = [20.0, -20.0][self.step % 2];
            self.setpoint = UnitQuaternion::from_euler_angles(0.0, p.to_radians(), self.yaw);
            run.machine.on_setpoint(self.setpoint, Some(self.depth));
            self.step += 1;
        }
        self.setpoint
    }
}

pub fn pitch_with(
    run: &mut Run,
    seconds: f64,
    mut each: impl FnMut(&UnitQuaternion<f64>, &Run),
) -> Option<(f64, String)> {
    let mut plan = PitchSteps::new(run);
    let start = run.sim.time_s();
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        let sp = plan.at(run, t);
        run.tick();
        each(&sp, run);
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(why) = e {
                return Some((t, why));
            }
        }
        assert_eq!(
            run.machine.state(),
            State::Active,
            "left control at {t:.1} s"
        );
    }
    None
}

/// What `khz_hold` varies; the default is the shipped setup.
pub struct KhzSettings {
    pub seconds: f64,
    /// The deadband the machine compensates (0.05: the T200's, as thruster-sim's driver does
    /// in the daemon's setup). With 0 the model is linear where the thrust is not, and the
    /// change test took that for a yaw thruster's change after 13 s (seed 1).
    pub deadband: f64,
    pub change_test: bool,
    pub latency_us: Option<(u64, u64)>,
    /// The first estimation's `estimator.target_rel_err` (None: the shipped 0.06). A lower
    /// target runs longer and leaves the model's terms tighter, which is what the change
    /// test's `change_term_z` is about.
    pub target_rel_err: Option<f64>,
}

impl Default for KhzSettings {
    fn default() -> Self {
        KhzSettings {
            seconds: 180.0,
            deadband: 0.05,
            change_test: true,
            latency_us: None,
            target_rel_err: None,
        }
    }
}

/// Estimates at 1 kHz and the paper's noise, then holds through pitch 0 / 10 deg steps every
/// 20 s for `seconds`; panics on any mismatch reported or on leaving Active. The number of
/// refinement windows judged.
pub fn khz_hold(seed: u64, k: KhzSettings) -> usize {
    let mut run = Run::with_rate("amour5", NoisePreset::Paper, seed, 1000.0);
    run.latency_us = k.latency_us;
    let mut setup = MachineSetup {
        thrusters: 5,
        ..MachineSetup::default()
    };
    // No driver in between: the machine compensates the deadband itself.
    setup.machine.deadband = k.deadband;
    setup.refinement.change_test = k.change_test;
    if let Some(t) = k.target_rel_err {
        setup.estimator.target_rel_err = t;
    }
    run.machine = Machine::new(setup);
    run.run_for(1.0);
    run.estimate();
    run.machine.take_events();
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    let start = run.sim.time_s();
    let mut step = 0;
    let mut windows = 0;
    while run.sim.time_s() - start < k.seconds {
        let t = run.sim.time_s() - start;
        if t >= 20.0 * step as f64 {
            let p: f64 = [10.0, 0.0][step % 2];
            run.machine.on_setpoint(
                UnitQuaternion::from_euler_angles(0.0, p.to_radians(), yaw),
                Some(depth),
            );
            step += 1;
        }
        let before = run.machine.refinement().copied();
        run.tick();
        if run.machine.refinement().copied() != before {
            windows += 1;
        }
        for e in run.machine.take_events() {
            assert!(
                !matches!(e, Event::MismatchDetected(_)),
                "seed {seed}: false alarm at {t:.1} s: {e:?}"
            );
        }
        assert_eq!(
            run.machine.state(),
            State::Active,
            "seed {seed} at {t:.1} s"
        );
    }
    windows
}

/// Hold level at the current heading and depth for `seconds`; the first mismatch's time (s
/// from the start of this call) and text, if any.
pub fn level_until_mismatch(run: &mut Run, seconds: f64) -> Option<(f64, String)> {
    level_with(run, seconds, |_| {})
}

/// [`level_until_mismatch`], calling `each` after every sample.
pub fn level_with(
    run: &mut Run,
    seconds: f64,
    mut each: impl FnMut(&Run),
) -> Option<(f64, String)> {
    let yaw = run.sim.roll_pitch_yaw()[2];
    let depth = run.sim.position_ned().z;
    run.machine.on_setpoint(
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        Some(depth),
    );
    let start = run.sim.time_s();
    while run.sim.time_s() - start < seconds {
        run.tick();
        each(run);
        let t = run.sim.time_s() - start;
        for e in run.machine.take_events() {
            if let Event::MismatchDetected(why) = e {
                return Some((t, why));
            }
        }
        assert_eq!(
            run.machine.state(),
            State::Active,
            "left control at {t:.1} s"
        );
    }
    None
}

pub fn quiet_flight(run: &mut Run, seconds: f64) -> (Mismatch, Mismatch) {
    let pitch = pitch_until_mismatch(run, seconds);
    let level = if pitch.is_none() {
        level_until_mismatch(run, seconds)
    } else {
        None
    };
    (pitch, level)
}

/// The shipped refinement settings (the per-sample change test on, as by default: see
/// `RefinementConfig::change_test`). What the asserting tests use: no environment variable
/// changes it.
pub fn shipped_change_test() -> RefinementConfig {
    let c = RefinementConfig::default();
    assert!(c.change_test, "the change test is on by default");
    c
}
