//! The MAVLink conversation with ArduSub, without IO: messages and time in, messages out.
//!
//! - Link: the autopilot is the first HEARTBEAT sender whose `autopilot` is not
//!   MAV_AUTOPILOT_INVALID (ground stations and companions send INVALID), unless
//!   `target_system`/`target_component` name it. The link is up while its HEARTBEATs keep
//!   coming; after `link_timeout_ms` without one it is down and no reading is produced.
//! - Set-up, each time the link comes up: MAV_CMD_SET_MESSAGE_INTERVAL for the IMU,
//!   ATTITUDE and depth's pressure messages (then MAV_CMD_COMPONENT_ARM_DISARM when `arm`),
//!   one COMMAND_LONG at a time, because a COMMAND_ACK names the command but not the
//!   message id; each is retried `command_retries` times without an ACK.
//! - Readings: one per IMU message from the autopilot, stamped with its receive time, with
//!   the newest depth (and ATTITUDE rates, with `gyro_source = "attitude"`) if younger than
//!   `depth_timeout_ms`.
//! - Thrust: the current pulses go out at once when they change and every `resend_ms`
//!   otherwise, as DO_MOTOR_TEST per thruster (only while the autopilot reports armed:
//!   ArduSub refuses motor tests when disarmed, with a STATUSTEXT at most every 2 s) or as one
//!   RC_CHANNELS_OVERRIDE. Motor tests start with the first non-neutral pulse, not at
//!   link-up: the first one puts ArduSub into motor-test mode, which bypasses the pilot and
//!   which ArduSub leaves only by disarming 500 ms after the last one (docs/hardware.md).
//!   Once started they go on (neutral when there is nothing to do) until the vehicle
//!   disarms or the link is lost.
//! - Every path that stops thrust messages sends a neutral round first: link loss (no
//!   HEARTBEAT while data may still flow) and shutdown.
//! - DO_MOTOR_TEST param1 is ArduSub's 0-based motor index: `channel - 1` (see
//!   [`ardusub_motor_index`]).
//! - Our HEARTBEAT every `heartbeat_ms`, from the start.
//! - RC override mode: the autopilot's pilot-input failsafe (`FS_PILOT_INPUT`,
//!   `FS_PILOT_TIMEOUT`) and `RC_OVERRIDE_TIME` are read at each link-up; until they say our
//!   last override is taken back to neutral soon after we stop, overrides carry neutral only
//!   ([`super::override_hold`]).
//! - Depth: only from the pressure message of the barometer the autopilot's device ids say is
//!   in the water ([`super::water_baro`], read at each link-up); none, said, until then.
//! - Supply: the newest voltage (and current) of SYS_STATUS or BATTERY_STATUS monitor 0
//!   ([`super::battery`]), reported while younger than [`SUPPLY_STALE_NS`]; ArduSub streams
//!   both at its default rates (SYS_STATUS in EXT_STAT, BATTERY_STATUS in EXTRA3: `SRn_*`
//!   before ArduPilot 4.7, `MAVn_*` since), so no interval is requested.

use std::collections::VecDeque;

use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavSeverity, MavState, MavType,
    ATTITUDE_DATA, COMMAND_ACK_DATA, COMMAND_LONG_DATA, HEARTBEAT_DATA, RAW_IMU_DATA,
    RC_CHANNELS_DATA, SCALED_IMU2_DATA, SCALED_IMU_DATA, SCALED_PRESSURE2_DATA,
    SCALED_PRESSURE_DATA,
};
use mavlink::{MavHeader, MessageData};
use tracing::{debug, info, warn};

use super::battery::SupplyTracker;
use super::convert::{attitude_rates, depth_from_hpa, implausible, imu_reading, plausible_mag};
use super::motor_test::motor_test;
use super::override_hold::OverrideHold;
use super::rate_watch::RateWatch;
use super::rc_override::{self, OverrideWatch, RC_CHANNELS_HZ};
use super::water_baro::WaterBaro;
use crate::backend::{LinkState, OutputSpec, Supply};

pub use super::battery::SUPPLY_STALE_NS;
use crate::config::{GyroSource, ImuMessage, MavlinkConfig, OutputMode};
use crate::core::pwm::Pwm;
use thruster_driver_kit::LogLimiter;
use thruster_protocol::ImuReading;

