//! A tiny SVG line-chart writer: panels in a grid, lines with optional +-1 sigma bands,
//! shaded x intervals (an estimation period) and round tick values. Nothing is clipped
//! silently: a panel whose points leave its y range says so in red, with the extreme value.
//!
//! Hand-written rather than a plotting crate because the charts are simple and a font-free SVG
//! renders anywhere (browsers, GitHub) without system font libraries on the build machine.

use std::fmt::Write;

/// One curve: points, and optionally a shaded band (x, low, high) around it.
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    pub color: &'static str,
    pub dashed: bool,
    pub points: Vec<(f64, f64)>,
    pub band: Option<Vec<(f64, f64, f64)>>,
}

/// One chart in the grid.
#[derive(Debug, Clone, Default)]
pub struct Panel {
    pub title: String,
    pub series: Vec<Series>,
    /// This panel's y axis (low, high) instead of the grid's 0..y_max: signed quantities
    /// (attitude angles) and panels of different scales in one figure.
    pub y_range: Option<(f64, f64)>,
    /// x intervals shaded grey behind the lines (e.g. while the daemon estimated).
    pub shade: Vec<(f64, f64)>,
}

/// Round tick values covering [lo, hi]: steps of 1, 2 or 5 times a power of ten, about
/// `want` of them, starting and ending on a multiple of the step at or beyond the ends.
pub fn nice_ticks(lo: f64, hi: f64, want: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / want.max(1) as f64;
    let power = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * power)
        .find(|s| *s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * power);
    let first = (lo / step + 1e-9).floor() as i64;
    let last = (hi / step - 1e-9).ceil() as i64;
    // Multiples of the step, computed from integers so 0.1 * 3 prints as 0.3.
    (first..=last).map(|k| k as f64 * step).collect()
}

/// [lo, hi] widened to the round ticks that cover it: the axis [`render`] draws for it.
pub fn nice_range(lo: f64, hi: f64) -> (f64, f64) {
    let t = nice_ticks(lo, hi, 5);
    (t[0], t[t.len() - 1])
}

/// Layout and axes shared by every panel.
#[derive(Debug, Clone)]
pub struct Grid {
    pub title: String,
    pub columns: usize,
    pub x_label: String,
    pub y_label: String,
    pub x_max: f64,
    pub y_max: f64,
}

const PANEL_W: f64 = 300.0;
const PANEL_H: f64 = 190.0;
const MARGIN_L: f64 = 46.0;
const MARGIN_B: f64 = 34.0;
const MARGIN_T: f64 = 24.0;
const GAP: f64 = 14.0;

/// Render panels into an SVG document.
pub fn render(grid: &Grid, panels: &[Panel]) -> String {
    let cols = grid.columns.max(1);
    let rows = panels.len().div_ceil(cols);
    let cell_w = MARGIN_L + PANEL_W + GAP;
    let cell_h = MARGIN_T + PANEL_H + MARGIN_B;
    let width = cols as f64 * cell_w + GAP;
    // Every line's label once, from every panel (issue 27: the thrust panels' lines were
    // in no legend, which took the first panel's only), wrapped to the figure's width.
    let mut entries: Vec<&Series> = Vec::new();
    for ser in panels.iter().flat_map(|p| &p.series) {
        if !entries
            .iter()
            .any(|e| e.label == ser.label && e.color == ser.color)
        {
            entries.push(ser);
        }
    }
    let entry_w = |ser: &Series| 34.0 + 6.5 * ser.label.len() as f64;
    let mut legend_rows = 1;
    let mut x = GAP + MARGIN_L;
    let mut placed = Vec::with_capacity(entries.len());
    for ser in &entries {
        if x + entry_w(ser) > width && x > GAP + MARGIN_L {
            legend_rows += 1;
            x = GAP + MARGIN_L;
        }
        placed.push((x, legend_rows - 1));
        x += entry_w(ser);
    }
    let legend_h = 12.0 + 16.0 * legend_rows as f64;
    let height = 40.0 + rows as f64 * cell_h + legend_h;
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">"#
    );
    let _ = write!(
        s,
        r#"<rect width="100%" height="100%" fill="white"/><text x="{}" y="22" font-size="15" text-anchor="middle">{}</text>"#,
        width / 2.0,
        esc(&grid.title)
    );
    for (i, panel) in panels.iter().enumerate() {
        let x0 = GAP + (i % cols) as f64 * cell_w + MARGIN_L;
        let y0 = 40.0 + (i / cols) as f64 * cell_h + MARGIN_T;
        draw_panel(&mut s, grid, panel, x0, y0);
    }
    for (ser, (x, row)) in entries.iter().zip(placed) {
        let y = height - legend_h + 16.0 + 16.0 * row as f64;
        let dash = if ser.dashed {
            r#" stroke-dasharray="5,3""#
        } else {
            ""
        };
        let _ = write!(
            s,
            r#"<line x1="{x}" y1="{y}" x2="{}" y2="{y}" stroke="{}" stroke-width="2"{dash}/><text x="{}" y="{}">{}</text>"#,
            x + 22.0,
            ser.color,
            x + 26.0,
            y + 4.0,
            esc(&ser.label)
        );
    }
    s.push_str("</svg>\n");
    s
}

