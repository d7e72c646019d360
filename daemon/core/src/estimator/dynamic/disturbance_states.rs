//! Disturbance states (issue 32 item 3): forcing the vehicle's model does not have, as more
//! columns of the dynamic fit with a free coefficient per DOF row. By default only the
//! swell's two, in the open-loop fit made again where the water moves
//! (`EstimatorConfig::moving_water_swell_hz`); the rest through the research hook
//! `EstimatorConfig::disturbance`.
//!
//! - A swell at a known frequency f: sin and cos of 2 pi f t (a moment fixed in the body,
//!   amplitude and phase free per row), and optionally the same times each of the nine
//!   entries of the attitude's rotation R^T (body from NED), for a force fixed in the world
//!   that the body sees turn as it yaws and tilts.
//! - A constant force fixed in the world, horizontal: the entries of R^T's first two
//!   columns (the third, `down`, is a term already). What a start attitude tilted by a rest
//!   that was not one leaves in the acceleration rows: the strapdown's gravity then leaks
//!   g R^T eps with eps a constant world vector, since the gyro turns the estimate and the
//!   truth alike.

use nalgebra::UnitQuaternion;

/// Columns at most.
pub const MAX_COLUMNS: usize = 32;

/// Which disturbance states the fit carries.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DisturbanceStates {
    /// The swell's frequency, Hz (None: no swell states).
    pub swell_hz: Option<f64>,
    /// The swell's force fixed in the world (its 18 columns) besides the body's moment.
    pub swell_in_world: bool,
    /// A constant horizontal force fixed in the world (6 columns).
    pub world_constant: bool,
    /// The same growing linearly in time (6 columns): what a velocity error that ramps in the
    /// world (a tilted start's gravity leak, integrated) leaves through the linear damping.
    pub world_ramp: bool,
}

impl DisturbanceStates {
    /// Columns these states take (0: none).
    pub fn columns(&self) -> usize {
        let swell = match self.swell_hz {
            Some(_) if self.swell_in_world => 20,
            Some(_) => 2,
            None => 0,
        };
        swell + if self.world_constant { 6 } else { 0 } + if self.world_ramp { 6 } else { 0 }
    }

    /// Whether any state is on (and well formed).
    pub fn any(&self) -> bool {
        self.columns() > 0 && self.swell_hz.is_none_or(|f| f.is_finite() && f > 0.0)
    }

    /// The regressors at `t_s` under `attitude` (body to NED) into `out[..columns()]`.
    pub fn fill(&self, t_s: f64, attitude: &UnitQuaternion<f64>, out: &mut [f64; MAX_COLUMNS]) {
        // The swell's two alone (the default) need no rotation.
        let world = self.world_constant || self.world_ramp || self.swell_in_world;
        let r = if world {
            attitude.to_rotation_matrix()
        } else {
            nalgebra::Rotation3::identity()
        };
        let mut k = 0;
        if let Some(hz) = self.swell_hz {
            let (s, c) = (std::f64::consts::TAU * hz * t_s).sin_cos();
            out[0] = s;
            out[1] = c;
            k = 2;
            if self.swell_in_world {
                for j in 0..3 {
                    for a in 0..3 {
                        // Body component j of NED axis a: R^T[j, a] = R[a, j].
                        let e = r[(a, j)];
                        out[k] = e * s;
                        out[k + 1] = e * c;
                        k += 2;
                    }
                }
            }
        }
        if self.world_constant {
            for j in 0..3 {
                for a in 0..2 {
                    out[k] = r[(a, j)];
                    k += 1;
                }
            }
        }
        if self.world_ramp {
            for j in 0..3 {
                for a in 0..2 {
                    out[k] = r[(a, j)] * t_s;
                    k += 1;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_world_force_seen_from_the_body_is_in_the_span_of_the_columns() {
        // 2 N north at the swell's phase, seen from a body yawed 30 deg and pitched 10 deg.
        let states = DisturbanceStates {
            swell_hz: Some(0.15),
            swell_in_world: true,
            world_constant: true,
            world_ramp: false,
        };
        assert_eq!(states.columns(), 26);
        let q = UnitQuaternion::from_euler_angles(0.0, 0.17, 0.52);
        let t = 1.3;
        let mut x = [0.0; MAX_COLUMNS];
        states.fill(t, &q, &mut x);
        let s = (std::f64::consts::TAU * 0.15 * t).sin();
        let body = q.inverse_transform_vector(&nalgebra::Vector3::new(2.0 * s, 0.0, 0.0));
        // Component j is 2 x the column of (j, north, sin).
        for j in 0..3 {
            assert!((2.0 * x[2 + 2 * (3 * j)] - body[j]).abs() < 1e-12);
        }
        // The constant east axis seen from the body.
        let east = q.inverse_transform_vector(&nalgebra::Vector3::y());
        for j in 0..3 {
            assert!((x[20 + 2 * j + 1] - east[j]).abs() < 1e-12);
        }
    }
}
