//! Whether the vehicle swayed over a long rest more than its IMU's white noise explains: the
//! water moved it (a swell, a current swinging it), or it was still.
//!
//! Why: at the paper's noise (a gyro of 0.25 rad/s white) a moderate swell is below what a
//! 1-2 s rest or the fit's unexplained rotation can see, so every rule that acts "in moving
//! water" stays shut there. Over a minute of rest it is not: the swell's 6.7 s period shows in
//! the means of 1 s bins, whose white noise is 1/sqrt(200) of a sample's. What reads it: the
//! Allan variance at one bin, the mean square of adjacent bins' difference, against what the
//! white noise alone gives it, sigma^2 (1/n_k + 1/n_k+1), with sigma^2 from the same over
//! 0.1 s bins (a swell or a slow drift hardly moves the next tenth of a second, and a walking
//! bias hardly moves the next second). Why tenths and not single samples: a real IMU's
//! readings are low-passed before they are sampled (ArduPilot's gyro filter is 20 Hz by
//! default), so adjacent samples share their noise and their differences understate it;
//! a tenth of a second is many such correlation times. Still water reads 1 (its scatter about
//! sqrt(2 / bins) over the axes summed); the swell adds its motion. For the gyro and the
//! specific force each; the larger ratio is the reading. Running sums, no buffer, no
//! allocation.

use nalgebra::Vector3;

/// The long bins, s: many samples' worth of white noise averaged away, a small part of a
/// swell's period.
const BIN_S: f64 = 1.0;

/// The short bins that measure the white noise, s: long against a sensor filter's
/// correlation (a 20 Hz low-pass: 8 ms), short against a swell.
const NOISE_BIN_S: f64 = 0.1;

/// Fewest adjacent long-bin pairs for a reading (their ratio's scatter is about sqrt(2 / (3
/// pairs)): 0.15 at 30).
const MIN_PAIRS: u64 = 30;

/// The least white noise a sample is taken to have, gyro (rad/s) and specific force (m/s^2):
/// half a realistic MEMS IMU's. Why: noise-free (the simulator's), a vehicle settling by a
/// micro-radian would otherwise read as swaying without bound.
const MIN_GYRO_SIGMA: f64 = 1e-3;
const MIN_FORCE_SIGMA: f64 = 1.5e-2;

/// Means of consecutive bins `span_s` long, and the squared differences of adjacent ones.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
struct Bins {
    start_s: Option<f64>,
    sum: Vector3<f64>,
    n: u64,
    last: Option<(Vector3<f64>, u64)>,
    d2: f64,
    /// The sum over pairs of (1/n_k + 1/n_k+1): what multiplies sigma^2 (per axis, per
    /// sample) in the white noise's share of `d2`.
    weight: f64,
    pairs: u64,
}

impl Bins {
    fn push(&mut self, span_s: f64, t_s: f64, v: &Vector3<f64>) {
        let start = *self.start_s.get_or_insert(t_s);
        if t_s - start >= span_s && self.n > 0 {
            let mean = self.sum / self.n as f64;
            if let Some((last, last_n)) = self.last {
                self.d2 += (mean - last).norm_squared();
                self.weight += 1.0 / self.n as f64 + 1.0 / last_n as f64;
                self.pairs += 1;
            }
            self.last = Some((mean, self.n));
            self.sum = Vector3::zeros();
            self.n = 0;
            self.start_s = Some(t_s);
        }
        self.sum += v;
        self.n += 1;
    }

    /// sigma^2 summed over the axes if the bins' differences were white noise alone.
    fn white_sigma2(&self) -> Option<f64> {
        (self.weight > 0.0).then(|| self.d2 / self.weight)
    }
}

/// One quantity's long and short bins.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
struct Allan {
    long: Bins,
    short: Bins,
}

impl Allan {
    fn push(&mut self, t_s: f64, v: &Vector3<f64>) {
        self.long.push(BIN_S, t_s, v);
        self.short.push(NOISE_BIN_S, t_s, v);
    }

    /// The long bins' mean square difference over the white noise's share of it (the noise
    /// from the short bins, taken as no less than `min_sigma` a sample per axis).
    fn ratio(&self, min_sigma: f64) -> Option<f64> {
        if self.long.pairs < MIN_PAIRS {
            return None;
        }
        let sigma2 = self.short.white_sigma2()?.max(3.0 * min_sigma * min_sigma);
        Some(self.long.d2 / (sigma2 * self.long.weight))
    }
}

