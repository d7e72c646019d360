//! The daemon's config file and the command-line overrides `run` and `replay` share: the core
//! parses text, this edge reads the file.

use std::path::Path;

use anyhow::Result;
use thruster_protocol::MAX_THRUSTERS;
use thrusterd_core::config::DaemonConfig;

/// Reads and checks the config file at `path` (errors name the file, line and key).
pub fn load(path: &Path) -> Result<DaemonConfig> {
    let text = thruster_driver_kit::read_text(path)?;
    Ok(DaemonConfig::from_toml_str(
        &text,
        &path.display().to_string(),
    )?)
}

/// `--thrusters N`: that many thrusters, the file's declared geometry dropped.
pub fn set_thrusters(cfg: &mut DaemonConfig, n: usize) -> Result<()> {
    anyhow::ensure!(
        (1..=MAX_THRUSTERS).contains(&n),
        "--thrusters {n}: must be 1..{MAX_THRUSTERS}"
    );
    cfg.vehicle.thrusters = n;
    cfg.vehicle.thruster.clear();
    Ok(())
}