const MS: u64 = 1_000_000;

/// Readings kept when the loop does not collect them (bounded: stale readings are useless).
const MAX_PENDING_READINGS: usize = 64;

pub use super::rc_override::RC_IGNORE;

/// A COMMAND_LONG waiting for its ACK.
#[derive(Debug, Clone)]
struct Pending {
    label: String,
    command: MavCmd,
    params: [f32; 7],
    attempts: u32,
    sent_ns: Option<u64>,
}

/// Counters for the status line and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ConversationCounters {
    /// Readings produced.
    pub readings: u64,
    /// IMU messages dropped because the link was not up.
    pub dropped_link_down: u64,
    /// IMU messages dropped because `gyro_source = "attitude"` had no fresh ATTITUDE.
    pub dropped_no_attitude: u64,
    /// Thrust messages sent (one per DO_MOTOR_TEST or RC_CHANNELS_OVERRIDE).
    pub thrust_sent: u64,
    /// DO_MOTOR_TEST refused by the autopilot (ACK other than ACCEPTED).
    pub motor_test_refused: u64,
    /// Commands that got no ACK after every retry.
    pub commands_unacked: u64,
    /// Link losses.
    pub link_losses: u64,
    /// IMU messages dropped because a value was physically implausible (e.g. ADC counts).
    pub imu_implausible: u64,
    /// Magnetometer readings dropped as implausible (the sample was kept without them).
    pub mag_implausible: u64,
}

/// See the module docs.
#[derive(Debug)]
pub struct Conversation {
    cfg: MavlinkConfig,
    outputs: Vec<OutputSpec>,
    started_ns: u64,
    target: Option<(u8, u8)>,
    last_heartbeat_ns: Option<u64>,
    link: LinkState,
    /// The autopilot's armed flag from its last HEARTBEAT; `None` before the first one.
    armed: Option<bool>,
    /// Motor tests have started (ArduSub is in motor-test mode because of us).
    engaged: bool,
    armed_by_us: bool,
    commands: VecDeque<Pending>,
    attitude: Option<(u64, [f64; 3])>,
    depth: Option<(u64, f64)>,
    /// The supply's newest reading, and whether its voltage is the ESCs' ([`super::battery`]).
    supply: SupplyTracker,
    /// How long the autopilot keeps an override (asked only in `rc_override` mode).
    override_hold: OverrideHold,
    /// Whether the autopilot applies our overrides or another sender's (`rc_override` mode).
    override_watch: OverrideWatch,
    /// The IMU stream's rate, for a ground station that reset it ([`super::rate_watch`]).
    imu_rate: RateWatch,
    /// Which barometer is in the water, and the verdict as last computed: the instance whose
    /// pressure message gives depth, or why none does.
    water_baro: WaterBaro,
    depth_instance: Result<usize, String>,
    readings: VecDeque<ImuReading>,
    pwm: Vec<Pwm>,
    thrust_dirty: bool,
    last_thrust_ns: Option<u64>,
    next_heartbeat_ns: u64,
    outgoing: Vec<MavMessage>,
    counters: ConversationCounters,
    refusal_log: LogLimiter,
    text_log: LogLimiter,
    implausible_log: LogLimiter,
    rate_log: LogLimiter,
}

impl Conversation {
    /// A conversation for `outputs` (thruster order), started at `now_ns`: outputs neutral,
    /// our first HEARTBEAT due at once.
    pub fn new(cfg: MavlinkConfig, outputs: Vec<OutputSpec>, now_ns: u64) -> Self {
        let pwm = outputs.iter().map(|o| o.neutral).collect();
        let target = (cfg.target_system != 0 && cfg.target_component != 0)
            .then_some((cfg.target_system, cfg.target_component));
        let override_hold = OverrideHold::new(cfg.max_override_hold_s, outputs.clone());
        let imu_rate = RateWatch::new(cfg.imu_rate_hz);
        let water_baro = WaterBaro::new(cfg.pressure_message);
        let depth_instance = water_baro.verdict();
        Conversation {
            cfg,
            outputs,
            started_ns: now_ns,
            target,
            last_heartbeat_ns: None,
            link: LinkState::Connecting,
            armed: None,
            engaged: false,
            armed_by_us: false,
            commands: VecDeque::new(),
            attitude: None,
            depth: None,
            supply: SupplyTracker::default(),
            override_hold,
            override_watch: OverrideWatch::default(),
            imu_rate,
            water_baro,
            depth_instance,
            readings: VecDeque::new(),
            pwm,
            thrust_dirty: true,
            last_thrust_ns: None,
            next_heartbeat_ns: now_ns,
            outgoing: Vec::new(),
            counters: ConversationCounters::default(),
            refusal_log: LogLimiter::default(),
            text_log: LogLimiter::new(20, std::time::Duration::from_secs(10)),
            implausible_log: LogLimiter::default(),
            rate_log: LogLimiter::default(),
        }
    }

