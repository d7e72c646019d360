//! The vehicle as it is (issue 32): where its IMU sits and what water it is in, for a lab
//! run's simulator. The daemon is told neither: what it learns is judged against a vehicle it
//! does not know, as in a pool or the sea.
//!
//! The presets are the simulator's ([`thruster_sim::disturbance::WaterPreset`]), each a
//! `[sim.disturbance]`, recorded in the JSON.
//!
//! `--tether N` adds a cable pulling N newtons aft (world -x) at the stern (0.3 m behind the
//! CO), varying by 30 % over 20 s; `--water-file` replaces the preset with any
//! `[disturbance]` table the simulator takes (current, waves, tether).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use thruster_sim::disturbance::TetherConfig;
use thruster_sim::DisturbanceConfig;

pub use thruster_sim::disturbance::WaterPreset as Water;

/// The options every lab run takes for the vehicle's IMU and water.
#[derive(Args, Debug, Clone, Default)]
pub struct WaterArgs {
    /// The simulator's IMU position from the vehicle's CO, body frame (x forward, y starboard,
    /// z down), m, as "X,Y,Z" (the daemon is not told; default: at the CO).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_xyz, allow_hyphen_values = true)]
    pub imu_position: Option<[f64; 3]>,
    /// Water: still, current (0.3 m/s), moderate (0.3 m/s and a 10 N / 1 N m swell at
    /// 0.15 Hz) or rough (0.5 m/s, 20 N / 2 N m).
    #[arg(long, value_enum, default_value_t = Water::Still)]
    pub water: Water,
    /// A TOML file with a `[disturbance]` table (current_ned_mps, [[disturbance.wave]],
    /// [disturbance.tether]) used instead of the --water preset.
    #[arg(long, value_name = "FILE.toml")]
    pub water_file: Option<PathBuf>,
    /// A tether pulling this many newtons aft at the stern, varying by 30 % over 20 s.
    #[arg(long, value_name = "N", value_parser = parse_tether, allow_hyphen_values = true)]
    pub tether: Option<f64>,
}

/// Most a `--tether` may pull, N.
const MAX_TETHER_N: f64 = 1000.0;

/// `--tether`: checked where it is given (exit 2), as the other flags.
fn parse_tether(s: &str) -> Result<f64, String> {
    crate::flags::within(s, MAX_TETHER_N, "N")
}

fn parse_xyz(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e} (want X,Y,Z in metres)"))?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite() && c.abs() <= 10.0) => Ok([*x, *y, *z]),
        _ => Err(format!(
            "{s:?}: want three finite numbers X,Y,Z within +-10 m"
        )),
    }
}

/// A `[disturbance]` file's contents.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct WaterFile {
    disturbance: DisturbanceConfig,
}

impl WaterArgs {
    /// The disturbance the simulator gets: the file's, or the preset's, with the tether.
    pub fn disturbance(&self) -> Result<DisturbanceConfig> {
        let mut d = match &self.water_file {
            Some(path) => read_water_file(path)?,
            None => self.water.disturbance(),
        };
        if let Some(pull) = self.tether {
            // Also for runs built in code, which no flag parser saw.
            anyhow::ensure!(
                (0.0..=MAX_TETHER_N).contains(&pull),
                "--tether must be within 0..={MAX_TETHER_N} N, got {pull}"
            );
            d.tether = Some(TetherConfig {
                attach_m: [-0.3, 0.0, 0.0],
                pull_ned_n: [-pull, 0.0, 0.0],
                vary_ned_n: [-0.3 * pull, 0.0, 0.0],
                period_s: 20.0,
            });
        }
        Ok(d)
    }

    /// Whether the run's vehicle differs from the idealised one (IMU at the CO, still water).
    pub fn is_default(&self) -> bool {
        self.imu_position.is_none()
            && self.water == Water::Still
            && self.water_file.is_none()
            && self.tether.is_none()
    }

    /// The simulator's config file text for these options (its `[sensors] lever_arm_m` and
    /// `[sim.disturbance]`); None when the defaults hold.
    pub fn sim_config(&self) -> Result<Option<String>> {
        if self.is_default() {
            return Ok(None);
        }
        let mut root = toml::Table::new();
        let arm = self.imu_position.unwrap_or([0.0; 3]);
        let mut sensors = toml::Table::new();
        sensors.insert(
            "lever_arm_m".into(),
            toml::Value::Array(arm.iter().map(|v| toml::Value::Float(*v)).collect()),
        );
        root.insert("sensors".into(), toml::Value::Table(sensors));
        let disturbance = toml::Value::try_from(self.disturbance()?)
            .context("writing the disturbance as TOML")?;
        let mut sim = toml::Table::new();
        sim.insert("disturbance".into(), disturbance);
        root.insert("sim".into(), toml::Value::Table(sim));
        Ok(Some(
            toml::to_string(&root).context("writing the simulator's config")?,
        ))
    }

    /// What the run's JSON records of the vehicle and the water.
    pub fn json(&self) -> Result<serde_json::Value> {
        Ok(serde_json::json!({
            "imu_position_true_m": self.imu_position.unwrap_or([0.0; 3]),
            "water": self.water_file.as_ref().map_or(self.water.name().to_string(), |p| p.display().to_string()),
            "disturbance": serde_json::to_value(self.disturbance()?)?,
        }))
    }
}

fn read_water_file(path: &Path) -> Result<DisturbanceConfig> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let file: WaterFile =
        toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    file.disturbance
        .validate(&path.display().to_string())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(file.disturbance)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_parse_and_bad_ones_are_named() {
        assert_eq!(parse_xyz("0.15,0.05,-0.1").unwrap(), [0.15, 0.05, -0.1]);
        let e = parse_xyz("0.1,0.2").unwrap_err();
        assert!(e.contains("three finite numbers"), "{e}");
        let e = parse_xyz("0.1,x,0").unwrap_err();
        assert!(e.contains("\"0.1,x,0\""), "{e}");
        assert!(parse_xyz("0,0,20").is_err());
    }

    #[test]
    fn the_simulator_reads_what_the_options_write() {
        let args = WaterArgs {
            imu_position: Some([0.15, 0.05, -0.1]),
            water: Water::Moderate,
            tether: Some(10.0),
            ..WaterArgs::default()
        };
        let text = args.sim_config().unwrap().unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sim.toml");
        std::fs::write(&path, &text).unwrap();
        let cfg = thruster_sim::settings::load_file(&path).unwrap();
        assert_eq!(cfg.sensors.lever_arm_m, [0.15, 0.05, -0.1]);
        let d = &cfg.sim.disturbance;
        assert_eq!(d.current_ned_mps, [0.3, 0.0, 0.0]);
        assert_eq!(d.waves.len(), 1);
        assert!((d.waves[0].force_ned_n[0] - 10.0 / 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(d.tether.as_ref().unwrap().pull_ned_n, [-10.0, 0.0, 0.0]);
        assert!(WaterArgs::default().sim_config().unwrap().is_none());
    }

    #[test]
    fn a_water_file_with_a_typo_is_refused_with_its_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("water.toml");
        std::fs::write(&path, "[disturbance]\ncurrent_ned_mp = [0.1, 0.0, 0.0]\n").unwrap();
        let args = WaterArgs {
            water_file: Some(path),
            ..WaterArgs::default()
        };
        let e = args.disturbance().unwrap_err().to_string();
        assert!(
            e.contains("water.toml") && e.contains("current_ned_mp"),
            "{e}"
        );
    }
}
