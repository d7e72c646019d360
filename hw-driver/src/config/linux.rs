//! `[linux]`: sysfs PWM outputs and IIO sensors.

use std::path::PathBuf;

use serde::{Deserialize, Deserializer};

use super::ranged::ranged;
use crate::core::axes::AxisMap;

ranged!(
    de_period_ns,
    "pwm_period_ns",
    u64,
    2_100_000,
    100_000_000,
    " ns"
);
ranged!(
    de_export_timeout_ms,
    "export_timeout_ms",
    u64,
    1,
    60_000,
    " ms"
);
ranged!(de_rate_hz, "rate_hz", f64, 1.0, 1000.0, " Hz");
ranged!(de_supply_channel, "supply_channel", u32, 0, 255, "");
ranged!(de_supply_gain, "supply_gain", f64, 0.001, 1000.0, "");
ranged!(
    de_density,
    "fluid_density_kg_m3",
    f64,
    900.0,
    1100.0,
    " kg/m^3"
);
ranged!(
    de_surface_kpa,
    "surface_pressure_kpa",
    f64,
    80.0,
    120.0,
    " kPa"
);

/// 4096 steps of the PCA9685's 25 MHz oscillator times (prescale 15 + 1): the default period.
pub const PCA9685_EXACT_PERIOD_NS: u64 = 2_621_440;

/// What the pressure sensor's kernel driver computes, and what the driver does about it
/// (`backend::linux::water_pressure`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PressureFormula {
    /// The driver's pressure is right as it is (a Bar02 under `ms5637`, a Keller, ...).
    #[default]
    AsReported,
    /// A Bar30 (MS5837-30BA) bound to the mainline `ms5637` driver as "ms5837": computed
    /// with the 2-bar part's formula, it reads 1/20 of the pressure; multiplied by 20.
    Bar30ReadAs02ba,
}

/// `[linux]`. Every key optional; defaults documented per key and in
/// config/thruster-hw.toml.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinuxConfig {
    /// Where sysfs is mounted. Default "/sys"; tests point it at a fake tree. A relative
    /// path is taken relative to the config file's directory.
    pub sysfs_root: PathBuf,
    /// The PWM chip N of `<root>/class/pwm/pwmchipN`. Default 0.
    pub pwm_chip: u32,
    /// PWM period, ns (2.1 ms ..= 100 ms). Default 2621440 (381.5 Hz, under the 400 Hz a Blue
    /// Robotics ESC accepts: a new pulse width reaches the ESC within 2.7 ms), a period a
    /// PCA9685 makes exactly: its 25 MHz clock / 4096 steps / (prescale 15 + 1). Older
    /// `pwm-pca9685` drivers round the prescale and scale the duty against the *requested*
    /// period (`duty = DIV_ROUND_UP(4096 * duty_ns, period_ns)`), so 2500000 (400 Hz) gave a
    /// real period of 2457600 ns and every pulse 1.7 % short: 1500 us came out 1475 us, a
    /// deadband's width off neutral (docs/hardware.md). Use 20000000 (50 Hz) for ESCs or
    /// servos that want the classic servo rate.
    #[serde(deserialize_with = "de_period_ns")]
    pub pwm_period_ns: u64,
    /// How long to wait for `pwmM/` to appear (and become writable) after `export`, ms.
    /// udev may take a moment to apply permissions. Default 2000.
    #[serde(deserialize_with = "de_export_timeout_ms")]
    pub export_timeout_ms: u64,
    /// IMU polling rate, Hz (1..=1000). Default 200. Each sample reads every channel file.
    #[serde(deserialize_with = "de_rate_hz")]
    pub rate_hz: f64,
    /// IIO device with `in_anglvel_{x,y,z}_raw`: "iio:deviceN" or the device's `name`
    /// (e.g. "icm20602"). Default "iio:device0".
    pub gyro_device: String,
    /// IIO device with `in_accel_{x,y,z}_raw`. Default: `gyro_device`.
    pub accel_device: Option<String>,
    /// IIO device with `in_magn_{x,y,z}_raw` (gauss after scale). Default: none (no
    /// magnetometer in the samples).
    pub mag_device: Option<String>,
    /// IIO device with `in_pressure_input` or `in_pressure_raw` (kPa after scale), for
    /// depth. Default: none (no depth in the samples).
    pub pressure_device: Option<String>,
    /// "as_reported" (default) or "bar30_read_as_02ba": a Bar30 (MS5837-30BA) under the
    /// mainline `ms5637` driver, which has no 30-bar formula and reads 1/20 of the pressure
    /// (docs/hardware.md). A pressure under 30 kPa is never used for depth: the driver
    /// refuses to start on one, naming this key.
    pub pressure_formula: PressureFormula,
    /// IIO device whose `in_voltage<supply_channel>` measures the thrusters' supply (an ADC
    /// behind a voltage divider, e.g. a Navigator's ADS1115): "iio:deviceN" or its name.
    /// Default: none (the supply voltage is reported unknown).
    pub supply_device: Option<String>,
    /// The ADC channel N of `in_voltageN_raw` (0..=255). Default 0.
    #[serde(deserialize_with = "de_supply_channel")]
    pub supply_channel: u32,
    /// Supply volts per volt at the ADC (the divider's ratio), in [0.001, 1000]: supply V =
    /// (in_voltageN_raw + offset) x scale / 1000 (IIO gives mV) x supply_gain. Default 1.
    #[serde(deserialize_with = "de_supply_gain")]
    pub supply_gain: f64,
    /// Body axes from sensor axes for gyro and accelerometer: body x, y, z (forward,
    /// starboard, down) are these signed sensor axes. Default ["x", "-y", "-z"]: a chip
    /// mounted face up with its x axis forward (its y points to port, z up).
    #[serde(deserialize_with = "de_axes")]
    pub imu_axes: AxisMap,
    /// As `imu_axes`, for the magnetometer. Default: `imu_axes`.
    #[serde(deserialize_with = "de_axes_opt")]
    pub mag_axes: Option<AxisMap>,
    /// Density of the water, kg/m^3. Default 997.
    #[serde(deserialize_with = "de_density")]
    pub fluid_density_kg_m3: f64,
    /// Absolute pressure at the surface, kPa. Default 101.325.
    #[serde(deserialize_with = "de_surface_kpa")]
    pub surface_pressure_kpa: f64,
}

