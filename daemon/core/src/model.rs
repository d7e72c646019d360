//! The model the controller runs on: effectiveness, allocation and their quality, with the
//! checks a model must pass before it may replace the current one.

use nalgebra::{DMatrix, Vector3};
use serde::{Deserialize, Serialize};

use thruster_protocol::validate::limits::{MAX_ALLOCATION, MAX_EFFECTIVENESS};

use crate::allocation::{self, pseudo_inverse};
use crate::estimator::analysis::rank_report;
use crate::estimator::dynamic::DynamicTerms;
use crate::estimator::{Dof, DofMask, Estimate, EstimatorConfig, Method};

/// Where a model came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelSource {
    /// Computed from declared geometry (a vehicle file or a reconfiguration event).
    Nominal,
    /// Learned in the water.
    Estimated,
    /// A configuration seen before, swapped back from the cache.
    Cache,
    /// Read from the state directory at start.
    Loaded,
}

/// A thruster model ready for control.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Model {
    /// Increases by one with every swap; 0 = no model yet.
    pub version: u64,
    pub source: ModelSource,
    pub method: Method,
    /// 6 x N, DOF rows (rad/s^2 and m/s^2 per unit command).
    pub effectiveness: DMatrix<f64>,
    /// N x 6, commands per unit desired motion; zero columns for unactuated DOFs.
    pub allocation: DMatrix<f64>,
    /// 6 x N standard errors; NaN where unknown (nominal models, the paper's method).
    pub std_err: DMatrix<f64>,
    pub actuated: DofMask,
    pub rel_err_rot: f64,
    pub rel_err_acc: f64,
    /// Identity of the declared geometry this model belongs to, when known (cache key).
    pub geometry_key: Option<u64>,
    /// Vehicle time at which the model was made (solved, or computed from geometry), ns on
    /// the IMU's clock; 0 when unknown (a file from an older daemon). Not the swap time: a
    /// model reverted to, cached or loaded keeps it.
    pub made_t_ns: u64,
    /// Made by an estimation in the water (true) or computed from declared geometry.
    pub estimated: bool,
    /// Pulses the estimation that made it took (0 when unknown or not estimated).
    pub pulses: usize,
    /// The file it was last loaded from, when it came from one.
    pub loaded_from: Option<String>,
    /// The dynamic method's other coefficients (damping, restoring, Coriolis), the learned
    /// lags, thrust shape and IMU position, and the excursion while it was learned; None for
    /// other methods (and for files of daemons before format version 2). The model file
    /// keeps them (`model_file`), checked on loading (`stored_terms`).
    pub dynamics: Option<DynamicTerms>,
    /// Times the continuous refinement has updated it since it was estimated (0: as solved).
    /// `made_t_ns` is then the last update's time.
    pub refinements: u32,
}

/// Why a candidate model was not swapped in.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SwapRejection {
    #[error("model has {got} thrusters, the vehicle has {want}")]
    WrongCount { got: usize, want: usize },
    #[error("model matrices have inconsistent shapes")]
    Shape,
    #[error("model contains a non-finite value in {0}")]
    NonFinite(&'static str),
    #[error("model actuates no degree of freedom")]
    NoDof,
    #[error("model confidence too low: relative error bound {rel_err:.3} > {limit:.3}")]
    LowConfidence { rel_err: f64, limit: f64 },
    #[error("thrusters were never excited in both directions, or not apart from each other")]
    NotExcited,
    /// A learned model without its error bounds: the confidence gate could not judge it (a
    /// missing bound compares as no bound) and the allocation would take its B as exact.
    #[error("a learned ({method:?}) model must carry its error bounds: {missing} unknown")]
    NoBound {
        method: Method,
        missing: &'static str,
    },
    /// Beyond the protocol's physical bounds: no thruster of a small vehicle does that, so
    /// the model comes from a units mistake, a corrupt file or a failed estimate.
    #[error("model {what}[{row}][{col}] = {value:e} is outside the physical bound +-{max:e}")]
    OutOfBounds {
        what: &'static str,
        row: usize,
        col: usize,
        value: f64,
        max: f64,
    },
}

