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
    /// PWM period, ns (2.1 ms ..= 100 ms). Default 2500000 (400 Hz, the fastest a Blue
    /// Robotics ESC accepts: a new pulse width reaches the ESC within 2.5 ms). Use 20000000
    /// (50 Hz) for ESCs or servos that want the classic servo rate.
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
            pwm_period_ns: 2_500_000,
            export_timeout_ms: 2000,
            rate_hz: 200.0,
            gyro_device: "iio:device0".to_string(),
            accel_device: None,
            mag_device: None,
            pressure_device: None,
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
