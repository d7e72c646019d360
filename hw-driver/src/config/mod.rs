//! Settings of `thruster-hw run`: `config/thruster-hw.toml` merged with the command line,
//! which wins.
//!
//! Every table uses `deny_unknown_fields`; range checks run inside deserialisation so they
//! report the line; cross-field checks name the key path (`thruster[2].neutral_us`).

mod linux;
mod load;
mod mavlink;
mod ranged;
mod thruster;

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use thruster_protocol::services::DEFAULT_ROOT_BASE;
use thruster_protocol::MAX_THRUSTERS;

pub use linux::{LinuxConfig, PressureFormula};
pub use load::{parse_toml, read_text, LoadError};
pub use mavlink::{GyroSource, ImuMessage, MavlinkConfig, OutputMode, PressureMessage};
pub use thruster::{ThrusterConfig, PULSE_LIMITS_US};

use ranged::ranged;

ranged!(de_watchdog_ms, "watchdog_ms", u64, 10, 60_000, " ms");
ranged!(de_arming_ms, "arming_ms", u64, 0, 60_000, " ms");
ranged!(
    de_status_period_ms,
    "status_period_ms",
    u64,
    100,
    3_600_000,
    " ms"
);

/// Which hardware the driver talks to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BackendKind {
    /// ArduSub (or another ArduPilot) over MAVLink: `[mavlink]`.
    Mavlink,
    /// Linux sysfs PWM and IIO: `[linux]`.
    Linux,
}

impl BackendKind {
    /// The name used in the file and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Mavlink => "mavlink",
            BackendKind::Linux => "linux",
        }
    }
}

/// What the command line gives over the file (`thruster-hw run`'s options; the command line
/// itself, clap's `RunArgs`, converts into this, so the settings do not depend on the CLI).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Overrides {
    /// Config file (TOML, see config/thruster-hw.toml).
    pub config: PathBuf,
    /// IPC namespace shared with the daemon.
    pub namespace: Option<String>,
    /// Hardware backend.
    pub backend: Option<BackendKind>,
}

/// Problems with the settings (one type for every driver).
pub use thruster_driver_kit::SettingsError;

/// The config file as written. All keys but `[[thruster]]` are optional.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FileConfig {
    /// IPC namespace. No default (here or `--namespace`).
    pub namespace: Option<String>,
    /// Base directory of iceoryx2's files (absolute). Default "/tmp/iceoryx2/thr"; the same
    /// for every process of the namespace.
    pub ipc_root: PathBuf,
    /// "mavlink" or "linux". No default (here or `--backend`): real thrusters are not
    /// driven by a guess.
    pub backend: Option<BackendKind>,
    /// Outputs go neutral when no fresh valid command arrived for this long, ms
    /// (10..=60000). Default 200. A command is fresh while the IMU sample it answers is
    /// younger than this: an old command never re-arms the outputs.
    #[serde(deserialize_with = "de_watchdog_ms")]
    pub watchdog_ms: u64,
    /// Neutral is held this long after start before any command is applied, ms
    /// (0..=60000): ESCs arm on a steady neutral. Default 2000.
    #[serde(deserialize_with = "de_arming_ms")]
    pub arming_ms: u64,
    /// Period of the status line in the log, ms. Default 10000. State changes are logged
    /// at once.
    #[serde(deserialize_with = "de_status_period_ms")]
    pub status_period_ms: u64,
    /// The thrusters, in the order of the daemon's commands (1..=16). Required.
    #[serde(rename = "thruster")]
    pub thrusters: Vec<ThrusterConfig>,
    /// `[mavlink]`.
    pub mavlink: MavlinkConfig,
    /// `[linux]`.
    pub linux: LinuxConfig,
}

impl Default for FileConfig {
    fn default() -> Self {
        FileConfig {
            namespace: None,
            ipc_root: PathBuf::from(DEFAULT_ROOT_BASE),
            backend: None,
            watchdog_ms: 200,
            arming_ms: 2000,
            status_period_ms: 10_000,
            thrusters: Vec::new(),
            mavlink: MavlinkConfig::default(),
            linux: LinuxConfig::default(),
        }
    }
}

/// Everything the driver needs, resolved and checked.
#[derive(Debug, Clone)]
pub struct Settings {
    /// IPC namespace.
    pub namespace: String,
    /// Base directory of iceoryx2's files.
    pub ipc_root: PathBuf,
    /// The backend.
    pub backend: BackendKind,
    /// Watchdog, ms.
    pub watchdog_ms: u64,
    /// Neutral hold at start, ms.
    pub arming_ms: u64,
    /// Status line period, ms.
    pub status_period_ms: u64,
    /// The thrusters, in command order.
    pub thrusters: Vec<ThrusterConfig>,
    /// MAVLink settings (used with [`BackendKind::Mavlink`]).
    pub mavlink: MavlinkConfig,
    /// Linux settings (used with [`BackendKind::Linux`]).
    pub linux: LinuxConfig,
}

