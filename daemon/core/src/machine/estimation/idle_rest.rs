//! The rest the vehicle already took while idle, kept so that an estimation asked for from
//! idle does not sit still for another `machine.noise_s` first (issue 30: the noise
//! measurement was a fixed second of every time-to-model, a fifth of it with a realistic IMU).
//!
//! While the machine is idle (thrusters neutral) every sample goes into two windows that
//! restart every `2 noise_s`, staggered by `noise_s`. Once the machine has been idle for
//! `noise_s`, one of them always covers between `noise_s` and `2 noise_s` ending at the
//! present sample: the same rest the noise measurement would take after the request, only
//! taken before it. Bounded memory (two running sums, no sample buffer), so it costs nothing
//! per sample and a checkpoint stays small.
//!
//! What makes a window stale is the machine's business: it clears them when it leaves idle
//! and when the thrusters change (the vehicle was handled; its rest must come after that).

use super::{Motion, NoiseMeter, Rest};

/// One window: since when, the noise meter and the rest (start attitude, depth trend).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
struct Window {
    since_ns: Option<u64>,
    noise: NoiseMeter,
    rest: Rest,
}

impl Window {
    fn age_s(&self, t_ns: u64) -> f64 {
        self.since_ns
            .map_or(0.0, |s| t_ns.saturating_sub(s) as f64 * 1e-9)
    }

    fn push(&mut self, t_ns: u64, m: &Motion) {
        self.since_ns.get_or_insert(t_ns);
        self.noise.push(&m.gyro.into(), &m.accel.into());
        self.rest.push(m, t_ns as f64 * 1e-9);
    }
}

/// The two staggered windows of the rest while idle.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub(in crate::machine) struct IdleRest {
    windows: [Window; 2],
}

/// A rest taken while idle, ready to stand for the noise measurement.
pub(in crate::machine) struct TakenRest {
    pub(in crate::machine) noise: NoiseMeter,
    pub(in crate::machine) rest: Rest,
    /// How long it covers, s (between `noise_s` and `2 noise_s`).
    pub(in crate::machine) span_s: f64,
}

impl IdleRest {
    /// One sample at `t_ns` while idle, the windows `noise_s` long at least.
    pub(in crate::machine) fn push(&mut self, t_ns: u64, m: &Motion, noise_s: f64) {
        let noise_s = noise_s.max(0.0);
        for w in &mut self.windows {
            if w.since_ns.is_some() && w.age_s(t_ns) >= 2.0 * noise_s {
                *w = Window::default();
            }
        }
        // The second window starts `noise_s` after the first, and the stagger then holds:
        // each restarts `2 noise_s` after it started.
        let [a, b] = &mut self.windows;
        a.push(t_ns, m);
        if b.since_ns.is_some() || a.age_s(t_ns) >= noise_s {
            b.push(t_ns, m);
        }
    }

    /// Forget the rest (the machine left idle, or the vehicle was changed).
    pub(in crate::machine) fn clear(&mut self) {
        *self = IdleRest::default();
    }

    /// The window that covers at least `noise_s` up to `t_ns` with at least `min_samples`
    /// samples (the older of the two), and the windows cleared; None when idle for less.
    pub(in crate::machine) fn take(
        &mut self,
        t_ns: u64,
        noise_s: f64,
        min_samples: u64,
    ) -> Option<TakenRest> {
        let best = self
            .windows
            .iter()
            .filter(|w| w.age_s(t_ns) >= noise_s && w.noise.samples() >= min_samples)
            .max_by(|x, y| x.age_s(t_ns).total_cmp(&y.age_s(t_ns)))?;
        let taken = TakenRest {
            noise: best.noise.clone(),
            rest: best.rest.clone(),
            span_s: best.age_s(t_ns),
        };
        self.clear();
        Some(taken)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn still(z: f64) -> Motion {
        Motion {
            gyro: Vector3::new(0.01, 0.0, 0.0),
            accel: Vector3::zeros(),
            specific_force: Vector3::new(0.0, 0.0, -9.81),
            depth: Some(z),
        }
    }

    /// 200 Hz for `seconds` from `t0_s`; returns the time of the last sample, ns.
    fn idle_for(r: &mut IdleRest, t0_s: f64, seconds: f64, noise_s: f64) -> u64 {
        let mut t = 0;
        for k in 0..(seconds * 200.0).round() as u64 {
            t = ((t0_s + k as f64 * 0.005) * 1e9).round() as u64;
            r.push(t, &still(1.0), noise_s);
        }
        t
    }

    #[test]
    fn nothing_is_taken_before_the_vehicle_rested_noise_s() {
        let mut r = IdleRest::default();
        let t = idle_for(&mut r, 10.0, 0.9, 1.0);
        assert!(r.take(t, 1.0, 10).is_none());
    }

    /// However long the machine idles, the window taken ends at the present sample and
    /// covers between noise_s and 2 noise_s: the rest stays as fresh as a measurement made
    /// after the request, never hours of drift.
    #[test]
    fn the_window_taken_covers_one_to_two_noise_s_and_ends_now() {
        for idle_s in [1.0, 1.3, 1.99, 2.0, 2.5, 3.7, 60.0] {
            let mut r = IdleRest::default();
            let t = idle_for(&mut r, 5.0, idle_s + 0.005, 1.0);
            let taken = r.take(t, 1.0, 10).expect("rested long enough");
            assert!(
                (1.0..2.0 + 1e-9).contains(&taken.span_s),
                "idle {idle_s} s: span {}",
                taken.span_s
            );
            let samples = taken.noise.samples() as f64;
            assert!(
                (samples - (taken.span_s * 200.0 + 1.0)).abs() <= 1.0,
                "idle {idle_s} s: {samples} samples over {} s",
                taken.span_s
            );
            assert!((taken.noise.levels().gyro_baseline[0] - 0.01).abs() < 1e-12);
            // Taken once: the next estimation needs a rest of its own.
            assert!(r.take(t, 1.0, 10).is_none());
        }
    }

    #[test]
    fn a_cleared_rest_starts_over() {
        let mut r = IdleRest::default();
        let t = idle_for(&mut r, 0.0, 3.0, 1.0);
        r.clear();
        assert!(r.take(t, 1.0, 10).is_none());
        let t = idle_for(&mut r, 3.0, 1.01, 1.0);
        assert!(r.take(t, 1.0, 10).is_some());
    }
}
