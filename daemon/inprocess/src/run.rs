//! The machine and the simulator stepped together (`Run`), with the measurements the tests and
//! sweeps make of a run: a re-estimation's way to a new model, errors against the truth.

use std::path::PathBuf;

use nalgebra::DMatrix;
use thruster_sim::{NoisePreset, SensorConfig, Simulator, Vehicle};
use thrusterd_core::estimator::EstimatorConfig;
use thrusterd_core::machine::{ImuInput, Machine, MachineSetup, Mode, Request, State};

/// Every vehicle file in config/vehicles, for sweeps over all of them.
pub const VEHICLES: [&str; 6] = [
    "aligned",
    "amour5",
    "amour5_top45",
    "eight_vectored",
    "four_up",
    "six_dof",
];

pub fn vehicle(name: &str) -> Vehicle {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/vehicles")
        .join(format!("{name}.toml"));
    Vehicle::load(&path).unwrap()
}

pub struct Run {
    pub machine: Machine,
    pub sim: Simulator,
    pub last_mode: Mode,
    pub max_abs_cmd: f64,
    /// The command takes effect this long after its sample, us, drawn uniformly from the
    /// range for every sample (a deterministic hash of its time): as through the driver in
    /// real time (thruster-sim steps the physics to the command's arrival). None: at once.
    /// Set by measuring sweeps (`RUN_LATENCY_US` there), never by an environment variable in
    /// a test CI runs.
    pub latency_us: Option<(u64, u64)>,
    /// The simulator's battery voltage handed to the machine every this many ns of vehicle
    /// time, before the sample that follows (a driver's report: thruster-sim's every 100 ms).
    /// None: never (the machine runs without a reading).
    pub supply_report_ns: Option<u64>,
    /// Vehicle time the next report is due at, ns.
    pub next_report_ns: u64,
    /// The supply voltage the truth is taken at, V: the daemon's reference when it refers or
    /// linearizes its commands through the T200's table (a model learned that way describes
    /// the thrusters there, `model_truth` in the lab); None: the battery's present voltage.
    pub truth_voltage_v: Option<f64>,
    /// The simulator's true body velocity handed to the machine at every sample, as a
    /// perfect DVL would (the decisive run for the navigation's share of an error). Set by
    /// measuring sweeps only (`ID_DVL` there).
    pub perfect_dvl: bool,
}

/// The machine as the vehicle's operator configures it, with no driver between it and the
/// physics. Power-law thrusters: their dead band is jumped by the machine (`machine.deadband`),
/// as thruster-sim's driver does for them. T200 thrusters: commanded through the table
/// (`[supply] linearize`, as the demo configures them from the data sheet), their dead zone
/// not jumped a second time (thruster-sim's driver passes their command unchanged). Before,
/// a T200 vehicle ran here with the power-law dead band and no linearization, unlike through
/// the processes: under control its model learned the small-signal gain of the raw curve
/// (42 % under the truth).
fn operator_setup(v: &Vehicle, setup: &mut MachineSetup) {
    setup.machine.deadband = operator_deadband(v);
    if v.all_t200() {
        setup.supply.linearize = true;
    } else {
        // Another make's (or of two makes): no T200 table for them. Without a battery (no
        // vehicle file but the T200 ones has one) nothing is referred either way; what it
        // changes is that a thrust curve an identification names is learned
        // (`identification.learn_thrust_curve`), not taken for a T200's.
        setup.supply.compensation = thrusterd_core::supply::CompensationModel::None;
    }
}

/// The dead band the machine jumps for vehicle `v` as its operator configures it
/// ([`operator_setup`]): 0.05 for power-law thrusters, none for T200s (their driver passes
/// the command through their table's dead zone).
pub fn operator_deadband(v: &Vehicle) -> f64 {
    if v.all_t200() {
        0.0
    } else {
        0.05
    }
}

/// Period of thruster-sim's voltage report, ns (its driver's, every 100 ms).
const SUPPLY_REPORT_NS: u64 = 100_000_000;

impl Run {
    pub fn new(name: &str, noise: NoisePreset, seed: u64) -> Run {
        Run::with_rate(name, noise, seed, 200.0)
    }

