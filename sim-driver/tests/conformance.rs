//! The driver contract's conformance suite (`thruster_driver_kit::conformance`) against the
//! `thruster-sim` process in real time: the same tests every hardware backend runs from
//! hw-driver/tests/conformance.rs. What only a simulator does (lockstep, the replica
//! comparison, scenarios) is in process.rs.

use thruster_driver_kit::conformance::{DriverProcess, DriverUnderTest};
use thruster_protocol::services::IpcConfig;

/// The simulator on AMOUR-5 (five thrusters), 100 Hz, noise-free sensors, real time (its
/// watchdog is the suite's 200 ms by default).
struct Sim;

impl DriverUnderTest for Sim {
    const NAME: &'static str = "sim";
    const RATE_HZ: f64 = 100.0;
    const THRUSTERS: usize = 5;

    fn start(ns: &IpcConfig) -> (Self, DriverProcess) {
        let vehicle = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../config/vehicles/amour5.toml"
        );
        let args = [
            "run",
            "--namespace",
            ns.namespace(),
            "--vehicle",
            vehicle,
            "--realtime",
            "--rate",
            "100",
            "--noise",
            "none",
        ];
        let proc = DriverProcess::spawn(env!("CARGO_BIN_EXE_thruster-sim"), &args)
            .expect("thruster-sim starts");
        (Sim, proc)
    }
}

thruster_driver_kit::conformance_suite!(sim: Sim);
