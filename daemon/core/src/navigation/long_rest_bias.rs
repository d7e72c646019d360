//! The gyro's bias over a long rest (a minute or two of thrusters at neutral), from how the
//! gyro turned the directions the accelerometer and the magnetometer measure.
//!
//! Why: a short rest's mean gyro is its bias plus the vehicle's mean rotation, and in a
//! swell (a 6.7 s period) a 1-2 s rest's mean rotation is anything up to the swell's rate:
//! 0.04-0.19 rad/s taken for bias, which the navigation integrated into a gravity tilted by up
//! to 0.36 rad all through the run (docs/study.md, "What breaks the acceleration rows in a
//! strong swell"). `rest_rotation` nets out a turn in small angles over the short rest; over
//! minutes a resting vehicle in a swell does not turn by small angles: eight_vectored in the
//! full moderate swell turned about the vertical by 0.13 rad/s on average for two minutes,
//! rocking 0.3 rad while it did, so a mean gyro kept its turn and a tilted one's turn put
//! 0.03 rad/s into its body x and y.
//!
//! Exact instead, in two parts. Across gravity: "down" d, fixed in the world, seen in the
//! body moves as d' = -(g - b) x d with g the gyro and b its bias. About gravity: the heading
//! psi from the magnetometer (tilt-compensated, unwrapped so whole turns count) moves as
//! psi' = (g - b) . c with c = (0, sin roll, cos roll) / cos pitch (Z-Y-X angles, roll and
//! pitch from "down"). Whatever the vehicle did, rocking, coning or turning, those hold. Both
//! are weighted by w(t) = t (span - t), zero at the rest's ends, and integrated by parts:
//! b x Dw = Sw - (integral of w' d), with Dw and Sw the integrals of w d and w g x d, and
//! b . Cw = Gw + (integral of w' psi). Why the weight: unweighted, the ends' own readings
//! enter (d_end - d_start), and an accelerometer reads accelerations as "down": a vehicle
//! released into a current read 0.08 rad off at the start, which left 0.08 rad / span in the
//! bias (eight_vectored in the moderate water at a tenth of its swell: 0.0078 rad/s after 10 s,
//! still 0.0007 after 110 s, and a start attitude 0.012 rad off). Weighted, 1e-5 after 30 s.
//! The swell's acceleration in "down" averages out over the rest. (The field's own direction
//! in the first equation would not do for the part about gravity: turning whole turns, its
//! horizontal part integrates to nothing.) Without a magnetometer the part about "down" is not
//! seen: the caller keeps another estimate for it. Running moments (t^0..t^2, trapezoidal), so
//! the weight can be chosen when the rest ends; no allocation.

use nalgebra::{Matrix3, Vector3};

/// Fewest samples and shortest span for the bias to mean anything.
const MIN_SAMPLES: u64 = 200;
const MIN_SPAN_S: f64 = 5.0;

/// A horizontal field weaker than this share of the whole (near a magnetic pole, a reading
/// swamped by the vehicle's own field) gives no heading.
const MIN_HORIZONTAL_SHARE: f64 = 0.1;

/// Pitched closer to vertical than this (cos pitch), the heading's rate equation is
/// singular: no heading.
const MIN_COS_PITCH: f64 = 0.2;

/// Moments of a sampled quantity F against time since the rest's first sample:
/// the integrals of F, t F and t^2 F (trapezoidal).
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
struct Moments<T> {
    m: [T; 3],
    last: Option<(f64, T)>,
}

impl<T> Moments<T>
where
    T: Copy + Default + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T>,
{
    fn push(&mut self, t: f64, f: T) {
        if let Some((t0, f0)) = self.last {
            let dt = t - t0;
            let (mut p0, mut p1) = (1.0, 1.0);
            for k in 0..3 {
                self.m[k] = self.m[k] + (f0 * p0 + f * p1) * (0.5 * dt);
                p0 *= t0;
                p1 *= t;
            }
        }
        self.last = Some((t, f));
    }

    /// The integrals of w F and of w' F, with w(t) = t (span - t): a weight that is zero at
    /// both ends of the rest.
    fn weighted(&self, span: f64) -> (T, T) {
        let [m0, m1, m2] = self.m;
        (m1 * span + m2 * -1.0, m0 * span + m1 * -2.0)
    }
}

