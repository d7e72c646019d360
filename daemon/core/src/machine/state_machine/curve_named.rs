//! A thrust curve an identification under control named, remembered until the next model or
//! estimation: the detectors' mismatches that follow are the curve, not a moved thruster.
//!
//! Why: with thrusters whose thrust is not linear in the command and a daemon not told
//! (`[supply] linearize`, `power_law_exponent`), the open-loop model is right at the pulses'
//! amplitude only. Under control the refinement then calls a change every 7-8 s, the
//! identification names the curve and is refused (`identification.max_curve_evidence`),
//! and the next window calls the change again: eight_vectored_lag80ms_curve identified
//! every 27 s, each refused, its dither never ending (docs/study.md, "A curve named is not a
//! moved thruster"). Re-identifying cannot help until the curve is configured.

/// The curve named, and what the detectors said since.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub(super) struct CurveNamed {
    /// The bent commands' exponent that explained the data best (thrust ~ command^p).
    pub exponent: f64,
    /// Its ln likelihood ratio over the linear fit.
    pub log_likelihood_ratio: f64,
    /// Vehicle time it was named, s.
    pub at_s: f64,
    /// Mismatches the detectors called since, not re-identified.
    pub mismatches: u32,
}

impl CurveNamed {
    pub fn new(exponent: f64, log_likelihood_ratio: f64, at_s: f64) -> Self {
        CurveNamed {
            exponent,
            log_likelihood_ratio,
            at_s,
            mismatches: 0,
        }
    }

    /// A detector's mismatch `why`, counted, and what is said of it.
    pub fn mismatch(&mut self, why: &str) -> Said {
        self.mismatches += 1;
        // The status holds 128 bytes: what the daemon does and why come first, the
        // detector's own words after.
        let status = format!(
            "holding attitude; mismatch {} since the thrust curve (~command^{:.2}) was named, not re-identified: configure the curve; {why}",
            self.mismatches, self.exponent
        );
        let journal = (self.mismatches == 1).then(|| {
            format!(
                "{why}: not re-identified: the thrust curve named at {:.1} s (thrust ~ command^{:.2}, ln likelihood ratio {:.0}) explains it; configure the thrusters' curve ([supply] linearize for T200s, power_law_exponent for another make); later mismatches are counted in the status",
                self.at_s, self.exponent, self.log_likelihood_ratio
            )
        });
        Said { status, journal }
    }
}

/// What a mismatch after the curve was named says.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Said {
    /// The status text.
    pub status: String,
    /// The journal's event, for the first mismatch only.
    pub journal: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::CurveNamed;

    #[test]
    fn the_first_mismatch_goes_to_the_journal_and_the_status_counts_them_all() {
        let mut c = CurveNamed::new(1.5, 7992.0, 28.1);
        let first = c.mismatch("model mismatch on thruster 5");
        let second = c.mismatch("model mismatch on thruster 7");
        assert_eq!(c.mismatches, 2);
        let journal = first.journal.expect("the first is journalled");
        assert!(
            journal.starts_with("model mismatch on thruster 5: not re-identified")
                && journal
                    .contains("named at 28.1 s (thrust ~ command^1.50, ln likelihood ratio 7992)"),
            "{journal}"
        );
        assert_eq!(second.journal, None);
        // The protocol's status keeps 128 bytes: the count, the curve and the advice fit.
        let head: String = second.status.chars().take(128).collect();
        assert!(
            head.contains("mismatch 2 since the thrust curve (~command^1.50)")
                && head.contains("configure the curve"),
            "{head}"
        );
    }
}
