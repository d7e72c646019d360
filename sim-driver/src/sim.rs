//! The simulator: vehicle dynamics, thrusters, sensors and disturbances on one clock.
//!
//! Time is an integer count of nanoseconds from 0, so a long lockstep run never drifts. The
//! dynamics run at a fixed inner rate (default 1 kHz) with the latest commands held; sensor
//! samples are taken whenever the caller asks, normally once per output period.

use nalgebra::{DMatrix, Quaternion, UnitQuaternion, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::battery::Battery;
use crate::disturbance::DisturbanceConfig;
use crate::dynamics::{RigidBody, State};
use crate::effectiveness::effectiveness_at;
use crate::load::{symmetric, Checker, LoadError, Range};
use crate::scenario::Action;
use crate::sensors::{Imu, SensorBiases, SensorConfig, SensorTruth};
use crate::thruster::{Thruster, FIXED_SUPPLY_V};
use crate::vehicle::{ThrusterSpec, Vehicle};
use thruster_protocol::validate::limits::{
    MAX_DEPTH_M, MAX_DVL_SPEED, MAX_GYRO_RAD_S, MIN_DEPTH_M,
};
use thruster_protocol::{ImuReading, MAX_THRUSTERS};

/// Farthest start north or east of the origin, m (1000 km).
pub const MAX_NORTH_EAST_M: f64 = 1e6;

/// Errors of the simulator.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A configuration value is invalid.
    #[error(transparent)]
    Config(#[from] LoadError),
    /// `set_commands` got the wrong number of commands (the held commands are unchanged).
    #[error("expected {expected} thrust commands, got {got}")]
    CommandCount { expected: usize, got: usize },
    /// A scenario action names a thruster the vehicle does not have.
    #[error("no thruster named {0:?}")]
    UnknownThruster(String),
    /// An added thruster's name is already taken.
    #[error("a thruster named {0:?} already exists")]
    DuplicateThruster(String),
    /// Adding would exceed [`MAX_THRUSTERS`].
    #[error("cannot add a thruster: at most {MAX_THRUSTERS}")]
    TooManyThrusters,
}

fn default_integration_rate_hz() -> f64 {
    1000.0
}

/// Initial conditions (`[initial]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialState {
    /// Position of the CO, NED, m. Default [0, 0, 30] (30 m deep): the model has no free
    /// surface and a BlueROV2 is 2 N buoyant, so an uncontrolled vehicle rises ~0.17 m/s; 30 m
    /// keeps a few minutes of estimation and drift below the surface.
    pub position_ned_m: [f64; 3],
    /// Roll, pitch, yaw (ZYX Euler), degrees. Default level, heading north.
    pub attitude_rpy_deg: [f64; 3],
    /// Body linear velocity [u v w], m/s. Default 0.
    pub linear_mps: [f64; 3],
    /// Body angular velocity [p q r], rad/s. Default 0.
    pub angular_radps: [f64; 3],
}

impl Default for InitialState {
    fn default() -> Self {
        InitialState {
            position_ned_m: [0.0, 0.0, 30.0],
            attitude_rpy_deg: [0.0; 3],
            linear_mps: [0.0; 3],
            angular_radps: [0.0; 3],
        }
    }
}

impl InitialState {
    /// As a dynamics state.
    pub fn to_state(&self) -> State {
        let [r, p, y] = self.attitude_rpy_deg.map(f64::to_radians);
        let mut nu = Vector6::zeros();
        for i in 0..3 {
            nu[i] = self.linear_mps[i];
            nu[3 + i] = self.angular_radps[i];
        }
        State {
            position_ned_m: Vector3::from(self.position_ned_m),
            attitude: UnitQuaternion::from_euler_angles(r, p, y),
            nu,
        }
    }

