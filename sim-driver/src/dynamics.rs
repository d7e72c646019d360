//! Fossen 6-DOF rigid-body and hydrodynamic model, integrated with fixed-step RK4.
//!
//! ```text
//! M nu_r_dot + C(nu_r) nu_r + D(nu_r) nu_r + g(q) = tau
//! nu = nu_r + [v_c; 0],   v_c = R(q)^T current_ned
//! p_dot = R(q) v,         q_dot = 1/2 q (x) [0, omega]
//! ```
//!
//! `nu = [u v w p q r]` (Fossen order, body frame, m/s and rad/s) is the velocity over ground,
//! `nu_r` the velocity relative to the water. `M = M_RB + M_A` (rigid body about the CO with
//! the CG offset, plus diagonal added mass). `C(nu) nu` is the Kirchhoff form derived from `M`
//! (Fossen 2011, Theorem 3.2), which covers rigid-body and added-mass Coriolis/centripetal terms
//! and is skew-symmetric, so it does no work. With a constant, irrotational current, writing
//! the rigid-body terms in `nu_r` is exact (Fossen 2011, Property 8.1), and `nu_c_dot = [-omega x
//! v_c; 0]`. `D(nu) nu = D_l nu + D_q |nu| nu` (diagonal). `g(q)` is gravity at the CG and
//! buoyancy at the CB.

use nalgebra::{Matrix3, Matrix6, Quaternion, UnitQuaternion, Vector3, Vector6};

use crate::load::LoadError;
use crate::vehicle::Body;

/// Kinematic and velocity state of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct State {
    /// Position of the CO in the local NED frame, m (z = depth, positive down).
    pub position_ned_m: Vector3<f64>,
    /// Attitude, body-to-NED (`v_ned = attitude * v_body`).
    pub attitude: UnitQuaternion<f64>,
    /// Body velocity over ground `[u v w p q r]`, m/s and rad/s (Fossen order).
    pub nu: Vector6<f64>,
}

impl State {
    /// At rest at `position_ned_m` with `attitude`.
    pub fn at_rest(position_ned_m: Vector3<f64>, attitude: UnitQuaternion<f64>) -> Self {
        State {
            position_ned_m,
            attitude,
            nu: Vector6::zeros(),
        }
    }

    /// Linear body velocity `[u v w]`, m/s.
    pub fn linear(&self) -> Vector3<f64> {
        self.nu.fixed_rows::<3>(0).into_owned()
    }

    /// Angular body velocity `[p q r]`, rad/s.
    pub fn angular(&self) -> Vector3<f64> {
        self.nu.fixed_rows::<3>(3).into_owned()
    }
}

/// Skew-symmetric cross-product matrix: `skew(a) * b = a x b`.
pub fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// Rigid-body mass matrix about the CO (Fossen 2011, eq. 3.44), Fossen order.
pub fn rigid_body_mass(body: &Body) -> Matrix6<f64> {
    let m = body.mass_kg;
    let s = skew(&Vector3::from(body.cg_m));
    let i_g = Matrix3::from_diagonal(&Vector3::from(body.inertia_kgm2));
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Matrix3::identity() * m));
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-m * s));
    out.fixed_view_mut::<3, 3>(3, 0).copy_from(&(m * s));
    // Parallel-axis theorem: I_o = I_g - m S(r_g)^2.
    out.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(i_g - m * s * s));
    out
}

/// Diagonal added-mass matrix, Fossen order (positive entries).
pub fn added_mass(body: &Body) -> Matrix6<f64> {
    Matrix6::from_diagonal(&body.added_mass.to_fossen())
}

