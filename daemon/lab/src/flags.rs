//! Numbers on the lab's command line, checked where they are given (clap's exit 2, the flag
//! named): a NaN or a negative one is refused rather than quietly leaving part of a run out.

/// A number in `0..=max` (`unit` for the message).
pub(crate) fn within(s: &str, max: f64, unit: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("expected a number of {unit}, got {s:?}"))?;
    if (0.0..=max).contains(&v) {
        Ok(v)
    } else {
        Err(format!("must be within 0..={max} {unit}, got {v}"))
    }
}
