//! Settings of the `thruster-sim run` process: the config file (`config/thruster-sim.toml`)
//! merged with the command line, which wins.
//!
//! Every table uses `deny_unknown_fields`, so a typo is an error with file, line and key.
//! Range checks run inside deserialisation (`deserialize_with`), so they also report the line
//! of the offending value; checks of the embedded library types (`[sim]`, sensor vectors) name
//! the key.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Deserializer};
use thruster_protocol::services::DEFAULT_ROOT_BASE;

use crate::cli::RunArgs;
use crate::load::{parse_toml, read_text, Checker, LoadError};
use crate::sensors::{ImuNoise, NoisePreset, SensorConfig, RATE_RANGE_HZ};
use crate::sim::SimOptions;

/// Default IMU sample rate of the driver, Hz.
pub const DEFAULT_RATE_HZ: f64 = 200.0;

/// Problems with the settings (one type for every driver).
pub use thruster_driver_kit::SettingsError;

/// How the sample clock runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// One sample per period of the wall clock; commands applied as they arrive.
    #[default]
    Realtime,
    /// Each sample waits for the command answering it; runs as fast as the daemon answers.
    Lockstep,
}

/// The config file, as written (all keys optional; defaults documented per key and in
/// config/thruster-sim.toml).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FileConfig {
    /// IPC namespace. No default (required here or as `--namespace`).
    pub namespace: Option<String>,
    /// Vehicle file. No default (required here or as `--vehicle`).
    pub vehicle: Option<PathBuf>,
    /// Scenario file. Default none.
    pub scenario: Option<PathBuf>,
    /// Truth JSON file. Default none.
    pub truth_file: Option<PathBuf>,
    /// Base directory of iceoryx2's files (absolute). Default "/tmp/iceoryx2/thr"; every
    /// process of a namespace must use the same one (under systemd with PrivateTmp, e.g.
    /// "/run/thrusterd").
    pub ipc_root: PathBuf,
    /// Seed of the sensor noise. Default 1.
    pub seed: u64,
    /// "realtime" (default) or "lockstep".
    pub mode: Mode,
    /// Vehicle time after which the process exits, s (> 0). Default: run until a signal.
    #[serde(deserialize_with = "de_duration_s")]
    pub duration_s: Option<f64>,
    /// `[sensors]`.
    pub sensors: SensorSettings,
    /// `[sim]`: integration rate, initial state, disturbances (library defaults).
    pub sim: SimOptions,
    /// `[lockstep]`.
    pub lockstep: LockstepSettings,
    /// `[realtime]`.
    pub realtime: RealtimeSettings,
}

impl Default for FileConfig {
    fn default() -> Self {
        FileConfig {
            namespace: None,
            vehicle: None,
            scenario: None,
            truth_file: None,
            ipc_root: PathBuf::from(DEFAULT_ROOT_BASE),
            seed: 1,
            mode: Mode::Realtime,
            duration_s: None,
            sensors: SensorSettings::default(),
            sim: SimOptions::default(),
            lockstep: LockstepSettings::default(),
            realtime: RealtimeSettings::default(),
        }
    }
}

/// `[sensors]`: like the library's [`SensorConfig`] but with the driver's default rate.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorSettings {
    /// IMU sample rate, Hz, in [100, 1000]. Default 200.
    #[serde(deserialize_with = "de_rate_hz")]
    pub rate_hz: f64,
    /// "none", "realistic" (default) or "paper".
    pub noise: NoisePreset,
    /// Replaces the preset entirely when present (all keys of the library's `ImuNoise`).
    pub custom_noise: Option<ImuNoise>,
    /// IMU position relative to the CO, body frame, m. Default [0, 0, 0].
    pub lever_arm_m: [f64; 3],
    /// Earth magnetic field in NED, uT. Default [20, 0, 45].
    pub mag_field_ned_ut: [f64; 3],
    /// `[sensors.dvl]`: a Doppler velocity log publishing on the `dvl` topic (rate_hz, default
    /// 5; std_mps, default 0.01). Absent (default): none.
    pub dvl: Option<crate::dvl::DvlConfig>,
}

