//! The same fit made again from its log: with other thruster lags (the lag search's and the
//! per-thruster search's evaluations), with the terms at the centre's velocity once the IMU is
//! found off it, or on inputs the lab replaced (its decisive runs).

use nalgebra::Vector3;

use super::disturbance_states::DisturbanceStates;
use super::regressors::TERMS;
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

    /// This run with its log's commands bent to the power `p` (None without a log;
    /// `top_kept`: see [`SampleLog::with_commands_bent`]), not refitted: refit it to fit
    /// thrust ~ command^p ([`super::thrust_curve::best_exponent`]).
    pub fn with_commands_bent(&self, p: f64, top_kept: bool) -> Option<DynamicRun> {
        let log = self.log.as_ref()?.with_commands_bent(p, top_kept);
        Some(DynamicRun {
            log: Some(log),
            ..self.clone()
        })
    }

    /// This run fitted again from its log with the commands bent plainly to `p` (thrust ~
    /// command^p), at its own lags, the bent log kept: a run whose B is per unit of the
    /// commands through that curve, which the lag search and the IMU's refits can refit
    /// again. None without a log.
    pub fn bent(&self, p: f64) -> Option<DynamicRun> {
        let with = self.with_commands_bent(p, false)?;
        let mut run = with.replay(self.lags(), self.lags_learned, &Vector3::zeros(), None)?;
        run.log = with.log;
        Some(run)
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
        self.replay(lags, learned, imu_m, None)
    }

    /// This run made again from its log with disturbance states `states` in place of its
    /// own ([`super::disturbance_states`]), at its lags, keeping the log so that it can be
    /// refitted in turn (the lag searched with the states): the moving-water fit
    /// (`EstimatorConfig::moving_water_states`). None without a log.
    pub fn restated(&self, states: DisturbanceStates) -> Option<DynamicRun> {
        let mut run = self.replay_with(
            self.lags(),
            self.lags_learned(),
            &Vector3::zeros(),
            None,
            states,
        )?;
        run.log = self.log.clone();
        run.last_command = self.last_command;
        Some(run)
    }

    /// A refitter for many refits of this run's log with the IMU at `imu_m`, each cheaper
    /// than [`Self::refit_with`] and the same to the bit. None without a log.
    pub fn refitter(&self, imu_m: &Vector3<f64>) -> Option<Refitter<'_>> {
        Some(Refitter {
            run: self,
            imu_m: *imu_m,
            reference: self.refit_with(self.lags(), true, imu_m)?,
        })
    }

    /// The log replayed into a fresh fit with `lags`. With `terms_from`, a fit of the same
    /// log at the same IMU position, the terms' products with each other are taken from it
    /// rather than summed again.
    fn replay(
        &self,
        lags: &[f64],
        learned: bool,
        imu_m: &Vector3<f64>,
        terms_from: Option<&DynamicRun>,
    ) -> Option<DynamicRun> {
        self.replay_with(lags, learned, imu_m, terms_from, self.disturbance)
    }

    /// [`Self::replay`] with disturbance states `states`.
    fn replay_with(
        &self,
        lags: &[f64],
        learned: bool,
        imu_m: &Vector3<f64>,
        terms_from: Option<&DynamicRun>,
        states: DisturbanceStates,
    ) -> Option<DynamicRun> {
        let log = self.log.as_ref()?;
        let run = DynamicRun {
            lags_learned: learned,
            log: None,
            floor_when_split: self.floor_when_split,
            asymmetry: self.asymmetry,
            at_rest_until_s: self.at_rest_until_s,
            term_prior_mean: self.term_prior_mean.clone(),
            ..Self::with_columns(
                self.n,
                self.split,
                0.0,
                self.segment_s,
                &Vector3::new(0.0, 0.0, -1.0),
                DepthAid::default(),
            )
        };
        let mut run = run.with_disturbance(states);
        run.set_lags(if lags.is_empty() { &[0.0] } else { lags });
        if terms_from.is_some() {
            run.skip_lag_free_terms();
        }
        run.nav = self.nav.clone();
        for s in log.iter() {
            let nav = NavState {
                attitude: s.attitude,
                velocity: s.velocity - s.rate.cross(imu_m),
                rate: s.rate,
                down: s.down,
                motion: s.motion,
            };
            run.fit(s.t_s, &s.gyro, &nav, log.command(s.command), None);
        }
        if let Some(from) = terms_from {
            if !run.adopt_lag_free_terms(from) {
                // Not a fit of the same rows: never expected; the full refit is the answer.
                return self.replay_with(lags, learned, imu_m, None, states);
            }
        }
        Some(run)
    }

    /// The terms that do not depend on the lag: all but the last (the mean |command|
    /// through the lag), after the thrust columns.
    fn lag_free_terms(&self) -> (usize, usize) {
        (self.cols, self.cols + TERMS - 1)
    }

    fn skip_lag_free_terms(&mut self) {
        let (a, b) = self.lag_free_terms();
        self.rot.skip_block(a, b);
        self.acc.skip_block(a, b);
    }

    fn adopt_lag_free_terms(&mut self, from: &DynamicRun) -> bool {
        from.cols == self.cols && self.rot.adopt_block(&from.rot) && self.acc.adopt_block(&from.acc)
    }
}