/// The first entry of `m` with |x| > `max`, as a rejection naming it.
fn out_of_bounds(what: &'static str, m: &DMatrix<f64>, max: f64) -> Result<(), SwapRejection> {
    for row in 0..m.nrows() {
        for col in 0..m.ncols() {
            let value = m[(row, col)];
            if value.abs() > max {
                return Err(SwapRejection::OutOfBounds {
                    what,
                    row,
                    col,
                    value,
                    max,
                });
            }
        }
    }
    Ok(())
}

impl Model {
    pub fn thrusters(&self) -> usize {
        self.effectiveness.ncols()
    }

    /// The reported bounds and B's standard errors widened by `scale` per row group (rotation
    /// rows 0-2, acceleration rows 3-5): what the fit's own statistics did not see (a fight,
    /// a prior the data moved beyond its errors).
    pub fn widen(&mut self, scale: [f64; 2]) {
        self.rel_err_rot *= scale[0];
        self.rel_err_acc *= scale[1];
        for (g, k) in scale.iter().enumerate() {
            let rows = (3 * g).min(self.std_err.nrows());
            let count = 3.min(self.std_err.nrows() - rows);
            self.std_err.rows_mut(rows, count).scale_mut(*k);
        }
    }

    /// The thrusters' spin-up time constant this model's estimation learned, s; None when it
    /// was configured or the model did not come from the dynamic method. Whatever fits
    /// against this model (the refinement's windows and change test, identification under
    /// control) uses it instead of `estimator.spin_up_s`.
    pub fn learned_spin_up_s(&self) -> Option<f64> {
        self.dynamics
            .as_ref()
            .filter(|d| d.spin_up_learned && d.spin_up_s.is_finite())
            .map(|d| d.spin_up_s)
    }

    /// The relative error of B (rotation and acceleration rows) that the learned lags carry:
    /// the lag's own uncertainty and the floor of lags the data could not tell apart
    /// (`DynamicTerms::spin_up_rel_err`, `spin_up_floor_rel_err`), in quadrature; zero when
    /// nothing was learned. A fit that uses these lags without learning them again (under
    /// control) has this much error no data of its own removes: eight_vectored with
    /// thrusters at 0.1 and 0.12 s, noise-free, identified under control 0.040 / 0.042 off
    /// under bounds of 0.004 / 0.025, where the model its lags came from said 0.093 / 0.063.
    pub fn lag_rel_err(&self) -> [f64; 2] {
        let Some(d) = self.dynamics.as_ref().filter(|d| d.spin_up_learned) else {
            return [0.0; 2];
        };
        [0, 1].map(|g| {
            let e = d.spin_up_rel_err[g].hypot(d.spin_up_floor_rel_err[g]);
            if e.is_finite() {
                e
            } else {
                0.0
            }
        })
    }

    /// The relative error the navigation's own errors left in B, per row group, which the
    /// bound counts and the standard errors do not (`DynamicTerms::navigation_rel_err`); 0
    /// where none was drawn or inherited.
    pub fn navigation_rel_err(&self) -> [f64; 2] {
        self.dynamics.as_ref().map_or([0.0; 2], |d| {
            d.navigation_rel_err
                .map(|e| if e.is_finite() && e > 0.0 { e } else { 0.0 })
        })
    }

    /// What a thrust curve named puts this line model off at the hold's commands, per row
    /// group (`DynamicTerms::curve_named_rel_err`): refused, or learned and the model on it
    /// not yet identified; 0 where none was named.
    pub fn curve_named_rel_err(&self) -> [f64; 2] {
        self.dynamics.as_ref().map_or([0.0; 2], |d| {
            d.curve_named_rel_err.map(|e| {
                if e.is_finite() && e > 0.0 {
                    e.min(crate::estimator::dynamic::MAX_CURVE_NAMED_REL_ERR)
                } else {
                    0.0
                }
            })
        })
    }

