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
//! (with a full `spec`, as a `[[thruster]]` of a vehicle file), `kill` (dead, no thrust),
//! `weaken` (thrust times `factor`), and `degrade` (thrust falls linearly to `to` of what it
//! was over `over_s`: a fouled propeller or a tired motor; never announced, expanded into
//! `weaken` steps every [`DEGRADE_STEP_S`]):
//!
//! ```toml
//! [[event]]
//! t_s = 30.0
//! announce = false
//! action = { kind = "degrade", thruster = "L", to = 0.7, over_s = 60 }
//! ```
//! This module only schedules: [`Scenario::due`] hands out the events whose time has come, the
//! simulator applies them ([`crate::Simulator::apply`]) and the driver publishes announced ones.

use std::path::Path;

use serde::{Deserialize, Serialize};

use thruster_protocol::validate::limits::MAX_POSITION_M;

use crate::load::{parse_toml, read_text, symmetric, Checker, LoadError, Range};
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
    /// Forward and reverse thrust multiplied by `factor`, in (0, 10]; the thrust that results
    /// must still be valid for the vehicle (checked when applied, and by the driver's dry run
    /// before it starts).
    Weaken { thruster: String, factor: f64 },
    /// Thrust falls linearly to `to` (0 < to <= 1) times its value at `t_s`, reached `over_s`
    /// later. [`Scenario::new`] turns it into `weaken` steps; it must not be announced.
    Degrade {
        thruster: String,
        to: f64,
        over_s: f64,
    },
}

/// Latest event time, s (about 30 years of vehicle time).
pub const MAX_EVENT_T_S: f64 = 1e9;

/// Time between the `weaken` steps of a `degrade`, s: 10 steps a second is smooth for a
/// controller and an estimator working over seconds.
pub const DEGRADE_STEP_S: f64 = 0.1;

impl Action {
    /// Name of the thruster the action concerns.
    pub fn thruster(&self) -> &str {
        match self {
            Action::Rotate { thruster, .. }
            | Action::SetDirection { thruster, .. }
            | Action::Move { thruster, .. }
            | Action::Remove { thruster }
            | Action::Kill { thruster }
            | Action::Weaken { thruster, .. }
            | Action::Degrade { thruster, .. } => thruster,
            Action::Add { spec } => &spec.name,
        }
    }