    /// The same with the static forward method and the settings it was tuned with.
    pub fn forward(name: &str, noise: NoisePreset, seed: u64) -> Run {
        let mut run = Run::new(name, noise, seed);
        let mut setup = MachineSetup {
            thrusters: run.sim.thruster_count(),
            estimator: EstimatorConfig::forward(),
            ..MachineSetup::default()
        };
        setup.machine.deadband = 0.05;
        run.machine = Machine::new(setup);
        run
    }

    pub fn with_rate(name: &str, noise: NoisePreset, seed: u64, rate_hz: f64) -> Run {
        Run::with_vehicle(vehicle(name), noise, seed, rate_hz)
    }

    /// The same for a vehicle built or edited in the test.
    pub fn with_vehicle(v: Vehicle, noise: NoisePreset, seed: u64, rate_hz: f64) -> Run {
        let n = v.thrusters.len();
        let sensors = SensorConfig {
            rate_hz,
            noise,
            ..SensorConfig::default()
        };
        let mut setup = MachineSetup {
            thrusters: n,
            ..MachineSetup::default()
        };
        operator_setup(&v, &mut setup);
        let sim = Simulator::new(v, sensors, seed).unwrap();
        let mut run = Run {
            machine: Machine::new(MachineSetup::default()),
            sim,
            last_mode: Mode::Neutral,
            max_abs_cmd: 0.0,
            latency_us: None,
            perfect_dvl: false,
            supply_report_ns: None,
            next_report_ns: 0,
            truth_voltage_v: None,
        };
        run.install(setup);
        run
    }

    /// `setup` as the machine, with what goes with it: the battery's voltage reported as
    /// thruster-sim's driver does when the vehicle has one, and the truth taken at the voltage
    /// the machine's models describe.
    fn install(&mut self, setup: MachineSetup) {
        let mut supply = thrusterd_core::supply::Supply::new(setup.supply.clone());
        let battery = self.sim.battery().map(|b| b.voltage_v());
        supply.on_voltage(battery);
        self.supply_report_ns = battery.map(|_| SUPPLY_REPORT_NS);
        self.next_report_ns = 0;
        self.truth_voltage_v = supply.model_voltage_v().or(setup
            .supply
            .linearize
            .then_some(setup.supply.reference_voltage_v));
        self.machine = Machine::new(setup);
    }

    /// The simulator stepped to the next sample on the sensor's grid (a command may have
    /// arrived mid-period), and that sample as the machine takes it.
    pub fn next_input(&mut self) -> ImuInput {
        let period = self.sim.sample_period_ns();
        self.sim.step_to((self.sim.time_ns() / period + 1) * period);
        self.sim.sample()
    }

    pub fn tick(&mut self) {
        let input = self.next_input();
        if let (Some(every), Some(b)) = (self.supply_report_ns, self.sim.battery()) {
            if input.t_ns >= self.next_report_ns {
                self.machine.on_supply(Some(b.voltage_v()));
                self.next_report_ns = input.t_ns + every;
            }
        }
        if self.perfect_dvl {
            self.machine.on_dvl(self.sim.linear_velocity().into());
        }
        let cmd = self.machine.on_imu(&input);
        assert_eq!(cmd.count, self.sim.thruster_count());
        for v in &cmd.thrust[..cmd.count] {
            assert!(v.is_finite() && v.abs() <= 1.0, "command {v}");
            self.max_abs_cmd = self.max_abs_cmd.max(v.abs());
        }
        assert!(cmd.thrust[cmd.count..].iter().all(|v| *v == 0.0));
        self.last_mode = cmd.mode;
        if let Some((lo, hi)) = self.latency_us {
            let h = input.t_ns.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
            let us = lo + h % (hi - lo + 1);
            self.sim.step_to(input.t_ns + us * 1000);
        }
        self.sim.set_commands(&cmd.thrust[..cmd.count]).unwrap();
    }

    pub fn run_for(&mut self, s: f64) {
        self.run_until(s, |_| false);
    }