    /// Each thruster's own lag this model learned, s, where its run kept them apart
    /// (`DynamicTerms::spin_up_per_thruster_s`); None when it learned one for all or none.
    /// Fits against this model under control use them, not their mean.
    pub fn learned_thruster_lags(&self) -> Option<&[f64]> {
        self.dynamics
            .as_ref()
            .filter(|d| d.spin_up_learned)
            .map(|d| d.spin_up_per_thruster_s.as_slice())
            .filter(|l| !l.is_empty() && l.iter().all(|v| v.is_finite() && *v >= 0.0))
    }

    /// The IMU's position from the centre this model's acceleration rows are referred with, m
    /// (learned or configured); None when the model did not come from the dynamic method.
    /// Fits under control against this model use it rather than learning it again.
    pub fn imu_position_m(&self) -> Option<nalgebra::Vector3<f64>> {
        self.dynamics
            .as_ref()
            .and_then(|d| d.imu_position)
            .map(|p| p.position_m)
    }

    /// A model from an estimate solved at vehicle time `t_ns` (version assigned at swap time).
    pub fn from_estimate(e: &Estimate, geometry_key: Option<u64>, t_ns: u64) -> Model {
        Model {
            made_t_ns: t_ns,
            estimated: true,
            pulses: e.pulses,
            loaded_from: None,
            dynamics: e.dynamics.clone(),
            refinements: 0,
            version: 0,
            source: ModelSource::Estimated,
            method: e.method,
            effectiveness: e.effectiveness.clone(),
            allocation: e.allocation.clone(),
            std_err: e.std_err.clone(),
            actuated: e.rank.actuated,
            rel_err_rot: e.rel_err_rot,
            rel_err_acc: e.rel_err_acc,
            geometry_key,
        }
    }

    /// The nominal (manual) model of a declared effectiveness: what PX4 and ArduSub use.
    pub fn nominal(effectiveness: DMatrix<f64>, geometry_key: Option<u64>) -> Model {
        let n = effectiveness.ncols();
        // Exact geometry: no estimation noise, so only round-off decides the rank.
        let zeros = DMatrix::zeros(6, n);
        let rank = rank_report(&effectiveness, &zeros, &EstimatorConfig::default());
        Model {
            made_t_ns: 0,
            estimated: false,
            pulses: 0,
            loaded_from: None,
            dynamics: None,
            refinements: 0,
            version: 0,
            source: ModelSource::Nominal,
            method: Method::Forward,
            allocation: pseudo_inverse(&effectiveness, rank.actuated, rank.rank),
            std_err: DMatrix::from_element(6, n, f64::NAN),
            actuated: rank.actuated,
            rel_err_rot: f64::NAN,
            rel_err_acc: f64::NAN,
            effectiveness,
            geometry_key,
        }
    }

    /// The same model with its actuated DOFs and allocation derived again from its
    /// effectiveness and standard errors, as the estimator derives them. A model from a file
    /// or a request is used this way: its own allocation is never trusted (a file can pair a
    /// harmless effectiveness with an absurd allocation). Unknown standard errors count as
    /// none, as for a nominal model.
    pub fn with_derived_allocation(mut self, cfg: &EstimatorConfig) -> Model {
        let known_err = self.std_err.map(|v| if v.is_finite() { v } else { 0.0 });
        let rank = rank_report(&self.effectiveness, &known_err, cfg);
        self.allocation = pseudo_inverse(&self.effectiveness, rank.actuated, rank.rank);
        self.actuated = rank.actuated;
        self
    }

    /// The same, checked against the physical bounds too, as a value the machine installs
    /// without deriving again: a caller may prepare a model off the control thread (the rank
    /// report is an SVD) and hand it over (`Machine::load_prepared`).
    pub fn prepared(self, cfg: &EstimatorConfig) -> Result<PreparedModel, SwapRejection> {
        let model = self.with_derived_allocation(cfg);
        // The count is the machine's business at install time; everything else is checked now.
        model.check(model.thrusters(), f64::INFINITY)?;
        Ok(PreparedModel(model))
    }

