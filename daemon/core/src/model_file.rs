//! The model file's format: a model as JSON text and back, every value checked. Writing and
//! reading the file itself (atomically, in the state directory) is the daemon's job
//! (thrusterd's store module): the core touches no files.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::estimator::dynamic::{stored_terms, DynamicTerms};
use crate::estimator::{DofMask, Method};
use crate::model::{Model, ModelSource};

/// Identifies our files; a different value is someone else's file.
pub const FORMAT: &str = "thrusterd-model";
/// Version of the layout below; files from a newer daemon are refused, not guessed at.
/// 2 added `dynamics` (version 1 files, without it, are read as before); 3 added
/// `dynamics.command_exponent` (a learned thrust curve the model's B is per unit of: a daemon
/// before it would fly such a model on the commands unbent, so it must refuse the file).
pub const FORMAT_VERSION: u32 = 3;

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
    /// The dynamic method's other terms: the learned lags, the thrust's shape, the IMU's
    /// position, damping and restoring. Without them a loaded model is flown, refined and
    /// change-tested with the configured lag and no shape (see `stored_terms` for what that
    /// did). Absent in version 1 files, in other methods' models, and when a value was not
    /// finite (JSON cannot hold it).
    #[serde(default)]
    dynamics: Option<DynamicTerms>,
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
    let dynamics = model
        .dynamics
        .as_ref()
        .map(with_finite_errors)
        .filter(|d| storable(d, model.thrusters()));
    // The lowest version that holds what the file says: a model without a learned curve
    // stays readable by the daemons before it.
    let format_version = if dynamics
        .as_ref()
        .is_some_and(|d| d.command_exponent.is_some())
    {
        FORMAT_VERSION
    } else {
        2
    };
    let file = ModelFile {
        format: FORMAT.into(),
        format_version,
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
        dynamics,
    };
    // Plain data with string keys: serialisation cannot fail.
    serde_json::to_string_pretty(&file).unwrap_or_default()
}

/// `terms` with `f` applied to every standard error (of the terms, and B's least-squares ones).
fn map_std_errors(mut t: DynamicTerms, f: impl Fn(f64) -> f64) -> DynamicTerms {
    for m in [&mut t.std_err, &mut t.ols_std_err, &mut t.b_ols_std_err] {
        m.iter_mut().for_each(|v| *v = f(*v));
    }
    t
}

/// `terms` with every non-finite standard error (a term the run never excited has an infinite
/// one) as `f64::MAX`: "nothing known" in a number JSON can hold; [`with_unknown_errors`]
/// turns it back on loading.
fn with_finite_errors(terms: &DynamicTerms) -> DynamicTerms {
    map_std_errors(terms.clone(), |v| if v.is_finite() { v } else { f64::MAX })
}

/// The inverse of [`with_finite_errors`]: `f64::MAX` standard errors infinite again.
fn with_unknown_errors(t: DynamicTerms) -> DynamicTerms {
    map_std_errors(t, |v| if v == f64::MAX { f64::INFINITY } else { v })
}