    /// Our header (sequence numbers are filled in by the connection).
    pub fn header(&self) -> MavHeader {
        MavHeader {
            system_id: u32::from(self.cfg.system_id),
            component_id: self.cfg.component_id,
            sequence: 0,
        }
    }

    /// The link state.
    pub fn link(&self) -> LinkState {
        self.link.clone()
    }

    /// The autopilot's (system, component), once known.
    pub fn target(&self) -> Option<(u8, u8)> {
        self.target
    }

    /// The autopilot reported itself armed in its last HEARTBEAT.
    pub fn autopilot_armed(&self) -> bool {
        self.armed == Some(true)
    }

    /// The autopilot's armed flag from its last HEARTBEAT (`None` before the first one and
    /// after a link loss).
    pub fn armed_state(&self) -> Option<bool> {
        self.armed
    }

    /// Motor tests have started: ArduSub is in motor-test mode because of us.
    pub fn engaged(&self) -> bool {
        self.engaged
    }

    /// Why our thrust cannot reach the outputs although the link is up (RC override mode
    /// with an override hold not known, or too long): only neutral goes out then.
    pub fn held(&self) -> Option<String> {
        match self.cfg.output {
            OutputMode::RcOverride if self.link == LinkState::Up => {
                match self.override_watch.fight() {
                    Some(why) => Some(why.to_string()),
                    None => self.override_hold.verdict().err(),
                }
            }
            _ => None,
        }
    }

    /// The connection itself failed (TCP closed, serial gone): the link is down at once,
    /// nothing can be sent until the backend has reconnected.
    pub fn on_disconnect(&mut self, reason: &str) {
        if self.link == LinkState::Up {
            self.counters.link_losses += 1;
        }
        self.link = LinkState::Down(format!("connection lost: {reason}"));
        self.forget_link();
    }

    /// What a lost link invalidates: pending readings and requests, and the armed state
    /// (unknown until the next HEARTBEAT). Motor-test mode ends on ArduSub's side 500 ms
    /// after our last motor test, with a disarm.
    fn forget_link(&mut self) {
        self.readings.clear();
        self.commands.clear();
        self.armed = None;
        self.engaged = false;
        self.override_hold.params.link_lost();
        self.override_watch.link_lost();
        self.imu_rate.stop();
        self.water_baro.params.link_lost();
        self.depth_instance = self.water_baro.verdict();
        self.supply.options.link_lost();
    }

    /// We armed the vehicle (so we disarm it on exit).
    pub fn armed_by_us(&self) -> bool {
        self.armed_by_us
    }

    /// Counters.
    pub fn counters(&self) -> ConversationCounters {
        self.counters
    }

    /// Messages to send now (in order); empties the queue.
    pub fn drain_outgoing(&mut self) -> Vec<MavMessage> {
        std::mem::take(&mut self.outgoing)
    }

    /// The next reading, oldest first.
    pub fn take_reading(&mut self) -> Option<ImuReading> {
        self.readings.pop_front()
    }

    /// Sets the pulses (thruster order); they go out on the next [`Conversation::service`] if
    /// they changed.
    pub fn set_outputs(&mut self, pwm: &[Pwm]) {
        if self.pwm.as_slice() != pwm {
            self.pwm.clear();
            self.pwm.extend_from_slice(pwm);
            self.thrust_dirty = true;
        }
    }

    /// The pulses currently commanded.
    pub fn outputs(&self) -> &[Pwm] {
        &self.pwm
    }

