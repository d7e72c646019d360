//! The experiment's figure (SVG): per run the attitude against the setpoint, the thrust, and
//! the estimation periods shaded.

use super::*;

/// Like the paper's Fig. 6: per run, roll, pitch and yaw against the setpoint over time, the
/// error and the thrust commands; estimation periods shaded. The runs of one figure share
/// each panel's y range, so their rows compare at a glance.
pub(super) fn figure(name: Name, outs: &[RunOutput]) -> String {
    // At most ~600 points per line keeps the SVG small.
    let thin = |rows: &[Row]| -> Vec<Row> {
        let k = (rows.len() / 600).max(1);
        rows.iter().step_by(k).copied().collect()
    };
    let x_max = outs
        .iter()
        .filter_map(|o| o.rows.last().map(|r| r.t - o.hold_start))
        .fold(1.0, f64::max)
        .ceil();
    // Shared ranges: every run's attitude (setpoint and truth) per axis, every run's error.
    let all = || outs.iter().flat_map(|o| o.rows.iter());
    let axis_range: Vec<(f64, f64)> = (0..3)
        .map(|i| {
            let (lo, hi) = all()
                .flat_map(|r| [r.sp[i], r.tru[i]])
                .filter(|v| v.is_finite())
                .fold((-5.0, 5.0), |(lo, hi), v| {
                    (f64::min(lo, v), f64::max(hi, v))
                });
            nice_range(lo, hi)
        })
        .collect();
    let err_range = nice_range(
        0.0,
        all()
            .map(|r| r.err)
            .filter(|v| v.is_finite())
            .fold(5.0, f64::max),
    );
    let mut panels = Vec::new();
    for o in outs {
        let rows = thin(&o.rows);
        let x = |r: &Row| r.t - o.hold_start;
        let change = o.spec.change.map(|c| c.0 - o.hold_start);
        let shade = estimating_intervals(&o.rows, o.hold_start);
        for (i, axis) in ["roll", "pitch", "yaw"].iter().enumerate() {
            let range = axis_range[i];
            let mut series = vec![
                Series {
                    label: "setpoint".into(),
                    color: "black",
                    dashed: true,
                    points: rows.iter().map(|r| (x(r), r.sp[i])).collect(),
                    band: None,
                },
                Series {
                    label: "true attitude".into(),
                    color: "#2a2",
                    dashed: false,
                    points: rows.iter().map(|r| (x(r), r.tru[i])).collect(),
                    band: None,
                },
            ];
            if let Some(c) = change {
                series.push(vline(c, range));
            }
            panels.push(Panel {
                title: format!("{}: {axis}, deg", o.spec.label),
                series,
                y_range: Some(range),
                shade: shade.clone(),
            });
        }
        let mut series = vec![
            Series {
                label: "angular error".into(),
                color: "#22c",
                dashed: false,
                points: rows.iter().map(|r| (x(r), r.err)).collect(),
                band: None,
            },
            Series {
                label: "|yaw error|".into(),
                color: "#c62",
                dashed: false,
                points: rows.iter().map(|r| (x(r), r.yaw_err.abs())).collect(),
                band: None,
            },
        ];
        if let Some(c) = change {
            series.push(vline(c, err_range));
        }
        panels.push(Panel {
            title: format!("{}: error, deg (blue total, orange |yaw|)", o.spec.label),
            series,
            y_range: Some(err_range),
            shade: shade.clone(),
        });
        panels.push(Panel {
            title: format!("{}: thrust commands, -1..1", o.spec.label),
            series: thrust_series(&rows, o.hold_start),
            y_range: Some((-1.0, 1.0)),
            shade,
        });
    }
    let title = match name {
        Name::ManualVsLearned => "AMOUR-5, yaw / pitch / roll steps: learned, manual and the simulator's true model (rows, top to bottom)",
        Name::Misaligned => "Top thruster rotated 45 deg, pitch steps: manual, re-learned and the simulator's true model (rows, top to bottom)",
        Name::Aligned => "All thrusters aligned, yaw and pitch steps: the paper's estimator, ours and the simulator's true model (rows, top to bottom)",
        Name::HotSwap => "Top thruster rotated 45 deg mid-run (red line): announced, announced holding level, silent (realistic IMU), silent (paper noise), true model (rows, top to bottom)",
        Name::Degrade => "Thruster L loses 30 % over a minute from the red line, realistic IMU: refined model, fixed model, true model (rows, top to bottom)",
        Name::Dive => "A 30-minute dive from a full to a nearly empty battery, T200 thrusters, realistic IMU: commands referred to 16 V (top) and as computed (bottom)",
    };
    let title = if shading_drawn(&panels, x_max) {
        format!("{title}; grey: estimating")
    } else {
        title.to_string()
    };
    render(
        &Grid {
            title,
            columns: 5,
            x_label: "vehicle time since the hold began, s".into(),
            y_label: "deg".into(),
            x_max,
            y_max: 1.0,
        },
        &panels,
    )
}

/// Whether any panel shades an interval inside the plotted 0..x_max: only then does the title
/// promise grey bands (issue 27: manual-vs-learned estimates before its hold, at x < 0).
pub(super) fn shading_drawn(panels: &[Panel], x_max: f64) -> bool {
    panels
        .iter()
        .flat_map(|p| &p.shade)
        .any(|&(a, b)| b > 0.0 && a < x_max && b > a)
}

/// The vehicle-time intervals (since the hold began) in which the daemon estimated: open-loop
/// pulses and settles, or identification under control.
pub(super) fn estimating_intervals(rows: &[Row], hold_start: f64) -> Vec<(f64, f64)> {
    let estimating = |s: DaemonState| {
        matches!(
            s,
            DaemonState::MeasureNoise
                | DaemonState::Pulse
                | DaemonState::Settle
                | DaemonState::Solve
                | DaemonState::Identify
        )
    };
    let mut out: Vec<(f64, f64)> = Vec::new();
    let mut open: Option<f64> = None;
    for r in rows {
        let t = r.t - hold_start;
        match (open, estimating(r.state)) {
            (None, true) => open = Some(t),
            (Some(a), false) => {
                out.push((a, t));
                open = None;
            }
            _ => {}
        }
    }
    if let (Some(a), Some(last)) = (open, rows.last()) {
        out.push((a, last.t - hold_start));
    }
    out
}

/// One line per thruster, in a repeating palette.
pub(super) fn thrust_series(rows: &[Row], hold_start: f64) -> Vec<Series> {
    const COLORS: [&str; 8] = [
        "#1b6ca8", "#d1495b", "#2e8b57", "#e69f00", "#8e44ad", "#555", "#17becf", "#bcbd22",
    ];
    let n = rows.iter().map(|r| r.nu).max().unwrap_or(0);
    (0..n)
        .map(|k| Series {
            label: format!("thruster {k}"),
            color: COLORS[k % COLORS.len()],
            dashed: false,
            points: rows.iter().map(|r| (r.t - hold_start, r.u[k])).collect(),
            band: None,
        })
        .collect()
}

pub(super) fn vline(x: f64, range: (f64, f64)) -> Series {
    Series {
        label: "thruster rotated".into(),
        color: "#d22",
        dashed: true,
        points: vec![(x, range.0), (x, range.1)],
        band: None,
    }
}