/// The body's constant matrices, and the model's force terms.
///
/// The hot path (one RK4 step is four evaluations, 1000 steps per simulated second) works on
/// plain arrays: in unoptimised builds, which the system tests use, nalgebra's generic
/// small-matrix code is an order of magnitude slower than these loops. The public methods take
/// and return nalgebra types and share the same array implementation.
#[derive(Debug, Clone)]
pub struct RigidBody {
    mass: Matrix6<f64>,
    mass_inv: Matrix6<f64>,
    m: [[f64; 6]; 6],
    m_inv: [[f64; 6]; 6],
    d_lin: V6,
    d_quad: V6,
    weight_n: f64,
    buoyancy_n: f64,
    gravity_mps2: f64,
    r_g: V3,
    r_b: V3,
}

type V3 = [f64; 3];
type V6 = [f64; 6];
/// Quaternion `[w, x, y, z]`.
type Q4 = [f64; 4];

fn cross(a: &V3, b: &V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn matvec(m: &[[f64; 6]; 6], v: &V6) -> V6 {
    // Plain index loops: iterator adapters are not inlined in unoptimised builds.
    let mut out = [0.0; 6];
    for i in 0..6 {
        let mut acc = 0.0;
        for j in 0..6 {
            acc += m[i][j] * v[j];
        }
        out[i] = acc;
    }
    out
}

/// `R(q) v` for a unit quaternion: `v + 2 w (u x v) + 2 u x (u x v)`.
fn rotate(q: &Q4, v: &V3) -> V3 {
    let u = [q[1], q[2], q[3]];
    let t = cross(&u, v);
    let t = [2.0 * t[0], 2.0 * t[1], 2.0 * t[2]];
    let ut = cross(&u, &t);
    [
        v[0] + q[0] * t[0] + ut[0],
        v[1] + q[0] * t[1] + ut[1],
        v[2] + q[0] * t[2] + ut[2],
    ]
}

/// `R(q)^T v`: rotation by the conjugate.
fn rotate_back(q: &Q4, v: &V3) -> V3 {
    rotate(&[q[0], -q[1], -q[2], -q[3]], v)
}

fn to_q4(q: &UnitQuaternion<f64>) -> Q4 {
    let q = q.quaternion();
    [q.w, q.i, q.j, q.k]
}

fn from_q4(q: &Q4) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(Quaternion::new(q[0], q[1], q[2], q[3]))
}

fn normalized(q: &Q4) -> Q4 {
    let n = q.iter().map(|a| a * a).sum::<f64>().sqrt();
    [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
}

fn v6(v: &Vector6<f64>) -> V6 {
    [v[0], v[1], v[2], v[3], v[4], v[5]]
}

fn to_rows(m: &Matrix6<f64>) -> [[f64; 6]; 6] {
    let mut out = [[0.0; 6]; 6];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = m[(i, j)];
        }
    }
    out
}

/// Integrated quantities in array form.
#[derive(Debug, Clone, Copy)]
struct Raw {
    p: V3,
    q: Q4,
    nu: V6,
}

impl Raw {
    fn from_state(s: &State) -> Raw {
        Raw {
            p: s.position_ned_m.into(),
            q: to_q4(&s.attitude),
            nu: v6(&s.nu),
        }
    }

    /// `self + k * h` (the quaternion is not renormalised).
    fn offset(&self, k: &Raw, h: f64) -> Raw {
        let mut out = *self;
        for i in 0..3 {
            out.p[i] += k.p[i] * h;
        }
        for i in 0..4 {
            out.q[i] += k.q[i] * h;
        }
        for i in 0..6 {
            out.nu[i] += k.nu[i] * h;
        }
        out
    }
}

