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
//!
//! A second pair of windows, `machine.gyro_bias_rest_s` long (a minute), keeps how the gyro
//! turned gravity and the magnetic field over a long idle spell (`long_rest_bias`): the
//! gyro's bias from it, not from the 1-2 s rest. Why: in a swell (a 6.7 s period) a 1-2 s
//! rest takes the swell's rotation for bias (0.04-0.19 rad/s, docs/study.md "What breaks the
//! acceleration rows in a strong swell"), and the navigation integrates it into a tilted
//! gravity all through the run. Over a minute the swell's acceleration averages out of the
//! directions, and a MEMS gyro's bias hardly moves. With them, "down" averaged over the last
//! third of that minute and carried by the gyro (`long_rest_down`). The run uses them only
//! when the short rest's bias disagrees (`estimation::long_rest_bias`).

use nalgebra::Vector3;

use super::{Motion, NoiseMeter, Rest};
use crate::navigation::long_rest_bias::{LongRestBias, RestBias};
use crate::navigation::long_rest_down::LongRestDown;
use crate::navigation::long_rest_sway::LongRestSway;

/// One window: since when, the noise meter and the rest (start attitude, depth trend).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
struct Window {
    since_ns: Option<u64>,
    noise: NoiseMeter,
    rest: Rest,
}

impl Window {
    fn push(&mut self, t_ns: u64, m: &Motion) {
        self.since_ns.get_or_insert(t_ns);
        self.noise.push(&m.gyro.into(), &m.accel.into());
        self.rest.push(m, t_ns as f64 * 1e-9);
    }
}

/// One long window for the gyro's bias: since when, and what the gyro did to the
/// directions the accelerometer and magnetometer measure.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
struct BiasWindow {
    since_ns: Option<u64>,
    rest: LongRestBias,
    /// How much it swayed beyond the IMU's white noise (`long_rest_sway`).
    sway: LongRestSway,
}

impl BiasWindow {
    fn push(&mut self, t_ns: u64, m: &Motion) {
        self.since_ns.get_or_insert(t_ns);
        let t_s = t_ns as f64 * 1e-9;
        self.rest
            .push(t_s, &m.gyro, &m.specific_force, m.mag.as_ref());
        self.sway.push(t_s, &m.gyro, &m.specific_force);
    }
}

/// Something a pair of staggered windows is made of.
trait Spell: Default {
    fn since_ns(&self) -> Option<u64>;
    fn add(&mut self, t_ns: u64, m: &Motion);
    fn age_s(&self, t_ns: u64) -> f64 {
        self.since_ns()
            .map_or(0.0, |s| t_ns.saturating_sub(s) as f64 * 1e-9)
    }
}

impl Spell for Window {
    fn since_ns(&self) -> Option<u64> {
        self.since_ns
    }
    fn add(&mut self, t_ns: u64, m: &Motion) {
        self.push(t_ns, m);
    }
}

impl Spell for BiasWindow {
    fn since_ns(&self) -> Option<u64> {
        self.since_ns
    }
    fn add(&mut self, t_ns: u64, m: &Motion) {
        self.push(t_ns, m);
    }
}

/// One sample at `t_ns` into two windows that restart every `2 span_s`, the second started
/// `span_s` after the first: once idle for `span_s`, one of them covers between `span_s` and
/// `2 span_s` ending at this sample.
fn stagger<W: Spell>(windows: &mut [W; 2], t_ns: u64, m: &Motion, span_s: f64) {
    let span_s = span_s.max(0.0);
    for w in windows.iter_mut() {
        if w.since_ns().is_some() && w.age_s(t_ns) >= 2.0 * span_s {
            *w = W::default();
        }
    }
    let [a, b] = windows;
    a.add(t_ns, m);
    if b.since_ns().is_some() || a.age_s(t_ns) >= span_s {
        b.add(t_ns, m);
    }
}

/// The two staggered windows of the rest while idle, and the two long ones of the gyro's
/// bias.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub(in crate::machine) struct IdleRest {
    windows: [Window; 2],
    bias: [BiasWindow; 2],
    /// "Down" averaged over the last `bias_s / DOWN_TAU_SHARE`, carried by the gyro net of
    /// `bias_now` (`long_rest_down`): where the navigation starts from after a long rest.
    down: Option<LongRestDown>,
    /// The long windows' latest bias, refreshed every `BIAS_REFRESH_S`, and when.
    bias_now: Vector3<f64>,
    bias_refreshed_ns: Option<u64>,
}

