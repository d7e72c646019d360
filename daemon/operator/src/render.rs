//! Human-readable text for status and model. Pure functions of the messages, so the
//! exact output is unit-tested.

use std::fmt::Write;

use thruster_protocol::{DaemonState, Dof, ModelMsg, StatusMsg};

use crate::chart::{contribution_chart, HALF_WIDTH};
use crate::json::{dof_key, state_name};
use crate::number::{num, num_with};

/// A relative error as a percentage.
fn percent(v: f64) -> String {
    format!("{:.1} %", 100.0 * v)
}

/// An error bound for people: early in an estimation the bound is meaningless (thousands of
/// percent, issue 27's "43923.9 %"), so above 100 % it reads "> 100 %"; None when unknown.
pub fn bound(v: f64) -> Option<String> {
    if !(v.is_finite() && v > 0.0) {
        None
    } else if v > 1.0 {
        Some("> 100 %".to_string())
    } else {
        Some(percent(v))
    }
}

/// `v` with `decimals`, or "unknown": thrusterd sends NaN for what it does not know yet.
fn known(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{v:.decimals$}")
    } else {
        "unknown".to_string()
    }
}

fn seconds(ns: u64) -> String {
    format!("{:.3} s", ns as f64 * 1e-9)
}

/// What the daemon is doing, in words: "pulse 3 of 8", "measuring noise", ...
/// `pulse` counts completed pulses: the one running is `pulse + 1`.
pub fn progress(s: &StatusMsg) -> String {
    let planned = s.pulses_planned;
    // NaN (no estimate yet) and 0 (not estimating) both mean: nothing to show.
    let bound = bound(s.error_bound)
        .map(|b| format!(", error bound {b}"))
        .unwrap_or_default();
    match s.state() {
        Ok(DaemonState::MeasureNoise) => "measuring noise at rest".to_string(),
        Ok(DaemonState::Pulse) => format!("pulse {} of {planned}{bound}", s.pulse + 1),
        Ok(DaemonState::Settle) => {
            format!("settling after pulse {} of {planned}{bound}", s.pulse)
        }
        Ok(DaemonState::Solve) => format!("solving after {} pulses{bound}", s.pulse),
        Ok(DaemonState::Identify) => {
            format!("identifying under control, decision {}{bound}", s.pulse)
        }
        Ok(DaemonState::Active) => format!("controlling with the model{bound}"),
        Ok(DaemonState::Idle) => "idle, zero thrust".to_string(),
        Ok(DaemonState::Fault) => "FAULT, zero thrust".to_string(),
        Err(_) => "unknown state".to_string(),
    }
}

fn rejections(s: &StatusMsg) -> String {
    let parts: Vec<String> = [
        (s.rejected_nonfinite, "non-finite"),
        (s.rejected_range, "out of range"),
        (s.rejected_time, "time/sequence"),
        (s.rejected_count, "count/index"),
        (s.rejected_other, "other"),
        (s.samples_missed, "IMU samples missed"),
    ]
    .iter()
    .filter(|(n, _)| *n > 0)
    .map(|(n, what)| format!("{n} {what}"))
    .collect();
    if parts.is_empty() {
        "none".to_string()
    } else {
        parts.join(", ")
    }
}

pub fn total_rejections(s: &StatusMsg) -> u64 {
    s.rejected_nonfinite + s.rejected_range + s.rejected_time + s.rejected_count + s.rejected_other
}

/// The multi-line report of `thrusterctl status`.
/// The driver's own report on its outputs, one indented line like the status rows.
pub fn driver_line(d: Option<&thruster_protocol::DriverStatusMsg>) -> String {
    let Some(d) = d else {
        return format!("  {:<13}no driver status published\n", "driver");
    };
    let state = d
        .output_state()
        .map(|s| format!("{s:?}"))
        .unwrap_or_else(|e| format!("Unknown({})", e.value));
    let mut line = format!(
        "  {:<13}{}: {} thrusters, outputs {state}, link {}, {}, commands {} accepted / {} rejected, watchdog {}{}",
        "driver",
        d.driver(),
        d.thruster_count,
        if d.link_up == 1 { "up" } else { "down" },
        if d.armed == 1 { "armed" } else { "disarmed" },
        d.commands_accepted,
        d.commands_rejected,
        d.watchdog_expiries,
        match (d.supply_voltage(), d.supply_current()) {
            (Some(v), Some(a)) => format!(", supply {v:.2} V {a:.1} A"),
            (Some(v), None) => format!(", supply {v:.2} V"),
            _ => String::new(),
        },
    );
    if !d.text().is_empty() {
        line.push_str(&format!(" ({})", d.text()));
    }
    line.push('\n');
    line
}