    /// The next time [`Conversation::service`] has work without a new message.
    pub fn next_deadline_ns(&self) -> u64 {
        // Only deadlines that `service` moves forward, or the loop would spin on one that
        // stays in the past (thrust waits for a target; the link timer only runs while up).
        let mut d = self.next_heartbeat_ns;
        if self.target.is_some() {
            let resend = self
                .last_thrust_ns
                .map_or(self.started_ns, |t| t + self.cfg.resend_ms * MS);
            d = d.min(resend);
        }
        let link_timeout = self.cfg.link_timeout_ms * MS;
        match (&self.link, self.last_heartbeat_ns) {
            (LinkState::Up, Some(t)) => d = d.min(t + link_timeout),
            (LinkState::Connecting, _) => d = d.min(self.started_ns + link_timeout),
            _ => {}
        }
        if let Some(sent) = self.commands.front().and_then(|c| c.sent_ns) {
            d = d.min(sent + self.cfg.command_timeout_ms * MS);
        }
        for t in [
            self.override_hold.params.next_deadline_ns(),
            self.imu_rate.next_deadline_ns(),
            self.water_baro.params.next_deadline_ns(),
            self.supply.options.next_deadline_ns(),
        ]
        .into_iter()
        .flatten()
        {
            d = d.min(t);
        }
        d
    }

    /// The messages [`Conversation::on_message`] uses: only these are handed over by the
    /// receive thread (`io`), and the rest (dozens of streams a GCS link carries) are dropped
    /// there so the loop is woken only for something it uses. Kept beside `on_message`: a
    /// message handled there and missing here is never seen (SYS_STATUS, BATTERY_STATUS and
    /// PARAM_VALUE were, found by the process test of the override check).
    pub fn takes(msg: &MavMessage) -> bool {
        matches!(
            msg,
            MavMessage::HEARTBEAT(_)
                | MavMessage::COMMAND_ACK(_)
                | MavMessage::SCALED_IMU(_)
                | MavMessage::SCALED_IMU2(_)
                | MavMessage::RAW_IMU(_)
                | MavMessage::ATTITUDE(_)
                | MavMessage::SCALED_PRESSURE(_)
                | MavMessage::SCALED_PRESSURE2(_)
                | MavMessage::STATUSTEXT(_)
                | MavMessage::SYS_STATUS(_)
                | MavMessage::BATTERY_STATUS(_)
                | MavMessage::PARAM_VALUE(_)
                | MavMessage::RC_CHANNELS(_)
        )
    }

    /// Handles one message received at `t_ns`.
    pub fn on_message(&mut self, t_ns: u64, header: &MavHeader, msg: &MavMessage) {
        if let MavMessage::HEARTBEAT(hb) = msg {
            self.on_heartbeat(t_ns, header, hb);
            return;
        }
        let from_target = self
            .target
            .is_some_and(|(s, c)| u32::from(s) == header.system_id && c == header.component_id);
        if !from_target {
            return;
        }
        if let Some(imu) = imu_reading(msg, self.cfg.imu_message) {
            self.on_imu(t_ns, imu);
            return;
        }
        match msg {
            MavMessage::ATTITUDE(a) => self.attitude = Some((t_ns, attitude_rates(a))),
            MavMessage::SCALED_PRESSURE(p) => self.on_pressure(t_ns, 0, p.press_abs),
            MavMessage::SCALED_PRESSURE2(p) => self.on_pressure(t_ns, 1, p.press_abs),
            MavMessage::SYS_STATUS(st) => self.supply.on_sys_status(t_ns, st),
            MavMessage::BATTERY_STATUS(b) => self.supply.on_battery_status(t_ns, b),
            MavMessage::COMMAND_ACK(ack) => self.on_ack(t_ns, ack),
            MavMessage::RC_CHANNELS(rc) => self.on_rc_channels(t_ns, rc),
            MavMessage::PARAM_VALUE(v) => {
                self.on_baro_param(v);
                if self.supply.options.on_value(v).is_some() {
                    if let Some(why) = self.supply.not_the_esc_voltage() {
                        warn!("supply voltage reported unknown: {why} (docs/hardware.md)");
                    }
                }
                if let Some((name, value)) = self.override_hold.params.on_value(v) {
                    info!("autopilot {name} = {value}");
                    match self.override_hold.verdict() {
                        Ok(()) => info!(
                            "the autopilot neutralises an override we leave: overrides carry \
                             thrust"
                        ),
                        Err(why) => warn!(
                            max_override_hold_s = self.cfg.max_override_hold_s,
                            "RC overrides held neutral: {why} (ArduSub keeps driving the last \
                             override until its pilot-input failsafe: after a crash of ours, \
                             our last thrust; docs/hardware.md)"
                        ),
                    }
                    self.thrust_dirty = true;
                }
            }
            MavMessage::STATUSTEXT(s) => {
                if let Some(suppressed) = self.text_log.allow() {
                    let text = s
                        .text
                        .to_str()
                        .unwrap_or("<not UTF-8>")
                        .trim_end_matches('\0');
                    let severe = (s.severity as u32) <= (MavSeverity::MAV_SEVERITY_WARNING as u32);
                    if severe {
                        warn!(suppressed, "autopilot: {text}");
                    } else {
                        info!(suppressed, "autopilot: {text}");
                    }
                }
            }
            _ => {}
        }
    }

