//! Pure scoring and maneuver code of the experiments: no IPC, no clocks. Angles between the
//! true attitude and the setpoint, statistics over windows of a run, the time until an error
//! is back under a threshold, and maneuver plans (setpoint steps over vehicle time).

use nalgebra::UnitQuaternion;

/// One step of a maneuver: hold this attitude (relative to the run's start heading) for a time.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// What the plot and report call it, e.g. "yaw +30".
    pub label: String,
    /// The maneuver it belongs to ("level", "yaw", "pitch", "roll"): per-maneuver errors
    /// group the step out and the step back.
    pub group: &'static str,
    pub roll_deg: f64,
    pub pitch_deg: f64,
    /// Heading change from the start heading.
    pub yaw_deg: f64,
    pub duration_s: f64,
}

impl Step {
    pub fn new(group: &'static str, rpy_deg: [f64; 3], duration_s: f64) -> Step {
        let [r, p, y] = rpy_deg;
        let label = match (r != 0.0, p != 0.0, y != 0.0) {
            (false, false, false) if group == "level" => "level".to_string(),
            (false, false, false) => format!("{group} back"),
            _ => {
                let mut parts = Vec::new();
                for (name, v) in [("roll", r), ("pitch", p), ("yaw", y)] {
                    if v != 0.0 {
                        parts.push(format!("{name} {v:+}"));
                    }
                }
                parts.join(" ")
            }
        };
        Step {
            label,
            group,
            roll_deg: r,
            pitch_deg: p,
            yaw_deg: y,
            duration_s,
        }
    }

    /// The attitude to hold (body to NED), from the start heading.
    pub fn attitude(&self, heading_rad: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(
            self.roll_deg.to_radians(),
            self.pitch_deg.to_radians(),
            heading_rad + self.yaw_deg.to_radians(),
        )
    }
}

/// A maneuver plan: steps in order; optionally the steps after the first repeated until a
/// vehicle time (s since the start of the plan).
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    pub steps: Vec<Step>,
    pub repeat_until_s: Option<f64>,
}

impl Plan {
    /// The step due at `t` s after the plan started (its index into `steps`), None after the end.
    pub fn step_at(&self, t: f64) -> Option<usize> {
        let mut start = 0.0;
        for (i, s) in self.steps.iter().enumerate() {
            if t < start + s.duration_s {
                return Some(i);
            }
            start += s.duration_s;
        }
        let until = self.repeat_until_s?;
        if t >= until || self.steps.len() < 2 {
            return None;
        }
        let first = self.steps[0].duration_s;
        let cycle: f64 = self.steps[1..].iter().map(|s| s.duration_s).sum();
        if cycle <= 0.0 {
            return None;
        }
        let mut u = (t - first) % cycle;
        for (i, s) in self.steps.iter().enumerate().skip(1) {
            if u < s.duration_s {
                return Some(i);
            }
            u -= s.duration_s;
        }
        None
    }

    /// Length of the plan, s.
    pub fn duration_s(&self) -> f64 {
        self.repeat_until_s
            .unwrap_or_else(|| self.steps.iter().map(|s| s.duration_s).sum())
    }
}

/// Roll, pitch, yaw (ZYX Euler) in degrees.
pub fn euler_deg(q: &UnitQuaternion<f64>) -> [f64; 3] {
    let (r, p, y) = q.euler_angles();
    [r.to_degrees(), p.to_degrees(), y.to_degrees()]
}

/// An angle wrapped into (-180, 180] degrees.
pub fn wrap_deg(a: f64) -> f64 {
    let w = (a + 180.0).rem_euclid(360.0) - 180.0;
    if w == -180.0 {
        180.0
    } else {
        w
    }
}

/// Total angle between the true attitude and the setpoint, degrees (the paper's "mean angular
/// error" averages this).
pub fn angle_error_deg(truth: &UnitQuaternion<f64>, setpoint: &UnitQuaternion<f64>) -> f64 {
    truth.angle_to(setpoint).to_degrees()
}

/// Tilt error: the angle between the true body z axis and the setpoint's, degrees (the
/// roll and pitch part of the error, whatever the heading; a magnetometer's bias moves the
/// heading the controller holds, not this).
pub fn tilt_error_deg(truth: &UnitQuaternion<f64>, setpoint: &UnitQuaternion<f64>) -> f64 {
    let z = nalgebra::Vector3::z();
    (truth * z).angle(&(setpoint * z)).to_degrees()
}

/// Heading error (true minus setpoint), wrapped, degrees.
pub fn yaw_error_deg(truth: &UnitQuaternion<f64>, setpoint: &UnitQuaternion<f64>) -> f64 {
    wrap_deg(euler_deg(truth)[2] - euler_deg(setpoint)[2])
}

