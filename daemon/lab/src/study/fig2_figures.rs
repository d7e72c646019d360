//! Turns study rows into the figures of docs/study.md (pure: returns file names and contents).

use thrusterd_core::estimator::{Excitation, Method};

use super::fig2::StudyRow;
use crate::plot::{render, Grid, Panel, Series};

const BLUE: &str = "#1f5fbf";
const RED: &str = "#c8321e";
const ORANGE: &str = "#e08a00";
const BLACK: &str = "#222222";

fn select(
    rows: &[StudyRow],
    n: usize,
    p: f64,
    method: Method,
    excitation: Excitation,
) -> Vec<&StudyRow> {
    rows.iter()
        .filter(|r| r.n == n && r.p == p && r.method == method && r.excitation == excitation)
        .collect()
}

fn series(
    rows: &[&StudyRow],
    label: &str,
    color: &'static str,
    acc: bool,
    with_band: bool,
) -> Series {
    let stat = |r: &StudyRow| if acc { r.err_acc } else { r.err_rot };
    Series {
        label: label.to_string(),
        color,
        dashed: false,
        points: rows
            .iter()
            .map(|r| (r.pulse as f64, stat(r).mean))
            .collect(),
        band: with_band.then(|| {
            rows.iter()
                .map(|r| {
                    let s = stat(r);
                    (r.pulse as f64, (s.mean - s.std).max(0.0), s.mean + s.std)
                })
                .collect()
        }),
    }
}

fn crlb_series(rows: &[&StudyRow], acc: bool) -> Series {
    Series {
        label: "Cramer-Rao".into(),
        color: BLACK,
        dashed: true,
        points: rows
            .iter()
            .map(|r| {
                let v = if acc { r.crlb_acc } else { r.crlb_rot };
                (r.pulse as f64, v.unwrap_or(f64::NAN))
            })
            .collect(),
        band: None,
    }
}

fn distinct<T: PartialEq + Copy>(it: impl Iterator<Item = T>) -> Vec<T> {
    let mut out: Vec<T> = Vec::new();
    for v in it {
        if !out.contains(&v) {
            out.push(v);
        }
    }
    out
}

/// SVG figures: the paper's Fig. 2 replica, and method/plan comparisons per p and sensor group.
pub fn figures(rows: &[StudyRow]) -> Vec<(String, String)> {
    let ns = distinct(rows.iter().map(|r| r.n));
    let ps = distinct(rows.iter().map(|r| r.p));
    let x_max = rows.iter().map(|r| r.pulse).max().unwrap_or(1) as f64;
    let mut out = Vec::new();

    // 1. The paper's figure: its method, round robin, rot (blue) and acc (red), +-1 sigma.
    let mut panels = Vec::new();
    for &n in &ns {
        for &p in &ps {
            let sel = select(rows, n, p, Method::Paper, Excitation::RoundRobin);
            panels.push(Panel {
                title: format!("N = {n}, p = {p}"),
                series: vec![
                    series(&sel, "rotation error", BLUE, false, true),
                    series(&sel, "acceleration error", RED, true, true),
                ],
                y_range: None,
                shade: Vec::new(),
            });
        }
    }
    out.push((
        "fig2_paper.svg".to_string(),
        render(
            &Grid {
                title: "Fig. 2 reproduced: the paper's method, round-robin pulses (mean +-1 sigma over configurations)".into(),
                columns: ps.len(),
                x_label: "pulses".into(),
                y_label: "relative error".into(),
                x_max,
                y_max: 1.2,
            },
            &panels,
        ),
    ));

    // 2. Comparisons: per p and group, rows = N, columns = excitation.
    for &p in &ps {
        for (acc, group) in [(false, "rot"), (true, "acc")] {
            let mut panels = Vec::new();
            for &n in &ns {
                for exc in Excitation::ALL {
                    let paper = select(rows, n, p, Method::Paper, exc);
                    let fwd = select(rows, n, p, Method::Forward, exc);
                    if fwd.is_empty() {
                        continue;
                    }
                    panels.push(Panel {
                        title: format!("N = {n}, {}", exc.name()),
                        series: vec![
                            series(&paper, "paper (S A = T)", ORANGE, acc, true),
                            series(&fwd, "forward (y = B u)", BLUE, acc, true),
                            crlb_series(&fwd, acc),
                        ],
                        y_range: None,
                        shade: Vec::new(),
                    });
                }
            }
            let what = if acc { "acceleration" } else { "rotation" };
            out.push((
                format!("compare_p{p}_{group}.svg"),
                render(
                    &Grid {
                        title: format!("{what} model error, p = {p}: paper vs forward vs Cramer-Rao, by excitation plan"),
                        columns: Excitation::ALL.len(),
                        x_label: "pulses".into(),
                        y_label: "relative error".into(),
                        x_max,
                        y_max: 1.2,
                    },
                    &panels,
                ),
            ));
        }
    }
    out
}