    /// Checks before a hot swap: right size, finite, within the protocol's physical bounds,
    /// actuates something, confident enough. Every model passes it, learned, nominal,
    /// cached or loaded. `max_rel_err` applies to estimated models (nominal and paper models
    /// carry no bound).
    pub fn check(&self, thrusters: usize, max_rel_err: f64) -> Result<(), SwapRejection> {
        let n = self.effectiveness.ncols();
        if n != thrusters {
            return Err(SwapRejection::WrongCount {
                got: n,
                want: thrusters,
            });
        }
        if self.effectiveness.nrows() != 6
            || self.allocation.shape() != (n, 6)
            || self.std_err.shape() != (6, n)
        {
            return Err(SwapRejection::Shape);
        }
        if !self.effectiveness.iter().all(|v| v.is_finite()) {
            return Err(SwapRejection::NonFinite("effectiveness"));
        }
        if !self.allocation.iter().all(|v| v.is_finite()) {
            return Err(SwapRejection::NonFinite("allocation"));
        }
        out_of_bounds("effectiveness", &self.effectiveness, MAX_EFFECTIVENESS)?;
        out_of_bounds("allocation", &self.allocation, MAX_ALLOCATION)?;
        // Before the standard errors' bound: an infinite bound (columns the data cannot
        // separate, their errors infinite too) is a model never excited, not a units mistake.
        if self.rel_err_rot.is_infinite() || self.rel_err_acc.is_infinite() {
            return Err(SwapRejection::NotExcited);
        }
        let known_err = self.std_err.map(|v| if v.is_nan() { 0.0 } else { v });
        if known_err.iter().any(|v| *v < 0.0) {
            return Err(SwapRejection::NonFinite("std_err (negative)"));
        }
        out_of_bounds("std_err", &known_err, MAX_EFFECTIVENESS)?;
        if self.actuated.count() == 0 || self.allocation.norm() == 0.0 {
            return Err(SwapRejection::NoDof);
        }
        self.check_bound_known()?;
        // Infinite bounds were refused above; a NaN one (none: a nominal or paper model,
        // checked just above) compares false.
        for rel in [self.rel_err_rot, self.rel_err_acc] {
            if rel > max_rel_err {
                return Err(SwapRejection::LowConfidence {
                    rel_err: rel,
                    limit: max_rel_err,
                });
            }
        }
        Ok(())
    }

    /// A learned model's bounds are all known. Every fit of the forward and dynamic methods
    /// has them (an infinite one is refused as never excited), so a missing one comes from a
    /// hand-made or cut file, which the gate below would otherwise let through at any error.
    /// Nominal models and the paper's method have none by design.
    fn check_bound_known(&self) -> Result<(), SwapRejection> {
        if !self.estimated || self.method == Method::Paper {
            return Ok(());
        }
        let missing = if self.rel_err_rot.is_nan() {
            "rel_err_rot"
        } else if self.rel_err_acc.is_nan() {
            "rel_err_acc"
        } else if self.std_err.iter().any(|v| v.is_nan()) {
            "std_err"
        } else {
            return Ok(());
        };
        Err(SwapRejection::NoBound {
            method: self.method,
            missing,
        })
    }

    /// Thruster commands for a desired motion (6, DOF order). Unactuated DOFs contribute
    /// nothing because their allocation columns are zero.
    pub fn allocate(&self, desired: &[f64; 6], out: &mut [f64]) {
        allocation::product(&self.allocation, desired, out);
    }

    pub fn is_actuated(&self, dof: Dof) -> bool {
        self.actuated.contains(dof)
    }