impl Default for SensorSettings {
    fn default() -> Self {
        let lib = SensorConfig::default();
        SensorSettings {
            rate_hz: DEFAULT_RATE_HZ,
            noise: lib.noise,
            custom_noise: None,
            lever_arm_m: lib.lever_arm_m,
            mag_field_ned_ut: lib.mag_field_ned_ut,
            dvl: None,
        }
    }
}

impl SensorSettings {
    fn to_sensor_config(&self) -> SensorConfig {
        SensorConfig {
            rate_hz: self.rate_hz,
            noise: self.noise,
            custom_noise: self.custom_noise,
            lever_arm_m: self.lever_arm_m,
            mag_field_ned_ut: self.mag_field_ned_ut,
            dvl: self.dvl,
        }
    }
}

/// A stepped simulator's wait for each answer, wall ms (the most `timeout_ms` allows).
pub const STEPPED_TIMEOUT_MS: u64 = 600_000;

/// `[lockstep]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LockstepSettings {
    /// How long to wait for the command answering a sample, wall ms (1..=600000). Default
    /// 2000. When it passes, thrust goes neutral and the simulation continues slowly.
    #[serde(deserialize_with = "de_ms")]
    pub timeout_ms: u64,
    /// After a timeout, wait at most this long per sample until answers come back, wall ms
    /// (1..=600000). Default 100 (the vehicle then runs at 1/20 of real time at 200 Hz).
    #[serde(deserialize_with = "de_ms")]
    pub idle_period_ms: u64,
    /// Busy-poll for the answer up to this long before blocking, wall us (0..=10000).
    /// Default 50. A blocked wake-up costs tens of microseconds; polling keeps lockstep fast.
    /// Adaptive: see [`crate::driver::wait::AdaptiveSpin`].
    #[serde(deserialize_with = "de_spin_us")]
    pub spin_us: u64,
    /// Run no faster than this many times real time (0 = as fast as the daemon answers, the
    /// default; otherwise 1..=100000). Experiments that send setpoints at vehicle times use
    /// it so their timing does not depend on how fast they poll.
    #[serde(deserialize_with = "de_pace")]
    pub pace: f64,
}

impl Default for LockstepSettings {
    fn default() -> Self {
        LockstepSettings {
            timeout_ms: 2000,
            idle_period_ms: 100,
            spin_us: 50,
            pace: 0.0,
        }
    }
}

impl LockstepSettings {
    /// `timeout_ms` as a duration.
    pub fn timeout(&self) -> Duration {
        Duration::from_millis(self.timeout_ms)
    }
    /// `idle_period_ms` as a duration.
    pub fn idle_period(&self) -> Duration {
        Duration::from_millis(self.idle_period_ms)
    }
    /// `spin_us` as a duration.
    pub fn spin(&self) -> Duration {
        Duration::from_micros(self.spin_us)
    }
}

/// `[realtime]`.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RealtimeSettings {
    /// Thrust goes neutral when no valid command arrived for this long, wall ms
    /// (1..=600000). Default 200, the watchdog of a real driver.
    #[serde(deserialize_with = "de_ms")]
    pub watchdog_ms: u64,
}

impl Default for RealtimeSettings {
    fn default() -> Self {
        RealtimeSettings { watchdog_ms: 200 }
    }
}

impl RealtimeSettings {
    /// `watchdog_ms` as a duration.
    pub fn watchdog(&self) -> Duration {
        Duration::from_millis(self.watchdog_ms)
    }
}

/// Everything the driver needs, resolved and checked.
#[derive(Debug, Clone)]
pub struct Settings {
    /// IPC namespace.
    pub namespace: String,
    /// Vehicle file.
    pub vehicle: PathBuf,
    /// Scenario file, if any.
    pub scenario: Option<PathBuf>,
    /// Truth JSON file, if any.
    pub truth_file: Option<PathBuf>,
    /// Link statistics file (JSON lines, real time only), if any; command line only.
    pub stats_file: Option<PathBuf>,
    /// Base directory of iceoryx2's files.
    pub ipc_root: PathBuf,
    /// Noise seed.
    pub seed: u64,
    /// Clock mode.
    pub mode: Mode,
    /// Vehicle time limit, s.
    pub duration_s: Option<f64>,
    /// Sensors (rate and noise included).
    pub sensors: SensorConfig,
    /// Simulator options.
    pub sim: SimOptions,
    /// Lockstep tuning.
    pub lockstep: LockstepSettings,
    /// Real-time tuning.
    pub realtime: RealtimeSettings,
    /// Lockstep advanced by standard input (`--stepped`, command line only).
    pub stepped: bool,
}

