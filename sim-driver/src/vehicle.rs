//! Vehicle description: rigid body, hydrodynamic coefficients and thruster geometry, as loaded
//! from `config/vehicles/*.toml`.
//!
//! Frames (Fossen / SNAME): body x forward, y starboard, z down; all positions are relative to
//! the body origin, the CO (centre of origin), about which the equations of motion are written.
//!
//! Every key of `[body]` and most keys of a `[[thruster]]` have documented defaults: the body
//! defaults are the BlueROV2 parameter set of Wu (2018), see `docs/simulation.md`. Loading and
//! checking a file is `vehicle_file.rs`.

use nalgebra::{Vector3, Vector6};
use serde::{Deserialize, Serialize};
use thruster_protocol::validate::limits::{MAX_POSITION_M, MAX_SPIN_UP_S};

use crate::battery::BatterySpec;
use crate::load::{symmetric, Checker, LoadError, Range};

/// Standard gravity, m/s^2 per kgf (thrust data sheets are in kgf).
pub const KGF_N: f64 = 9.80665;
/// Blue Robotics T200 maximum forward thrust at 16 V: 5.25 kgf, in N (51.5 N).
pub const T200_FORWARD_MAX_N: f64 = 5.25 * KGF_N;
/// Blue Robotics T200 maximum reverse thrust at 16 V: 4.1 kgf, in N (40.2 N).
pub const T200_REVERSE_MAX_N: f64 = 4.1 * KGF_N;
/// One value per degree of freedom, by name, so no file depends on a DOF ordering convention.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dof6 {
    pub surge: f64,
    pub sway: f64,
    pub heave: f64,
    pub roll: f64,
    pub pitch: f64,
    pub yaw: f64,
}

impl Dof6 {
    /// In Fossen order `[surge, sway, heave, roll, pitch, yaw]`.
    pub fn to_fossen(&self) -> Vector6<f64> {
        Vector6::new(
            self.surge, self.sway, self.heave, self.roll, self.pitch, self.yaw,
        )
    }

    fn named(&self) -> [(&'static str, f64); 6] {
        [
            ("surge", self.surge),
            ("sway", self.sway),
            ("heave", self.heave),
            ("roll", self.roll),
            ("pitch", self.pitch),
            ("yaw", self.yaw),
        ]
    }
}

/// Rigid body and hydrodynamics. Defaults: BlueROV2 (standard, 6 thrusters) from Wu (2018).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Body {
    /// Dry mass, kg. Default 11.5.
    pub mass_kg: f64,
    /// Principal moments of inertia about the CG along the body axes [Ixx, Iyy, Izz], kg m^2
    /// (the parallel-axis shift to the CO is applied). Default [0.16, 0.16, 0.16].
    pub inertia_kgm2: [f64; 3],
    /// Diagonal added mass, positive numbers (-X_udot, ...): kg for surge/sway/heave, kg m^2 for
    /// roll/pitch/yaw. Default surge 5.5, sway 12.7, heave 14.57, roll/pitch/yaw 0.12.
    pub added_mass: Dof6,
    /// Linear damping, positive (-X_u, ...): N s/m, N m s/rad. Default surge 4.03, sway 6.22,
    /// heave 5.18, roll/pitch/yaw 0.07.
    pub linear_damping: Dof6,
    /// Quadratic damping, positive (-X_u|u|, ...): N s^2/m^2, N m s^2/rad^2. Default surge
    /// 18.18, sway 21.66, heave 36.99, roll/pitch/yaw 1.55.
    pub quadratic_damping: Dof6,
    /// Buoyancy force, N. Default 114.8 (2 N more than the 112.8 N weight: slightly positive).
    pub buoyancy_n: f64,
    /// Gravitational acceleration, m/s^2. Default 9.81.
    pub gravity_mps2: f64,
    /// Centre of gravity relative to the CO, m. Default [0, 0, 0.02] (2 cm below the CB).
    pub cg_m: [f64; 3],
    /// Centre of buoyancy relative to the CO, m. Default [0, 0, 0]. Keep it above the CG
    /// (smaller z) for passive roll/pitch stability.
    pub cb_m: [f64; 3],
}