impl RigidBody {
    /// Builds the model; `body` is validated first.
    pub fn new(body: &Body) -> Result<Self, LoadError> {
        body.validate("body")?;
        let mass = rigid_body_mass(body) + added_mass(body);
        // M is symmetric positive definite for a valid body; Cholesky both proves it and gives
        // a well-conditioned inverse.
        let mass_inv = mass
            .cholesky()
            .ok_or_else(|| {
                LoadError::invalid("body", "body", "mass matrix is not positive definite")
            })?
            .inverse();
        Ok(RigidBody {
            m: to_rows(&mass),
            m_inv: to_rows(&mass_inv),
            mass,
            mass_inv,
            d_lin: v6(&body.linear_damping.to_fossen()),
            d_quad: v6(&body.quadratic_damping.to_fossen()),
            weight_n: body.weight_n(),
            buoyancy_n: body.buoyancy_n,
            gravity_mps2: body.gravity_mps2,
            r_g: body.cg_m,
            r_b: body.cb_m,
        })
    }

    /// `M = M_RB + M_A`, Fossen order.
    pub fn mass_matrix(&self) -> &Matrix6<f64> {
        &self.mass
    }

    /// `M^-1`.
    pub fn mass_matrix_inverse(&self) -> &Matrix6<f64> {
        &self.mass_inv
    }

    /// Gravitational acceleration, m/s^2.
    pub fn gravity_mps2(&self) -> f64 {
        self.gravity_mps2
    }

    /// `C(nu) nu` (N, N m), Kirchhoff form from `M`: with `[p1; p2] = M nu`,
    /// `[omega x p1; omega x p2 + v x p1]`.
    pub fn coriolis_force(&self, nu: &Vector6<f64>) -> Vector6<f64> {
        Vector6::from(self.coriolis(&v6(nu)))
    }

    /// `D(nu) nu` (N, N m): linear plus quadratic, per DOF.
    pub fn damping_force(&self, nu: &Vector6<f64>) -> Vector6<f64> {
        Vector6::from(self.damping(&v6(nu)))
    }

    /// `g(q)` (N, N m), left-hand-side convention: the restoring generalised force acting on
    /// the vehicle is `-g(q)`.
    pub fn restoring_force(&self, attitude: &UnitQuaternion<f64>) -> Vector6<f64> {
        Vector6::from(self.restoring(&to_q4(attitude)))
    }

    /// `nu_dot` (m/s^2, rad/s^2, body frame, Fossen order) for generalised force `tau` (N, N m,
    /// body) and a constant NED current (m/s).
    pub fn acceleration(
        &self,
        state: &State,
        tau: &Vector6<f64>,
        current_ned: &Vector3<f64>,
    ) -> Vector6<f64> {
        let raw = Raw::from_state(state);
        Vector6::from(self.accel(&raw.q, &raw.nu, &v6(tau), &(*current_ned).into()))
    }

    /// Mechanical energy, J: `1/2 nu^T M nu` plus gravity and buoyancy potentials (zero at the
    /// NED origin, level). Meaningful without current; never increases without thrust when
    /// damping is non-negative.
    pub fn energy(&self, state: &State) -> f64 {
        let nu = v6(&state.nu);
        let m_nu = matvec(&self.m, &nu);
        let kinetic = 0.5 * nu.iter().zip(&m_nu).map(|(a, b)| a * b).sum::<f64>();
        let q = to_q4(&state.attitude);
        let z = state.position_ned_m.z;
        let z_g = z + rotate(&q, &self.r_g)[2];
        let z_b = z + rotate(&q, &self.r_b)[2];
        // Depth is positive down: sinking lowers the gravity potential, raises buoyancy's.
        kinetic - self.weight_n * z_g + self.buoyancy_n * z_b
    }

    /// One classical RK4 step of `dt` seconds. `tau(s, state)` gives the generalised force (N,
    /// N m, body, Fossen order) at `s` seconds into the step; the quaternion is renormalised.
    pub fn step_rk4<F>(&self, state: &State, dt: f64, current_ned: &Vector3<f64>, tau: F) -> State
    where
        F: Fn(f64, &State) -> Vector6<f64>,
    {
        let raw = self.step_raw(
            &Raw::from_state(state),
            dt,
            &(*current_ned).into(),
            |s, raw| {
                let st = State {
                    position_ned_m: Vector3::from(raw.p),
                    attitude: from_q4(&raw.q),
                    nu: Vector6::from(raw.nu),
                };
                v6(&tau(s, &st))
            },
        );
        State {
            position_ned_m: Vector3::from(raw.p),
            attitude: from_q4(&raw.q),
            nu: Vector6::from(raw.nu),
        }
    }

