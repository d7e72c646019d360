//! Scripted reconfiguration events at given simulation times, from TOML:
//!
//! ```toml
//! [[event]]
//! t_s = 20.0
//! announce = true          # publish a reconfiguration event to the daemon (default true)
//! action = { kind = "rotate", thruster = "T", axis = [1, 0, 0], angle_deg = 45 }
//! ```
//!
//! Kinds: `rotate` (axis/angle in the body frame), `set_direction`, `move`, `remove`, `add`
//! (with a full `spec`, as a `[[thruster]]` of a vehicle file), `kill` (dead, no thrust).
//! This module only schedules: [`Scenario::due`] hands out the events whose time has come, the
//! simulator applies them ([`crate::Simulator::apply`]) and the driver publishes announced ones.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::load::{check_finite, parse_toml, read_text, LoadError};
use crate::vehicle::ThrusterSpec;

/// What happens to the vehicle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Action {
    /// Rotates a thruster's direction by `angle_deg` about `axis` (body frame, right-hand
    /// rule); its position is unchanged.
    Rotate {
        thruster: String,
        axis: [f64; 3],
        angle_deg: f64,
    },
    /// Sets a thruster's direction (normalised; must not be zero).
    SetDirection {
        thruster: String,
        direction: [f64; 3],
    },
    /// Moves a thruster to `position_m` (relative to the CO, m); its direction is unchanged.
    Move {
        thruster: String,
        position_m: [f64; 3],
    },
    /// Detaches a thruster: later thrusters move down one command index.
    Remove { thruster: String },
    /// Attaches a new thruster at the end of the command vector.
    Add { spec: ThrusterSpec },
    /// The thruster stops producing thrust (it stays in the command vector).
    Kill { thruster: String },
}

impl Action {
    /// Name of the thruster the action concerns.
    pub fn thruster(&self) -> &str {
        match self {
            Action::Rotate { thruster, .. }
            | Action::SetDirection { thruster, .. }
            | Action::Move { thruster, .. }
            | Action::Remove { thruster }
            | Action::Kill { thruster } => thruster,
            Action::Add { spec } => &spec.name,
        }
    }

    fn validate(&mut self, origin: &str, key: &str) -> Result<(), LoadError> {
        match self {
            Action::Rotate {
                axis, angle_deg, ..
            } => {
                check_finite(origin, &format!("{key}.axis"), axis)?;
                check_finite(origin, &format!("{key}.angle_deg"), &[*angle_deg])?;
                if axis.iter().map(|a| a * a).sum::<f64>() < 1e-12 {
                    return Err(LoadError::invalid(
                        origin,
                        format!("{key}.axis"),
                        "must not be zero",
                    ));
                }
            }
            Action::SetDirection { direction, .. } => {
                check_finite(origin, &format!("{key}.direction"), direction)?;
                if direction.iter().map(|a| a * a).sum::<f64>() < 1e-12 {
                    return Err(LoadError::invalid(
                        origin,
                        format!("{key}.direction"),
                        "must not be zero",
                    ));
                }
            }
            Action::Move { position_m, .. } => {
                check_finite(origin, &format!("{key}.position_m"), position_m)?;
            }
            Action::Add { spec } => spec.validate(origin, &format!("{key}.spec"))?,
            Action::Remove { .. } | Action::Kill { .. } => {}
        }
        Ok(())
    }
}

fn default_announce() -> bool {
    true
}

/// A scheduled action.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Event {
    /// Simulation time, s (>= 0).
    pub t_s: f64,
    /// Whether the driver tells the daemon (a reconfiguration event); false models an
    /// unannounced change (a bumped or failed thruster) the daemon must discover. Default true.
    #[serde(default = "default_announce")]
    pub announce: bool,
    /// What happens.
    pub action: Action,
}

impl Event {
    /// Time, ns (rounded).
    pub fn t_ns(&self) -> u64 {
        (self.t_s * 1e9).round() as u64
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScenarioFile {
    #[serde(rename = "event", default)]
    events: Vec<Event>,
}

/// Events in time order with a cursor.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scenario {
    events: Vec<Event>,
    next: usize,
}

impl Scenario {
    /// Validates and sorts `events` by time (stable: same-time events keep their order).
    pub fn new(mut events: Vec<Event>, origin: &str) -> Result<Self, LoadError> {
        for (i, e) in events.iter_mut().enumerate() {
            let key = format!("event[{i}]");
            if !(e.t_s.is_finite() && e.t_s >= 0.0) {
                return Err(LoadError::invalid(
                    origin,
                    format!("{key}.t_s"),
                    format!("must be >= 0, got {}", e.t_s),
                ));
            }
            e.action.validate(origin, &format!("{key}.action"))?;
        }
        events.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        Ok(Scenario { events, next: 0 })
    }

    /// Loads a scenario file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LoadError> {
        let path = path.as_ref();
        let text = read_text(path)?;
        Scenario::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, LoadError> {
        let file: ScenarioFile = parse_toml(text, origin)?;
        Scenario::new(file.events, origin)
    }

    /// Events not handed out yet whose time is <= `t_ns`, in order; each is returned once.
    pub fn due(&mut self, t_ns: u64) -> &[Event] {
        let start = self.next;
        while self.next < self.events.len() && self.events[self.next].t_ns() <= t_ns {
            self.next += 1;
        }
        &self.events[start..self.next]
    }

    /// All events, sorted.
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// Events not handed out yet.
    pub fn remaining(&self) -> usize {
        self.events.len() - self.next
    }

    /// Starts over (for a new run).
    pub fn rewind(&mut self) {
        self.next = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = r#"
[[event]]
t_s = 5.0
action = { kind = "kill", thruster = "L" }

[[event]]
t_s = 2.0
announce = false
action = { kind = "rotate", thruster = "T", axis = [1, 0, 0], angle_deg = 45 }

[[event]]
t_s = 8
[event.action]
kind = "add"
spec = { name = "X", position_m = [0, 0.2, 0], direction = [0, 1, 0] }
"#;

    #[test]
    fn parses_sorts_and_hands_out_once() {
        let mut s = Scenario::from_toml_str(TEXT, "s.toml").expect("valid");
        assert_eq!(s.events().len(), 3);
        assert!(s.due(1_999_999_999).is_empty());
        let due = s.due(2_000_000_000);
        assert_eq!(due.len(), 1);
        assert!(!due[0].announce);
        assert_eq!(due[0].action.thruster(), "T");
        assert!(s.due(2_000_000_000).is_empty());
        let due = s.due(10_000_000_000).to_vec();
        assert_eq!(due.len(), 2);
        assert!(due[0].announce);
        assert!(matches!(due[1].action, Action::Add { .. }));
        assert_eq!(s.remaining(), 0);
        s.rewind();
        assert_eq!(s.remaining(), 3);
    }

    #[test]
    fn rejects_unknown_fields_and_bad_values() {
        let typo = TEXT.replace("angle_deg", "angel_deg");
        assert!(matches!(
            Scenario::from_toml_str(&typo, "s"),
            Err(LoadError::Parse { .. })
        ));
        let zero = TEXT.replace("axis = [1, 0, 0]", "axis = [0, 0, 0]");
        let err = Scenario::from_toml_str(&zero, "s").unwrap_err().to_string();
        assert!(err.contains("event[1].action.axis"), "{err}");
        let neg = TEXT.replace("t_s = 5.0", "t_s = -1.0");
        assert!(Scenario::from_toml_str(&neg, "s").is_err());
    }
}
