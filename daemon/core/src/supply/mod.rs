//! Commands referred to a reference supply voltage (`[supply]`).
//!
//! A T200's thrust at a given command falls with the battery: about 1.4x less at 12 V than at
//! 16 V (the published table, `thruster_table`). A model learned at one voltage is then too
//! strong as the pack drains, and the refinement would see every thruster "weaken" at once.
//! Like PX4's `MC_BAT_SCALE_EN` or ArduPilot's `MOT_BAT_VOLT_MAX`, the daemon scales its
//! outputs with the measured voltage, but through the thruster's measured table instead of a
//! linear factor: everything inside the machine (controller, estimator, identification,
//! refinement, monitor) works in commands *referred to `reference_voltage_v`*, and only the
//! command that leaves the machine is carried to the present voltage, the one whose thrust at
//! the present voltage equals the referred command's thrust at the reference:
//!
//! ```text
//! u_out = T_V^-1( T_Vref(u_ref) )          T_V: the table's thrust vs command at V
//! ```
//!
//! So the estimator learns B referred to the reference voltage, and a sagging battery is not a
//! weaker thruster. Beyond what the thruster can give at the present voltage the output
//! saturates at +-1 (the referred command then asks for more than it gets: near empty, the
//! top of the command range is lost). Without a voltage reading (no driver measures one) the
//! commands go out unchanged, as before, and status says so. Pure: readings in, commands out.

mod sag;

use serde::{Deserialize, Serialize};
use thruster_driver_kit::Range;

pub use sag::Sag;
use thruster_protocol::SupplyCompensation;
use thruster_table::ThrusterTable;

/// Which thruster table refers the commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CompensationModel {
    /// No compensation: commands go out as computed whatever the voltage.
    None,
    /// The Blue Robotics T200's table (command u is the PWM 1500 + 400 u us).
    T200,
}

/// `[supply]` of thrusterd.toml.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupplyConfig {
    /// `"t200"` (default): commands are referred to `reference_voltage_v` through the T200's
    /// table whenever the driver reports a supply voltage; `"none"`: never.
    pub compensation: CompensationModel,
    /// The voltage models are learned at and commands referred to, V, in [10, 20] (the
    /// table's range). Default 16 (the T200 figures the simulator's default thrusters use).
    pub reference_voltage_v: f64,
    /// Command through the thruster's curve (with `compensation = "t200"`): a referred command
    /// c asks for thrust c times the thruster's full thrust that way at the reference
    /// voltage, so thrust is linear in the command on each side and the ESC's dead zone
    /// (+-25 us around 1500 us, where the T200 gives nothing) is stepped over instead of
    /// swallowing small corrections. Applies without a voltage reading too (at the reference
    /// voltage). Default false: the outgoing command is the one whose thrust at the present
    /// voltage equals the referred command's at the reference (the curve and dead zone kept).
    /// A driver that jumps the dead zone itself (thruster-hw's `deadband_us`) must not have
    /// it jumped twice. Issue 29 item 5; measured in docs/experiments.md ("The dead zone").
    pub linearize: bool,
    /// The pack's resistance assumed until the readings show its sag (Ohm, in [0, 0.5]):
    /// estimation pulses are capped at what the thrusters give with the pack sagging by this
    /// under all of them. Default 0.05, a weak 4S pack with its wiring (the simulator's is
    /// 0.02): too high only lowers the first pulses' power, too low lets them saturate and
    /// teach a weaker thruster. Once the readings spread over the pulses' current the fitted
    /// line (`sag`) replaces it.
    pub sag_prior_ohm: f64,
    /// Thrusters of another make, from their data sheet: thrust ~ |u|^exponent beyond a dead
    /// band their driver steps over (thruster-sim's power-law thrusters), exponent in
    /// [0.5, 3]. With `linearize` a command c then goes out as sign(c) |c|^(1/exponent), so
    /// thrust is linear in it. No voltage table exists for such a curve: it needs
    /// `compensation = "none"`. Default unset: the T200's table.
    pub power_law_exponent: Option<f64>,
}

impl Default for SupplyConfig {
    fn default() -> Self {
        SupplyConfig {
            compensation: CompensationModel::T200,
            reference_voltage_v: 16.0,
            linearize: false,
            sag_prior_ohm: 0.05,
            power_law_exponent: None,
        }
    }
}

