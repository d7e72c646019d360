//! `--truth-file`: the true effectiveness as JSON, for scoring estimates after a run.
//!
//! The file holds every truth since the start (one entry at start and one per change), and
//! is rewritten atomically (temporary file + rename) after each, so a reader never sees a
//! half-written file.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde::Serialize;

use crate::sim::Simulator;

/// One truth: the geometry and effectiveness valid from `t_s`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TruthEntry {
    /// Simulation time from which it holds, s.
    pub t_s: f64,
    /// Same, ns (the IMU clock).
    pub t_ns: u64,
    /// What made it: "start", a scenario action kind ("rotate", ...), or "final".
    pub cause: String,
    /// Thruster names in command order.
    pub thrusters: Vec<String>,
    /// B_fwd, 6 rows (roll, pitch, yaw, surge, sway, heave) x N: rad/s^2 or m/s^2 per unit
    /// command.
    pub effectiveness: Vec<Vec<f64>>,
    /// B_rev, same shape: the response to a negative command u is B_rev u.
    pub reverse_effectiveness: Vec<Vec<f64>>,
}

impl TruthEntry {
    /// The current truth of `sim`.
    pub fn of(sim: &Simulator, cause: &str) -> Self {
        let (fwd, rev) = sim.truth();
        TruthEntry {
            t_s: sim.time_s(),
            t_ns: sim.time_ns(),
            cause: cause.to_string(),
            thrusters: sim
                .vehicle()
                .thrusters
                .iter()
                .map(|t| t.name.clone())
                .collect(),
            effectiveness: rows(&fwd),
            reverse_effectiveness: rows(&rev),
        }
    }
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

#[derive(Debug, Serialize)]
struct FileBody<'a> {
    vehicle: &'a str,
    dof_order: [&'static str; 6],
    truth: &'a [TruthEntry],
}

/// Errors writing the truth file.
#[derive(Debug, thiserror::Error)]
// The OS error is in the message and not a `source`: a chain printed whole ("{:#}") said it
// twice.
#[error("cannot write truth file {}: {error}", path.display())]
pub struct TruthFileError {
    /// The file.
    pub path: PathBuf,
    /// Why.
    pub error: std::io::Error,
}

/// The truth file and the entries written so far.
#[derive(Debug)]
pub struct TruthFile {
    path: PathBuf,
    vehicle: String,
    entries: Vec<TruthEntry>,
}

impl TruthFile {
    /// A truth file at `path` for the vehicle called `vehicle` (nothing written yet).
    pub fn new(path: &Path, vehicle: &str) -> Self {
        TruthFile {
            path: path.to_path_buf(),
            vehicle: vehicle.to_string(),
            entries: Vec::new(),
        }
    }

    /// Adds an entry and rewrites the file.
    pub fn push(&mut self, entry: TruthEntry) -> Result<(), TruthFileError> {
        self.entries.push(entry);
        self.write()
    }

    fn write(&self) -> Result<(), TruthFileError> {
        let err = |error| TruthFileError {
            path: self.path.clone(),
            error,
        };
        let body = FileBody {
            vehicle: &self.vehicle,
            dof_order: ["roll", "pitch", "yaw", "surge", "sway", "heave"],
            truth: &self.entries,
        };
        let json = serde_json::to_vec_pretty(&body).map_err(|e| err(e.into()))?;
        let mut tmp = self.path.clone().into_os_string();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        let mut f = fs::File::create(&tmp).map_err(err)?;
        f.write_all(&json).map_err(err)?;
        f.write_all(b"\n").map_err(err)?;
        drop(f);
        fs::rename(&tmp, &self.path).map_err(err)
    }
}
