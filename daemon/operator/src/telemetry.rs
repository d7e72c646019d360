//! Telemetry for people: one plain line (piped `watch`), a small dashboard redrawn in place (a
//! terminal), and the setpoint line `watch` prints when the daemon's setpoint changes. Pure
//! functions of the message, so the exact output is unit-tested. Degrees and metres; the
//! message itself is in radians.

use std::fmt::Write;

use thruster_protocol::{DaemonState, TelemetryMsg};

use crate::json::state_name;

/// Thrust values per dashboard line (each 6 characters wide, so 8 fit in 80 columns with the
/// label).
const THRUST_PER_LINE: usize = 8;

fn deg(rad: f64) -> f64 {
    rad.to_degrees()
}

fn seconds(ns: u64) -> String {
    format!("{:.3} s", ns as f64 * 1e-9)
}

/// Degrees with one decimal and a sign, where a value that rounds to zero is `+0.0`: a level
/// setpoint computed as -1e-17 rad must not read "-0.0".
fn deg1(rad: f64) -> String {
    let d = deg(rad);
    let d = if (d * 10.0).round() == 0.0 { 0.0 } else { d };
    format!("{d:+.1}")
}

/// `roll +1.2 pitch -3.4 yaw +45.0`, degrees.
fn angles(euler: &[f64; 3]) -> String {
    format!(
        "roll {} pitch {} yaw {}",
        deg1(euler[0]),
        deg1(euler[1]),
        deg1(euler[2])
    )
}

/// What the estimation under way has done, or None.
pub fn estimation(t: &TelemetryMsg) -> Option<String> {
    if !t.has(TelemetryMsg::ESTIMATING) {
        return None;
    }
    // `pulse` counts pulses completed: while one runs it is the next one, as status says it
    // (one number for one moment, issue 27).
    let current = if t.state() == Ok(DaemonState::Pulse) {
        t.pulse + 1
    } else {
        t.pulse
    };
    let mut s = format!(
        "pulse {current} of {}, power {:.2}",
        t.pulses_planned, t.power
    );
    if let Some(b) = t
        .has(TelemetryMsg::HAS_ERROR_BOUND)
        .then(|| crate::render::bound(t.error_bound))
        .flatten()
    {
        let _ = write!(s, ", bound {b}");
    }
    if t.has(TelemetryMsg::HAS_NOISE) {
        let _ = write!(
            s,
            ", noise {:.3} rad/s {:.3} m/s^2",
            t.sigma_rot, t.sigma_acc
        );
    }
    Some(s)
}

fn thrust_numbers(values: &[f64]) -> String {
    let parts: Vec<String> = values.iter().map(|v| format!("{v:+.2}")).collect();
    parts.join(" ")
}

/// One line per telemetry message, for a pipe or a log: time, state, attitude, setpoint and
/// error, depth, commands, model, and the estimation when one runs.
pub fn line(t: &TelemetryMsg) -> String {
    let mut s = format!(
        "[{:>11}] telemetry {} | att {} deg",
        seconds(t.t_ns),
        state_name(t.state),
        angles(&t.euler)
    );
    if t.has(TelemetryMsg::HAS_SETPOINT) {
        let _ = write!(
            s,
            " | sp {} deg | err {:.2} deg",
            angles(&t.setpoint_euler),
            deg(t.attitude_error_angle)
        );
    }
    if t.has(TelemetryMsg::HAS_DEPTH) {
        let _ = write!(s, " | depth {:.2} m", t.depth);
    }
    if t.has(TelemetryMsg::HOLD_DEPTH) {
        let _ = write!(s, " sp {:.2} m", t.setpoint_depth);
        if t.has(TelemetryMsg::HAS_DEPTH) {
            let _ = write!(s, " err {:+.2} m", t.depth_error);
        }
    }
    let _ = write!(s, " | thrust {}", thrust_numbers(t.thrusters()));
    if t.model_version > 0 {
        let _ = write!(s, " | model v{}", t.model_version);
    }
    if let Some(e) = estimation(t) {
        let _ = write!(s, " | {e}");
    }
    s
}

