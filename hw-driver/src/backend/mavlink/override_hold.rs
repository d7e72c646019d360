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
//! neutral (`set_neutral_controls`, ArduSub/joystick.cpp) and, with 2 (the default), disarms.
//! "Neutral" there is each channel's own trim (`set_radio_in(get_radio_trim())`), and "the six
//! channels" are the ones `RCMAP_ROLL`, `_PITCH`, `_THROTTLE`, `_YAW`, `_FORWARD` and
//! `_LATERAL` name (ArduSub's defaults 2, 1, 3, 4, 5, 6). So thrust goes out only once the
//! autopilot has said `FS_PILOT_INPUT` != 0, `FS_PILOT_TIMEOUT` <= `max_override_hold_s`,
//! `RC_OVERRIDE_TIME` != 0 (0 makes ArduSub ignore overrides), that every thruster's channel is
//! an RCMAP channel, and that its `RCn_TRIM` is the thruster's neutral. And the overrides must
//! reach the ESCs as they are: some output's `SERVOm_FUNCTION` must be RCINn passthrough (51 +
//! n - 1) for each thruster's channel n, and no output may be a motor (33-40, 82-85, 160-179):
//! ArduSub's mixer would take our overrides on channels 1-6, the RCMAP channels, as pilot sticks
//! and drive its motors from them. Until all of that is known to hold only neutral overrides
//! go out and the driver reports its outputs held, with the reason. The config keeps thrusters
//! to channels 1-6.
//!
//! The values are read by a [`ParamReader`]: at each link-up, every second until all came,
//! every 10 s after. The driver changes no parameter.

use super::params::ParamReader;
use crate::backend::OutputSpec;

/// ArduSub's pilot-input failsafe action (0 disabled, 1 warn, 2 disarm; ArduSub/Parameters.cpp).
pub const FS_PILOT_INPUT: &str = "FS_PILOT_INPUT";
/// Its timeout, s (0.1-3, default 3).
pub const FS_PILOT_TIMEOUT: &str = "FS_PILOT_TIMEOUT";
/// How long an override is used (0 disables overrides, -1 never times out; RC_Channels_VarInfo.h).
pub const RC_OVERRIDE_TIME: &str = "RC_OVERRIDE_TIME";
/// The parameters read, in this order: the failsafe, the six RCMAP channels, the trims of
/// channels 1-6, the functions of outputs 1-16.
pub const PARAMS: [&str; 31] = [
    FS_PILOT_INPUT,
    FS_PILOT_TIMEOUT,
    RC_OVERRIDE_TIME,
    "RCMAP_ROLL",
    "RCMAP_PITCH",
    "RCMAP_THROTTLE",
    "RCMAP_YAW",
    "RCMAP_FORWARD",
    "RCMAP_LATERAL",
    "RC1_TRIM",
    "RC2_TRIM",
    "RC3_TRIM",
    "RC4_TRIM",
    "RC5_TRIM",
    "RC6_TRIM",
    "SERVO1_FUNCTION",
    "SERVO2_FUNCTION",
    "SERVO3_FUNCTION",
    "SERVO4_FUNCTION",
    "SERVO5_FUNCTION",
    "SERVO6_FUNCTION",
    "SERVO7_FUNCTION",
    "SERVO8_FUNCTION",
    "SERVO9_FUNCTION",
    "SERVO10_FUNCTION",
    "SERVO11_FUNCTION",
    "SERVO12_FUNCTION",
    "SERVO13_FUNCTION",
    "SERVO14_FUNCTION",
    "SERVO15_FUNCTION",
    "SERVO16_FUNCTION",
];
const RCMAP: std::ops::Range<usize> = 3..9;
const TRIMS: std::ops::Range<usize> = 9..15;
const FUNCTIONS: std::ops::Range<usize> = 15..31;

/// `SRV_Channel::k_rcin1`: output function "RC input 1 passed through"; RCINn is this + n - 1.
pub const RCIN1: f32 = 51.0;

/// Whether an output function is one of ArduPilot's motors (`k_motor1..8` 33-40, `k_motor9..12`
/// 82-85, `k_motor13..32` 160-179).
fn is_motor(function: f32) -> bool {
    [33.0..=40.0, 82.0..=85.0, 160.0..=179.0]
        .iter()
        .any(|r| r.contains(&function))
}

/// How far a channel's trim (where the failsafe leaves it) may be from the thruster's neutral,
/// us: well inside an ESC's dead band (+-25 us on a Blue Robotics ESC).
pub const TRIM_TOLERANCE_US: f32 = 10.0;