impl Settings {
    /// Reads `args.config` and applies the command line over it.
    pub fn resolve(args: &Overrides) -> Result<Settings, SettingsError> {
        let file = load_file(&args.config)?;
        let mut settings = Settings::merge(file, &args.config.display().to_string(), args)?;
        // Relative sysfs roots are relative to the config file (like every path in it).
        if settings.linux.sysfs_root.is_relative() {
            if let Some(dir) = args.config.parent() {
                settings.linux.sysfs_root = dir.join(&settings.linux.sysfs_root);
            }
        }
        Ok(settings)
    }

    /// Applies `args` over `file` and checks the result; `origin` names the file in errors.
    pub fn merge(
        file: FileConfig,
        origin: &str,
        args: &Overrides,
    ) -> Result<Settings, SettingsError> {
        let namespace =
            args.namespace
                .clone()
                .or(file.namespace)
                .ok_or(SettingsError::Missing {
                    key: "namespace",
                    flag: "--namespace",
                })?;
        let backend = args
            .backend
            .or(file.backend)
            .ok_or(SettingsError::Missing {
                key: "backend",
                flag: "--backend",
            })?;
        let settings = Settings {
            namespace,
            ipc_root: file.ipc_root,
            backend,
            watchdog_ms: file.watchdog_ms,
            arming_ms: file.arming_ms,
            status_period_ms: file.status_period_ms,
            thrusters: file.thrusters,
            mavlink: file.mavlink,
            linux: file.linux,
        };
        settings.validate(origin)?;
        Ok(settings)
    }

    fn validate(&self, origin: &str) -> Result<(), LoadError> {
        let n = self.thrusters.len();
        if n == 0 || n > MAX_THRUSTERS {
            return Err(LoadError::invalid(
                origin,
                "thruster",
                format!("needs 1..={MAX_THRUSTERS} [[thruster]] entries, found {n}"),
            ));
        }
        let (lo, hi) = match self.backend {
            BackendKind::Mavlink => (1, self.mavlink.max_channel()),
            BackendKind::Linux => (0, LinuxConfig::MAX_CHANNEL),
        };
        for (i, t) in self.thrusters.iter().enumerate() {
            t.validate(origin, i)?;
            if !(lo..=hi).contains(&t.channel) {
                return Err(LoadError::invalid(
                    origin,
                    format!("thruster[{i}].channel"),
                    format!(
                        "{} must be in [{lo}, {hi}] for the {} backend",
                        t.channel,
                        self.backend_label()
                    ),
                ));
            }
            if let Some(j) = self.thrusters[..i]
                .iter()
                .position(|o| o.channel == t.channel)
            {
                return Err(LoadError::invalid(
                    origin,
                    format!("thruster[{i}].channel"),
                    format!("channel {} is also used by thruster[{j}]", t.channel),
                ));
            }
        }
        if self.backend == BackendKind::Mavlink
            && self.mavlink.gyro_source == GyroSource::Attitude
            && self.mavlink.attitude_rate_hz <= 0.0
        {
            return Err(LoadError::invalid(
                origin,
                "mavlink.gyro_source",
                "\"attitude\" needs mavlink.attitude_rate_hz > 0",
            ));
        }
        Ok(())
    }

    fn backend_label(&self) -> String {
        match self.backend {
            BackendKind::Mavlink => format!("mavlink ({:?})", self.mavlink.output),
            BackendKind::Linux => "linux".to_string(),
        }
    }

    /// `watchdog_ms` as a duration.
    pub fn watchdog(&self) -> Duration {
        Duration::from_millis(self.watchdog_ms)
    }

    /// `arming_ms` as a duration.
    pub fn arming(&self) -> Duration {
        Duration::from_millis(self.arming_ms)
    }

    /// `status_period_ms` as a duration.
    pub fn status_period(&self) -> Duration {
        Duration::from_millis(self.status_period_ms)
    }
}