/// The supply: the voltage the daemon last heard and what it does with it.
pub fn supply(s: &StatusMsg) -> String {
    use thruster_protocol::SupplyCompensation;
    let volts = if s.supply_voltage_v.is_finite() {
        format!("{:.2} V", s.supply_voltage_v)
    } else {
        "no voltage reading".to_string()
    };
    let what = match s.supply_compensation() {
        Ok(SupplyCompensation::Active) => "commands referred to the reference voltage",
        Ok(SupplyCompensation::NoReading) => "not compensated (no voltage reading)",
        Ok(SupplyCompensation::Off) => "not compensated (supply.compensation = \"none\")",
        Err(_) => "unknown compensation state",
    };
    format!("{volts}, {what}")
}

pub fn status_report(namespace: &str, s: &StatusMsg) -> String {
    let mut out = String::new();
    let model = if s.model_version == 0 {
        "none".to_string()
    } else {
        format!("version {}", s.model_version)
    };
    let rows = [
        ("state", state_name(s.state)),
        ("progress", progress(s)),
        ("power", known(s.power, 2)),
        (
            "noise",
            if s.sigma_rot.is_finite() || s.sigma_acc.is_finite() {
                format!(
                    "rotation {} rad/s, acceleration {} m/s^2 (1 sigma)",
                    known(s.sigma_rot, 4),
                    known(s.sigma_acc, 4)
                )
            } else {
                "not measured yet".to_string()
            },
        ),
        ("samples", format!("{} IMU samples accepted", s.samples)),
        ("rejected", rejections(s)),
        (
            "refused",
            format!("{} operator requests refused", s.requests_refused),
        ),
        ("model", model),
        ("IMU rate", format!("{} Hz", known(s.imu_rate_hz, 1))),
        ("vehicle time", seconds(s.vehicle_time_ns)),
        ("supply", supply(s)),
    ];
    let _ = writeln!(out, "thrusterd on namespace {namespace}");
    for (k, v) in rows {
        let _ = writeln!(out, "  {k:<13}{v}");
    }
    if !s.text().is_empty() {
        let _ = writeln!(out, "  {:<13}{}", "message", s.text());
    }
    out
}

/// One line per status for `watch`.
pub fn status_line(s: &StatusMsg) -> String {
    if s.is_stopped() {
        // The state field is the one the daemon left, not what it is now.
        let mut line = format!(
            "[{:>11}] {:<12} thrusterd stopped (it was {}",
            seconds(s.vehicle_time_ns),
            "Stopped",
            state_name(s.state)
        );
        if s.model_version > 0 {
            let _ = write!(line, ", model v{}", s.model_version);
        }
        line.push(')');
        return line;
    }
    let mut line = format!(
        "[{:>11}] {:<12} {}",
        seconds(s.vehicle_time_ns),
        state_name(s.state),
        progress(s)
    );
    if s.model_version > 0 {
        let _ = write!(line, " | model v{}", s.model_version);
    }
    let rejected = total_rejections(s);
    if rejected > 0 {
        let _ = write!(line, " | {rejected} rejected");
    }
    if !s.text().is_empty() {
        let _ = write!(line, " | {}", s.text());
    }
    line
}

