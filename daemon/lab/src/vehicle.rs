//! The lab's vehicle files, read through the simulator's one loader (`thruster_sim::Vehicle`):
//! the file the simulator runs is the file the lab counts thrusters in and declares to the
//! daemon, checked the same way.

use std::path::Path;

use anyhow::Result;
use thruster_sim::Vehicle;

/// The vehicle file at `path`, loaded and checked by the simulator (1 to the protocol's
/// `MAX_THRUSTERS` thrusters, every value in range; its errors name the file, line and key).
pub fn load(path: &Path) -> Result<Vehicle> {
    Ok(Vehicle::load(path)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn declared_geometry_is_from_the_centre_of_mass_with_reversal() {
        let text = r#"
            [[thruster]]
            name = "a"
            position_m = [0.2, 0.0, -0.15]
            direction = [0.0, 0.0, -1.0]
            [[thruster]]
            name = "b"
            position_m = [0, -0.2, 0]
            direction = [1.0, 0.0, 0.0]
            reversed = true
        "#;
        let g = Vehicle::from_toml_str(text, "test")
            .unwrap()
            .declared_geometry();
        assert_eq!(g.len(), 2);
        assert_eq!(g[0].1, [0.0, 0.0, -1.0]);
        assert!((g[0].0[2] - (-0.17)).abs() < 1e-12, "{:?}", g[0].0);
        assert_eq!(g[1].0, [0.0, -0.2, -0.02]);
        assert_eq!(g[1].1, [-1.0, 0.0, 0.0]);
        let with_cg = format!("[body]\ncg_m = [0.0, 0.0, 0.0]\n{text}");
        let v = Vehicle::from_toml_str(&with_cg, "test").unwrap();
        assert_eq!(v.declared_geometry()[0].0, [0.2, 0.0, -0.15]);
    }

    #[test]
    fn a_vehicle_without_thrusters_is_refused_with_its_count() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("none.toml");
        std::fs::write(&file, "# no [[thruster]] tables\n").unwrap();
        let e = load(&file).unwrap_err();
        let e = e.to_string();
        assert!(e.contains("must be in [1, 16], got 0"), "{e}");
        // The file named once.
        assert_eq!(e.matches("none.toml").count(), 1, "{e}");
    }
}
