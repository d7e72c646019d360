//! The vehicle files of config/vehicles and what their true effectiveness says; scenario
//! reconfiguration.

use std::path::PathBuf;

use thruster_sim::{
    effectiveness::rank, random_vehicle, Action, ChangeKind, Scenario, SensorConfig, Simulator,
    ThrusterSpec, Vehicle,
};

fn vehicles_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/vehicles")
}

fn load(name: &str) -> Vehicle {
    Vehicle::load(vehicles_dir().join(format!("{name}.toml"))).unwrap_or_else(|e| panic!("{e}"))
}

fn sim(vehicle: Vehicle) -> Simulator {
    Simulator::new(vehicle, SensorConfig::ideal(100.0), 1).expect("valid")
}

const ROWS: [&str; 6] = ["roll", "pitch", "yaw", "surge", "sway", "heave"];

#[test]
fn every_vehicle_file_loads_with_the_expected_rank() {
    let expected = [
        ("four_up", 4, 3),
        ("amour5", 5, 5),
        ("amour5_top45", 5, 5),
        ("aligned", 5, 3),
        ("six_dof", 6, 6),
        ("eight_vectored", 8, 6),
        ("amour5_lag30ms", 5, 5),
        ("amour5_lag200ms", 5, 5),
        ("eight_vectored_lag200ms", 8, 6),
        ("eight_vectored_lag80ms_curve", 8, 6),
        ("amour5_t200", 5, 5),
        ("eight_vectored_t200", 8, 6),
        ("amour5_reverse60", 5, 5),
        ("amour5_two_makes", 5, 5),
        ("eight_vectored_two_makes", 8, 6),
        ("eight_vectored_lag100_120ms", 8, 6),
    ];
    let mut seen = 0;
    for entry in std::fs::read_dir(vehicles_dir()).expect("config/vehicles") {
        let path = entry.expect("entry").path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let vehicle = Vehicle::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default();
        assert_eq!(vehicle.name, stem, "name should match the file name");
        let (n, r) = expected
            .iter()
            .find(|(name, _, _)| *name == stem)
            .map(|(_, n, r)| (*n, *r))
            .unwrap_or_else(|| panic!("no expectation for {stem}: add it to this test"));
        assert_eq!(vehicle.thrusters.len(), n, "{stem}");
        let (fwd, rev) = sim(vehicle).truth();
        assert_eq!(rank(&fwd, 1e-6), r, "{stem}: {fwd}");
        assert_eq!(rank(&rev, 1e-6), r, "{stem}");
        seen += 1;
    }
    assert_eq!(seen, expected.len());
}

#[test]
fn aligned_configuration_cannot_roll_sway_or_heave() {
    let (fwd, rev) = sim(load("aligned")).truth();
    for b in [&fwd, &rev] {
        for row in [0, 4, 5] {
            assert!(
                b.row(row).norm() < 1e-12,
                "{} row: {}",
                ROWS[row],
                b.row(row)
            );
        }
        for row in [1, 2, 3] {
            assert!(
                b.row(row).norm() > 0.1,
                "{} row should be actuated",
                ROWS[row]
            );
        }
    }
}

#[test]
fn four_up_cannot_yaw_surge_or_sway_much() {
    let (fwd, _) = sim(load("four_up")).truth();
    assert!(fwd.row(2).norm() < 1e-12, "no yaw");
    // The CG below the CO couples pitch into a little surge and roll into a little sway;
    // neither is an independent DOF (rank 3).
    assert!(fwd.row(3).norm() < 0.02 * fwd.row(1).norm());
    assert!(fwd.row(4).norm() < 0.02 * fwd.row(0).norm());
    assert!(fwd.row(5).iter().all(|a| *a < 0.0), "all push up (-z)");
}

#[test]
fn rotating_the_top_thruster_changes_truth_to_amour5_top45() {
    let mut s = sim(load("amour5"));
    let before = s.truth().0;
    let change = s
        .apply(&Action::Rotate {
            thruster: "T".into(),
            axis: [1.0, 0.0, 0.0],
            angle_deg: 45.0,
        })
        .expect("applies");
    assert_eq!(change.kind, ChangeKind::Moved);
    assert_eq!(change.index, 0);
    let after = s.truth().0;
    let reference = sim(load("amour5_top45")).truth().0;
    assert!((after.clone() - reference).norm() < 1e-12);
    // Only T's column moved, and it now yaws the vehicle.
    assert!((after.column(0) - before.column(0)).norm() > 1.0);
    assert!((after.columns(1, 4) - before.columns(1, 4)).norm() < 1e-12);
    assert!(before[(2, 0)].abs() < 1e-12 && after[(2, 0)].abs() > 1.0);
}