    pub fn run_until(&mut self, max_s: f64, done: impl Fn(&Machine) -> bool) -> f64 {
        let start = self.sim.time_s();
        while self.sim.time_s() - start < max_s {
            self.tick();
            if done(&self.machine) {
                break;
            }
        }
        self.sim.time_s() - start
    }

    /// Symmetric truth: the model is linear, so it learns the mean of forward and reverse gain.
    pub fn truth(&self) -> DMatrix<f64> {
        let (fwd, rev) = match self.truth_voltage_v {
            Some(v) => self.sim.truth_at(v),
            None => self.sim.truth(),
        };
        (fwd + rev) * 0.5
    }

    pub fn estimate(&mut self) -> f64 {
        self.machine.on_request(Request::Estimate).unwrap();
        self.run_until(120.0, |m| m.state() == State::Active)
    }
}

pub fn rel_err(est: &DMatrix<f64>, truth: &DMatrix<f64>, rows: usize) -> f64 {
    (est.rows(rows, 3) - truth.rows(rows, 3)).norm() / truth.rows(rows, 3).norm()
}

/// The vehicle's declared geometry, as a driver announces it (thruster-sim's
/// `reconfig_event`): positions from the centre of mass, directions those of the force for a
/// positive command (a `reversed`, left-handed thruster pushes against its `direction`).
/// Before 2026-11-30 the file's own positions and directions were announced here: AMOUR-5's
/// positions 2 cm off in z (its CG is 2 cm below the CO), and the `aligned` vehicle's reversed
/// L pushing the wrong way in every nominal model, which spun that vehicle in yaw after an
/// announced change and tumbled it.
pub fn geometry(v: &Vehicle) -> thrusterd_core::machine::Geometry {
    let (positions, directions) = v.declared_geometry().into_iter().unzip();
    thrusterd_core::machine::Geometry {
        positions,
        directions,
    }
}

/// What a re-estimation did to the vehicle and what it learned.
#[derive(Debug, Clone, Copy)]
pub struct Reestimation {
    /// Vehicle time from its start until control with the new model, s.
    pub took_s: f64,
    /// Largest tilt (true attitude, angle of body z from down), deg.
    pub max_tilt_deg: f64,
    /// Largest heading change from where it started, deg.
    pub max_heading_deg: f64,
    /// Mean angle between the true attitude and level at the starting heading, deg.
    pub mean_err_deg: f64,
    /// The new model against the new truth, rotation and acceleration rows.
    pub err_rot: f64,
    pub err_acc: f64,
    pub source: thrusterd_core::model::ModelSource,
}

impl Run {
    /// The lab's start in moving water: the model learned in still water (1 s of settling, an
    /// estimation, its events dropped), then the water comes up.
    pub fn learn_then_water(&mut self, water: thruster_sim::disturbance::WaterPreset) {
        self.run_for(1.0);
        self.estimate();
        self.machine.take_events();
        if water != thruster_sim::disturbance::WaterPreset::Still {
            self.sim.set_disturbance(water.disturbance()).unwrap();
        }
    }

    /// AMOUR-5's top thruster "T" rotated 45 degrees about x, unannounced.
    pub fn rotate_top(&mut self) {
        self.sim
            .apply(&thruster_sim::Action::Rotate {
                thruster: "T".into(),
                axis: [1.0, 0.0, 0.0],
                angle_deg: 45.0,
            })
            .unwrap();
    }

    /// A new machine as `Run` builds it (`with_setup`), with the identification section
    /// replaced.
    pub fn with_identification(
        &mut self,
        identification: thrusterd_core::adaptation::identification::IdentificationConfig,
    ) {
        self.with_setup(|setup| setup.identification = identification);
    }

    /// A new machine as `Run` builds it (the vehicle's thruster count, configured as its
    /// operator would: `operator_setup`), then changed by `change`.
    pub fn with_setup(&mut self, change: impl FnOnce(&mut thrusterd_core::machine::MachineSetup)) {
        let mut setup = thrusterd_core::machine::MachineSetup {
            thrusters: self.sim.thruster_count(),
            ..thrusterd_core::machine::MachineSetup::default()
        };
        operator_setup(self.sim.vehicle(), &mut setup);
        change(&mut setup);
        self.install(setup);
    }

