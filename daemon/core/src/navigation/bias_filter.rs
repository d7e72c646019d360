//! The error-state Kalman filter behind the navigation: depth, NED velocity and the
//! accelerometer's bias.
//!
//! Why a filter and not a complementary depth aid: at rest an accelerometer bias across gravity
//! is indistinguishable from tilt, so starting the attitude from the rest's specific force
//! folds it into an attitude error psi. That error is constant in the NED frame (the gyro
//! carries both attitudes alike), and the rest ties it to the bias: psi = M0 b, with M0 from
//! the rest attitude. Once the vehicle turns, the folded bias no longer cancels: the velocity
//! error grows as d(dv)/dt = A(t) b with A = -C - [(C f)x] M0, whose vertical row is the body's
//! down vector seen by b. The depth sensor observes the vertical channel, so each turn of the
//! excitation makes another direction of b observable; the filter's cross-covariances carry
//! each bias update into the horizontal velocity and the attitude.
//!
//! States, true minus estimate: depth (m), NED velocity (3, m/s), body-frame bias (3, m/s^2).
//! Fixed-size matrices: no allocation per sample.

use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};

type Mat7 = SMatrix<f64, 7, 7>;
type Vec7 = SVector<f64, 7>;

/// A correction to apply to the navigation state.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Correction {
    pub depth: f64,
    pub velocity_ned: Vector3<f64>,
    pub bias: Vector3<f64>,
    /// Small NED-frame rotation to apply to the attitude (left-multiplied), rad.
    pub attitude: Vector3<f64>,
}

/// Settings of the bias filter (1-sigma values).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FilterNoise {
    /// Depth sensor noise per sample, m.
    pub depth_std_m: f64,
    /// Accelerometer white noise per sample, m/s^2 (the velocity's process noise).
    pub accel_std_mps2: f64,
    /// Unmodelled acceleration (attitude error from gyro noise, lever arm, ...), m/s^2/sqrt(Hz).
    pub accel_floor: f64,
    /// Prior of each bias axis, m/s^2 (0: no bias state, the bias stays folded into the
    /// attitude as before).
    pub bias_std_mps2: f64,
    /// Bias random walk, m/s^2/sqrt(s).
    pub bias_walk: f64,
    /// Prior of each velocity axis at the rest, m/s (the body is not exactly neutrally buoyant).
    pub velocity_std_mps: f64,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct BiasFilter {
    noise: FilterNoise,
    p: Mat7,
    /// psi = m0 * b: the attitude error that the rest ties to the bias.
    m0: Matrix3<f64>,
}

impl BiasFilter {
    /// At the rest, with the rest attitude `attitude` (body to NED) and gravity `gravity`.
    pub fn at_rest(noise: FilterNoise, attitude: &UnitQuaternion<f64>, gravity: f64) -> Self {
        let c0 = attitude.to_rotation_matrix().into_inner();
        // g (e_z x psi) = (C0 b) horizontally: psi_x = (C0 b)_y / g, psi_y = -(C0 b)_x / g.
        let mut m0 = Matrix3::zeros();
        m0.set_row(0, &(c0.row(1) / gravity));
        m0.set_row(1, &(-c0.row(0) / gravity));
        let mut p = Mat7::zeros();
        p[(0, 0)] = noise.depth_std_m.powi(2);
        for i in 1..4 {
            p[(i, i)] = noise.velocity_std_mps.powi(2);
        }
        for i in 4..7 {
            p[(i, i)] = noise.bias_std_mps2.powi(2);
        }
        BiasFilter { noise, p, m0 }
    }

    /// Propagates the error covariance over `dt` at attitude `c` (body to NED) with the
    /// bias-corrected specific force `f` (body, m/s^2).
    pub fn predict(&mut self, dt: f64, c: &Matrix3<f64>, f: &Vector3<f64>) {
        if dt <= 0.0 {
            return;
        }
        let cf = c * f;
        let a = -c - cf.cross_matrix() * self.m0;
        let mut phi = Mat7::identity();
        phi[(0, 3)] = dt;
        phi.fixed_view_mut::<3, 3>(1, 4).copy_from(&(a * dt));
        self.p = phi * self.p * phi.transpose();
        let q_v = (self.noise.accel_std_mps2 * dt).powi(2) + self.noise.accel_floor.powi(2) * dt;
        for i in 1..4 {
            self.p[(i, i)] += q_v;
        }
        if self.noise.bias_std_mps2 > 0.0 {
            let q_b = self.noise.bias_walk.powi(2) * dt;
            for i in 4..7 {
                self.p[(i, i)] += q_b;
            }
        }
    }

    /// A depth measurement with innovation `measured - estimated` (m): the correction to apply.
    pub fn update_depth(&mut self, innovation: f64) -> Correction {
        let s = self.p[(0, 0)] + self.noise.depth_std_m.powi(2).max(1e-12);
        let k: Vec7 = self.p.column(0) / s;
        // Joseph-free form is fine here: one scalar measurement, P kept symmetric below.
        let row0 = self.p.row(0).into_owned();
        self.p -= k * row0;
        self.p = 0.5 * (self.p + self.p.transpose());
        let dx = k * innovation;
        let bias = Vector3::new(dx[4], dx[5], dx[6]);
        Correction {
            depth: dx[0],
            velocity_ned: Vector3::new(dx[1], dx[2], dx[3]),
            bias,
            attitude: self.m0 * bias,
        }
    }

    /// 1-sigma of each bias axis, m/s^2.
    pub fn bias_std(&self) -> Vector3<f64> {
        Vector3::new(self.p[(4, 4)], self.p[(5, 5)], self.p[(6, 6)]).map(|v| v.max(0.0).sqrt())
    }
}