impl Settings {
    /// Reads `args.config` (if given) and applies the command line over it.
    pub fn resolve(args: &RunArgs) -> Result<Settings, SettingsError> {
        let (file, base) = match &args.config {
            Some(path) => (load_file(path)?, path.parent().map(Path::to_path_buf)),
            None => (FileConfig::default(), None),
        };
        let origin = args
            .config
            .as_ref()
            .map_or_else(|| "defaults".to_string(), |p| p.display().to_string());
        Settings::merge(file, base.as_deref(), &origin, args)
    }

    /// Applies `args` over `file`. Relative paths of the file are taken relative to
    /// `base_dir` (its directory); those of the command line relative to the working
    /// directory. `origin` names the file in errors.
    pub fn merge(
        file: FileConfig,
        base_dir: Option<&Path>,
        origin: &str,
        args: &RunArgs,
    ) -> Result<Settings, SettingsError> {
        let from_file = |p: Option<PathBuf>| p.map(|p| rebase(base_dir, p));
        let namespace =
            args.namespace
                .clone()
                .or(file.namespace)
                .ok_or(SettingsError::Missing {
                    key: "namespace",
                    flag: "--namespace",
                })?;
        let vehicle = args
            .vehicle
            .clone()
            .or_else(|| from_file(file.vehicle))
            .ok_or(SettingsError::Missing {
                key: "vehicle",
                flag: "--vehicle",
            })?;
        let mut sensors = file.sensors.to_sensor_config();
        if let Some(rate) = args.rate {
            check_rate(rate).map_err(|reason| SettingsError::Argument {
                flag: "--rate",
                reason,
            })?;
            sensors.rate_hz = rate;
        }
        if let Some(noise) = args.noise {
            sensors.noise = noise;
            // A preset chosen on the command line is meant to take effect.
            sensors.custom_noise = None;
        }
        let duration_s = match args.duration {
            Some(d) => Some(check_duration(d).map_err(|reason| SettingsError::Argument {
                flag: "--duration",
                reason,
            })?),
            None => file.duration_s,
        };
        let mode = if args.lockstep {
            Mode::Lockstep
        } else if args.realtime {
            Mode::Realtime
        } else {
            file.mode
        };
        // Checked (and located) when the file was read; again here for what the command line
        // changed and for a `FileConfig` made in code.
        sensors.check(&Checker::new(origin, ""), "sensors.")?;
        file.sim.check(&Checker::new(origin, ""), "sim.")?;
        Ok(Settings {
            namespace,
            vehicle,
            scenario: args.scenario.clone().or_else(|| from_file(file.scenario)),
            truth_file: args
                .truth_file
                .clone()
                .or_else(|| from_file(file.truth_file)),
            stats_file: args.stats_file.clone(),
            ipc_root: args.ipc_root.clone().unwrap_or(file.ipc_root),
            seed: args.seed.unwrap_or(file.seed),
            mode,
            duration_s,
            sensors,
            sim: file.sim,
            lockstep: LockstepSettings {
                pace: match args.pace {
                    Some(p) => check_pace(p).map_err(|reason| SettingsError::Argument {
                        flag: "--pace",
                        reason,
                    })?,
                    None => file.lockstep.pace,
                },
                // Stepped runs are for reproducible results: a late answer is waited for.
                timeout_ms: if args.stepped {
                    file.lockstep.timeout_ms.max(STEPPED_TIMEOUT_MS)
                } else {
                    file.lockstep.timeout_ms
                },
                ..file.lockstep
            },
            realtime: file.realtime,
            stepped: args.stepped,
        })
    }

    /// IMU sample period, ns.
    pub fn sample_period_ns(&self) -> u64 {
        self.sensors.sample_period_ns()
    }