impl Default for Body {
    fn default() -> Self {
        Body::bluerov2()
    }
}

impl Body {
    /// BlueROV2 (6 thrusters) as identified by Wu (2018), the set used by many BlueROV2 models.
    pub fn bluerov2() -> Body {
        Body {
            mass_kg: 11.5,
            inertia_kgm2: [0.16, 0.16, 0.16],
            added_mass: Dof6 {
                surge: 5.5,
                sway: 12.7,
                heave: 14.57,
                roll: 0.12,
                pitch: 0.12,
                yaw: 0.12,
            },
            linear_damping: Dof6 {
                surge: 4.03,
                sway: 6.22,
                heave: 5.18,
                roll: 0.07,
                pitch: 0.07,
                yaw: 0.07,
            },
            quadratic_damping: Dof6 {
                surge: 18.18,
                sway: 21.66,
                heave: 36.99,
                roll: 1.55,
                pitch: 1.55,
                yaw: 1.55,
            },
            buoyancy_n: 114.8,
            gravity_mps2: 9.81,
            cg_m: [0.0, 0.0, 0.02],
            cb_m: [0.0, 0.0, 0.0],
        }
    }

    /// BlueROV2 Heavy (8 thrusters) from von Benzon et al. (2022), trimmed 2 N positive (their
    /// displaced volume gives slightly negative buoyancy in fresh water; see the docs).
    pub fn bluerov2_heavy() -> Body {
        Body {
            mass_kg: 13.5,
            inertia_kgm2: [0.26, 0.23, 0.37],
            added_mass: Dof6 {
                surge: 6.36,
                sway: 7.12,
                heave: 18.68,
                roll: 0.189,
                pitch: 0.135,
                yaw: 0.222,
            },
            linear_damping: Dof6 {
                surge: 13.7,
                sway: 0.0,
                heave: 33.0,
                roll: 0.0,
                pitch: 0.8,
                yaw: 0.0,
            },
            quadratic_damping: Dof6 {
                surge: 141.0,
                sway: 217.0,
                heave: 190.0,
                roll: 1.19,
                pitch: 0.47,
                yaw: 1.5,
            },
            buoyancy_n: 134.4,
            gravity_mps2: 9.81,
            cg_m: [0.0, 0.0, 0.0],
            cb_m: [0.0, 0.0, -0.01],
        }
    }

    /// Weight m g, N.
    pub fn weight_n(&self) -> f64 {
        self.mass_kg * self.gravity_mps2
    }

    /// Checks ranges; `origin` names the file in errors.
    pub fn validate(&self, origin: &str) -> Result<(), LoadError> {
        self.check(&Checker::new(origin, ""))
    }

    /// Checks ranges, locating a bad value in `c.text`. They are wide enough for anything
    /// from a toy to a work-class ROV (BlueROV2: 11.5 kg, 0.16 kg m^2; the Heavy's quadratic
    /// sway damping 217) and keep absurd values out of the physics; at rest the accelerometer
    /// reads `gravity_mps2`, within the protocol's 200 m/s^2, and `cg_m`, `cb_m` are within
    /// its `MAX_POSITION_M` of the CO.
    pub(crate) fn check(&self, c: &Checker) -> Result<(), LoadError> {
        c.range("body.mass_kg", self.mass_kg, Range::closed(0.1, 1e4))?;
        c.range(
            "body.gravity_mps2",
            self.gravity_mps2,
            Range::closed(0.1, 100.0),
        )?;
        c.each(
            "body.inertia_kgm2",
            &self.inertia_kgm2,
            Range::closed(1e-4, 1e4),
        )?;
        c.range("body.buoyancy_n", self.buoyancy_n, Range::closed(0.0, 1e6))?;
        for (table, values, hi) in [
            ("added_mass", &self.added_mass, 1e4),
            ("linear_damping", &self.linear_damping, 1e5),
            ("quadratic_damping", &self.quadratic_damping, 1e5),
        ] {
            for (dof, v) in values.named() {
                c.range(&format!("body.{table}.{dof}"), v, Range::closed(0.0, hi))?;
            }
        }
        c.each("body.cg_m", &self.cg_m, symmetric(MAX_POSITION_M))?;
        c.each("body.cb_m", &self.cb_m, symmetric(MAX_POSITION_M))?;
        Ok(())
    }
}