    fn on_heartbeat(&mut self, t_ns: u64, header: &MavHeader, hb: &HEARTBEAT_DATA) {
        if hb.autopilot == MavAutopilot::MAV_AUTOPILOT_INVALID {
            return;
        }
        let Ok(sys) = u8::try_from(header.system_id) else {
            return;
        };
        let comp = header.component_id;
        let wanted = |want: u8, got: u8| want == 0 || want == got;
        if !wanted(self.cfg.target_system, sys) || !wanted(self.cfg.target_component, comp) {
            return;
        }
        match self.target {
            None => {
                info!(
                    system = sys,
                    component = comp,
                    vehicle = ?hb.mavtype,
                    autopilot = ?hb.autopilot,
                    "autopilot found"
                );
                if hb.mavtype != MavType::MAV_TYPE_SUBMARINE {
                    warn!(vehicle = ?hb.mavtype, "the autopilot is not ArduSub (MAV_TYPE_SUBMARINE)");
                }
                self.target = Some((sys, comp));
            }
            Some(t) if t != (sys, comp) => return,
            Some(_) => {}
        }
        self.last_heartbeat_ns = Some(t_ns);
        let armed = hb
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
        // Logged from the first HEARTBEAT on (None -> Some), not only on transitions: a
        // vehicle disarmed from the start must not look like one whose thrusters follow.
        if Some(armed) != self.armed {
            if armed {
                info!("autopilot armed: thrust commands take effect");
            } else {
                warn!("autopilot disarmed: thrust commands have no effect until it is armed");
                // Not motor-test mode itself: ArduSub leaves it 500 ms after the last
                // DO_MOTOR_TEST (a refused one too), so we stop sending them now and the next
                // thrust after arming starts them again.
                self.engaged = false;
            }
            self.armed = Some(armed);
            // Armed state gates DO_MOTOR_TEST: send the current pulses at once.
            self.thrust_dirty = true;
        }
        if self.link != LinkState::Up {
            info!(previous = %self.link, "link to the autopilot up; requesting message rates");
            self.link = LinkState::Up;
            self.queue_setup();
            self.imu_rate.restart(t_ns);
            if self.cfg.output == OutputMode::RcOverride {
                self.override_hold.params.link_up(t_ns);
            }
            self.water_baro.params.link_up(t_ns);
            self.supply.options.link_up(t_ns);
        }
    }

    /// What the autopilot applies on the RC channels: another sender on ours stops ours.
    fn on_rc_channels(&mut self, t_ns: u64, rc: &RC_CHANNELS_DATA) {
        if self.cfg.output != OutputMode::RcOverride || self.override_watch.fight().is_some() {
            return;
        }
        self.override_watch.on_report(t_ns, rc);
        if let Some(why) = self.override_watch.fight() {
            warn!(
                "{why} (a ground station's MANUAL_CONTROL overrides RC channels 1-8; disable \
                 its joystick and restart this driver; docs/hardware.md)"
            );
        }
    }

    /// A PARAM_VALUE that may name a barometer: the depth's source decided again, its rate
    /// asked for when it changed to a message.
    fn on_baro_param(&mut self, v: &mavlink::dialects::ardupilotmega::PARAM_VALUE_DATA) {
        let Some((name, value)) = self.water_baro.params.on_value(v) else {
            return;
        };
        info!("autopilot {name} = {value}");
        let verdict = self.water_baro.verdict();
        if verdict == self.depth_instance {
            return;
        }
        match &verdict {
            Ok(i) => info!(
                barometer = i + 1,
                "depth from {}",
                if *i == 0 {
                    "SCALED_PRESSURE"
                } else {
                    "SCALED_PRESSURE2"
                }
            ),
            // The ids come one by one at link-up: waiting for the next is not news.
            Err(why) if why.starts_with("waiting") => debug!("no depth yet: {why}"),
            Err(why) => warn!("no depth: {why} (docs/hardware.md)"),
        }
        self.depth_instance = verdict;
        self.depth = None;
        if self.depth_instance.is_ok() {
            self.queue_pressure_rate();
        }
    }

