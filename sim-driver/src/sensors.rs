//! IMU (gyro, accelerometer, magnetometer) and depth sensor models with white noise and bias
//! random walk, from a seeded RNG so runs are reproducible.
//!
//! Each reading is `truth + bias + white`, white ~ N(0, std) independently per axis and per
//! sample (std is per sample, whatever the rate: the paper states its noise that way). Biases
//! start at N(0, bias_init_std) and walk: `b += N(0, bias_walk * sqrt(dt))` between samples.

use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use thruster_protocol::ImuReading;

use thruster_protocol::validate::limits::{
    MAX_ACCEL_M_S2, MAX_GYRO_RAD_S, MAX_MAG_UT, MAX_POSITION_M,
};

use crate::load::{symmetric, Checker, LoadError, Range};

/// Standard gravity used to express the paper's accelerometer noise (0.05 g), m/s^2.
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// Lowest and highest supported output rate, Hz.
pub const RATE_RANGE_HZ: (f64, f64) = (100.0, 1000.0);

/// Named noise levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoisePreset {
    /// Perfect sensors: readings equal the truth.
    None,
    /// MEMS-grade IMU and a Bar30-class depth sensor, with turn-on bias and bias drift.
    Realistic,
    /// The paper's levels: 0.25 rad/s gyro and 0.05 g accelerometer white noise, which stand
    /// for the vehicle's own disturbances as much as sensor noise; no bias.
    Paper,
}

/// Noise parameters. Standard deviations are per sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuNoise {
    /// Gyro white noise, rad/s.
    pub gyro_std_radps: f64,
    /// Accelerometer white noise, m/s^2.
    pub accel_std_mps2: f64,
    /// Magnetometer white noise, uT.
    pub mag_std_ut: f64,
    /// Depth white noise, m.
    pub depth_std_m: f64,
    /// Gyro bias random walk, rad/s per sqrt(s).
    pub gyro_bias_walk: f64,
    /// Accelerometer bias random walk, m/s^2 per sqrt(s).
    pub accel_bias_walk: f64,
    /// Magnetometer bias random walk, uT per sqrt(s).
    pub mag_bias_walk: f64,
    /// Gyro turn-on bias std, rad/s.
    pub gyro_bias_init_std: f64,
    /// Accelerometer turn-on bias std, m/s^2.
    pub accel_bias_init_std: f64,
    /// Magnetometer turn-on bias (hard iron residue) std, uT.
    pub mag_bias_init_std: f64,
}

impl Default for ImuNoise {
    fn default() -> Self {
        NoisePreset::None.params()
    }
}

impl NoisePreset {
    /// The preset's parameters (documented in docs/simulation.md).
    pub fn params(self) -> ImuNoise {
        let zero = ImuNoise {
            gyro_std_radps: 0.0,
            accel_std_mps2: 0.0,
            mag_std_ut: 0.0,
            depth_std_m: 0.0,
            gyro_bias_walk: 0.0,
            accel_bias_walk: 0.0,
            mag_bias_walk: 0.0,
            gyro_bias_init_std: 0.0,
            accel_bias_init_std: 0.0,
            mag_bias_init_std: 0.0,
        };
        match self {
            NoisePreset::None => zero,
            NoisePreset::Realistic => ImuNoise {
                gyro_std_radps: 0.002,
                accel_std_mps2: 0.03,
                mag_std_ut: 0.4,
                depth_std_m: 0.003,
                gyro_bias_walk: 5e-5,
                accel_bias_walk: 5e-4,
                mag_bias_walk: 0.01,
                gyro_bias_init_std: 0.005,
                accel_bias_init_std: 0.05,
                mag_bias_init_std: 0.5,
            },
            NoisePreset::Paper => ImuNoise {
                gyro_std_radps: 0.25,
                accel_std_mps2: 0.05 * STANDARD_GRAVITY,
                // The paper gives no magnetometer or depth figures; use the realistic ones.
                mag_std_ut: 0.4,
                depth_std_m: 0.003,
                ..zero
            },
        }
    }
}

