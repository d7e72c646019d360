//! The same fit made again from its log: with other thruster lags (the lag search's and the
//! per-thruster search's evaluations), with the terms at the centre's velocity once the IMU is
//! found off it, or on inputs the lab replaced (its decisive runs).

use nalgebra::Vector3;

use super::sample_log::Navigated;
use super::DynamicRun;
use crate::navigation::{DepthAid, NavState};

impl DynamicRun {
    /// This run with its log's samples replaced by `f`'s (None without a log): for the lab's
    /// decisive runs ([`SampleLog::mapped`]); refit it to see the fit on the changed inputs.
    pub fn with_log_mapped(&self, f: impl FnMut(&Navigated) -> Navigated) -> Option<DynamicRun> {
        let log = self.log.as_ref()?.mapped(f);
        Some(DynamicRun {
            log: Some(log),
            ..self.clone()
        })
    }

    /// Fit with these lags, s: one per thruster, or one for all (before any sample; ignored
    /// when empty). Thrusters whose lags differ get a mean-|command| filter each.
    pub fn set_lags(&mut self, lags: &[f64]) {
        let Some(&last) = lags.last() else {
            return;
        };
        for (i, l) in self.lags.iter_mut().enumerate() {
            *l = lags.get(i).copied().unwrap_or(last).max(0.0);
        }
        let mixed = self.lags.iter().any(|l| *l != self.lags[0]);
        self.abs_each = if mixed { vec![0.0; self.n] } else { Vec::new() };
    }

    /// The same fit made again from the log with thruster lags `lags` (s, one per thruster, or
    /// one for all), marked learned; None without a log. The navigation is not run again (it
    /// does not depend on the lag): its excursion figures are this run's.
    pub fn refit(&self, lags: &[f64]) -> Option<DynamicRun> {
        self.refit_with(lags, true, &Vector3::zeros())
    }

    /// The same fit made again from the log with lags `lags` (`learned`: whether to report
    /// them so) and the terms evaluated at the velocity of a point `imu_m` behind the IMU:
    /// the navigation integrates the IMU's acceleration, so its velocity is the IMU's,
    /// v_centre + omega x r; the centre's, which the damping and Coriolis terms act on, is
    /// v - omega x r. None without a log.
    pub fn refit_with(
        &self,
        lags: &[f64],
        learned: bool,
        imu_m: &Vector3<f64>,
    ) -> Option<DynamicRun> {
        let log = self.log.as_ref()?;
        let mut run = DynamicRun {
            lags_learned: learned,
            log: None,
            floor_when_split: self.floor_when_split,
            ..Self::with_columns(
                self.n,
                self.split,
                0.0,
                self.segment_s,
                &Vector3::new(0.0, 0.0, -1.0),
                DepthAid::default(),
            )
        };
        run.set_lags(if lags.is_empty() { &[0.0] } else { lags });
        run.nav = self.nav.clone();
        for s in log.iter() {
            let nav = NavState {
                attitude: nalgebra::UnitQuaternion::identity(),
                velocity: s.velocity - s.rate.cross(imu_m),
                rate: s.rate,
                down: s.down,
                motion: s.motion,
            };
            run.fit(s.t_s, &s.gyro, &nav, log.command(s.command), None);
        }
        Some(run)
    }
}