/// The dashboard a terminal shows, redrawn in place: a few lines of at most 80 columns (a
/// longer line would wrap and the redraw would miscount; the estimation's words are cut).
pub fn dashboard(t: &TelemetryMsg) -> Vec<String> {
    let mut lines = Vec::new();
    let head = format!(
        "{:<12} t {:>11}  model {}",
        state_name(t.state),
        seconds(t.t_ns),
        if t.model_version > 0 {
            format!("v{}", t.model_version)
        } else {
            "none".to_string()
        }
    );
    lines.push(head);
    if let Some(e) = estimation(t) {
        lines.push(format!("estimate  {e}"));
    }
    lines.push(format!(
        "attitude  {} deg   rate {:+.2} {:+.2} {:+.2} rad/s",
        angles(&t.euler),
        t.rate[0],
        t.rate[1],
        t.rate[2]
    ));
    if t.has(TelemetryMsg::HAS_SETPOINT) {
        let e = &t.attitude_error;
        lines.push(format!("setpoint  {} deg", angles(&t.setpoint_euler)));
        lines.push(format!(
            "error     {:.2} deg   about body x {} y {} z {} deg",
            deg(t.attitude_error_angle),
            deg1(e[0]),
            deg1(e[1]),
            deg1(e[2])
        ));
    } else {
        lines.push("setpoint  none (not controlling)".to_string());
    }
    let mut depth = if t.has(TelemetryMsg::HAS_DEPTH) {
        format!("depth     {:.2} m", t.depth)
    } else {
        "depth     no sensor".to_string()
    };
    if t.has(TelemetryMsg::HOLD_DEPTH) {
        let _ = write!(depth, "   setpoint {:.2} m", t.setpoint_depth);
        if t.has(TelemetryMsg::HAS_DEPTH) {
            let _ = write!(depth, "   error {:+.2} m", t.depth_error);
        }
    }
    lines.push(depth);
    let thrust = t.thrusters();
    if thrust.is_empty() {
        lines.push("thrust    none".to_string());
    }
    for (i, chunk) in thrust.chunks(THRUST_PER_LINE).enumerate() {
        let label = if i == 0 { "thrust" } else { "" };
        lines.push(format!("{label:<9} {}", thrust_numbers(chunk)));
    }
    for l in &mut lines {
        if l.chars().count() > 80 {
            *l = l.chars().take(79).collect::<String>() + "~";
        }
    }
    lines
}

/// What the daemon holds, compared to print a line when it changes. The daemon holds a
/// setpoint exactly until the next one, so equality is bitwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldSetpoint {
    euler: [u64; 3],
    depth: Option<u64>,
}

impl HeldSetpoint {
    /// The setpoint `t` shows, or None while nothing is tracked.
    pub fn of(t: &TelemetryMsg) -> Option<Self> {
        t.has(TelemetryMsg::HAS_SETPOINT).then(|| Self {
            euler: t.setpoint_euler.map(f64::to_bits),
            depth: t
                .has(TelemetryMsg::HOLD_DEPTH)
                .then(|| t.setpoint_depth.to_bits()),
        })
    }
}

/// What the daemon holds, as the reply to a setpoint says it: read from telemetry published
/// after the daemon took the setpoint, so it is what is held, not what was asked.
pub fn held_text(t: &TelemetryMsg) -> String {
    if !t.has(TelemetryMsg::HAS_SETPOINT) {
        return format!(
            "thrusterd is {} and holds nothing now (it takes this setpoint when it controls)",
            state_name(t.state)
        );
    }
    let depth = if t.has(TelemetryMsg::HOLD_DEPTH) && !t.has(TelemetryMsg::HAS_DEPTH) {
        // The controller holds only a depth it measures: said, not claimed.
        format!(
            "depth {:.2} m asked but not held: the samples carry no depth",
            t.setpoint_depth
        )
    } else if t.has(TelemetryMsg::HOLD_DEPTH) {
        format!("depth {:.2} m", t.setpoint_depth)
    } else {
        "depth free".to_string()
    };
    format!("thrusterd holds {} deg, {depth}", angles(&t.setpoint_euler))
}