impl ImuNoise {
    /// Each level within the full scale of its sensor in the protocol (a gyro's 50 rad/s,
    /// an accelerometer's 200 m/s^2, a magnetometer's 5000 uT) and depth noise within 100 m.
    fn check(&self, c: &Checker, prefix: &str) -> Result<(), LoadError> {
        let all = [
            ("gyro_std_radps", self.gyro_std_radps, MAX_GYRO_RAD_S),
            ("accel_std_mps2", self.accel_std_mps2, MAX_ACCEL_M_S2),
            ("mag_std_ut", self.mag_std_ut, MAX_MAG_UT),
            ("depth_std_m", self.depth_std_m, 100.0),
            ("gyro_bias_walk", self.gyro_bias_walk, MAX_GYRO_RAD_S),
            ("accel_bias_walk", self.accel_bias_walk, MAX_ACCEL_M_S2),
            ("mag_bias_walk", self.mag_bias_walk, MAX_MAG_UT),
            (
                "gyro_bias_init_std",
                self.gyro_bias_init_std,
                MAX_GYRO_RAD_S,
            ),
            (
                "accel_bias_init_std",
                self.accel_bias_init_std,
                MAX_ACCEL_M_S2,
            ),
            ("mag_bias_init_std", self.mag_bias_init_std, MAX_MAG_UT),
        ];
        for (key, v, max) in all {
            c.range(
                &format!("{prefix}custom_noise.{key}"),
                v,
                Range::closed(0.0, max),
            )?;
        }
        Ok(())
    }
}

fn default_rate_hz() -> f64 {
    100.0
}

/// Sensor settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorConfig {
    /// Output rate, Hz, in [100, 1000]. Default 100.
    pub rate_hz: f64,
    /// Noise preset: "none", "realistic" (default) or "paper".
    pub noise: NoisePreset,
    /// Replaces the preset entirely when present.
    pub custom_noise: Option<ImuNoise>,
    /// IMU position relative to the CO, body frame, m. Default [0, 0, 0].
    pub lever_arm_m: [f64; 3],
    /// Earth magnetic field in NED, uT. Default [20, 0, 45] (mid-latitude, northern hemisphere).
    pub mag_field_ned_ut: [f64; 3],
    /// A Doppler velocity log, when the vehicle has one (default: none).
    pub dvl: Option<crate::dvl::DvlConfig>,
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            rate_hz: default_rate_hz(),
            noise: NoisePreset::Realistic,
            custom_noise: None,
            lever_arm_m: [0.0; 3],
            mag_field_ned_ut: [20.0, 0.0, 45.0],
            dvl: None,
        }
    }
}

impl SensorConfig {
    /// Perfect sensors at `rate_hz`, IMU at the CO.
    pub fn ideal(rate_hz: f64) -> Self {
        SensorConfig {
            rate_hz,
            noise: NoisePreset::None,
            ..SensorConfig::default()
        }
    }

    /// The noise parameters in effect.
    pub fn noise_params(&self) -> ImuNoise {
        self.custom_noise.unwrap_or_else(|| self.noise.params())
    }

    /// Output period, ns (rounded).
    pub fn sample_period_ns(&self) -> u64 {
        (1e9 / self.rate_hz).round() as u64
    }

    /// Checks ranges; `origin` names the source in errors.
    pub fn validate(&self, origin: &str) -> Result<(), LoadError> {
        self.check(&Checker::new(origin, ""), "")
    }

    /// Checks ranges, locating a bad value in `c.text`; `prefix` is the path of these keys
    /// (`"sensors."` in thruster-sim's config file). The IMU sits within the protocol's
    /// `MAX_POSITION_M` of the centre, the field within a magnetometer's full scale.
    pub(crate) fn check(&self, c: &Checker, prefix: &str) -> Result<(), LoadError> {
        let (lo, hi) = RATE_RANGE_HZ;
        c.range(
            &format!("{prefix}rate_hz"),
            self.rate_hz,
            Range::closed(lo, hi),
        )?;
        c.each(
            &format!("{prefix}lever_arm_m"),
            &self.lever_arm_m,
            symmetric(MAX_POSITION_M),
        )?;
        c.each(
            &format!("{prefix}mag_field_ned_ut"),
            &self.mag_field_ned_ut,
            symmetric(MAX_MAG_UT),
        )?;
        if let Some(n) = &self.custom_noise {
            n.check(c, prefix)?;
        }
        if let Some(d) = &self.dvl {
            d.check(c, prefix)?;
        }
        Ok(())
    }
}

