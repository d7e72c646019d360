//! Reading a fixed set of the autopilot's parameters by name, without IO.
//!
//! The driver changes no parameter; it reads the few whose values decide whether what it
//! sends or receives is safe to use (the pilot-input failsafe for RC overrides, the
//! barometers' device ids for depth). Each reader asks for its names (PARAM_REQUEST_READ by
//! name) at every link-up, every [`RETRY_NS`] until all have come (at most [`RETRIES`]
//! times: an autopilot without one of them, a board with one barometer say, answers nothing
//! for it), then every [`REREAD_NS`] (a parameter changed from a ground station while we run
//! is seen within that), and forgets them when the link goes (the autopilot may have rebooted
//! with other values).

use mavlink::dialects::ardupilotmega::{MavMessage, PARAM_REQUEST_READ_DATA, PARAM_VALUE_DATA};

/// How often the values are asked for while one is unknown, ns.
pub const RETRY_NS: u64 = 1_000_000_000;
/// How often known values are read again, ns.
pub const REREAD_NS: u64 = 10_000_000_000;
/// Rounds asked every [`RETRY_NS`] while a value is missing, before the reader falls back to
/// [`REREAD_NS`].
pub const RETRIES: u32 = 5;

/// The values of `N` named parameters, as far as the autopilot has told them since the link
/// came up.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamReader<const N: usize> {
    names: [&'static str; N],
    known: [Option<f32>; N],
    /// When the next requests go out; None while there is no link.
    next_request_ns: Option<u64>,
    /// Rounds asked since the link came up.
    rounds: u32,
}

impl<const N: usize> ParamReader<N> {
    pub fn new(names: [&'static str; N]) -> Self {
        ParamReader {
            names,
            known: [None; N],
            next_request_ns: None,
            rounds: 0,
        }
    }

    /// The link came up at `now_ns`: ask at once, and forget what an earlier link said.
    pub fn link_up(&mut self, now_ns: u64) {
        self.known = [None; N];
        self.next_request_ns = Some(now_ns);
        self.rounds = 0;
    }

    /// The link is gone: nothing to ask, nothing known.
    pub fn link_lost(&mut self) {
        self.known = [None; N];
        self.next_request_ns = None;
    }

    /// The next time [`ParamReader::requests`] has messages.
    pub fn next_deadline_ns(&self) -> Option<u64> {
        self.next_request_ns
    }

    /// The PARAM_REQUEST_READs due at `now_ns` for the autopilot `(sys, comp)`: one per
    /// name, or none.
    pub fn requests(&mut self, now_ns: u64, sys: u8, comp: u8, out: &mut Vec<MavMessage>) {
        let Some(due) = self.next_request_ns.filter(|t| now_ns >= *t) else {
            return;
        };
        self.rounds += 1;
        let period = if self.all_known() || self.rounds >= RETRIES {
            REREAD_NS
        } else {
            RETRY_NS
        };
        self.next_request_ns = Some(due.max(now_ns) + period);
        out.extend(self.names.iter().map(|name| {
            MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                // -1: by name.
                param_index: -1,
                target_system: sys,
                target_component: comp,
                param_id: (*name).into(),
            })
        }));
    }

    /// A PARAM_VALUE from the autopilot: taken when it is one of ours and a link is up.
    /// Returns the name and value when it changed what we know (for the log).
    pub fn on_value(&mut self, v: &PARAM_VALUE_DATA) -> Option<(&'static str, f32)> {
        // Without a link nothing was asked for.
        self.next_request_ns?;
        let name = v.param_id.to_str().unwrap_or("").trim_end_matches('\0');
        let i = self.names.iter().position(|p| *p == name)?;
        let changed = self.known[i] != Some(v.param_value);
        self.known[i] = Some(v.param_value);
        changed.then_some((self.names[i], v.param_value))
    }

    /// The values in the order of the names.
    pub fn known(&self) -> [Option<f32>; N] {
        self.known
    }

    /// Every value has come.
    pub fn all_known(&self) -> bool {
        self.known.iter().all(Option::is_some)
    }

    /// The first name without a value, if any.
    pub fn first_missing(&self) -> Option<&'static str> {
        self.names
            .iter()
            .zip(self.known)
            .find(|(_, v)| v.is_none())
            .map(|(n, _)| *n)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::MavParamType;

    /// A PARAM_VALUE as ArduPilot sends it (every value as a float).
    pub fn value(name: &str, v: f32) -> PARAM_VALUE_DATA {
        PARAM_VALUE_DATA {
            param_value: v,
            param_count: 1000,
            param_index: 12,
            param_id: name.into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }
    }

    /// The names asked for in `out`, checking every request is by name to `(sys, comp)`.
    pub fn asked(out: &[MavMessage], sys: u8, comp: u8) -> Vec<String> {
        out.iter()
            .map(|m| match m {
                MavMessage::PARAM_REQUEST_READ(r) => {
                    assert_eq!(
                        (r.param_index, r.target_system, r.target_component),
                        (-1, sys, comp)
                    );
                    r.param_id
                        .to_str()
                        .unwrap()
                        .trim_end_matches('\0')
                        .to_string()
                }
                other => panic!("{other:?}"),
            })
            .collect()
    }

    #[test]
    fn asked_at_link_up_every_second_until_known_then_every_ten() {
        let mut r = ParamReader::new(["A", "B"]);
        let mut out = Vec::new();
        r.requests(0, 1, 1, &mut out);
        assert!(out.is_empty(), "asked without a link");
        assert_eq!(r.on_value(&value("A", 1.0)), None, "taken without a link");
        r.link_up(5);
        r.requests(5, 1, 2, &mut out);
        assert_eq!(asked(&out, 1, 2), ["A", "B"]);
        out.clear();
        r.requests(5 + RETRY_NS - 1, 1, 2, &mut out);
        assert!(out.is_empty());
        r.requests(5 + RETRY_NS, 1, 2, &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(r.first_missing(), Some("A"));
        assert_eq!(r.on_value(&value("A", 2.0)), Some(("A", 2.0)));
        assert_eq!(r.on_value(&value("A", 2.0)), None, "unchanged");
        assert_eq!(r.on_value(&value("C", 2.0)), None, "not ours");
        assert_eq!(r.first_missing(), Some("B"));
        r.on_value(&value("B", 0.5));
        assert!(r.all_known());
        assert_eq!(r.known(), [Some(2.0), Some(0.5)]);
        out.clear();
        r.requests(5 + 2 * RETRY_NS, 1, 2, &mut out);
        assert_eq!(out.len(), 2, "the ones due");
        assert_eq!(r.next_deadline_ns(), Some(5 + 2 * RETRY_NS + REREAD_NS));
        r.link_lost();
        assert_eq!(r.known(), [None, None]);
        assert_eq!(r.next_deadline_ns(), None);
        // A name the autopilot never answers: asked every second RETRIES times, then with
        // the re-reads.
        r.link_up(0);
        r.on_value(&value("A", 1.0));
        let mut t = 0;
        for round in 1..=RETRIES {
            out.clear();
            r.requests(t, 1, 2, &mut out);
            assert_eq!(out.len(), 2, "round {round}");
            t = r.next_deadline_ns().unwrap();
        }
        assert_eq!(t, (u64::from(RETRIES) - 1) * RETRY_NS + REREAD_NS);
    }
}
