//! Declared thruster geometry from a vehicle file (the config/vehicles/*.toml format).
//!
//! The simulator owns that format: a file is first checked by its parser (unknown keys,
//! ranges, file:line:col), so a typo such as `reversd = true`, which would announce a wrong
//! thrust sign to a running daemon, is refused instead of ignored. Then we read only what a
//! `ReconfigEvent` needs. Two conversions make the file's numbers mean what the protocol
//! says:
//! - positions in the file are from the centre of origin (CO); the protocol measures from
//!   the centre of mass, so the file's `[body] cg_m` is subtracted;
//! - a `reversed` (left-handed) thruster pushes against its `direction` for a positive
//!   command; the protocol wants the direction of positive thrust, so it is flipped.
//!
//! Directions are normalised (the format allows any non-zero length).

use std::path::Path;

use serde::Deserialize;
use thruster_protocol::validate::limits::MAX_POSITION_M;
use thruster_protocol::MAX_THRUSTERS;

/// The vehicle format's centre of gravity when `[body] cg_m` is omitted: the BlueROV2 set
/// (Wu 2018) that thruster-sim fills in. A unit test checks the two agree.
pub const DEFAULT_CG_M: [f64; 3] = [0.0, 0.0, 0.02];

/// Below this length a direction is a typo, not a direction (the simulator's rule too).
const MIN_DIRECTION_NORM: f64 = 1e-6;

/// Geometry of every thruster, protocol conventions.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// From the centre of mass, body frame, m.
    pub position: Vec<[f64; 3]>,
    /// Unit direction of the force for a positive command, body frame.
    pub direction: Vec<[f64; 3]>,
}

impl Geometry {
    pub fn count(&self) -> usize {
        self.position.len()
    }
}

/// Without `deny_unknown_fields`: the simulator's parser has refused unknown keys already
/// (`checked_text`); this reads the few the protocol needs.
#[derive(Deserialize)]
struct VehicleFile {
    #[serde(default)]
    body: BodyKeys,
    #[serde(default, rename = "thruster")]
    thrusters: Vec<ThrusterKeys>,
}

#[derive(Deserialize)]
struct BodyKeys {
    #[serde(default = "default_cg")]
    cg_m: [f64; 3],
}

impl Default for BodyKeys {
    fn default() -> Self {
        Self { cg_m: DEFAULT_CG_M }
    }
}

fn default_cg() -> [f64; 3] {
    DEFAULT_CG_M
}

#[derive(Deserialize)]
struct ThrusterKeys {
    /// For people (a layout's labels); the protocol numbers thrusters by their order.
    #[serde(default)]
    name: Option<String>,
    position_m: [f64; 3],
    direction: [f64; 3],
    #[serde(default)]
    reversed: bool,
}

/// The text of the vehicle file at `path`, once the simulator's parser, which owns the
/// format, has accepted it (every key known, every value in range; its errors say
/// file:line:col and the key).
fn checked_text(path: &Path) -> anyhow::Result<String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
    thruster_sim::Vehicle::from_toml_str(&text, &path.display().to_string())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(text)
}

