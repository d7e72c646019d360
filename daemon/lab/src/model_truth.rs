//! The truth a learned model is scored against: the simulator's effectiveness at the supply
//! voltage the model describes.
//!
//! The simulator publishes its truth at the battery's present voltage (a T200's thrust follows
//! it). A daemon that refers its commands to a reference voltage (`[supply]`, a reading from
//! the driver) or linearizes them through the T200's table learns the thrusters *at the
//! reference*: scored against the present voltage's truth, a right model reads 3-7 % off (a 4S
//! pack at 15-16.8 V against 16 V), and a wrong one can read right. So the lab computes the
//! truth at the model's voltage from the same vehicle file with the simulator's own function,
//! after checking that this file gives the published truth at the published voltage (the
//! simulator runs what the lab thinks it runs). Power-law thrusters do not depend on the
//! voltage: their truth is the published one.

use std::path::Path;

use anyhow::{bail, Result};
use nalgebra::DMatrix;
use thruster_protocol::{TruthMsg, DOF_COUNT};
use thruster_sim::{SensorConfig, Simulator};
use thrusterd_core::supply::{Supply, SupplyConfig};

/// The truth a model learned under `supply` is scored against: `published` carried to the
/// voltage the model describes ([`model_voltage_v`]).
pub fn truth_for_model(
    vehicle_file: &Path,
    supply: &SupplyConfig,
    published: &TruthMsg,
) -> Result<TruthMsg> {
    truth_at(vehicle_file, published, model_voltage_v(supply, published))
}

/// The voltage whose truth a model learned under `supply` describes: the daemon's reference
/// when it referred or linearized its commands, else the thrusters' present one. The
/// simulator's driver reports the voltage exactly when it models a battery (`battery`), and
/// the daemon's own `Supply` decides what it does with the reading.
pub fn model_voltage_v(supply: &SupplyConfig, published: &TruthMsg) -> f64 {
    let mut s = Supply::new(supply.clone());
    s.on_voltage((published.battery == 1).then_some(published.supply_voltage_v));
    s.model_voltage_v().unwrap_or(published.supply_voltage_v)
}

/// `published` carried to `voltage_v` for the vehicle in `vehicle_file`; the published message
/// itself when the voltages agree or no thruster depends on the voltage.
pub fn truth_at(vehicle_file: &Path, published: &TruthMsg, voltage_v: f64) -> Result<TruthMsg> {
    if (voltage_v - published.supply_voltage_v).abs() < 1e-9 {
        return Ok(*published);
    }
    let vehicle = crate::vehicle::load(vehicle_file)?;
    let sim = Simulator::new(vehicle, SensorConfig::default(), 0)?;
    let n = published.thruster_count();
    let (fwd, rev) = sim.truth_at(published.supply_voltage_v);
    if fwd.ncols() != n {
        bail!(
            "{}: {} thrusters, the simulator's truth has {n}",
            vehicle_file.display(),
            fwd.ncols()
        );
    }
    let off = max_difference(&fwd, &published.effectiveness, n).max(max_difference(
        &rev,
        &published.reverse_effectiveness,
        n,
    ));
    let scale = fwd.amax().max(1e-12);
    if off > 1e-6 * scale {
        bail!(
            "{}: the file's effectiveness at {:.3} V differs from the simulator's published truth \
             by {off:.3e} (the simulator runs another vehicle or was reconfigured)",
            vehicle_file.display(),
            published.supply_voltage_v
        );
    }
    let (fwd, rev) = sim.truth_at(voltage_v);
    let mut out = *published;
    for j in 0..DOF_COUNT {
        for i in 0..n {
            out.effectiveness[j][i] = fwd[(j, i)];
            out.reverse_effectiveness[j][i] = rev[(j, i)];
        }
    }
    out.supply_voltage_v = voltage_v;
    Ok(out)
}

fn max_difference(
    m: &DMatrix<f64>,
    published: &[[f64; thruster_protocol::MAX_THRUSTERS]; DOF_COUNT],
    n: usize,
) -> f64 {
    (0..DOF_COUNT)
        .flat_map(|j| (0..n).map(move |i| (j, i)))
        .map(|(j, i)| (m[(j, i)] - published[j][i]).abs())
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use thrusterd_core::supply::CompensationModel;

    fn file(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../config/vehicles/{name}.toml"))
    }

    fn published(name: &str, v: f64) -> TruthMsg {
        let vehicle = crate::vehicle::load(&file(name)).unwrap();
        let sim = Simulator::new(vehicle, SensorConfig::default(), 0).unwrap();
        let (fwd, rev) = sim.truth_at(v);
        let mut t = TruthMsg {
            count: fwd.ncols() as u32,
            supply_voltage_v: v,
            battery: 1,
            ..TruthMsg::default()
        };
        for j in 0..DOF_COUNT {
            for i in 0..fwd.ncols() {
                t.effectiveness[j][i] = fwd[(j, i)];
                t.reverse_effectiveness[j][i] = rev[(j, i)];
            }
        }
        t
    }

    #[test]
    fn the_model_voltage_is_the_reference_only_when_commands_are_referred_or_linearized() {
        let battery = TruthMsg {
            supply_voltage_v: 15.2,
            battery: 1,
            ..TruthMsg::default()
        };
        let fixed = TruthMsg {
            battery: 0,
            ..battery
        };
        let on = SupplyConfig::default();
        assert_eq!(model_voltage_v(&on, &battery), 16.0);
        assert_eq!(model_voltage_v(&on, &fixed), 15.2);
        let linear = SupplyConfig {
            linearize: true,
            ..SupplyConfig::default()
        };
        assert_eq!(model_voltage_v(&linear, &fixed), 16.0);
        let off = SupplyConfig {
            compensation: CompensationModel::None,
            ..SupplyConfig::default()
        };
        assert_eq!(model_voltage_v(&off, &battery), 15.2);
    }

    #[test]
    fn a_t200_truth_is_carried_to_the_reference_and_a_power_law_one_is_not() {
        let t = truth_at(&file("amour5_t200"), &published("amour5_t200", 15.0), 16.0).unwrap();
        let at16 = published("amour5_t200", 16.0);
        assert_eq!(t.effectiveness, at16.effectiveness);
        assert_eq!(t.reverse_effectiveness, at16.reverse_effectiveness);
        // The T200 gives more at 16 V than at 15 V.
        let p = published("amour5_t200", 15.0);
        assert!(t.effectiveness[1][0] > 1.03 * p.effectiveness[1][0]);
        let pl = truth_at(&file("amour5"), &published("amour5", 15.0), 16.0).unwrap();
        assert_eq!(pl.effectiveness, published("amour5", 15.0).effectiveness);
        // Another vehicle's truth is refused, not scored against.
        let err = truth_at(&file("amour5_t200"), &published("amour5", 15.0), 16.0).unwrap_err();
        assert!(err.to_string().contains("differs"), "{err}");
    }
}
