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
//! The values are read by a [`ParamReader`]: at each link-up, every second until all three
//! came, every 10 s after. The driver changes no parameter.

use mavlink::dialects::ardupilotmega::{MavMessage, PARAM_VALUE_DATA};

use super::params::ParamReader;

/// ArduSub's pilot-input failsafe action (0 disabled, 1 warn, 2 disarm; ArduSub/Parameters.cpp).
pub const FS_PILOT_INPUT: &str = "FS_PILOT_INPUT";
/// Its timeout, s (0.1-3, default 3).
pub const FS_PILOT_TIMEOUT: &str = "FS_PILOT_TIMEOUT";
/// How long an override is used (0 disables overrides, -1 never times out; RC_Channels_VarInfo.h).
pub const RC_OVERRIDE_TIME: &str = "RC_OVERRIDE_TIME";
/// The parameters read, in this order.
pub const PARAMS: [&str; 3] = [FS_PILOT_INPUT, FS_PILOT_TIMEOUT, RC_OVERRIDE_TIME];

/// The autopilot's settings that bound our last override, as far as we know them.
#[derive(Debug, Clone, PartialEq)]
pub struct OverrideHold {
    /// The longest `FS_PILOT_TIMEOUT` accepted, s (`max_override_hold_s`).
    max_s: f64,
    params: ParamReader<3>,
}

impl OverrideHold {
    pub fn new(max_s: f64) -> Self {
        OverrideHold {
            max_s,
            params: ParamReader::new(PARAMS),
        }
    }

    /// The link came up at `now_ns`: ask at once, forget what an earlier link said.
    pub fn link_up(&mut self, now_ns: u64) {
        self.params.link_up(now_ns);
    }

    /// The link is gone: nothing to ask.
    pub fn link_lost(&mut self) {
        self.params.link_lost();
    }

    /// The next time [`OverrideHold::requests`] has messages.
    pub fn next_deadline_ns(&self) -> Option<u64> {
        self.params.next_deadline_ns()
    }

    /// The PARAM_REQUEST_READs due at `now_ns` for the autopilot `(sys, comp)`.
    pub fn requests(&mut self, now_ns: u64, sys: u8, comp: u8, out: &mut Vec<MavMessage>) {
        self.params.requests(now_ns, sys, comp, out);
    }

    /// A PARAM_VALUE from the autopilot: the name and value when it changed what we know.
    pub fn on_value(&mut self, v: &PARAM_VALUE_DATA) -> Option<(&'static str, f32)> {
        self.params.on_value(v)
    }

    /// Ok when overrides may carry thrust; else why only neutral ones go out, short enough
    /// for `driver_status`'s text (128 bytes with its prefix).
    pub fn verdict(&self) -> Result<(), String> {
        let max = self.max_s;
        let [Some(input), Some(timeout), Some(override_s)] = self.params.known() else {
            let missing = self.params.first_missing().unwrap_or("");
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
    use crate::backend::mavlink::params::tests::{asked, value};
    use crate::backend::mavlink::params::{REREAD_NS, RETRY_NS};

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
    fn its_three_parameters_are_asked_for_at_link_up() {
        let mut h = OverrideHold::new(1.0);
        let mut out = Vec::new();
        h.requests(0, 1, 1, &mut out);
        assert!(out.is_empty(), "asked without a link");
        h.link_up(5);
        h.requests(5, 1, 2, &mut out);
        assert_eq!(asked(&out, 1, 2), PARAMS);
        assert_eq!(h.next_deadline_ns(), Some(5 + RETRY_NS));
        for (name, v) in [
            (FS_PILOT_INPUT, 2.0),
            (FS_PILOT_TIMEOUT, 0.5),
            (RC_OVERRIDE_TIME, 3.0),
        ] {
            h.on_value(&value(name, v));
        }
        out.clear();
        h.requests(5 + RETRY_NS, 1, 2, &mut out);
        assert_eq!(h.next_deadline_ns(), Some(5 + RETRY_NS + REREAD_NS));
    }
}
