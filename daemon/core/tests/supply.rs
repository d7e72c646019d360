//! The model holds across the battery: AMOUR-5 with T200 thrusters (the measured table),
//! estimated noise-free in-process at a 12 V supply with the voltage reported to the machine
//! learns the same B as at the 16 V reference; without the reading it learns the 12 V
//! thrusters, ~1.4x weaker (the table's ratio). Every command the harness sees is checked
//! finite and in [-1, 1].

mod common;

use common::{rel_err, vehicle, Run};
use nalgebra::DMatrix;
use thruster_protocol::SupplyCompensation;
use thruster_sim::{BatterySpec, NoisePreset};
use thruster_table::ThrusterTable;
use thrusterd_core::machine::{Machine, MachineSetup, State};
use thrusterd_core::supply::{Supply, SupplyConfig};

/// `amour5_t200` on an ideal pack holding `volts`; the machine told `reported` (or nothing),
/// its pulses at `power`.
fn run(volts: f64, reported: Option<f64>) -> Run {
    run_at(volts, reported, 0.7)
}

fn run_at(volts: f64, reported: Option<f64>, power: f64) -> Run {
    let mut v = vehicle("amour5_t200");
    v.battery = Some(BatterySpec {
        cells: 4,
        cell_ocv_v: vec![volts / 4.0; 2],
        internal_resistance_ohm: 0.0,
        hotel_current_a: 0.0,
        ..BatterySpec::default()
    });
    let mut run = Run::with_vehicle(v, NoisePreset::None, 1, 200.0);
    let mut setup = MachineSetup {
        thrusters: run.sim.thruster_count(),
        ..MachineSetup::default()
    };
    // The T200's dead zone is about +-28 us of +-400 at 16 V: jumped by the machine, as for a
    // driver that does not.
    setup.machine.deadband = 0.07;
    // One pulse power for every run, within what 12 V can give referred to 16 V: the T200's
    // curve is not linear, so the gain a linear model learns depends on the power (the
    // machine caps the power at the attainable one; here it need not).
    setup.estimator.initial_power = power;
    setup.estimator.max_power = power;
    // An ideal pack, read once: it does not sag, and the machine is told so (no readings
    // would ever show its line).
    setup.supply.sag_prior_ohm = 0.0;
    run.machine = Machine::new(setup);
    // Told once, here, not by the harness's driver-like reports.
    run.supply_report_ns = None;
    run.machine.on_supply(reported);
    run
}

fn learned(run: &mut Run) -> DMatrix<f64> {
    run.run_for(1.0);
    run.estimate();
    assert_eq!(
        run.machine.state(),
        State::Active,
        "no model: {}",
        run.machine.status().text
    );

    run.machine.model().unwrap().effectiveness.clone()
}

#[test]
fn the_model_learned_at_12_v_with_the_reading_is_the_16_v_model() {
    let mut at16 = run(16.0, Some(16.0));
    let b16 = learned(&mut at16);
    let mut at12 = run(12.0, Some(12.0));
    assert_eq!(at12.machine.status().supply, SupplyCompensation::Active);
    let b12 = learned(&mut at12);
    let mut blind = run(12.0, None);
    assert_eq!(blind.machine.status().supply, SupplyCompensation::NoReading);
    let b12_blind = learned(&mut blind);

    let (d_rot, d_acc) = (rel_err(&b12, &b16, 0), rel_err(&b12, &b16, 3));
    let (u_rot, u_acc) = (rel_err(&b12_blind, &b16, 0), rel_err(&b12_blind, &b16, 3));
    let ratio = b16.rows(0, 3).norm() / b12_blind.rows(0, 3).norm();
    let table = ThrusterTable::t200();
    let data = table.thrust_at_command(16.0, 1.0) / table.thrust_at_command(12.0, 1.0);
    println!(
        "referred: rot {d_rot:.4} acc {d_acc:.4}; unreferred: rot {u_rot:.4} acc {u_acc:.4}; \
         |B16|/|B12 unreferred| {ratio:.3} (table at full command {data:.3})"
    );
    // Referred to 16 V the 12 V model is the 16 V one (the table's 4 us steps and the
    // trajectories' small differences are what is left).
    assert!(d_rot < 0.03 && d_acc < 0.03, "rot {d_rot}, acc {d_acc}");
    // Unreferred it is the weaker 12 V thruster, by about the table's ratio.
    assert!(u_rot > 0.2 && u_acc > 0.2, "rot {u_rot}, acc {u_acc}");
    assert!((1.3..1.6).contains(&ratio), "{ratio}");
}

