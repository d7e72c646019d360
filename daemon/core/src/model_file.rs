//! The model file's format: a model as JSON text and back, every value checked. Writing and
//! reading the file itself (atomically, in the state directory) is the daemon's job
//! (thrusterd's store module): the core touches no files.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::estimator::{DofMask, Method};
use crate::model::{Model, ModelSource};

/// Identifies our files; a different value is someone else's file.
pub const FORMAT: &str = "thrusterd-model";
/// Version of the layout below; files from a newer daemon are refused, not guessed at.
pub const FORMAT_VERSION: u32 = 1;

#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: not a thrusterd model file: {why}")]
    Corrupt { path: String, why: String },
    #[error("{path}: format version {found} is newer than this daemon's {FORMAT_VERSION}")]
    Incompatible { path: String, found: u64 },
}

/// On-disk form; NaN (unknown standard error) is stored as null.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    format: String,
    format_version: u32,
    thrusters: usize,
    version: u64,
    source: ModelSource,
    method: Method,
    /// 6 rows (roll, pitch, yaw, surge, sway, heave) of `thrusters` values.
    effectiveness: Vec<Vec<f64>>,
    /// `thrusters` rows of 6 values.
    allocation: Vec<Vec<f64>>,
    std_err: Vec<Vec<Option<f64>>>,
    actuated: Vec<String>,
    rel_err_rot: Option<f64>,
    rel_err_acc: Option<f64>,
    geometry_key: Option<u64>,
    /// Vehicle time the model was made, ns (absent in files of older daemons).
    #[serde(default)]
    made_t_ns: u64,
    /// Made by an estimation (absent in older files: then taken from `source`).
    #[serde(default)]
    estimated: Option<bool>,
    /// Pulses of the estimation that made it; 0 for a nominal model (absent in older files).
    #[serde(default)]
    pulses: usize,
    /// Times the continuous refinement updated it (absent in older files: 0).
    #[serde(default)]
    refinements: u32,
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|r| m.row(r).iter().cloned().collect())
        .collect()
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// Serialise a model to the file's JSON text.
pub fn to_json(model: &Model) -> String {
    let file = ModelFile {
        format: FORMAT.into(),
        format_version: FORMAT_VERSION,
        thrusters: model.thrusters(),
        version: model.version,
        source: model.source,
        method: model.method,
        effectiveness: rows(&model.effectiveness),
        allocation: rows(&model.allocation),
        std_err: (0..model.std_err.nrows())
            .map(|r| model.std_err.row(r).iter().map(|v| finite(*v)).collect())
            .collect(),
        actuated: model
            .actuated
            .names()
            .iter()
            .map(|s| s.to_string())
            .collect(),
        rel_err_rot: finite(model.rel_err_rot),
        rel_err_acc: finite(model.rel_err_acc),
        geometry_key: model.geometry_key,
        made_t_ns: model.made_t_ns,
        estimated: Some(model.estimated),
        pulses: model.pulses,
        refinements: model.refinements,
    };
    // Plain data with string keys: serialisation cannot fail.
    serde_json::to_string_pretty(&file).unwrap_or_default()
}

fn matrix(name: &str, rows: &[Vec<f64>], r: usize, c: usize) -> Result<DMatrix<f64>, String> {
    if rows.len() != r || rows.iter().any(|row| row.len() != c) {
        return Err(format!("{name} must be {r} x {c}"));
    }
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(format!("{name} has a non-finite value"));
    }
    Ok(DMatrix::from_fn(r, c, |i, j| rows[i][j]))
}