/// What a long rest's sway says of the water, against a limit (`machine.max_still_sway`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum RestWater {
    /// It swayed no more than the limit times what the IMU's white noise explains.
    Still,
    /// It swayed more: a swell, a vehicle swinging on a tether.
    Moved,
}

impl RestWater {
    /// What `sway` (a `LongRestSway::ratio`) says against `max_still`; None when the limit is
    /// 0 (the reading not used) or not finite.
    pub fn read(sway: f64, max_still: f64) -> Option<Self> {
        if !(max_still > 0.0 && max_still.is_finite()) {
            return None;
        }
        Some(if sway <= max_still {
            RestWater::Still
        } else {
            RestWater::Moved
        })
    }

    /// The operator's word for it.
    pub fn text(self) -> &'static str {
        match self {
            RestWater::Still => "still water",
            RestWater::Moved => "the water moved",
        }
    }
}

/// The sway over a rest, for the gyro (rad/s) and the specific force (m/s^2).
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct LongRestSway {
    gyro: Allan,
    force: Allan,
}

impl LongRestSway {
    /// One sample at `t_s`. A non-finite sample is skipped.
    pub fn push(&mut self, t_s: f64, gyro: &Vector3<f64>, specific_force: &Vector3<f64>) {
        let finite = t_s.is_finite()
            && gyro.iter().all(|v| v.is_finite())
            && specific_force.iter().all(|v| v.is_finite());
        if !finite {
            return;
        }
        self.gyro.push(t_s, gyro);
        self.force.push(t_s, specific_force);
    }

