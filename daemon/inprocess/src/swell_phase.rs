//! Where the swell is when a run begins. The water presets start their waves at phase 0 on
//! every seed, so over seeds only the sensors' noise varied, never where the swell was when
//! the pulses or the dither began (docs/study.md, "The swell's phase"); the sweeps and tests
//! that vary it take the phase from here.

use thruster_sim::DisturbanceConfig;

/// The swell's phase for `seed`, rad: 2 pi frac(seed x 0.618...), the golden ratio's
/// sequence, so any ten seeds spread over the circle, none twice.
pub fn of_seed(seed: u64) -> f64 {
    let golden = (5f64.sqrt() - 1.0) / 2.0;
    std::f64::consts::TAU * (seed as f64 * golden).fract()
}

/// Every wave of `water` starts at `phase_rad`.
pub fn set(water: &mut DisturbanceConfig, phase_rad: f64) {
    water.waves.iter_mut().for_each(|w| w.phase_rad = phase_rad);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ten_seeds_put_the_swell_at_ten_phases_spread_over_the_cycle() {
        let mut phases: Vec<f64> = (1..=10).map(of_seed).collect();
        phases.sort_by(f64::total_cmp);
        assert!(phases
            .iter()
            .all(|p| (0.0..std::f64::consts::TAU).contains(p)));
        // The widest gap between neighbours on the circle, the wrap-around included.
        let widest = phases
            .windows(2)
            .map(|w| w[1] - w[0])
            .chain([phases[0] + std::f64::consts::TAU - phases[9]])
            .fold(0.0, f64::max);
        assert!(widest < 1.0, "a gap of {widest} rad");
    }
}
