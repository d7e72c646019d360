//! Normalised command -> pulse width, per thruster.
//!
//! ```text
//! stop = neutral + trim
//! u  = 0          -> stop
//! u  > 0          -> stop + deadband + u * (max - stop - deadband)
//! u  < 0          -> stop - deadband + u * (stop - deadband - min)
//! reversed        -> u is negated first
//! ```
//! Full command reaches exactly `min`/`max`; the result is always clamped to
//! `[min, max]`, and anything non-finite maps to the stop pulse, so no input at all can
//! produce a pulse outside the configured range.

/// A pulse width in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Pwm(pub u16);

impl Pwm {
    /// Microseconds.
    pub fn us(self) -> u16 {
        self.0
    }

    /// Nanoseconds (sysfs PWM unit).
    pub fn ns(self) -> u64 {
        u64::from(self.0) * 1000
    }
}

/// Mapping parameters of one output (checked by the config: `min < stop +- deadband < max`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputParams {
    /// Shortest pulse, us.
    pub min_us: u16,
    /// Longest pulse, us.
    pub max_us: u16,
    /// Nominal stop pulse, us.
    pub neutral_us: u16,
    /// Half-width of the ESC deadband, us.
    pub deadband_us: u16,
    /// Offset of the true stop pulse, us.
    pub trim_us: i16,
    /// Negate commands.
    pub reversed: bool,
}

impl Default for OutputParams {
    /// A Blue Robotics Basic ESC.
    fn default() -> Self {
        OutputParams {
            min_us: 1100,
            max_us: 1900,
            neutral_us: 1500,
            deadband_us: 25,
            trim_us: 0,
            reversed: false,
        }
    }
}

/// The command -> pulse mapping of one output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputMap {
    params: OutputParams,
    min: f64,
    max: f64,
    stop: f64,
    deadband: f64,
}

impl OutputMap {
    /// The mapping for `params`. Inconsistent parameters (refused by the config) still
    /// give pulses within `[min_us, max_us]`.
    pub fn new(params: OutputParams) -> Self {
        let min = f64::from(params.min_us.min(params.max_us));
        let max = f64::from(params.max_us.max(params.min_us));
        let stop = (f64::from(params.neutral_us) + f64::from(params.trim_us)).clamp(min, max);
        OutputMap {
            params,
            min,
            max,
            stop,
            deadband: f64::from(params.deadband_us),
        }
    }

    /// The parameters.
    pub fn params(&self) -> &OutputParams {
        &self.params
    }

    /// The stop pulse (neutral + trim).
    pub fn neutral(&self) -> Pwm {
        self.pulse(self.stop)
    }

    /// Shortest and longest pulse this output ever gets.
    pub fn range(&self) -> (Pwm, Pwm) {
        (Pwm(self.min as u16), Pwm(self.max as u16))
    }

    /// The pulse for normalised command `u` (clamped to [-1, 1]; non-finite -> stop).
    pub fn map(&self, u: f64) -> Pwm {
        if !u.is_finite() {
            return self.neutral();
        }
        let u = u.clamp(-1.0, 1.0);
        let u = if self.params.reversed { -u } else { u };
        let us = if u > 0.0 {
            self.stop + self.deadband + u * (self.max - self.stop - self.deadband)
        } else if u < 0.0 {
            self.stop - self.deadband + u * (self.stop - self.deadband - self.min)
        } else {
            self.stop
        };
        self.pulse(us)
    }

    fn pulse(&self, us: f64) -> Pwm {
        // The clamp is the invariant the rest relies on: whatever happened above, the
        // pulse stays inside the configured range.
        Pwm(us.round().clamp(self.min, self.max) as u16)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn esc() -> OutputMap {
        OutputMap::new(OutputParams::default())
    }

    #[test]
    fn blue_robotics_esc_mapping() {
        let m = esc();
        assert_eq!(m.neutral(), Pwm(1500));
        assert_eq!(m.map(0.0), Pwm(1500));
        assert_eq!(m.map(-0.0), Pwm(1500));
        assert_eq!(m.map(1.0), Pwm(1900));
        assert_eq!(m.map(-1.0), Pwm(1100));
        // 1500 + 25 + 0.6 * 375 = 1750
        assert_eq!(m.map(0.6), Pwm(1750));
        assert_eq!(m.map(-0.2), Pwm(1400));
        // Any non-zero command leaves the deadband.
        assert_eq!(m.map(1e-9), Pwm(1525));
        assert_eq!(m.map(-1e-9), Pwm(1475));
        assert_eq!(m.range(), (Pwm(1100), Pwm(1900)));
        assert_eq!(Pwm(1500).ns(), 1_500_000);
    }

    #[test]
    fn reversed_trim_and_garbage() {
        let m = OutputMap::new(OutputParams {
            reversed: true,
            trim_us: 10,
            ..OutputParams::default()
        });
        assert_eq!(m.neutral(), Pwm(1510));
        assert_eq!(m.map(0.0), Pwm(1510));
        // Reversed: +1 is full reverse, reaching min exactly even with trim.
        assert_eq!(m.map(1.0), Pwm(1100));
        assert_eq!(m.map(-1.0), Pwm(1900));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(m.map(bad), Pwm(1510));
        }
        assert_eq!(m.map(1e9), Pwm(1100));
        assert_eq!(m.map(-1e9), Pwm(1900));
    }

    #[test]
    fn inconsistent_parameters_still_stay_in_range() {
        let m = OutputMap::new(OutputParams {
            min_us: 1400,
            max_us: 1600,
            neutral_us: 1590,
            deadband_us: 100,
            trim_us: 0,
            reversed: false,
        });
        for u in [-1.0, -0.5, 0.0, 1e-3, 0.5, 1.0] {
            let p = m.map(u).us();
            assert!((1400..=1600).contains(&p), "{u} -> {p}");
        }
    }

    proptest! {
        #[test]
        fn any_input_any_valid_config_stays_in_range_and_is_monotonic(
            u in prop::num::f64::ANY,
            v in -1.0f64..=1.0,
            w in -1.0f64..=1.0,
            min in 900u16..1400,
            span in 300u16..900,
            db in 0u16..60,
            trim in -40i16..40,
            reversed in any::<bool>(),
        ) {
            let max = min + span;
            let neutral = min + span / 2;
            let m = OutputMap::new(OutputParams {
                min_us: min, max_us: max, neutral_us: neutral,
                deadband_us: db, trim_us: trim, reversed,
            });
            let p = m.map(u).us();
            prop_assert!((min..=max).contains(&p), "{} -> {} outside [{}, {}]", u, p, min, max);
            // Monotonic in the command (decreasing when reversed).
            let (a, b) = (v.min(w), v.max(w));
            let (pa, pb) = (m.map(a).us(), m.map(b).us());
            if reversed { prop_assert!(pa >= pb) } else { prop_assert!(pa <= pb) }
        }
    }
}