/// Reads and checks the geometry in `path`; errors name the file and the thruster.
pub fn load(path: &Path) -> anyhow::Result<Geometry> {
    let text = checked_text(path)?;
    parse(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// The thrusters' names in `path`, in the protocol's order, after the same checks as [`load`]:
/// the file's `name`, or `thruster i` where it has none.
pub fn load_names(path: &Path) -> anyhow::Result<Vec<String>> {
    let text = checked_text(path)?;
    parse(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let file: VehicleFile =
        toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(file
        .thrusters
        .iter()
        .enumerate()
        .map(|(i, t)| t.name.clone().unwrap_or_else(|| format!("thruster {i}")))
        .collect())
}

/// Parses vehicle-file TOML text.
pub fn parse(text: &str) -> Result<Geometry, String> {
    let file: VehicleFile = toml::from_str(text).map_err(|e| e.to_string())?;
    if file.thrusters.is_empty() {
        return Err("no [[thruster]] tables".to_string());
    }
    if file.thrusters.len() > MAX_THRUSTERS {
        return Err(format!(
            "{} thrusters, at most {MAX_THRUSTERS} are supported",
            file.thrusters.len()
        ));
    }
    let cg = file.body.cg_m;
    if !cg.iter().all(|v| v.is_finite()) {
        return Err(format!("body.cg_m must be finite, got {cg:?}"));
    }
    let mut geometry = Geometry {
        position: Vec::with_capacity(file.thrusters.len()),
        direction: Vec::with_capacity(file.thrusters.len()),
    };
    for (i, t) in file.thrusters.iter().enumerate() {
        let position: [f64; 3] = std::array::from_fn(|k| t.position_m[k] - cg[k]);
        if !position.iter().all(|v| v.is_finite()) {
            return Err(format!("thruster[{i}].position_m must be finite"));
        }
        if position.iter().any(|v| v.abs() > MAX_POSITION_M) {
            return Err(format!(
                "thruster[{i}] sits {position:?} m from the centre of mass, \
                 more than {MAX_POSITION_M} m on an axis"
            ));
        }
        let d = t.direction;
        let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if !norm.is_finite() {
            return Err(format!("thruster[{i}].direction must be finite"));
        }
        if norm < MIN_DIRECTION_NORM {
            return Err(format!("thruster[{i}].direction must not be zero"));
        }
        let sign = if t.reversed { -1.0 } else { 1.0 };
        geometry.position.push(position);
        geometry.direction.push(d.map(|v| sign * v / norm));
    }
    Ok(geometry)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO: &str = r#"
name = "two"
description = "ignored, as are the thrust-curve keys below"

[body]
mass_kg = 12.0
cg_m = [0.0, 0.0, 0.1]

[[thruster]]
name = "A"
position_m = [0.2, 0.0, -0.15]
direction = [0.0, 0.0, -2.0]
forward_max_n = 40.0

[[thruster]]
name = "B"
position_m = [0.0, 0.2, 0.0]
direction = [1.0, 0.0, 0.0]
reversed = true
"#;

    #[test]
    fn converts_to_protocol_conventions() {
        let g = parse(TWO).unwrap();
        assert_eq!(g.count(), 2);
        // Shifted by the CG, direction normalised.
        assert_eq!(g.position[0], [0.2, 0.0, -0.25]);
        assert_eq!(g.direction[0], [0.0, 0.0, -1.0]);
        // Reversed thruster: positive thrust points the other way.
        assert_eq!(g.position[1], [0.0, 0.2, -0.1]);
        assert_eq!(g.direction[1], [-1.0, 0.0, 0.0]);
    }

    #[test]
    fn omitted_cg_takes_the_format_default() {
        let g = parse("[[thruster]]\nposition_m = [0, 0, 0]\ndirection = [1, 0, 0]\n").unwrap();
        assert_eq!(g.position[0], [0.0, 0.0, -0.02]);
    }

    #[test]
    fn errors_name_the_problem() {
        let one = |pos: &str, dir: &str| {
            parse(&format!(
                "[[thruster]]\nposition_m = {pos}\ndirection = {dir}\n"
            ))
            .unwrap_err()
        };
        assert!(one("[0, 0, 0]", "[0, 0, 0]").contains("thruster[0].direction must not be zero"));
        assert!(one("[0, 0, 0]", "[nan, 0, 1]").contains("direction must be finite"));
        assert!(one("[inf, 0, 0]", "[1, 0, 0]").contains("position_m must be finite"));
        assert!(one("[11, 0, 0]", "[1, 0, 0]").contains("more than 10 m"));
        assert!(one("[0, 0]", "[1, 0, 0]").contains("position_m"));
        let missing = parse("[[thruster]]\nposition_m = [0, 0, 0]\n").unwrap_err();
        assert!(missing.contains("missing field `direction`"), "{missing}");
        assert!(parse("name = \"x\"\n")
            .unwrap_err()
            .contains("no [[thruster]]"));
        assert!(parse("[[thruster]\n").is_err());
        let many = "[[thruster]]\nposition_m = [0, 0, 0]\ndirection = [1, 0, 0]\n".repeat(17);
        assert!(parse(&many).unwrap_err().contains("17 thrusters"));
    }

    #[test]
    fn load_names_the_file() {
        let e = load(Path::new("/nonexistent/vehicle.toml")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/vehicle.toml"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, "[[thruster]]\nposition_m = 3\n").unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.starts_with(&path.display().to_string()), "{e}");
        // A typo in a key is refused where it is, not ignored (it would announce a thruster
        // pushing the wrong way, or the centre of mass in the wrong place).
        for (typo, key, line) in [
            ("reversd = true\n", "reversd", 5),
            ("[body]\ncg = [0, 0, 0.5]\n", "cg", 6),
        ] {
            let text = format!(
                "[[thruster]]\nname = \"a\"\nposition_m = [0, 0, 0]\ndirection = [1, 0, 0]\n{typo}"
            );
            std::fs::write(&path, text).unwrap();
            let e = load(&path).unwrap_err().to_string();
            assert!(e.starts_with(&format!("{}:{line}:", path.display())), "{e}");
            assert!(e.contains(&format!("unknown field `{key}`")), "{e}");
            let e = load_names(&path).unwrap_err().to_string();
            assert!(e.contains(&format!("unknown field `{key}`")), "{e}");
        }
    }

    /// Every shipped vehicle file reads the same here as in the simulator that owns the
    /// format (CG default, CG shift, normalisation, reversed screws).
    #[test]
    fn agrees_with_the_simulator_on_shipped_vehicles() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/vehicles");
        let mut checked = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let ours = load(&path).unwrap();
            let sim = thruster_sim::Vehicle::load(&path).unwrap();
            assert_eq!(ours.count(), sim.thrusters.len(), "{}", path.display());
            for (i, t) in sim.thrusters.iter().enumerate() {
                let sign = if t.reversed { -1.0 } else { 1.0 };
                for k in 0..3 {
                    let p = t.position_m[k] - sim.body.cg_m[k];
                    assert!(
                        (ours.position[i][k] - p).abs() < 1e-12,
                        "{}",
                        path.display()
                    );
                    let d = sign * t.direction[k];
                    assert!(
                        (ours.direction[i][k] - d).abs() < 1e-12,
                        "{}",
                        path.display()
                    );
                }
            }
            checked += 1;
        }
        assert!(
            checked >= 5,
            "only {checked} vehicle files in {}",
            dir.display()
        );
        assert_eq!(thruster_sim::Body::bluerov2().cg_m, DEFAULT_CG_M);
    }
}
