//! The terms of the dynamic response model besides the thrust, one value each per sample.
//!
//! Fossen's model, M nu_dot + C(nu) nu + D(nu) nu + g(q) = tau, solved for nu_dot, is linear in
//! these terms once M^-1 is folded into unknown coefficients: body rates and velocities (linear
//! damping, and the coupling M^-1 brings between axes), their |x| x (quadratic damping), gravity
//! in the body frame (restoring moment and net buoyancy), and the products nu_i nu_j (rigid-body
//! and added-mass Coriolis, the Munk moment, and the accelerometer's omega x v). A constant takes
//! a slow drift (a gyro bias left after the rest), and the mean |command| through the thruster
//! lag takes the forward/reverse asymmetry that the balanced excitation leaves as a near-constant
//! force. Noise-free, this set recovers the simulator's B to 1e-3 with the true state
//! (docs/study.md, "oracle").

use nalgebra::Vector3;

/// Number of terms (the protocol's, which carries them in `DynamicsMsg`).
pub const TERMS: usize = thruster_protocol::DYNAMIC_TERMS;

/// Name of each term, in order (for reports and the demo's JSON).
pub const TERM_NAMES: [&str; TERMS] = thruster_protocol::DYNAMIC_TERM_NAMES;

/// Index of the first term of each group in [`TERM_NAMES`].
pub const RATE: usize = 0;
pub const RATE_QUADRATIC: usize = 3;
pub const VELOCITY: usize = 6;
pub const VELOCITY_QUADRATIC: usize = 9;
pub const DOWN: usize = 12;

/// Whether term `j` has the body velocity in it (its own group, |v| v, and the products nu_i
/// nu_j with a velocity among them): the terms a dead-reckoned velocity's error enters.
pub fn touches_velocity(j: usize) -> bool {
    if (VELOCITY..DOWN).contains(&j) {
        return true;
    }
    let mut k = DOWN + 3;
    for i in 0..6 {
        for jj in i..6 {
            if k == j {
                return i < 3 || jj < 3;
            }
            k += 1;
        }
    }
    false
}

/// Writes the terms for body velocity `v`, rate `w`, gravity direction `down` (unit, body
/// frame) and mean lagged |command| into `out` (length [`TERMS`]).
pub fn terms(
    v: &Vector3<f64>,
    w: &Vector3<f64>,
    down: &Vector3<f64>,
    mean_abs_command: f64,
    out: &mut [f64],
) {
    debug_assert_eq!(out.len(), TERMS);
    let nu = [v.x, v.y, v.z, w.x, w.y, w.z];
    for a in 0..3 {
        out[RATE + a] = w[a];
        out[RATE_QUADRATIC + a] = w[a].abs() * w[a];
        out[VELOCITY + a] = v[a];
        out[VELOCITY_QUADRATIC + a] = v[a].abs() * v[a];
        out[DOWN + a] = down[a];
    }
    let mut k = DOWN + 3;
    for i in 0..6 {
        for j in i..6 {
            out[k] = nu[i] * nu[j];
            k += 1;
        }
    }
    out[k] = 1.0;
    out[k + 1] = mean_abs_command;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_velocity_terms_are_those_a_velocity_moves() {
        let (w, down) = (Vector3::new(0.3, -0.2, 0.5), Vector3::new(0.1, 0.0, 0.99));
        let mut at_rest = [0.0; TERMS];
        let mut moving = [0.0; TERMS];
        terms(&Vector3::zeros(), &w, &down, 0.4, &mut at_rest);
        terms(&Vector3::new(0.2, -0.1, 0.3), &w, &down, 0.4, &mut moving);
        for j in 0..TERMS {
            assert_eq!(touches_velocity(j), at_rest[j] != moving[j], "term {j}");
        }
        assert_eq!((0..TERMS).filter(|&j| touches_velocity(j)).count(), 6 + 15);
    }

    #[test]
    fn names_match_the_layout() {
        let mut out = [0.0; TERMS];
        terms(
            &Vector3::new(1.0, 2.0, 3.0),
            &Vector3::new(4.0, 5.0, 6.0),
            &Vector3::z(),
            0.5,
            &mut out,
        );
        let at = |name: &str| out[TERM_NAMES.iter().position(|n| *n == name).unwrap()];
        assert_eq!(at("q"), 5.0);
        assert_eq!(at("|w|w"), 9.0);
        assert_eq!(at("down_z"), 1.0);
        assert_eq!(at("vr"), 12.0);
        assert_eq!(at("rr"), 36.0);
        assert_eq!(at("mean_abs_command"), 0.5);
    }
}