/// The true motion the sensors observe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorTruth {
    /// Attitude, body-to-NED.
    pub attitude: UnitQuaternion<f64>,
    /// Angular velocity, body, rad/s.
    pub omega: Vector3<f64>,
    /// Angular acceleration, body, rad/s^2.
    pub alpha: Vector3<f64>,
    /// Inertial acceleration of the CO expressed in the body frame (`v_dot + omega x v`), m/s^2.
    pub accel_co: Vector3<f64>,
    /// Depth of the CO, m.
    pub depth_m: f64,
    /// Gravitational acceleration, m/s^2.
    pub gravity_mps2: f64,
}

/// Specific force at a point `lever_arm` (m, body) from the CO, body frame, m/s^2:
/// `a_co + alpha x r + omega x (omega x r) - R^T [0, 0, g]`.
pub fn specific_force(truth: &SensorTruth, lever_arm: &Vector3<f64>) -> Vector3<f64> {
    let a = truth.accel_co
        + truth.alpha.cross(lever_arm)
        + truth.omega.cross(&truth.omega.cross(lever_arm));
    let g_body =
        truth
            .attitude
            .inverse_transform_vector(&Vector3::new(0.0, 0.0, truth.gravity_mps2));
    a - g_body
}

/// Current sensor biases (truth, for scoring).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorBiases {
    /// rad/s.
    pub gyro: Vector3<f64>,
    /// m/s^2.
    pub accel: Vector3<f64>,
    /// uT.
    pub mag: Vector3<f64>,
}

/// The sensor suite with its noise state.
#[derive(Debug, Clone)]
pub struct Imu {
    config: SensorConfig,
    noise: ImuNoise,
    rng: ChaCha8Rng,
    biases: SensorBiases,
    last_t_ns: Option<u64>,
}

/// RNG stream of the sensors, distinct from any other use of the same seed.
const SENSOR_STREAM: u64 = 1;

impl Imu {
    /// Sensors with noise drawn from `seed`. `config` must be validated.
    pub fn new(config: SensorConfig, seed: u64) -> Self {
        let noise = config.noise_params();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(SENSOR_STREAM);
        let mut draw3 = |std: f64| {
            Vector3::new(
                normal(&mut rng, std),
                normal(&mut rng, std),
                normal(&mut rng, std),
            )
        };
        let biases = SensorBiases {
            gyro: draw3(noise.gyro_bias_init_std),
            accel: draw3(noise.accel_bias_init_std),
            mag: draw3(noise.mag_bias_init_std),
        };
        Imu {
            config,
            noise,
            rng,
            biases,
            last_t_ns: None,
        }
    }

    /// Settings.
    pub fn config(&self) -> &SensorConfig {
        &self.config
    }

    /// Current biases.
    pub fn biases(&self) -> &SensorBiases {
        &self.biases
    }

    /// Noise-free reading of `truth`. Every channel is present (the simulated vehicle has a
    /// magnetometer and a depth sensor); `seq` is 0: the driver numbers what it publishes.
    pub fn ideal(&self, t_ns: u64, truth: &SensorTruth) -> ImuReading {
        let f = specific_force(truth, &Vector3::from(self.config.lever_arm_m));
        let mag = truth
            .attitude
            .inverse_transform_vector(&Vector3::from(self.config.mag_field_ned_ut));
        ImuReading {
            seq: 0,
            t_ns,
            gyro: truth.omega.into(),
            accel: f.into(),
            mag: Some(mag.into()),
            depth: Some(truth.depth_m),
        }
    }