/// The long "down"'s forgetting time is the bias window's over this (60 s: 20 s, three
/// periods of the presets' swell).
const DOWN_TAU_SHARE: f64 = 3.0;

/// How often the bias that carries "down" is refreshed from the long windows, s.
const BIAS_REFRESH_S: f64 = 1.0;

/// A rest taken while idle, ready to stand for the noise measurement.
pub(in crate::machine) struct TakenRest {
    pub(in crate::machine) noise: NoiseMeter,
    pub(in crate::machine) rest: Rest,
    /// How long it covers, s (between `noise_s` and `2 noise_s`).
    pub(in crate::machine) span_s: f64,
    /// The gyro's bias over the long window, when the machine idled `gyro_bias_rest_s`
    /// (and that is not 0).
    pub(in crate::machine) gyro_bias: Option<RestBias>,
    /// With it, the long average of "down" (`long_rest_down`), to be carried on through the
    /// noise measurement.
    pub(in crate::machine) down: Option<LongRestDown>,
    /// With it, how much the vehicle swayed over the long window beyond the IMU's white noise
    /// (`long_rest_sway`; 1: still).
    pub(in crate::machine) sway: Option<f64>,
}

impl IdleRest {
    /// One sample at `t_ns` while idle, the windows `noise_s` long at least, the bias's
    /// `bias_s` (0: none kept).
    pub(in crate::machine) fn push(&mut self, t_ns: u64, m: &Motion, noise_s: f64, bias_s: f64) {
        stagger(&mut self.windows, t_ns, m, noise_s);
        if bias_s > 0.0 {
            stagger(&mut self.bias, t_ns, m, bias_s);
            let due = self
                .bias_refreshed_ns
                .is_none_or(|t| t_ns.saturating_sub(t) as f64 * 1e-9 >= BIAS_REFRESH_S);
            if due {
                // The older window's, once it has one (a gyro net of nothing before).
                if let Some(b) = self.oldest_bias(t_ns, 0.0) {
                    self.bias_now = b.bias;
                }
                self.bias_refreshed_ns = Some(t_ns);
            }
            let down = self
                .down
                .get_or_insert_with(|| LongRestDown::new(bias_s / DOWN_TAU_SHARE));
            down.push(
                t_ns as f64 * 1e-9,
                &(m.gyro - self.bias_now),
                &m.specific_force,
            );
        }
    }

    /// The older long window that covers at least `bias_s`.
    fn oldest(&self, t_ns: u64, bias_s: f64) -> Option<&BiasWindow> {
        self.bias
            .iter()
            .filter(|w| w.age_s(t_ns) >= bias_s)
            .max_by(|x, y| x.age_s(t_ns).total_cmp(&y.age_s(t_ns)))
    }

    /// The bias of the older long window that covers at least `bias_s` and has one.
    fn oldest_bias(&self, t_ns: u64, bias_s: f64) -> Option<RestBias> {
        self.oldest(t_ns, bias_s).and_then(|w| w.rest.bias())
    }

    /// Forget the rest (the machine left idle, or the vehicle was changed).
    pub(in crate::machine) fn clear(&mut self) {
        *self = IdleRest::default();
    }

