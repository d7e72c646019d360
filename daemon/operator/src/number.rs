//! Numbers for the operator's tables and charts (render and chart share them).

/// A signed number for tables: fixed 3 decimals, scientific when it would not fit.
pub fn num(v: f64) -> String {
    num_with(v, 3)
}

/// As [`num`] with `decimals`. Allocation entries are small (commands per rad/s^2), so
/// they get one decimal more than effectiveness entries.
pub fn num_with(v: f64, decimals: usize) -> String {
    if v.is_finite() && v.abs() < 1e4 {
        format!("{v:+.decimals$}")
    } else {
        format!("{v:+.2e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers() {
        assert_eq!(num(1.23456), "+1.235");
        assert_eq!(num(-0.5), "-0.500");
        assert_eq!(num(123456.0), "+1.23e5");
        assert_eq!(num(f64::NAN), "NaN");
    }
}