/// Whether `terms` come back from the file as they are: a non-finite value would be written
/// as null and make the whole file unreadable, and terms out of bounds would be refused on
/// loading; either way the model is better saved without them.
fn storable(terms: &DynamicTerms, thrusters: usize) -> bool {
    stored_terms::check(terms, thrusters).is_ok()
        && serde_json::to_value(terms)
            .and_then(serde_json::from_value::<DynamicTerms>)
            .is_ok_and(|back| back == *terms)
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
    if let Some(d) = &f.dynamics {
        stored_terms::check(d, n).map_err(|e| corrupt(e.to_string()))?;
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
        dynamics: f.dynamics.map(with_unknown_errors),
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

    /// Terms as a learned model has them: lags, the shape, the IMU's position, a term the
    /// run never excited (infinite standard error).
    fn terms(n: usize) -> DynamicTerms {
        use crate::estimator::dynamic::imu_position::ImuPosition;
        use crate::estimator::dynamic::regressors::TERMS;
        let mut std_err = DMatrix::from_fn(6, TERMS, |r, c| 0.01 + (r * TERMS + c) as f64 * 1e-4);
        std_err[(4, 20)] = f64::INFINITY;
        DynamicTerms {
            coefficients: DMatrix::from_fn(6, TERMS, |r, c| (r as f64 - 2.5) * 0.3 + c as f64),
            std_err: std_err.clone(),
            ols_std_err: std_err,
            b_ols_std_err: DMatrix::from_element(6, n, 0.002),
            max_tilt_rad: 0.3,
            max_heading_change_rad: 0.2,
            spin_up_s: 0.19,
            spin_up_learned: true,
            spin_up_sd_ln: 0.01,
            spin_up_rel_err: [0.004, 0.006],
            spin_up_per_thruster_s: vec![0.1, 0.12, 0.11],
            thruster_lag_evidence: 3.5,
            spin_up_groups: None,
            spin_up_floor_rel_err: [0.0; 2],
            lag_check: None,
            thrust_curve: None,
            command_exponent: Some(1.5),
            curve_named_rel_err: [0.3, 0.4],
            thrust_asymmetry: 0.22 / 1.78,
            prior_disagreement: [0.5, 0.7],
            navigation_rel_err: [0.0; 2],
            start_velocity_ned_mps: None,
            velocity_drift_ned_mps2: None,
            imu_position: Some(ImuPosition {
                position_m: nalgebra::Vector3::new(0.15, 0.05, -0.1),
                cov: nalgebra::Matrix3::identity() * 1e-6,
                learned: None,
                contradicted: false,
                rel_err_share: 0.0,
            }),
            unexplained_rate_radps: 0.001,
            lag_gap_without_states: None,
            instrumented: [true, false],
        }
    }

    /// Without the terms a loaded model flew with the configured lag and no thrust shape
    /// (`stored_terms`): every one comes back, the never-excited term's infinite error too.
    #[test]
    fn the_dynamic_terms_come_back_exactly() {
        let mut m = model();
        m.dynamics = Some(terms(3));
        let text = to_json(&m);
        // With a learned curve, the version that has it; without, the one before.
        assert!(text.contains("\"format_version\": 3"), "{text}");
        let mut unbent = m.clone();
        unbent.dynamics.as_mut().unwrap().command_exponent = None;
        assert!(to_json(&unbent).contains("\"format_version\": 2"));
        let back = from_json(&text, "m.json").unwrap();
        assert_eq!(back.dynamics, m.dynamics);
        assert_eq!(back.learned_spin_up_s(), Some(0.19));
        assert_eq!(back.learned_thruster_lags(), Some(&[0.1, 0.12, 0.11][..]));
        assert_eq!(back.dynamics.unwrap().std_err[(4, 20)], f64::INFINITY);
    }

    /// A version 1 file (no terms) loads as before; terms the daemon could not write back
    /// (a NaN) are left out rather than making the whole file unreadable.
    #[test]
    fn older_files_load_and_unwritable_terms_are_left_out() {
        let mut m = model();
        m.dynamics = Some(terms(3));
        let v1: serde_json::Value = {
            let mut v: serde_json::Value = serde_json::from_str(&to_json(&m)).unwrap();
            let o = v.as_object_mut().unwrap();
            o.remove("dynamics");
            o.insert("format_version".into(), 1.into());
            v
        };
        let back = from_json(&v1.to_string(), "old.json").unwrap();
        assert_eq!(back.dynamics, None);
        assert_eq!(back.effectiveness, m.effectiveness);
        m.dynamics.as_mut().unwrap().coefficients[(0, 0)] = f64::NAN;
        let back = from_json(&to_json(&m), "m.json").unwrap();
        assert_eq!(back.dynamics, None);
        assert_eq!(back.effectiveness, m.effectiveness);
    }

    /// Terms from a file pass the bounds the estimator's own keep, and a refusal names the key
    /// and the range.
    #[test]
    fn out_of_bounds_terms_are_refused_naming_the_key() {
        let mut m = model();
        m.dynamics = Some(terms(3));
        let text = to_json(&m);
        for (from, to, key) in [
            (
                "\"spin_up_s\": 0.19",
                "\"spin_up_s\": 7.0",
                "dynamics.spin_up_s: 7 is not in [0, 2]",
            ),
            (
                "\"thrust_asymmetry\": 0.12359550561797752",
                "\"thrust_asymmetry\": 0.95",
                "dynamics.thrust_asymmetry: 0.95 is not in [0, 0.9]",
            ),
            (
                "\"command_exponent\": 1.5",
                "\"command_exponent\": 4.0",
                "dynamics.command_exponent: 4 is not in [0.5, 3]",
            ),
            (
                "\"thruster_lag_evidence\": 3.5",
                "\"thruster_lag_evidence\": null",
                "expected f64",
            ),
        ] {
            assert!(text.contains(from), "{from} not in {text}");
            let e = from_json(&text.replace(from, to), "m.json").unwrap_err();
            assert!(
                matches!(e, StoreError::Corrupt { .. }) && e.to_string().contains(key),
                "{to}: {e}"
            );
        }
        // A restated bound's share opens the swap gate: a file may not open it wider than
        // the machine does.
        let text_curve = text.split_whitespace().collect::<String>();
        let from = "\"curve_named_rel_err\":[0.3,0.4]";
        assert!(text_curve.contains(from), "{text_curve}");
        let e = from_json(
            &text_curve.replace(from, "\"curve_named_rel_err\":[30.0,0.4]"),
            "m.json",
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("dynamics.curve_named_rel_err: 30 is not in [0, 2]"),
            "{e}"
        );
        let mut lags = m.clone();
        lags.dynamics.as_mut().unwrap().spin_up_per_thruster_s = vec![0.1, 0.1];
        // Written without them (they would not load), never as a file that fails.
        assert_eq!(from_json(&to_json(&lags), "m.json").unwrap().dynamics, None);
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
            &text.replace("\"format_version\": 2", "\"format_version\": 9"),
            "m.json",
        )
        .unwrap_err();
        assert!(
            matches!(e, StoreError::Incompatible { found: 9, .. }),
            "{e}"
        );
        let e = from_json(
            &text.replace("\"format_version\": 2", "\"format_version\": 4294967297"),
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
