//! The estimation run under control (state Identify): first a hold without dither, for the
//! navigation's starting attitude (the mean specific force) and, when no noise levels are known
//! yet, the noise: `machine.noise_s` to measure the noise, else the shorter
//! `identification.lead_in_s`; then the dither on top of the controller's command, the
//! estimator fed with the total command, and a stop decision every `estimator.segment_s`.

use nalgebra::Vector3;
use thruster_protocol::MAX_THRUSTERS;

use super::{EstimationRun, Motion};
use crate::adaptation::identification::{Dither, IdentificationConfig};
use crate::adaptation::refinement::command_level::CommandLevel;
use crate::estimator::dynamic::spin_state::{lags_for_fit, SpinState};
use crate::estimator::dynamic::thrust_curve;
use crate::estimator::Method;
use crate::machine::config::MachineSetup;
use crate::model::Model;
use crate::solve::Purpose;

/// Where a closed-loop run stands.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(in crate::machine) struct ClosedLoop {
    pub(super) dither: Dither,
    start_ns: u64,
    /// When the dither started (None while holding for the noise and the starting attitude).
    excite_from_ns: Option<u64>,
    next_decision_ns: u64,
    /// The command sent after the last sample: it acted during the interval the next sample
    /// ends, and is fitted with that sample.
    sent: [f64; MAX_THRUSTERS],
    /// The dither's shape sent with it (unit amplitude): the thrust columns' instruments.
    #[serde(default = "zero_commands", with = "crate::serde_arrays::array")]
    sent_dither: [f64; MAX_THRUSTERS],
    /// The gyro bias, frozen when the dither starts: the attitude filter's estimate wanders
    /// with the accelerations the dither causes, and a wandering bias is motion to the fit.
    gyro_bias: Vector3<f64>,
    /// Dither amplitude, sized to the noise when the dither starts.
    amplitude: f64,
    /// How the dither compared with the controller's own command since it started.
    #[serde(default)]
    excitation: Excitation,
    /// The thrust columns are fitted with the dither as their instrument
    /// (`IdentificationConfig::instrument`).
    #[serde(default)]
    instrumented: bool,
    /// The commands sent through the fit's lags (`estimator::dynamic::spin_state`): the
    /// thrusters are running when the fit starts, and its lags start where they are.
    #[serde(default)]
    spin: SpinState,
    /// The ratio of the thrust-curve probe's exponents (`thrust_curve::WIDE`, or `NARROW`
    /// when the commands already go through a learned curve).
    #[serde(default = "wide_curve")]
    curve_ratio: f64,
    /// The run's shortest dither, s, where it is not `identification.min_s`: the
    /// identification that confirms a curve just learned (`run_at_least`).
    #[serde(default)]
    shortest_s: Option<f64>,
    /// How far below full command the commands sent since the dither started were
    /// (`refinement::command_level`): where a line fitted on them sits on a thrust curve.
    #[serde(default)]
    level: CommandLevel,
}

impl ClosedLoop {
    /// The run's shortest dither, s: `identification.min_s` unless lengthened
    /// (`EstimationRun::run_at_least`).
    fn shortest_s(&self, cfg: &IdentificationConfig) -> f64 {
        self.shortest_s.unwrap_or(cfg.min_s)
    }
}

fn wide_curve() -> f64 {
    thrust_curve::WIDE
}

/// The dither against the controller's own command over an identification: how much of the
/// commands' variation was the dither's.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct Excitation {
    samples: u64,
    dither_sq: f64,
    #[serde(with = "crate::serde_arrays::array")]
    control_sum: [f64; MAX_THRUSTERS],
    #[serde(with = "crate::serde_arrays::array")]
    control_sq: [f64; MAX_THRUSTERS],
}

impl Excitation {
    fn push(&mut self, control: &[f64], sent: &[f64]) {
        self.samples += 1;
        for (i, (c, s)) in control.iter().zip(sent).enumerate() {
            self.dither_sq += (s - c) * (s - c);
            self.control_sum[i] += c;
            self.control_sq[i] += c * c;
        }
    }

