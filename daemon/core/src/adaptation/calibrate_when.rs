//! When the detectors' calibrations against the water (`monitor.calibration_s`,
//! `refinement.change_calibration_s`) apply: in a sea only, or always.
//!
//! Why not always: a calibration measures how far an unchanged vehicle's statistic runs in the
//! water it is in, and a detector judges only once it has batches (30-50 s after every new
//! model). In a swell that is what keeps the change test and the monitor from taking the
//! controller's answer to the waves for a moved thruster (13-35 needless re-estimations per
//! vehicle-hour uncalibrated). In still water it only costs: the detectors are blind for the
//! first minute after every model, and the model's own few-percent errors under manoeuvres
//! inflate the factor too, so a moved thruster was found later and not named (docs/study.md,
//! "A swell is not a moved thruster"). The sea-state gauge (`identification::sea_state`, the
//! attitude error while held, steps' transients left out) tells the two apart: still water
//! reads under 1.5 deg or nothing, moderate water 7.5-12.4, rough 13-18; in a sea
//! ([`sea_state::InASea`](super::identification::sea_state::InASea)) the calibrations start
//! afresh and apply, elsewhere the detectors judge uncalibrated, exactly as without them.

use serde::{Deserialize, Serialize};

/// When a detector's calibration against the water applies (its time constant > 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CalibrateWhen {
    /// While the sea-state gauge says the water moves the held vehicle (the default).
    #[default]
    InASea,
    /// Always (open water with waves known in advance; before 2026-12-01 the only mode).
    Always,
}

impl CalibrateWhen {
    /// Whether a calibration with time constant `calibration_s` (0: off) applies now, the
    /// vehicle being `in_a_sea` or not.
    pub fn applies(self, calibration_s: f64, in_a_sea: bool) -> bool {
        calibration_s > 0.0
            && match self {
                CalibrateWhen::InASea => in_a_sea,
                CalibrateWhen::Always => true,
            }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_calibration_applies_when_on_and_in_a_sea_or_always() {
        assert!(!CalibrateWhen::InASea.applies(120.0, false));
        assert!(CalibrateWhen::InASea.applies(120.0, true));
        assert!(CalibrateWhen::Always.applies(120.0, false));
        assert!(!CalibrateWhen::Always.applies(0.0, true));
        assert!(!CalibrateWhen::InASea.applies(0.0, true));
    }
}