    /// The window that covers at least `noise_s` up to `t_ns` with at least `min_samples`
    /// samples (the older of the two), with the bias over the long window that covers at
    /// least `bias_s` (if one does), and the windows cleared; None when idle for less than
    /// `noise_s`.
    pub(in crate::machine) fn take(
        &mut self,
        t_ns: u64,
        noise_s: f64,
        bias_s: f64,
        min_samples: u64,
    ) -> Option<TakenRest> {
        let best = self
            .windows
            .iter()
            .filter(|w| w.age_s(t_ns) >= noise_s && w.noise.samples() >= min_samples)
            .max_by(|x, y| x.age_s(t_ns).total_cmp(&y.age_s(t_ns)))?;
        let gyro_bias = (bias_s > 0.0)
            .then(|| self.oldest_bias(t_ns, bias_s))
            .flatten();
        let sway = gyro_bias
            .and(self.oldest(t_ns, bias_s))
            .and_then(|w| w.sway.ratio());
        let taken = TakenRest {
            noise: best.noise.clone(),
            rest: best.rest.clone(),
            span_s: best.age_s(t_ns),
            gyro_bias,
            down: gyro_bias.and(self.down.clone()),
            sway,
        };
        self.clear();
        Some(taken)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn still(z: f64) -> Motion {
        Motion {
            gyro: Vector3::new(0.01, 0.0, 0.0),
            accel: Vector3::zeros(),
            specific_force: Vector3::new(0.0, 0.0, -9.81),
            depth: Some(z),
            mag: None,
        }
    }

    /// 200 Hz for `seconds` from `t0_s`; returns the time of the last sample, ns.
    fn idle_for(r: &mut IdleRest, t0_s: f64, seconds: f64, noise_s: f64) -> u64 {
        let mut t = 0;
        for k in 0..(seconds * 200.0).round() as u64 {
            t = ((t0_s + k as f64 * 0.005) * 1e9).round() as u64;
            r.push(t, &still(1.0), noise_s, 0.0);
        }
        t
    }

    #[test]
    fn nothing_is_taken_before_the_vehicle_rested_noise_s() {
        let mut r = IdleRest::default();
        let t = idle_for(&mut r, 10.0, 0.9, 1.0);
        assert!(r.take(t, 1.0, 0.0, 10).is_none());
    }

    /// However long the machine idles, the window taken ends at the present sample and
    /// covers between noise_s and 2 noise_s: the rest stays as fresh as a measurement made
    /// after the request, never hours of drift.
    #[test]
    fn the_window_taken_covers_one_to_two_noise_s_and_ends_now() {
        for idle_s in [1.0, 1.3, 1.99, 2.0, 2.5, 3.7, 60.0] {
            let mut r = IdleRest::default();
            let t = idle_for(&mut r, 5.0, idle_s + 0.005, 1.0);
            let taken = r.take(t, 1.0, 0.0, 10).expect("rested long enough");
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
            assert!(r.take(t, 1.0, 0.0, 10).is_none());
        }
    }

    /// The bias's long window: none before the machine idled `bias_s` or with it 0; after,
    /// the bias of a still gyro (0.01 rad/s about x) on every axis, the field giving the part
    /// about gravity, and "down" with it.
    #[test]
    fn the_long_window_gives_the_bias_after_bias_s() {
        let with_field = |z| Motion {
            mag: Some(Vector3::new(20.0, 3.0, 45.0)),
            ..still(z)
        };
        let mut r = IdleRest::default();
        let mut t = 0;
        for k in 0..(59.0 * 200.0) as u64 {
            t = 1_000_000_000 + k * 5_000_000;
            r.push(t, &with_field(1.0), 1.0, 30.0);
        }
        let taken = r.take(t, 1.0, 30.0, 10).unwrap();
        let bias = taken.gyro_bias.expect("idled 59 s, a window of 30");
        assert!(bias.about_down_seen);
        assert!(
            (bias.bias - Vector3::new(0.01, 0.0, 0.0)).norm() < 1e-6,
            "{}",
            bias.bias
        );
        let down = taken
            .down
            .and_then(|d| d.down())
            .expect("down with the bias");
        // Within a mrad: its first 5 s were carried by a gyro net of no bias yet, forgotten
        // since.
        assert!((down - Vector3::z()).norm() < 1e-3, "{down}");
        // 29 s is not enough for a window of 30; a window of 0 is none.
        for (seconds, bias_s) in [(29.0, 30.0), (59.0, 0.0)] {
            let mut r = IdleRest::default();
            for k in 0..(seconds * 200.0) as u64 {
                t = 1_000_000_000 + k * 5_000_000;
                r.push(t, &with_field(1.0), 1.0, bias_s);
            }
            let taken = r.take(t, 1.0, bias_s, 10).unwrap();
            assert!(
                taken.gyro_bias.is_none() && taken.down.is_none(),
                "{seconds} s, {bias_s}"
            );
        }
    }

    #[test]
    fn a_cleared_rest_starts_over() {
        let mut r = IdleRest::default();
        let t = idle_for(&mut r, 0.0, 3.0, 1.0);
        r.clear();
        assert!(r.take(t, 1.0, 0.0, 10).is_none());
        let t = idle_for(&mut r, 3.0, 1.01, 1.0);
        assert!(r.take(t, 1.0, 0.0, 10).is_some());
    }
}