    /// `duration_s` in ns.
    pub fn duration_ns(&self) -> Option<u64> {
        self.duration_s.map(|s| (s * 1e9).round() as u64)
    }
}

/// Reads and parses a config file, and checks its `[sensors]` and `[sim]` (the simulator's
/// own types, checked after parsing: errors name file, line, column and key).
pub fn load_file(path: &Path) -> Result<FileConfig, LoadError> {
    let text = read_text(path)?;
    from_toml_str(&text, &path.display().to_string())
}

/// As [`load_file`], for the text of a file; `origin` names it in errors.
pub fn from_toml_str(text: &str, origin: &str) -> Result<FileConfig, LoadError> {
    let file: FileConfig = parse_toml(text, origin)?;
    let c = Checker::new(origin, text);
    file.sensors.to_sensor_config().check(&c, "sensors.")?;
    file.sim.check(&c, "sim.")?;
    Ok(file)
}

fn rebase(base_dir: Option<&Path>, p: PathBuf) -> PathBuf {
    match base_dir {
        Some(base) if p.is_relative() => base.join(p),
        _ => p,
    }
}

fn check_rate(rate: f64) -> Result<f64, String> {
    let (lo, hi) = RATE_RANGE_HZ;
    if rate.is_finite() && (lo..=hi).contains(&rate) {
        Ok(rate)
    } else {
        Err(format!("must be in [{lo}, {hi}] Hz, got {rate}"))
    }
}

fn check_duration(d: f64) -> Result<f64, String> {
    // Below one nanosecond the limit rounds to zero samples; above ~500 years u64 ns overflow.
    if d.is_finite() && d > 0.0 && d < 1e10 {
        Ok(d)
    } else {
        Err(format!("must be in (0, 1e10) s, got {d}"))
    }
}

// The range checks inside deserialisation say what is wrong; `parse_toml` puts the key of the
// value in front (`s.toml:2:14: lockstep.timeout_ms: must be in ...`).
fn de_rate_hz<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    check_rate(f64::deserialize(d)?).map_err(serde::de::Error::custom)
}

fn de_duration_s<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    check_duration(f64::deserialize(d)?)
        .map(Some)
        .map_err(serde::de::Error::custom)
}

fn de_ms<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
    let v = u64::deserialize(d)?;
    if (1..=600_000).contains(&v) {
        Ok(v)
    } else {
        Err(serde::de::Error::custom(format!(
            "must be in [1, 600000] ms, got {v}"
        )))
    }
}

fn de_pace<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let v = f64::deserialize(d)?;
    check_pace(v).map_err(serde::de::Error::custom)
}

/// 0 (off) or a speed-up factor in [1, 100000].
fn check_pace(v: f64) -> Result<f64, String> {
    if v == 0.0 || (1.0..=100_000.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("must be 0 or in [1, 100000], got {v}"))
    }
}