    fn queue_setup(&mut self) {
        self.commands.clear();
        self.queue_rates();
        if self.cfg.arm && self.armed != Some(true) {
            self.commands.push_back(Pending {
                label: "arm".to_string(),
                command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                params: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                attempts: 0,
                sent_ns: None,
            });
        }
    }

    /// SET_MESSAGE_INTERVAL for the IMU, ATTITUDE and pressure messages.
    fn queue_rates(&mut self) {
        let imu_id = match self.cfg.imu_message {
            ImuMessage::ScaledImu2 => SCALED_IMU2_DATA::ID,
            ImuMessage::ScaledImu => SCALED_IMU_DATA::ID,
            ImuMessage::RawImu => RAW_IMU_DATA::ID,
        };
        self.queue_rate("IMU", imu_id, self.cfg.imu_rate_hz);
        self.queue_rate("ATTITUDE", ATTITUDE_DATA::ID, self.cfg.attitude_rate_hz);
        self.queue_pressure_rate();
        if self.cfg.output == OutputMode::RcOverride {
            self.queue_rate("RC_CHANNELS", RC_CHANNELS_DATA::ID, RC_CHANNELS_HZ);
        }
    }

    /// SET_MESSAGE_INTERVAL for the depth's pressure message, once it is known.
    fn queue_pressure_rate(&mut self) {
        match self.depth_instance {
            Ok(0) => self.queue_rate(
                "SCALED_PRESSURE",
                SCALED_PRESSURE_DATA::ID,
                self.cfg.pressure_rate_hz,
            ),
            Ok(_) => self.queue_rate(
                "SCALED_PRESSURE2",
                SCALED_PRESSURE2_DATA::ID,
                self.cfg.pressure_rate_hz,
            ),
            Err(_) => {}
        }
    }

    fn queue_rate(&mut self, name: &str, id: u32, hz: f64) {
        if hz > 0.0 {
            let interval_us = (1e6 / hz).round() as f32;
            self.commands.push_back(Pending {
                label: format!("{name} (id {id}) every {interval_us} us"),
                command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                params: [id as f32, interval_us, 0.0, 0.0, 0.0, 0.0, 0.0],
                attempts: 0,
                sent_ns: None,
            });
        }
    }

    fn on_imu(&mut self, t_ns: u64, mut imu: ImuReading) {
        if self.link != LinkState::Up {
            self.counters.dropped_link_down += 1;
            return;
        }
        self.imu_rate.counted();
        if let Some(why) = implausible(&imu) {
            self.counters.imu_implausible += 1;
            if let Some(suppressed) = self.implausible_log.allow() {
                warn!(
                    suppressed,
                    total = self.counters.imu_implausible,
                    accel = ?imu.accel,
                    gyro = ?imu.gyro,
                    "IMU message dropped: {why} (not a physical reading; is imu_message right?)"
                );
            }
            return;
        }
        if imu.mag.is_some() && plausible_mag(imu.mag).is_none() {
            self.counters.mag_implausible += 1;
            imu.mag = None;
        }
        let fresh = |t: u64| t_ns.saturating_sub(t) < self.cfg.depth_timeout_ms * MS;
        let gyro = match self.cfg.gyro_source {
            GyroSource::Imu => imu.gyro,
            GyroSource::Attitude => match self.attitude {
                Some((t, rates)) if fresh(t) => rates,
                _ => {
                    self.counters.dropped_no_attitude += 1;
                    return;
                }
            },
        };
        let depth = self.depth.filter(|&(t, _)| fresh(t)).map(|(_, d)| d);
        if self.readings.len() >= MAX_PENDING_READINGS {
            self.readings.pop_front();
        }
        self.readings.push_back(ImuReading {
            t_ns,
            gyro,
            depth,
            ..imu
        });
        self.counters.readings += 1;
    }