/// Largest `forward_max_n` / `reverse_max_n`, N (about a tonne-force; a T200 gives 51.5 N).
/// What a thruster may really give is bounded by the body: see [`Vehicle::validate`].
pub const MAX_THRUST_N: f64 = 1e4;

fn default_forward_max_n() -> f64 {
    T200_FORWARD_MAX_N
}
fn default_reverse_max_n() -> f64 {
    T200_REVERSE_MAX_N
}
fn default_deadband() -> f64 {
    0.05
}
fn default_time_constant_s() -> f64 {
    0.1
}
fn default_exponent() -> f64 {
    1.0
}

/// Where a thruster's steady thrust comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ThrusterModel {
    /// `forward_max_n` / `reverse_max_n` times the deadband-rescaled command to `exponent`,
    /// whatever the supply voltage (the simulator's original thrusters).
    #[default]
    PowerLaw,
    /// The Blue Robotics T200's published thrust-vs-PWM table at the present supply voltage
    /// (`thruster_table::ThrusterTable::t200`; command u is 1500 + 400 u us, the ESC's dead
    /// zone and asymmetry are the data's), scaled by `forward_max_n / 51.5 N` forward and
    /// `reverse_max_n / 40.2 N` in reverse (1 with the defaults; `weaken` scales them).
    /// `deadband` and `exponent` are not used.
    T200,
}

/// One thruster: where it sits, which way it pushes, how hard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThrusterSpec {
    /// Unique name within the vehicle (used by scenarios).
    pub name: String,
    /// Position of the thrust application point relative to the CO, body frame, m: each
    /// within the protocol's `MAX_POSITION_M` (10 m) of the CO and of the centre of gravity.
    pub position_m: [f64; 3],
    /// Direction of the force on the vehicle for a positive command (for a `reversed` thruster
    /// the force is opposite), body frame. Any non-zero length; normalised on load.
    pub direction: [f64; 3],
    /// Thrust at command +1, N, in (0, 10000] and no more than the body can take (the truth
    /// within the protocol's `MAX_EFFECTIVENESS`). Default 51.5 N (T200, 5.25 kgf).
    #[serde(default = "default_forward_max_n")]
    pub forward_max_n: f64,
    /// Thrust magnitude at command -1, N, in [0, 10000] (bounded like `forward_max_n`).
    /// Default 40.2 N (T200, 4.1 kgf).
    #[serde(default = "default_reverse_max_n")]
    pub reverse_max_n: f64,
    /// Commands with |u| <= deadband give no thrust; beyond it the curve starts at zero and
    /// reaches the maximum at |u| = 1. Normalised, in [0, 1). Default 0.05 (about the +-25 us
    /// of a Blue Robotics ESC over its +-400 us range is 0.0625).
    #[serde(default = "default_deadband")]
    pub deadband: f64,
    /// First-order spin-up/down time constant of the thrust, s, in [0, 2] (the protocol's
    /// `MAX_SPIN_UP_S`; 0 = instantaneous). Default 0.1.
    #[serde(default = "default_time_constant_s")]
    pub time_constant_s: f64,
    /// Shape of the curve beyond the deadband: thrust = max * e^exponent, e in [0, 1] the
    /// rescaled command. Default 1 (linear, the model the paper's estimator assumes).
    #[serde(default = "default_exponent")]
    pub exponent: f64,
    /// Left-handed screw: a positive command pushes against `direction`. Default false.
    #[serde(default)]
    pub reversed: bool,
    /// Produces no thrust at all. Default false.
    #[serde(default)]
    pub dead: bool,
    /// The thrust curve: `"power_law"` (default: the keys above, no voltage dependence) or
    /// `"t200"` (the T200's measured table at the battery's voltage).
    #[serde(default)]
    pub model: ThrusterModel,
}