/// The body's heading (rad, Z-Y-X yaw: from north towards east) and the heading rate's
/// direction c (psi' = w . c), from the magnetometer (any unit) and the specific force at rest
/// (which points up). None when the field has too little horizontal part, the body is near
/// vertical, or a reading is degenerate.
pub fn heading(mag: &Vector3<f64>, specific_force: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
    let down = -specific_force.try_normalize(1e-9)?;
    let east = down.cross(mag);
    // NaN fails this too.
    let horizontal = east.norm() >= MIN_HORIZONTAL_SHARE * mag.norm();
    if !horizontal {
        return None;
    }
    let east = east.normalize();
    let north = east.cross(&down);
    // Z-Y-X: down in the body is (-sin pitch, sin roll cos pitch, cos roll cos pitch).
    let cos_pitch = down.y.hypot(down.z);
    if cos_pitch < MIN_COS_PITCH {
        return None;
    }
    let (sin_roll, cos_roll) = (down.y / cos_pitch, down.z / cos_pitch);
    let c = Vector3::new(0.0, sin_roll, cos_roll) / cos_pitch;
    // The body's x axis in the world: its north and east components.
    let psi = east.x.atan2(north.x);
    (psi.is_finite() && c.iter().all(|v| v.is_finite())).then_some((psi, c))
}

/// The long rest's running integrals.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct LongRestBias {
    /// The first and the last sample's times, s.
    t0: f64,
    last_t_s: Option<f64>,
    n: u64,
    /// "Down" and the gyro crossed with it.
    down: Moments<Vector3<f64>>,
    turned: Moments<Vector3<f64>>,
    /// The unwrapped heading, c and the gyro dotted with c; the last heading; whether a
    /// sample had none (then the part about gravity is not seen).
    psi: Moments<f64>,
    c: Moments<Vector3<f64>>,
    gc: Moments<f64>,
    unwrapped: Option<(f64, f64)>,
    headless: bool,
}

/// The bias found over a long rest.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RestBias {
    /// The gyro's bias, rad/s. When `about_down_seen` is false its part about `down` is zero:
    /// the caller supplies it.
    pub bias: Vector3<f64>,
    /// The mean "down" over the rest (unit, body frame).
    pub down: Vector3<f64>,
    /// Whether the part about `down` was seen (a magnetometer with a heading all along).
    pub about_down_seen: bool,
    /// The rest's span, s.
    pub span_s: f64,
}

impl LongRestBias {
    pub fn new() -> Self {
        Self::default()
    }

    /// One sample at `t_s`: raw gyro (rad/s), specific force (m/s^2) and magnetometer (any
    /// unit; None without one), body frame. A sample with a non-finite or degenerate value,
    /// or a time that does not advance, is skipped.
    pub fn push(
        &mut self,
        t_s: f64,
        gyro: &Vector3<f64>,
        specific_force: &Vector3<f64>,
        mag: Option<&Vector3<f64>>,
    ) {
        // At rest the specific force points up: "down" is its opposite.
        let Some(down) = specific_force.try_normalize(1e-9).map(|f| -f) else {
            return;
        };
        let finite = t_s.is_finite()
            && gyro.iter().all(|v| v.is_finite())
            && down.iter().all(|v| v.is_finite());
        if !finite || self.last_t_s.is_some_and(|t| t_s <= t) {
            return;
        }
        if self.last_t_s.is_none() {
            self.t0 = t_s;
        }
        let t = t_s - self.t0;
        self.down.push(t, down);
        self.turned.push(t, gyro.cross(&down));
        match mag.and_then(|m| heading(m, specific_force)) {
            Some((psi, c)) if !self.headless => {
                let unwrapped = match self.unwrapped {
                    Some((last, value)) => {
                        let step = (psi - last + std::f64::consts::PI)
                            .rem_euclid(std::f64::consts::TAU)
                            - std::f64::consts::PI;
                        value + step
                    }
                    None => 0.0,
                };
                self.unwrapped = Some((psi, unwrapped));
                self.psi.push(t, unwrapped);
                self.c.push(t, c);
                self.gc.push(t, gyro.dot(&c));
            }
            _ => self.headless = true,
        }
        self.last_t_s = Some(t_s);
        self.n += 1;
    }

