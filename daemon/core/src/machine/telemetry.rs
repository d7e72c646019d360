//! What the daemon publishes on `telemetry`: the machine as it stands after answering one IMU
//! sample (attitude estimate, the setpoint the controller tracks and the error to it, depth,
//! the model in force, the estimation's progress). Pure and allocation-free, so the daemon
//! may take one on every sample; the commands are the `Command` that sample got, which the
//! daemon puts beside it (`wire::telemetry_msg`) as they went out on the wire.

use nalgebra::{UnitQuaternion, Vector3};

use super::state_machine::Machine;
use super::types::{ImuInput, State};
use crate::controller::{attitude_error, Target};

/// The estimation under way, as far as it got.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Progress {
    /// Pulses completed.
    pub pulses: usize,
    /// Pulses planned (may grow until the stopping rule is met).
    pub pulses_planned: usize,
    /// Excitation power, normalised command in [0, 1].
    pub power: f64,
    /// Relative error bound (1 sigma) of this run's latest estimate; None before its first
    /// estimate, or while the bound is not finite (not every thruster pulsed yet).
    pub error_bound: Option<f64>,
    /// Measured noise, one sigma: rotation rate rad/s and acceleration m/s^2 (None before
    /// measured).
    pub sigma: Option<(f64, f64)>,
}

/// The machine after one IMU sample, in SI units.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TelemetrySnapshot {
    /// The sample's time, ns, IMU clock, and its sequence number.
    pub t_ns: u64,
    pub imu_seq: u64,
    pub state: State,
    /// Attitude estimate, body to NED.
    pub attitude: UnitQuaternion<f64>,
    /// Body rate, gyro minus the filter's bias estimate, rad/s.
    pub rate: Vector3<f64>,
    /// The sample's depth, m, positive down (None: no depth sensor).
    pub depth: Option<f64>,
    /// What the controller tracks while it controls (holding, or levelling before a run);
    /// None while it does not.
    pub setpoint: Option<Target>,
    /// Rotation from the estimate to the setpoint as a body-frame rotation vector, rad (the
    /// controller's error); zero without a setpoint.
    pub attitude_error: Vector3<f64>,
    /// `setpoint depth - depth`, m, when both are known.
    pub depth_error: Option<f64>,
    /// `version` of the model in force (0 = none).
    pub model_version: u64,
    /// The estimation under way (None when none is).
    pub progress: Option<Progress>,
}

impl TelemetrySnapshot {
    /// Angle between the estimate and the setpoint, rad, in [0, pi] (0 without a setpoint).
    pub fn attitude_error_angle(&self) -> f64 {
        self.attitude_error.norm()
    }
}

