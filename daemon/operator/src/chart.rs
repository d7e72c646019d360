//! Terminal bar chart of each thruster's contribution to each DOF, like the paper's
//! Fig. 5b: one block per DOF, one horizontal bar per thruster.
//!
//! Bars diverge from a centre line (negative to the left, positive to the right) so the
//! sign is visible at a glance, and each DOF is scaled to its own largest |entry|: rotation
//! and translation rows have different units and magnitudes, and the question the chart
//! answers is "which thrusters do the work in this DOF", not "which DOF is strongest".

use std::fmt::Write;

use thruster_protocol::{Dof, ModelMsg};

use crate::json::dof_key;
use crate::number::num;

/// Block order of the paper's Fig. 5b.
pub const CHART_ORDER: [Dof; 6] = [
    Dof::Yaw,
    Dof::Pitch,
    Dof::Roll,
    Dof::Heave,
    Dof::Sway,
    Dof::Surge,
];

/// Cells on each side of the centre line.
pub const HALF_WIDTH: usize = 20;

const BAR: char = '█';
const AXIS: char = '│';

/// The whole chart for the model's `count` thrusters.
pub fn contribution_chart(m: &ModelMsg, half_width: usize) -> String {
    let n = m.thruster_count();
    let mut out = String::new();
    for dof in CHART_ORDER {
        let row = &m.effectiveness[dof.index()][..n];
        let max = row
            .iter()
            .filter(|v| v.is_finite())
            .fold(0.0_f64, |acc, v| acc.max(v.abs()));
        let unit = if dof.is_rotation() {
            "rad/s^2"
        } else {
            "m/s^2"
        };
        let _ = write!(out, "{} [{unit} per unit command]", dof_key(dof));
        if max > 0.0 {
            let _ = write!(
                out,
                "  largest |entry| {}",
                num(max).trim_start_matches('+')
            );
        }
        if !m.is_actuated(dof) {
            let _ = write!(out, "  NOT ACTUATED (never commanded)");
        }
        out.push('\n');
        if max == 0.0 {
            let _ = writeln!(out, "  (no thruster acts on {})", dof_key(dof));
            continue;
        }
        for (i, &v) in row.iter().enumerate() {
            let line = format!(
                "  {:<4}{:>10}  {}",
                format!("T{i}"),
                num(v),
                bar(v, max, half_width)
            );
            let _ = writeln!(out, "{}", line.trim_end());
        }
    }
    out
}

/// `half_width` cells left of the axis and `half_width` right; |v| = max fills a side.
pub fn bar(v: f64, max: f64, half_width: usize) -> String {
    let cells = if v.is_finite() && max > 0.0 {
        ((v.abs() / max) * half_width as f64)
            .round()
            .min(half_width as f64) as usize
    } else {
        0
    };
    let filled: String = std::iter::repeat_n(BAR, cells).collect();
    if v < 0.0 {
        format!("{filled:>half_width$}{AXIS}")
    } else {
        format!("{:half_width$}{AXIS}{filled}", "")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> ModelMsg {
        // Three thrusters: a yaw pair and a heave thruster; sway not actuated.
        let mut m = ModelMsg {
            count: 3,
            actuated: Dof::Yaw.mask() | Dof::Heave.mask() | Dof::Surge.mask(),
            ..ModelMsg::default()
        };
        m.effectiveness[Dof::Yaw.index()][..3].copy_from_slice(&[2.0, -1.0, 0.0]);
        m.effectiveness[Dof::Heave.index()][..3].copy_from_slice(&[0.0, 0.0, -0.5]);
        m.effectiveness[Dof::Surge.index()][..3].copy_from_slice(&[0.4, 0.4, 0.0]);
        m.effectiveness[Dof::Sway.index()][..3].copy_from_slice(&[0.0, 0.0, 0.05]);
        m
    }

    #[test]
    fn bars_scale_per_dof_and_show_sign() {
        assert_eq!(bar(2.0, 2.0, 4), "    │████");
        assert_eq!(bar(-1.0, 2.0, 4), "  ██│");
        assert_eq!(bar(0.0, 2.0, 4), "    │");
        assert_eq!(bar(f64::NAN, 2.0, 4), "    │");
        assert_eq!(bar(0.3, 2.0, 4), "    │█"); // 0.6 cell rounds up
    }

    #[test]
    fn chart_of_a_known_model() {
        let chart = contribution_chart(&model(), 4);
        let expected = "\
yaw [rad/s^2 per unit command]  largest |entry| 2.000
  T0      +2.000      │████
  T1      -1.000    ██│
  T2      +0.000      │
pitch [rad/s^2 per unit command]  NOT ACTUATED (never commanded)
  (no thruster acts on pitch)
roll [rad/s^2 per unit command]  NOT ACTUATED (never commanded)
  (no thruster acts on roll)
heave [m/s^2 per unit command]  largest |entry| 0.500
  T0      +0.000      │
  T1      +0.000      │
  T2      -0.500  ████│
sway [m/s^2 per unit command]  largest |entry| 0.050  NOT ACTUATED (never commanded)
  T0      +0.000      │
  T1      +0.000      │
  T2      +0.050      │████
surge [m/s^2 per unit command]  largest |entry| 0.400
  T0      +0.400      │████
  T1      +0.400      │████
  T2      +0.000      │
";
        assert_eq!(chart, expected);
    }

    #[test]
    fn ignores_columns_beyond_count() {
        let mut m = model();
        m.effectiveness[Dof::Yaw.index()][7] = 100.0;
        let chart = contribution_chart(&m, 4);
        assert!(chart.contains("largest |entry| 2.000"));
        assert!(!chart.contains("T3"));
    }
}
