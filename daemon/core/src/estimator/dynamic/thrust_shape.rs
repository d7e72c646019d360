//! The thrust's shape: a thruster whose forward and reverse gains are f and r pushes its B
//! column times u (1 + k) forward and u (1 - k) reverse, k = (f - r) / (f + r), when B is the
//! mean of the two gains. `estimator.shaped_thrust` fits the one column to that shape (the
//! open-loop pulses' unequal levels otherwise mix k into the gain, docs/study.md, "The
//! thrust's shape in the one column"); the model carries k, and whoever predicts motion from B
//! and the commands (the change test) or commands through B (the controller) shapes with it.

use super::{DynamicRun, DynamicTerms};

/// The largest forward/reverse asymmetry a model's columns may assume: a reverse ratio of
/// 0.053 (`estimator.reverse_ratio` allows any in (0, 1]); the controller divides by 1 - k.
pub const MAX_THRUST_ASYMMETRY: f64 = 0.9;

impl DynamicTerms {
    /// Command `u`'s thrust shape under [`Self::thrust_asymmetry`] `k`: what B multiplies.
    pub fn thrust_shape(k: f64, u: f64) -> f64 {
        u + k * u.abs()
    }

    /// The command whose thrust shape under `k` is `v` (the inverse of [`Self::thrust_shape`]
    /// for k in [0, 1)).
    pub fn command_for_shape(k: f64, v: f64) -> f64 {
        if v > 0.0 {
            v / (1.0 + k)
        } else {
            v / (1.0 - k)
        }
    }

    /// [`Self::thrust_asymmetry`] when usable, else 0: finite and in [0,
    /// [`MAX_THRUST_ASYMMETRY`]] (what `DynamicRun::with_asymmetry` makes). A checkpoint's
    /// value outside it is not divided by.
    pub fn asymmetry(&self) -> f64 {
        let k = self.thrust_asymmetry;
        if k.is_finite() && (0.0..=MAX_THRUST_ASYMMETRY).contains(&k) {
            k
        } else {
            0.0
        }
    }
}

impl DynamicRun {
    /// The one thrust column fitted to the thrust shape of thrusters whose forward and reverse
    /// gains are f and r, given as their ratio `reverse_ratio` = r / f (see `asymmetry`).
    ///
    /// Why: the open-loop pulses' forward level is `reverse_ratio` times the reverse one (so
    /// the impulses balance), and a column fitted to the bare command then mixes each
    /// thruster's asymmetry into its gain: the gain came out (f + r) / 2 x (1 + k q), q =
    /// (a - 1) / (a + 1), 1.5 % low on T200-like thrusters and 3 % on ones with 60 % reverse
    /// (docs/study.md, "Where the one column's 1.5-3 % comes from"). Ratios outside (0, 1]
    /// are taken as 1; k is at most [`MAX_THRUST_ASYMMETRY`].
    pub fn with_asymmetry(mut self, reverse_ratio: f64) -> Self {
        let a = if reverse_ratio > 0.0 && reverse_ratio <= 1.0 {
            reverse_ratio
        } else {
            1.0
        };
        self.asymmetry = ((1.0 - a) / (1.0 + a)).min(MAX_THRUST_ASYMMETRY);
        self
    }
}
