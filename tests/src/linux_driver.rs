//! thruster-hw's config for the tests that run it on its Linux backend over the hardware
//! driver's fake sysfs tree (`hw-driver/tests/common/fake_sysfs.rs`, included by path).

use std::path::Path;

/// The config: `channels` one thruster each, the shipped 200 ms watchdog, a 200 ms arming
/// hold, a status every `status_period_ms`; the fake tree's IMU, magnetometer and pressure
/// devices at `sysfs_root`, its water's `density` (kg/m^3) and `surface_kpa`.
pub fn config(
    namespace: &str,
    channels: &[u32],
    status_period_ms: u64,
    sysfs_root: &Path,
    density: f64,
    surface_kpa: f64,
) -> String {
    let mut cfg = format!(
        "namespace = \"{namespace}\"\nbackend = \"linux\"\nwatchdog_ms = 200\narming_ms = 200\n\
         status_period_ms = {status_period_ms}\n"
    );
    for ch in channels {
        cfg += &format!("[[thruster]]\nchannel = {ch}\n");
    }
    cfg += &format!(
        "[linux]\nsysfs_root = \"{}\"\nrate_hz = 200.0\ngyro_device = \"icm20602\"\n\
         mag_device = \"ak09916\"\npressure_device = \"ms5837\"\n\
         fluid_density_kg_m3 = {density}\nsurface_pressure_kpa = {surface_kpa}\n",
        sysfs_root.display(),
    );
    cfg
}

/// thruster-hw run with `cfg` (written to the world's `thruster-hw.toml`), left running.
pub fn spawn(world: &crate::World, cfg: &str) -> crate::Proc {
    let path = world.path("thruster-hw.toml");
    std::fs::write(&path, cfg).expect("thruster-hw.toml written");
    crate::Proc::spawn(
        "thruster-hw",
        &["run", "--config", path.to_str().expect("a UTF-8 path")],
        world.dir.path(),
    )
}