    /// North and east within [`MAX_NORTH_EAST_M`], depth within the protocol's depth range,
    /// angles within a turn, speeds within what the protocol's DVL (10 m/s) and gyro
    /// (50 rad/s) can report.
    fn check(&self, c: &Checker, prefix: &str) -> Result<(), LoadError> {
        let key = |k: &str| format!("{prefix}initial.{k}");
        let [n, e, d] = self.position_ned_m;
        let position = key("position_ned_m");
        c.range(&format!("{position}[0]"), n, symmetric(MAX_NORTH_EAST_M))?;
        c.range(&format!("{position}[1]"), e, symmetric(MAX_NORTH_EAST_M))?;
        c.range(
            &format!("{position}[2]"),
            d,
            Range::closed(MIN_DEPTH_M, MAX_DEPTH_M),
        )?;
        c.each(
            &key("attitude_rpy_deg"),
            &self.attitude_rpy_deg,
            symmetric(360.0),
        )?;
        c.each(
            &key("linear_mps"),
            &self.linear_mps,
            symmetric(MAX_DVL_SPEED),
        )?;
        c.each(
            &key("angular_radps"),
            &self.angular_radps,
            symmetric(MAX_GYRO_RAD_S),
        )
    }
}

/// Everything but the vehicle and the sensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimOptions {
    /// Inner integration rate, Hz, in [1000, 1e6]. Default 1000.
    pub integration_rate_hz: f64,
    /// Initial conditions.
    pub initial: InitialState,
    /// Current and waves (off by default).
    pub disturbance: DisturbanceConfig,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            integration_rate_hz: default_integration_rate_hz(),
            initial: InitialState::default(),
            disturbance: DisturbanceConfig::default(),
        }
    }
}

impl SimOptions {
    /// Checks ranges; `origin` names the source in errors.
    pub fn validate(&self, origin: &str) -> Result<(), LoadError> {
        self.check(&Checker::new(origin, ""), "")
    }

    /// Checks ranges, locating a bad value in `c.text`; `prefix` is the path of these keys
    /// (`"sim."` in thruster-sim's config file).
    pub(crate) fn check(&self, c: &Checker, prefix: &str) -> Result<(), LoadError> {
        // Below 1 kHz the 100 ms thruster lag and fast roll modes are resolved poorly; above
        // 1 MHz the ns clock would quantise the step noticeably.
        c.range(
            &format!("{prefix}integration_rate_hz"),
            self.integration_rate_hz,
            Range::closed(1000.0, 1e6),
        )?;
        self.initial.check(c, prefix)?;
        self.disturbance.check(c, prefix)
    }
}

/// What a scenario action changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChangeKind {
    /// Direction or position changed (rotate, set_direction, move).
    Moved,
    /// A thruster was appended.
    Added,
    /// A thruster was removed; later ones moved down one index.
    Removed,
    /// A thruster became dead.
    Killed,
    /// A thruster's thrust was scaled (weaken).
    Weakened,
}

/// Result of [`Simulator::apply`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Change {
    /// What happened.
    pub kind: ChangeKind,
    /// Command index of the thruster concerned (for `Removed`: the index it had).
    pub index: usize,
    /// Thruster count afterwards.
    pub thruster_count: usize,
}

/// The simulated vehicle.
#[derive(Debug, Clone)]
pub struct Simulator {
    vehicle: Vehicle,
    body: RigidBody,
    thrusters: Vec<Thruster>,
    state: State,
    t_ns: u64,
    dt_inner_ns: u64,
    imu: Imu,
    dvl: Option<crate::dvl::Dvl>,
    disturbance: DisturbanceConfig,
    /// None: a fixed supply at [`FIXED_SUPPLY_V`].
    battery: Option<Battery>,
}

impl Simulator {
    /// A simulator with default [`SimOptions`] (1 kHz, 30 m deep, level, at rest, no
    /// disturbance). `seed` drives the sensor noise.
    pub fn new(vehicle: Vehicle, sensors: SensorConfig, seed: u64) -> Result<Self, SimError> {
        Simulator::with_options(vehicle, sensors, seed, SimOptions::default())
    }

