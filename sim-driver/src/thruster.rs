//! Per-thruster actuator model: command sanitising, deadband, asymmetric thrust curve,
//! saturation and first-order spin-up lag.
//!
//! Thrust is a signed scalar along the thruster's unit `direction` (N). The steady-state map
//! from a normalised command u is
//!
//! ```text
//! u := 0 if u is not finite, else clamp(u, -1, 1)
//! e  = max(0, (|u| - deadband) / (1 - deadband))          (0 inside the deadband, 1 at |u| = 1)
//! T  = +forward_max_n * e^exponent   for u > 0
//!      -reverse_max_n * e^exponent   for u < 0
//! T  = -T if reversed;   T = 0 if dead
//! ```
//!
//! and the delivered thrust follows `tau dT/dt = T_ss - T` (exact exponential update).
//!
//! A `model = "t200"` thruster takes `T_ss` from the T200's measured table at the present
//! supply voltage instead (`thruster_table`; u is the PWM pulse 1500 + 400 u us, the dead zone
//! and asymmetry are the data's), scaled by `forward_max_n` / `reverse_max_n` relative to the
//! defaults, so `weaken` works the same on both models.

use nalgebra::Vector6;
use thruster_table::ThrusterTable;

use crate::vehicle::{ThrusterModel, ThrusterSpec, T200_FORWARD_MAX_N, T200_REVERSE_MAX_N};

/// The supply a simulator without a `[battery]` has, V: the voltage of the T200 data the
/// power-law defaults (5.25 / 4.1 kgf) come from.
pub const FIXED_SUPPLY_V: f64 = 16.0;

/// Replaces a non-finite command by 0 and clamps to [-1, 1]: nothing non-finite ever reaches
/// a thruster, and a saturated command is just full thrust.
pub fn sanitize_command(u: f64) -> f64 {
    if u.is_finite() {
        u.clamp(-1.0, 1.0)
    } else {
        0.0
    }
}

/// Current the thruster draws at command `u` and supply `supply_v`, A: the T200 table's
/// (a power-law thruster is a T200-class one too); none when dead. The held command's steady
/// current, not the spin-up's.
pub fn current_at(spec: &ThrusterSpec, u: f64, supply_v: f64) -> f64 {
    if spec.dead {
        return 0.0;
    }
    ThrusterTable::t200().current_at_command(supply_v, sanitize_command(u))
}

/// Steady-state thrust (N, signed along `spec.direction`) for command `u` at the fixed
/// supply ([`FIXED_SUPPLY_V`]).
pub fn steady_thrust(spec: &ThrusterSpec, u: f64) -> f64 {
    steady_thrust_at(spec, u, FIXED_SUPPLY_V)
}

/// Steady-state thrust (N, signed along `spec.direction`) for command `u` at supply voltage
/// `supply_v` (only `t200` thrusters depend on it).
pub fn steady_thrust_at(spec: &ThrusterSpec, u: f64, supply_v: f64) -> f64 {
    let u = sanitize_command(u);
    if spec.dead {
        return 0.0;
    }
    if spec.model == ThrusterModel::T200 {
        let table = ThrusterTable::t200().thrust_at_command(supply_v, u);
        let scale = if table >= 0.0 {
            spec.forward_max_n / T200_FORWARD_MAX_N
        } else {
            spec.reverse_max_n / T200_REVERSE_MAX_N
        };
        let thrust = table * scale;
        return if spec.reversed { -thrust } else { thrust };
    }
    let mag = u.abs();
    if mag <= spec.deadband {
        return 0.0;
    }
    // Rescale so the curve starts at the deadband edge and still reaches the full maximum at
    // |u| = 1, as an ESC with a neutral band does.
    let e = ((mag - spec.deadband) / (1.0 - spec.deadband)).min(1.0);
    let shaped = e.powf(spec.exponent);
    let thrust = if u > 0.0 {
        spec.forward_max_n * shaped
    } else {
        -spec.reverse_max_n * shaped
    };
    if spec.reversed {
        -thrust
    } else {
        thrust
    }
}

/// A thruster with its dynamic state.
#[derive(Debug, Clone)]
pub struct Thruster {
    spec: ThrusterSpec,
    wrench: Vector6<f64>,
    // The same as an array, for the integration hot path.
    wrench_a: [f64; 6],
    command: f64,
    supply_v: f64,
    target_n: f64,
    thrust_n: f64,
}