/// The autopilot's settings that bound our last override, as far as we know them.
#[derive(Debug, Clone, PartialEq)]
pub struct OverrideHold {
    /// The longest `FS_PILOT_TIMEOUT` accepted, s (`max_override_hold_s`).
    max_s: f64,
    /// Our thrusters' channels and neutrals.
    outputs: Vec<OutputSpec>,
    /// The autopilot parameters this judges, read at each link-up ([`ParamReader`]).
    pub params: ParamReader<31>,
}

impl OverrideHold {
    pub fn new(max_s: f64, outputs: Vec<OutputSpec>) -> Self {
        OverrideHold {
            max_s,
            outputs,
            params: ParamReader::new(PARAMS),
        }
    }
    /// Ok when overrides may carry thrust; else why only neutral ones go out, short enough
    /// for `driver_status`'s text (128 bytes with its prefix).
    pub fn verdict(&self) -> Result<(), String> {
        let max = self.max_s;
        let known = self.params.known();
        let waiting = || {
            let missing = self.params.first_missing().unwrap_or("");
            Err(format!("waiting for the autopilot's {missing}"))
        };
        let (Some(input), Some(timeout), Some(override_s)) = (known[0], known[1], known[2]) else {
            return waiting();
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
        if !self.params.all_known() {
            return waiting();
        }
        let mapped: [f32; 6] = std::array::from_fn(|k| known[RCMAP.start + k].unwrap_or(0.0));
        for o in &self.outputs {
            let ch = o.channel as f32;
            if !mapped.contains(&ch) {
                return Err(format!(
                    "channel {ch} is not an RCMAP channel ({mapped:?}): the failsafe leaves it"
                ));
            }
            let trim = (o.channel as usize)
                .checked_sub(1)
                .and_then(|i| known.get(TRIMS.start + i).copied().flatten())
                .unwrap_or(f32::NAN);
            let neutral = f32::from(o.neutral.us());
            if trim.is_nan() || (trim - neutral).abs() > TRIM_TOLERANCE_US {
                return Err(format!(
                    "RC{ch}_TRIM = {trim}: the failsafe leaves channel {ch} there, not at {neutral}"
                ));
            }
        }
        let functions: [f32; 16] =
            std::array::from_fn(|k| known[FUNCTIONS.start + k].unwrap_or(0.0));
        if let Some((k, f)) = functions.iter().enumerate().find(|(_, f)| is_motor(**f)) {
            return Err(format!(
                "SERVO{}_FUNCTION = {f} (a motor): ArduSub mixes our overrides as pilot sticks",
                k + 1
            ));
        }
        for o in &self.outputs {
            let rcin = RCIN1 + o.channel as f32 - 1.0;
            if !functions.contains(&rcin) {
                return Err(format!(
                    "no SERVOn_FUNCTION = {rcin} (RCIN{} passthrough): channel {} drives nothing",
                    o.channel, o.channel
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::mavlink::params::tests::{asked, value};
    use crate::backend::mavlink::params::{REREAD_NS, RETRY_NS};

    /// Thrusters on channels 1 and 5, neutral 1500.
    fn outputs() -> Vec<OutputSpec> {
        [1, 5]
            .map(|channel| OutputSpec {
                channel,
                neutral: crate::core::pwm::Pwm(1500),
            })
            .to_vec()
    }

    /// ArduSub's RCMAP (roll 2, pitch 1, throttle 3, yaw 4, forward 5, lateral 6) and trims
    /// (1500).
    fn ardusub_mapping(h: &mut OverrideHold) {
        for (name, v) in PARAMS[RCMAP].iter().zip([2.0, 1.0, 3.0, 4.0, 5.0, 6.0]) {
            h.params.on_value(&value(name, v));
        }
        for name in &PARAMS[TRIMS] {
            h.params.on_value(&value(name, 1500.0));
        }
        // Outputs 1 and 2 pass RC inputs 1 and 5 through; the rest unused.
        for (k, name) in PARAMS[FUNCTIONS].iter().enumerate() {
            let f = [RCIN1, RCIN1 + 4.0].get(k).copied().unwrap_or(0.0);
            h.params.on_value(&value(name, f));
        }
    }

    fn with(input: f32, timeout: f32, override_s: f32) -> OverrideHold {
        let mut h = OverrideHold::new(1.0, outputs());
        h.params.link_up(0);
        h.params.on_value(&value(FS_PILOT_INPUT, input));
        h.params.on_value(&value(FS_PILOT_TIMEOUT, timeout));
        h.params.on_value(&value(RC_OVERRIDE_TIME, override_s));
        ardusub_mapping(&mut h);
        h
    }

    /// The failsafe neutralises the RCMAP channels, each at its trim: a thruster on another
    /// channel, or a trim off its neutral, keeps our last override or a thrust after we stop.
    #[test]
    fn thrust_only_where_the_failsafe_takes_the_channel_to_the_thrusters_neutral() {
        assert_eq!(with(2.0, 0.5, 3.0).verdict(), Ok(()));
        let mut h = with(2.0, 0.5, 3.0);
        h.params.on_value(&value("RCMAP_FORWARD", 7.0));
        let why = h.verdict().unwrap_err();
        assert!(
            why.starts_with("channel 5 is not an RCMAP channel"),
            "{why}"
        );
        assert!(why.len() <= 100, "{} bytes: {why}", why.len());
        let mut h = with(2.0, 0.5, 3.0);
        h.params.on_value(&value("RC1_TRIM", 1550.0));
        let why = h.verdict().unwrap_err();
        assert_eq!(
            why,
            "RC1_TRIM = 1550: the failsafe leaves channel 1 there, not at 1500"
        );
        h.params.on_value(&value("RC1_TRIM", 1508.0));
        assert_eq!(h.verdict(), Ok(()), "within the tolerance");
        // A trim of a channel we do not use does not matter.
        h.params.on_value(&value("RC2_TRIM", 1700.0));
        assert_eq!(h.verdict(), Ok(()));
        // A stock BlueROV2 frame (outputs 1-8 Motor 1-8): our overrides would be pilot sticks.
        let mut h = with(2.0, 0.5, 3.0);
        h.params.on_value(&value("SERVO3_FUNCTION", 35.0));
        assert_eq!(
            h.verdict().unwrap_err(),
            "SERVO3_FUNCTION = 35 (a motor): ArduSub mixes our overrides as pilot sticks"
        );
        // Channel 5 passed through nowhere.
        let mut h = with(2.0, 0.5, 3.0);
        h.params.on_value(&value("SERVO2_FUNCTION", 0.0));
        let why = h.verdict().unwrap_err();
        assert_eq!(
            why,
            "no SERVOn_FUNCTION = 55 (RCIN5 passthrough): channel 5 drives nothing"
        );
        assert!(!is_motor(RCIN1) && is_motor(40.0) && is_motor(82.0) && is_motor(179.0));
        // The failsafe's own parameters are judged before the mapping has come.
        let mut h = OverrideHold::new(1.0, outputs());
        h.params.link_up(0);
        for (name, v) in [
            (FS_PILOT_INPUT, 2.0),
            (FS_PILOT_TIMEOUT, 3.0),
            (RC_OVERRIDE_TIME, 3.0),
        ] {
            h.params.on_value(&value(name, v));
        }
        assert!(h.verdict().unwrap_err().contains("outlive us"));
        h.params.on_value(&value(FS_PILOT_TIMEOUT, 0.5));
        assert_eq!(
            h.verdict().unwrap_err(),
            "waiting for the autopilot's RCMAP_ROLL"
        );
    }

    #[test]
    fn thrust_only_with_the_failsafe_on_and_short_and_overrides_taken() {
        let mut h = OverrideHold::new(1.0, outputs());
        assert!(h.verdict().unwrap_err().contains("waiting"));
        h.params.link_up(0);
        h.params.on_value(&value(FS_PILOT_INPUT, 2.0));
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
        assert_eq!(h.params.on_value(&value("FS_PILOT_TIMEOUX", 9.0)), None);
        assert!(h.verdict().is_ok());
        h.params.link_lost();
        assert!(h.verdict().is_err());
        assert_eq!(h.params.next_deadline_ns(), None);
        assert_eq!(
            h.params.on_value(&value(FS_PILOT_INPUT, 2.0)),
            None,
            "taken without a link"
        );
    }

    #[test]
    fn its_parameters_are_asked_for_at_link_up() {
        let mut h = OverrideHold::new(1.0, outputs());
        let mut out = Vec::new();
        h.params.requests(0, 1, 1, &mut out);
        assert!(out.is_empty(), "asked without a link");
        h.params.link_up(5);
        h.params.requests(5, 1, 2, &mut out);
        assert_eq!(asked(&out, 1, 2), PARAMS);
        assert_eq!(h.params.next_deadline_ns(), Some(5 + RETRY_NS));
        for (name, v) in [
            (FS_PILOT_INPUT, 2.0),
            (FS_PILOT_TIMEOUT, 0.5),
            (RC_OVERRIDE_TIME, 3.0),
        ] {
            h.params.on_value(&value(name, v));
        }
        ardusub_mapping(&mut h);
        assert_eq!(h.verdict(), Ok(()));
        out.clear();
        h.params.requests(5 + RETRY_NS, 1, 2, &mut out);
        assert_eq!(h.params.next_deadline_ns(), Some(5 + RETRY_NS + REREAD_NS));
    }
}
