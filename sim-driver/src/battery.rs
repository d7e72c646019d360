//! The vehicle's battery: open-circuit voltage against state of charge, an internal
//! resistance that makes the terminal voltage sag under load, and a capacity the thrusters'
//! current drains over a dive.
//!
//! ```text
//! V = OCV(soc) - R (I_thrusters(V) + I_hotel)        solved for V each step (bisection:
//!                                                     the thrusters draw more at a higher V)
//! d(charge)/dt = -(I_thrusters(V) + I_hotel)          soc = charge / capacity, kept in [0, 1]
//! ```
//!
//! The default open-circuit curve is a generic LiPo/Li-ion cell at rest, 4.20 V full to
//! 3.30 V empty (a 4S pack: 16.8 V to 13.2 V, about 13.5 V when nearly empty); a vehicle file
//! may give its own. No temperature, no recovery after load, no ageing.

use serde::{Deserialize, Serialize};

use crate::load::{number, LoadError};
use thruster_driver_kit::load::Range;

/// A generic LiPo/Li-ion cell's open-circuit voltage at state of charge 0, 0.1, ..., 1 (V):
/// the flat middle and steep ends of published resting-voltage charts, rounded.
pub const LIPO_CELL_OCV_V: [f64; 11] = [
    3.30, 3.60, 3.70, 3.74, 3.77, 3.80, 3.84, 3.90, 3.97, 4.06, 4.20,
];

fn default_capacity_ah() -> f64 {
    18.0
}
fn default_cells() -> u32 {
    4
}
fn default_internal_resistance_ohm() -> f64 {
    0.02
}
fn default_initial_charge() -> f64 {
    1.0
}
fn default_hotel_current_a() -> f64 {
    1.0
}
fn default_cell_ocv_v() -> Vec<f64> {
    LIPO_CELL_OCV_V.to_vec()
}

/// `[battery]` of a vehicle file. Every key optional.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BatterySpec {
    /// Capacity, Ah, in (0, 1000]. Default 18 (a Blue Robotics 4S 18 Ah Li-ion pack).
    #[serde(default = "default_capacity_ah")]
    pub capacity_ah: f64,
    /// Cells in series, in [1, 14]. Default 4 (4S: 16.8 V full).
    #[serde(default = "default_cells")]
    pub cells: u32,
    /// Internal resistance of the pack with its wiring, ohm, in [0, 1]. Default 0.02 (8
    /// T200s at full thrust, ~190 A at 16 V, sag it by ~4 V).
    #[serde(default = "default_internal_resistance_ohm")]
    pub internal_resistance_ohm: f64,
    /// State of charge at the start, in [0, 1]. Default 1 (full).
    #[serde(default = "default_initial_charge")]
    pub initial_charge: f64,
    /// Current the rest of the vehicle draws (computer, lights, sensors), A, in [0, 100].
    /// Default 1.
    #[serde(default = "default_hotel_current_a")]
    pub hotel_current_a: f64,
    /// One cell's open-circuit voltage at state of charge 0, 1/(n-1), ..., 1, V, at least 2
    /// values, non-decreasing, each in [2, 5]. Default [`LIPO_CELL_OCV_V`].
    #[serde(default = "default_cell_ocv_v")]
    pub cell_ocv_v: Vec<f64>,
}

impl Default for BatterySpec {
    fn default() -> Self {
        BatterySpec {
            capacity_ah: default_capacity_ah(),
            cells: default_cells(),
            internal_resistance_ohm: default_internal_resistance_ohm(),
            initial_charge: default_initial_charge(),
            hotel_current_a: default_hotel_current_a(),
            cell_ocv_v: default_cell_ocv_v(),
        }
    }
}

impl BatterySpec {
    /// Checks every range; `text` (the file's, or "") locates the key in errors.
    pub fn validate(&self, origin: &str, text: &str) -> Result<(), LoadError> {
        let check = |key: &str, v: f64, range: Range| {
            if v.is_finite() && range.contains(v) {
                Ok(())
            } else {
                Err(LoadError::out_of_range(
                    origin,
                    text,
                    &format!("battery.{key}"),
                    range,
                    number(v),
                ))
            }
        };
        check(
            "capacity_ah",
            self.capacity_ah,
            Range::above_to(0.0, 1000.0),
        )?;
        check("cells", self.cells as f64, Range::closed(1.0, 14.0))?;
        check(
            "internal_resistance_ohm",
            self.internal_resistance_ohm,
            Range::closed(0.0, 1.0),
        )?;
        check(
            "initial_charge",
            self.initial_charge,
            Range::closed(0.0, 1.0),
        )?;
        check(
            "hotel_current_a",
            self.hotel_current_a,
            Range::closed(0.0, 100.0),
        )?;
        if self.cell_ocv_v.len() < 2 {
            return Err(LoadError::value(
                origin,
                text,
                "battery.cell_ocv_v",
                format!("needs at least 2 values, got {}", self.cell_ocv_v.len()),
            ));
        }
        for (i, v) in self.cell_ocv_v.iter().enumerate() {
            check(&format!("cell_ocv_v[{i}]"), *v, Range::closed(2.0, 5.0))?;
        }
        if self.cell_ocv_v.windows(2).any(|w| w[1] < w[0]) {
            return Err(LoadError::value(
                origin,
                text,
                "battery.cell_ocv_v",
                "must not decrease with the state of charge",
            ));
        }
        Ok(())
    }
}

/// A battery being discharged.
#[derive(Debug, Clone, PartialEq)]
pub struct Battery {
    spec: BatterySpec,
    charge_ah: f64,
    voltage_v: f64,
    current_a: f64,
}

