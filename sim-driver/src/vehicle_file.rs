//! Loading a vehicle file: parsed, every value checked where it is written (file:line:col),
//! and what the driver will publish about the vehicle checked against the protocol's
//! bounds. Apart from `vehicle.rs` (the format's types) because the last check needs the
//! rigid body and the effectiveness, which are built from those types.

use std::collections::HashSet;
use std::path::Path;

use thruster_protocol::validate::limits::{MAX_EFFECTIVENESS, MAX_POSITION_M};
// The largest thruster count a vehicle may have is the protocol's (the fixed capacity of its
// messages), so every simulated vehicle can be driven by the daemon.
use thruster_protocol::MAX_THRUSTERS;
use thruster_table::ThrusterTable;

use crate::dynamics::RigidBody;
use crate::effectiveness::effectiveness_at;
use crate::load::{number, parse_toml, read_text, Checker, LoadError, Range};
use crate::thruster::FIXED_SUPPLY_V;
use crate::vehicle::Vehicle;

impl Vehicle {
    /// Loads and validates a vehicle file.
    pub fn load(path: impl AsRef<Path>) -> Result<Vehicle, LoadError> {
        let path = path.as_ref();
        let text = read_text(path)?;
        Vehicle::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses and validates TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Vehicle, LoadError> {
        let mut vehicle: Vehicle = parse_toml(text, origin)?;
        // With the text at hand, a bad value is located (file:line:col).
        vehicle.check(&Checker::new(origin, text))?;
        Ok(vehicle)
    }

    /// Checks every value, 1 to [`MAX_THRUSTERS`] thrusters with unique names, and that what
    /// is published about them can be: positions within the protocol's `MAX_POSITION_M` of
    /// the centre of gravity, effectiveness within its `MAX_EFFECTIVENESS`. Normalises
    /// thruster directions.
    pub fn validate(&mut self, origin: &str) -> Result<(), LoadError> {
        self.check(&Checker::new(origin, ""))
    }

    pub(crate) fn check(&mut self, c: &Checker) -> Result<(), LoadError> {
        self.body.check(c)?;
        if let Some(b) = &self.battery {
            b.validate(c.origin, c.text)?;
        }
        let n = self.thrusters.len();
        if !(1..=MAX_THRUSTERS).contains(&n) {
            return Err(c.error(
                "thruster",
                "thruster",
                format!("the number of thrusters ([[thruster]] tables) must be in [1, {MAX_THRUSTERS}], got {n}"),
            ));
        }
        let mut names = HashSet::new();
        for (i, t) in self.thrusters.iter_mut().enumerate() {
            t.check(c, &format!("thruster[{i}]"))?;
            if !names.insert(t.name.clone()) {
                let key = format!("thruster[{i}].name");
                return Err(c.error(&key, &key, format!("{:?} is used twice", t.name)));
            }
        }
        self.check_publishable(c)
    }

    /// What the driver publishes about the thrusters must pass the protocol's validation:
    /// the declared positions (from the centre of gravity) and the true effectiveness, at the
    /// highest supply voltage the T200 table knows (the most a `t200` thruster can give).
    fn check_publishable(&self, c: &Checker) -> Result<(), LoadError> {
        let cg = self.body.cg_m;
        for (i, t) in self.thrusters.iter().enumerate() {
            for (k, (p, g)) in t.position_m.iter().zip(cg).enumerate() {
                let range = Range::closed(g - MAX_POSITION_M, g + MAX_POSITION_M);
                if !range.contains(*p) {
                    return Err(c.error(
                        &format!("thruster[{i}].position_m[{k}]"),
                        &format!("thruster[{i}] ({:?}).position_m[{k}]", t.name),
                        format!(
                            "must be in {range} (within {MAX_POSITION_M} m of body.cg_m), got {p}"
                        ),
                    ));
                }
            }
        }
        let body = RigidBody::new(&self.body)?;
        let supply_v = ThrusterTable::t200().voltage_range().1.max(FIXED_SUPPLY_V);
        let (fwd, rev) = effectiveness_at(body.mass_matrix_inverse(), &self.thrusters, supply_v);
        const DOFS: [(&str, &str); 6] = [
            ("roll", "rad/s^2"),
            ("pitch", "rad/s^2"),
            ("yaw", "rad/s^2"),
            ("surge", "m/s^2"),
            ("sway", "m/s^2"),
            ("heave", "m/s^2"),
        ];
        for (i, t) in self.thrusters.iter().enumerate() {
            for (b, field, thrust) in [
                (&fwd, "forward_max_n", t.forward_max_n),
                (&rev, "reverse_max_n", t.reverse_max_n),
            ] {
                for (row, v) in b.column(i).iter().enumerate() {
                    if v.abs() <= MAX_EFFECTIVENESS {
                        continue;
                    }
                    let (dof, unit) = DOFS[row];
                    return Err(c.error(
                        &format!("thruster[{i}].{field}"),
                        &format!("thruster[{i}] ({:?}).{field}", t.name),
                        format!(
                            "{} N accelerates this body by {} {unit} in {dof}, more than the \
                             {MAX_EFFECTIVENESS} per unit command the protocol accepts: lower \
                             it, or check body mass and inertia",
                            number((thrust * 10.0).round() / 10.0),
                            number((v.abs() * 10.0).round() / 10.0),
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}
