//! The first pulse's strength from what is already known: with a model in force (the declared
//! geometry's, or the one being replaced) and the noise just measured, pulse no harder than the
//! noise requires.
//!
//! Why: a fixed strong pulse (0.8 of full thrust, tuned for the paper's 0.25 rad/s gyro) spins
//! a BlueROV2-class body at up to ~3 rad/s per pulse. With a realistic IMU that buys nothing:
//! in-process (docs/study.md, "Pulse power"), with the declared geometry as the model in force,
//! the same 16 pulses at the 0.2 floor instead of 0.8 tilted AMOUR-5 17 deg instead of 43 and
//! the model came out more accurate (rotation error 0.12 instead of 0.16; six_dof 0.14 instead
//! of 0.19, four_up 0.13 instead of 0.22), since quadratic drag bends the response of a
//! fast-spinning body away from the linear model. At the paper's noise nothing changes.

use nalgebra::DMatrix;

use super::noise::NoiseLevels;

/// Pulse strength (fraction of full command) at which the model predicts that a pulse of
/// `pulse_s` changes the body rate by `snr` gyro standard deviations through a typical
/// thruster (the median of the columns' rotational norms: a thruster the old model saw as
/// dead must not force full power), within `[min_power, max_start]`. `None` when the model
/// says nothing (wrong size, no rotational effect, no noise figure).
pub fn pulse_power(
    effectiveness: &DMatrix<f64>,
    thrusters: usize,
    noise: &NoiseLevels,
    pulse_s: f64,
    snr: f64,
    min_power: f64,
    max_start: f64,
) -> Option<f64> {
    if effectiveness.ncols() != thrusters || effectiveness.nrows() != 6 || thrusters == 0 {
        return None;
    }
    let mut norms: Vec<f64> = (0..thrusters)
        .map(|i| effectiveness.fixed_view::<3, 1>(0, i).norm())
        .collect();
    norms.sort_by(f64::total_cmp);
    let typical = norms[thrusters / 2];
    let sigma = noise.sigma_rot();
    if !(typical.is_finite() && typical > 0.0 && sigma.is_finite() && pulse_s > 0.0) {
        return None;
    }
    let p = snr * sigma / (typical * pulse_s);
    p.is_finite().then(|| p.max(min_power).min(max_start))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(gains: &[f64]) -> DMatrix<f64> {
        // Each thruster pitches with its gain, rad/s^2 per unit command.
        DMatrix::from_fn(6, gains.len(), |r, c| if r == 1 { gains[c] } else { 0.0 })
    }

    #[test]
    fn the_power_follows_the_noise_between_its_bounds() {
        let b = model(&[30.0, 30.0, 30.0]);
        let at = |sigma: f64| {
            pulse_power(
                &b,
                3,
                &NoiseLevels::isotropic(sigma, 0.1),
                0.1,
                12.0,
                0.2,
                0.8,
            )
            .unwrap()
        };
        // 12 sigma of 0.01 rad/s from 3 rad/s per unit power: 0.04, floored at 0.2.
        assert_eq!(at(0.01), 0.2);
        // 12 x 0.1 / 3 = 0.4.
        assert!((at(0.1) - 0.4).abs() < 1e-12);
        // The paper's 0.25 rad/s asks for 1.0: capped at the configured start.
        assert_eq!(at(0.25), 0.8);
    }

    #[test]
    fn a_dead_thruster_in_the_old_model_does_not_force_full_power() {
        let b = model(&[30.0, 0.0, 30.0]);
        let p = pulse_power(
            &b,
            3,
            &NoiseLevels::isotropic(0.1, 0.1),
            0.1,
            12.0,
            0.2,
            0.8,
        );
        assert!((p.unwrap() - 0.4).abs() < 1e-12);
    }

    #[test]
    fn a_model_of_another_size_or_without_effect_says_nothing() {
        let noise = NoiseLevels::isotropic(0.1, 0.1);
        assert_eq!(
            pulse_power(&model(&[30.0; 3]), 4, &noise, 0.1, 12.0, 0.2, 0.8),
            None
        );
        assert_eq!(
            pulse_power(&model(&[0.0; 3]), 3, &noise, 0.1, 12.0, 0.2, 0.8),
            None
        );
    }
}