/// Count, mean, RMS and maximum of some values.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Stats {
    pub n: usize,
    pub mean: f64,
    pub rms: f64,
    pub max: f64,
}

impl Stats {
    pub fn of(values: impl IntoIterator<Item = f64>) -> Stats {
        let (mut n, mut sum, mut sq, mut max) = (0usize, 0.0, 0.0, f64::NEG_INFINITY);
        for v in values {
            n += 1;
            sum += v;
            sq += v * v;
            max = max.max(v);
        }
        if n == 0 {
            return Stats {
                n: 0,
                mean: f64::NAN,
                rms: f64::NAN,
                max: f64::NAN,
            };
        }
        Stats {
            n,
            mean: sum / n as f64,
            rms: (sq / n as f64).sqrt(),
            max,
        }
    }
}

/// Means over consecutive windows of `width` s: (window start, mean), from the first sample's
/// time on; windows without samples are left out. `samples` are (t, value) in time order.
pub fn window_means(samples: &[(f64, f64)], width: f64) -> Vec<(f64, f64)> {
    let Some(&(t0, _)) = samples.first() else {
        return Vec::new();
    };
    let mut out: Vec<(f64, f64)> = Vec::new();
    let (mut k, mut sum, mut n) = (0u64, 0.0, 0usize);
    for &(t, v) in samples {
        let kk = ((t - t0) / width).floor().max(0.0) as u64;
        if kk != k {
            if n > 0 {
                out.push((t0 + k as f64 * width, sum / n as f64));
            }
            (k, sum, n) = (kk, 0.0, 0);
        }
        sum += v;
        n += 1;
    }
    if n > 0 {
        out.push((t0 + k as f64 * width, sum / n as f64));
    }
    out
}

/// The time from which the error stays recovered: the start of the earliest window at or after
/// `from` such that it and every later window has a mean below `threshold`. None when the last
/// window is still above (never recovered) or no window starts after `from`.
pub fn recovered_at(windows: &[(f64, f64)], from: f64, threshold: f64) -> Option<f64> {
    let mut at = None;
    for &(t, mean) in windows.iter().filter(|w| w.0 >= from) {
        if mean < threshold {
            at.get_or_insert(t);
        } else {
            at = None;
        }
    }
    at
}

