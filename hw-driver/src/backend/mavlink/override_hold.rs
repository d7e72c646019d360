//! How long ArduSub keeps our last RC override after we stop: its `RC_OVERRIDE_TIME`, read
//! with PARAM_REQUEST_READ in `output = "rc_override"` mode (docs/hardware.md).
//!
//! An RC override has no lapse of its own: after a SIGKILL, a watchdog abort or the OOM
//! killer (nothing of ours runs then) the autopilot drives the last pulses until
//! `RC_OVERRIDE_TIME` has passed: 3 s by default, never with -1, and with 0 it ignores
//! overrides altogether. So until the autopilot has said a value in
//! (0, `max_override_hold_s`], only neutral overrides go out and the driver reports its outputs
//! held, with the reason. The value is asked for at each link-up, again every
//! [`RETRY_NS`] until it comes, and every [`REREAD_NS`] after (a parameter changed from the
//! ground station while we run is seen within that). The driver changes no parameter.

use mavlink::dialects::ardupilotmega::{MavMessage, PARAM_REQUEST_READ_DATA, PARAM_VALUE_DATA};

/// ArduSub's parameter (`libraries/RC_Channel/RC_Channels_VarInfo.h`, "_OVERRIDE_TIME").
pub const PARAM: &str = "RC_OVERRIDE_TIME";
/// How often the value is asked for while unknown, ns.
pub const RETRY_NS: u64 = 1_000_000_000;
/// How often a known value is read again, ns.
pub const REREAD_NS: u64 = 10_000_000_000;

/// The autopilot's override hold as far as we know it.
#[derive(Debug, Clone, PartialEq)]
pub struct OverrideHold {
    /// The most a hold may be, s (`max_override_hold_s`).
    max_s: f64,
    /// The autopilot's `RC_OVERRIDE_TIME`, s, once it answered (since the last link-up).
    known_s: Option<f32>,
    /// When the next request goes out; None while there is no link.
    next_request_ns: Option<u64>,
}

impl OverrideHold {
    pub fn new(max_s: f64) -> Self {
        OverrideHold {
            max_s,
            known_s: None,
            next_request_ns: None,
        }
    }

    /// The link came up at `now_ns`: ask at once, and forget what an earlier link said (the
    /// autopilot may have rebooted with other parameters).
    pub fn link_up(&mut self, now_ns: u64) {
        self.known_s = None;
        self.next_request_ns = Some(now_ns);
    }

    /// The link is gone: nothing to ask.
    pub fn link_lost(&mut self) {
        self.known_s = None;
        self.next_request_ns = None;
    }

    /// The next time [`OverrideHold::request`] has a message.
    pub fn next_deadline_ns(&self) -> Option<u64> {
        self.next_request_ns
    }

