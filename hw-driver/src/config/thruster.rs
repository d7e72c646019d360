//! `[[thruster]]`: one entry per thruster, in the order of the daemon's commands.

use serde::Deserialize;

use super::ranged::ranged;
use super::LoadError;
use crate::core::pwm::OutputParams;

/// Narrowest and widest pulse any entry may name, us: beyond these no RC-style ESC or servo
/// input is specified, so such a value is a typo (e.g. ns or ms for us).
pub const PULSE_LIMITS_US: (u16, u16) = (500, 2500);

ranged!(de_min_us, "min_us", u16, 500, 2500, " us");
ranged!(de_max_us, "max_us", u16, 500, 2500, " us");
ranged!(de_neutral_us, "neutral_us", u16, 500, 2500, " us");
ranged!(de_deadband_us, "deadband_us", u16, 0, 200, " us");
ranged!(de_trim_us, "trim_us", i16, -200, 200, " us");

/// One thruster's output. Defaults are a Blue Robotics Basic ESC (1100-1900 us, 1500 us
/// neutral, +-25 us deadband).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThrusterConfig {
    /// Label for logs. Default `thruster<index>`.
    #[serde(default)]
    pub name: Option<String>,
    /// Output channel, numbered as the backend names its outputs: MAVLink `motor_test`:
    /// the board output (1-based, as labelled: MAIN OUT n / Navigator PWM n); MAVLink
    /// `rc_override`: the RC input channel 1..=6 passed through to the output; Linux: the
    /// sysfs PWM index `M` of `pwmchipN/pwmM` (0-based). Required.
    pub channel: u32,
    /// Shortest pulse ever sent, us. Default 1100.
    #[serde(default = "default_min_us", deserialize_with = "de_min_us")]
    pub min_us: u16,
    /// Longest pulse ever sent, us. Default 1900.
    #[serde(default = "default_max_us", deserialize_with = "de_max_us")]
    pub max_us: u16,
    /// The ESC's stop pulse, us. Default 1500.
    #[serde(default = "default_neutral_us", deserialize_with = "de_neutral_us")]
    pub neutral_us: u16,
    /// Half-width of the ESC's deadband around neutral, us. A non-zero command jumps past it
    /// (|u| > 0 -> neutral +- (deadband + |u| * span)), so small commands still turn the
    /// propeller. Default 25. Set 0 when the daemon compensates the deadband itself
    /// (`machine.deadband` in thrusterd.toml), or both would add it.
    #[serde(default = "default_deadband_us", deserialize_with = "de_deadband_us")]
    pub deadband_us: u16,
    /// The thruster pushes backwards for a positive pulse offset (left-handed propeller or
    /// swapped motor wires): the command's sign is flipped. Default false.
    #[serde(default)]
    pub reversed: bool,
    /// Offset of this ESC's true stop point from `neutral_us`, us: the neutral written is
    /// `neutral_us + trim_us` and the deadband is centred there. Default 0.
    #[serde(default, deserialize_with = "de_trim_us")]
    pub trim_us: i16,
}

fn default_min_us() -> u16 {
    1100
}
fn default_max_us() -> u16 {
    1900
}
fn default_neutral_us() -> u16 {
    1500
}
fn default_deadband_us() -> u16 {
    25
}

impl ThrusterConfig {
    /// A thruster on `channel` with every default.
    pub fn on_channel(channel: u32) -> Self {
        ThrusterConfig {
            name: None,
            channel,
            min_us: default_min_us(),
            max_us: default_max_us(),
            neutral_us: default_neutral_us(),
            deadband_us: default_deadband_us(),
            reversed: false,
            trim_us: 0,
        }
    }

    /// The mapping parameters of the pure core.
    pub fn params(&self) -> OutputParams {
        OutputParams {
            min_us: self.min_us,
            max_us: self.max_us,
            neutral_us: self.neutral_us,
            deadband_us: self.deadband_us,
            trim_us: self.trim_us,
            reversed: self.reversed,
        }
    }

    /// The label for logs.
    pub fn label(&self, index: usize) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| format!("thruster{index}"))
    }

    /// Cross-field checks: the stop point and its deadband lie strictly inside the range.
    pub fn validate(&self, origin: &str, index: usize) -> Result<(), LoadError> {
        let key = |k: &str| format!("thruster[{index}].{k}");
        if self.min_us >= self.max_us {
            return Err(LoadError::invalid(
                origin,
                key("min_us"),
                format!(
                    "min_us ({}) must be below max_us ({})",
                    self.min_us, self.max_us
                ),
            ));
        }
        let stop = i32::from(self.neutral_us) + i32::from(self.trim_us);
        let db = i32::from(self.deadband_us);
        let (lo, hi) = (i32::from(self.min_us), i32::from(self.max_us));
        if stop - db <= lo || stop + db >= hi {
            return Err(LoadError::invalid(
                origin,
                key("neutral_us"),
                format!(
                    "neutral_us + trim_us +- deadband_us ({stop} +- {db}) must lie strictly \
                     inside [min_us, max_us] = [{lo}, {hi}]"
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_a_blue_robotics_esc() {
        let t: ThrusterConfig = toml::from_str("channel = 3").unwrap();
        assert_eq!(t, ThrusterConfig::on_channel(3));
        assert_eq!(
            (t.min_us, t.neutral_us, t.max_us, t.deadband_us),
            (1100, 1500, 1900, 25)
        );
        t.validate("x", 0).unwrap();
    }

    #[test]
    fn out_of_range_and_inconsistent_values_are_refused() {
        let e = toml::from_str::<ThrusterConfig>("channel = 1\nmin_us = 11000").unwrap_err();
        assert!(e.message().contains("min_us"), "{e}");
        assert!(toml::from_str::<ThrusterConfig>("channel = 1\nspeed = 2").is_err());
        let mut t = ThrusterConfig::on_channel(1);
        t.trim_us = 200;
        t.max_us = 1700;
        let e = t.validate("f.toml", 4).unwrap_err().to_string();
        assert!(e.contains("thruster[4].neutral_us"), "{e}");
        t = ThrusterConfig::on_channel(1);
        t.min_us = 1900;
        assert!(t.validate("f", 0).is_err());
    }
}
