//! The simulator's own dynamics in the dynamic model's 38 terms (a probe's truth): for the
//! decisive run that holds the terms at their true values, so what is left in B is what the
//! terms' estimation does not explain (docs/study.md, "The first cycle against the whole run").

use nalgebra::{DMatrix, UnitQuaternion, Vector3, Vector6};
use thruster_sim::dynamics::{fossen_to_dof_order, RigidBody, State};
use thrusterd_core::estimator::dynamic::regressors::{terms, TERMS};

/// 6 x TERMS coefficients (DOF rows, the layout of `DynamicTerms::coefficients`) that give the
/// simulator's unforced acceleration of `name` (no thrust, no water) from the terms: the
/// rotation rows its angular acceleration, the translation rows what the gravity-free
/// accelerometer at the centre reads (v_dot + omega x v). Fitted by least squares at 400
/// states spread over +-0.6 m/s, +-1.5 rad/s and every attitude; the model is in the terms'
/// span, so the fit is exact. Returns the coefficients and the largest residual.
pub fn true_terms_38(name: &str) -> (DMatrix<f64>, f64) {
    let v = thruster_inprocess::estimation::vehicle(name);
    let rb = RigidBody::new(&v.body).expect("the vehicle's body");
    const N: usize = 400;
    // The last two terms (the constant and the mean |command|) are not physics here; the
    // constant is kept in the fit so a body heavier than it floats shows as its own term.
    let cols = TERMS - 1;
    let mut x = DMatrix::zeros(N, cols);
    let mut y = DMatrix::zeros(N, 6);
    // A fixed low-discrepancy walk: the same states every run.
    let frac = |k: usize, a: f64| ((k as f64 + 1.0) * a).fract() * 2.0 - 1.0;
    let mut t = vec![0.0; TERMS];
    for k in 0..N {
        let vel = Vector3::new(frac(k, 0.618_034), frac(k, 0.414_214), frac(k, 0.732_051)) * 0.6;
        let w = Vector3::new(frac(k, 0.236_068), frac(k, 0.645_751), frac(k, 0.316_625)) * 1.5;
        let att = UnitQuaternion::from_euler_angles(
            frac(k, 0.123_106) * 3.1,
            frac(k, 0.561_553) * 1.5,
            frac(k, 0.872_983) * 3.1,
        );
        let state = State {
            position_ned_m: Vector3::zeros(),
            attitude: att,
            nu: Vector6::new(vel.x, vel.y, vel.z, w.x, w.y, w.z),
        };
        let nu_dot = rb.acceleration(&state, &Vector6::zeros(), &Vector3::zeros());
        let lin = Vector3::new(nu_dot[0], nu_dot[1], nu_dot[2]) + w.cross(&vel);
        let out = fossen_to_dof_order(&Vector6::new(
            lin.x, lin.y, lin.z, nu_dot[3], nu_dot[4], nu_dot[5],
        ));
        let down = att.inverse_transform_vector(&Vector3::z());
        terms(&vel, &w, &down, 0.0, &mut t);
        for j in 0..cols {
            x[(k, j)] = t[j];
        }
        for r in 0..6 {
            y[(k, r)] = out[r];
        }
    }
    let svd = x.clone().svd(true, true);
    let theta = svd.solve(&y, 1e-12).expect("least squares");
    let residual = (&x * &theta - &y).abs().max();
    let mut coefficients = DMatrix::zeros(6, TERMS);
    for r in 0..6 {
        for j in 0..cols {
            coefficients[(r, j)] = theta[(j, r)];
        }
    }
    (coefficients, residual)
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_inprocess::estimation::{estimate_ideal, true_terms, Ideal};
    use thruster_sim::{NoisePreset, SensorConfig};
    use thrusterd_core::estimator::dynamic::regressors::{DOWN, RATE, VELOCITY};
    use thrusterd_core::estimator::EstimatorConfig;

    /// The fit is exact, and its linear and restoring parts are the simulator's own as the
    /// older, direct `true_terms` computes them (the Coriolis and quadratic terms, the rest of
    /// the fit, cannot move them: they are products of the velocities).
    #[test]
    fn the_simulators_dynamics_are_in_the_terms_span() {
        for name in ["amour5", "eight_vectored"] {
            let (c, residual) = true_terms_38(name);
            assert!(residual < 1e-9, "{name}: residual {residual}");
            let (lin, restoring) = true_terms(name);
            for r in 0..6 {
                for a in 0..3 {
                    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * (1.0 + y.abs());
                    assert!(
                        close(c[(r, RATE + a)], lin[(r, 3 + a)]),
                        "{name} row {r} rate {a}"
                    );
                    assert!(
                        close(c[(r, VELOCITY + a)], lin[(r, a)]),
                        "{name} row {r} vel {a}"
                    );
                    assert!(
                        close(c[(r, DOWN + a)], restoring[(r, a)]),
                        "{name} row {r} down {a}"
                    );
                }
            }
        }
    }

    /// The research hook holds the terms where it is told: noise-free in still water, held at
    /// the truth B stays within 0.2 % (the free fit's own accuracy), and held with one
    /// coefficient moved, the fit reports the moved value, not the data's.
    #[test]
    fn a_prior_mean_holds_the_terms_where_it_is_told() {
        let (truth, _) = true_terms_38("amour5");
        let sensors = SensorConfig {
            rate_hz: 200.0,
            noise: NoisePreset::None,
            ..SensorConfig::default()
        };
        let flight = |mean: DMatrix<f64>| {
            let cfg = EstimatorConfig {
                learn_spin_up: false,
                term_prior_sd: 1e-6,
                term_prior_mean: Some(mean),
                ..EstimatorConfig::dynamic()
            };
            estimate_ideal("amour5", sensors.clone(), 1, cfg, Ideal::default())
        };
        let held = flight(truth.clone());
        assert!(
            held.err_rot < 0.002 && held.err_acc < 0.002,
            "{} / {}",
            held.err_rot,
            held.err_acc
        );
        let mut moved = truth.clone();
        moved[(0, RATE)] += 1.0;
        let o = flight(moved);
        let fitted = o.terms.coefficients[(0, RATE)];
        // Within 1 % of the move (the noise-free data pulls against the prior's 1e-6).
        assert!(
            (fitted - (truth[(0, RATE)] + 1.0)).abs() < 0.01,
            "roll damping {fitted}, held at {}",
            truth[(0, RATE)] + 1.0
        );
    }
}