impl ThrusterSpec {
    /// A T200-class thruster with every default.
    pub fn new(name: impl Into<String>, position_m: [f64; 3], direction: [f64; 3]) -> Self {
        ThrusterSpec {
            name: name.into(),
            position_m,
            direction,
            forward_max_n: T200_FORWARD_MAX_N,
            reverse_max_n: T200_REVERSE_MAX_N,
            deadband: default_deadband(),
            time_constant_s: default_time_constant_s(),
            exponent: default_exponent(),
            reversed: false,
            dead: false,
            model: ThrusterModel::PowerLaw,
        }
    }

    /// Position relative to the CO, m.
    pub fn position(&self) -> Vector3<f64> {
        Vector3::from(self.position_m)
    }

    /// Unit direction (after validation), body frame.
    pub fn direction(&self) -> Vector3<f64> {
        Vector3::from(self.direction)
    }

    /// Generalised force per newton of thrust along `direction`, Fossen order
    /// `[f; r x f]` (N per N, N m per N).
    pub fn wrench_per_newton(&self) -> Vector6<f64> {
        let d = self.direction();
        let m = self.position().cross(&d);
        Vector6::new(d.x, d.y, d.z, m.x, m.y, m.z)
    }

    /// Checks ranges and normalises `direction`. `key` prefixes error keys (e.g.
    /// `thruster[2]`).
    pub fn validate(&mut self, origin: &str, key: &str) -> Result<(), LoadError> {
        self.check(&Checker::new(origin, ""), key)
    }

    /// As [`ThrusterSpec::validate`], locating a bad value in `c.text` by `key` (the
    /// thruster's table: `thruster[2]`, `event[0].action.spec`). Errors show the key with the
    /// thruster's name: `thruster[2] ("L").forward_max_n`. Whether the body can take what
    /// the thruster gives is the vehicle's check ([`Vehicle::validate`]).
    pub(crate) fn check(&mut self, c: &Checker, key: &str) -> Result<(), LoadError> {
        if self.name.trim().is_empty() {
            let key = format!("{key}.name");
            return Err(c.error(&key, &key, "must not be empty"));
        }
        let shown = format!("{key} ({:?})", self.name);
        let path = |field: &str| (format!("{key}.{field}"), format!("{shown}.{field}"));
        let range = |field: &str, v: f64, r: Range| {
            let (key, shown) = path(field);
            c.range_shown(&key, &shown, v, r)
        };
        let each = |field: &str, v: &[f64], r: Range| {
            let (key, shown) = path(field);
            c.each_shown(&key, &shown, v, r)
        };
        // Within the protocol's reach of the vehicle's centre (declared geometry).
        each("position_m", &self.position_m, symmetric(MAX_POSITION_M))?;
        each("direction", &self.direction, symmetric(1e6))?;
        let d = self.direction();
        let norm = d.norm();
        // Anything this short is a typo, not a direction: normalising it would amplify noise.
        if norm < 1e-6 {
            let (key, shown) = path("direction");
            return Err(c.error(&key, &shown, "must not be zero"));
        }
        self.direction = (d / norm).into();
        range(
            "forward_max_n",
            self.forward_max_n,
            Range::above_to(0.0, MAX_THRUST_N),
        )?;
        range(
            "reverse_max_n",
            self.reverse_max_n,
            Range::closed(0.0, MAX_THRUST_N),
        )?;
        range("deadband", self.deadband, Range::from_below(0.0, 1.0))?;
        // The protocol's longest spin-up: a daemon could not report a longer lag.
        range(
            "time_constant_s",
            self.time_constant_s,
            Range::closed(0.0, MAX_SPIN_UP_S),
        )?;
        range("exponent", self.exponent, Range::closed(0.2, 5.0))?;
        Ok(())
    }
}

