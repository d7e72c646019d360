//! Excitation plans: which thrusters fire, and with which sign, on each pulse.
//!
//! The pulse design sets the Gram matrix U^T U of the regression and so the estimate's
//! covariance sigma^2 (U^T U)^-1. One thruster at a time (the paper) gives diag(m_i p^2); all
//! thrusters at +-p along Hadamard rows give M p^2 I after M pulses: about sqrt(N) times smaller
//! error for the same number of pulses.

use serde::{Deserialize, Serialize};

/// The pulse pattern family, chosen in config.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Excitation {
    /// The paper's: thruster 1 at +p, thruster 1 at -p, thruster 2 at +p, ...
    RoundRobin,
    /// Two thrusters per pulse with the sign patterns ++, --, +-, -+ (orthogonal within a pair).
    Pairs,
    /// All thrusters at once, signs from the rows of a Sylvester Hadamard matrix, each row
    /// followed by its negation so forward and reverse thrust are balanced.
    Orthogonal,
    /// Orthogonal patterns as doublet pairs, back to back: each Hadamard row r pulsed as
    /// +r, -r, -r, +r, so the body rate and the angle it caused both return near zero after
    /// every four pulses (no settles needed; the dynamic method's default).
    DoubletPairs,
}

impl Excitation {
    /// The pulse-and-settle plans of the static study (Fig. 2).
    pub const ALL: [Excitation; 3] = [
        Excitation::RoundRobin,
        Excitation::Pairs,
        Excitation::Orthogonal,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Excitation::RoundRobin => "round_robin",
            Excitation::Pairs => "pairs",
            Excitation::Orthogonal => "orthogonal",
            Excitation::DoubletPairs => "doublet_pairs",
        }
    }
}

/// A concrete plan for N thrusters: the sign pattern (entries -1, 0, +1) of every pulse.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ExcitationPlan {
    kind: Excitation,
    n: usize,
    /// One full cycle of patterns; pulse k uses `cycle[k % cycle.len()]`.
    cycle: Vec<Vec<f64>>,
    /// The fewest pulses whose patterns tell every thruster apart, found once here: asking
    /// `confounded` is an eigendecomposition, and the stop gate asks every sample.
    spans_at: usize,
}

impl ExcitationPlan {
    /// Plan for `n` thrusters (n >= 1).
    pub fn new(kind: Excitation, n: usize) -> Self {
        let n = n.max(1);
        let cycle = match kind {
            Excitation::RoundRobin => round_robin(n),
            Excitation::Pairs => pairs(n),
            Excitation::Orthogonal => orthogonal(n),
            Excitation::DoubletPairs => doublet_pairs(n),
        };
        let mut plan = ExcitationPlan {
            kind,
            n,
            cycle,
            spans_at: 0,
        };
        plan.spans_at = first_spanning(&plan.cycle, n);
        plan
    }

    pub fn kind(&self) -> Excitation {
        self.kind
    }

    pub fn thrusters(&self) -> usize {
        self.n
    }

    /// Pulses in one full cycle; after a cycle every thruster has fired in both directions and
    /// the Gram matrix is full rank.
    pub fn cycle_len(&self) -> usize {
        self.cycle.len()
    }

    /// Sign pattern of pulse `k` (0-based).
    pub fn pattern(&self, k: usize) -> &[f64] {
        &self.cycle[k % self.cycle.len()]
    }

    /// The level (1 or `second`) at which every thruster fires on pulse `pulse`: doublet
    /// pairs fire each row's second doublet (-r, +r) at `second`, every other plan and pulse
    /// at 1. Why the same pattern at two levels, and not some thrusters low in some rows:
    /// with as many rows as thrusters (eight_vectored) any change of one row's response is
    /// a mix of the thrusters' columns, so a curve moves B's columns around and leaves the
    /// fit's residual where it was (measured: the score did not move between thrust ~
    /// command^0.3 and ^3); one pattern at two levels has no such mix. The Gram matrix stays
    /// diagonal (each row weighted 1 + second^2). The cost: a row's four pulses leave the
    /// body (1 - second) of one doublet's angle away from where it started.
    pub fn level(&self, pulse: usize, second: f64) -> f64 {
        if self.kind != Excitation::DoubletPairs {
            return 1.0;
        }
        if pulse % 4 >= 2 {
            second
        } else {
            1.0
        }
    }