    /// A simulator with explicit options. Everything is validated.
    pub fn with_options(
        mut vehicle: Vehicle,
        sensors: SensorConfig,
        seed: u64,
        options: SimOptions,
    ) -> Result<Self, SimError> {
        let origin = if vehicle.name.is_empty() {
            "vehicle".to_string()
        } else {
            vehicle.name.clone()
        };
        vehicle.validate(&origin)?;
        sensors.validate("sensors")?;
        options.validate("sim options")?;
        let body = RigidBody::new(&vehicle.body)?;
        let battery = vehicle.battery.clone().map(Battery::new);
        let thrusters = vehicle
            .thrusters
            .iter()
            .cloned()
            .map(Thruster::new)
            .collect();
        let mut sim = Simulator {
            body,
            thrusters,
            state: options.initial.to_state(),
            t_ns: 0,
            dt_inner_ns: (1e9 / options.integration_rate_hz).round() as u64,
            dvl: sensors.dvl.map(|d| crate::dvl::Dvl::new(d, seed)),
            imu: Imu::new(sensors, seed),
            disturbance: options.disturbance,
            vehicle,
            battery,
        };
        // The voltage at rest before the first step, so the first sample already sees it.
        sim.update_supply(0.0);
        Ok(sim)
    }

    /// The battery, when the vehicle has one.
    pub fn battery(&self) -> Option<&Battery> {
        self.battery.as_ref()
    }

    /// Supply voltage the thrusters see now, V ([`FIXED_SUPPLY_V`] without a battery).
    pub fn supply_voltage_v(&self) -> f64 {
        self.battery
            .as_ref()
            .map_or(FIXED_SUPPLY_V, Battery::voltage_v)
    }

    /// Solves the battery's voltage for the held commands, drains `dt` seconds of their
    /// current and hands the voltage to the thrusters. Nothing without a battery.
    fn update_supply(&mut self, dt: f64) {
        let Some(battery) = self.battery.as_mut() else {
            return;
        };
        let thrusters = &self.thrusters;
        battery.step(dt, |v| thrusters.iter().map(|t| t.current_a(v)).sum());
        let v = battery.voltage_v();
        for t in &mut self.thrusters {
            t.set_supply(v);
        }
    }

    /// Sets the commands, one per thruster in order, normalised to [-1, 1]; non-finite values
    /// become 0 and others are clamped. They are held until the next call. A wrong count is an
    /// error and leaves the held commands unchanged.
    /// The water from now on (the weather changes: a swell comes up). Checked first; an
    /// invalid one changes nothing.
    pub fn set_disturbance(&mut self, d: DisturbanceConfig) -> Result<(), SimError> {
        d.validate("set_disturbance")?;
        self.disturbance = d;
        Ok(())
    }

    pub fn set_commands(&mut self, u: &[f64]) -> Result<(), SimError> {
        if u.len() != self.thrusters.len() {
            return Err(SimError::CommandCount {
                expected: self.thrusters.len(),
                got: u.len(),
            });
        }
        for (t, &ui) in self.thrusters.iter_mut().zip(u) {
            t.set_command(ui);
        }
        // The new load sags the voltage at once (no charge drawn yet).
        self.update_supply(0.0);
        Ok(())
    }

    /// The held (sanitised) commands.
    pub fn commands(&self) -> Vec<f64> {
        self.thrusters.iter().map(Thruster::command).collect()
    }

    /// Thrust each thruster delivers now, N (signed along its direction).
    pub fn thrusts_n(&self) -> Vec<f64> {
        self.thrusters.iter().map(Thruster::thrust_n).collect()
    }

    /// Skips the spin-up lag: every thruster jumps to the steady thrust of its held command.
    pub fn settle_thrusters(&mut self) {
        for t in &mut self.thrusters {
            t.settle();
        }
    }