    /// [`RigidBody::step_rk4`] on arrays: `tau(s, attitude [w x y z])` (unit quaternion).
    pub(crate) fn step_rk4_fast<F>(&self, state: &State, dt: f64, current_ned: &V3, tau: F) -> State
    where
        F: Fn(f64, &Q4) -> V6,
    {
        let raw = self.step_raw(&Raw::from_state(state), dt, current_ned, |s, raw| {
            tau(s, &raw.q)
        });
        State {
            position_ned_m: Vector3::from(raw.p),
            attitude: from_q4(&raw.q),
            nu: Vector6::from(raw.nu),
        }
    }

    fn step_raw<F>(&self, x0: &Raw, dt: f64, current: &V3, tau: F) -> Raw
    where
        F: Fn(f64, &Raw) -> V6,
    {
        // Stages see a normalised attitude; the derivative of the quaternion uses the raw one
        // (standard RK4 on the 13-dimensional state), renormalised once at the end.
        let eval = |s: f64, x: &Raw| -> Raw {
            let unit = Raw {
                q: normalized(&x.q),
                ..*x
            };
            let t = tau(s, &unit);
            self.derivative(x, &unit.q, &t, current)
        };
        let k1 = eval(0.0, x0);
        let k2 = eval(0.5 * dt, &x0.offset(&k1, 0.5 * dt));
        let k3 = eval(0.5 * dt, &x0.offset(&k2, 0.5 * dt));
        let k4 = eval(dt, &x0.offset(&k3, dt));
        let w = dt / 6.0;
        let mut x = *x0;
        for i in 0..3 {
            x.p[i] += w * (k1.p[i] + 2.0 * k2.p[i] + 2.0 * k3.p[i] + k4.p[i]);
        }
        for i in 0..4 {
            x.q[i] += w * (k1.q[i] + 2.0 * k2.q[i] + 2.0 * k3.q[i] + k4.q[i]);
        }
        for i in 0..6 {
            x.nu[i] += w * (k1.nu[i] + 2.0 * k2.nu[i] + 2.0 * k3.nu[i] + k4.nu[i]);
        }
        x.q = normalized(&x.q);
        x
    }

    fn derivative(&self, x: &Raw, unit_q: &Q4, tau: &V6, current: &V3) -> Raw {
        let v = [x.nu[0], x.nu[1], x.nu[2]];
        let (w, q) = ([x.nu[3], x.nu[4], x.nu[5]], &x.q);
        Raw {
            p: rotate(unit_q, &v),
            q: [
                0.5 * (-q[1] * w[0] - q[2] * w[1] - q[3] * w[2]),
                0.5 * (q[0] * w[0] + q[2] * w[2] - q[3] * w[1]),
                0.5 * (q[0] * w[1] + q[3] * w[0] - q[1] * w[2]),
                0.5 * (q[0] * w[2] + q[1] * w[1] - q[2] * w[0]),
            ],
            nu: self.accel(unit_q, &x.nu, tau, current),
        }
    }

    fn coriolis(&self, nu: &V6) -> V6 {
        let p = matvec(&self.m, nu);
        let (p1, p2) = ([p[0], p[1], p[2]], [p[3], p[4], p[5]]);
        let (v, w) = ([nu[0], nu[1], nu[2]], [nu[3], nu[4], nu[5]]);
        let f = cross(&w, &p1);
        let a = cross(&w, &p2);
        let b = cross(&v, &p1);
        [f[0], f[1], f[2], a[0] + b[0], a[1] + b[1], a[2] + b[2]]
    }