    /// The thrusters whose columns the first `pulses` patterns cannot tell apart from the
    /// others': those a combination of thrusters that no pattern so far has told apart
    /// involves (the patterns' null space). Empty once the patterns span every thruster (a
    /// whole cycle always does).
    ///
    /// Why the plan and not the fit: the dynamic fit's columns are the lagged commands, and
    /// with the thrust's shape (forward and reverse weighted apart) thrusters pulsed in the
    /// same patterns are not exactly collinear there, so its pseudo-inverse reports a small
    /// bound on what the data cannot separate. eight_vectored stopped after 16 pulses
    /// (`max_pulses`, noise-free) came out 0.71 off under a 0.02 bound and was swapped in.
    pub fn confounded(&self, pulses: usize) -> Vec<usize> {
        // A whole cycle spans every thruster (`every_plan_has_a_diagonal_gram_over_a_cycle`):
        // the estimates after it, most of a run's, skip the decomposition.
        if pulses >= self.cycle.len() {
            return Vec::new();
        }
        let n = self.n;
        let mut gram = nalgebra::DMatrix::<f64>::zeros(n, n);
        for row in &self.cycle[..pulses] {
            for i in 0..n {
                for j in 0..n {
                    gram[(i, j)] += row[i] * row[j];
                }
            }
        }
        let eig = gram.symmetric_eigen();
        let top = eig.eigenvalues.iter().fold(0.0f64, |m, v| m.max(*v));
        // The patterns' entries are -1, 0, 1, so a spanned direction's eigenvalue is of order
        // one; round-off leaves an unspanned one at 1e-15 of the largest.
        let null: Vec<usize> = (0..n)
            .filter(|&c| eig.eigenvalues[c] <= 1e-9 * top.max(1.0))
            .collect();
        (0..n)
            .filter(|&i| null.iter().any(|&c| eig.eigenvectors[(i, c)].abs() > 1e-6))
            .collect()
    }

    /// The fewest pulses, a multiple of `step`, whose patterns tell every thruster apart
    /// (`confounded` empty); at most a whole cycle, which always does.
    /// Cheap: once the patterns span, more pulses never take it back.
    pub fn spanned_at(&self, step: usize) -> usize {
        self.spans_at
            .next_multiple_of(step.max(1))
            .min(self.cycle.len())
    }
}

fn round_robin(n: usize) -> Vec<Vec<f64>> {
    (0..2 * n)
        .map(|k| {
            let mut row = vec![0.0; n];
            row[k / 2] = if k % 2 == 0 { 1.0 } else { -1.0 };
            row
        })
        .collect()
}

fn pairs(n: usize) -> Vec<Vec<f64>> {
    if n == 1 {
        return round_robin(1);
    }
    const SIGNS: [(f64, f64); 4] = [(1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0)];
    let mut out = Vec::new();
    let mut i = 0;
    while i < n {
        // An odd thruster out is paired with thruster 0 again: still orthogonal within the pair.
        let j = if i + 1 < n { i + 1 } else { 0 };
        for (si, sj) in SIGNS {
            let mut row = vec![0.0; n];
            row[i] = si;
            row[j] = sj;
            out.push(row);
        }
        i += 2;
    }
    out
}

/// Sylvester Hadamard matrix of order 2^k >= n, first n columns; each row then its negation.
fn orthogonal(n: usize) -> Vec<Vec<f64>> {
    let h = hadamard(n.next_power_of_two().max(2));
    let mut out = Vec::with_capacity(2 * h.len());
    for row in &h {
        out.push(row[..n].to_vec());
    }
    for row in &h {
        out.push(row[..n].iter().map(|x| -x).collect());
    }
    out
}