    /// Integrates up to `t_ns` (ns since start) in inner steps; a time in the past is a no-op.
    pub fn step_to(&mut self, t_ns: u64) {
        while self.t_ns < t_ns {
            let h_ns = self.dt_inner_ns.min(t_ns - self.t_ns);
            self.inner_step(h_ns);
        }
    }

    /// Integrates for `dt_ns` nanoseconds.
    pub fn step(&mut self, dt_ns: u64) {
        self.step_to(self.t_ns.saturating_add(dt_ns));
    }

    /// Integrates for `dt_s` seconds (rounded to ns; negative or non-finite does nothing).
    pub fn step_secs(&mut self, dt_s: f64) {
        if dt_s.is_finite() && dt_s > 0.0 {
            self.step((dt_s * 1e9).round() as u64);
        }
    }

    /// Advances one sensor period and returns the sample taken at its end.
    pub fn advance_and_sample(&mut self) -> ImuReading {
        self.step(self.imu.config().sample_period_ns());
        self.sample()
    }

    /// A sensor sample at the current time (noise drawn now).
    pub fn sample(&mut self) -> ImuReading {
        let truth = self.sensor_truth();
        self.imu.measure(self.t_ns, &truth)
    }

    /// The noise-free sample at the current time.
    pub fn ideal_sample(&self) -> ImuReading {
        self.imu.ideal(self.t_ns, &self.sensor_truth())
    }

    /// True effectiveness `(B_fwd, B_rev)` of the current geometry at the present supply
    /// voltage, 6 x N, rows `[roll, pitch, yaw, surge, sway, heave]`; see
    /// [`crate::effectiveness`].
    pub fn truth(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        self.truth_at(self.supply_voltage_v())
    }

    /// True effectiveness at supply voltage `supply_v` (e.g. the daemon's reference voltage).
    pub fn truth_at(&self, supply_v: f64) -> (DMatrix<f64>, DMatrix<f64>) {
        let specs: Vec<ThrusterSpec> = self.thrusters.iter().map(|t| t.spec().clone()).collect();
        effectiveness_at(self.body.mass_matrix_inverse(), &specs, supply_v)
    }