    fn damping(&self, nu: &V6) -> V6 {
        let mut out = [0.0; 6];
        for i in 0..6 {
            out[i] = (self.d_lin[i] + self.d_quad[i] * nu[i].abs()) * nu[i];
        }
        out
    }

    fn restoring(&self, q: &Q4) -> V6 {
        let down = rotate_back(q, &[0.0, 0.0, 1.0]);
        let f_g = down.map(|d| d * self.weight_n);
        let f_b = down.map(|d| -d * self.buoyancy_n);
        let m_g = cross(&self.r_g, &f_g);
        let m_b = cross(&self.r_b, &f_b);
        let mut g = [0.0; 6];
        for i in 0..3 {
            g[i] = -(f_g[i] + f_b[i]);
            g[3 + i] = -(m_g[i] + m_b[i]);
        }
        g
    }

    fn accel(&self, q: &Q4, nu: &V6, tau: &V6, current_ned: &V3) -> V6 {
        let v_c = rotate_back(q, current_ned);
        let mut nu_r = *nu;
        for i in 0..3 {
            nu_r[i] -= v_c[i];
        }
        let c = self.coriolis(&nu_r);
        let d = self.damping(&nu_r);
        let g = self.restoring(q);
        let mut rhs = [0.0; 6];
        for i in 0..6 {
            rhs[i] = tau[i] - c[i] - d[i] - g[i];
        }
        let mut nu_dot = matvec(&self.m_inv, &rhs);
        // nu_c_dot = [-omega x v_c; 0]: the current is constant in NED, so it turns in the body.
        let c_dot = cross(&[nu[3], nu[4], nu[5]], &v_c);
        for i in 0..3 {
            nu_dot[i] -= c_dot[i];
        }
        nu_dot
    }
}

/// Reorders a Fossen-order 6-vector `[surge, sway, heave, roll, pitch, yaw]` into the DOF order
/// of effectiveness matrices `[roll, pitch, yaw, surge, sway, heave]`.
pub fn fossen_to_dof_order(v: &Vector6<f64>) -> Vector6<f64> {
    Vector6::new(v[3], v[4], v[5], v[0], v[1], v[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coriolis_does_no_work() {
        let rb = RigidBody::new(&Body::bluerov2()).expect("valid");
        let nu = Vector6::new(0.3, -0.2, 0.1, 0.5, -0.7, 0.9);
        let c = rb.coriolis_force(&nu);
        assert!(nu.dot(&c).abs() < 1e-12);
    }

    #[test]
    fn mass_matrix_is_symmetric_with_cg_coupling() {
        let body = Body::bluerov2();
        let m = RigidBody::new(&body).expect("valid");
        let mm = m.mass_matrix();
        assert!((mm - mm.transpose()).norm() < 1e-12);
        // z_g > 0 couples surge with pitch: M[0][4] = m z_g.
        assert!((mm[(0, 4)] - body.mass_kg * body.cg_m[2]).abs() < 1e-12);
        assert!((mm[(0, 0)] - (body.mass_kg + body.added_mass.surge)).abs() < 1e-12);
    }

    #[test]
    fn restoring_rights_a_rolled_vehicle() {
        let rb = RigidBody::new(&Body::bluerov2()).expect("valid");
        // Rolled to starboard (positive roll): the CG below the CB swings out to port, so the
        // restoring moment -g[3] is negative.
        let q = UnitQuaternion::from_euler_angles(0.3, 0.0, 0.0);
        let g = rb.restoring_force(&q);
        assert!(-g[3] < 0.0);
        // Level: only the net buoyancy, pushing up (-z).
        let g0 = rb.restoring_force(&UnitQuaternion::identity());
        assert!((-g0[2] - (112.815 - 114.8)).abs() < 1e-9);
        assert!(g0[3].abs() < 1e-12 && g0[4].abs() < 1e-12);
    }
}