impl SupplyConfig {
    /// The range of `power_law_exponent`: thrust from linear to cubic in the command.
    pub const EXPONENT_RANGE: Range = Range {
        lo: 0.5,
        hi: 3.0,
        lo_open: false,
        hi_open: false,
    };

    /// The range of `sag_prior_ohm`: the slopes the fitted line believes.
    pub const SAG_PRIOR_RANGE: Range = Range {
        lo: 0.0,
        hi: sag::MAX_RESISTANCE_OHM,
        lo_open: false,
        hi_open: false,
    };

    /// The range of `reference_voltage_v`: the measured voltages.
    pub const REFERENCE_RANGE: Range = Range {
        lo: 10.0,
        hi: 20.0,
        lo_open: false,
        hi_open: false,
    };
}

/// Every command finite and in [-1, 1] (0 for a non-finite one).
fn sanitize(commands: &mut [f64]) {
    for u in commands.iter_mut() {
        *u = if u.is_finite() {
            u.clamp(-1.0, 1.0)
        } else {
            0.0
        };
    }
}

/// The supply as the machine knows it, and the referral of commands.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Supply {
    config: SupplyConfig,
    /// Not in a checkpoint: the compiled-in table, the same in every process.
    #[serde(skip, default = "ThrusterTable::t200")]
    table: &'static ThrusterTable,
    voltage_v: Option<f64>,
    /// Full forward and reverse thrust at the reference voltage, N (reverse negative): the
    /// scale of a linearized command.
    full_n: (f64, f64),
    /// The pack's sag under load, learned from the readings (`sag`).
    sag: Sag,
    /// The current the last commands sent draw by the table, A: what a reading that comes
    /// before the next sample was taken under.
    draw_a: f64,
    /// A thrust curve the data named and the daemon learned (thrust ~ command^p; see
    /// [`Supply::set_learned_exponent`]); None: none learned.
    #[serde(default)]
    learned_exponent: Option<f64>,
}

impl Supply {
    /// No reading yet.
    pub fn new(config: SupplyConfig) -> Supply {
        // Parsed here, once, not in the first control tick.
        let table = ThrusterTable::t200();
        let v = config.reference_voltage_v;
        Supply {
            full_n: (
                table.thrust_at_command(v, 1.0),
                table.thrust_at_command(v, -1.0),
            ),
            config,
            table,
            voltage_v: None,
            sag: Sag::default(),
            draw_a: 0.0,
            learned_exponent: None,
        }
    }

    /// The thrust curve learned from the data, p in thrust ~ command^p, that commands now go
    /// through before everything else: a referred command c goes on as sign(c) |c|^(1/p), so
    /// the thrust is linear in c again. It is the model in force's (`DynamicTerms::
    /// command_exponent`: a model's B is per unit of the commands it was learned with), or
    /// the one an identification under control is learning with. Why: an untold curve
    /// (another make's thrust ~ command^1.5) made a linear model right at one amplitude only;
    /// the identification under control names it (`estimator::dynamic::thrust_curve`).
    /// None, or an exponent within 1 % of 1, or outside [0.5, 3]: none.
    pub fn set_learned_exponent(&mut self, exponent: Option<f64>) {
        self.learned_exponent =
            exponent.filter(|p| p.is_finite() && (0.5..=3.0).contains(p) && (p - 1.0).abs() > 0.01);
    }

    /// Whether the daemon takes the thrusters for T200s with their curve kept
    /// (`compensation = "t200"`, the default, without `linearize`): their curve and dead zone
    /// are the T200's table's, which `linearize` steps over, with a reading or without one.
    pub fn takes_t200_curve(&self) -> bool {
        self.power_law().is_none()
            && !self.config.linearize
            && self.config.compensation == CompensationModel::T200
    }

    /// The thrust curve learned, when one is in use.
    pub fn learned_exponent(&self) -> Option<f64> {
        self.learned_exponent
    }

    /// The exponent commands are linearized through, for another make's power-law curve.
    fn power_law(&self) -> Option<f64> {
        self.config
            .power_law_exponent
            .filter(|p| self.config.linearize && p.is_finite() && *p > 0.0)
    }

