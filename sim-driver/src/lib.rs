//! thruster-sim: a 6-DOF underwater vehicle simulator, the test bench of thrusterd.
//!
//! This library is the pure physics core (no clocks, no IPC; files only through the explicit
//! TOML loaders): a Fossen-style rigid-body and hydrodynamic model integrated with RK4 at 1 kHz,
//! T200-class thrusters with deadband, asymmetry and spin-up lag, an IMU and depth sensor with
//! seeded noise, disturbances, scripted reconfiguration and the true effectiveness matrices the
//! estimator is scored against. See `docs/simulation.md` for the model and its sources.
//!
//! The driver process (`thruster-sim run`) lives at the edge, in [`driver`] (IPC, clock,
//! files), [`settings`] and [`cli`]; [`responder`] is a stand-in daemon for tests. Nothing in
//! the physics modules depends on them.
//!
//! Conventions: body x forward, y starboard, z down; world NED; quaternions `[w, x, y, z]`
//! body-to-NED; commands normalised to [-1, 1] per thruster; effectiveness rows in DOF order
//! `[roll, pitch, yaw, surge, sway, heave]` (rad/s^2, m/s^2 per unit command).
//!
//! ```
//! use thruster_sim::{Simulator, SensorConfig, random_vehicle};
//!
//! let vehicle = random_vehicle(4, 7).unwrap();
//! let mut sim = Simulator::new(vehicle, SensorConfig::default(), 1).unwrap();
//! sim.set_commands(&[0.5, 0.0, 0.0, 0.0]).unwrap();
//! let reading = sim.advance_and_sample(); // 10 ms at the default 100 Hz
//! assert_eq!(reading.t_ns, 10_000_000);
//! let (b_fwd, _b_rev) = sim.truth();
//! assert_eq!(b_fwd.shape(), (6, 4));
//! ```

pub mod battery;
pub mod cli;
pub mod disturbance;
pub mod driver;
pub mod dvl;
pub mod dynamics;
pub mod effectiveness;
pub mod link_stats;
pub mod load;
pub mod random;
pub mod responder;
pub mod scenario;
pub mod sensors;
pub mod settings;
pub mod sim;
pub mod stepper;
pub mod thruster;
pub mod vehicle;
pub mod vehicle_file;

pub use battery::{Battery, BatterySpec};
pub use disturbance::{DisturbanceConfig, WaveComponent};
pub use dvl::{Dvl, DvlConfig};
pub use dynamics::{RigidBody, State};
pub use effectiveness::{effectiveness, rank};
pub use load::LoadError;
pub use random::random_vehicle;
pub use scenario::{Action, Event, Scenario};
pub use sensors::{ImuNoise, NoisePreset, SensorBiases, SensorConfig};
pub use sim::{Change, ChangeKind, InitialState, SimError, SimOptions, Simulator};
pub use thruster::{sanitize_command, steady_thrust, Thruster};
pub use vehicle::{Body, Dof6, ThrusterModel, ThrusterSpec, Vehicle};