/// Full power at 12 V cannot be referred to 16 V: the machine caps the pulses at what 12 V
/// gives, so the model is the 16 V one at that power, not a saturated mixture.
#[test]
fn at_full_power_the_pulses_are_capped_at_what_the_voltage_gives() {
    let mut at12 = run_at(12.0, Some(12.0), 1.0);
    let b12 = learned(&mut at12);
    let mut s = Supply::new(SupplyConfig::default());
    s.on_voltage(Some(12.0));
    let cap = (s.attainable() - 0.07) / (1.0 - 0.07);
    assert!((0.6..0.95).contains(&cap), "{cap}");
    // Never beyond what 12 V gives: the largest command out is within full scale but the
    // referred ones stayed below it.
    assert!(at12.max_abs_cmd <= 1.0);
    let mut at16 = run_at(16.0, Some(16.0), cap);
    let b16 = learned(&mut at16);
    let (d_rot, d_acc) = (rel_err(&b12, &b16, 0), rel_err(&b12, &b16, 3));
    println!("capped at {cap:.3}: rot {d_rot:.4} acc {d_acc:.4}");
    assert!(d_rot < 0.01 && d_acc < 0.01, "rot {d_rot}, acc {d_acc}");
}

/// Holds level for `hold_s` on a pack that drains fast (a 30 A hotel load on 0.5 Ah: full to
/// empty in about a minute), after learning at full charge; the machine is told every
/// sample's voltage when `compensate`, else nothing. Returns the refinements made and how far
/// the model in force moved from the learned one (rotation rows, relative).
fn hold_while_draining(
    compensate: bool,
    hold_s: f64,
    drain: bool,
) -> (u32, DMatrix<f64>, f64, f64) {
    let mut v = vehicle("amour5_t200");
    let b = v.battery.as_mut().unwrap();
    if drain {
        b.capacity_ah = 0.5;
        b.hotel_current_a = 30.0;
    } else {
        b.capacity_ah = 1000.0;
        b.hotel_current_a = 30.0;
    }
    let mut r = Run::with_vehicle(v, NoisePreset::None, 1, 200.0);
    let mut setup = MachineSetup {
        thrusters: r.sim.thruster_count(),
        ..MachineSetup::default()
    };
    setup.machine.deadband = 0.07;
    setup.estimator.initial_power = 0.6;
    setup.estimator.max_power = 0.6;
    r.machine = Machine::new(setup);
    // Told here, every sample or never, not by the harness's driver-like reports.
    r.supply_report_ns = None;
    r.machine.on_supply(Some(r.sim.supply_voltage_v()));
    let v_start = r.sim.supply_voltage_v();
    let b0 = learned(&mut r);
    if !compensate {
        r.machine.on_supply(None);
    }
    let end = r.sim.time_s() + hold_s;
    while r.sim.time_s() < end {
        if compensate {
            r.machine.on_supply(Some(r.sim.supply_voltage_v()));
        }
        r.tick();
    }
    let model = r.machine.model().unwrap();
    let _ = b0;
    (
        model.refinements,
        model.effectiveness.clone(),
        v_start,
        r.sim.supply_voltage_v(),
    )
}