    /// The bias, when the rest is long enough ([`MIN_SAMPLES`], [`MIN_SPAN_S`]).
    pub fn bias(&self) -> Option<RestBias> {
        let span_s = self.last_t_s.map_or(0.0, |t| t - self.t0);
        if self.n < MIN_SAMPLES || span_s < MIN_SPAN_S {
            return None;
        }
        // Weighted by w(t) = t (span - t), zero at both ends: the ends' readings (a swell's
        // acceleration in "down" then, a vehicle released into a current at the start: 0.08
        // rad, which left 0.08 rad / span in the bias) weigh nothing. d' = -(g - b) x d times w,
        // integrated by parts: b x Dw = Sw - (integral of w' d).
        let (d_w, d_dw) = self.down.weighted(span_s);
        let (s_w, _) = self.turned.weighted(span_s);
        let down = d_w.try_normalize(1e-12)?;
        // [-Dw]x b = rhs: least squares, with a ridge along "down" (which the cross product
        // does not see) that leaves that part zero.
        let a: Matrix3<f64> = (-d_w).cross_matrix();
        let rhs = s_w - d_dw;
        let scale = d_w.norm();
        let normal = a.transpose() * a + down * down.transpose() * (scale * scale);
        let mut bias = normal.try_inverse()? * (a.transpose() * rhs);
        // psi' = (g - b) . c times w, by parts: b . Cw = Gw + (integral of w' psi).
        let (c_w, _) = self.c.weighted(span_s);
        let (g_w, _) = self.gc.weighted(span_s);
        let (_, psi_dw) = self.psi.weighted(span_s);
        let seen = !self.headless && down.dot(&c_w).abs() > 0.5 * scale;
        if seen {
            let lambda = (g_w + psi_dw - bias.dot(&c_w)) / down.dot(&c_w);
            bias += down * lambda;
        }
        bias.iter().all(|v| v.is_finite()).then_some(RestBias {
            bias,
            down,
            about_down_seen: seen,
            span_s,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    const G: f64 = 9.80665;

    /// 200 Hz for `seconds` of a vehicle whose attitude (body to NED) is `attitude(t)`, its
    /// gyro reading the true body rate plus `bias`, in a field `field_ned`; `mag` false:
    /// no magnetometer.
    fn rest(
        bias: Vector3<f64>,
        seconds: f64,
        mag: bool,
        attitude: impl Fn(f64) -> UnitQuaternion<f64>,
    ) -> LongRestBias {
        let field = Vector3::new(20.0, 0.0, 45.0);
        let mut r = LongRestBias::new();
        let h = 1e-5;
        for k in 0..=(seconds * 200.0) as usize {
            let t = k as f64 * 0.005;
            let (q0, q1) = (attitude(t - h), attitude(t + h));
            // Body rate: q' = q * (0, w/2), so w = log(q0^-1 q1) / 2h.
            let w = (q0.inverse() * q1).scaled_axis() / (2.0 * h);
            let q = attitude(t);
            let f = q.inverse_transform_vector(&Vector3::new(0.0, 0.0, -G));
            let m = q.inverse_transform_vector(&field);
            r.push(50.0 + t, &(w + bias), &f, mag.then_some(&m));
        }
        r
    }

    /// Rocking 0.3 / 0.2 rad at a 6.7 s period while turning whole turns about the vertical
    /// (0.13 rad/s, 2.5 turns): every axis of the bias, with the field; without it the part
    /// across gravity. A mean gyro would be 0.09-0.13 rad/s off.
    #[test]
    fn a_rocking_vehicle_turning_whole_turns_gives_the_bias() {
        let bias = Vector3::new(0.004, -0.006, 0.003);
        let w = std::f64::consts::TAU / 6.7;
        let attitude = |t: f64| {
            UnitQuaternion::from_euler_angles(
                0.3 * (w * t).sin(),
                0.2 * (w * t + 1.0).cos(),
                0.13 * t + 0.1 * (w * t).sin(),
            )
        };
        let found = rest(bias, 120.0, true, attitude).bias().unwrap();
        assert!(found.about_down_seen);
        assert!(
            (found.bias - bias).norm() < 2e-4,
            "{} against {bias}",
            found.bias
        );
        let across = |v: Vector3<f64>| v - found.down * found.down.dot(&v);
        let no_field = rest(bias, 120.0, false, attitude).bias().unwrap();
        assert!(!no_field.about_down_seen);
        assert!(
            (across(no_field.bias) - across(bias)).norm() < 2e-4,
            "{} against {bias}",
            no_field.bias
        );
    }

    /// A vehicle tilted 0.4 rad and coning (its tilt's direction going round): its body rate
    /// has a steady part across its z axis that is no bias.
    #[test]
    fn coning_is_not_taken_for_bias() {
        let bias = Vector3::new(-0.002, 0.005, 0.001);
        let attitude = |t: f64| {
            let axis = Vector3::new((0.2 * t).cos(), (0.2 * t).sin(), 0.0);
            UnitQuaternion::from_scaled_axis(axis * 0.4)
        };
        let r = rest(bias, 90.0, true, attitude);
        let found = r.bias().unwrap();
        assert!(
            (found.bias - bias).norm() < 2e-4,
            "{} against {bias}",
            found.bias
        );
    }

    /// The accelerometer reads 0.8 m/s^2 across gravity, decaying over its first second (a
    /// vehicle released into a current): its reading at the end weighs nothing and the jolt
    /// only through w' over its 0.3 s, so 60 s later the bias is within 1e-4 rad/s (4e-5
    /// measured; the unweighted ends would leave its 0.09 rad over 60 s, 1.4e-3).
    #[test]
    fn a_jolt_at_the_start_is_not_taken_for_bias() {
        let bias = Vector3::new(0.002, -0.001, 0.0005);
        let field = Vector3::new(20.0, 0.0, 45.0);
        let q = UnitQuaternion::from_euler_angles(0.05, -0.03, 0.7);
        let mut r = LongRestBias::new();
        for k in 0..=(60.0 * 200.0) as usize {
            let t = k as f64 * 0.005;
            let jolt = Vector3::new(0.8, 0.3, 0.0) * (-t / 0.3).exp();
            let f = q.inverse_transform_vector(&(jolt - Vector3::new(0.0, 0.0, G)));
            let m = q.inverse_transform_vector(&field);
            r.push(t, &bias, &f, Some(&m));
        }
        let found = r.bias().unwrap();
        assert!(
            (found.bias - bias).norm() < 1e-4,
            "{} against {bias}",
            found.bias
        );
    }

    #[test]
    fn the_heading_of_a_tilted_body_is_its_yaw() {
        let field = Vector3::new(20.0, 0.0, 45.0);
        for yaw in [-3.0, -1.2, 0.0, 0.4, 2.9] {
            let q = UnitQuaternion::from_euler_angles(0.3, -0.2, yaw);
            let mag = q.inverse_transform_vector(&field);
            let f = q.inverse_transform_vector(&Vector3::new(0.0, 0.0, -G));
            let (psi, _) = heading(&mag, &f).unwrap();
            let d = (psi - yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            assert!(d.abs() < 1e-9, "yaw {yaw}: heading {psi}");
        }
        let up = Vector3::new(0.0, 0.0, -G);
        assert!(
            heading(&Vector3::new(0.0, 0.0, 45.0), &up).is_none(),
            "a vertical field"
        );
    }

    #[test]
    fn a_still_rest_gives_its_bias_and_a_short_one_nothing() {
        let bias = Vector3::new(0.01, 0.02, -0.03);
        let level = |_: f64| UnitQuaternion::from_euler_angles(0.05, -0.1, 1.0);
        let found = rest(bias, 10.0, true, level).bias().unwrap();
        assert!((found.bias - bias).norm() < 1e-9, "{}", found.bias);
        assert!(rest(bias, 4.0, true, level).bias().is_none(), "4 s");
    }
}
