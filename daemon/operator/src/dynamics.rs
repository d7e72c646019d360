//! The dynamic coefficients a model came with (`DynamicsMsg`), as the operator reads them:
//! a short text of what people look for first (each rotation's own damping and the righting
//! moment) and a JSON object with every coefficient and its standard error.

use std::fmt::Write as _;

use serde_json::{json, Map, Value};
use thruster_protocol::{Dof, DynamicsMsg, DYNAMIC_TERM_NAMES};

/// Index of `down_x` / `down_y` in [`DYNAMIC_TERM_NAMES`] (roll is righted by gravity's y
/// component in the body frame, pitch by its x component).
const DOWN_X: usize = 12;
const DOWN_Y: usize = 13;

/// A finite number, or null (JSON has no NaN).
fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// Every coefficient: per DOF row, term -> [value, standard error]; and the excursion.
pub fn json(d: &DynamicsMsg) -> Value {
    let rows: Map<String, Value> = Dof::ALL
        .iter()
        .enumerate()
        .map(|(r, dof)| {
            let (c, se) = (d.coefficients[r].to_terms(), d.std_err[r].to_terms());
            let row: Map<String, Value> = DYNAMIC_TERM_NAMES
                .iter()
                .enumerate()
                .map(|(k, name)| (name.to_string(), json!([num(c[k]), num(se[k])])))
                .collect();
            (dof.name().to_lowercase(), Value::Object(row))
        })
        .collect();
    json!({
        "model_version": d.model_version,
        "per_row_term_value_and_std_err": rows,
        "navigation_max_tilt_deg": num(d.max_tilt_rad.to_degrees()),
        "navigation_max_heading_change_deg": num(d.max_heading_change_rad.to_degrees()),
        "spin_up_s": num(d.spin_up_s),
        "spin_up_learned": d.spin_up_learned == 1,
        "imu_position_m": d.imu_position_m.map(num),
        "imu_position_contradicted": d.imu_position_contradicted == 1,
        "imu_learned_m": d.imu_learned_m.map(num),
        "imu_learned_sd_m": d.imu_learned_sd_m.map(num),
        "spin_up_sd_ln": num(d.spin_up_sd_ln),
        "spin_up_per_thruster_s": per_thruster_lags(d),
        "thruster_lag_evidence": num(d.thruster_lag_evidence),
        "spin_up_checked": d.spin_up_checked == 1,
        "spin_up_consistent_s": (d.spin_up_checked == 1).then(|| d.spin_up_consistent_s.map(num)),
    })
}

/// Each thruster's own lag, where the data said they differ (None: one lag for all).
pub fn per_thruster_lags(d: &DynamicsMsg) -> Option<Vec<f64>> {
    let n = d
        .spin_up_per_thruster_s
        .iter()
        .rposition(|s| s.is_finite())?
        + 1;
    Some(d.spin_up_per_thruster_s[..n].to_vec())
}

/// What the report says beside the coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReportOptions {
    /// The model's actuated-DOF bit mask (bit = `Dof` index): a row whose axis no thruster
    /// moves was not identified (nothing excited it), so its numbers are not printed.
    pub actuated: u64,
    /// Print the excursion the daemon's navigation estimated while learning. Off where the
    /// caller prints the simulator's true one: one figure for one estimation (issue 27).
    pub navigation_excursion: bool,
}