impl Default for LinuxConfig {
    fn default() -> Self {
        LinuxConfig {
            sysfs_root: PathBuf::from("/sys"),
            pwm_chip: 0,
            pwm_period_ns: PCA9685_EXACT_PERIOD_NS,
            export_timeout_ms: 2000,
            rate_hz: 200.0,
            gyro_device: "iio:device0".to_string(),
            accel_device: None,
            mag_device: None,
            pressure_device: None,
            pressure_formula: PressureFormula::AsReported,
            supply_device: None,
            supply_channel: 0,
            supply_gain: 1.0,
            imu_axes: AxisMap::FLU_TO_FRD,
            mag_axes: None,
            fluid_density_kg_m3: 997.0,
            surface_pressure_kpa: 101.325,
        }
    }
}

impl LinuxConfig {
    /// Highest PWM index accepted as a channel (sanity bound for typos).
    pub const MAX_CHANNEL: u32 = 255;

    /// The accelerometer's device.
    pub fn accel_device(&self) -> &str {
        self.accel_device.as_deref().unwrap_or(&self.gyro_device)
    }

    /// The magnetometer's axes.
    pub fn mag_axes(&self) -> AxisMap {
        self.mag_axes.unwrap_or(self.imu_axes)
    }
}

fn de_axes<'de, D: Deserializer<'de>>(d: D) -> Result<AxisMap, D::Error> {
    let names = <[String; 3]>::deserialize(d)?;
    AxisMap::parse(&names).map_err(serde::de::Error::custom)
}

fn de_axes_opt<'de, D: Deserializer<'de>>(d: D) -> Result<Option<AxisMap>, D::Error> {
    de_axes(d).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pulse an older `pwm-pca9685` (its `.apply`: prescale rounded from the requested
    /// period, duty scaled against the requested period) puts out for `duty_ns`, ns.
    fn pca9685_pulse_ns(period_ns: u64, duty_ns: u64) -> f64 {
        const OSC_HZ: u64 = 25_000_000;
        const STEPS: u64 = 4096;
        // DIV_ROUND_CLOSEST_ULL(25 * period, 4096 * 1000) - 1
        let prescale = (25 * period_ns + STEPS * 1000 / 2) / (STEPS * 1000) - 1;
        // DIV_ROUND_UP_ULL(4096 * duty, period)
        let counts = (STEPS * duty_ns).div_ceil(period_ns);
        counts as f64 * (prescale + 1) as f64 * 1e9 / OSC_HZ as f64
    }

    #[test]
    fn the_default_period_puts_out_the_pulses_asked_for_on_a_pca9685() {
        let default = LinuxConfig::default().pwm_period_ns;
        for us in [1100, 1500, 1900] {
            let asked = us * 1000;
            let got = pca9685_pulse_ns(default, asked);
            // One step is 640 ns at prescale 15; rounding up costs less than that.
            assert!(
                (got - asked as f64).abs() < 640.0,
                "{us} us came out {got} ns"
            );
            // The old default, 400 Hz: 1.7 % short, 25 us at neutral.
            let old = pca9685_pulse_ns(2_500_000, asked);
            assert!(
                asked as f64 - old > 0.015 * asked as f64,
                "{us} us: {old} ns"
            );
        }
        assert!(
            1e9 / default as f64 <= 400.0,
            "faster than a Blue Robotics ESC takes"
        );
    }
}