    /// How much more the vehicle moved from second to second than the white noise explains
    /// (1: still), the larger of the gyro's and the specific force's; None before
    /// `MIN_PAIRS` pairs of long bins.
    pub fn ratio(&self) -> Option<f64> {
        Some(
            self.gyro
                .ratio(MIN_GYRO_SIGMA)?
                .max(self.force.ratio(MIN_FORCE_SIGMA)?),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: f64 = 9.80665;
    const DT: f64 = 0.005;

    /// Deterministic white noise (xorshift, Box-Muller): the tests need no random crate.
    struct Noise(u64);
    impl Noise {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u, v) = (self.uniform().max(1e-300), self.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
        fn vec(&mut self, sd: f64) -> Vector3<f64> {
            Vector3::new(self.normal(), self.normal(), self.normal()) * sd
        }
    }

    /// A rest of `span_s` at the paper's noise (gyro 0.25 rad/s, accelerometer 0.49 m/s^2),
    /// rocking `roll_rad` at a 6.7 s period, with a bias walking `walk` rad/s/sqrt(s).
    fn rest(span_s: f64, roll_rad: f64, walk: f64, seed: u64) -> Option<f64> {
        let (mut s, mut noise, mut bias) = (LongRestSway::default(), Noise(seed), Vector3::zeros());
        let w = std::f64::consts::TAU / 6.7;
        for k in 0..(span_s / DT) as usize {
            let t = k as f64 * DT;
            let roll = roll_rad * (w * t).sin();
            let rate = Vector3::new(roll_rad * w * (w * t).cos(), 0.0, 0.0);
            let force = Vector3::new(0.0, G * roll.sin(), -G * roll.cos());
            bias += noise.vec(walk * DT.sqrt());
            s.push(
                t,
                &(rate + bias + noise.vec(0.25)),
                &(force + noise.vec(0.05 * G)),
            );
        }
        s.ratio()
    }

    #[test]
    fn still_water_reads_about_one_at_any_seed() {
        for seed in 1..=10 {
            let r = rest(60.0, 0.0, 0.0, seed).unwrap();
            assert!((0.6..1.5).contains(&r), "seed {seed}: {r:.3}");
        }
    }

    /// A realistic gyro's walk (5e-5 rad/s/sqrt(s)) is a bin-to-bin difference far below the
    /// paper's white noise: still.
    #[test]
    fn a_walking_bias_is_not_sway() {
        let r = rest(60.0, 0.0, 5e-5, 3).unwrap();
        assert!(r < 1.5, "{r:.3}");
    }

    /// Rocking 0.03 rad (under two degrees) at the swell's period stands out of the paper's
    /// noise over a minute.
    #[test]
    fn two_degrees_of_swell_is_sway() {
        for seed in 1..=5 {
            let r = rest(60.0, 0.03, 0.0, seed).unwrap();
            assert!(r > 2.0, "seed {seed}: {r:.3}");
        }
    }

    /// The noise low-passed before sampling (a first-order 20 Hz filter at 200 Hz, as
    /// ArduPilot's gyro filter): adjacent samples share it, but tenths of a second do not, so
    /// still water still reads about one (adjacent samples' differences read about 7 there:
    /// (1 + a) / (1 - a)^2 with the filter's a = 0.53).
    #[test]
    fn a_low_passed_imu_in_still_water_reads_about_one() {
        let alpha = 1.0 - (-std::f64::consts::TAU * 20.0 * DT).exp();
        for seed in 1..=5 {
            let (mut s, mut noise) = (LongRestSway::default(), Noise(seed));
            let (mut g, mut f) = (Vector3::zeros(), Vector3::zeros());
            for k in 0..(60.0 / DT) as usize {
                g += (noise.vec(0.25) - g) * alpha;
                f += (noise.vec(0.05 * G) - f) * alpha;
                s.push(k as f64 * DT, &g, &(Vector3::new(0.0, 0.0, -G) + f));
            }
            let r = s.ratio().unwrap();
            assert!((0.6..1.5).contains(&r), "seed {seed}: {r:.3}");
        }
    }

    /// What the MAVLink driver hands on from ArduSub (SCALED_IMU2 at 100 Hz, rounded to
    /// 1 mrad/s and 1 mG, through a 20 Hz filter) of a quiet IMU (0.5 mrad/s, 5 mm/s^2 white,
    /// below the rounding) in still water: still. The rounding's error is as white as the
    /// noise it rounds (0.92-1.29 on these seeds without the noise floor, `MIN_GYRO_SIGMA`).
    #[test]
    fn an_ardusub_stream_of_a_quiet_imu_in_still_water_reads_still() {
        let dt = 0.01;
        let alpha = 1.0 - (-std::f64::consts::TAU * 20.0 * dt).exp();
        let round = |v: Vector3<f64>, step: f64| v.map(|x| (x / step).round() * step);
        for seed in 1..=5 {
            let (mut s, mut noise) = (LongRestSway::default(), Noise(seed));
            let (mut g, mut f) = (Vector3::zeros(), Vector3::zeros());
            // A gyro bias of a few mrad/s, so the rounding is not centred on zero.
            let bias = Vector3::new(0.0031, -0.0017, 0.0006);
            for k in 0..(60.0 / dt) as usize {
                g += (noise.vec(5e-4) - g) * alpha;
                f += (noise.vec(5e-3) - f) * alpha;
                let force = Vector3::new(0.01, -0.02, -G) + f;
                s.push(
                    k as f64 * dt,
                    &round(g + bias, 1e-3),
                    &round(force, 1e-3 * G),
                );
            }
            let r = s.ratio().unwrap();
            assert!(r < 1.5, "seed {seed}: {r:.3}");
        }
    }

    #[test]
    fn the_water_is_read_against_the_limit_and_not_at_all_at_zero() {
        assert_eq!(RestWater::read(1.2, 1.5), Some(RestWater::Still));
        assert_eq!(RestWater::read(1.5, 1.5), Some(RestWater::Still));
        assert_eq!(RestWater::read(9.9, 1.5), Some(RestWater::Moved));
        assert_eq!(RestWater::read(1.2, 0.0), None);
        assert_eq!(RestWater::read(1.2, f64::NAN), None);
    }

    #[test]
    fn too_short_a_rest_reads_nothing() {
        assert!(rest(20.0, 0.3, 0.0, 1).is_none());
    }

    /// Noise-free: still reads 0, a settling by micro-radians below 1, a swell far above it.
    #[test]
    fn noise_free_still_and_moving() {
        let mut still = LongRestSway::default();
        let (mut settling, mut rocking) = (LongRestSway::default(), LongRestSway::default());
        for k in 0..(60.0 / DT) as usize {
            let t = k as f64 * DT;
            let f = Vector3::new(0.0, 0.0, -G);
            still.push(t, &Vector3::zeros(), &f);
            let creep = Vector3::new(1e-5 * (-t / 5.0).exp(), 0.0, 0.0);
            settling.push(t, &creep, &f);
            let w = std::f64::consts::TAU / 6.7;
            let rate = Vector3::new(0.05 * w * (w * t).cos(), 0.0, 0.0);
            rocking.push(t, &rate, &f);
        }
        assert!(still.ratio().unwrap() < 1e-9);
        assert!(settling.ratio().unwrap() < 0.1);
        assert!(rocking.ratio().unwrap() > 100.0);
    }
}
