//! The model in force's common gain at the hold's commands: the one factor by which every
//! column of a window's fit differs from the model's, per row group, pooled over the windows
//! judged against the same B.
//!
//! Why: on thrusters whose thrust is not linear in the command and a daemon not told, the
//! open-loop model is a line through its pulses' amplitude, and held at small commands the
//! vehicle gets less (thrust ~ command^1.5: about 60 % less) than the model says. With a
//! realistic IMU an identification names the curve; at the paper's noise nothing does (its
//! evidence 15-32 against a limit of 50), each refinement window's bound ends at 0.44-0.58,
//! and the line stayed in force 0.10-0.13 off the truth under a bound of 0.043-0.058, a
//! confident wrong model (issue 32 item 4). One factor over every column is far better
//! determined than the matrix the window fits, and a window's worth of them, pooled, sees a
//! gap of that size. A supply the daemon cannot read (a battery sagging without a voltage
//! reading) shows the same way, and is as real an error of the model in force.
//!
//! The factor per window is the weighted least-squares fit of the window's B on the model's,
//! each entry weighed by its standard error (scaled by `window_se_scale`: a window's errors
//! understate its real error at the paper's noise); the pool is the windows' weighted mean.

use nalgebra::DMatrix;
use thruster_protocol::MAX_THRUSTERS;

use super::fusion::BLOCKS;

/// One window's common gain over the model in force, per row group: (gain, standard error);
/// None for a group with nothing to weigh.
pub type WindowGain = [Option<(f64, f64)>; 2];

/// The factor g minimising sum ((w - g m) / se)^2 over each group's entries of the window's
/// fit `window` (standard errors `window_se`, times `se_scale`) and the model's `model`, with
/// its standard error. Entries whose standard error is not a positive number (a column the
/// window did not excite) are left out.
pub fn window_gain(
    window: &DMatrix<f64>,
    window_se: &DMatrix<f64>,
    model: &DMatrix<f64>,
    se_scale: f64,
) -> WindowGain {
    if window.shape() != model.shape() || window_se.shape() != model.shape() || model.nrows() != 6 {
        return [None; 2];
    }
    BLOCKS.map(|rows| {
        let (mut mm, mut mw) = (0.0, 0.0);
        for j in 0..model.ncols() {
            for r in rows.clone() {
                let se = window_se[(r, j)] * se_scale;
                let (m, w) = (model[(r, j)], window[(r, j)]);
                if !(se > 0.0 && se.is_finite() && m.is_finite() && w.is_finite()) {
                    continue;
                }
                let inv = 1.0 / (se * se);
                mm += m * m * inv;
                mw += m * w * inv;
            }
        }
        (mm > 0.0 && mm.is_finite()).then(|| (mw / mm, mm.sqrt().recip()))
    })
}

/// A model's B kept by value in a fixed array: the pool takes a window's gain on the control
/// tick, where nothing allocates.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
struct Against {
    rows: [[f64; MAX_THRUSTERS]; 6],
    thrusters: usize,
}

impl Against {
    /// None for a matrix that is not 6 x at most `MAX_THRUSTERS`.
    fn of(b: &DMatrix<f64>) -> Option<Self> {
        if b.nrows() != 6 || b.ncols() > MAX_THRUSTERS {
            return None;
        }
        let mut rows = [[0.0; MAX_THRUSTERS]; 6];
        for (r, row) in rows.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().take(b.ncols()).enumerate() {
                *v = b[(r, j)];
            }
        }
        Some(Against {
            rows,
            thrusters: b.ncols(),
        })
    }

    fn is(&self, b: &DMatrix<f64>) -> bool {
        b.nrows() == 6
            && b.ncols() == self.thrusters
            && (0..6).all(|r| (0..self.thrusters).all(|j| self.rows[r][j] == b[(r, j)]))
    }
}

/// The windows' gains pooled since the model in force's B last changed.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GainPool {
    /// The B the windows were judged against (a refinement or a new model starts over; a
    /// bound restated in place does not).
    against: Option<Against>,
    /// Per group: sum of 1 / se^2 and of gain / se^2.
    information: [f64; 2],
    weighted: [f64; 2],
    /// Windows pooled.
    windows: u32,
}

/// What the pool says: the common gain per row group with its standard error.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PooledGain {
    pub gain: [f64; 2],
    pub std_err: [f64; 2],
    pub windows: u32,
}

