//! A tiny SVG line-chart writer: panels in a grid, lines with optional +-1 sigma bands.
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
#[derive(Debug, Clone)]
pub struct Panel {
    pub title: String,
    pub series: Vec<Series>,
    /// This panel's y axis (low, high) instead of the grid's 0..y_max: signed quantities
    /// (attitude angles) and panels of different scales in one figure.
    pub y_range: Option<(f64, f64)>,
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
    let legend_h = 28.0;
    let width = cols as f64 * cell_w + GAP;
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
    // Legend from the first panel's series.
    if let Some(first) = panels.first() {
        let mut x = GAP + MARGIN_L;
        let y = height - 12.0;
        for ser in &first.series {
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
            x += 34.0 + 6.5 * ser.label.len() as f64;
        }
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
    for k in 0..=5 {
        let yv = y_lo + (y_hi - y_lo) * k as f64 / 5.0;
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
    for k in 0..=5 {
        let xv = grid.x_max * k as f64 / 5.0;
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
            }],
        );
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("a &lt; b"));
        assert_eq!(svg.matches("<polyline").count(), 1);
        assert_eq!(svg.matches("<path").count(), 1);
        // The NaN point is dropped: exactly two coordinates in the polyline.
        let line = svg.split("<polyline points=\"").nth(1).unwrap();
        assert_eq!(line.split('"').next().unwrap().split(' ').count(), 2);
    }
}