    /// The supply as last reported, if fresh at `now_ns` ([`SupplyTracker::supply`]).
    pub fn supply(&self, now_ns: u64) -> Supply {
        self.supply.supply(now_ns)
    }

    /// The pressure of barometer `instance`, hPa: depth if it is the water's.
    fn on_pressure(&mut self, t_ns: u64, instance: usize, press_abs_hpa: f32) {
        if self.depth_instance != Ok(instance) {
            return;
        }
        let d = depth_from_hpa(
            f64::from(press_abs_hpa),
            self.cfg.surface_pressure_hpa,
            self.cfg.fluid_density_kg_m3,
        );
        if d.is_finite() {
            self.depth = Some((t_ns, d));
        }
    }

    fn on_ack(&mut self, t_ns: u64, ack: &COMMAND_ACK_DATA) {
        if ack.command == MavCmd::MAV_CMD_DO_MOTOR_TEST {
            if ack.result != MavResult::MAV_RESULT_ACCEPTED {
                self.counters.motor_test_refused += 1;
                if let Some(suppressed) = self.refusal_log.allow() {
                    warn!(result = ?ack.result, suppressed, "autopilot refused DO_MOTOR_TEST (armed? in a mode that allows motor tests?)");
                }
            }
            return;
        }
        let Some(front) = self.commands.front() else {
            return;
        };
        if front.command != ack.command || front.sent_ns.is_none() {
            return;
        }
        let done = self.commands.pop_front().expect("front exists");
        match ack.result {
            MavResult::MAV_RESULT_ACCEPTED => {
                info!(request = %done.label, "autopilot accepted");
                if done.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM && done.params[0] == 1.0 {
                    self.armed_by_us = true;
                }
            }
            other => warn!(request = %done.label, result = ?other, "autopilot refused"),
        }
        // The next request goes out at once, not at the next deadline.
        self.service_commands(t_ns);
    }