    /// Where the model came from, in words: how it was made, and how it got here when that
    /// was not by being made here (a cache, a file). The same words in status and `model`.
    pub fn provenance(&self) -> String {
        let made = if self.estimated {
            let at = if self.made_t_ns > 0 {
                format!(" at vehicle time {:.1} s", self.made_t_ns as f64 * 1e-9)
            } else {
                String::new()
            };
            let pulses = if self.pulses > 0 {
                format!(" from {} pulses", self.pulses)
            } else {
                String::new()
            };
            let refined = match self.refinements {
                0 => String::new(),
                1 => ", refined once under control".to_string(),
                k => format!(", refined {k} times under control"),
            };
            // A curve learned: the model is per unit of the commands through it.
            let curve = match self.dynamics.as_ref().and_then(|d| d.command_exponent) {
                Some(p) => format!(", on the thrust curve ~command^{p:.2} learned"),
                None => String::new(),
            };
            format!("estimated{at}{pulses}{refined}{curve}")
        } else {
            "nominal, from the declared geometry".to_string()
        };
        match (self.source, &self.loaded_from) {
            (ModelSource::Loaded, Some(file)) => format!("loaded from {file} ({made})"),
            (ModelSource::Loaded, None) => format!("loaded ({made})"),
            (ModelSource::Cache, _) => format!("from the cache ({made})"),
            _ => made,
        }
    }
}

/// Mass properties the daemon needs to turn declared geometry into a nominal model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RigidBody {
    /// Dry mass, kg (default 11.5, a BlueROV2).
    pub mass_kg: f64,
    /// Principal moments of inertia about body x, y, z, kg m^2 (default 0.16 each).
    pub inertia_kg_m2: [f64; 3],
    /// Added mass along body x, y, z, kg (default 5.5, 12.7, 14.57; Wu 2018).
    pub added_mass_kg: [f64; 3],
    /// Added inertia about body x, y, z, kg m^2 (default 0.12, 0.12, 0.12; Wu 2018).
    pub added_inertia_kg_m2: [f64; 3],
    /// Forward thrust of one thruster at full command, N (default 51.5, a T200).
    pub max_thrust_n: f64,
}

impl Default for RigidBody {
    fn default() -> Self {
        RigidBody {
            mass_kg: 11.5,
            inertia_kg_m2: [0.16, 0.16, 0.16],
            added_mass_kg: [5.5, 12.7, 14.57],
            added_inertia_kg_m2: [0.12, 0.12, 0.12],
            max_thrust_n: 51.5,
        }
    }
}

/// Nominal effectiveness (6 x N) of thrusters at `positions` (m, from the centre of mass)
/// pushing along `directions`, for a body with diagonal mass matrix: the rigid-body-plus-added
/// inertia divides force and torque axis by axis.
pub fn nominal_effectiveness(
    body: &RigidBody,
    positions: &[[f64; 3]],
    directions: &[[f64; 3]],
) -> DMatrix<f64> {
    let n = positions.len().min(directions.len());
    let mut b = DMatrix::zeros(6, n);
    for i in 0..n {
        let d = Vector3::from(directions[i]);
        let d = if d.norm() > 0.0 { d.normalize() } else { d };
        let f = d * body.max_thrust_n;
        let tau = Vector3::from(positions[i]).cross(&f);
        for a in 0..3 {
            b[(a, i)] = tau[a] / (body.inertia_kg_m2[a] + body.added_inertia_kg_m2[a]);
            b[(3 + a, i)] = f[a] / (body.mass_kg + body.added_mass_kg[a]);
        }
    }
    b
}