/// The rotation rows' own-axis damping and the roll/pitch restoring, one line each.
pub fn report(d: &DynamicsMsg, options: ReportOptions) -> String {
    let mut s = String::from("learned dynamics (per unit of the term, 1-sigma):\n");
    for (r, rate) in ["p", "q", "r"].iter().enumerate() {
        if options.actuated & (1 << r) == 0 {
            // Issue 27: aligned printed `|p|p -55.881 +- 24.544` for a roll no thruster moves.
            let _ = writeln!(
                s,
                "  {:>5}: axis not actuated: not identified",
                Dof::ALL[r].name().to_lowercase()
            );
            continue;
        }
        let c = d.coefficients[r].to_terms();
        let se = d.std_err[r].to_terms();
        let (k, kq) = (r, 3 + r);
        let _ = write!(
            s,
            "  {:>5}: damping {rate} {:+.3} +- {:.3}, |{rate}|{rate} {:+.3} +- {:.3}",
            Dof::ALL[r].name().to_lowercase(),
            c[k],
            se[k],
            c[kq],
            se[kq]
        );
        if r < 2 {
            let g = if r == 0 { DOWN_Y } else { DOWN_X };
            let _ = write!(
                s,
                ", restoring {} {:+.2} +- {:.2}",
                DYNAMIC_TERM_NAMES[g], c[g], se[g]
            );
        }
        s.push('\n');
    }
    if options.navigation_excursion {
        let _ = writeln!(
            s,
            "  while it was learned the vehicle tilted up to {:.1} deg and turned up to {:.1} deg (navigation estimate)",
            d.max_tilt_rad.to_degrees(),
            d.max_heading_change_rad.to_degrees()
        );
    }
    if d.imu_position_m.iter().all(|v| v.is_finite()) {
        let [x, y, z] = d.imu_position_m;
        let how = if d.imu_position_contradicted == 1 {
            "learned: the data contradicted the configured estimator.imu_position_m"
        } else {
            "configured"
        };
        let _ = write!(
            s,
            "  translation rows referred from the IMU at ({x:.3}, {y:.3}, {z:.3}) m ({how})"
        );
        if d.imu_learned_m.iter().all(|v| v.is_finite()) {
            let [lx, ly, lz] = d.imu_learned_m;
            let [sx, sy, sz] = d.imu_learned_sd_m;
            let _ = write!(
                s,
                "; the data puts it at ({lx:.3}, {ly:.3}, {lz:.3}) +- ({sx:.3}, {sy:.3}, {sz:.3}) m from the centre of mass"
            );
        }
        s.push('\n');
    }
    if d.spin_up_s.is_finite() {
        let how = if d.spin_up_learned == 1 {
            "learned from the pulses"
        } else {
            "configured, not learned"
        };
        let _ = write!(
            s,
            "  thruster spin-up time constant {:.3} s ({how}",
            d.spin_up_s
        );
        if d.spin_up_learned == 1 && d.spin_up_sd_ln.is_finite() {
            let _ = write!(s, ", +- {:.1} %", 100.0 * d.spin_up_sd_ln);
        }
        s.push_str(")\n");
        if let Some(lags) = per_thruster_lags(d) {
            let each: Vec<String> = lags.iter().map(|l| format!("{l:.3}")).collect();
            let _ = writeln!(
                s,
                "    per thruster, the data saying they differ (ln LR {:.0}): {} s",
                d.thruster_lag_evidence,
                each.join(", ")
            );
        }
        if d.spin_up_checked == 1 {
            let [lo, hi] = d.spin_up_consistent_s;
            let end = |v: f64| {
                if v.is_finite() {
                    format!("{v:.3}")
                } else {
                    "unbounded".to_string()
                }
            };
            let _ = writeln!(
                s,
                "    checked against the data (too noisy to learn it): consistent with {}-{} s",
                end(lo),
                end(hi)
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::DynamicsRow;

    #[test]
    fn the_righting_terms_are_named_where_they_are() {
        assert_eq!(DYNAMIC_TERM_NAMES[DOWN_X], "down_x");
        assert_eq!(DYNAMIC_TERM_NAMES[DOWN_Y], "down_y");
    }

    #[test]
    fn report_and_json_carry_the_values() {
        let mut d = DynamicsMsg {
            model_version: 3,
            max_tilt_rad: 0.4,
            spin_up_s: 0.052,
            spin_up_learned: 1,
            imu_position_contradicted: 1,
            imu_position_m: [0.149, 0.05, -0.113],
            imu_learned_m: [0.149, 0.05, -0.113],
            imu_learned_sd_m: [0.001, 0.0005, 0.0005],
            ..DynamicsMsg::default()
        };
        let mut terms = [0.0; thruster_protocol::DYNAMIC_TERMS];
        terms[DOWN_Y] = -8.06;
        d.coefficients[0] = DynamicsRow::from_terms(&terms);
        d.std_err[2].rate[2] = f64::NAN;
        let all = ReportOptions {
            actuated: 0b11_1111,
            navigation_excursion: true,
        };
        let text = report(&d, all);
        assert!(text.contains("restoring down_y -8.06"), "{text}");
        assert!(text.contains("tilted up to 22.9 deg"), "{text}");
        // Issue 27: roll not actuated (aligned), and the truth's tilt printed by the caller.
        let text = report(
            &d,
            ReportOptions {
                actuated: 0b11_1110,
                navigation_excursion: false,
            },
        );
        assert!(
            text.contains("   roll: axis not actuated: not identified\n"),
            "{text}"
        );
        assert!(!text.contains("down_y"), "{text}");
        assert!(text.contains("pitch: damping q"), "{text}");
        assert!(!text.contains("tilted"), "{text}");
        let text = report(&d, all);
        assert!(
            text.contains("spin-up time constant 0.052 s (learned from the pulses)"),
            "{text}"
        );
        assert!(!text.contains("per thruster"), "{text}");
        assert!(!text.contains("checked against"), "{text}");
        let v = json(&d);
        assert!(v["spin_up_per_thruster_s"].is_null(), "{v}");
        assert!(v["spin_up_consistent_s"].is_null(), "{v}");
        assert_eq!(
            v["per_row_term_value_and_std_err"]["roll"]["down_y"][0],
            -8.06
        );
        assert!(v["per_row_term_value_and_std_err"]["yaw"]["r"][1].is_null());
        assert_eq!(v["model_version"], 3);
        assert_eq!(v["spin_up_s"], 0.052);
        assert_eq!(v["spin_up_learned"], true);
        assert!(
            text.contains("IMU at (0.149, 0.050, -0.113) m (learned: the data contradicted"),
            "{text}"
        );
        assert_eq!(v["imu_position_m"][2], -0.113);
        assert_eq!(v["imu_position_contradicted"], true);
    }
}
