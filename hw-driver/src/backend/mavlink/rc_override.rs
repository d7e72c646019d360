//! RC_CHANNELS_OVERRIDE: the message we send, and whether the autopilot applies it or another
//! sender's, without IO.
//!
//! ArduSub takes RC overrides from its ground-station system id (`MAV_GCS_SYSID`, 255, ours
//! too) and keeps the newest per channel. A ground station's joystick sends MANUAL_CONTROL,
//! which ArduSub turns into overrides of channels 1-8 on every message
//! (`Sub::transform_manual_control_to_rc_override`), so with a joystick enabled the two
//! senders overwrite each other at their message rates and the thrusters get a mix. What the
//! autopilot applies it reports in RC_CHANNELS (`radio_in`, the override in force), asked for
//! at [`RC_CHANNELS_HZ`] in this mode. When our channels read other values than ours for
//! [`FIGHT_REPORTS`] reports in a row, with ours unchanged for [`SETTLE_NS`] before each, the
//! watch calls a fight: from then on until the link is lost no override of ours goes out (the
//! other sender, a pilot, has the vehicle) and `driver_status` says why.

use mavlink::dialects::ardupilotmega::{MavMessage, RC_CHANNELS_DATA, RC_CHANNELS_OVERRIDE_DATA};

use crate::backend::OutputSpec;
use crate::core::pwm::Pwm;

/// "Ignore this channel" in RC_CHANNELS_OVERRIDE (0 would release it to the radio).
pub const RC_IGNORE: u16 = u16::MAX;

/// RC_CHANNELS's rate in this mode, Hz (ArduSub's default RC_CHAN stream is 2 Hz).
pub const RC_CHANNELS_HZ: f64 = 10.0;

/// How long our values must have stood before a report is judged, ns: the override reaches
/// `radio_in` within ArduSub's next RC read (100 Hz) and the report within its stream period.
pub const SETTLE_NS: u64 = 250_000_000;

/// Reports in a row that must disagree before a fight is called (0.3 s at 10 Hz): one report
/// that crossed our change in flight is not a fight.
pub const FIGHT_REPORTS: u32 = 3;

/// A pulse is ours when the report is within this of it, us (ArduSub reports what it got).
const TOLERANCE_US: u16 = 2;

/// The override carrying `pwm` (or, unless `thrust`, each output's neutral) on each output's
/// channel (1-based; channels 1..=8), the rest ignored: the message and the eight values.
pub fn message(
    outputs: &[OutputSpec],
    pwm: &[Pwm],
    thrust: bool,
    sys: u8,
    comp: u8,
) -> (MavMessage, [u16; 8]) {
    let mut ch = [RC_IGNORE; 8];
    for (o, p) in outputs.iter().zip(pwm) {
        let p = if thrust { p } else { &o.neutral };
        let slot = (o.channel as usize)
            .checked_sub(1)
            .and_then(|i| ch.get_mut(i));
        if let Some(slot) = slot {
            *slot = p.us();
        }
    }
    let msg = MavMessage::RC_CHANNELS_OVERRIDE(RC_CHANNELS_OVERRIDE_DATA {
        chan1_raw: ch[0],
        chan2_raw: ch[1],
        chan3_raw: ch[2],
        chan4_raw: ch[3],
        chan5_raw: ch[4],
        chan6_raw: ch[5],
        chan7_raw: ch[6],
        chan8_raw: ch[7],
        target_system: sys,
        target_component: comp,
    });
    (msg, ch)
}

/// See the module docs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OverrideWatch {
    /// The values we last sent and since when they stood.
    sent: Option<(u64, [u16; 8])>,
    disagreeing: u32,
    fight: Option<String>,
}

impl OverrideWatch {
    /// We sent `values` at `t_ns`.
    pub fn sent(&mut self, t_ns: u64, values: [u16; 8]) {
        if self.sent.is_none_or(|(_, v)| v != values) {
            self.sent = Some((t_ns, values));
        }
    }

