//! Reading TOML configuration with located errors (shared with thruster-hw through
//! `thruster_driver_kit`), plus the checks specific to this crate.

pub use thruster_driver_kit::load::{parse_toml, read_text, LoadError};

/// Checks that every component is finite.
pub(crate) fn check_finite(origin: &str, key: &str, values: &[f64]) -> Result<(), LoadError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(LoadError::invalid(origin, key, "must be finite"))
    }
}