/// A complete vehicle: body and thrusters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vehicle {
    /// Short name, e.g. "amour5". Default "".
    #[serde(default)]
    pub name: String,
    /// Free text. Default "".
    #[serde(default)]
    pub description: String,
    /// Rigid body and hydrodynamics; omitted keys take the BlueROV2 defaults.
    #[serde(default)]
    pub body: Body,
    /// The thrusters, in command order (`[[thruster]]` tables in the file).
    #[serde(rename = "thruster", default)]
    pub thrusters: Vec<ThrusterSpec>,
    /// The battery (`[battery]`). Default none: a fixed supply that never sags, as before
    /// (no voltage is reported then, and `t200` thrusters see the table's 16 V).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub battery: Option<BatterySpec>,
}

impl Vehicle {
    /// Index of the thruster called `name`.
    pub fn thruster_index(&self, name: &str) -> Option<usize> {
        self.thrusters.iter().position(|t| t.name == name)
    }

    /// The geometry a driver declares for this vehicle, per thruster (position, direction) in
    /// the protocol's conventions: positions from the centre of mass (the file's are from the
    /// CO; `[body] cg_m`, default the BlueROV2 body's), directions those of the force for a
    /// positive command (a `reversed`, left-handed thruster pushes against its `direction`).
    /// The one conversion the driver's reconfiguration events, the lab and the in-process
    /// harness share.
    pub fn declared_geometry(&self) -> Vec<([f64; 3], [f64; 3])> {
        let cg = self.body.cg_m;
        self.thrusters
            .iter()
            .map(|t| {
                let sign = if t.reversed { -1.0 } else { 1.0 };
                (
                    std::array::from_fn(|k| t.position_m[k] - cg[k]),
                    t.direction.map(|d| sign * d),
                )
            })
            .collect()
    }

    /// Whether every thruster is a T200 from the measured table (whose operator configures the
    /// daemon for it: `[supply] linearize`).
    pub fn all_t200(&self) -> bool {
        self.thrusters
            .iter()
            .all(|t| t.model == ThrusterModel::T200)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
name = "m"
[[thruster]]
name = "a"
position_m = [0.1, 0.0, 0.0]
direction = [0.0, 0.0, -2.0]
"#;

    #[test]
    fn defaults_and_normalisation() {
        let v = Vehicle::from_toml_str(MINIMAL, "m.toml").expect("valid");
        assert_eq!(v.body, Body::bluerov2());
        let t = &v.thrusters[0];
        assert_eq!(t.direction, [0.0, 0.0, -1.0]);
        assert!((t.forward_max_n - 51.485).abs() < 0.01);
        assert!((t.reverse_max_n - 40.207).abs() < 0.01);
        assert_eq!(t.deadband, 0.05);
        assert_eq!(t.time_constant_s, 0.1);
        assert!(!t.reversed && !t.dead);
    }

    #[test]
    fn zero_direction_is_rejected_with_key() {
        let text = MINIMAL.replace("[0.0, 0.0, -2.0]", "[0.0, 0.0, 0.0]");
        let err = Vehicle::from_toml_str(&text, "m.toml").unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("m.toml"), "{msg}");
        assert!(msg.contains("thruster[0]"), "{msg}");
        assert!(msg.contains("direction"), "{msg}");
    }

    #[test]
    fn unknown_key_is_rejected_with_line() {
        let text = MINIMAL.replace("name = \"a\"", "name = \"a\"\nforwrd_max_n = 3.0");
        match Vehicle::from_toml_str(&text, "m.toml") {
            Err(LoadError::Parse { line, message, .. }) => {
                assert!(message.contains("forwrd_max_n"), "{message}");
                assert!(line >= 4, "line {line}");
            }
            other => panic!("expected parse error, got {other:?}"),
        }
    }

