//! What ends our last RC override after we stop, read from the autopilot in
//! `output = "rc_override"` mode (docs/hardware.md, "RC override mode").
//!
//! An RC override has no lapse of its own that helps: once `RC_OVERRIDE_TIME` has passed,
//! ArduSub on a vehicle without an RC receiver leaves the channel's input at the last override
//! (`RC_Channel::update` rewrites `radio_in` only from an override or a receiver), and an
//! `RCINn` passthrough output keeps driving it. What takes the channels back to neutral after
//! a SIGKILL, a watchdog abort or the OOM killer (nothing of ours runs then) is ArduSub's
//! pilot-input failsafe: after `FS_PILOT_TIMEOUT` s without pilot input (our overrides count
//! as input), with `FS_PILOT_INPUT` not 0, it sets the six RCMAP channels (1-6 by default) to
//! neutral (`set_neutral_controls`, ArduSub/failsafe.cpp) and, with 2 (the default), disarms.
//! So thrust goes out only once the autopilot has said `FS_PILOT_INPUT` != 0,
//! `FS_PILOT_TIMEOUT` <= `max_override_hold_s`, and `RC_OVERRIDE_TIME` != 0 (0 makes ArduSub
//! ignore overrides); until then only neutral overrides go out and the driver reports its
//! outputs held, with the reason. The config keeps thrusters to channels 1-6.
//!
//! The values are asked for (PARAM_REQUEST_READ by name) at each link-up, every [`RETRY_NS`]
//! until all three came, every [`REREAD_NS`] after (a parameter changed from the ground
//! station while we run is seen within that). The driver changes no parameter.

use mavlink::dialects::ardupilotmega::{MavMessage, PARAM_REQUEST_READ_DATA, PARAM_VALUE_DATA};

/// ArduSub's pilot-input failsafe action (0 disabled, 1 warn, 2 disarm; ArduSub/Parameters.cpp).
pub const FS_PILOT_INPUT: &str = "FS_PILOT_INPUT";
/// Its timeout, s (0.1-3, default 3).
pub const FS_PILOT_TIMEOUT: &str = "FS_PILOT_TIMEOUT";
/// How long an override is used (0 disables overrides, -1 never times out; RC_Channels_VarInfo.h).
pub const RC_OVERRIDE_TIME: &str = "RC_OVERRIDE_TIME";
/// The parameters read, in this order.
pub const PARAMS: [&str; 3] = [FS_PILOT_INPUT, FS_PILOT_TIMEOUT, RC_OVERRIDE_TIME];
/// How often the values are asked for while one is unknown, ns.
pub const RETRY_NS: u64 = 1_000_000_000;
/// How often known values are read again, ns.
pub const REREAD_NS: u64 = 10_000_000_000;

/// The autopilot's settings that bound our last override, as far as we know them.
#[derive(Debug, Clone, PartialEq)]
pub struct OverrideHold {
    /// The longest `FS_PILOT_TIMEOUT` accepted, s (`max_override_hold_s`).
    max_s: f64,
    /// The values of [`PARAMS`] since the last link-up.
    known: [Option<f32>; 3],
    /// When the next requests go out; None while there is no link.
    next_request_ns: Option<u64>,
}

impl OverrideHold {
    pub fn new(max_s: f64) -> Self {
        OverrideHold {
            max_s,
            known: [None; 3],
            next_request_ns: None,
        }
    }

    /// The link came up at `now_ns`: ask at once, and forget what an earlier link said (the
    /// autopilot may have rebooted with other parameters).
    pub fn link_up(&mut self, now_ns: u64) {
        self.known = [None; 3];
        self.next_request_ns = Some(now_ns);
    }

    /// The link is gone: nothing to ask.
    pub fn link_lost(&mut self) {
        self.known = [None; 3];
        self.next_request_ns = None;
    }

    /// The next time [`OverrideHold::requests`] has messages.
    pub fn next_deadline_ns(&self) -> Option<u64> {
        self.next_request_ns
    }