/// RMS of a signal after a first-order high-pass with time constant `tau` s: what is left of
/// an error once its slow part (steps, offsets) is removed, i.e. oscillation. `samples` are
/// (t, value) in time order; gaps are handled by the actual time steps.
pub fn high_pass_rms(samples: &[(f64, f64)], tau: f64) -> f64 {
    let mut out = Vec::with_capacity(samples.len());
    let mut prev: Option<(f64, f64, f64)> = None; // (t, x, y)
    for &(t, x) in samples {
        let y = match prev {
            None => 0.0,
            Some((tp, xp, yp)) => {
                let a = tau / (tau + (t - tp).max(0.0));
                a * (yp + x - xp)
            }
        };
        out.push(y);
        prev = Some((t, x, y));
    }
    // The filter's start-up transient is not oscillation: skip the first tau.
    let t0 = samples.first().map_or(0.0, |s| s.0);
    Stats::of(
        samples
            .iter()
            .zip(&out)
            .filter(|(s, _)| s.0 >= t0 + tau)
            .map(|(_, y)| *y),
    )
    .rms
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_and_yaw_error_go_the_short_way_round() {
        assert_eq!(wrap_deg(190.0), -170.0);
        assert_eq!(wrap_deg(-190.0), 170.0);
        assert_eq!(wrap_deg(180.0), 180.0);
        assert_eq!(wrap_deg(-180.0), 180.0);
        let a = UnitQuaternion::from_euler_angles(0.0, 0.0, 175f64.to_radians());
        let b = UnitQuaternion::from_euler_angles(0.0, 0.0, (-175f64).to_radians());
        assert!((yaw_error_deg(&a, &b) - (-10.0)).abs() < 1e-9);
        assert!((angle_error_deg(&a, &b) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn angle_error_is_the_total_rotation_angle() {
        let level = UnitQuaternion::identity();
        let pitched = Step::new("pitch", [0.0, 20.0, 0.0], 1.0).attitude(0.0);
        assert!((angle_error_deg(&pitched, &level) - 20.0).abs() < 1e-9);
        // Roll 3 and pitch 4 degrees: about 5 degrees in total, not 7.
        let both = UnitQuaternion::from_euler_angles(3f64.to_radians(), 4f64.to_radians(), 0.0);
        let e = angle_error_deg(&both, &level);
        assert!((e - 5.0).abs() < 0.01, "{e}");
        assert_eq!(euler_deg(&pitched).map(|v| v.round()), [0.0, 20.0, 0.0]);
    }

    #[test]
    fn steps_are_labelled_and_keep_the_start_heading() {
        assert_eq!(Step::new("yaw", [0.0, 0.0, 30.0], 1.0).label, "yaw +30");
        assert_eq!(Step::new("yaw", [0.0, 0.0, 0.0], 1.0).label, "yaw back");
        assert_eq!(Step::new("level", [0.0, 0.0, 0.0], 1.0).label, "level");
        let q = Step::new("pitch", [0.0, -20.0, 0.0], 1.0).attitude(1.0);
        let [_, p, y] = euler_deg(&q);
        assert!((p + 20.0).abs() < 1e-9 && (y - 1f64.to_degrees()).abs() < 1e-9);
    }

    #[test]
    fn plans_step_through_and_repeat_after_the_first_step() {
        let steps = vec![
            Step::new("level", [0.0; 3], 5.0),
            Step::new("pitch", [0.0, 20.0, 0.0], 2.0),
            Step::new("pitch", [0.0; 3], 3.0),
        ];
        let once = Plan {
            steps: steps.clone(),
            repeat_until_s: None,
        };
        assert_eq!(once.duration_s(), 10.0);
        assert_eq!(
            [0.0, 4.99, 5.0, 6.99, 7.0, 9.99, 10.0].map(|t| once.step_at(t)),
            [Some(0), Some(0), Some(1), Some(1), Some(2), Some(2), None]
        );
        let repeated = Plan {
            steps,
            repeat_until_s: Some(21.0),
        };
        assert_eq!(
            [10.0, 11.9, 12.0, 15.0, 20.9, 21.0].map(|t| repeated.step_at(t)),
            [Some(1), Some(1), Some(2), Some(1), Some(1), None]
        );
    }

    #[test]
    fn stats_and_windows() {
        let s = Stats::of([3.0, -4.0]);
        assert_eq!((s.n, s.mean, s.max), (2, -0.5, 3.0));
        assert!((s.rms - (12.5f64).sqrt()).abs() < 1e-12);
        assert!(Stats::of([]).mean.is_nan());
        let samples: Vec<(f64, f64)> = (0..10).map(|k| (k as f64 * 0.5, k as f64)).collect();
        // Windows of 2 s: samples 0..4, 4..8, 8..10.
        assert_eq!(
            window_means(&samples, 2.0),
            vec![(0.0, 1.5), (2.0, 5.5), (4.0, 8.5)]
        );
        assert!(window_means(&[], 1.0).is_empty());
    }

    #[test]
    fn recovery_is_the_start_of_the_final_run_of_good_windows() {
        let w = [
            (0.0, 1.0),
            (2.0, 9.0),
            (4.0, 1.0),
            (6.0, 8.0),
            (8.0, 1.0),
            (10.0, 1.5),
        ];
        assert_eq!(recovered_at(&w, 1.0, 2.0), Some(8.0));
        // Good from the start on when nothing after `from` exceeds it.
        assert_eq!(recovered_at(&w, 7.0, 2.0), Some(8.0));
        assert_eq!(recovered_at(&w, 0.0, 10.0), Some(0.0));
        // Still bad at the end: never recovered.
        assert_eq!(recovered_at(&w[..4], 1.0, 2.0), None);
        assert_eq!(recovered_at(&w, 11.0, 2.0), None);
    }

    #[test]
    fn high_pass_removes_steps_and_keeps_oscillation() {
        let dt = 0.01;
        let step: Vec<(f64, f64)> = (0..2000)
            .map(|k| (k as f64 * dt, if k < 1000 { 0.0 } else { 10.0 }))
            .collect();
        let osc: Vec<(f64, f64)> = (0..2000)
            .map(|k| {
                let t = k as f64 * dt;
                (t, 10.0 + (2.0 * std::f64::consts::PI * 2.0 * t).sin())
            })
            .collect();
        let (s, o) = (high_pass_rms(&step, 1.0), high_pass_rms(&osc, 1.0));
        // A 2 Hz sine of amplitude 1 passes almost whole (RMS 0.707); a single step decays.
        assert!((o - 0.707).abs() < 0.05, "{o}");
        assert!(s < 2.5 && s > 0.5, "{s}");
        let flat: Vec<(f64, f64)> = (0..100).map(|k| (k as f64 * dt, 3.0)).collect();
        assert!(high_pass_rms(&flat, 0.2).abs() < 1e-12);
    }
}