    #[test]
    fn absurd_values_are_refused_naming_file_line_key_and_range() {
        let err = |text: &str| {
            Vehicle::from_toml_str(text, "m.toml")
                .unwrap_err()
                .to_string()
        };
        let with = |line: &str| MINIMAL.replace("name = \"a\"", &format!("name = \"a\"\n{line}"));
        // Each once started a simulator whose truth failed the protocol's validation, or
        // whose integration diverged.
        assert_eq!(
            err(&with("forward_max_n = 1e300")),
            "m.toml:5:17: thruster[0] (\"a\").forward_max_n: must be in (0, 10000], got 1e300"
        );
        assert_eq!(
            err(&MINIMAL.replace("[0.1, 0.0, 0.0]", "[1e9, 0.0, 0.0]")),
            "m.toml:5:15: thruster[0] (\"a\").position_m[0]: must be in [-10, 10], got 1000000000"
        );
        assert_eq!(
            err(&with("time_constant_s = inf")),
            "m.toml:5:19: thruster[0] (\"a\").time_constant_s: must be in [0, 2], got inf"
        );
        assert_eq!(
            err(&format!("{MINIMAL}[body]\nmass_kg = inf\n")),
            "m.toml:8:11: body.mass_kg: must be in [0.1, 10000], got inf"
        );
        assert_eq!(
            err(&format!("{MINIMAL}[body]\ninertia_kgm2 = [0.1, -1, 0.1]\n")),
            "m.toml:8:22: body.inertia_kgm2[1]: must be in [0.0001, 10000], got -1"
        );
        // Within its own range, but more than the body can take: the truth would exceed
        // the protocol's MAX_EFFECTIVENESS.
        assert_eq!(
            err(&with("forward_max_n = 9000")),
            "m.toml:5:17: thruster[0] (\"a\").forward_max_n: 9000 N accelerates this body by \
             3197.3 rad/s^2 in pitch, more than the 1000 per unit command the protocol accepts: \
             lower it, or check body mass and inertia"
        );
        // Declared positions are from the centre of gravity.
        assert_eq!(
            err(&format!(
                "{}[body]\ncg_m = [0, 0, 1]\n",
                MINIMAL.replace("[0.1, 0.0, 0.0]", "[0.1, 0.0, -9.5]")
            )),
            "m.toml:5:25: thruster[0] (\"a\").position_m[2]: must be in [-9, 11] (within 10 m \
             of body.cg_m), got -9.5"
        );
        // No thrusters (an empty file), or more than the protocol carries.
        let none = "m.toml: thruster: the number of thrusters ([[thruster]] tables) must be in \
                    [1, 16], got 0";
        assert_eq!(err(""), none);
        assert_eq!(err("name = \"m\"\n[body]\nmass_kg = 12.0\n"), none);
        let many: String = (0..17)
            .map(|i| format!("[[thruster]]\nname = \"t{i}\"\nposition_m = [0, 0, 0]\ndirection = [1, 0, 0]\n"))
            .collect();
        assert!(
            err(&many).ends_with("must be in [1, 16], got 17"),
            "{}",
            err(&many)
        );
    }

    #[test]
    fn duplicate_names_and_bad_ranges_are_rejected() {
        let twice = format!(
            "{MINIMAL}[[thruster]]\nname = \"a\"\nposition_m = [0, 0, 0]\ndirection = [1, 0, 0]\n"
        );
        assert!(Vehicle::from_toml_str(&twice, "m").is_err());
        let bad = MINIMAL.replace("name = \"a\"", "name = \"a\"\ndeadband = 1.0");
        assert!(Vehicle::from_toml_str(&bad, "m").is_err());
        let heavy = "[body]\nmass_kg = -1.0\n";
        let err = Vehicle::from_toml_str(heavy, "m").unwrap_err().to_string();
        assert!(err.contains("body.mass_kg"), "{err}");
    }
}