/// A stable key for declared geometry: positions and directions rounded to 1 mm and 0.001,
/// so the same physical layout maps to the same cache entry despite float noise.
pub fn geometry_key(positions: &[[f64; 3]], directions: &[[f64; 3]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut feed = |v: i64| {
        for byte in v.to_le_bytes() {
            h ^= byte as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    feed(positions.len() as i64);
    for (p, d) in positions.iter().zip(directions) {
        for v in p.iter().chain(d.iter()) {
            feed((v * 1000.0).round() as i64);
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_scales_each_row_groups_bound_and_standard_errors() {
        let mut m = Model::nominal(DMatrix::from_element(6, 2, 1.0), None);
        m.std_err = DMatrix::from_element(6, 2, 0.1);
        m.rel_err_rot = 0.02;
        m.rel_err_acc = 0.03;
        m.widen([2.0, 3.0]);
        assert!((m.rel_err_rot - 0.04).abs() < 1e-12 && (m.rel_err_acc - 0.09).abs() < 1e-12);
        assert!(m.std_err.rows(0, 3).iter().all(|s| (s - 0.2).abs() < 1e-12));
        assert!(m.std_err.rows(3, 3).iter().all(|s| (s - 0.3).abs() < 1e-12));
    }

    #[test]
    fn nominal_of_aligned_thrusters_leaves_roll_sway_heave_out() {
        let body = RigidBody::default();
        let pos = [[0.0, -0.2, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, -0.15]];
        let dir = [[1.0, 0.0, 0.0]; 3];
        let m = Model::nominal(nominal_effectiveness(&body, &pos, &dir), None);
        assert_eq!(m.actuated.names(), vec!["pitch", "yaw", "surge"]);
        m.check(3, 0.1).unwrap();
        // Port thruster (y = -0.2) pushing forward yaws the nose to starboard: +yaw (z down).
        assert!(m.effectiveness[(Dof::Yaw.index(), 0)] > 0.0);
        let surge = 51.5 / (11.5 + 5.5);
        assert!((m.effectiveness[(Dof::Surge.index(), 2)] - surge).abs() < 1e-12);
    }

    #[test]
    fn check_rejects_bad_models() {
        let body = RigidBody::default();
        let pos = [[0.0, -0.2, 0.0], [0.0, 0.2, 0.0]];
        let dir = [[1.0, 0.0, 0.0]; 2];
        let good = Model::nominal(nominal_effectiveness(&body, &pos, &dir), None);
        assert!(matches!(
            good.check(3, 0.1),
            Err(SwapRejection::WrongCount { .. })
        ));
        let mut nan = good.clone();
        nan.allocation[(0, 0)] = f64::NAN;
        assert_eq!(
            nan.check(2, 0.1),
            Err(SwapRejection::NonFinite("allocation"))
        );
        let mut vague = good.clone();
        vague.rel_err_rot = 0.5;
        assert!(matches!(
            vague.check(2, 0.1),
            Err(SwapRejection::LowConfidence { .. })
        ));
        let mut unexcited = good;
        unexcited.rel_err_acc = f64::INFINITY;
        assert_eq!(unexcited.check(2, 0.1), Err(SwapRejection::NotExcited));
    }

    /// A learned model whose file left its bounds out passed the gate at any error (a missing
    /// bound compared false); now it names what is missing. A nominal model and the paper's
    /// method still have none by design.
    #[test]
    fn a_learned_model_without_its_bounds_is_refused_and_a_nominal_one_needs_none() {
        let body = RigidBody::default();
        let pos = [[0.0, -0.2, 0.0], [0.0, 0.2, 0.0]];
        let dir = [[1.0, 0.0, 0.0]; 2];
        let nominal = Model::nominal(nominal_effectiveness(&body, &pos, &dir), None);
        nominal.check(2, 0.1).unwrap();
        let mut learned = nominal.clone();
        learned.estimated = true;
        learned.method = Method::Dynamic;
        learned.std_err.fill(0.001);
        learned.rel_err_rot = 0.01;
        learned.rel_err_acc = 0.01;
        learned.check(2, 0.1).unwrap();
        for (missing, cut) in [
            (
                "rel_err_rot",
                (|m: &mut Model| m.rel_err_rot = f64::NAN) as fn(&mut Model),
            ),
            ("rel_err_acc", |m: &mut Model| m.rel_err_acc = f64::NAN),
            ("std_err", |m: &mut Model| m.std_err[(4, 1)] = f64::NAN),
        ] {
            let mut m = learned.clone();
            cut(&mut m);
            let e = m.check(2, 0.1).unwrap_err();
            assert_eq!(
                e,
                SwapRejection::NoBound {
                    method: Method::Dynamic,
                    missing
                }
            );
            assert!(e.to_string().contains(missing), "{e}");
        }
        let mut paper = learned;
        paper.method = Method::Paper;
        paper.rel_err_rot = f64::NAN;
        paper.rel_err_acc = f64::NAN;
        paper.std_err.fill(f64::NAN);
        paper.check(2, 0.1).unwrap();
    }

    #[test]
    fn check_applies_the_protocols_physical_bounds_and_loads_derive_their_allocation() {
        let body = RigidBody::default();
        let pos = [[0.0, -0.2, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, -0.15]];
        let dir = [[1.0, 0.0, 0.0]; 3];
        let good = Model::nominal(nominal_effectiveness(&body, &pos, &dir), None);
        let mut absurd = good.clone();
        absurd.effectiveness[(Dof::Yaw.index(), 1)] = 1e300;
        let e = absurd.check(3, 0.1).unwrap_err();
        assert!(matches!(
            e,
            SwapRejection::OutOfBounds {
                what: "effectiveness",
                row: 2,
                col: 1,
                ..
            }
        ));
        assert!(e.to_string().contains("effectiveness[2][1] = 1e300"), "{e}");
        // A harmless effectiveness with an absurd allocation: the allocation is derived again
        // from the effectiveness, so what a file says about it does not matter.
        let mut lying = good.clone();
        lying.allocation[(0, Dof::Yaw.index())] = 1e9;
        lying.actuated = DofMask::ALL;
        assert!(matches!(
            lying.check(3, 0.1),
            Err(SwapRejection::OutOfBounds {
                what: "allocation",
                ..
            })
        ));
        let derived = lying.with_derived_allocation(&EstimatorConfig::default());
        assert_eq!(derived.actuated, good.actuated);
        assert!((&derived.allocation - &good.allocation).amax() < 1e-12);
        derived.check(3, 0.1).unwrap();
        let mut negative = good;
        negative.std_err[(0, 0)] = -1.0;
        assert!(negative.check(3, 0.1).is_err());
    }

    #[test]
    fn provenance_says_how_it_was_made_and_how_it_got_here() {
        let body = RigidBody::default();
        let pos = [[0.0, -0.2, 0.0], [0.0, 0.2, 0.0]];
        let dir = [[1.0, 0.0, 0.0]; 2];
        let mut m = Model::nominal(nominal_effectiveness(&body, &pos, &dir), None);
        assert_eq!(m.provenance(), "nominal, from the declared geometry");
        m.estimated = true;
        m.pulses = 16;
        m.made_t_ns = 16_500_000_000;
        m.source = ModelSource::Estimated;
        assert_eq!(
            m.provenance(),
            "estimated at vehicle time 16.5 s from 16 pulses"
        );
        m.source = ModelSource::Cache;
        assert_eq!(
            m.provenance(),
            "from the cache (estimated at vehicle time 16.5 s from 16 pulses)"
        );
        m.source = ModelSource::Loaded;
        m.loaded_from = Some("/var/lib/thrusterd/model.json".into());
        assert_eq!(
            m.provenance(),
            "loaded from /var/lib/thrusterd/model.json (estimated at vehicle time 16.5 s from 16 pulses)"
        );
    }

    #[test]
    fn geometry_key_ignores_float_noise_but_not_moves() {
        let pos = [[0.1, 0.2, 0.3]];
        let dir = [[1.0, 0.0, 0.0]];
        let k = geometry_key(&pos, &dir);
        assert_eq!(k, geometry_key(&[[0.1000001, 0.2, 0.3]], &dir));
        assert_ne!(k, geometry_key(&[[0.11, 0.2, 0.3]], &dir));
        assert_ne!(k, geometry_key(&pos, &[[0.0, 1.0, 0.0]]));
    }
}

/// A model from outside (a file) with its actuated DOFs and allocation derived again by
/// [`Model::prepared`], never taken from the file. Only that function makes one.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedModel(Model);

impl PreparedModel {
    /// The model.
    pub fn model(&self) -> &Model {
        &self.0
    }

    pub(crate) fn into_model(self) -> Model {
        self.0
    }
}