/// The line `watch` prints when the held setpoint changes.
pub fn setpoint_line(t: &TelemetryMsg) -> String {
    let mut s = format!(
        "[{:>11}] setpoint {} deg",
        seconds(t.t_ns),
        angles(&t.setpoint_euler)
    );
    if t.has(TelemetryMsg::HOLD_DEPTH) {
        let _ = write!(s, ", depth {:.2} m", t.setpoint_depth);
        if !t.has(TelemetryMsg::HAS_DEPTH) {
            s.push_str(" (no depth measured: not held)");
        }
    } else {
        s.push_str(", depth free");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::ThrustMode;

    fn holding() -> TelemetryMsg {
        let pitch = 10f64.to_radians();
        let mut t = TelemetryMsg {
            t_ns: 12_345_000_000,
            flags: TelemetryMsg::HAS_SETPOINT | TelemetryMsg::HOLD_DEPTH | TelemetryMsg::HAS_DEPTH,
            count: 5,
            model_version: 2,
            euler: [0.0, 9f64.to_radians(), 45f64.to_radians()],
            rate: [0.01, -0.02, 0.0],
            depth: 2.04,
            setpoint_euler: [0.0, pitch, 45f64.to_radians()],
            setpoint_depth: 2.0,
            attitude_error: [0.0, 1f64.to_radians(), 0.0],
            attitude_error_angle: 1f64.to_radians(),
            depth_error: -0.04,
            ..TelemetryMsg::default()
        };
        t.set_state(DaemonState::Active);
        t.set_mode(ThrustMode::Controlling);
        t.thrust[..5].copy_from_slice(&[0.12, -0.05, 0.0, 0.31, -1.0]);
        t
    }

    #[test]
    fn the_held_setpoint_says_depth() {
        assert_eq!(
            held_text(&holding()),
            "thrusterd holds roll +0.0 pitch +10.0 yaw +45.0 deg, depth 2.00 m"
        );
        let mut free = holding();
        free.flags &= !TelemetryMsg::HOLD_DEPTH;
        assert!(held_text(&free).ends_with(", depth free"));
        // No depth measured (a driver without a sensor, or one that refused its sensor).
        let mut blind = holding();
        blind.flags &= !TelemetryMsg::HAS_DEPTH;
        assert!(
            held_text(&blind)
                .ends_with("depth 2.00 m asked but not held: the samples carry no depth"),
            "{}",
            held_text(&blind)
        );
        let mut idle = holding();
        idle.flags = 0;
        idle.set_state(DaemonState::Idle);
        assert_eq!(
            held_text(&idle),
            "thrusterd is Idle and holds nothing now (it takes this setpoint when it controls)"
        );
    }

    #[test]
    fn a_line_while_holding() {
        assert_eq!(
            line(&holding()),
            "[   12.345 s] telemetry Active | att roll +0.0 pitch +9.0 yaw +45.0 deg \
             | sp roll +0.0 pitch +10.0 yaw +45.0 deg | err 1.00 deg \
             | depth 2.04 m sp 2.00 m err -0.04 m | thrust +0.12 -0.05 +0.00 +0.31 -1.00 \
             | model v2"
        );
    }

    #[test]
    fn a_line_while_estimating_shows_progress_and_no_setpoint() {
        let mut t = TelemetryMsg {
            flags: TelemetryMsg::ESTIMATING | TelemetryMsg::HAS_NOISE,
            pulse: 3,
            pulses_planned: 56,
            power: 0.8,
            sigma_rot: 0.25,
            sigma_acc: 0.49,
            count: 2,
            ..TelemetryMsg::default()
        };
        t.set_state(DaemonState::Pulse);
        assert_eq!(
            line(&t),
            "[    0.000 s] telemetry Pulse | att roll +0.0 pitch +0.0 yaw +0.0 deg \
             | thrust +0.00 +0.00 | pulse 4 of 56, power 0.80, noise 0.250 rad/s 0.490 m/s^2"
        );
        t.flags |= TelemetryMsg::HAS_ERROR_BOUND;
        t.error_bound = 0.081;
        assert!(line(&t).ends_with("power 0.80, bound 8.1 %, noise 0.250 rad/s 0.490 m/s^2"));
        // Issue 27's "error bound 43923.9 %": meaningless early bounds read "> 100 %".
        t.error_bound = 439.239;
        assert!(line(&t).contains("pulse 4 of 56, power 0.80, bound > 100 %, noise"));
    }

    #[test]
    fn the_dashboard_fits_80_columns() {
        let lines = dashboard(&holding());
        assert_eq!(
            lines,
            [
                "Active       t    12.345 s  model v2",
                "attitude  roll +0.0 pitch +9.0 yaw +45.0 deg   rate +0.01 -0.02 +0.00 rad/s",
                "setpoint  roll +0.0 pitch +10.0 yaw +45.0 deg",
                "error     1.00 deg   about body x +0.0 y +1.0 z +0.0 deg",
                "depth     2.04 m   setpoint 2.00 m   error -0.04 m",
                "thrust    +0.12 -0.05 +0.00 +0.31 -1.00",
            ]
        );
        // Sixteen thrusters and an estimation: two thrust lines, nothing wider than 80.
        let mut t = holding();
        t.count = 16;
        t.flags |= TelemetryMsg::ESTIMATING | TelemetryMsg::HAS_ERROR_BOUND;
        t.flags |= TelemetryMsg::HAS_NOISE;
        t.pulses_planned = 80;
        t.error_bound = 0.5;
        t.sigma_rot = 10.0;
        t.sigma_acc = 100.0;
        t.rate = [-49.0; 3];
        t.euler = [-3.1, -1.5, -3.1];
        let lines = dashboard(&t);
        assert_eq!(lines.len(), 8, "{lines:#?}");
        assert!(lines.iter().all(|l| l.chars().count() <= 80), "{lines:#?}");
        assert!(
            lines[1].starts_with("estimate  pulse 0 of 80"),
            "{}",
            lines[1]
        );
        // What does not fit is cut, visibly.
        assert!(lines[2].ends_with('~'), "{}", lines[2]);
        assert_eq!(
            lines[7],
            "          +0.00 +0.00 +0.00 +0.00 +0.00 +0.00 +0.00 +0.00"
        );
    }

    #[test]
    fn the_held_setpoint_and_its_line() {
        let t = holding();
        let held = HeldSetpoint::of(&t).unwrap();
        let mut moved = t;
        moved.setpoint_euler[1] = 15f64.to_radians();
        assert_ne!(HeldSetpoint::of(&moved), Some(held));
        // The estimate moving changes nothing the operator asked for.
        let mut later = t;
        later.euler[1] = 9.9f64.to_radians();
        later.t_ns += 1_000_000;
        assert_eq!(HeldSetpoint::of(&later), Some(held));
        let mut idle = t;
        idle.flags = 0;
        // Rounding noise of a level setpoint reads as zero, never "-0.0".
        assert_eq!(deg1(-1e-17), "+0.0");
        assert_eq!(deg1(-0.0008), "+0.0");
        assert_eq!(deg1(-0.002), "-0.1");
        assert_eq!(HeldSetpoint::of(&idle), None);
        assert_eq!(
            setpoint_line(&t),
            "[   12.345 s] setpoint roll +0.0 pitch +10.0 yaw +45.0 deg, depth 2.00 m"
        );
        let mut blind = t;
        blind.flags &= !TelemetryMsg::HAS_DEPTH;
        assert!(setpoint_line(&blind).ends_with("depth 2.00 m (no depth measured: not held)"));
    }
}