#[test]
fn scenario_events_apply_in_order() {
    let text = r#"
[[event]]
t_s = 1.0
action = { kind = "kill", thruster = "L" }

[[event]]
t_s = 2.0
announce = false
action = { kind = "move", thruster = "R", position_m = [0.1, 0.25, 0.0] }

[[event]]
t_s = 3.0
action = { kind = "remove", thruster = "LB" }

[[event]]
t_s = 4.0
[event.action]
kind = "add"
spec = { name = "S", position_m = [0, 0, 0.1], direction = [0, 2, 0], reversed = true }
"#;
    let mut scenario = Scenario::from_toml_str(text, "test scenario").expect("valid");
    let mut s = sim(load("amour5"));
    let mut changes = Vec::new();
    while s.time_s() < 5.0 {
        s.step(10_000_000);
        for event in scenario.due(s.time_ns()) {
            changes.push((event.announce, s.apply(&event.action).expect("applies")));
        }
    }
    let kinds: Vec<_> = changes.iter().map(|(_, c)| c.kind).collect();
    assert_eq!(
        kinds,
        [
            ChangeKind::Killed,
            ChangeKind::Moved,
            ChangeKind::Removed,
            ChangeKind::Added
        ]
    );
    assert!(!changes[1].0);
    assert_eq!(changes[2].1.index, 1);
    assert_eq!(s.thruster_count(), 5);
    let (fwd, _) = s.truth();
    let names: Vec<_> = s
        .vehicle()
        .thrusters
        .iter()
        .map(|t| t.name.as_str())
        .collect();
    assert_eq!(names, ["T", "RB", "L", "R", "S"]);
    assert_eq!(fwd.column(2).norm(), 0.0, "L is dead");
    assert!(fwd[(4, 4)] < 0.0, "S is reversed: pushes to port");
    assert_eq!(s.vehicle().thrusters[4].direction, [0.0, 1.0, 0.0]);
    assert!(s.set_commands(&[0.0; 5]).is_ok());
    // Errors: unknown and duplicate names.
    assert!(s
        .apply(&Action::Kill {
            thruster: "nope".into()
        })
        .is_err());
    let dup = ThrusterSpec::new("S", [0.0; 3], [1.0, 0.0, 0.0]);
    assert!(s.apply(&Action::Add { spec: dup }).is_err());
}

#[test]
fn an_action_that_would_break_the_vehicle_is_refused_and_changes_nothing() {
    let mut s = sim(load("amour5"));
    let weaken = |factor| Action::Weaken {
        thruster: "T".into(),
        factor,
    };
    s.apply(&weaken(10.0))
        .expect("515 N is within what the body takes");
    // Each step is within its own range, but together they would give the body more than
    // the protocol's truth can carry (or a scenario's dry run would find that they do).
    let e = s.apply(&weaken(10.0)).unwrap_err().to_string();
    assert!(
        e.starts_with("scenario action: thruster[0] (\"T\").forward_max_n: 5148.5")
            && e.contains("pitch"),
        "{e}"
    );
    assert!((s.vehicle().thrusters[0].forward_max_n - 514.85).abs() < 0.01);
    let (fwd, rev) = s.truth();
    assert!(fwd.amax() <= 1e3 && rev.amax() <= 1e3);
    let e = s
        .apply(&Action::Move {
            thruster: "L".into(),
            position_m: [0.0, 0.0, 10.5],
        })
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "scenario action: thruster[3] (\"L\").position_m[2]: must be in [-10, 10], got 10.5"
    );
    assert_eq!(s.vehicle().thrusters[3].position_m, [0.0, -0.2, 0.0]);
    // A vehicle keeps at least one thruster.
    let mut s = sim(load("four_up"));
    let names: Vec<String> = s
        .vehicle()
        .thrusters
        .iter()
        .map(|t| t.name.clone())
        .collect();
    for name in &names[..3] {
        s.apply(&Action::Remove {
            thruster: name.clone(),
        })
        .expect("removes");
    }
    let e = s
        .apply(&Action::Remove {
            thruster: names[3].clone(),
        })
        .unwrap_err()
        .to_string();
    assert!(e.ends_with("must be in [1, 16], got 0"), "{e}");
    assert_eq!(s.thruster_count(), 1);
}

#[test]
fn random_vehicles_simulate() {
    for (n, seed) in [(2, 1), (4, 2), (6, 3), (8, 4)] {
        let v = random_vehicle(n, seed).expect("valid");
        let mut s = sim(v);
        s.set_commands(&vec![0.5; n]).expect("count");
        s.step_secs(1.0);
        assert!(s.state().nu.iter().all(|x| x.is_finite()));
        let (fwd, _) = s.truth();
        assert_eq!(rank(&fwd, 1e-6), n.min(6));
    }
}