/// The full report of `thrusterctl model`.
pub fn model_report(m: &ModelMsg) -> String {
    let n = m.thruster_count();
    let mut out = String::new();
    let source = m
        .source()
        .map_or_else(|e| e.to_string(), |s| s.name().into());
    let method = m
        .method()
        .map_or_else(|e| e.to_string(), |s| s.name().into());
    let _ = writeln!(
        out,
        "model version {}: {n} thrusters, source {source}, method {method}",
        m.version,
    );
    if !m.provenance().is_empty() {
        let _ = writeln!(out, "provenance: {}", m.provenance());
    }
    if m.rel_err_rot.is_finite() || m.rel_err_acc.is_finite() {
        let _ = writeln!(
            out,
            "confidence: relative error bound {} (rotation), {} (translation)",
            percent(m.rel_err_rot),
            percent(m.rel_err_acc)
        );
    } else {
        // A nominal model, or the paper's method: no bound, not "NaN %".
        let _ = writeln!(
            out,
            "confidence: no error bound (not estimated by this method)"
        );
    }
    let (on, off): (Vec<Dof>, Vec<Dof>) = Dof::ALL.iter().partition(|d| m.is_actuated(**d));
    let names = |dofs: &[Dof]| {
        if dofs.is_empty() {
            "none".to_string()
        } else {
            dofs.iter()
                .map(|d| dof_key(*d))
                .collect::<Vec<_>>()
                .join(", ")
        }
    };
    let _ = writeln!(out, "actuated DOFs: {}", names(&on));
    if !off.is_empty() {
        let _ = writeln!(
            out,
            "NOT actuated:  {} (never commanded; the thrusters cannot move the vehicle there \
             independently)",
            names(&off)
        );
    }

    // Thrusters as rows: 6 columns always fit a terminal, 16 thruster columns would not.
    let header: String = Dof::ALL
        .iter()
        .map(|d| format!("{:>17}", dof_key(*d)))
        .collect();
    let _ = writeln!(
        out,
        "\neffectiveness B, transposed (response per unit command: rad/s^2 roll/pitch/yaw, \
         m/s^2 surge/sway/heave; +- one standard error where known)"
    );
    let _ = writeln!(out, "{:<6}{header}", "");
    for j in 0..n {
        let cells: String = Dof::ALL
            .iter()
            .map(|d| {
                let v = m.effectiveness[d.index()][j];
                let e = m.std_err[d.index()][j];
                let err = if e.is_finite() {
                    format!("±{:.3}", e)
                } else {
                    String::new()
                };
                format!("{:>10}{err:<7}", num(v))
            })
            .collect();
        let _ = writeln!(out, "{:<6}{}", format!("T{j}"), cells.trim_end());
    }

    let header: String = Dof::ALL
        .iter()
        .map(|d| format!("{:>10}", dof_key(*d)))
        .collect();
    let _ = writeln!(
        out,
        "\nallocation A (command per unit of desired motion: per rad/s^2 or m/s^2; \
         '-' = DOF not actuated)"
    );
    let _ = writeln!(out, "{:<6}{header}", "");
    for (j, row) in m.allocation[..n].iter().enumerate() {
        let cells: String = Dof::ALL
            .iter()
            .map(|d| {
                if m.is_actuated(*d) {
                    format!("{:>10}", num_with(row[d.index()], 4))
                } else {
                    format!("{:>10}", "-")
                }
            })
            .collect();
        let _ = writeln!(out, "{:<6}{cells}", format!("T{j}"));
    }

    let _ = writeln!(
        out,
        "\ncontribution of each thruster per DOF (bars scaled to the DOF's largest entry)"
    );
    out.push_str(&contribution_chart(m, HALF_WIDTH));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::{ModelMethod, ModelSource};

    fn status(state: DaemonState) -> StatusMsg {
        let mut s = StatusMsg {
            pulse: 2,
            pulses_planned: 8,
            error_bound: 0.042,
            power: 0.5,
            sigma_rot: 0.0123,
            sigma_acc: 0.0456,
            samples: 5000,
            model_version: 3,
            imu_rate_hz: 400.0,
            vehicle_time_ns: 12_345_000_000,
            ..StatusMsg::default()
        };
        s.set_state(state);
        s
    }

    #[test]
    fn progress_counts_completed_pulses_and_says_what_happens() {
        // `pulse` = 2 completed: the third is running, or the second just ended.
        assert_eq!(
            progress(&status(DaemonState::Pulse)),
            "pulse 3 of 8, error bound 4.2 %"
        );
        assert_eq!(
            progress(&status(DaemonState::Settle)),
            "settling after pulse 2 of 8, error bound 4.2 %"
        );
        let mut s = status(DaemonState::Pulse);
        s.error_bound = 0.0;
        assert_eq!(progress(&s), "pulse 3 of 8");
        assert_eq!(progress(&status(DaemonState::Fault)), "FAULT, zero thrust");
        s.error_bound = f64::NAN;
        assert_eq!(progress(&s), "pulse 3 of 8");
        // Early in a run the bound is meaningless: no number in the thousands of percent.
        s.error_bound = 439.239;
        assert_eq!(progress(&s), "pulse 3 of 8, error bound > 100 %");
        s.error_bound = 1.0;
        assert_eq!(progress(&s), "pulse 3 of 8, error bound 100.0 %");
        // Solving counts the pulses done, not the plan's (which may have grown).
        let mut s = status(DaemonState::Solve);
        s.pulse = 12;
        assert_eq!(progress(&s), "solving after 12 pulses, error bound 4.2 %");
    }

    #[test]
    fn status_report_lists_every_field() {
        let mut s = status(DaemonState::Pulse);
        s.rejected_nonfinite = 2;
        s.rejected_time = 1;
        s.requests_refused = 4;
        s.supply_voltage_v = 15.87;
        s.supply_compensation = thruster_protocol::SupplyCompensation::Active.as_u32();
        s.set_text("pulsing thruster 2");
        let text = status_report("veh1", &s);
        let expected = "\
thrusterd on namespace veh1
  state        Pulse
  progress     pulse 3 of 8, error bound 4.2 %
  power        0.50
  noise        rotation 0.0123 rad/s, acceleration 0.0456 m/s^2 (1 sigma)
  samples      5000 IMU samples accepted
  rejected     2 non-finite, 1 time/sequence
  refused      4 operator requests refused
  model        version 3
  IMU rate     400.0 Hz
  vehicle time 12.345 s
  supply       15.87 V, commands referred to the reference voltage
  message      pulsing thruster 2
";
        assert_eq!(text, expected);
    }

    #[test]
    fn unknown_values_say_so() {
        let mut s = status(DaemonState::Idle);
        s.sigma_rot = f64::NAN;
        s.sigma_acc = f64::NAN;
        s.imu_rate_hz = f64::NAN;
        s.error_bound = f64::NAN;
        let text = status_report("veh1", &s);
        assert!(text.contains("  noise        not measured yet\n"), "{text}");
        assert!(text.contains("  IMU rate     unknown Hz\n"), "{text}");
        s.supply_voltage_v = f64::NAN;
        s.supply_compensation = thruster_protocol::SupplyCompensation::NoReading.as_u32();
        assert!(
            status_report("veh1", &s).contains(
                "  supply       no voltage reading, not compensated (no voltage reading)\n"
            ),
            "{text}"
        );
        assert!(
            text.contains("  progress     idle, zero thrust\n"),
            "{text}"
        );
        s.sigma_acc = 0.5;
        assert!(
            status_report("veh1", &s).contains("rotation unknown rad/s, acceleration 0.5000 m/s^2")
        );
    }

    #[test]
    fn status_line_is_compact() {
        let mut s = status(DaemonState::Active);
        assert_eq!(
            status_line(&s),
            "[   12.345 s] Active       controlling with the model, error bound 4.2 % | model v3"
        );
        s.rejected_range = 4;
        s.set_text("model refused: rank 4");
        assert!(status_line(&s).ends_with("| model v3 | 4 rejected | model refused: rank 4"));
        // Issue 27: the last status read "Active ... | thrusterd stopped".
        s.set_text(StatusMsg::STOPPED_TEXT);
        assert_eq!(
            status_line(&s),
            "[   12.345 s] Stopped      thrusterd stopped (it was Active, model v3)"
        );
    }

    #[test]
    fn model_report_shows_tables_dofs_and_chart() {
        let mut m = ModelMsg {
            version: 5,
            count: 2,
            actuated: Dof::Yaw.mask() | Dof::Surge.mask(),
            rel_err_rot: 0.05,
            rel_err_acc: 0.125,
            ..ModelMsg::default()
        };
        m.set_source(ModelSource::Estimated);
        m.set_method(ModelMethod::Forward);
        m.effectiveness[Dof::Yaw.index()][..2].copy_from_slice(&[1.5, -1.5]);
        m.effectiveness[Dof::Surge.index()][..2].copy_from_slice(&[0.8, 0.8]);
        for row in m.std_err.iter_mut() {
            row[..2].copy_from_slice(&[0.01, f64::NAN]);
        }
        m.allocation[0][Dof::Yaw.index()] = 0.333;
        m.allocation[0][Dof::Surge.index()] = 0.625;
        let text = model_report(&m);
        assert!(text.starts_with("model version 5: 2 thrusters, source Estimated, method Forward"));
        assert!(text.contains("relative error bound 5.0 % (rotation), 12.5 % (translation)"));
        assert!(text.contains("actuated DOFs: yaw, surge\n"));
        assert!(text.contains("NOT actuated:  roll, pitch, sway, heave"));
        // Thruster 0 has finite standard errors, thruster 1 unknown ones (no "±").
        let t0 = text.lines().find(|l| l.starts_with("T0    ")).unwrap();
        assert!(t0.contains("+1.500±0.010"), "{t0}");
        let t1 = text.lines().find(|l| l.starts_with("T1    ")).unwrap();
        assert!(t1.contains("-1.500") && !t1.contains('±'), "{t1}");
        // Allocation: unactuated columns are dashes.
        let a0 = text
            .lines()
            .filter(|l| l.starts_with("T0    "))
            .nth(1)
            .unwrap();
        assert_eq!(
            a0,
            "T0             -         -   +0.3330   +0.6250         -         -"
        );
        assert!(text.contains("yaw [rad/s^2 per unit command]  largest |entry| 1.500"));
    }
}