    /// The dither's share of the commands' variance: its power over its own and the
    /// controller's variation about its mean, summed over the thrusters.
    pub fn dither_share(&self) -> f64 {
        if self.samples == 0 {
            return 0.0;
        }
        let n = self.samples as f64;
        let control: f64 = self
            .control_sum
            .iter()
            .zip(&self.control_sq)
            .map(|(s, q)| (q - s * s / n).max(0.0))
            .sum();
        let total = self.dither_sq + control;
        if total > 0.0 {
            self.dither_sq / total
        } else {
            0.0
        }
    }
}

fn zero_commands() -> [f64; MAX_THRUSTERS] {
    [0.0; MAX_THRUSTERS]
}

/// What one sample under control led to.
pub(in crate::machine) enum ClosedStep {
    /// Holding without dither, measuring.
    Holding,
    /// The dither was added to the command.
    Exciting,
    /// A decision interval ended, `elapsed_s` into the dither: its estimate and decision
    /// are a solve (a job, `crate::solve`); the run goes on until its result is applied.
    Decide { elapsed_s: f64 },
}

impl EstimationRun {
    /// Whether a run may go on under control with this setup: the dynamic method only.
    pub(in crate::machine) fn closed_loop_possible(setup: &MachineSetup) -> bool {
        setup.identification.closed_loop && setup.estimator.method == Method::Dynamic
    }

    /// A new run under control begins at `t_ns`. The noise levels of an earlier run (measured
    /// at rest) are kept: under control the gyro also sees the held motion.
    pub(in crate::machine) fn begin_closed_loop(
        &mut self,
        t_ns: u64,
        cfg: &IdentificationConfig,
        n: usize,
        spin: SpinState,
        curve_learned: bool,
    ) {
        self.restart();
        self.closed = Some(ClosedLoop {
            dither: Dither::new(n, cfg.hold_s, t_ns),
            start_ns: t_ns,
            excite_from_ns: None,
            next_decision_ns: u64::MAX,
            sent: [0.0; MAX_THRUSTERS],
            sent_dither: [0.0; MAX_THRUSTERS],
            gyro_bias: Vector3::zeros(),
            amplitude: cfg.dither,
            excitation: Excitation::default(),
            instrumented: false,
            spin,
            curve_ratio: if curve_learned {
                thrust_curve::NARROW
            } else {
                thrust_curve::WIDE
            },
            shortest_s: None,
            level: CommandLevel::default(),
        });
    }

    /// The run under control goes on for at least `s` of dither (and `identification.min_s`),
    /// never beyond `max_s`. Nothing open loop.
    pub(in crate::machine) fn run_at_least(&mut self, s: f64, cfg: &IdentificationConfig) {
        if let Some(c) = self.closed.as_mut() {
            c.shortest_s = Some(s.max(cfg.min_s).min(cfg.max_s));
        }
    }

    /// |E ln |u|| of the commands sent under control since the dither started, weighted as a
    /// linear fit weighs them (`CommandLevel`); None open loop or before any.
    pub(in crate::machine) fn command_log_level(&self) -> Option<f64> {
        self.closed.as_ref().and_then(|c| c.level.log_level())
    }

    /// The shortest dither of the run under control, s: `identification.min_s` unless the
    /// run was lengthened (`run_at_least`).
    pub(in crate::machine) fn shortest_s(&self, cfg: &IdentificationConfig) -> f64 {
        self.closed
            .as_ref()
            .map_or(cfg.min_s, |c| c.shortest_s(cfg))
    }

    /// The dither against the controller's command so far (None open loop).
    pub(in crate::machine) fn excitation(&self) -> Option<Excitation> {
        self.closed.as_ref().map(|c| c.excitation)
    }

    /// The commands sent through the fit's lags so far (None open loop).
    pub(in crate::machine) fn spin_state(&self) -> Option<&SpinState> {
        self.closed.as_ref().map(|c| &c.spin)
    }