    /// A noisy reading of `truth` at `t_ns`; walks the biases by the time since the last one.
    pub fn measure(&mut self, t_ns: u64, truth: &SensorTruth) -> ImuReading {
        let dt = self
            .last_t_ns
            .map_or(0.0, |last| t_ns.saturating_sub(last) as f64 * 1e-9);
        self.last_t_ns = Some(t_ns);
        let sq = dt.sqrt();
        let n = self.noise;
        let walk = |rng: &mut ChaCha8Rng, b: &mut Vector3<f64>, rate: f64| {
            for i in 0..3 {
                b[i] += normal(rng, rate * sq);
            }
        };
        walk(&mut self.rng, &mut self.biases.gyro, n.gyro_bias_walk);
        walk(&mut self.rng, &mut self.biases.accel, n.accel_bias_walk);
        walk(&mut self.rng, &mut self.biases.mag, n.mag_bias_walk);
        let ideal = self.ideal(t_ns, truth);
        let rng = &mut self.rng;
        let noisy = |rng: &mut ChaCha8Rng, v: [f64; 3], b: &Vector3<f64>, std: f64| {
            let mut out = v;
            for i in 0..3 {
                out[i] += b[i] + normal(rng, std);
            }
            out
        };
        // Fields in this order: the noise is drawn gyro, accel, mag, depth (a seed's stream).
        ImuReading {
            seq: 0,
            t_ns,
            gyro: noisy(rng, ideal.gyro, &self.biases.gyro, n.gyro_std_radps),
            accel: noisy(rng, ideal.accel, &self.biases.accel, n.accel_std_mps2),
            mag: ideal
                .mag
                .map(|m| noisy(rng, m, &self.biases.mag, n.mag_std_ut)),
            depth: ideal.depth.map(|d| d + normal(rng, n.depth_std_m)),
        }
    }
}

/// N(0, std); draws nothing when std is 0 so noise-free runs do not consume the stream.
fn normal(rng: &mut ChaCha8Rng, std: f64) -> f64 {
    if std > 0.0 {
        let z: f64 = rng.sample(StandardNormal);
        z * std
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn still(attitude: UnitQuaternion<f64>) -> SensorTruth {
        SensorTruth {
            attitude,
            omega: Vector3::zeros(),
            alpha: Vector3::zeros(),
            accel_co: Vector3::zeros(),
            depth_m: 3.0,
            gravity_mps2: 9.81,
        }
    }

    #[test]
    fn level_at_rest_reads_minus_g_on_z() {
        let f = specific_force(&still(UnitQuaternion::identity()), &Vector3::zeros());
        assert!((f - Vector3::new(0.0, 0.0, -9.81)).norm() < 1e-12);
    }

    #[test]
    fn pitched_up_reads_gravity_on_x() {
        // Nose up by 90 degrees: body x points up, and at rest the accelerometer reads the
        // upward support force, +g along body x.
        let q = UnitQuaternion::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0);
        let f = specific_force(&still(q), &Vector3::zeros());
        assert!((f - Vector3::new(9.81, 0.0, 0.0)).norm() < 1e-9, "{f}");
    }

    #[test]
    fn lever_arm_adds_centripetal_and_tangential() {
        let mut t = still(UnitQuaternion::identity());
        t.omega = Vector3::new(0.0, 0.0, 2.0);
        t.alpha = Vector3::new(0.0, 0.0, 1.0);
        let r = Vector3::new(0.5, 0.0, 0.0);
        let f = specific_force(&t, &r);
        // omega x (omega x r) = -4 * 0.5 x; alpha x r = 0.5 y.
        assert!((f - Vector3::new(-2.0, 0.5, -9.81)).norm() < 1e-12, "{f}");
    }

    #[test]
    fn magnetometer_rotates_with_heading() {
        let imu = Imu::new(SensorConfig::ideal(100.0), 0);
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let r = imu.ideal(0, &still(q));
        // Facing east, north is to port (-y).
        let mag = r.mag.expect("the simulator has a magnetometer");
        assert!((mag[0]).abs() < 1e-9 && (mag[1] + 20.0).abs() < 1e-9);
        assert!((mag[2] - 45.0).abs() < 1e-9);
    }

    #[test]
    fn config_rejects_out_of_range_rate() {
        let mut c = SensorConfig::default();
        c.validate("s").expect("default valid");
        c.rate_hz = 50.0;
        assert!(c.validate("s").is_err());
        c.rate_hz = 1000.0;
        c.validate("s").expect("1 kHz valid");
    }
}
