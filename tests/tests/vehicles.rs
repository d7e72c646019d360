//! Every manual configuration of the paper, estimated through the whole loop (real thrusterd and
//! thruster-sim processes in lockstep over iceoryx2) at the paper's noise, scored against the
//! simulator's truth; and the all-aligned vehicle reported with its missing DOFs.

use std::time::Duration;

use system_tests::vehicle_clock::STEPPED_DAEMON;
use system_tests::{model_error, state, Operator, World};
use thruster_protocol::{DaemonState, Dof, ModelMsg, ModelSource};

const LONG: Duration = Duration::from_secs(90);

fn thruster_count(vehicle: &str) -> usize {
    let path = system_tests::workspace()
        .join("config/vehicles")
        .join(format!("{vehicle}.toml"));
    let text = std::fs::read_to_string(path).unwrap();
    text.lines().filter(|l| l.trim() == "[[thruster]]").count()
}

/// Estimate `vehicle` and return the model and its rotation / acceleration errors.
fn estimate(vehicle: &str, seed: u64) -> (ModelMsg, f64, f64) {
    let world = World::new("veh");
    let op = Operator::new(&world);
    let n = thruster_count(vehicle).to_string();
    // `--estimate` starts at the first sample; stepped, the simulator waits for every
    // answer and the daemon for every late solve: the run is the same on any machine.
    let mut daemon =
        world.daemon(&[&["--estimate", "--thrusters", &n], &STEPPED_DAEMON[..]].concat());
    let seed = seed.to_string();
    let (mut sim, mut clock) = world.stepped_sim(
        vehicle,
        &["--noise", "paper", "--seed", &seed, "--duration", "100000"],
    );
    clock
        .run_until(&op.status, 60.0, |s| {
            state(s) == DaemonState::Active && s.model_version >= 1
        })
        .unwrap_or_else(|| {
            panic!(
                "{vehicle}: no model\n--- thrusterd ---\n{}\n--- thruster-sim (running: {}) ---\n{}",
                daemon.log_text(),
                sim.is_running(),
                sim.log_text()
            )
        });
    let model = op
        .wait_model(LONG, |m| m.source() == Ok(ModelSource::Estimated))
        .expect("model published");
    let truth = op.latest_truth(LONG).expect("truth");
    assert!(sim.stop().success());
    assert!(daemon.stop().success());
    let (e_rot, e_acc) = (
        model_error(&model, &truth, 0),
        model_error(&model, &truth, 3),
    );
    println!("{vehicle}: rotation error {e_rot:.3}, acceleration error {e_acc:.3}");
    (model, e_rot, e_acc)
}

fn actuated(m: &ModelMsg) -> Vec<String> {
    Dof::ALL
        .iter()
        .filter(|d| m.is_actuated(**d))
        .map(|d| d.name().to_lowercase())
        .collect()
}

/// Paper noise, seed 7, in vehicle time (the same figures every run). Measured rotation /
/// acceleration errors against the simulator's truth; each must stay under 1.5x its own
/// figure, so a 2x regression on any vehicle fails. (The dynamic method stops at a 6 %
/// (1 sigma) bound, `target_rel_err`, optimistic at this noise, docs/study.md; the static forward model
/// needed 0.3 here, 0.35 for four_up.)
const MEASURED: [(&str, f64, f64); 4] = [
    ("four_up", 0.062, 0.073),
    ("amour5", 0.065, 0.074),
    ("six_dof", 0.054, 0.074),
    ("eight_vectored", 0.051, 0.084),
];

#[test]
fn every_manual_configuration_is_learned_within_the_threshold() {
    for (vehicle, rot, acc) in MEASURED {
        let (model, e_rot, e_acc) = estimate(vehicle, 7);
        assert!(
            e_rot < 1.5 * rot && e_acc < 1.5 * acc,
            "{vehicle}: errors rot {e_rot:.3} acc {e_acc:.3} (measured {rot} / {acc})"
        );
        let dofs = actuated(&model);
        match vehicle {
            "four_up" => assert_eq!(dofs, ["roll", "pitch", "heave"], "{vehicle}"),
            "amour5" => assert_eq!(
                dofs,
                ["roll", "pitch", "yaw", "surge", "heave"],
                "{vehicle}"
            ),
            _ => assert_eq!(dofs.len(), 6, "{vehicle}: {dofs:?}"),
        }
    }
}

#[test]
fn all_aligned_thrusters_report_heave_sway_and_roll_unactuated() {
    let (model, e_rot, e_acc) = estimate("aligned", 3);
    // Measured 0.043 / 0.054 (seed 3); 1.5x.
    assert!(
        e_rot < 0.065 && e_acc < 0.081,
        "errors rot {e_rot:.3} acc {e_acc:.3}"
    );
    assert_eq!(actuated(&model), ["pitch", "yaw", "surge"]);
    for i in 0..model.count as usize {
        for dof in [Dof::Roll, Dof::Sway, Dof::Heave] {
            assert_eq!(
                model.allocation[i][dof.index()],
                0.0,
                "thruster {i} commanded for {dof:?}"
            );
        }
    }
}