/// The fewest leading patterns of `cycle` that span all `n` thrusters (`confounded` empty,
/// which is the patterns' Gram matrix at full rank), or the whole cycle. Found by adding the
/// patterns one at a time to an orthonormal basis (Gram-Schmidt, twice for round-off), not
/// by an eigendecomposition per pulse count: a refinement window builds a plan on the control
/// thread, and searched that way 16 thrusters' 64-pulse cycle cost 0.9 ms there
/// (`cargo bench -p thrusterd-core --bench estimator -- closed_loop_window_open`).
fn first_spanning(cycle: &[Vec<f64>], n: usize) -> usize {
    let mut basis: Vec<Vec<f64>> = Vec::with_capacity(n);
    for (k, row) in cycle.iter().enumerate() {
        let mut v = row.clone();
        for _ in 0..2 {
            for b in &basis {
                let dot: f64 = v.iter().zip(b).map(|(x, y)| x * y).sum();
                v.iter_mut().zip(b).for_each(|(x, y)| *x -= dot * y);
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        // Entries are -1, 0, 1: a new direction leaves a residual of order one, a repeated
        // one round-off.
        if norm > 1e-6 {
            v.iter_mut().for_each(|x| *x /= norm);
            basis.push(v);
            if basis.len() == n {
                return k + 1;
            }
        }
    }
    cycle.len()
}

/// Each Hadamard row (first n columns) as +r, -r, -r, +r.
fn doublet_pairs(n: usize) -> Vec<Vec<f64>> {
    let h = hadamard(n.next_power_of_two().max(2));
    let mut out = Vec::with_capacity(4 * h.len());
    for row in &h {
        let r = &row[..n];
        let neg: Vec<f64> = r.iter().map(|x| -x).collect();
        out.extend([r.to_vec(), neg.clone(), neg, r.to_vec()]);
    }
    out
}

/// Sylvester construction: H_1 = [1], H_2m = [[H, H], [H, -H]].
pub fn hadamard(order: usize) -> Vec<Vec<f64>> {
    assert!(
        order.is_power_of_two(),
        "Sylvester Hadamard needs a power of two"
    );
    let mut h = vec![vec![1.0]];
    while h.len() < order {
        let m = h.len();
        let mut next = vec![vec![0.0; 2 * m]; 2 * m];
        for r in 0..m {
            for c in 0..m {
                next[r][c] = h[r][c];
                next[r][c + m] = h[r][c];
                next[r + m][c] = h[r][c];
                next[r + m][c + m] = -h[r][c];
            }
        }
        h = next;
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gram(plan: &ExcitationPlan, pulses: usize) -> Vec<Vec<f64>> {
        let n = plan.thrusters();
        let mut g = vec![vec![0.0; n]; n];
        for k in 0..pulses {
            let u = plan.pattern(k);
            for i in 0..n {
                for j in 0..n {
                    g[i][j] += u[i] * u[j];
                }
            }
        }
        g
    }

    fn assert_diag(g: &[Vec<f64>], diag: f64) {
        for (i, row) in g.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                let want = if i == j { diag } else { 0.0 };
                assert!((v - want).abs() < 1e-12, "G[{i}][{j}] = {v}, want {want}");
            }
        }
    }

    #[test]
    fn round_robin_is_the_papers_order() {
        let p = ExcitationPlan::new(Excitation::RoundRobin, 3);
        assert_eq!(p.cycle_len(), 6);
        assert_eq!(p.pattern(0), &[1.0, 0.0, 0.0]);
        assert_eq!(p.pattern(1), &[-1.0, 0.0, 0.0]);
        assert_eq!(p.pattern(2), &[0.0, 1.0, 0.0]);
        assert_eq!(p.pattern(6), &[1.0, 0.0, 0.0]);
        assert_diag(&gram(&p, 6), 2.0);
    }

    #[test]
    fn every_plan_has_a_diagonal_gram_over_a_cycle() {
        for n in 1..=16 {
            let rr = ExcitationPlan::new(Excitation::RoundRobin, n);
            assert_diag(&gram(&rr, rr.cycle_len()), 2.0);
            let orth = ExcitationPlan::new(Excitation::Orthogonal, n);
            let h = n.next_power_of_two().max(2);
            assert_eq!(orth.cycle_len(), 2 * h);
            assert_diag(&gram(&orth, orth.cycle_len()), 2.0 * h as f64);
            if n % 2 == 0 {
                let pr = ExcitationPlan::new(Excitation::Pairs, n);
                assert_diag(&gram(&pr, pr.cycle_len()), 4.0);
            }
        }
    }

    #[test]
    fn odd_pairs_are_full_rank_and_balanced() {
        let p = ExcitationPlan::new(Excitation::Pairs, 5);
        assert_eq!(p.cycle_len(), 12);
        let g = gram(&p, p.cycle_len());
        // Thruster 0 fires in two pairs; every pair block is orthogonal.
        assert_eq!(g[0][0], 8.0);
        assert_eq!(g[4][4], 4.0);
        assert_eq!(g[0][4], 0.0);
        for k in 0..p.cycle_len() {
            assert!(p.pattern(k).iter().filter(|x| **x != 0.0).count() == 2);
        }
        let sum: f64 = (0..p.cycle_len()).map(|k| p.pattern(k)[4]).sum();
        assert_eq!(sum, 0.0, "forward and reverse pulses balanced");
    }

    /// With a second level the cycle's Gram matrix stays diagonal (every row weighted 1 +
    /// second^2), and every thruster fires in both directions at both levels: the curve is
    /// seen within each direction, apart from the reverse ratio.
    #[test]
    fn the_second_level_keeps_the_design_orthogonal_and_fires_both_levels_both_ways() {
        for n in [3, 5, 6, 8] {
            let plan = ExcitationPlan::new(Excitation::DoubletPairs, n);
            let h = n.next_power_of_two().max(2) as f64;
            let mut g = vec![vec![0.0; n]; n];
            let mut seen = vec![std::collections::BTreeSet::new(); n];
            for k in 0..plan.cycle_len() {
                let level = plan.level(k, 0.6);
                let u: Vec<f64> = plan.pattern(k).iter().map(|s| s * level).collect();
                for ((row, seen), ui) in g.iter_mut().zip(seen.iter_mut()).zip(&u) {
                    seen.insert(((ui * 10.0).round()) as i64);
                    for (gij, uj) in row.iter_mut().zip(&u) {
                        *gij += ui * uj;
                    }
                }
            }
            assert_diag(&g, 2.0 * h * (1.0 + 0.36));
            for s in &seen {
                let want: std::collections::BTreeSet<i64> = [-10, -6, 6, 10].into();
                assert_eq!(*s, want, "n = {n}");
            }
        }
        // One level: every pulse at 1; the other plans never take the second.
        let plan = ExcitationPlan::new(Excitation::DoubletPairs, 5);
        assert!((0..32).all(|k| plan.level(k, 1.0) == 1.0));
        let orth = ExcitationPlan::new(Excitation::Orthogonal, 5);
        assert!((0..32).all(|k| orth.level(k, 0.6) == 1.0));
    }

    #[test]
    fn confounded_until_the_patterns_span_every_thruster() {
        // eight_vectored: doublet pairs of the order-8 Hadamard rows, four pulses a row, so
        // k rows span k thrusters' directions and all 8 are confounded until 32 pulses.
        let eight = ExcitationPlan::new(Excitation::DoubletPairs, 8);
        assert_eq!(eight.confounded(16).len(), 8);
        assert_eq!(eight.confounded(28).len(), 8);
        assert!(eight.confounded(32).is_empty());
        assert!(eight.confounded(40).is_empty());
        // AMOUR-5: the first five rows of H8 on five columns span them; four do not.
        let five = ExcitationPlan::new(Excitation::DoubletPairs, 5);
        assert!(!five.confounded(16).is_empty());
        assert!(five.confounded(20).is_empty());
        assert_eq!(five.spanned_at(1), 17);
        assert_eq!(five.spanned_at(4), 20);
        assert_eq!(eight.spanned_at(4), 32);
        // Round robin: a thruster not yet pulsed is confounded (with nothing: its column
        // is all zero), the others not.
        let rr = ExcitationPlan::new(Excitation::RoundRobin, 3);
        assert_eq!(rr.confounded(2), vec![1, 2]);
        assert!(rr.confounded(6).is_empty());
        assert_eq!(rr.confounded(0), vec![0, 1, 2]);
    }

    #[test]
    fn the_span_found_by_gram_schmidt_is_the_first_pulse_count_the_eigenvalues_call_spanning() {
        for kind in [
            Excitation::RoundRobin,
            Excitation::Pairs,
            Excitation::Orthogonal,
            Excitation::DoubletPairs,
        ] {
            for n in 1..=thruster_protocol::MAX_THRUSTERS {
                let plan = ExcitationPlan::new(kind, n);
                let searched = (1..plan.cycle_len())
                    .find(|&k| plan.confounded(k).is_empty())
                    .unwrap_or(plan.cycle_len());
                assert_eq!(plan.spanned_at(1), searched, "{kind:?}, {n} thrusters");
            }
        }
    }

    #[test]
    fn hadamard_rows_are_orthogonal() {
        let h = hadamard(8);
        for a in 0..8 {
            for b in 0..8 {
                let dot: f64 = (0..8).map(|c| h[a][c] * h[b][c]).sum();
                assert_eq!(dot, if a == b { 8.0 } else { 0.0 });
            }
        }
    }
}