    /// Applies a scenario action now.
    pub fn apply(&mut self, action: &Action) -> Result<Change, SimError> {
        let origin = "scenario action";
        let find = |name: &str| {
            self.vehicle
                .thruster_index(name)
                .ok_or_else(|| SimError::UnknownThruster(name.to_string()))
        };
        let change = match action {
            Action::Rotate {
                thruster,
                axis,
                angle_deg,
            } => {
                let i = find(thruster)?;
                let axis = Vector3::from(*axis);
                let unit = nalgebra::Unit::try_new(axis, 1e-9)
                    .ok_or_else(|| LoadError::invalid(origin, "axis", "must not be zero"))?;
                let rot = UnitQuaternion::from_axis_angle(&unit, angle_deg.to_radians());
                let mut spec = self.vehicle.thrusters[i].clone();
                spec.direction = (rot * spec.direction()).into();
                self.replace_spec(i, spec, origin)?;
                Change {
                    kind: ChangeKind::Moved,
                    index: i,
                    thruster_count: self.thrusters.len(),
                }
            }
            Action::SetDirection {
                thruster,
                direction,
            } => {
                let i = find(thruster)?;
                let mut spec = self.vehicle.thrusters[i].clone();
                spec.direction = *direction;
                self.replace_spec(i, spec, origin)?;
                Change {
                    kind: ChangeKind::Moved,
                    index: i,
                    thruster_count: self.thrusters.len(),
                }
            }
            Action::Move {
                thruster,
                position_m,
            } => {
                let i = find(thruster)?;
                let mut spec = self.vehicle.thrusters[i].clone();
                spec.position_m = *position_m;
                self.replace_spec(i, spec, origin)?;
                Change {
                    kind: ChangeKind::Moved,
                    index: i,
                    thruster_count: self.thrusters.len(),
                }
            }
            Action::Kill { thruster } => {
                let i = find(thruster)?;
                let mut spec = self.vehicle.thrusters[i].clone();
                spec.dead = true;
                self.replace_spec(i, spec, origin)?;
                Change {
                    kind: ChangeKind::Killed,
                    index: i,
                    thruster_count: self.thrusters.len(),
                }
            }
            Action::Weaken { thruster, factor } => {
                let i = find(thruster)?;
                let mut spec = self.vehicle.thrusters[i].clone();
                spec.forward_max_n *= factor;
                spec.reverse_max_n *= factor;
                self.replace_spec(i, spec, origin)?;
                Change {
                    kind: ChangeKind::Weakened,
                    index: i,
                    thruster_count: self.thrusters.len(),
                }
            }
            Action::Degrade { .. } => {
                // Expanded into `weaken` steps when the scenario is made: applied at once,
                // it would be a step, not a degradation.
                return Err(SimError::Config(LoadError::invalid(
                    origin,
                    "kind",
                    "a degrade is applied as its weaken steps (made by Scenario::new)",
                )));
            }
            Action::Remove { thruster } => {
                let i = find(thruster)?;
                // The vehicle must keep a thruster (and its truth stay publishable).
                let mut vehicle = self.vehicle.clone();
                vehicle.thrusters.remove(i);
                vehicle.validate(origin)?;
                self.vehicle = vehicle;
                self.thrusters.remove(i);
                Change {
                    kind: ChangeKind::Removed,
                    index: i,
                    thruster_count: self.thrusters.len(),
                }
            }
            Action::Add { spec } => {
                if self.vehicle.thruster_index(&spec.name).is_some() {
                    return Err(SimError::DuplicateThruster(spec.name.clone()));
                }
                if self.thrusters.len() >= MAX_THRUSTERS {
                    return Err(SimError::TooManyThrusters);
                }
                let mut spec = spec.clone();
                spec.validate(origin, "spec")?;
                let mut vehicle = self.vehicle.clone();
                vehicle.thrusters.push(spec);
                vehicle.validate(origin)?;
                let spec = vehicle.thrusters[vehicle.thrusters.len() - 1].clone();
                self.vehicle = vehicle;
                self.thrusters.push(Thruster::new(spec));
                Change {
                    kind: ChangeKind::Added,
                    index: self.thrusters.len() - 1,
                    thruster_count: self.thrusters.len(),
                }
            }
        };
        Ok(change)
    }

    /// Replaces thruster `i` when the vehicle with it is still valid (every range, and what
    /// is published about it publishable); otherwise changes nothing.
    fn replace_spec(&mut self, i: usize, spec: ThrusterSpec, origin: &str) -> Result<(), SimError> {
        let mut vehicle = self.vehicle.clone();
        vehicle.thrusters[i] = spec;
        vehicle.validate(origin)?;
        self.thrusters[i].set_spec(vehicle.thrusters[i].clone());
        self.vehicle = vehicle;
        Ok(())
    }

    /// The DVL's measurement of the body velocity when one is due now (its rate), else None;
    /// always None without a DVL.
    pub fn dvl_measurement(&mut self) -> Option<Vector3<f64>> {
        let v = self.state.linear();
        let t = self.t_ns;
        self.dvl.as_mut()?.measure(t, &v)
    }

    /// Time since start, ns.
    pub fn time_ns(&self) -> u64 {
        self.t_ns
    }

    /// Time since start, s.
    pub fn time_s(&self) -> f64 {
        self.t_ns as f64 * 1e-9
    }

    /// Inner integration step, ns.
    pub fn integration_step_ns(&self) -> u64 {
        self.dt_inner_ns
    }

    /// Sensor output period, ns.
    pub fn sample_period_ns(&self) -> u64 {
        self.imu.config().sample_period_ns()
    }

    /// The vehicle as currently configured (scenario changes included).
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// Number of thrusters (length of the command vector).
    pub fn thruster_count(&self) -> usize {
        self.thrusters.len()
    }

    /// The body model.
    pub fn body(&self) -> &RigidBody {
        &self.body
    }

