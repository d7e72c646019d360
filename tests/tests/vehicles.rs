//! Every manual configuration of the paper, estimated through the whole loop (real thrusterd and
//! thruster-sim processes in lockstep over iceoryx2) at the paper's noise, scored against the
//! simulator's truth; and the all-aligned vehicle reported with its missing DOFs.

use std::time::Duration;

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
    let mut daemon = world.daemon(&["--estimate", "--thrusters", &n, "--lockstep"]);
    let seed = seed.to_string();
    let mut sim = world.sim(
        vehicle,
        &[
            "--noise",
            "paper",
            "--lockstep",
            "--seed",
            &seed,
            "--duration",
            "100000",
        ],
    );
    op.wait_status(LONG, |s| {
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

/// Threshold 0.15 (paper noise, seed 7): the dynamic method stops at a 5 % (1 sigma) bound,
/// which at this noise is optimistic (the demo over seeds 1-5: true 0.052 / 0.061, docs/study.md);
/// measured here 0.038-0.061 rotation and 0.055-0.097 acceleration over the five vehicles. The
/// margin is for the vehicle time at which the request lands, which moves with process
/// scheduling. (With the static forward model this test needed 0.3, and 0.35 for four_up.)
#[test]
fn every_manual_configuration_is_learned_within_the_threshold() {
    for vehicle in ["four_up", "amour5", "six_dof", "eight_vectored"] {
        let (model, e_rot, e_acc) = estimate(vehicle, 7);
        let limit = 0.15;
        assert!(
            e_rot < limit && e_acc < limit,
            "{vehicle}: errors rot {e_rot:.3} acc {e_acc:.3}"
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
    let (model, _, _) = estimate("aligned", 3);
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