    /// The voltage commands go out at: the reading when compensating, the reference when
    /// only linearizing; None: commands pass unchanged (or through a power law, which has no
    /// voltage).
    fn out_voltage(&self) -> Option<f64> {
        if self.power_law().is_some() {
            return None;
        }
        match (self.config.compensation, self.voltage_v) {
            (CompensationModel::T200, Some(v)) => Some(v),
            (CompensationModel::T200, None) if self.config.linearize => {
                Some(self.config.reference_voltage_v)
            }
            _ => None,
        }
    }

    /// The supply voltage whose thrust a model learned now describes: the reference when
    /// commands are referred (a reading) or linearized (commands go out as at the reference);
    /// `None` when commands pass unchanged and the model is the thrusters' at whatever voltage
    /// they had. What a model is scored against (the lab's truth for the model).
    pub fn model_voltage_v(&self) -> Option<f64> {
        self.out_voltage().map(|_| self.config.reference_voltage_v)
    }

    /// The thrust a referred command `c` asks for, N.
    fn wanted_n(&self, c: f64) -> f64 {
        if self.config.linearize {
            if c >= 0.0 {
                c * self.full_n.0
            } else {
                -c * self.full_n.1
            }
        } else {
            self.table
                .thrust_at_command(self.config.reference_voltage_v, c)
        }
    }

    /// A validated reading (V), or `None` when the driver stopped reporting one.
    pub fn on_voltage(&mut self, voltage_v: Option<f64>) {
        self.voltage_v = voltage_v.filter(|v| v.is_finite() && *v > 0.0);
    }

    /// A reading taken at vehicle time `t_s`, under the commands last sent: the reading, and a
    /// point of the pack's sag line.
    pub fn on_reading(&mut self, t_s: f64, voltage_v: Option<f64>) {
        self.on_voltage(voltage_v);
        if let Some(v) = self.voltage_v {
            self.sag.on_reading(t_s, v, self.draw_a);
        }
    }

    /// The pack's learned sag line `(E, R)`, once the readings fix it.
    pub fn sag_line(&self) -> Option<(f64, f64)> {
        self.sag.line()
    }

    /// The last reading, V.
    pub fn voltage_v(&self) -> Option<f64> {
        self.voltage_v
    }

    /// What is done with the commands.
    pub fn state(&self) -> SupplyCompensation {
        match (self.config.compensation, self.voltage_v) {
            (CompensationModel::None, _) => SupplyCompensation::Off,
            (CompensationModel::T200, None) => SupplyCompensation::NoReading,
            (CompensationModel::T200, Some(_)) => SupplyCompensation::Active,
        }
    }

    /// Commands through the thrust curves that act beyond the dead band, in place: a learned
    /// one (`set_learned_exponent`), then another make's configured power law. Before the
    /// machine jumps the dead band (`machine.deadband`): such a curve starts at the dead
    /// band's edge (thruster-sim's e = (|u| - deadband) / (1 - deadband), thrust ~ e^p), so
    /// its inverse comes first; jumped first, a learned ^1.5 came out 1.25 and its model 20 %
    /// off. The T200's table, which holds its dead zone, comes after (`to_present`). Every
    /// command ends finite and in [-1, 1].
    pub fn through_curve(&self, commands: &mut [f64]) {
        sanitize(commands);
        for q in [self.learned_exponent, self.power_law()]
            .into_iter()
            .flatten()
        {
            for u in commands.iter_mut() {
                *u = (u.signum() * u.abs().powf(1.0 / q)).clamp(-1.0, 1.0);
            }
        }
    }