#[test]
fn a_draining_battery_is_not_a_weakening_thruster() {
    // The refinement moves a T200 model on a steady pack too (it learns the gain about the
    // hover commands, the curve is not linear): the reference is where it ends on a pack that
    // does not drain.
    let (n_steady, b_steady, _, _) = hold_while_draining(true, 60.0, false);
    let (n_comp, b_comp, v0, v1) = hold_while_draining(true, 60.0, true);
    let (n_blind, b_blind, _, _) = hold_while_draining(false, 60.0, true);
    let d_comp = rel_err(&b_comp, &b_steady, 0);
    let d_blind = rel_err(&b_blind, &b_steady, 0);
    let ratio = |b: &DMatrix<f64>| b.rows(0, 3).norm() / b_steady.rows(0, 3).norm();
    println!(
        "{v0:.2} V -> {v1:.2} V; refinements steady {n_steady}, compensated {n_comp}, \
         uncompensated {n_blind}; against the steady pack's model: compensated {d_comp:.3} \
         (|B| x{:.3}), uncompensated {d_blind:.3} (|B| x{:.3})",
        ratio(&b_comp),
        ratio(&b_blind)
    );
    assert!(v0 - v1 > 2.5, "the pack drained: {v0} -> {v1}");
    // Measured (noise-free, seed 1): compensated 0.099 away, |B| x1.095 (one refinement
    // instead of two, and near empty the top of the command range saturates); uncompensated
    // 0.294 away, |B| x0.716: it learned the battery.
    assert!(d_comp < 0.15, "compensated {d_comp}");
    assert!(d_blind > 2.0 * d_comp, "uncompensated {d_blind}");
    assert!((0.9..1.15).contains(&ratio(&b_comp)), "{}", ratio(&b_comp));
    assert!(ratio(&b_blind) < 0.8, "{}", ratio(&b_blind));
}

/// A T200 vehicle on the shipped 4S pack (20 mOhm: 2-3 V of sag under the pulses), the
/// voltage reported every `report_ms` as thruster-sim's driver does, commands linearized
/// through the T200's curve; noise-free. Returns the model against the truth at the 16 V
/// reference (err_rot, err_acc), and the lowest voltage seen.
fn sagging(name: &str, report_ms: Option<u64>, resistance_ohm: f64, power: f64) -> (f64, f64, f64) {
    let mut v = vehicle(name);
    v.battery.as_mut().unwrap().internal_resistance_ohm = resistance_ohm;
    let mut r = Run::with_vehicle(v, NoisePreset::None, 1, 200.0);
    let mut setup = MachineSetup {
        thrusters: r.sim.thruster_count(),
        ..MachineSetup::default()
    };
    setup.supply.linearize = true;
    setup.estimator.initial_power = power;
    r.machine = Machine::new(setup);
    r.supply_report_ns = report_ms.map(|ms| ms * 1_000_000);
    r.run_for(3.0);
    r.machine
        .on_request(thrusterd_core::machine::Request::Estimate)
        .unwrap();
    let mut lowest = f64::INFINITY;
    let start = r.sim.time_s();
    while r.machine.state() != State::Active && r.sim.time_s() - start < 60.0 {
        r.tick();
        lowest = lowest.min(r.sim.supply_voltage_v());
    }
    assert_eq!(r.machine.state(), State::Active, "no model");
    let b = r.machine.model().unwrap().effectiveness.clone();
    let (fwd, rev) = r.sim.truth_at(16.0);
    let truth = (fwd + rev) * 0.5;
    (rel_err(&b, &truth, 0), rel_err(&b, &truth, 3), lowest)
}

/// The pack sags 2-3 V under the pulses and the driver reports its voltage every 100 ms:
/// the machine predicts the sag from the readings and caps the pulses at what the thrusters
/// give under it, so the model is the one learned without sag. Before (commands referred to
/// the last reading, pulses capped at the resting voltage's power): AMOUR-5 0.060 / 0.066,
/// eight_vectored 0.092 / 0.092, every pulse at full power saturating at 13.6-14.6 V.
#[test]
fn a_sagging_pack_read_every_100_ms_is_not_taken_for_weaker_thrusters() {
    for name in ["amour5_t200", "eight_vectored_t200"] {
        let (rot0, acc0, _) = sagging(name, Some(100), 0.0, 1.0);
        let (rot, acc, lowest) = sagging(name, Some(100), 0.02, 1.0);
        println!(
            "{name}: without sag {rot0:.4} / {acc0:.4}; sagging to {lowest:.2} V {rot:.4} / {acc:.4}"
        );
        // Measured: AMOUR-5 0.0131 / 0.0100 without sag, 0.0155 / 0.0147 sagging to 14.67 V;
        // eight_vectored 0.0143 / 0.0148, 0.0153 / 0.0157 at 13.69 V.
        assert!(lowest < 15.0, "the pack sagged: {lowest}");
        assert!(rot < 0.02 && acc < 0.02, "{name}: {rot} / {acc}");
        assert!(
            (rot - rot0).abs() < 0.005 && (acc - acc0).abs() < 0.007,
            "{name}: {rot} / {acc} against {rot0} / {acc0} without sag"
        );
    }
}