    /// The PARAM_REQUEST_READs due at `now_ns` for the autopilot `(sys, comp)`: one per
    /// parameter, or none.
    pub fn requests(&mut self, now_ns: u64, sys: u8, comp: u8, out: &mut Vec<MavMessage>) {
        let Some(due) = self.next_request_ns.filter(|t| now_ns >= *t) else {
            return;
        };
        let period = if self.known.iter().all(Option::is_some) {
            REREAD_NS
        } else {
            RETRY_NS
        };
        self.next_request_ns = Some(due.max(now_ns) + period);
        out.extend(PARAMS.iter().map(|name| {
            MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                // -1: by name.
                param_index: -1,
                target_system: sys,
                target_component: comp,
                param_id: (*name).into(),
            })
        }));
    }

    /// A PARAM_VALUE from the autopilot: taken when it is one of ours. Returns the name and
    /// value when it changed what we know (for the log).
    pub fn on_value(&mut self, v: &PARAM_VALUE_DATA) -> Option<(&'static str, f32)> {
        // Without a link nothing was asked for.
        self.next_request_ns?;
        let name = v.param_id.to_str().unwrap_or("").trim_end_matches('\0');
        let i = PARAMS.iter().position(|p| *p == name)?;
        let changed = self.known[i] != Some(v.param_value);
        self.known[i] = Some(v.param_value);
        changed.then_some((PARAMS[i], v.param_value))
    }

    /// Ok when overrides may carry thrust; else why only neutral ones go out, short enough
    /// for `driver_status`'s text (128 bytes with its prefix).
    pub fn verdict(&self) -> Result<(), String> {
        let max = self.max_s;
        let [Some(input), Some(timeout), Some(override_s)] = self.known else {
            let missing = PARAMS
                .iter()
                .zip(self.known)
                .find(|(_, v)| v.is_none())
                .map_or("", |(n, _)| *n);
            return Err(format!("waiting for the autopilot's {missing}"));
        };
        if !input.is_finite() || input == 0.0 {
            return Err(format!(
                "{FS_PILOT_INPUT} = {input}: nothing neutralises our last override; set it to 2"
            ));
        }
        if !timeout.is_finite() || f64::from(timeout) > max {
            return Err(format!(
                "{FS_PILOT_TIMEOUT} = {timeout} s: our last override would outlive us \
                 {timeout} s; set it <= {max} s"
            ));
        }
        if override_s == 0.0 {
            return Err(format!(
                "{RC_OVERRIDE_TIME} = 0: the autopilot ignores overrides"
            ));
        }
        Ok(())
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

    fn with(input: f32, timeout: f32, override_s: f32) -> OverrideHold {
        let mut h = OverrideHold::new(1.0);
        h.link_up(0);
        h.on_value(&value(FS_PILOT_INPUT, input));
        h.on_value(&value(FS_PILOT_TIMEOUT, timeout));
        h.on_value(&value(RC_OVERRIDE_TIME, override_s));
        h
    }

    #[test]
    fn thrust_only_with_the_failsafe_on_and_short_and_overrides_taken() {
        let mut h = OverrideHold::new(1.0);
        assert!(h.verdict().unwrap_err().contains("waiting"));
        h.link_up(0);
        h.on_value(&value(FS_PILOT_INPUT, 2.0));
        assert_eq!(
            h.verdict().unwrap_err(),
            "waiting for the autopilot's FS_PILOT_TIMEOUT"
        );
        for (input, timeout, override_s, ok, says) in [
            (2.0, 0.5, 3.0, true, ""),
            (1.0, 1.0, -1.0, true, ""),
            // ArduSub's defaults: the failsafe after 3 s.
            (
                2.0,
                3.0,
                3.0,
                false,
                "FS_PILOT_TIMEOUT = 3 s: our last override would outlive us 3 s; set it <= 1 s",
            ),
            (
                0.0,
                0.5,
                3.0,
                false,
                "FS_PILOT_INPUT = 0: nothing neutralises",
            ),
            (
                2.0,
                0.5,
                0.0,
                false,
                "RC_OVERRIDE_TIME = 0: the autopilot ignores overrides",
            ),
            (2.0, f32::NAN, 3.0, false, "FS_PILOT_TIMEOUT = NaN"),
        ] {
            let verdict = with(input, timeout, override_s).verdict();
            assert_eq!(
                verdict.is_ok(),
                ok,
                "{input} {timeout} {override_s}: {verdict:?}"
            );
            if let Err(why) = verdict {
                assert!(why.starts_with(says), "{why}");
                assert!(why.len() <= 100, "{} bytes: {why}", why.len());
            }
        }
        // Another parameter's value changes nothing; a lost link forgets and stops asking.
        let mut h = with(2.0, 0.5, 3.0);
        assert_eq!(h.on_value(&value("FS_PILOT_TIMEOUX", 9.0)), None);
        assert!(h.verdict().is_ok());
        h.link_lost();
        assert!(h.verdict().is_err());
        assert_eq!(h.next_deadline_ns(), None);
        assert_eq!(
            h.on_value(&value(FS_PILOT_INPUT, 2.0)),
            None,
            "taken without a link"
        );
    }

    #[test]
    fn asked_at_link_up_every_second_until_known_then_every_ten() {
        let mut h = OverrideHold::new(1.0);
        let mut out = Vec::new();
        h.requests(0, 1, 1, &mut out);
        assert!(out.is_empty(), "asked without a link");
        h.link_up(5);
        h.requests(5, 1, 2, &mut out);
        let names: Vec<String> = out
            .iter()
            .map(|m| match m {
                MavMessage::PARAM_REQUEST_READ(r) => {
                    assert_eq!(
                        (r.param_index, r.target_system, r.target_component),
                        (-1, 1, 2)
                    );
                    r.param_id
                        .to_str()
                        .unwrap()
                        .trim_end_matches('\0')
                        .to_string()
                }
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(names, PARAMS);
        out.clear();
        h.requests(5 + RETRY_NS - 1, 1, 2, &mut out);
        assert!(out.is_empty());
        h.requests(5 + RETRY_NS, 1, 2, &mut out);
        assert_eq!(out.len(), 3);
        assert_eq!(
            h.on_value(&value(FS_PILOT_INPUT, 2.0)),
            Some((FS_PILOT_INPUT, 2.0))
        );
        assert_eq!(h.on_value(&value(FS_PILOT_INPUT, 2.0)), None, "unchanged");
        h.on_value(&value(FS_PILOT_TIMEOUT, 0.5));
        h.on_value(&value(RC_OVERRIDE_TIME, 3.0));
        out.clear();
        h.requests(5 + 2 * RETRY_NS, 1, 2, &mut out);
        assert_eq!(out.len(), 3, "the ones due");
        assert_eq!(h.next_deadline_ns(), Some(5 + 2 * RETRY_NS + REREAD_NS));
    }
}