impl Battery {
    /// A battery at its initial charge, at rest. `spec` must be validated.
    pub fn new(spec: BatterySpec) -> Battery {
        let charge_ah = spec.capacity_ah * spec.initial_charge;
        let mut b = Battery {
            spec,
            charge_ah,
            voltage_v: 0.0,
            current_a: 0.0,
        };
        b.voltage_v = b.open_circuit_v();
        b
    }

    /// The spec it was made from.
    pub fn spec(&self) -> &BatterySpec {
        &self.spec
    }

    /// State of charge, in [0, 1].
    pub fn state_of_charge(&self) -> f64 {
        (self.charge_ah / self.spec.capacity_ah).clamp(0.0, 1.0)
    }

    /// Open-circuit voltage at the present charge, V (linear between the curve's points).
    pub fn open_circuit_v(&self) -> f64 {
        let ocv = &self.spec.cell_ocv_v;
        let x = self.state_of_charge() * (ocv.len() - 1) as f64;
        let i = (x.floor() as usize).min(ocv.len() - 2);
        let cell = ocv[i] + (ocv[i + 1] - ocv[i]) * (x - i as f64);
        cell * self.spec.cells as f64
    }

    /// Terminal voltage after the last step, V.
    pub fn voltage_v(&self) -> f64 {
        self.voltage_v
    }

    /// Current drawn in the last step (thrusters and hotel load), A.
    pub fn current_a(&self) -> f64 {
        self.current_a
    }

    /// Solves the terminal voltage for the load `thrusters_a(V)` (A drawn by the thrusters at
    /// terminal voltage V; must not decrease with V) and drains `dt_s` seconds of it.
    pub fn step(&mut self, dt_s: f64, thrusters_a: impl Fn(f64) -> f64) {
        let ocv = self.open_circuit_v();
        let r = self.spec.internal_resistance_ohm;
        let hotel = self.spec.hotel_current_a;
        // g(V) = V - OCV + R I(V) rises with V: g(0) <= 0 <= g(OCV), so bisect. 40 halvings
        // of ~17 V are far below a microvolt.
        let (mut lo, mut hi) = (0.0, ocv);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if mid - ocv + r * (thrusters_a(mid) + hotel) > 0.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        self.voltage_v = 0.5 * (lo + hi);
        self.current_a = thrusters_a(self.voltage_v) + hotel;
        if dt_s.is_finite() && dt_s > 0.0 {
            self.charge_ah = (self.charge_ah - self.current_a * dt_s / 3600.0).max(0.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_and_empty_4s_voltages() {
        let full = Battery::new(BatterySpec::default());
        assert!((full.open_circuit_v() - 16.8).abs() < 1e-12);
        let empty = Battery::new(BatterySpec {
            initial_charge: 0.0,
            ..BatterySpec::default()
        });
        assert!((empty.open_circuit_v() - 13.2).abs() < 1e-12);
        let half = Battery::new(BatterySpec {
            initial_charge: 0.55,
            ..BatterySpec::default()
        });
        // Halfway between the 50 % (3.80 V) and 60 % (3.84 V) points, 4 cells.
        assert!((half.open_circuit_v() - 4.0 * 3.82).abs() < 1e-9);
    }

    #[test]
    fn sags_by_ir_under_a_constant_load() {
        let mut b = Battery::new(BatterySpec::default());
        b.step(0.0, |_| 99.0);
        // 100 A through 0.02 ohm: 2 V below 16.8 V.
        assert!((b.voltage_v() - 14.8).abs() < 1e-6, "{}", b.voltage_v());
        assert!((b.current_a() - 100.0).abs() < 1e-9);
        // A load that grows with voltage settles where V = OCV - R I(V): I = 10 V gives
        // V = 16.8 / (1 + 0.2) - 0.02 / 1.2 (hotel 1 A).
        b.step(0.0, |v| 10.0 * v);
        let expect = (16.8 - 0.02) / 1.2;
        assert!((b.voltage_v() - expect).abs() < 1e-6, "{}", b.voltage_v());
    }

    #[test]
    fn discharges_by_amp_hours() {
        let mut b = Battery::new(BatterySpec {
            capacity_ah: 2.0,
            hotel_current_a: 0.0,
            ..BatterySpec::default()
        });
        // 10 A for 6 min = 1 Ah of 2: half charge, 4 x 3.82 V open-circuit.
        for _ in 0..360 {
            b.step(1.0, |_| 10.0);
        }
        assert!((b.state_of_charge() - 0.5).abs() < 1e-9);
        assert!((b.open_circuit_v() - 4.0 * 3.80).abs() < 1e-9);
        // Drained past empty it stays at empty.
        for _ in 0..1000 {
            b.step(1.0, |_| 10.0);
        }
        assert_eq!(b.state_of_charge(), 0.0);
        assert!((b.open_circuit_v() - 13.2).abs() < 1e-12);
    }

    #[test]
    fn bad_values_name_the_key_and_line() {
        let spec = BatterySpec {
            internal_resistance_ohm: 2.0,
            ..BatterySpec::default()
        };
        let text = "name = \"x\"\n[battery]\ninternal_resistance_ohm = 2.0\n";
        let err = spec.validate("v.toml", text).unwrap_err().to_string();
        assert!(err.contains("v.toml:3:"), "{err}");
        assert!(err.contains("battery.internal_resistance_ohm"), "{err}");
        assert!(err.contains("[0, 1]"), "{err}");
    }
}