impl Machine {
    /// The machine after answering `sample` (call it right after [`Machine::on_imu`] with the
    /// same sample): no allocation, no change to the machine.
    pub fn telemetry(&self, sample: &ImuInput) -> TelemetrySnapshot {
        let attitude = self.attitude();
        let setpoint = self.tracked_target();
        let attitude_error =
            setpoint.map_or_else(Vector3::zeros, |t| attitude_error(&attitude, &t.attitude));
        let depth_error = match (setpoint.and_then(|t| t.depth), sample.depth) {
            (Some(want), Some(depth)) => Some(want - depth),
            _ => None,
        };
        let progress = self.run().estimator().map(|est| {
            let pulses = est.pulses();
            // The last estimate may be the previous run's: only this run's counts. Estimates
            // are made as a pulse ends, so this run's latest has exactly its pulse count.
            let error_bound = self
                .run()
                .last_estimate()
                .filter(|e| pulses > 0 && e.pulses == pulses)
                .map(|e| e.rel_err_rot.max(e.rel_err_acc))
                .filter(|b| b.is_finite());
            let sigma = self
                .run()
                .levels()
                .map(|l| (l.sigma_rot(), l.sigma_acc()))
                .filter(|(r, a)| r.is_finite() && a.is_finite());
            Progress {
                pulses,
                pulses_planned: est.plan_extent(),
                power: est.power(),
                error_bound,
                sigma,
            }
        });
        TelemetrySnapshot {
            t_ns: sample.t_ns,
            imu_seq: sample.seq,
            state: self.state(),
            attitude,
            rate: Vector3::from(sample.gyro) - self.gyro_bias(),
            depth: sample.depth,
            setpoint,
            attitude_error,
            depth_error,
            model_version: self.model().map_or(0, |m| m.version),
            progress,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::{DepthInput, Geometry, MachineSetup, Request, SetpointInput};

    /// AMOUR-like layout: two thrusters along x at the sides, two pushing up fore and aft.
    fn machine() -> Machine {
        let geometry = Geometry {
            positions: vec![
                [0.0, -0.2, 0.0],
                [0.0, 0.2, 0.0],
                [-0.2, -0.15, 0.0],
                [0.2, 0.15, 0.0],
            ],
            directions: vec![
                [1.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 0.0, -1.0],
                [0.0, 0.0, -1.0],
            ],
        };
        Machine::new(MachineSetup {
            thrusters: 4,
            geometry: Some(geometry),
            ..MachineSetup::default()
        })
    }

    /// Level and still, 200 Hz, depth `depth`.
    fn level(k: u64, depth: f64) -> ImuInput {
        ImuInput {
            seq: k,
            t_ns: 1_000_000_000 + k * 5_000_000,
            gyro: [0.0; 3],
            accel: [0.0, 0.0, -9.80665],
            mag: Some([20.0, 0.0, 45.0]),
            depth: Some(depth),
        }
    }

    #[test]
    fn idle_has_no_setpoint_and_reports_the_sample() {
        let mut m = machine();
        let s = ImuInput {
            gyro: [0.01, -0.02, 0.0],
            ..level(1, 3.0)
        };
        m.on_imu(&s);
        let t = m.telemetry(&s);
        assert_eq!(t.state, State::Idle);
        assert_eq!((t.t_ns, t.imu_seq), (s.t_ns, 1));
        assert_eq!(t.depth, Some(3.0));
        assert_eq!(t.setpoint, None);
        assert_eq!(t.attitude_error_angle(), 0.0);
        assert_eq!(t.depth_error, None);
        assert!(t.progress.is_none());
        // The nominal model from the declared geometry is in force.
        assert_eq!(t.model_version, m.model().unwrap().version);
        assert!(t.model_version > 0);
        // The filter has no bias estimate yet: the rate is the gyro's.
        assert!((t.rate - Vector3::new(0.01, -0.02, 0.0)).norm() < 1e-9);
    }

    #[test]
    fn holding_a_pitch_setpoint_reports_it_and_the_error_to_it() {
        let mut m = machine();
        let mut k = 0;
        for _ in 0..50 {
            k += 1;
            m.on_imu(&level(k, 3.0));
        }
        m.on_request(Request::Hold).unwrap();
        k += 1;
        let s = level(k, 3.0);
        m.on_imu(&s);
        let t = m.telemetry(&s);
        assert_eq!(t.state, State::Active);
        // Hold without a setpoint: level at the heading and depth of the moment.
        let held = t.setpoint.expect("a setpoint while holding");
        assert_eq!(held.depth, Some(3.0));
        assert!(held.attitude.euler_angles().0.abs() < 1e-9);
        assert!(held.attitude.euler_angles().1.abs() < 1e-9);
        assert!(t.attitude_error_angle() < 1e-3, "{t:?}");
        assert!((t.attitude_error_angle() - t.attitude.angle_to(&held.attitude)).abs() < 1e-9);
        assert_eq!(t.depth_error, Some(0.0));

        // The operator asks for 10 deg nose up and 2.5 m, keeping the heading.
        let want = UnitQuaternion::from_euler_angles(0.0, 10f64.to_radians(), 0.0);
        m.on_setpoint_input(&SetpointInput {
            attitude: want,
            keep: [false, false, true],
            depth: DepthInput::Hold(2.5),
        });
        k += 1;
        let s = level(k, 3.1);
        m.on_imu(&s);
        let t = m.telemetry(&s);
        let sp = t.setpoint.unwrap();
        let (_, pitch, _) = sp.attitude.euler_angles();
        assert!((pitch - 10f64.to_radians()).abs() < 1e-9, "{pitch}");
        // Still level: the whole error is pitch, about body y, positive (nose up wanted).
        let angle = t.attitude_error_angle();
        assert!((angle - 10f64.to_radians()).abs() < 1e-3, "{angle}");
        assert!(t.attitude_error.y > 0.99 * angle, "{:?}", t.attitude_error);
        let e = t.depth_error.unwrap();
        assert!((e - (2.5 - 3.1)).abs() < 1e-12, "{e}");
        // Idle again: nothing is tracked, whatever the last setpoint was.
        m.on_request(Request::Idle).unwrap();
        k += 1;
        let s = level(k, 3.1);
        m.on_imu(&s);
        let t = m.telemetry(&s);
        assert_eq!(t.setpoint, None);
        assert_eq!(t.depth_error, None);
    }

    /// Issue 27: `setpoint --pitch 10` from a depth hold let the vehicle rise 7 m. A setpoint
    /// that does not mention depth keeps the depth held; only an explicit release frees it.
    #[test]
    fn a_setpoint_without_depth_keeps_the_held_depth() {
        let mut m = machine();
        let mut k = 0;
        let mut step = |m: &mut Machine, depth: f64| {
            k += 1;
            let s = level(k, depth);
            m.on_imu(&s);
            m.telemetry(&s)
        };
        for _ in 0..50 {
            step(&mut m, 26.56);
        }
        m.on_request(Request::Hold).unwrap();
        assert_eq!(step(&mut m, 26.56).setpoint.unwrap().depth, Some(26.56));
        let pitch = |depth| SetpointInput {
            attitude: UnitQuaternion::from_euler_angles(0.0, 10f64.to_radians(), 0.0),
            keep: [true, false, true],
            depth,
        };
        m.on_setpoint_input(&pitch(DepthInput::Keep));
        let t = step(&mut m, 26.6);
        let sp = t.setpoint.unwrap();
        assert_eq!(sp.depth, Some(26.56));
        assert!((sp.attitude.euler_angles().1 - 10f64.to_radians()).abs() < 1e-9);
        assert!((t.depth_error.unwrap() - (26.56 - 26.6)).abs() < 1e-12);
        m.on_setpoint_input(&pitch(DepthInput::Hold(20.0)));
        assert_eq!(step(&mut m, 26.6).setpoint.unwrap().depth, Some(20.0));
        m.on_setpoint_input(&pitch(DepthInput::Release));
        let t = step(&mut m, 26.6);
        assert_eq!(t.setpoint.unwrap().depth, None);
        assert_eq!(t.depth_error, None);
        // Released stays released: keeping keeps "free".
        m.on_setpoint_input(&pitch(DepthInput::Keep));
        assert_eq!(step(&mut m, 26.6).setpoint.unwrap().depth, None);
    }

    /// Issue 27: a daemon started before its driver said "no IMU samples from any driver"
    /// beside a 200 Hz rate until an estimation. The first sample clears it.
    #[test]
    fn the_first_sample_clears_no_imu_yet() {
        let mut m = machine();
        m.on_no_imu_yet("no IMU samples from any driver for 100 ms (namespace x)");
        assert!(
            m.status().text.contains("no IMU samples"),
            "{}",
            m.status().text
        );
        m.on_imu(&level(1, 3.0));
        let text = m.status().text;
        assert_eq!(text, "idle: waiting for an estimate request");
        // Once samples came, the call does nothing (the daemon stops making it anyway).
        m.on_no_imu_yet("no IMU samples from any driver for 100 ms (namespace x)");
        assert_eq!(m.status().text, text);
    }

    /// Issue 27: a saved model v8 reloaded as version 1. It keeps its version when the
    /// daemon's counter is below it; an older file gets the next number (versions never go
    /// back) and status names the version it was saved as.
    #[test]
    fn a_loaded_model_keeps_its_saved_version_and_versions_only_go_up() {
        let mut m = machine();
        let mut saved = m.model().unwrap().clone();
        assert_eq!(saved.version, 1);
        saved.version = 8;
        m.load_model(saved.clone()).unwrap();
        assert_eq!(m.model().unwrap().version, 8);
        assert!(
            m.status().text.starts_with("model loaded: model v8"),
            "{}",
            m.status().text
        );
        saved.version = 3;
        m.load_model(saved).unwrap();
        assert_eq!(m.model().unwrap().version, 9);
        assert!(
            m.status()
                .text
                .starts_with("model loaded (saved as v3): model v9"),
            "{}",
            m.status().text
        );
    }

    #[test]
    fn an_estimation_reports_its_own_progress_only() {
        let mut m = machine();
        let mut k = 0;
        for _ in 0..20 {
            k += 1;
            m.on_imu(&level(k, 3.0));
        }
        m.on_request(Request::Estimate).unwrap();
        // Measuring noise: no estimator yet, so no progress; the state says what happens.
        k += 1;
        let s = level(k, 3.0);
        m.on_imu(&s);
        let t = m.telemetry(&s);
        assert_eq!(t.state, State::MeasureNoise);
        assert!(t.progress.is_none());
        // Until the first pulse: the noise is known, the pulses planned, no estimate yet.
        let mut first = None;
        for _ in 0..2000 {
            k += 1;
            let s = level(k, 3.0);
            m.on_imu(&s);
            if m.state() == State::Pulse {
                first = Some(m.telemetry(&s));
                break;
            }
        }
        let t = first.expect("pulsing within 10 s");
        let p = t.progress.expect("progress while pulsing");
        assert_eq!(p.pulses, 0);
        assert!(p.pulses_planned > 0);
        assert!(p.power > 0.0 && p.power <= 1.0, "{p:?}");
        assert_eq!(p.error_bound, None);
        let (rot, acc) = p.sigma.expect("noise measured before pulsing");
        assert!(rot.is_finite() && acc.is_finite());
    }
}