/// Parse the file's JSON text (`origin` names it in errors).
pub fn from_json(text: &str, origin: &str) -> Result<Model, StoreError> {
    let corrupt = |why: String| StoreError::Corrupt {
        path: origin.to_string(),
        why,
    };
    // Look at the header first so a newer file is reported as such, not as garbage.
    let header: serde_json::Value =
        serde_json::from_str(text).map_err(|e| corrupt(e.to_string()))?;
    if header.get("format").and_then(|f| f.as_str()) != Some(FORMAT) {
        return Err(corrupt(format!("missing \"format\": \"{FORMAT}\"")));
    }
    // Compared as u64: a cast to u32 first made 2^32 + 1 look like version 1 (found by the
    // parser tests), reported as a type error instead of as a newer file.
    let found = match header.get("format_version") {
        Some(v) => v
            .as_u64()
            .ok_or_else(|| corrupt(format!("format_version {v} is not a version number")))?,
        None => return Err(corrupt("missing \"format_version\"".into())),
    };
    if found > u64::from(FORMAT_VERSION) {
        return Err(StoreError::Incompatible {
            path: origin.to_string(),
            found,
        });
    }
    let f: ModelFile = serde_json::from_value(header).map_err(|e| corrupt(e.to_string()))?;
    let n = f.thrusters;
    if !(1..=thruster_protocol::MAX_THRUSTERS).contains(&n) {
        return Err(corrupt(format!(
            "thrusters = {n} is not 1..{}",
            thruster_protocol::MAX_THRUSTERS
        )));
    }
    let effectiveness = matrix("effectiveness", &f.effectiveness, 6, n).map_err(corrupt)?;
    let allocation = matrix("allocation", &f.allocation, n, 6).map_err(corrupt)?;
    if f.std_err.len() != 6 || f.std_err.iter().any(|r| r.len() != n) {
        return Err(corrupt("std_err must be 6 x thrusters".into()));
    }
    let std_err = DMatrix::from_fn(6, n, |i, j| f.std_err[i][j].unwrap_or(f64::NAN));
    let mut actuated = DofMask::NONE;
    for name in &f.actuated {
        let dof = crate::estimator::Dof::ALL
            .iter()
            .find(|d| d.name() == name)
            .ok_or_else(|| corrupt(format!("unknown DOF \"{name}\" in actuated")))?;
        actuated.0[dof.index()] = true;
    }
    Ok(Model {
        version: f.version,
        source: f.source,
        method: f.method,
        effectiveness,
        allocation,
        std_err,
        actuated,
        rel_err_rot: f.rel_err_rot.unwrap_or(f64::NAN),
        rel_err_acc: f.rel_err_acc.unwrap_or(f64::NAN),
        geometry_key: f.geometry_key,
        made_t_ns: f.made_t_ns,
        estimated: f.estimated.unwrap_or(f.source != ModelSource::Nominal),
        pulses: f.pulses,
        loaded_from: Some(origin.to_string()),
        dynamics: None,
        refinements: f.refinements,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{nominal_effectiveness, RigidBody};

    fn model() -> Model {
        let pos = [[0.0, -0.2, 0.0], [0.0, 0.2, 0.0], [0.1, 0.0, -0.1]];
        let dir = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];
        let mut m = Model::nominal(
            nominal_effectiveness(&RigidBody::default(), &pos, &dir),
            Some(42),
        );
        m.version = 7;
        m.std_err[(0, 0)] = 0.01;
        m
    }

    #[test]
    fn round_trip_keeps_every_value() {
        let m = model();
        let back = from_json(&to_json(&m), "m.json").unwrap();
        assert_eq!(back.effectiveness, m.effectiveness);
        assert_eq!(back.allocation, m.allocation);
        assert_eq!(back.actuated, m.actuated);
        assert_eq!(back.version, 7);
        assert_eq!(back.geometry_key, Some(42));
        assert_eq!(back.std_err[(0, 0)], 0.01);
        assert!(back.std_err[(1, 1)].is_nan());
        assert_eq!(back.loaded_from.as_deref(), Some("m.json"));
    }

    #[test]
    fn corrupt_truncated_and_future_files_are_refused_with_reasons() {
        let text = to_json(&model());
        let e = from_json(&text[..text.len() / 2], "m.json").unwrap_err();
        assert!(
            matches!(e, StoreError::Corrupt { .. }) && e.to_string().starts_with("m.json"),
            "{e}"
        );
        let e = from_json(
            &text.replace("\"format_version\": 1", "\"format_version\": 9"),
            "m.json",
        )
        .unwrap_err();
        assert!(
            matches!(e, StoreError::Incompatible { found: 9, .. }),
            "{e}"
        );
        let e = from_json(
            &text.replace("\"format_version\": 1", "\"format_version\": 4294967297"),
            "m.json",
        )
        .unwrap_err();
        assert!(
            matches!(
                e,
                StoreError::Incompatible {
                    found: 4294967297,
                    ..
                }
            ),
            "{e}"
        );
        let e = from_json(&text.replace("thrusterd-model", "other"), "m.json").unwrap_err();
        assert!(e.to_string().contains("format"), "{e}");
        let e = from_json(
            &text.replace("\"thrusters\": 3", "\"thrusters\": 4"),
            "m.json",
        )
        .unwrap_err();
        assert!(e.to_string().contains("effectiveness must be 6 x 4"), "{e}");
        let e = from_json(&text.replacen("\"pitch\"", "\"pitchh\"", 1), "m.json");
        assert!(e.is_err());
    }
}