    /// Checks the action on its own (whether it applies to the vehicle is the dry run's
    /// question: `Simulator::apply` on a copy), locating a bad value in `c.text` by `key`.
    fn check(&mut self, c: &Checker, key: &str) -> Result<(), LoadError> {
        let key = |k: &str| format!("{key}.{k}");
        let nonzero = |k: &str, v: &[f64; 3]| {
            c.each(&key(k), v, symmetric(1e6))?;
            if v.iter().map(|a| a * a).sum::<f64>() < 1e-12 {
                return Err(c.error(&key(k), &key(k), "must not be zero"));
            }
            Ok(())
        };
        match self {
            Action::Rotate {
                axis, angle_deg, ..
            } => {
                nonzero("axis", axis)?;
                c.range(&key("angle_deg"), *angle_deg, symmetric(360.0))?;
            }
            Action::SetDirection { direction, .. } => nonzero("direction", direction)?,
            Action::Move { position_m, .. } => {
                c.each(&key("position_m"), position_m, symmetric(MAX_POSITION_M))?;
            }
            Action::Add { spec } => spec.check(c, &key("spec"))?,
            Action::Remove { .. } | Action::Kill { .. } => {}
            Action::Weaken { factor, .. } => {
                // At most ten times stronger (a weakened thruster restored, and more); the
                // thrust that results is checked against the vehicle when applied.
                c.range(&key("factor"), *factor, Range::above_to(0.0, 10.0))?;
            }
            Action::Degrade { to, over_s, .. } => {
                c.range(&key("to"), *to, Range::above_to(0.0, 1.0))?;
                c.range(&key("over_s"), *over_s, Range::above_to(0.0, 86_400.0))?;
            }
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
    /// Simulation time, s, in [0, 1e9].
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

/// A `degrade` as its `weaken` steps (each the ratio of two successive points of the linear
/// ramp, so their product follows it); any other event as itself.
fn expand(e: Event) -> Vec<Event> {
    let Action::Degrade {
        thruster,
        to,
        over_s,
    } = &e.action
    else {
        return vec![e];
    };
    let steps = (over_s / DEGRADE_STEP_S).ceil().max(1.0) as usize;
    let level = |k: usize| 1.0 - (1.0 - to) * k as f64 / steps as f64;
    (1..=steps)
        .map(|k| Event {
            t_s: e.t_s + over_s * k as f64 / steps as f64,
            announce: false,
            action: Action::Weaken {
                thruster: thruster.clone(),
                factor: level(k) / level(k - 1),
            },
        })
        .collect()
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
    pub fn new(events: Vec<Event>, origin: &str) -> Result<Self, LoadError> {
        Scenario::checked(events, &Checker::new(origin, ""))
    }

    /// As [`Scenario::new`], locating a bad value in `c.text` (keys `event[i]` in file order).
    fn checked(mut events: Vec<Event>, c: &Checker) -> Result<Self, LoadError> {
        for (i, e) in events.iter_mut().enumerate() {
            let key = format!("event[{i}]");
            c.range(
                &format!("{key}.t_s"),
                e.t_s,
                Range::closed(0.0, MAX_EVENT_T_S),
            )?;
            e.action.check(c, &format!("{key}.action"))?;
            if e.announce && matches!(e.action, Action::Degrade { .. }) {
                let key = format!("{key}.announce");
                return Err(c.error(
                    &key,
                    &key,
                    "a degrade is gradual and never announced: set announce = false",
                ));
            }
        }
        let mut events: Vec<Event> = events.into_iter().flat_map(expand).collect();
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
        Scenario::checked(file.events, &Checker::new(origin, text))
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
    fn a_degrade_is_a_linear_ramp_of_silent_weaken_steps() {
        let text = r#"
[[event]]
t_s = 10.0
announce = false
action = { kind = "degrade", thruster = "L", to = 0.7, over_s = 60 }
"#;
        let s = Scenario::from_toml_str(text, "d.toml").expect("valid");
        assert_eq!(s.events().len(), 600);
        let mut strength = 1.0;
        for (k, e) in s.events().iter().enumerate() {
            let Action::Weaken { thruster, factor } = &e.action else {
                panic!("{e:?}")
            };
            assert_eq!(thruster, "L");
            assert!(!e.announce);
            strength *= factor;
            // Linear in time: 1 at t = 10 s, 0.7 at t = 70 s.
            let expected = 1.0 - 0.3 * (e.t_s - 10.0) / 60.0;
            assert!((strength - expected).abs() < 1e-12, "step {k}: {strength}");
        }
        assert!((s.events()[599].t_s - 70.0).abs() < 1e-9);
        // Announced, or a level outside (0, 1]: refused, naming the key.
        let loud = text.replace("announce = false\n", "");
        let err = Scenario::from_toml_str(&loud, "d").unwrap_err().to_string();
        assert!(err.contains("event[0].announce"), "{err}");
        let err = Scenario::from_toml_str(&text.replace("0.7", "1.5"), "d")
            .unwrap_err()
            .to_string();
        assert!(err.contains("event[0].action.to"), "{err}");
    }

    #[test]
    fn absurd_values_name_file_line_key_and_range() {
        let err = |text: &str| {
            Scenario::from_toml_str(text, "s.toml")
                .unwrap_err()
                .to_string()
        };
        let event = |action: &str| format!("[[event]]\nt_s = 1.0\naction = {{ {action} }}\n");
        assert_eq!(
            err(&event(
                "kind = \"weaken\", thruster = \"T\", factor = 1e300"
            )),
            "s.toml:3:54: event[0].action.factor: must be in (0, 10], got 1e300"
        );
        assert_eq!(
            err(&event(
                "kind = \"move\", thruster = \"T\", position_m = [0, 1e9, 0]"
            )),
            "s.toml:3:60: event[0].action.position_m[1]: must be in [-10, 10], got 1000000000"
        );
        assert_eq!(
            err(&event(
                "kind = \"add\", spec = { name = \"X\", position_m = [0, 0, 0], \
                 direction = [0, 1, 0], forward_max_n = 1e300 }"
            )),
            "s.toml:3:110: event[0].action.spec (\"X\").forward_max_n: must be in (0, 10000], \
             got 1e300"
        );
        assert_eq!(
            err("[[event]]\nt_s = inf\naction = { kind = \"kill\", thruster = \"T\" }\n"),
            "s.toml:2:7: event[0].t_s: must be in [0, 1000000000], got inf"
        );
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