/// Many refits of one run's log at one IMU position ([`DynamicRun::refitter`]): the lag
/// search's. The terms' products with each other do not depend on the lag, so they are summed
/// once, in a reference refit, and each refit sums only the thrust columns' products (at N = 8
/// about a third of them).
#[derive(Debug, Clone)]
pub struct Refitter<'a> {
    run: &'a DynamicRun,
    imu_m: Vector3<f64>,
    reference: DynamicRun,
}

impl Refitter<'_> {
    /// The run's log fitted again with `lags` (one per thruster, or one for all), marked
    /// learned: what [`DynamicRun::refit_with`] gives, to the bit.
    pub fn refit(&self, lags: &[f64]) -> Option<DynamicRun> {
        self.run
            .replay(lags, true, &self.imu_m, Some(&self.reference))
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::super::lag_search::profile_score;
    use super::*;

    /// The asymmetry from a reverse ratio, kept within what the model's users divide by, and
    /// carried through a refit from the log (the lag search's and the IMU check's fits).
    #[test]
    fn the_thrust_asymmetry_is_bounded_and_refits_keep_it() {
        let new = |r: f64| {
            DynamicRun::new(3, 0.1, 1.0, &Vector3::z(), DepthAid::default()).with_asymmetry(r)
        };
        assert!((new(0.78).asymmetry - 0.22 / 1.78).abs() < 1e-15);
        assert_eq!(new(0.01).asymmetry, super::super::MAX_THRUST_ASYMMETRY);
        assert_eq!(new(1.5).asymmetry, 0.0);
        assert_eq!(new(f64::NAN).asymmetry, 0.0);
        let run = logged_run().with_asymmetry(0.6);
        let refit = run.refit(&[0.12]).expect("a log");
        assert_eq!(refit.asymmetry, 0.25);
        assert_eq!(
            refit
                .solve(&[1e-3; 6], 0.0, 0.0, None)
                .terms
                .thrust_asymmetry,
            0.25
        );
    }

    /// Three thrusters, 7.25 s: seven 1 s segments closed, the last left open.
    fn logged_run() -> DynamicRun {
        super::super::lag_search::tests::logged_run(3, 0.1, 1450)
    }

    /// The refitter's refits are the full refits to the bit: one lag for all and one each,
    /// the IMU at the centre and off it, B, its errors, the terms and the search's score.
    #[test]
    fn a_refitters_refit_is_the_full_refit_to_the_bit() {
        let run = logged_run();
        let rest = [0.01; 6];
        for imu in [Vector3::zeros(), Vector3::new(0.15, 0.05, -0.1)] {
            let refitter = run.refitter(&imu).unwrap();
            for lags in [vec![0.1], vec![0.04], vec![0.03, 0.2, 0.1]] {
                let (full, cheap) = (
                    run.refit_with(&lags, true, &imu).unwrap(),
                    refitter.refit(&lags).unwrap(),
                );
                assert_eq!(profile_score(&full), profile_score(&cheap), "{lags:?}");
                let (a, b) = (
                    full.solve(&rest, 0.0, 0.0, None),
                    cheap.solve(&rest, 0.0, 0.0, None),
                );
                assert_eq!(a.b, b.b, "{lags:?} at {imu:?}");
                assert_eq!(a.std_err, b.std_err, "{lags:?} at {imu:?}");
                assert_eq!(a.rel_err, b.rel_err);
                assert_eq!(a.terms.coefficients, b.terms.coefficients);
                assert_eq!(cheap.lags(), full.lags());
            }
        }
    }

    /// A refit of another log cannot take the terms from this one's reference: it falls back
    /// to the full refit.
    #[test]
    fn a_reference_of_other_rows_is_not_taken() {
        let run = logged_run();
        let reference = run.refit_with(&[0.1], true, &Vector3::zeros()).unwrap();
        let mut other = DynamicRun::new(3, 0.1, 1.0, &Vector3::z(), DepthAid::default());
        other.skip_lag_free_terms();
        assert!(!other.adopt_lag_free_terms(&reference), "no rows yet");
    }
}
