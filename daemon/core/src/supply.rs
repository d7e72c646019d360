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

use serde::{Deserialize, Serialize};
use thruster_driver_kit::Range;
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
}

impl Default for SupplyConfig {
    fn default() -> Self {
        SupplyConfig {
            compensation: CompensationModel::T200,
            reference_voltage_v: 16.0,
            linearize: false,
        }
    }
}

impl SupplyConfig {
    /// The range of `reference_voltage_v`: the measured voltages.
    pub const REFERENCE_RANGE: Range = Range {
        lo: 10.0,
        hi: 20.0,
        lo_open: false,
        hi_open: false,
    };
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
        }
    }

    /// The voltage commands go out at: the reading when compensating, the reference when
    /// only linearizing; None: commands pass unchanged.
    fn out_voltage(&self) -> Option<f64> {
        match (self.config.compensation, self.voltage_v) {
            (CompensationModel::T200, Some(v)) => Some(v),
            (CompensationModel::T200, None) if self.config.linearize => {
                Some(self.config.reference_voltage_v)
            }
            _ => None,
        }
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

    /// Carries commands referred to the reference voltage to the present one, in place.
    /// Whatever happens every command ends finite and in [-1, 1].
    pub fn to_present(&self, commands: &mut [f64]) {
        let present = self.out_voltage();
        for u in commands {
            let c = if u.is_finite() {
                u.clamp(-1.0, 1.0)
            } else {
                0.0
            };
            let out = match present {
                Some(v) if c != 0.0 => self.table.command_for_thrust(v, self.wanted_n(c)),
                _ => c,
            };
            *u = if out.is_finite() {
                out.clamp(-1.0, 1.0)
            } else {
                0.0
            };
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

    /// The command referred to the reference voltage that `u` (sent at the present voltage)
    /// amounts to: the inverse of [`Supply::to_present`] where the output did not saturate.
    pub fn referred(&self, u: f64) -> f64 {
        let Some(v) = self.out_voltage() else {
            return u;
        };
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