fn draw_panel(s: &mut String, grid: &Grid, panel: &Panel, x0: f64, y0: f64) {
    let (y_lo, y_hi) = panel.y_range.unwrap_or((0.0, grid.y_max));
    let sx = |x: f64| x0 + (x / grid.x_max).clamp(0.0, 1.0) * PANEL_W;
    let sy = |y: f64| y0 + PANEL_H - ((y - y_lo) / (y_hi - y_lo)).clamp(0.0, 1.0) * PANEL_H;
    let _ = write!(
        s,
        r##"<rect x="{x0}" y="{y0}" width="{PANEL_W}" height="{PANEL_H}" fill="none" stroke="#888"/><text x="{}" y="{}" text-anchor="middle" font-size="12">{}</text>"##,
        x0 + PANEL_W / 2.0,
        y0 - 7.0,
        esc(&panel.title)
    );
    for (a, b) in &panel.shade {
        let (xa, xb) = (sx(a.min(*b)), sx(a.max(*b)));
        if xb > xa {
            let _ = write!(
                s,
                r##"<rect x="{xa:.1}" y="{y0}" width="{:.1}" height="{PANEL_H}" fill="#bbb" fill-opacity="0.35" stroke="none"/>"##,
                xb - xa
            );
        }
    }
    for yv in nice_ticks(y_lo, y_hi, 5)
        .into_iter()
        .filter(|v| *v >= y_lo - 1e-9 && *v <= y_hi + 1e-9)
    {
        let y = sy(yv);
        let _ = write!(
            s,
            r##"<line x1="{x0}" y1="{y}" x2="{}" y2="{y}" stroke="#eee"/><text x="{}" y="{}" text-anchor="end">{}</text>"##,
            x0 + PANEL_W,
            x0 - 4.0,
            y + 4.0,
            trim(yv)
        );
    }
    for xv in nice_ticks(0.0, grid.x_max, 5)
        .into_iter()
        .filter(|v| *v <= grid.x_max + 1e-9)
    {
        let x = sx(xv);
        let _ = write!(
            s,
            r#"<text x="{x}" y="{}" text-anchor="middle">{}</text>"#,
            y0 + PANEL_H + 14.0,
            trim(xv)
        );
    }
    let _ = write!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text><text x="{}" y="{}" text-anchor="middle" transform="rotate(-90 {} {})">{}</text>"#,
        x0 + PANEL_W / 2.0,
        y0 + PANEL_H + 28.0,
        esc(&grid.x_label),
        x0 - 34.0,
        y0 + PANEL_H / 2.0,
        x0 - 34.0,
        y0 + PANEL_H / 2.0,
        esc(&grid.y_label)
    );
    for ser in &panel.series {
        if let Some(band) = &ser.band {
            let finite: Vec<_> = band
                .iter()
                .filter(|b| b.1.is_finite() && b.2.is_finite())
                .collect();
            if finite.len() > 1 {
                let mut d = String::new();
                for (k, b) in finite.iter().enumerate() {
                    let _ = write!(
                        d,
                        "{}{:.1},{:.1} ",
                        if k == 0 { "M" } else { "L" },
                        sx(b.0),
                        sy(b.2)
                    );
                }
                for b in finite.iter().rev() {
                    let _ = write!(d, "L{:.1},{:.1} ", sx(b.0), sy(b.1));
                }
                let _ = write!(
                    s,
                    r#"<path d="{d}Z" fill="{}" fill-opacity="0.15" stroke="none"/>"#,
                    ser.color
                );
            }
        }
        let pts: Vec<String> = ser
            .points
            .iter()
            .filter(|p| p.1.is_finite())
            .map(|p| format!("{:.1},{:.1}", sx(p.0), sy(p.1)))
            .collect();
        if pts.len() > 1 {
            let dash = if ser.dashed {
                r#" stroke-dasharray="5,3""#
            } else {
                ""
            };
            let _ = write!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="1.6"{dash}/>"#,
                pts.join(" "),
                ser.color
            );
        }
    }
    clipped_note(s, panel, (y_lo, y_hi), x0, y0);
}

/// Points beyond the y range are drawn at its edge; this says so, with the extreme value, so
/// a flat line at the top is never mistaken for the data.
fn clipped_note(s: &mut String, panel: &Panel, (y_lo, y_hi): (f64, f64), x0: f64, y0: f64) {
    let ys = || {
        panel
            .series
            .iter()
            .flat_map(|ser| ser.points.iter().map(|p| p.1))
            .filter(|y| y.is_finite())
    };
    let above = ys().filter(|y| *y > y_hi).fold(f64::NAN, f64::max);
    let below = ys().filter(|y| *y < y_lo).fold(f64::NAN, f64::min);
    let mut note = Vec::new();
    if above.is_finite() {
        note.push(format!("clipped above: max {}", trim(above)));
    }
    if below.is_finite() {
        note.push(format!("clipped below: min {}", trim(below)));
    }
    if !note.is_empty() {
        let _ = write!(
            s,
            r##"<text x="{}" y="{}" text-anchor="end" fill="#c00">{}</text>"##,
            x0 + PANEL_W - 4.0,
            y0 + 13.0,
            esc(&note.join(", "))
        );
    }
}