/// Reads and parses a config file.
pub fn load_file(path: &Path) -> Result<FileConfig, LoadError> {
    let text = read_text(path)?;
    parse_toml(&text, &path.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args() -> Overrides {
        Overrides {
            config: PathBuf::from("x.toml"),
            namespace: None,
            backend: None,
        }
    }

    const MINIMAL: &str = r#"
namespace = "veh1"
backend = "mavlink"
[[thruster]]
channel = 1
[[thruster]]
channel = 2
reversed = true
"#;

    #[test]
    fn minimal_file_resolves_with_documented_defaults() {
        let f: FileConfig = parse_toml(MINIMAL, "m.toml").unwrap();
        let s = Settings::merge(f, "m.toml", &args()).unwrap();
        assert_eq!(s.namespace, "veh1");
        assert_eq!(s.backend, BackendKind::Mavlink);
        assert_eq!((s.watchdog_ms, s.arming_ms), (200, 2000));
        assert_eq!(s.thrusters.len(), 2);
        assert!(s.thrusters[1].reversed);
        assert_eq!(s.mavlink, MavlinkConfig::default());
        assert_eq!(s.linux, LinuxConfig::default());
    }

    #[test]
    fn command_line_wins() {
        let f: FileConfig = parse_toml(MINIMAL, "m.toml").unwrap();
        let a = Overrides {
            namespace: Some("other".into()),
            backend: Some(BackendKind::Linux),
            ..args()
        };
        let s = Settings::merge(f, "m.toml", &a).unwrap();
        assert_eq!(
            (s.namespace.as_str(), s.backend),
            ("other", BackendKind::Linux)
        );
    }

    #[test]
    fn errors_name_file_line_and_key() {
        let text = "namespace = \"v\"\nbackend = \"mavlink\"\nwatchdog_ms = 0\n";
        let e = parse_toml::<FileConfig>(text, "w.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("w.toml:3:"), "{e}");
        assert!(e.contains("watchdog_ms"), "{e}");
        let text = "backend = \"mavlink\"\n[mavlink]\nresend_ms = 600\n";
        let e = parse_toml::<FileConfig>(text, "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("r.toml:3:") && e.contains("resend_ms"), "{e}");
        let text = "backend = \"mavlink\"\n[linux]\nimu_axes = [\"x\", \"x\", \"z\"]\n";
        let e = parse_toml::<FileConfig>(text, "a.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("a.toml:3:"), "{e}");
        let e = parse_toml::<FileConfig>("watchdog = 3\n", "u.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("watchdog"), "{e}");
    }

    #[test]
    fn missing_and_inconsistent_settings_are_refused() {
        let f: FileConfig = parse_toml("namespace = \"v\"\n", "f").unwrap();
        assert!(matches!(
            Settings::merge(f, "f", &args()),
            Err(SettingsError::Missing { key: "backend", .. })
        ));
        let f: FileConfig = parse_toml("namespace = \"v\"\nbackend = \"linux\"\n", "f").unwrap();
        let e = Settings::merge(f, "f", &args()).unwrap_err().to_string();
        assert!(e.contains("`thruster`"), "{e}");
        let dup = format!("{MINIMAL}[[thruster]]\nchannel = 2\n");
        let f: FileConfig = parse_toml(&dup, "d").unwrap();
        let e = Settings::merge(f, "d", &args()).unwrap_err().to_string();
        assert!(e.contains("thruster[2].channel"), "{e}");
        let rc =
            format!("{MINIMAL}[[thruster]]\nchannel = 9\n[mavlink]\noutput = \"rc_override\"\n");
        let f: FileConfig = parse_toml(&rc, "c").unwrap();
        let e = Settings::merge(f, "c", &args()).unwrap_err().to_string();
        assert!(e.contains("thruster[2].channel"), "{e}");
    }

    #[test]
    fn shipped_config_file_is_valid() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/thruster-hw.toml");
        let a = Overrides {
            config: path.clone(),
            ..args()
        };
        let s = Settings::resolve(&a).unwrap();
        // The shipped examples work together: same namespace and thruster count as
        // config/thrusterd.toml (AMOUR-5), and its IPC root (iceoryx2's default there).
        let daemon: toml::Value = toml::from_str(
            &std::fs::read_to_string(path.with_file_name("thrusterd.toml")).unwrap(),
        )
        .unwrap();
        assert_eq!(
            s.thrusters.len() as i64,
            daemon["vehicle"]["thrusters"].as_integer().unwrap()
        );
        assert_eq!(s.namespace, daemon["ipc"]["namespace"].as_str().unwrap());
        assert!(daemon["ipc"].get("root").is_none());
        assert_eq!(
            s.ipc_root,
            Path::new(thruster_protocol::services::DEFAULT_ROOT_BASE)
        );
        assert_eq!(s.mavlink.address, MavlinkConfig::default().address);
        // Both backends' sections are valid whichever is selected.
        let b = Overrides {
            backend: Some(BackendKind::Linux),
            ..a
        };
        Settings::resolve(&b).unwrap();
    }
}