    /// Seconds of dither so far (0 while holding or open loop).
    pub(in crate::machine) fn excited_s(&self, t_ns: u64) -> f64 {
        self.closed
            .as_ref()
            .and_then(|c| c.excite_from_ns)
            .map_or(0.0, |t0| t_ns.saturating_sub(t0) as f64 * 1e-9)
    }

    /// One sample under control. `command` holds the controller's command (model units) for
    /// `n` thrusters and gets the dither added, faded by the attitude error `err_deg`; `m.gyro`
    /// is the raw rate, `gyro_bias` the attitude filter's bias estimate now, `instrument`
    /// whether the fit is to be instrumented if it starts now (`Instrument::applies` on the
    /// sea state before the identification). A decision
    /// interval that ends while the last one's solve is still out waits for it (the next
    /// sample asks again): decisions are made in order, one at a time.
    #[allow(clippy::too_many_arguments)]
    pub(in crate::machine) fn closed_loop_sample(
        &mut self,
        t_ns: u64,
        m: &Motion,
        gyro_bias: &Vector3<f64>,
        err_deg: f64,
        setup: &MachineSetup,
        model: Option<&Model>,
        instrument: bool,
        n: usize,
        command: &mut [f64],
    ) -> ClosedStep {
        // The lag the model in force learned, if it did (its own run learned it open loop),
        // or the learned model a carried-over prior came from (after an announced change
        // the model in force is the new geometry's nominal one).
        let prior = self.prior.as_ref();
        let lag = model
            .and_then(|m| m.learned_spin_up_s())
            .or(prior.and_then(|p| p.spin_up_s));
        let lags = model
            .and_then(|m| m.learned_thruster_lags())
            .or(prior.map(|p| p.thruster_lags_s.as_slice()))
            .filter(|l| !l.is_empty());
        let k = command.len().min(MAX_THRUSTERS);
        let fit_lags = lags_for_fit(k, setup.estimator.spin_up_s, lag, lags);
        let Some(c) = self.closed.as_mut() else {
            return ClosedStep::Holding;
        };
        let t_s = t_ns as f64 * 1e-9;
        c.spin.advance_to(t_s, &fit_lags[..k]);
        let Some(excite_from) = c.excite_from_ns else {
            // Holding: the rest (starting attitude and vertical velocity) and the noise.
            self.noise.push(&m.gyro.into(), &m.accel.into());
            let held_s = t_ns.saturating_sub(c.start_ns) as f64 * 1e-9;
            self.rest.push_held(m, held_s);
            c.sent[..command.len()].copy_from_slice(command);
            c.spin.hold(command);
            // The noise measured once is kept: then the hold is only the lead-in
            // (`IdentificationConfig::lead_in_s`), as long as the controller holds the vehicle
            // within the dither's full amplitude by then (half the attitude budget); one it
            // does not hold yet is held for `machine.noise_s` (or the lead-in, if longer), as
            // before the lead-in.
            let ident = &setup.identification;
            let taken_up = err_deg <= 0.5 * ident.attitude_budget_deg;
            let hold_s = match (self.levels.is_some(), taken_up) {
                (true, true) => ident.lead_in_s,
                (true, false) => ident.lead_in_s.max(setup.machine.noise_s),
                (false, _) => setup.machine.noise_s,
            };
            if held_s < hold_s || self.noise.samples() < super::MIN_REST_SAMPLES {
                return ClosedStep::Holding;
            }
            c.gyro_bias = *gyro_bias;
            c.excite_from_ns = Some(t_ns);
            c.next_decision_ns = t_ns + (setup.estimator.segment_s * 1e9) as u64;
            let levels = *self.levels.get_or_insert_with(|| self.noise.levels());
            c.amplitude = setup.identification.amplitude(levels.sigma_rot());
            // The focus `carry` set follows the amplitude now the noise is known
            // (`IdentificationConfig::focus_at`).
            let ident = &setup.identification;
            if let Some(p) = self.prior.as_ref().filter(|_| ident.focus_gain > 0.0) {
                let (gain, others) = ident.focus_at(c.amplitude);
                c.dither.focus(&p.unknown_thrusters(), gain, others);
            }
            let mut est = self.new_estimator(setup.estimator.clone(), n, levels, model);
            if let Some(lag_s) = lag {
                est = est.with_learned_lag(lag_s);
            }
            if let Some(lags) = lags {
                est = est.with_learned_thruster_lags(lags);
            }
            // What those lags put into B comes with them, from where they came.
            let lag_rel_err = match model.filter(|m| m.learned_spin_up_s().is_some()) {
                Some(m) => m.lag_rel_err(),
                None => prior.map_or([0.0; 2], |p| p.lag_rel_err),
            };
            est = est.with_inherited_lag_error(lag_rel_err);
            // And what the kept columns' own run's navigation left in them.
            if let Some(p) = prior {
                est = est.with_inherited_navigation_error(p.navigation_rel_err);
            }
            // The IMU did not move with the thrusters: where the model in force (or the prior's)
            // put it, else where it is configured. Never learned again here: closed-loop data
            // cannot place it (eight_vectored in moderate water found it 16 cm off and its
            // acceleration rows came out 158 % off under a 20 % bound).
            let imu = model
                .and_then(|m| m.imu_position_m())
                .or(prior.and_then(|p| p.imu_position_m.map(Vector3::from)));
            est = match imu {
                Some(p) => est.with_known_imu_position(p),
                None => est.with_configured_imu_position(),
            };
            if let Some(c) = self.closed.as_mut() {
                c.instrumented = instrument;
            }
            if instrument {
                est.begin_instrumented_closed_loop();
            } else {
                est.begin_closed_loop();
            }
            if let Some(c) = self.closed.as_ref() {
                est.start_spun_up(&c.spin);
                if ident.max_curve_evidence > 0.0 {
                    est.probe_thrust_curve(c.curve_ratio);
                }
            }
            self.est = Some(est);
            return ClosedStep::Holding;
        };
        let Some(est) = self.est.as_mut() else {
            return ClosedStep::Holding;
        };
        let cfg = &setup.identification;
        let instrumented = c.instrumented;
        let k = command.len();
        est.push_commanded_sample(
            t_s,
            &(m.gyro - c.gyro_bias),
            &m.specific_force,
            m.depth,
            &c.sent[..k],
            instrumented.then_some(&c.sent_dither[..k]),
        );
        let mut control = [0.0; MAX_THRUSTERS];
        control[..k].copy_from_slice(command);
        let amplitude = c.amplitude * cfg.fade(err_deg);
        c.dither
            .add_to(t_s, amplitude, setup.estimator.reverse_ratio, command);
        c.excitation.push(&control[..k], command);
        c.level.push(command);
        c.sent[..k].copy_from_slice(command);
        c.spin.hold(command);
        if instrumented {
            c.dither
                .instruments(setup.estimator.reverse_ratio, &mut c.sent_dither[..k]);
        }
        if t_ns < c.next_decision_ns || self.solver.waiting_for(Purpose::Interval) {
            return ClosedStep::Exciting;
        }
        let elapsed_s = t_ns.saturating_sub(excite_from) as f64 * 1e-9;
        // Every segment; every `settle_decision_s` while the stop may wait for a settled
        // estimate (from a segment before `min_s`: each decision compares with the estimate a
        // segment earlier); every `late_decision_s` once that wait is over. A fight (the dither
        // under its share) keeps the segments: stopped sooner, its model was out of its widened
        // bound.
        let ident = &setup.identification;
        let segment_s = setup.estimator.segment_s;
        let min_s = c.shortest_s(ident);
        let late = elapsed_s + 1e-9 >= min_s + ident.settle_wait_s;
        let settling = ident.settle > 0.0 && elapsed_s + 1e-9 >= min_s - segment_s;
        let every_s = if c.excitation.dither_share() < ident.min_dither_share {
            segment_s
        } else if late {
            ident.late_decision_s.min(segment_s)
        } else if settling {
            ident.settle_decision_s.min(segment_s)
        } else {
            segment_s
        };
        c.next_decision_ns += (every_s * 1e9) as u64;
        est.end_interval();
        ClosedStep::Decide { elapsed_s }
    }
}
