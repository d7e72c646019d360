//! Replayed models against the recorded ones, entry for entry, exactly: the same machine fed
//! the same numbers in the same order computes the same bits, and JSON (serde_json's
//! shortest round-trip form, read back with `float_roundtrip`) carries every bit of an f64.

use thruster_protocol::{ModelMsg, DOF_COUNT};

/// The first difference between two model lists, or `None` when they are identical in every
/// entry (effectiveness, standard errors, allocation, bounds, version, source, method,
/// actuated DOFs, pulses, time, provenance).
pub fn first_difference(replayed: &[ModelMsg], recorded: &[ModelMsg]) -> Option<String> {
    if replayed.len() != recorded.len() {
        return Some(format!(
            "{} model swap(s) replayed, {} recorded",
            replayed.len(),
            recorded.len()
        ));
    }
    replayed
        .iter()
        .zip(recorded)
        .enumerate()
        .find_map(|(i, (a, b))| model_difference(a, b).map(|d| format!("swap {}: {d}", i + 1)))
}

/// Bit for bit; a recorded NaN stands for any non-finite value (the recording's JSON writes
/// NaN and infinities alike as `null`).
fn same(replayed: f64, recorded: f64) -> bool {
    replayed.to_bits() == recorded.to_bits() || (recorded.is_nan() && !replayed.is_finite())
}

fn model_difference(a: &ModelMsg, b: &ModelMsg) -> Option<String> {
    let fields = [
        ("version", a.version, b.version),
        ("t_ns", a.t_ns, b.t_ns),
        ("count", u64::from(a.count), u64::from(b.count)),
        ("source", u64::from(a.source), u64::from(b.source)),
        ("method", u64::from(a.method), u64::from(b.method)),
        ("actuated", u64::from(a.actuated), u64::from(b.actuated)),
        ("pulses", u64::from(a.pulses), u64::from(b.pulses)),
    ];
    for (name, x, y) in fields {
        if x != y {
            return Some(format!("{name} {x} replayed, {y} recorded"));
        }
    }
    for (name, x, y) in [
        ("rel_err_rot", a.rel_err_rot, b.rel_err_rot),
        ("rel_err_acc", a.rel_err_acc, b.rel_err_acc),
    ] {
        if !same(x, y) {
            return Some(format!("{name} {x:e} replayed, {y:e} recorded"));
        }
    }
    let n = a.thruster_count();
    for d in 0..DOF_COUNT {
        for t in 0..n {
            for (name, x, y) in [
                (
                    "effectiveness",
                    a.effectiveness[d][t],
                    b.effectiveness[d][t],
                ),
                ("std_err", a.std_err[d][t], b.std_err[d][t]),
                ("allocation", a.allocation[t][d], b.allocation[t][d]),
            ] {
                if !same(x, y) {
                    return Some(format!(
                        "{name} DOF {d} thruster {t}: {x:e} replayed, {y:e} recorded"
                    ));
                }
            }
        }
    }
    (a.provenance() != b.provenance()).then(|| {
        format!(
            "provenance {:?} replayed, {:?} recorded",
            a.provenance(),
            b.provenance()
        )
    })
}

/// Entries compared per model: effectiveness, standard errors and allocation, 6 x count each.
pub fn entries(models: &[ModelMsg]) -> usize {
    models
        .iter()
        .map(|m| 3 * DOF_COUNT * m.thruster_count())
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(v: u64) -> ModelMsg {
        let mut m = ModelMsg {
            version: v,
            count: 3,
            ..ModelMsg::default()
        };
        m.effectiveness[1][2] = 0.1 + 0.2;
        m.allocation[2][1] = -3.5;
        m
    }

    #[test]
    fn identical_models_have_no_difference() {
        assert_eq!(
            first_difference(&[model(1), model(2)], &[model(1), model(2)]),
            None
        );
        assert_eq!(entries(&[model(1)]), 54);
    }

    #[test]
    fn one_bit_in_one_entry_is_a_difference() {
        let mut b = model(1);
        b.effectiveness[1][2] = f64::from_bits(b.effectiveness[1][2].to_bits() + 1);
        let d = first_difference(&[model(1)], &[b]).unwrap();
        assert!(
            d.starts_with("swap 1: effectiveness DOF 1 thruster 2"),
            "{d}"
        );
    }

    #[test]
    fn entries_beyond_the_count_do_not_matter() {
        let mut b = model(1);
        b.effectiveness[0][7] = 9.0;
        assert_eq!(first_difference(&[model(1)], &[b]), None);
    }

    #[test]
    fn a_missing_swap_is_a_difference() {
        assert!(first_difference(&[model(1)], &[])
            .unwrap()
            .contains("1 model swap(s) replayed, 0 recorded"));
    }
}