    /// Carries commands referred to the reference voltage to the present one, in place: the
    /// voltage the pack will give under these commands when its sag is known (`sag`), else
    /// the last reading. After `through_curve` and the dead band's jump. Whatever happens
    /// every command ends finite and in [-1, 1].
    pub fn to_present(&mut self, commands: &mut [f64]) {
        sanitize(commands);
        if self.power_law().is_some() {
            // Taken through in `through_curve`; no voltage table for it.
            return;
        }
        let Some(read) = self.out_voltage() else {
            return;
        };
        let mut v = read;
        if let (Some(_), Some((e, r))) = (self.voltage_v, self.sag.line()) {
            // The voltage under the draw of the commands it gives: a fixed point, contracting
            // (R dI/dV is a few percent), three steps from the last draw are within mV. Never
            // below 70 % of the open-circuit voltage, whatever the fit says.
            let mut draw = self.draw_a;
            for _ in 0..3 {
                v = (e - r * draw).clamp(0.7 * e, e);
                draw = commands
                    .iter()
                    .map(|c| self.current_a(v, self.out_command(v, *c)))
                    .sum();
            }
        }
        let mut draw = 0.0;
        for u in commands.iter_mut() {
            *u = self.out_command(v, *u);
            draw += self.current_a(v, *u);
        }
        self.draw_a = draw;
    }

    /// The command sent at voltage `v` for the referred command `c` (finite, in [-1, 1]).
    fn out_command(&self, v: f64, c: f64) -> f64 {
        let out = if c != 0.0 {
            self.table.command_for_thrust(v, self.wanted_n(c))
        } else {
            0.0
        };
        if out.is_finite() {
            out.clamp(-1.0, 1.0)
        } else {
            0.0
        }
    }

    /// The current one thruster draws at command `u` and voltage `v`, A, by the table.
    fn current_a(&self, v: f64, u: f64) -> f64 {
        let i = self.table.current_at_command(v, u);
        if i.is_finite() {
            i.max(0.0)
        } else {
            0.0
        }
    }

    /// The largest referred command magnitude the thrusters still give in both directions at
    /// the present voltage (1 when not compensating, or at or above the reference), less a 2 %
    /// margin for sag between two readings.
    pub fn attainable(&self) -> f64 {
        if self.state() != SupplyCompensation::Active {
            return 1.0;
        }
        let fwd = self.referred(1.0).abs();
        let rev = self.referred(-1.0).abs();
        if fwd >= 1.0 && rev >= 1.0 {
            1.0
        } else {
            0.98 * fwd.min(rev)
        }
    }

