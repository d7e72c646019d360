//! Reading TOML configuration with located errors (shared with thruster-hw through
//! `thruster_driver_kit`), plus the checks specific to this crate.

pub use thruster_driver_kit::load::{parse_toml, read_text, LoadError, Range};

/// Where checked values come from: the source named in errors (usually the file) and its
/// text, which locates each value (file:line:col); with no text ("") errors name the key
/// only (a value built in code, a scenario action applied while running).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Checker<'a> {
    pub origin: &'a str,
    pub text: &'a str,
}

impl<'a> Checker<'a> {
    pub fn new(origin: &'a str, text: &'a str) -> Self {
        Checker { origin, text }
    }

    /// An error about the value at `key` (a key path: `thruster[1].position_m[0]`), shown
    /// as `shown` (`thruster[1] ("LB").position_m[0]`).
    pub fn error(&self, key: &str, shown: &str, reason: impl Into<String>) -> LoadError {
        LoadError::value_shown(self.origin, self.text, key, shown, reason)
    }

    /// `v` must be in `range`, which NaN and the infinities never are (every range here is
    /// finite or open at infinity): `file:line:col: key: must be in [a, b], got v`.
    pub fn range(&self, key: &str, v: f64, range: Range) -> Result<(), LoadError> {
        self.range_shown(key, key, v, range)
    }

    /// As [`Checker::range`], the key shown as `shown`.
    pub fn range_shown(
        &self,
        key: &str,
        shown: &str,
        v: f64,
        range: Range,
    ) -> Result<(), LoadError> {
        if range.contains(v) {
            Ok(())
        } else {
            Err(self.error(key, shown, format!("must be in {range}, got {}", number(v))))
        }
    }

    /// Every component of `values` in `range` (errors name `key[i]`).
    pub fn each(&self, key: &str, values: &[f64], range: Range) -> Result<(), LoadError> {
        self.each_shown(key, key, values, range)
    }

    /// As [`Checker::each`], the key shown as `shown`.
    pub fn each_shown(
        &self,
        key: &str,
        shown: &str,
        values: &[f64],
        range: Range,
    ) -> Result<(), LoadError> {
        for (i, v) in values.iter().enumerate() {
            self.range_shown(&format!("{key}[{i}]"), &format!("{shown}[{i}]"), *v, range)?;
        }
        Ok(())
    }
}

/// `v` as a message prints it: the shortest form that reads back the same, but `1e300`
/// rather than its 301 digits.
pub(crate) fn number(v: f64) -> String {
    if v.is_finite() && v != 0.0 && !(1e-5..1e16).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// `[-max, max]`.
pub(crate) fn symmetric(max: f64) -> Range {
    Range::closed(-max, max)
}
