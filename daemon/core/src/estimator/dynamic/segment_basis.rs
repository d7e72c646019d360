//! What the segmented least squares ([`super::segmented_ls`]) and its instruments
//! ([`super::instruments`]) share about a segment: the cluster slots and the segment's own
//! nuisance (its intercept, and its ramp when there is one), which both project out of their
//! sums the same way.

use nalgebra::{DVector, Vector3};

/// Cluster slots kept for the robust covariance (each at least one segment, 1 s by default).
pub const CLUSTERS: usize = 32;

/// What a segment's nuisance (its intercept, and its ramp when there is one) explains of a
/// cross product: given sum u and sum tau u of one series and the same of another, the part of
/// sum u v that the projection on the segment's [1, tau] takes out.
#[derive(Debug, Clone, Copy)]
pub(super) struct Basis {
    pub n: f64,
    pub t: f64,
    pub tt: f64,
    pub ramp: bool,
}

impl Basis {
    /// The segment's rows.
    pub(super) fn rows(&self) -> f64 {
        self.n
    }

    pub(super) fn explained(&self, au: f64, bu: f64, av: f64, bv: f64) -> f64 {
        if self.ramp {
            let det = self.n * self.tt - self.t * self.t;
            // A one-row segment has no ramp to fit.
            if det > 1e-9 * self.n * self.tt {
                return (self.tt * au * av - self.t * (au * bv + bu * av) + self.n * bu * bv) / det;
            }
        }
        au * av / self.n
    }
}

/// The open segment's sums the instruments are centred with.
pub(super) struct SegmentSums<'a> {
    pub x: &'a DVector<f64>,
    /// sum tau x, with a ramp.
    pub rx: Option<&'a DVector<f64>>,
    pub y: Vector3<f64>,
    pub ry: Vector3<f64>,
    pub basis: Basis,
}