fn de_spin_us<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
    let v = u64::deserialize(d)?;
    if v <= 10_000 {
        Ok(v)
    } else {
        Err(serde::de::Error::custom(format!(
            "must be in [0, 10000] us, got {v}"
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<FileConfig, LoadError> {
        parse_toml(text, "sim.toml")
    }

    fn args() -> RunArgs {
        RunArgs::default()
    }

    #[test]
    fn empty_file_gives_documented_defaults() {
        let f = parse("").unwrap();
        assert_eq!(f.seed, 1);
        assert_eq!(f.mode, Mode::Realtime);
        assert_eq!(f.sensors.rate_hz, 200.0);
        assert_eq!(f.sensors.noise, NoisePreset::Realistic);
        assert_eq!(f.lockstep, LockstepSettings::default());
        assert_eq!(f.lockstep.timeout_ms, 2000);
        assert_eq!(f.realtime.watchdog_ms, 200);
        assert_eq!(f.sim, SimOptions::default());
    }

    #[test]
    fn pace_is_off_or_a_speed_up_of_at_least_one() {
        assert_eq!(parse("").unwrap().lockstep.pace, 0.0);
        assert_eq!(
            parse("[lockstep]\npace = 50.0\n").unwrap().lockstep.pace,
            50.0
        );
        let err = parse("[lockstep]\npace = 0.5\n").unwrap_err().to_string();
        assert!(
            err.starts_with("sim.toml:2:") && err.contains("pace"),
            "{err}"
        );
    }

    #[test]
    fn unknown_key_names_file_line_and_key() {
        let err = parse("seed = 3\n[lockstep]\ntimeout_ms = 10\nspinn_us = 3\n").unwrap_err();
        let msg = err.to_string();
        assert!(msg.starts_with("sim.toml:4:"), "{msg}");
        assert!(msg.contains("spinn_us"), "{msg}");
    }

    #[test]
    fn out_of_range_value_names_line_and_key() {
        let err = parse("\n[sensors]\nrate_hz = 5000\n").unwrap_err();
        let msg = err.to_string();
        assert!(msg.starts_with("sim.toml:3:"), "{msg}");
        assert!(msg.contains("rate_hz"), "{msg}");
        let err = parse("duration_s = -1\n").unwrap_err().to_string();
        assert!(
            err.starts_with("sim.toml:1:") && err.contains("duration_s"),
            "{err}"
        );
        let err = parse("[lockstep]\ntimeout_ms = 0\n")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("sim.toml:2:"), "{err}");
        let err = parse("mode = \"fast\"\n").unwrap_err().to_string();
        assert!(err.contains("fast"), "{err}");
    }

    #[test]
    fn command_line_overrides_file_and_paths_rebase() {
        let f = parse(
            "namespace = \"file\"\nvehicle = \"vehicles/a.toml\"\nscenario = \"/abs/s.toml\"\n\
             mode = \"lockstep\"\nseed = 5\nduration_s = 30\n[sensors]\nrate_hz = 100\n\
             noise = \"paper\"\n",
        )
        .unwrap();
        let s = Settings::merge(f.clone(), Some(Path::new("/etc/thr")), "f", &args()).unwrap();
        assert_eq!(s.namespace, "file");
        assert_eq!(s.vehicle, PathBuf::from("/etc/thr/vehicles/a.toml"));
        assert_eq!(s.scenario, Some(PathBuf::from("/abs/s.toml")));
        assert_eq!(s.mode, Mode::Lockstep);
        assert_eq!(s.seed, 5);
        assert_eq!(s.duration_ns(), Some(30_000_000_000));
        assert_eq!(s.sensors.rate_hz, 100.0);
        assert_eq!(s.sample_period_ns(), 10_000_000);

        let cli = RunArgs {
            namespace: Some("cli".into()),
            vehicle: Some("v.toml".into()),
            rate: Some(250.0),
            noise: Some(NoisePreset::None),
            seed: Some(9),
            realtime: true,
            duration: Some(2.0),
            ..args()
        };
        let s = Settings::merge(f, Some(Path::new("/etc/thr")), "f", &cli).unwrap();
        assert_eq!(s.namespace, "cli");
        assert_eq!(s.vehicle, PathBuf::from("v.toml"));
        assert_eq!(s.mode, Mode::Realtime);
        assert_eq!(s.seed, 9);
        assert_eq!(s.sensors.rate_hz, 250.0);
        assert_eq!(s.sensors.noise, NoisePreset::None);
        assert_eq!(s.duration_s, Some(2.0));
    }

    #[test]
    fn missing_and_bad_arguments_are_reported() {
        let err = Settings::merge(FileConfig::default(), None, "d", &args()).unwrap_err();
        assert!(err.to_string().contains("--namespace"), "{err}");
        let a = RunArgs {
            namespace: Some("n".into()),
            ..args()
        };
        let err = Settings::merge(FileConfig::default(), None, "d", &a).unwrap_err();
        assert!(err.to_string().contains("--vehicle"), "{err}");
        let a = RunArgs {
            namespace: Some("n".into()),
            vehicle: Some("v".into()),
            rate: Some(50.0),
            ..args()
        };
        let err = Settings::merge(FileConfig::default(), None, "d", &a).unwrap_err();
        assert!(err.to_string().starts_with("--rate"), "{err}");
    }

    #[test]
    fn shipped_config_parses_and_states_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/thruster-sim.toml");
        let f = load_file(&path).unwrap_or_else(|e| panic!("{e}"));
        let d = FileConfig::default();
        // The file sets the example keys and writes every other key with its default.
        assert_eq!(f.namespace.as_deref(), Some("thrusterd"));
        assert_eq!(f.vehicle, Some(PathBuf::from("vehicles/amour5.toml")));
        assert_eq!(
            (&f.scenario, &f.truth_file, f.duration_s),
            (&None, &None, None)
        );
        assert_eq!((f.seed, f.mode, &f.ipc_root), (d.seed, d.mode, &d.ipc_root));
        assert_eq!(f.sensors, d.sensors);
        assert_eq!(f.sim, d.sim);
        assert_eq!(f.lockstep, d.lockstep);
        assert_eq!(f.realtime, d.realtime);
        let s = Settings::merge(f, path.parent(), "shipped", &args()).unwrap();
        assert!(s.vehicle.exists(), "{}", s.vehicle.display());
    }

    #[test]
    fn bad_values_name_file_line_key_and_range() {
        let err = |text: &str| from_toml_str(text, "s.toml").unwrap_err().to_string();
        for (text, expected) in [
            // Once loaded, then "the simulation diverged at t = 0.005 s".
            (
                "[sim.initial]\nangular_radps = [1e6, 0, 0]\n",
                "s.toml:2:18: sim.initial.angular_radps[0]: must be in [-50, 50], got 1000000",
            ),
            (
                "[sim.disturbance]\ncurrent_ned_mps = [1e6, 0, 0]\n",
                "s.toml:2:20: sim.disturbance.current_ned_mps[0]: must be in [-5, 5], got 1000000",
            ),
            (
                "[[sim.disturbance.wave]]\nfrequency_hz = 0\n",
                "s.toml:2:16: sim.disturbance.wave[0].frequency_hz: must be in (0, 10], got 0",
            ),
            (
                "[sim.initial]\nposition_ned_m = [0, 0, inf]\n",
                "s.toml:2:25: sim.initial.position_ned_m[2]: must be in [-10, 11000], got inf",
            ),
            (
                "[sensors]\nlever_arm_m = [0, 0, 20]\n",
                "s.toml:2:22: sensors.lever_arm_m[2]: must be in [-10, 10], got 20",
            ),
            (
                "[sensors.custom_noise]\ngyro_std_radps = inf\n",
                "s.toml:2:18: sensors.custom_noise.gyro_std_radps: must be in [0, 50], got inf",
            ),
            (
                "[sensors.dvl]\nstd_mps = -1\n",
                "s.toml:2:11: sensors.dvl.std_mps: must be in [0, 10], got -1",
            ),
            // Range checks inside deserialisation, and wrong types, name the key too.
            (
                "[lockstep]\ntimeout_ms = 0\n",
                "s.toml:2:14: lockstep.timeout_ms: must be in [1, 600000] ms, got 0",
            ),
            (
                "[realtime]\nwatchdog_ms = 0\n",
                "s.toml:2:15: realtime.watchdog_ms: must be in [1, 600000] ms, got 0",
            ),
            (
                "[sensors]\nrate_hz = \"fast\"\n",
                "s.toml:2:11: sensors.rate_hz: invalid type: string \"fast\", expected f64",
            ),
            (
                "duration_s = -1\n",
                "s.toml:1:14: duration_s: must be in (0, 1e10) s, got -1",
            ),
        ] {
            assert_eq!(err(text), expected);
        }
    }

    #[test]
    fn embedded_sim_options_are_checked() {
        let f = parse("[sim]\nintegration_rate_hz = 10\n").unwrap();
        let a = RunArgs {
            namespace: Some("n".into()),
            vehicle: Some("v".into()),
            ..args()
        };
        let err = Settings::merge(f, None, "sim.toml", &a)
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "sim.toml: sim.integration_rate_hz: must be in [1000, 1000000], got 10"
        );
        // Read from a file, the value is located too.
        let err = from_toml_str("[sim]\nintegration_rate_hz = 10\n", "sim.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "sim.toml:2:23: sim.integration_rate_hz: must be in [1000, 1000000], got 10"
        );
        let err = parse("[sim.initial]\nposition_ned_m = [0, 0]\n")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("sim.toml:2:"), "{err}");
    }
}
