//! The protocol's checks on what thrusterd publishes, for display.
//!
//! A process that acts on a message drops it when it fails validation. thrusterctl only
//! shows it, so it shows the message as it is (NaN as "unknown", `null` in JSON) and warns,
//! rather than hiding everything else in it. NaN in the fields below is not a problem at
//! all: thrusterd publishes NaN for "not known yet" (no noise measured, no estimate yet),
//! and for a standard error of the model it means "unknown"; an infinite error bound means
//! "no bound yet" early in an estimation.

use thruster_protocol::{ModelMsg, StatusMsg, Validate};

/// Why `s` fails the protocol's checks, NaN-as-unknown fields aside.
pub fn status_problem(s: &StatusMsg) -> Option<String> {
    let mut known = *s;
    // +inf error bound: estimation running, too few pulses for a bound yet.
    if known.error_bound == f64::INFINITY {
        known.error_bound = 0.0;
    }
    for v in [
        &mut known.error_bound,
        &mut known.power,
        &mut known.sigma_rot,
        &mut known.sigma_acc,
        &mut known.imu_rate_hz,
    ] {
        if v.is_nan() {
            *v = 0.0;
        }
    }
    known
        .validate()
        .err()
        .map(|r| format!("thrusterd published an invalid status: {r}"))
}

/// Why `m` fails the protocol's checks, unknown (NaN) standard errors aside.
pub fn model_problem(m: &ModelMsg) -> Option<String> {
    let mut known = *m;
    for v in known.std_err.iter_mut().flatten() {
        if v.is_nan() {
            *v = 0.0;
        }
    }
    for v in [&mut known.rel_err_rot, &mut known.rel_err_acc] {
        if v.is_nan() {
            *v = 0.0;
        }
    }
    known
        .validate()
        .err()
        .map(|r| format!("thrusterd published an invalid model: {r}"))
}

/// Prints each distinct warning once: a bad field repeats in every status at 10 Hz.
#[derive(Debug, Default)]
pub struct Warner {
    last: Option<String>,
}

impl Warner {
    /// The warning to print now, if any.
    pub fn check(&mut self, problem: Option<String>) -> Option<String> {
        match problem {
            Some(p) if self.last.as_ref() != Some(&p) => {
                self.last = Some(p.clone());
                Some(p)
            }
            _ => None,
        }
    }

    pub fn warn(&mut self, problem: Option<String>) {
        if let Some(p) = self.check(problem) {
            eprintln!("warning: {p}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::DaemonState;

    #[test]
    fn nan_means_unknown_in_status() {
        let mut s = StatusMsg {
            error_bound: f64::NAN,
            sigma_rot: f64::NAN,
            sigma_acc: f64::NAN,
            ..StatusMsg::default()
        };
        s.set_state(DaemonState::Idle);
        assert_eq!(status_problem(&s), None);
        s.error_bound = f64::INFINITY;
        assert_eq!(status_problem(&s), None);
        s.error_bound = -1.0;
        assert!(status_problem(&s).unwrap().contains("error_bound"));
        s.error_bound = 0.0;
        s.state = 42;
        assert!(status_problem(&s).unwrap().contains("invalid status"));
        s.set_state(DaemonState::Idle);
        s.sigma_rot = f64::INFINITY;
        assert!(status_problem(&s).is_some());
    }

    #[test]
    fn nan_std_err_is_unknown_but_nan_effectiveness_is_a_problem() {
        let mut m = ModelMsg {
            count: 1,
            ..ModelMsg::default()
        };
        m.std_err[0][0] = f64::NAN;
        assert_eq!(model_problem(&m), None);
        m.effectiveness[0][0] = f64::NAN;
        assert!(model_problem(&m).unwrap().contains("invalid model"));
    }

    #[test]
    fn warner_repeats_nothing() {
        let mut w = Warner::default();
        assert_eq!(w.check(Some("a".into())), Some("a".into()));
        assert_eq!(w.check(Some("a".into())), None);
        assert_eq!(w.check(None), None);
        assert_eq!(w.check(Some("b".into())), Some("b".into()));
    }
}