impl Thruster {
    /// A stopped thruster. `spec` must be validated (unit direction).
    pub fn new(spec: ThrusterSpec) -> Self {
        let wrench = spec.wrench_per_newton();
        Thruster {
            spec,
            wrench,
            wrench_a: wrench.into(),
            command: 0.0,
            supply_v: FIXED_SUPPLY_V,
            target_n: 0.0,
            thrust_n: 0.0,
        }
    }

    /// Geometry and limits.
    pub fn spec(&self) -> &ThrusterSpec {
        &self.spec
    }

    /// Replaces geometry and limits (reconfiguration); the spin state is kept, the target is
    /// recomputed from the held command. `spec` must be validated.
    pub fn set_spec(&mut self, spec: ThrusterSpec) {
        self.wrench = spec.wrench_per_newton();
        self.wrench_a = self.wrench.into();
        self.spec = spec;
        self.target_n = steady_thrust_at(&self.spec, self.command, self.supply_v);
    }

    /// Generalised force per newton of thrust, Fossen order `[f; r x f]`.
    pub fn wrench_per_newton(&self) -> &Vector6<f64> {
        &self.wrench
    }

    pub(crate) fn wrench_array(&self) -> &[f64; 6] {
        &self.wrench_a
    }

    /// Sets the held command (sanitised, see [`sanitize_command`]).
    pub fn set_command(&mut self, u: f64) {
        self.command = sanitize_command(u);
        self.target_n = steady_thrust_at(&self.spec, self.command, self.supply_v);
    }

    /// Sets the supply voltage the thruster sees (V); the target thrust follows it.
    pub fn set_supply(&mut self, supply_v: f64) {
        if supply_v != self.supply_v && supply_v.is_finite() {
            self.supply_v = supply_v;
            if self.spec.model == ThrusterModel::T200 {
                self.target_n = steady_thrust_at(&self.spec, self.command, supply_v);
            }
        }
    }

    /// Current drawn at the held command and supply `supply_v`, A.
    pub fn current_a(&self, supply_v: f64) -> f64 {
        current_at(&self.spec, self.command, supply_v)
    }

    /// The held (sanitised) command, normalised.
    pub fn command(&self) -> f64 {
        self.command
    }

    /// Thrust the held command settles to, N.
    pub fn target_n(&self) -> f64 {
        self.target_n
    }

    /// Thrust delivered now, N (signed along the direction).
    pub fn thrust_n(&self) -> f64 {
        self.thrust_n
    }

    /// Thrust `dt` seconds from now with the command held, N (exact solution of the lag).
    pub fn thrust_after(&self, dt: f64) -> f64 {
        if self.spec.time_constant_s <= 0.0 {
            return self.target_n;
        }
        let decay = (-dt / self.spec.time_constant_s).exp();
        self.target_n + (self.thrust_n - self.target_n) * decay
    }

    /// Advances the spin state by `dt` seconds.
    pub fn advance(&mut self, dt: f64) {
        self.thrust_n = self.thrust_after(dt);
    }