    /// The full true state.
    pub fn state(&self) -> &State {
        &self.state
    }

    /// Replaces the true state (velocities included); time and thrusters are unchanged.
    pub fn set_state(&mut self, state: State) {
        self.state = state;
    }

    /// Attitude, body-to-NED.
    pub fn attitude(&self) -> UnitQuaternion<f64> {
        self.state.attitude
    }

    /// Attitude quaternion `[w, x, y, z]`, body-to-NED.
    pub fn attitude_wxyz(&self) -> [f64; 4] {
        let q = self.state.attitude.quaternion();
        [q.w, q.i, q.j, q.k]
    }

    /// Roll, pitch, yaw (ZYX Euler), rad.
    pub fn roll_pitch_yaw(&self) -> [f64; 3] {
        let (r, p, y) = self.state.attitude.euler_angles();
        [r, p, y]
    }

    /// Angular velocity `[p q r]`, body, rad/s.
    pub fn angular_velocity(&self) -> Vector3<f64> {
        self.state.angular()
    }

    /// Linear velocity over ground `[u v w]`, body, m/s.
    pub fn linear_velocity(&self) -> Vector3<f64> {
        self.state.linear()
    }

    /// Position of the CO, NED, m.
    pub fn position_ned(&self) -> Vector3<f64> {
        self.state.position_ned_m
    }

    /// `nu_dot` now (Fossen order `[u v w p q r]` derivatives, body, m/s^2 and rad/s^2) with
    /// the thrust delivered now.
    pub fn acceleration(&self) -> Vector6<f64> {
        let q = self.attitude_wxyz();
        let tau = Vector6::from(self.generalized_force(0.0, &q));
        self.body
            .acceleration(&self.state, &tau, &self.disturbance.current_ned())
    }

    /// Mechanical energy (kinetic + gravity/buoyancy potential), J.
    pub fn energy(&self) -> f64 {
        self.body.energy(&self.state)
    }

    /// True sensor biases now.
    pub fn sensor_biases(&self) -> &SensorBiases {
        self.imu.biases()
    }

    /// Generalised force (body, Fossen order) `s` seconds after the current time for attitude
    /// `q` (`[w x y z]`, unit): thrusters with their lag, plus waves and a tether.
    fn generalized_force(&self, s: f64, q: &[f64; 4]) -> [f64; 6] {
        let mut tau = [0.0; 6];
        for t in &self.thrusters {
            let f = t.thrust_after(s);
            for (acc, w) in tau.iter_mut().zip(t.wrench_array()) {
                *acc += w * f;
            }
        }
        if self.disturbance.has_forcing() {
            let att = UnitQuaternion::new_unchecked(Quaternion::new(q[0], q[1], q[2], q[3]));
            let wave = self.disturbance.forcing(self.time_s() + s, &att);
            for (acc, w) in tau.iter_mut().zip(wave.iter()) {
                *acc += w;
            }
        }
        tau
    }

    fn inner_step(&mut self, h_ns: u64) {
        let h = h_ns as f64 * 1e-9;
        let current = self.disturbance.current_ned_mps;
        let next = self.body.step_rk4_fast(&self.state, h, &current, |s, q| {
            self.generalized_force(s, q)
        });
        self.state = next;
        for t in &mut self.thrusters {
            t.advance(h);
        }
        self.update_supply(h);
        self.t_ns += h_ns;
    }

    fn sensor_truth(&self) -> SensorTruth {
        let nu_dot = self.acceleration();
        let v = self.state.linear();
        let omega = self.state.angular();
        let v_dot = nu_dot.fixed_rows::<3>(0).into_owned();
        SensorTruth {
            attitude: self.state.attitude,
            omega,
            alpha: nu_dot.fixed_rows::<3>(3).into_owned(),
            accel_co: v_dot + omega.cross(&v),
            depth_m: self.state.position_ned_m.z,
            gravity_mps2: self.body.gravity_mps2(),
        }
    }
}
