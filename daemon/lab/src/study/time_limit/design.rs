//! The excitation families the input design searches: what every thruster is commanded at
//! each instant of the excitation, within |command| <= 1.
//!
//! - [`Excitation::Doublets`]: the daemon's default family (`Excitation::DoubletPairs`):
//!   Hadamard rows pulsed as +r, -r, -r, +r back to back, each pulse `pulse_s` long at
//!   `power`; the default is 0.1 s at power 1.
//! - [`Excitation::Multisine`]: every thruster a sum of sines on its own harmonics of `f0_hz`
//!   (thruster i takes harmonics i + 1, i + 1 + N, ...: orthogonal over a period), up to
//!   `f_max_hz`, with Schroeder phases, scaled to a peak of `power`.
//!
//! Both scale positive commands by the reverse ratio (0.78, the daemon's `reverse_ratio`) so
//! that forward and reverse impulses balance, as the daemon's pulses do.

use thrusterd_core::estimator::excitation::{Excitation as Plan, ExcitationPlan};

/// The daemon's reverse/forward ratio (`EstimatorConfig::reverse_ratio`).
pub const REVERSE_RATIO: f64 = 0.78;

#[derive(Debug, Clone)]
pub enum Excitation {
    Doublets {
        pulse_s: f64,
        power: f64,
        plan: ExcitationPlan,
    },
    Multisine {
        f0_hz: f64,
        f_max_hz: f64,
        power: f64,
        /// Per thruster: (frequency Hz, phase rad) of its sines, and its scale to the peak.
        sines: Vec<(Vec<(f64, f64)>, f64)>,
    },
}

impl Excitation {
    /// The daemon's default excitation for `n` thrusters: doublet pairs, 0.1 s, power 1.
    pub fn default_for(n: usize) -> Self {
        Self::doublets(n, 0.1, 1.0)
    }

    pub fn doublets(n: usize, pulse_s: f64, power: f64) -> Self {
        Excitation::Doublets {
            pulse_s,
            power,
            plan: ExcitationPlan::new(Plan::DoubletPairs, n),
        }
    }

    pub fn multisine(n: usize, f0_hz: f64, f_max_hz: f64, power: f64) -> Self {
        let harmonics = (f_max_hz / f0_hz).floor().max(1.0) as usize;
        let mut sines = Vec::with_capacity(n);
        for i in 0..n {
            let ks: Vec<usize> = (i + 1..=harmonics.max(i + 1)).step_by(n).collect();
            let m = ks.len() as f64;
            // Schroeder phases: a low crest factor for a flat spectrum.
            let set: Vec<(f64, f64)> = ks
                .iter()
                .enumerate()
                .map(|(j, &k)| {
                    let j = j as f64 + 1.0;
                    (k as f64 * f0_hz, -std::f64::consts::PI * j * (j - 1.0) / m)
                })
                .collect();
            // The peak over one period, found on a fine grid.
            let period = 1.0 / f0_hz;
            let steps = 4000;
            let peak = (0..steps)
                .map(|s| raw(&set, period * s as f64 / steps as f64).abs())
                .fold(0.0_f64, f64::max)
                .max(1e-9);
            sines.push((set, 1.0 / peak));
        }
        Excitation::Multisine {
            f0_hz,
            f_max_hz,
            power,
            sines,
        }
    }

    /// The command of every thruster `t_s` into the excitation, in [-1, 1].
    pub fn command(&self, t_s: f64, out: &mut [f64]) {
        match self {
            Excitation::Doublets {
                pulse_s,
                power,
                plan,
            } => {
                let k = (t_s / pulse_s + 1e-9).floor().max(0.0) as usize;
                for (o, s) in out.iter_mut().zip(plan.pattern(k)) {
                    *o = s * power;
                }
            }
            Excitation::Multisine { power, sines, .. } => {
                for (o, (set, scale)) in out.iter_mut().zip(sines) {
                    *o = power * scale * raw(set, t_s);
                }
            }
        }
        for o in out.iter_mut() {
            if *o > 0.0 {
                *o *= REVERSE_RATIO;
            }
            *o = o.clamp(-1.0, 1.0);
        }
    }

    /// A short name for tables, e.g. `doublets 0.10 s x1.00` or `multisine 0.50-6 Hz x1.00`.
    pub fn label(&self) -> String {
        match self {
            Excitation::Doublets { pulse_s, power, .. } => {
                format!("doublets {pulse_s:.3} s x{power:.2}")
            }
            Excitation::Multisine {
                f0_hz,
                f_max_hz,
                power,
                ..
            } => format!("multisine {f0_hz:.2}-{f_max_hz:.0} Hz x{power:.2}"),
        }
    }

    /// The least time a run of this excitation should last to be whole: pulses end on a
    /// multiple of four (a doublet pair returns the body near rest).
    pub fn whole(&self, t_s: f64) -> f64 {
        match self {
            Excitation::Doublets { pulse_s, .. } => {
                let pulses = (t_s / pulse_s - 1e-9).ceil().max(1.0);
                pulses * pulse_s
            }
            Excitation::Multisine { .. } => t_s,
        }
    }
}

fn raw(set: &[(f64, f64)], t_s: f64) -> f64 {
    set.iter()
        .map(|(f, phi)| (2.0 * std::f64::consts::PI * f * t_s + phi).sin())
        .sum()
}

/// The candidates the design searches, the default first.
pub fn candidates(n: usize) -> Vec<Excitation> {
    let mut out = vec![Excitation::default_for(n)];
    for pulse_s in [0.05, 0.075, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4] {
        for power in [0.5, 0.7, 0.85, 1.0] {
            if (pulse_s - 0.1_f64).abs() < 1e-9 && power == 1.0 {
                continue;
            }
            out.push(Excitation::doublets(n, pulse_s, power));
        }
    }
    for f0_hz in [0.25, 0.5, 1.0] {
        for f_max_hz in [3.0, 6.0, 10.0] {
            for power in [0.7, 1.0] {
                out.push(Excitation::multisine(n, f0_hz, f_max_hz, power));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_stay_within_the_budget() {
        for e in candidates(8) {
            let mut u = vec![0.0; 8];
            for k in 0..2000 {
                e.command(k as f64 * 0.005, &mut u);
                assert!(u.iter().all(|v| v.abs() <= 1.0), "{}", e.label());
            }
        }
    }
}
