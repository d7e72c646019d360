//! T200 thrusters on a battery: the simulator's thrust follows the published table at the
//! battery's voltage, the voltage sags by the table's current through the internal resistance,
//! and the charge drains by amp-hours.

use std::path::PathBuf;

use thruster_sim::{BatterySpec, SensorConfig, Simulator, Vehicle};
use thruster_table::ThrusterTable;

fn load(name: &str) -> Vehicle {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../config/vehicles")
        .join(format!("{name}.toml"));
    Vehicle::load(path).unwrap_or_else(|e| panic!("{e}"))
}

/// `amour5_t200` on an ideal pack that holds `volts` whatever the load.
fn at_fixed_voltage(volts: f64) -> Simulator {
    let mut v = load("amour5_t200");
    v.battery = Some(BatterySpec {
        cells: 4,
        cell_ocv_v: vec![volts / 4.0, volts / 4.0],
        internal_resistance_ohm: 0.0,
        hotel_current_a: 0.0,
        ..BatterySpec::default()
    });
    Simulator::new(v, SensorConfig::ideal(100.0), 1).expect("valid")
}

#[test]
fn thrust_at_12_volts_against_16_follows_the_data() {
    let table = ThrusterTable::t200();
    let commands = [0.6, -0.6, 1.0, -1.0, 0.3];
    let thrust = |volts: f64| {
        let mut sim = at_fixed_voltage(volts);
        sim.set_commands(&commands).unwrap();
        sim.step_secs(1.5);
        assert!((sim.supply_voltage_v() - volts).abs() < 1e-9);
        sim.thrusts_n()
    };
    let (t12, t16) = (thrust(12.0), thrust(16.0));
    for (i, u) in commands.iter().enumerate() {
        let data = table.thrust_at_command(16.0, *u) / table.thrust_at_command(12.0, *u);
        let sim = t16[i] / t12[i];
        // After 15 time constants the lag is gone to 3e-7.
        assert!((sim - data).abs() < 1e-5, "u {u}: sim {sim}, data {data}");
        assert!((1.3..1.7).contains(&sim), "u {u}: {sim}");
    }
    // Full forward at 16 V is the data's 5.245 kgf (the sign is the thruster's direction).
    assert!((t16[2].abs() - 5.24504 * thruster_table::KGF_N).abs() < 1e-3);
    // The truth follows the voltage the same way: full-command columns scale by the ratio.
    let (b12, _) = at_fixed_voltage(12.0).truth();
    let (b16, _) = at_fixed_voltage(16.0).truth();
    let ratio = table.thrust_at_command(16.0, 1.0) / table.thrust_at_command(12.0, 1.0);
    assert!(((b16.norm() / b12.norm()) - ratio).abs() < 1e-9);
}

#[test]
fn the_voltage_sags_by_the_tables_current_through_the_resistance() {
    let mut sim = Simulator::new(load("amour5_t200"), SensorConfig::ideal(100.0), 1).unwrap();
    // At rest only the 1 A hotel load: 16.8 V less 0.02 V.
    assert!((sim.supply_voltage_v() - 16.78).abs() < 1e-9);
    sim.set_commands(&[1.0; 5]).unwrap();
    let v = sim.supply_voltage_v();
    let table = ThrusterTable::t200();
    let amps = 5.0 * table.current_at_command(v, 1.0) + 1.0;
    // V = OCV - R I(V) solved: five T200s at full draw ~105 A there, 2.2 V of sag at 0.02 ohm.
    assert!((v - (16.8 - 0.02 * amps)).abs() < 1e-6, "{v} V, {amps} A");
    assert!((14.3..14.9).contains(&v), "{v}");
    let b = sim.battery().unwrap();
    assert!((b.current_a() - amps).abs() < 1e-6);
    // Back to neutral the voltage recovers to the open-circuit one less the hotel load.
    sim.set_commands(&[0.0; 5]).unwrap();
    assert!((sim.supply_voltage_v() - (16.8 - 0.02)).abs() < 1e-6);
}

#[test]
fn a_dive_drains_the_charge_and_the_voltage_falls() {
    let mut v = load("amour5_t200");
    let spec = v.battery.as_mut().unwrap();
    spec.capacity_ah = 1.0;
    spec.hotel_current_a = 0.0;
    let mut sim = Simulator::new(v, SensorConfig::ideal(100.0), 1).unwrap();
    sim.set_commands(&[0.5; 5]).unwrap();
    let v_start = sim.supply_voltage_v();
    let i_start = sim.battery().unwrap().current_a();
    sim.step_secs(120.0);
    let b = sim.battery().unwrap();
    // About 5 x 5 A for 2 min of 1 Ah: 0.8 Ah left; the current falls with the voltage,
    // so the charge drawn lies between the end current's and the start's.
    let drawn = 1.0 - b.state_of_charge();
    assert!(
        drawn <= i_start * 120.0 / 3600.0 + 1e-9 && drawn >= b.current_a() * 120.0 / 3600.0,
        "drawn {drawn} Ah, current {i_start} -> {} A",
        b.current_a()
    );
    assert!(
        sim.supply_voltage_v() < v_start - 0.2,
        "{v_start} -> {}",
        sim.supply_voltage_v()
    );
}

#[test]
fn vehicles_without_a_battery_keep_the_fixed_supply() {
    let sim = Simulator::new(load("amour5"), SensorConfig::ideal(100.0), 1).unwrap();
    assert!(sim.battery().is_none());
    assert_eq!(sim.supply_voltage_v(), 16.0);
    // The power law's truth: full forward is forward_max_n on each column.
    let (fwd, _) = sim.truth();
    let (fwd16, _) = sim.truth_at(12.0);
    assert_eq!(
        fwd, fwd16,
        "a power-law thruster does not depend on the voltage"
    );
}