    /// Periodic work at `now_ns`: link supervision, our HEARTBEAT, command (re)sends, thrust.
    pub fn service(&mut self, now_ns: u64) {
        self.supervise_link(now_ns);
        if now_ns >= self.next_heartbeat_ns {
            self.outgoing.push(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }));
            self.next_heartbeat_ns = now_ns + self.cfg.heartbeat_ms * MS;
        }
        // Judged only with no request out: the rates being asked for are not yet in force,
        // so the window starts once the last request is answered or given up.
        if !self.commands.is_empty() {
            self.imu_rate.restart(now_ns);
        } else {
            if let Some(hz) = self.imu_rate.starved(now_ns) {
                if let Some(suppressed) = self.rate_log.allow() {
                    warn!(
                        suppressed,
                        "IMU messages at {hz:.1} Hz, {} asked for (a ground station's \
                         REQUEST_DATA_STREAM resets the rates): asking again",
                        self.cfg.imu_rate_hz
                    );
                }
                self.queue_rates();
            }
        }
        self.service_commands(now_ns);
        if let Some((sys, comp)) = self.target {
            self.override_hold
                .params
                .requests(now_ns, sys, comp, &mut self.outgoing);
            self.water_baro
                .params
                .requests(now_ns, sys, comp, &mut self.outgoing);
            self.supply
                .options
                .requests(now_ns, sys, comp, &mut self.outgoing);
        }
        let resend_due = self
            .last_thrust_ns
            .is_none_or(|t| now_ns >= t + self.cfg.resend_ms * MS);
        if self.thrust_dirty || resend_due {
            self.push_thrust(now_ns);
        }
    }

    fn supervise_link(&mut self, now_ns: u64) {
        let timeout = self.cfg.link_timeout_ms * MS;
        match (self.last_heartbeat_ns, &self.link) {
            (Some(t), LinkState::Up) if now_ns >= t + timeout => {
                warn!(
                    link_timeout_ms = self.cfg.link_timeout_ms,
                    "no autopilot HEARTBEAT within the link timeout: link down, outputs \
                     neutral, IMU samples stop"
                );
                // Data may still flow (only HEARTBEATs lost), so the autopilot may still be
                // listening: leave it with neutral, not with the last pulses, before going
                // quiet. Nothing is sent while the link is down.
                self.neutral_round(now_ns);
                self.link =
                    LinkState::Down(format!("no HEARTBEAT for {} ms", self.cfg.link_timeout_ms));
                self.counters.link_losses += 1;
                self.forget_link();
            }
            (None, LinkState::Connecting) if now_ns >= self.started_ns + timeout => {
                warn!(
                    address = %self.cfg.address,
                    "no autopilot HEARTBEAT yet; still waiting"
                );
                self.link = LinkState::Down("no autopilot HEARTBEAT yet".to_string());
            }
            _ => {}
        }
    }

    fn service_commands(&mut self, now_ns: u64) {
        let Some((sys, comp)) = self.target else {
            return;
        };
        let timeout = self.cfg.command_timeout_ms * MS;
        let retries = self.cfg.command_retries;
        let Some(front) = self.commands.front_mut() else {
            return;
        };
        let due = front.sent_ns.is_none_or(|t| now_ns >= t + timeout);
        if !due {
            return;
        }
        if front.attempts > retries {
            warn!(request = %front.label, attempts = front.attempts, "no COMMAND_ACK from the autopilot; giving up");
            self.counters.commands_unacked += 1;
            self.commands.pop_front();
            return self.service_commands(now_ns);
        }
        debug!(request = %front.label, attempt = front.attempts + 1, "sending command");
        let p = front.params;
        let msg = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            command: front.command,
            target_system: sys,
            target_component: comp,
            // MAVLink: 0 for the first transmission, then the retry number.
            confirmation: front.attempts.min(255) as u8,
        });
        front.attempts += 1;
        front.sent_ns = Some(now_ns);
        self.outgoing.push(msg);
    }

    fn push_thrust(&mut self, now_ns: u64) {
        let Some((sys, comp)) = self.target else {
            return;
        };
        self.thrust_dirty = false;
        self.last_thrust_ns = Some(now_ns);
        match self.cfg.output {
            OutputMode::MotorTest => {
                if self.armed != Some(true) {
                    self.engaged = false;
                    return;
                }
                if !self.engaged {
                    let idle = self
                        .outputs
                        .iter()
                        .zip(&self.pwm)
                        .all(|(o, p)| *p == o.neutral);
                    // Nothing to command: stay out of motor-test mode, which would take the
                    // vehicle from its pilot and disarm it 500 ms after we stop.
                    if idle {
                        return;
                    }
                    info!("first thrust: motor tests start (ArduSub motor-test mode: pilot input bypassed until it disarms)");
                    self.engaged = true;
                }
                let timeout_s = self.cfg.motor_test_timeout_ms as f32 / 1000.0;
                for (o, p) in self.outputs.iter().zip(&self.pwm) {
                    self.outgoing
                        .push(motor_test(sys, comp, o.channel, *p, timeout_s));
                    self.counters.thrust_sent += 1;
                }
            }
            OutputMode::RcOverride => {
                // Another sender on our channels (a pilot's joystick): nothing of ours.
                if self.override_watch.fight().is_some() {
                    return;
                }
                // Thrust only once the autopilot's hold after our last message is known to
                // be short: until then the outputs get neutral.
                let thrust = self.override_hold.verdict().is_ok();
                let (msg, values) =
                    rc_override::message(&self.outputs, &self.pwm, thrust, sys, comp);
                self.outgoing.push(msg);
                self.override_watch.sent(now_ns, values);
                self.counters.thrust_sent += 1;
            }
        }
    }

    /// Neutral on every output now, whatever the resend timer says (nothing if motor tests
    /// never started: then nothing of ours is on the outputs).
    fn neutral_round(&mut self, now_ns: u64) {
        let neutral: Vec<Pwm> = self.outputs.iter().map(|o| o.neutral).collect();
        self.set_outputs(&neutral);
        self.push_thrust(now_ns);
    }

    /// Queues the messages that end the conversation: neutral thrust now (whatever the resend
    /// timer says) and, if we armed the vehicle, a disarm command.
    pub fn shutdown(&mut self, now_ns: u64) {
        self.neutral_round(now_ns);
        if self.armed_by_us {
            if let Some((sys, comp)) = self.target {
                self.outgoing
                    .push(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                        param1: 0.0,
                        command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                        target_system: sys,
                        target_component: comp,
                        ..COMMAND_LONG_DATA::DEFAULT
                    }));
            }
        }
    }
}

#[cfg(test)]
mod tests;