    /// An RC_CHANNELS report received at `t_ns`.
    pub fn on_report(&mut self, t_ns: u64, rc: &RC_CHANNELS_DATA) {
        let Some((since, ours)) = self.sent else {
            return;
        };
        if self.fight.is_some() || t_ns < since + SETTLE_NS {
            return;
        }
        let applied = [
            rc.chan1_raw,
            rc.chan2_raw,
            rc.chan3_raw,
            rc.chan4_raw,
            rc.chan5_raw,
            rc.chan6_raw,
            rc.chan7_raw,
            rc.chan8_raw,
        ];
        let other = ours
            .iter()
            .zip(applied)
            .enumerate()
            .find(|(_, (o, a))| **o != RC_IGNORE && o.abs_diff(*a) > TOLERANCE_US);
        let Some((i, (o, a))) = other else {
            self.disagreeing = 0;
            return;
        };
        self.disagreeing += 1;
        if self.disagreeing >= FIGHT_REPORTS {
            self.fight = Some(format!(
                "channel {} applies {a} us, not our {o}: another sender overrides (joystick?); \
                 ours stopped",
                i + 1
            ));
        }
    }

    /// Why our overrides stopped, once another sender was seen.
    pub fn fight(&self) -> Option<&str> {
        self.fight.as_deref()
    }

    /// The link is gone: a new link starts unjudged.
    pub fn link_lost(&mut self) {
        *self = OverrideWatch::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn report(ch: [u16; 8]) -> RC_CHANNELS_DATA {
        RC_CHANNELS_DATA {
            chan1_raw: ch[0],
            chan2_raw: ch[1],
            chan3_raw: ch[2],
            chan4_raw: ch[3],
            chan5_raw: ch[4],
            chan6_raw: ch[5],
            chan7_raw: ch[6],
            chan8_raw: ch[7],
            chancount: 16,
            ..RC_CHANNELS_DATA::default()
        }
    }

    #[test]
    fn the_message_carries_our_channels_and_ignores_the_rest() {
        let outputs = [
            OutputSpec {
                channel: 1,
                neutral: Pwm(1500),
            },
            OutputSpec {
                channel: 6,
                neutral: Pwm(1500),
            },
        ];
        let (_, held) = message(&outputs, &[Pwm(1600), Pwm(1400)], false, 1, 2);
        assert_eq!((held[0], held[5]), (1500, 1500), "neutral unless thrust");
        let (msg, ch) = message(&outputs, &[Pwm(1600), Pwm(1400)], true, 1, 2);
        assert_eq!(
            ch,
            [1600, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE, 1400, RC_IGNORE, RC_IGNORE]
        );
        let MavMessage::RC_CHANNELS_OVERRIDE(m) = msg else {
            panic!("{msg:?}")
        };
        assert_eq!(
            (
                m.chan1_raw,
                m.chan6_raw,
                m.target_system,
                m.target_component
            ),
            (1600, 1400, 1, 2)
        );
    }

    #[test]
    fn a_fight_is_three_settled_reports_of_another_senders_values() {
        let ours = [
            1600, 1400, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE,
        ];
        // The joystick's idle stick: every channel 1500 (ArduSub's MANUAL_CONTROL mapping).
        let joystick = [1500; 8];
        let mut w = OverrideWatch::default();
        w.sent(0, ours);
        // Ours applied (channels we do not send may read anything): no fight.
        for k in 0..10 {
            w.on_report(
                300 * MS + k * 100 * MS,
                &report([1601, 1400, 1100, 1900, 0, 0, 0, 0]),
            );
        }
        assert_eq!(w.fight(), None);
        // A report before our change settled is not judged; two disagreeing, then one that
        // agrees, reset the count.
        w.sent(
            2_000 * MS,
            [
                1650, 1400, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE,
            ],
        );
        for k in 0..5 {
            w.on_report(2_000 * MS + k * 40 * MS, &report(joystick));
        }
        w.on_report(2_300 * MS, &report(joystick));
        w.on_report(2_400 * MS, &report(joystick));
        w.on_report(2_500 * MS, &report([1650, 1400, 0, 0, 0, 0, 0, 0]));
        assert_eq!(w.fight(), None);
        // Resending the same values does not restart the settling.
        w.sent(
            2_550 * MS,
            [
                1650, 1400, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE, RC_IGNORE,
            ],
        );
        for t in [2_600, 2_700, 2_800] {
            w.on_report(t * MS, &report(joystick));
        }
        let why = w.fight().unwrap();
        assert!(
            why.starts_with("channel 1 applies 1500 us, not our 1650"),
            "{why}"
        );
        assert!(why.len() <= 100, "{} bytes", why.len());
        w.link_lost();
        assert_eq!(w.fight(), None);
    }
}