    /// The largest referred command magnitude every one of `thrusters` thrusters can be given
    /// at once, in both directions, with the pack sagging under their draw (`sag`), less the
    /// same 2 % margin: what an estimation pulse may ask without saturating. Without a learned
    /// sag line, [`Supply::attainable`].
    pub fn attainable_loaded(&self, thrusters: usize) -> f64 {
        let line = match (self.state(), self.sag.line(), self.voltage_v) {
            (SupplyCompensation::Active, Some(line), _) => line,
            // Not yet shown: the prior, from the last reading (the pack at rest).
            (SupplyCompensation::Active, None, Some(v)) => (v, self.config.sag_prior_ohm),
            _ => return self.attainable(),
        };
        let (e, r) = line;
        // g(a): what the voltage under n thrusters at a gives; decreasing in a, so the
        // fixed point a = g(a) is bracketed and found by bisection (once per pulse).
        let g = |a: f64| {
            let mut v = e;
            for _ in 0..3 {
                let each = [a, -a]
                    .map(|c| self.current_a(v, self.out_command(v, c)))
                    .into_iter()
                    .fold(0.0, f64::max);
                v = (e - r * thrusters as f64 * each).clamp(0.7 * e, e);
            }
            let fwd = self.referred_at(v, 1.0).abs();
            let rev = self.referred_at(v, -1.0).abs();
            (0.98 * fwd.min(rev)).min(1.0)
        };
        let (mut lo, mut hi) = (0.0, 1.0);
        if g(hi) >= hi {
            return 1.0;
        }
        for _ in 0..12 {
            let mid = 0.5 * (lo + hi);
            if g(mid) >= mid {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// The command referred to the reference voltage that `u` (sent at the present voltage)
    /// amounts to: the inverse of [`Supply::to_present`] where the output did not saturate.
    pub fn referred(&self, u: f64) -> f64 {
        let c = if let Some(p) = self.power_law() {
            u.signum() * u.abs().powf(p)
        } else {
            match self.out_voltage() {
                Some(v) => self.referred_at(v, u),
                None => u,
            }
        };
        match self.learned_exponent {
            Some(q) => c.signum() * c.abs().powf(q),
            None => c,
        }
    }

    /// The referred command that `u`, sent at voltage `v`, amounts to.
    fn referred_at(&self, v: f64, u: f64) -> f64 {
        let thrust = self.table.thrust_at_command(v, u);
        if self.config.linearize {
            let full = if thrust >= 0.0 {
                self.full_n.0
            } else {
                -self.full_n.1
            };
            if full > 0.0 {
                thrust / full
            } else {
                0.0
            }
        } else {
            self.table
                .command_for_thrust(self.config.reference_voltage_v, thrust)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t200() -> &'static ThrusterTable {
        ThrusterTable::t200()
    }

    #[test]
    fn without_a_reading_or_configured_off_commands_pass_unchanged_and_clamped() {
        let mut s = Supply::new(SupplyConfig::default());
        assert_eq!(s.state(), SupplyCompensation::NoReading);
        let mut u = [0.3, -0.7, 2.0, f64::NAN, f64::NEG_INFINITY];
        s.to_present(&mut u);
        assert_eq!(u, [0.3, -0.7, 1.0, 0.0, 0.0]);
        let mut off = Supply::new(SupplyConfig {
            compensation: CompensationModel::None,
            ..SupplyConfig::default()
        });
        off.on_voltage(Some(12.0));
        assert_eq!(off.state(), SupplyCompensation::Off);
        let mut u = [0.3, -0.7];
        off.to_present(&mut u);
        assert_eq!(u, [0.3, -0.7]);
        // A reading that is lost stops the compensation.
        s.on_voltage(Some(12.0));
        assert_eq!(s.state(), SupplyCompensation::Active);
        s.on_voltage(None);
        assert_eq!(s.state(), SupplyCompensation::NoReading);
    }

    #[test]
    fn a_learned_curve_goes_first_and_comes_back_through_referred() {
        let mut s = Supply::new(SupplyConfig {
            compensation: CompensationModel::None,
            ..SupplyConfig::default()
        });
        s.set_learned_exponent(Some(1.5));
        assert_eq!(s.learned_exponent(), Some(1.5));
        let mut u = [0.125, -0.512, 1.0, 0.0, f64::NAN];
        s.through_curve(&mut u);
        let through = u;
        s.to_present(&mut u);
        assert_eq!(u, through, "no table, no reading: nothing more");
        // 0.125^(2/3) = 0.25, 0.512^(2/3) = 0.64.
        for (got, want) in u.iter().zip([0.25, -0.64, 1.0, 0.0, 0.0]) {
            assert!((got - want).abs() < 1e-12, "{u:?}");
        }
        assert!((s.referred(0.25) - 0.125).abs() < 1e-12);
        assert!((s.referred(-0.64) + 0.512).abs() < 1e-12);
        // Linear within 1 %, or outside the configuration's range: none.
        for p in [Some(1.005), Some(0.3), Some(f64::NAN), None] {
            s.set_learned_exponent(p);
            assert_eq!(s.learned_exponent(), None, "{p:?}");
        }
        // On top of a configured power law: each undoes its own.
        let mut both = Supply::new(SupplyConfig {
            compensation: CompensationModel::None,
            linearize: true,
            power_law_exponent: Some(2.0),
            ..SupplyConfig::default()
        });
        both.set_learned_exponent(Some(0.5));
        let mut u = [0.36];
        both.through_curve(&mut u);
        both.to_present(&mut u);
        // 0.36^(1/0.5) = 0.1296, then ^(1/2) = 0.36.
        assert!((u[0] - 0.36).abs() < 1e-12, "{u:?}");
        assert!((both.referred(u[0]) - 0.36).abs() < 1e-12);
    }

    #[test]
    fn at_a_lower_voltage_the_thrust_of_the_reference_is_kept() {
        let mut s = Supply::new(SupplyConfig::default());
        s.on_voltage(Some(13.0));
        let wanted = [0.2, 0.5, -0.5, 0.8];
        let mut u = wanted;
        s.to_present(&mut u);
        for (out, r) in u.iter().zip(wanted) {
            let at_ref = t200().thrust_at_command(16.0, r);
            let now = t200().thrust_at_command(13.0, *out);
            // Within the table's 4 us steps and its few non-monotone points.
            assert!(
                (now - at_ref).abs() < 0.02 * at_ref.abs() + 0.05,
                "{r}: {out}"
            );
            assert!(out.abs() > r.abs(), "more command at the lower voltage");
            assert!((s.referred(*out) - r).abs() < 0.01, "{r}");
        }
        // Beyond what 13 V can give: saturated, never beyond 1.
        let mut u = [1.0, -1.0];
        s.to_present(&mut u);
        assert_eq!(u, [1.0, -1.0]);
        // What 13 V can give, referred to 16 V: less than full, more than the thrust ratio.
        s.on_voltage(Some(13.0));
        let a = s.attainable();
        assert!(a > 0.6 && a < 0.98, "{a}");
        let f16 = t200().thrust_at_command(16.0, a / 0.98);
        assert!(f16 <= t200().thrust_at_command(13.0, 1.0) * 1.001);
        // At the reference voltage itself the commands stay (to the table's resolution).
        s.on_voltage(Some(16.0));
        let mut u = [0.5, -0.3];
        s.to_present(&mut u);
        assert!(
            (u[0] - 0.5).abs() < 1e-9 && (u[1] + 0.3).abs() < 1e-9,
            "{u:?}"
        );
    }

    /// Another make's curve: thrust ~ |u|^1.5 is linear in the referred command, with or
    /// without a reading (no voltage table), and the inverse holds.
    #[test]
    fn a_power_law_curve_is_linearized_through_its_exponent() {
        let mut s = Supply::new(SupplyConfig {
            compensation: CompensationModel::None,
            linearize: true,
            power_law_exponent: Some(1.5),
            ..SupplyConfig::default()
        });
        for reading in [None, Some(13.0)] {
            s.on_voltage(reading);
            let asked = [0.02, 0.3, 0.8, 1.0, -0.02, -0.5, 0.0, f64::NAN, 3.0];
            let mut u = asked;
            s.through_curve(&mut u);
            s.to_present(&mut u);
            for (c, out) in asked.iter().zip(u) {
                let c = if c.is_finite() {
                    c.clamp(-1.0, 1.0)
                } else {
                    0.0
                };
                assert!(out.is_finite() && out.abs() <= 1.0);
                // thrust / full = |out|^1.5 = |c|
                assert!(
                    (out.signum() * out.abs().powf(1.5) - c).abs() < 1e-12,
                    "{c}: {out}"
                );
                assert!((s.referred(out) - c).abs() < 1e-12);
            }
            assert_eq!(s.attainable(), 1.0);
            assert_eq!(s.model_voltage_v(), None);
        }
    }

    fn linearized() -> Supply {
        Supply::new(SupplyConfig {
            linearize: true,
            ..SupplyConfig::default()
        })
    }

    /// Linearized, thrust is the command times the full thrust that way, from the smallest
    /// command up, with or without a reading; the T200's dead zone swallows 0.02 otherwise.
    #[test]
    fn linearized_commands_step_over_the_dead_zone_and_are_linear_in_thrust() {
        let (fwd, rev) = (
            t200().thrust_at_command(16.0, 1.0),
            t200().thrust_at_command(16.0, -1.0),
        );
        for voltage in [None, Some(16.0), Some(13.5)] {
            let mut s = linearized();
            s.on_voltage(voltage);
            let v = voltage.unwrap_or(16.0);
            for c in [0.02, 0.05, 0.3, 0.8, -0.02, -0.3, -0.8] {
                let mut u = [c];
                s.to_present(&mut u);
                let thrust = t200().thrust_at_command(v, u[0]);
                let want = if c > 0.0 { c * fwd } else { -c * rev };
                assert!(
                    (thrust - want).abs() <= 0.01 * want.abs() + 0.02,
                    "{voltage:?} V, c {c}: {thrust} N for {want} N (out {})",
                    u[0]
                );
                assert!((s.referred(u[0]) - c).abs() < 0.01, "{voltage:?} {c}");
            }
        }
        let mut plain = Supply::new(SupplyConfig::default());
        plain.on_voltage(Some(16.0));
        let mut u = [0.02];
        plain.to_present(&mut u);
        assert_eq!(t200().thrust_at_command(16.0, u[0]), 0.0, "{u:?}");
    }
}