fn trim(v: f64) -> String {
    let t = format!("{v:.2}");
    t.trim_end_matches('0').trim_end_matches('.').to_string()
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_lines_bands_and_escapes() {
        let grid = Grid {
            title: "a < b".into(),
            columns: 2,
            x_label: "pulses".into(),
            y_label: "error".into(),
            x_max: 10.0,
            y_max: 1.0,
        };
        let series = Series {
            label: "rot".into(),
            color: "blue",
            dashed: false,
            points: vec![(0.0, 1.0), (10.0, 0.0), (5.0, f64::NAN)],
            band: Some(vec![(0.0, 0.5, 1.0), (10.0, 0.0, 0.2)]),
        };
        let svg = render(
            &grid,
            &[Panel {
                title: "n=2".into(),
                series: vec![series],
                y_range: None,
                shade: vec![(2.0, 4.0)],
            }],
        );
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("a &lt; b"));
        assert_eq!(svg.matches("<polyline").count(), 1);
        assert_eq!(svg.matches("<path").count(), 1);
        // The NaN point is dropped: exactly two coordinates in the polyline.
        let line = svg.split("<polyline points=\"").nth(1).unwrap();
        assert_eq!(line.split('"').next().unwrap().split(' ').count(), 2);
        // The shaded interval, 2..4 of 0..10: a fifth of the panel's width.
        assert!(
            svg.contains(&format!(
                r##"width="{:.1}" height="{PANEL_H}" fill="#bbb""##,
                PANEL_W / 5.0
            )),
            "{svg}"
        );
        assert!(!svg.contains("clipped"), "nothing is beyond the range");
    }

    /// Issue 27: the experiments' thrust panels had no legend (it came from the first panel).
    #[test]
    fn the_legend_names_every_panels_lines_once() {
        let grid = Grid {
            title: "t".into(),
            columns: 2,
            x_label: "s".into(),
            y_label: "deg".into(),
            x_max: 10.0,
            y_max: 1.0,
        };
        let line = |label: &str, color: &'static str| Series {
            label: label.into(),
            color,
            dashed: false,
            points: vec![(0.0, 0.0), (1.0, 1.0)],
            band: None,
        };
        let panel = |series| Panel {
            title: "p".into(),
            series,
            y_range: None,
            shade: vec![],
        };
        let thrusters: Vec<Series> = (0..8)
            .map(|k| line(&format!("thruster {k}"), "red"))
            .collect();
        let svg = render(
            &grid,
            &[
                panel(vec![line("setpoint", "black")]),
                panel(thrusters),
                panel(vec![line("setpoint", "black")]),
            ],
        );
        let legend_text = |label: &str| svg.matches(&format!(">{label}</text>")).count();
        assert_eq!(legend_text("setpoint"), 1, "{svg}");
        for k in 0..8 {
            assert_eq!(legend_text(&format!("thruster {k}")), 1, "{svg}");
        }
    }

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        assert_eq!(
            nice_ticks(0.0, 10.0, 5),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
        assert_eq!(nice_ticks(0.0, 147.0, 5), vec![0.0, 50.0, 100.0, 150.0]);
        assert_eq!(
            nice_ticks(-23.0, 41.0, 5),
            vec![-40.0, -20.0, 0.0, 20.0, 40.0, 60.0]
        );
        assert_eq!(nice_range(0.0, 0.37), (0.0, 0.4));
        let t = nice_ticks(0.0, 0.3, 3);
        assert_eq!(
            t.iter().map(|v| trim(*v)).collect::<Vec<_>>(),
            ["0", "0.1", "0.2", "0.3"]
        );
        assert_eq!(nice_ticks(1.0, 1.0, 5), vec![1.0]);
    }

    #[test]
    fn points_beyond_the_range_are_reported_not_hidden() {
        let grid = Grid {
            title: "t".into(),
            columns: 1,
            x_label: "x".into(),
            y_label: "y".into(),
            x_max: 10.0,
            y_max: 90.0,
        };
        let panel = Panel {
            title: "error".into(),
            series: vec![Series {
                label: "err".into(),
                color: "blue",
                dashed: false,
                points: vec![(0.0, 10.0), (5.0, 147.0), (10.0, -3.0)],
                band: None,
            }],
            ..Panel::default()
        };
        let svg = render(&grid, &[panel]);
        assert!(
            svg.contains("clipped above: max 147, clipped below: min -3"),
            "{svg}"
        );
    }
}