    /// The top thruster of AMOUR-5 rotated 45 degrees about x and announced with its new
    /// geometry while the machine holds level: runs until control resumes with a new model
    /// (at most 120 s) and measures the way there against the simulator's truth.
    pub fn announced_rotation(&mut self, v: &Vehicle) -> Reestimation {
        self.announced_rotation_observed(v, |_, _| {})
    }

    /// The same, calling `observe` with the machine and the seconds since the announcement
    /// after every sample (the sweep in closed_loop.rs watches the error bounds with it).
    pub fn announced_rotation_observed(
        &mut self,
        v: &Vehicle,
        observe: impl FnMut(&Machine, f64),
    ) -> Reestimation {
        let top = thrusterd_core::machine::ThrusterChange::Moved(0);
        self.announced_rotation_as(v, top, observe)
    }

    /// The same, the announcement saying `change` (which may name the wrong thruster).
    pub fn announced_rotation_as(
        &mut self,
        v: &Vehicle,
        change: thrusterd_core::machine::ThrusterChange,
        observe: impl FnMut(&Machine, f64),
    ) -> Reestimation {
        self.announced_turn(v, 0, [1.0, 0.0, 0.0], 45.0, change, observe)
    }

    /// Turns thruster `index` of `v` by `angle_deg` about `axis` in the simulator and
    /// announces the turned geometry to the machine as `change` (what `announced_turn` then
    /// watches; a test that acts on the machine mid-way starts here).
    pub fn announce_turn(
        &mut self,
        v: &Vehicle,
        index: usize,
        axis: [f64; 3],
        angle_deg: f64,
        change: thrusterd_core::machine::ThrusterChange,
    ) {
        use nalgebra::{Unit, UnitQuaternion, Vector3};
        self.sim
            .apply(&thruster_sim::Action::Rotate {
                thruster: v.thrusters[index].name.clone(),
                axis,
                angle_deg,
            })
            .unwrap();
        let mut moved = geometry(v);
        let r = UnitQuaternion::from_axis_angle(
            &Unit::new_normalize(Vector3::from(axis)),
            angle_deg.to_radians(),
        );
        moved.directions[index] = (r * Vector3::from(moved.directions[index])).into();
        self.machine.on_reconfig(thrusterd_core::machine::Reconfig {
            count: v.thrusters.len(),
            geometry: Some(moved),
            change,
            what: "top thruster rotated".into(),
        });
    }

    /// Thruster `index` of `v` turned by `angle_deg` about `axis` (body frame) and announced
    /// as `change` with the new geometry, the machine holding level: as [`Self::announced_rotation`].
    pub fn announced_turn(
        &mut self,
        v: &Vehicle,
        index: usize,
        axis: [f64; 3],
        angle_deg: f64,
        change: thrusterd_core::machine::ThrusterChange,
        mut observe: impl FnMut(&Machine, f64),
    ) -> Reestimation {
        use nalgebra::{UnitQuaternion, Vector3};
        let before = self.machine.model().map_or(0, |m| m.version);
        self.announce_turn(v, index, axis, angle_deg, change);
        let heading = self.sim.roll_pitch_yaw()[2];
        let level = UnitQuaternion::from_euler_angles(0.0, 0.0, heading);
        let start = self.sim.time_s();
        let (mut max_tilt, mut max_heading, mut err_sum, mut k) = (0.0f64, 0.0f64, 0.0, 0u64);
        while self.sim.time_s() - start < 120.0 {
            self.tick();
            let q = self.sim.attitude();
            let down = q.inverse() * Vector3::z();
            max_tilt = max_tilt.max(down.z.clamp(-1.0, 1.0).acos().to_degrees());
            let dh = (q.euler_angles().2 - heading + std::f64::consts::PI)
                .rem_euclid(2.0 * std::f64::consts::PI)
                - std::f64::consts::PI;
            max_heading = max_heading.max(dh.abs().to_degrees());
            err_sum += q.angle_to(&level).to_degrees();
            k += 1;
            observe(&self.machine, self.sim.time_s() - start);
            let m = &self.machine;
            // A fight's model waiting for its confirmation is not the end
            // (`identification::fight`).
            if m.state() == State::Active
                && !m.confirmation_pending()
                && m.model().is_some_and(|m| m.version > before + 1)
            {
                break;
            }
        }
        let model = self.machine.model().unwrap().clone();
        let truth = self.truth();
        Reestimation {
            took_s: self.sim.time_s() - start,
            max_tilt_deg: max_tilt,
            max_heading_deg: max_heading,
            mean_err_deg: err_sum / k.max(1) as f64,
            err_rot: rel_err(&model.effectiveness, &truth, 0),
            err_acc: rel_err(&model.effectiveness, &truth, 3),
            source: model.source,
        }
    }
}