    /// Jumps to the steady state of the held command (skips the lag; for tests/experiments).
    pub fn settle(&mut self) {
        self.thrust_n = self.target_n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::ThrusterSpec;

    fn spec() -> ThrusterSpec {
        ThrusterSpec::new("t", [0.0; 3], [1.0, 0.0, 0.0])
    }

    #[test]
    fn deadband_gives_zero_and_curve_starts_at_its_edge() {
        let s = spec();
        assert_eq!(steady_thrust(&s, 0.0), 0.0);
        assert_eq!(steady_thrust(&s, 0.05), 0.0);
        assert_eq!(steady_thrust(&s, -0.049), 0.0);
        let just_out = steady_thrust(&s, 0.06);
        assert!(just_out > 0.0 && just_out < 0.02 * s.forward_max_n);
        // Linear beyond the band: halfway between the edge and 1 gives half thrust.
        let mid = steady_thrust(&s, 0.525);
        assert!((mid - 0.5 * s.forward_max_n).abs() < 1e-9);
    }

    #[test]
    fn asymmetric_and_saturated() {
        let s = spec();
        assert!((steady_thrust(&s, 1.0) - 51.485).abs() < 1e-3);
        assert!((steady_thrust(&s, -1.0) + 40.207).abs() < 1e-3);
        assert_eq!(steady_thrust(&s, 3.0), steady_thrust(&s, 1.0));
        assert_eq!(steady_thrust(&s, -7.0), steady_thrust(&s, -1.0));
        assert_eq!(steady_thrust(&s, f64::NAN), 0.0);
        assert_eq!(steady_thrust(&s, f64::INFINITY), 0.0);
    }

    #[test]
    fn reversed_and_dead() {
        let mut s = spec();
        s.reversed = true;
        assert!((steady_thrust(&s, 1.0) + s.forward_max_n).abs() < 1e-12);
        assert!((steady_thrust(&s, -1.0) - s.reverse_max_n).abs() < 1e-12);
        s.dead = true;
        assert_eq!(steady_thrust(&s, 1.0), 0.0);
    }

    #[test]
    fn first_order_lag() {
        let mut t = Thruster::new(spec());
        t.set_command(1.0);
        assert_eq!(t.thrust_n(), 0.0);
        // One time constant in 1 ms steps reaches 1 - 1/e of the target.
        for _ in 0..100 {
            t.advance(0.001);
        }
        let expect = t.target_n() * (1.0 - (-1.0f64).exp());
        assert!((t.thrust_n() - expect).abs() < 1e-9 * t.target_n());
        for _ in 0..1000 {
            t.advance(0.001);
        }
        assert!((t.thrust_n() - t.target_n()).abs() < 1e-3);
        // Spin-down follows the same law.
        t.set_command(0.0);
        t.advance(0.1);
        assert!((t.thrust_n() / t.forward_max() - (-1.0f64).exp()).abs() < 1e-3);
    }

    impl Thruster {
        fn forward_max(&self) -> f64 {
            self.spec.forward_max_n
        }
    }

    #[test]
    fn t200_model_follows_the_table_and_the_voltage() {
        let mut s = spec();
        s.model = ThrusterModel::T200;
        let t = ThrusterTable::t200();
        // At 16 V full forward is the data's 5.245 kgf, full reverse its -4.069 kgf.
        assert!((steady_thrust_at(&s, 1.0, 16.0) - 5.24504 * thruster_table::KGF_N).abs() < 1e-3);
        assert!((steady_thrust_at(&s, -1.0, 16.0) + 4.06948 * thruster_table::KGF_N).abs() < 1e-3);
        // The ESC's dead zone: 0.06 is 1524 us, no thrust at 16 V.
        assert_eq!(steady_thrust_at(&s, 0.06, 16.0), 0.0);
        // 12 V against 16 V: the data's ratio at full and at half command.
        for u in [1.0, 0.5, -0.5] {
            let ratio = steady_thrust_at(&s, u, 16.0) / steady_thrust_at(&s, u, 12.0);
            let data = t.thrust_at_command(16.0, u) / t.thrust_at_command(12.0, u);
            assert!((ratio - data).abs() < 1e-12, "u {u}");
            assert!((1.3..1.6).contains(&ratio), "u {u}: {ratio}");
        }
        // weaken scales it; reversed flips it.
        s.forward_max_n *= 0.5;
        assert!(
            (steady_thrust_at(&s, 1.0, 16.0) - 0.5 * t.thrust_at_command(16.0, 1.0)).abs() < 1e-9
        );
        s.reversed = true;
        assert!(steady_thrust_at(&s, 1.0, 16.0) < 0.0);
        // The supply moves the target of a held command.
        let mut th = Thruster::new(spec_t200());
        th.set_command(1.0);
        let at16 = th.target_n();
        th.set_supply(12.0);
        assert!((at16 / th.target_n() - 5.24504 / 3.71416).abs() < 1e-4);
        assert!((th.current_a(12.0) - 16.9117).abs() < 1e-3);
    }

    fn spec_t200() -> ThrusterSpec {
        let mut s = spec();
        s.model = ThrusterModel::T200;
        s
    }

    #[test]
    fn power_law_ignores_the_supply() {
        let mut t = Thruster::new(spec());
        t.set_command(0.7);
        let before = t.target_n();
        t.set_supply(12.0);
        assert_eq!(t.target_n(), before);
    }

    #[test]
    fn zero_time_constant_is_instant() {
        let mut s = spec();
        s.time_constant_s = 0.0;
        let mut t = Thruster::new(s);
        t.set_command(-1.0);
        t.advance(1e-6);
        assert_eq!(t.thrust_n(), t.target_n());
    }
}