    /// The PARAM_REQUEST_READ due at `now_ns` for the autopilot `(sys, comp)`, if one is.
    pub fn request(&mut self, now_ns: u64, sys: u8, comp: u8) -> Option<MavMessage> {
        let due = self.next_request_ns.filter(|t| now_ns >= *t)?;
        let period = if self.known_s.is_some() {
            REREAD_NS
        } else {
            RETRY_NS
        };
        self.next_request_ns = Some(due.max(now_ns) + period);
        Some(MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            // -1: by name.
            param_index: -1,
            target_system: sys,
            target_component: comp,
            param_id: PARAM.into(),
        }))
    }

    /// A PARAM_VALUE from the autopilot: taken when it is ours. Returns the value when it
    /// changed what we know (for the log).
    pub fn on_value(&mut self, v: &PARAM_VALUE_DATA) -> Option<f32> {
        let name = v.param_id.to_str().unwrap_or("").trim_end_matches('\0');
        if name != PARAM || self.next_request_ns.is_none() {
            return None;
        }
        let changed = self.known_s != Some(v.param_value);
        self.known_s = Some(v.param_value);
        changed.then_some(v.param_value)
    }

    /// Ok when overrides may carry thrust; else why only neutral ones go out, short enough
    /// for `driver_status`'s text (128 bytes with its prefix).
    pub fn verdict(&self) -> Result<(), String> {
        let max = self.max_s;
        match self.known_s {
            None => Err(format!("waiting for the autopilot's {PARAM}")),
            Some(v) if !v.is_finite() || v < 0.0 => Err(format!(
                "{PARAM} = {v}: our last override would outlive us forever; set it <= {max} s"
            )),
            Some(0.0) => Err(format!(
                "{PARAM} = 0: the autopilot ignores overrides; set it <= {max} s"
            )),
            Some(v) if f64::from(v) > max => Err(format!(
                "{PARAM} = {v} s: our last override would outlive us {v} s; set it <= {max} s"
            )),
            Some(_) => Ok(()),
        }
    }

    /// The autopilot's value, once known.
    pub fn known_s(&self) -> Option<f32> {
        self.known_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::MavParamType;

    fn value(name: &str, v: f32) -> PARAM_VALUE_DATA {
        PARAM_VALUE_DATA {
            param_value: v,
            param_count: 1000,
            param_index: 12,
            param_id: name.into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }
    }

    #[test]
    fn only_a_short_positive_hold_lets_thrust_through() {
        let mut h = OverrideHold::new(1.0);
        assert!(h.verdict().unwrap_err().contains("waiting"));
        h.link_up(0);
        for (v, ok, says) in [
            (0.5, true, ""),
            (1.0, true, ""),
            (3.0, false, "outlive us 3 s"),
            (-1.0, false, "forever"),
            (0.0, false, "ignores overrides"),
            (f32::NAN, false, "forever"),
        ] {
            h.on_value(&value(PARAM, v));
            let verdict = h.verdict();
            assert_eq!(verdict.is_ok(), ok, "{v}: {verdict:?}");
            if let Err(why) = verdict {
                assert!(why.contains(says), "{v}: {why}");
                assert!(why.ends_with("set it <= 1 s"), "{v}: {why}");
                assert!(why.len() <= 100, "{v}: {} bytes", why.len());
            }
        }
        // Another parameter's value changes nothing; a lost link forgets and stops asking.
        h.on_value(&value(PARAM, 0.5));
        assert_eq!(h.on_value(&value("RC_OVERRIDE_TIMF", 9.0)), None);
        assert!(h.verdict().is_ok());
        h.link_lost();
        assert!(h.verdict().is_err());
        assert_eq!(h.next_deadline_ns(), None);
        assert_eq!(h.on_value(&value(PARAM, 0.5)), None, "taken without a link");
    }

    #[test]
    fn asked_at_link_up_every_second_until_known_then_every_ten() {
        let mut h = OverrideHold::new(1.0);
        assert!(h.request(0, 1, 1).is_none(), "asked without a link");
        h.link_up(5);
        let Some(MavMessage::PARAM_REQUEST_READ(r)) = h.request(5, 1, 2) else {
            panic!("no request at link-up");
        };
        assert_eq!(
            (r.param_index, r.target_system, r.target_component),
            (-1, 1, 2)
        );
        assert_eq!(r.param_id.to_str().unwrap().trim_end_matches('\0'), PARAM);
        assert!(h.request(5 + RETRY_NS - 1, 1, 2).is_none());
        assert!(h.request(5 + RETRY_NS, 1, 2).is_some());
        assert_eq!(h.on_value(&value(PARAM, 0.5)), Some(0.5));
        assert_eq!(h.on_value(&value(PARAM, 0.5)), None, "unchanged");
        assert!(h.request(5 + 2 * RETRY_NS, 1, 2).is_some(), "the one due");
        assert_eq!(h.next_deadline_ns(), Some(5 + 2 * RETRY_NS + REREAD_NS));
    }
}
