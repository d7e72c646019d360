//! The monitor's calibration against the water: how far its Chow statistic runs above the
//! white-noise expectation on the vehicle as it is, measured on consecutive batches of settled
//! control compared with the reference. A recent stretch must then differ from the reference by
//! that factor more to count as a changed thruster.
//!
//! Why: the test's variance is the block residuals' (0.1 s), as if they were white. In a swell
//! the waves' unmodelled torque is slow (a 6-7 s period) and the controller's answer to it is in
//! the commands, so the thruster coefficients fitted on 8-10 s of data wander with the wave and
//! the manoeuvre: an unchanged vehicle's statistic reaches z 20-60 and the monitor re-estimates
//! tens of times per vehicle-hour (docs/study.md, issue 32 item 5). A batch as long as the
//! reference, compared with it, shows how far an unchanged vehicle wanders in this water; the
//! mean of those chi-squares over the recent past, per degree of freedom, is the factor.
//!
//! A real change also raises the batches' statistic. So the factor in use leaves out the
//! latest batch: a batch holding the change counts only from the end of the next one, 10-20 s
//! after the change, while the monitor's verdict takes a few seconds (on a toy yaw axis the
//! factor with the latest batch put a change 1 s before a batch's end 4.4 s later).
//! Measured: docs/study.md, "A swell is not a moved thruster".
//!
//! Pure, fixed-size (the batch's normal equations are allocated once, with the monitor).

use super::{chow, Stretch};

/// The batches' chi-squares (per degree of freedom), forgetting over the recent past.
#[derive(Clone, Default, serde::Serialize, serde::Deserialize)]
pub(super) struct Calibration {
    /// The batch under way.
    batch: Box<Stretch>,
    /// Per axis: forgetting-weighted sum of the batches' chi2 / k, and the weights' sum.
    sum: [f64; 3],
    weight: f64,
    /// The same before the latest batch: what the factor uses.
    used_sum: [f64; 3],
    used_weight: f64,
    /// Batches completed since the reset (not forgotten: a count).
    batches: u32,
}

/// The calibration is used once this many batches (besides the latest) are in; until then the
/// monitor does not judge.
const MIN_BATCHES: u32 = 3;

/// The largest factor: beyond it an axis is as good as not judged.
const MAX_INFLATION: f64 = 1e6;

impl Calibration {
    /// Forget everything (a new model, control restarted). No allocation.
    pub(super) fn reset(&mut self) {
        *self.batch = Stretch::default();
        self.sum = [0.0; 3];
        self.weight = 0.0;
        self.used_sum = [0.0; 3];
        self.used_weight = 0.0;
        self.batches = 0;
    }

    /// The batch under way, to add a block to (no forgetting inside a batch).
    pub(super) fn batch_mut(&mut self) -> &mut Stretch {
        &mut self.batch
    }

    /// Close the batch once it is `batch_s` long: its chi-square against the reference, per
    /// axis, joins the forgetting mean (time constant `calibration_s`). `k` thruster terms,
    /// `p` regressors in all.
    pub(super) fn close_if_due(
        &mut self,
        reference: &Stretch,
        batch_s: f64,
        calibration_s: f64,
        k: usize,
        p: usize,
    ) {
        if self.batch.seconds < batch_s {
            return;
        }
        let mut ratio = [f64::NAN; 3];
        for (a, r) in ratio.iter_mut().enumerate() {
            if let Some(c) = chow(reference, &self.batch, a, k, p) {
                *r = c.chi2() / k as f64;
            }
        }
        // A batch the fit could not judge (a thruster never used in it) leaves the mean alone.
        if ratio.iter().all(|r| r.is_finite()) {
            (self.used_sum, self.used_weight) = (self.sum, self.weight);
            let forget = (-self.batch.seconds / calibration_s.max(1e-9)).exp();
            for (s, r) in self.sum.iter_mut().zip(ratio) {
                *s = forget * *s + r;
            }
            self.weight = forget * self.weight + 1.0;
            self.batches += 1;
        }
        *self.batch = Stretch::default();
    }

    /// Enough batches to judge (the factor in use leaves the latest out).
    pub(super) fn ready(&self) -> bool {
        self.batches > MIN_BATCHES
    }

    /// The factor (at least 1) on an axis's residual variance.
    pub(super) fn inflation(&self, axis: usize) -> f64 {
        if self.used_weight <= 0.0 {
            return 1.0;
        }
        (self.used_sum[axis] / self.used_weight).clamp(1.0, MAX_INFLATION)
    }
}