impl GainPool {
    /// One window's gain over `model` (the B in force when it was judged).
    pub fn push(&mut self, model: &DMatrix<f64>, gain: WindowGain) {
        if !self.against.is_some_and(|a| a.is(model)) {
            *self = GainPool {
                against: Against::of(model),
                ..GainPool::default()
            };
            if self.against.is_none() {
                return;
            }
        }
        let mut any = false;
        for (g, v) in gain.iter().enumerate() {
            if let Some((k, se)) = v.filter(|(k, se)| k.is_finite() && *se > 0.0) {
                let inv = 1.0 / (se * se);
                self.information[g] += inv;
                self.weighted[g] += k * inv;
                any = true;
            }
        }
        if any {
            self.windows += 1;
        }
    }

    /// Start over (a new model, control restarted).
    pub fn reset(&mut self) {
        *self = GainPool::default();
    }

    /// The pooled gain over `model`; None when the windows were judged against another B, or
    /// before any.
    pub fn pooled(&self, model: &DMatrix<f64>) -> Option<PooledGain> {
        if self.windows == 0 || !self.against.is_some_and(|a| a.is(model)) {
            return None;
        }
        let each = |g: usize| {
            let i = self.information[g];
            if i > 0.0 {
                (self.weighted[g] / i, i.sqrt().recip())
            } else {
                (f64::NAN, f64::INFINITY)
            }
        };
        let (r, a) = (each(0), each(1));
        Some(PooledGain {
            gain: [r.0, a.0],
            std_err: [r.1, a.1],
            windows: self.windows,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::{window_gain, GainPool};
    use nalgebra::DMatrix;

    fn model() -> DMatrix<f64> {
        DMatrix::from_fn(6, 4, |r, c| {
            if (r + c) % 3 == 0 {
                0.5
            } else {
                -0.2 - 0.1 * c as f64
            }
        })
    }

    /// A window that is the model scaled: that factor, in each group; its standard error the
    /// weighted sum's, and a column without standard errors left out.
    #[test]
    fn a_scaled_window_gives_its_scale() {
        let m = model();
        let mut w = m.clone();
        w.rows_mut(0, 3).scale_mut(0.4);
        w.rows_mut(3, 3).scale_mut(1.1);
        let mut se = DMatrix::from_element(6, 4, 0.05);
        // Column 3 unexcited: whatever the window says there is left out.
        se.column_mut(3).fill(f64::INFINITY);
        w.column_mut(3).fill(9.0);
        let g = window_gain(&w, &se, &m, 2.0);
        let (rot, acc) = (g[0].unwrap(), g[1].unwrap());
        assert!(
            (rot.0 - 0.4).abs() < 1e-12 && (acc.0 - 1.1).abs() < 1e-12,
            "{g:?}"
        );
        let mm: f64 = m.view((0, 0), (3, 3)).iter().map(|v| v * v).sum();
        assert!((rot.1 - 0.1 / mm.sqrt()).abs() < 1e-12, "{g:?}");
        // Shapes that do not match say nothing.
        assert_eq!(window_gain(&w, &se, &DMatrix::zeros(6, 3), 1.0), [None; 2]);
    }

    /// The pool is the windows' weighted mean, and starts over when B changes.
    #[test]
    fn the_pool_weighs_windows_and_starts_over_on_a_new_b() {
        let m = model();
        let mut pool = GainPool::default();
        assert_eq!(pool.pooled(&m), None);
        pool.push(&m, [Some((0.5, 0.1)), Some((1.0, 0.2))]);
        pool.push(&m, [Some((0.8, 0.2)), None]);
        let p = pool.pooled(&m).unwrap();
        let want = (0.5 / 0.01 + 0.8 / 0.04) / (1.0 / 0.01 + 1.0 / 0.04);
        assert!((p.gain[0] - want).abs() < 1e-12, "{p:?}");
        assert!((p.std_err[0] - (1.0f64 / 0.01 + 1.0 / 0.04).sqrt().recip()).abs() < 1e-12);
        assert_eq!((p.gain[1], p.windows), (1.0, 2));
        // Asked about another B: nothing; a window against it starts over.
        let mut other = m.clone();
        other[(0, 0)] = 0.6;
        assert_eq!(pool.pooled(&other), None);
        pool.push(&other, [Some((0.9, 0.1)), Some((1.0, 0.1))]);
        assert_eq!(pool.pooled(&other).unwrap().windows, 1);
        assert_eq!(pool.pooled(&m), None);
    }
}