/// A comma-separated list from the environment (`1-5` also for integer ranges), or `default`.
pub fn env_list<T: std::str::FromStr + Copy>(key: &str, default: &[T]) -> Vec<T> {
    let Ok(text) = std::env::var(key) else {
        return default.to_vec();
    };
    let mut out = Vec::new();
    for item in text.split(',').map(str::trim).filter(|t| !t.is_empty()) {
        if let Some((a, b)) = item.split_once('-') {
            if let (Ok(a), Ok(b)) = (a.parse::<u64>(), b.parse::<u64>()) {
                for k in a..=b {
                    out.push(
                        k.to_string()
                            .parse()
                            .unwrap_or_else(|_| panic!("{key}: {k}")),
                    );
                }
                continue;
            }
        }
        out.push(item.parse().unwrap_or_else(|_| panic!("{key}: {item}")));
    }
    out
}

/// The same with the machine's identification section replaced (None: the defaults), calling
/// `observe` after every sample of the re-estimation.
pub fn rotate_while_holding_with(
    noise: NoisePreset,
    seed: u64,
    identification: Option<thrusterd_core::adaptation::identification::IdentificationConfig>,
    observe: impl FnMut(&Machine, f64),
) -> (Run, Reestimation) {
    rotate_while_holding_in(noise, seed, identification, None, observe)
}

/// The same in moving water: the first model is learned in still water, then `water` comes
/// up (None: still water throughout) and the vehicle holds in it 20 s before the announcement.
pub fn rotate_while_holding_in(
    noise: NoisePreset,
    seed: u64,
    identification: Option<thrusterd_core::adaptation::identification::IdentificationConfig>,
    water: Option<thruster_sim::DisturbanceConfig>,
    observe: impl FnMut(&Machine, f64),
) -> (Run, Reestimation) {
    let v = vehicle("amour5");
    let mut run = Run::new("amour5", noise, seed);
    if let Some(identification) = identification {
        run.with_identification(identification);
    }
    rotate_while_holding_on(run, &v, water, observe)
}

/// How long [`rotate_while_holding_on`] waits for the vehicle to hold again before the
/// announced change, vehicle s: an identification under control takes up to its 20 s limit.
const MAX_WAIT_FOR_HOLD_S: f64 = 30.0;

/// [`rotate_while_holding_in`] on a `run` already made (its machine set up as wanted) of
/// vehicle `v`. In moving water, the change is announced once the vehicle holds.
pub fn rotate_while_holding_on(
    mut run: Run,
    v: &Vehicle,
    water: Option<thruster_sim::DisturbanceConfig>,
    observe: impl FnMut(&Machine, f64),
) -> (Run, Reestimation) {
    run.run_for(1.0);
    run.estimate();
    run.run_for(3.0);
    if let Some(water) = water {
        run.sim.set_disturbance(water).unwrap();
        run.run_for(20.0);
        // In moving water the change test can take the swell for a moved thruster, and that
        // identification may still run when the change is due (four_up at one swell phase,
        // AMOUR-5 seed 7 deciding once a segment): the change is announced once the vehicle
        // holds again, so that it is a change made to a holding vehicle.
        let mut waited = 0.0;
        while run.machine.state() != State::Active && waited < MAX_WAIT_FOR_HOLD_S {
            run.run_for(0.5);
            waited += 0.5;
        }
    }
    assert_eq!(run.machine.state(), State::Active);
    let r = run.announced_rotation_observed(v, observe);
    (run, r)
}
