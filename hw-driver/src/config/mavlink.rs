//! `[mavlink]`: ArduSub over MAVLink.

use serde::Deserialize;

use super::ranged::ranged;

ranged!(de_heartbeat_ms, "heartbeat_ms", u64, 100, 10_000, " ms");
ranged!(
    de_link_timeout_ms,
    "link_timeout_ms",
    u64,
    500,
    60_000,
    " ms"
);
ranged!(de_imu_rate_hz, "imu_rate_hz", f64, 1.0, 1000.0, " Hz");
ranged!(
    de_attitude_rate_hz,
    "attitude_rate_hz",
    f64,
    0.0,
    1000.0,
    " Hz"
);
ranged!(
    de_pressure_rate_hz,
    "pressure_rate_hz",
    f64,
    0.0,
    1000.0,
    " Hz"
);
// ArduSub stops a motor test (and disarms) 500 ms after the last DO_MOTOR_TEST, so a resend
// period above 250 ms leaves no room for one lost packet.
ranged!(de_resend_ms, "resend_ms", u64, 10, 250, " ms");
ranged!(
    de_motor_test_timeout_ms,
    "motor_test_timeout_ms",
    u64,
    100,
    10_000,
    " ms"
);
ranged!(
    de_command_timeout_ms,
    "command_timeout_ms",
    u64,
    50,
    10_000,
    " ms"
);
ranged!(de_command_retries, "command_retries", u32, 0, 20, "");
ranged!(
    de_density,
    "fluid_density_kg_m3",
    f64,
    900.0,
    1100.0,
    " kg/m^3"
);
ranged!(
    de_surface_hpa,
    "surface_pressure_hpa",
    f64,
    800.0,
    1200.0,
    " hPa"
);
ranged!(
    de_depth_timeout_ms,
    "depth_timeout_ms",
    u64,
    10,
    10_000,
    " ms"
);
ranged!(de_read_timeout_ms, "read_timeout_ms", u64, 1, 1000, " ms");
// ArduSub's FS_PILOT_TIMEOUT is 0.1-3 s; a hold shorter than a resend period would fire the
// failsafe between our messages.
ranged!(
    de_max_override_hold_s,
    "max_override_hold_s",
    f64,
    0.25,
    120.0,
    " s"
);

/// Which MAVLink message carries the IMU sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImuMessage {
    /// SCALED_IMU2 (id 116): ArduPilot's second IMU, mG / mrad/s / mgauss.
    #[default]
    ScaledImu2,
    /// SCALED_IMU (id 26): the first IMU, same units.
    ScaledImu,
    /// RAW_IMU (id 27): ArduPilot fills it with the first IMU *scaled* to the same units
    /// as SCALED_IMU (despite the name); other autopilots send ADC counts.
    RawImu,
}

/// Which MAVLink message carries the depth sensor's pressure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PressureMessage {
    /// The first water-pressure sensor among the autopilot's barometers (`BARO1_DEVID`..
    /// `BARO3_DEVID`): SCALED_PRESSURE for instance 0, SCALED_PRESSURE2 for 1; none (said)
    /// for instance 2, which ArduSub does not report, or without one.
    #[default]
    Auto,
    /// SCALED_PRESSURE (barometer 1), unless the autopilot says it is an air barometer.
    ScaledPressure,
    /// SCALED_PRESSURE2 (barometer 2), unless the autopilot says it is an air barometer.
    ScaledPressure2,
}

/// Where the angular rate comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GyroSource {
    /// The IMU message's gyro (raw, 1 mrad/s resolution).
    #[default]
    Imu,
    /// ATTITUDE's body rates (float, bias-corrected by the autopilot's estimator). Needs
    /// `attitude_rate_hz` > 0; a sample takes the newest ATTITUDE received.
    Attitude,
}

/// How thrust reaches the ESCs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OutputMode {
    /// MAV_CMD_DO_MOTOR_TEST per thruster (PWM, board order), resent every `resend_ms`.
    /// The vehicle must be armed; ArduSub disarms when resends stop for 500 ms.
    #[default]
    MotorTest,
    /// RC_CHANNELS_OVERRIDE; needs SERVOn_FUNCTION = RCINn passthrough on each thruster
    /// output and no motor output (set by you; this driver changes no parameter, it reads
    /// them and holds its overrides neutral until they are so). Channels 1..=6 (the ones
    /// ArduSub's pilot-input failsafe takes back to neutral).
    RcOverride,
}

/// `[mavlink]`. Every key optional; defaults documented per key and in
/// config/thruster-hw.toml.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MavlinkConfig {
    /// Connection string: `udpin:ADDR:PORT` (listen; replies go only to the address the
    /// autopilot's HEARTBEAT came from, other senders are dropped), `udpout:HOST:PORT`,
    /// `tcpout:HOST:PORT`, `tcpin:ADDR:PORT`, `serial:/dev/ttyACM0:115200`. Default
    /// "udpin:127.0.0.1:14660": loopback only, for a BlueOS "UDP Client" endpoint on the
    /// same computer; listening on every interface would let anyone on the tether's network
    /// talk to the driver.
    pub address: String,
    /// Our system id. Default 255: ArduSub accepts RC_CHANNELS_OVERRIDE only from
    /// SYSID_MYGCS (default 255).
    pub system_id: u8,
    /// Our component id. Default 191 (MAV_COMP_ID_ONBOARD_COMPUTER), distinct from a
    /// ground station's 190.
    pub component_id: u8,
    /// Autopilot system id; 0 (default) takes it from the first autopilot HEARTBEAT.
    pub target_system: u8,
    /// Autopilot component id; 0 (default) takes it from that HEARTBEAT.
    pub target_component: u8,
    /// Our HEARTBEAT period, ms (100..=10000). Default 1000 (1 Hz).
    #[serde(deserialize_with = "de_heartbeat_ms")]
    pub heartbeat_ms: u64,
    /// The link is down when no autopilot HEARTBEAT came for this long, ms (500..=60000).
    /// Default 3000 (three missed 1 Hz heartbeats). While down no IMU sample is published,
    /// so the daemon's stale-IMU fault takes over.
    #[serde(deserialize_with = "de_link_timeout_ms")]
    pub link_timeout_ms: u64,
    /// The IMU message: "scaled_imu2" (default), "scaled_imu" or "raw_imu".
    pub imu_message: ImuMessage,
    /// Requested IMU message rate, Hz (1..=1000). Default 100. One sample is published
    /// per IMU message received.
    #[serde(deserialize_with = "de_imu_rate_hz")]
    pub imu_rate_hz: f64,
    /// Requested ATTITUDE rate, Hz (0 = not requested). Default 50.
    #[serde(deserialize_with = "de_attitude_rate_hz")]
    pub attitude_rate_hz: f64,
    /// Where the depth sensor's pressure comes from: "auto" (default: the barometer the
    /// autopilot's device ids say is in the water; no depth until they came, and none, said,
    /// when it is barometer 3, which ArduSub reports in no message), "scaled_pressure" or
    /// "scaled_pressure2" (used unless the autopilot says that barometer is in the air: an
    /// air barometer's depth is about 0 m at any depth). docs/hardware.md.
    pub pressure_message: PressureMessage,
    /// Requested rate of the depth's pressure message, Hz (0 = no depth). Default 20.
    #[serde(deserialize_with = "de_pressure_rate_hz")]
    pub pressure_rate_hz: f64,
    /// "imu" (default) or "attitude".
    pub gyro_source: GyroSource,
    /// "motor_test" (default) or "rc_override".
    pub output: OutputMode,
    /// `rc_override` only: the longest the autopilot may keep our last override after we
    /// stop, s (0.25..=120; ArduSub's `FS_PILOT_TIMEOUT` is 0.1-3). Default 1.0. ArduSub
    /// keeps driving an override until its pilot-input failsafe neutralises the channels, so
    /// until the autopilot says `FS_PILOT_INPUT` != 0 and `FS_PILOT_TIMEOUT` <= this (and
    /// `RC_OVERRIDE_TIME` != 0), overrides carry neutral only and `driver_status` says why.
    /// ArduSub's default timeout, 3 s, is refused by this default.
    #[serde(deserialize_with = "de_max_override_hold_s")]
    pub max_override_hold_s: f64,
    /// Resend period of the thrust messages while nothing changes, ms (10..=250). Default
    /// 100, five resends within ArduSub's 500 ms motor-test timeout. Changes are sent at once.
    #[serde(deserialize_with = "de_resend_ms")]
    pub resend_ms: u64,
    /// param4 (timeout, s) of DO_MOTOR_TEST, ms (100..=10000). Default 500. ArduSub
    /// ignores it (its own timeout is 500 ms); ArduCopter ends the test after it.
    #[serde(deserialize_with = "de_motor_test_timeout_ms")]
    pub motor_test_timeout_ms: u64,
    /// How long to wait for a COMMAND_ACK, ms (50..=10000). Default 1000.
    #[serde(deserialize_with = "de_command_timeout_ms")]
    pub command_timeout_ms: u64,
    /// Retries of a command that got no ACK (0..=20). Default 3.
    #[serde(deserialize_with = "de_command_retries")]
    pub command_retries: u32,
    /// Arm the vehicle (MAV_CMD_COMPONENT_ARM_DISARM) once the link is up, and disarm on
    /// exit. Default false: arm from the ground station.
    pub arm: bool,
    /// Density of the water, kg/m^3 (900..=1100). Default 997 (fresh); sea water ~1025.
    #[serde(deserialize_with = "de_density")]
    pub fluid_density_kg_m3: f64,
    /// Absolute pressure at the surface, hPa (800..=1200). Default 1013.25. Measure it
    /// with the vehicle at the surface for accurate depth.
    #[serde(deserialize_with = "de_surface_hpa")]
    pub surface_pressure_hpa: f64,
    /// A depth (or ATTITUDE rate) older than this is not attached to a sample, ms.
    /// Default 500.
    #[serde(deserialize_with = "de_depth_timeout_ms")]
    pub depth_timeout_ms: u64,
    /// Receive timeout of the UDP socket, ms (1..=1000): how often the receive thread
    /// looks at the stop flag. Default 50.
    #[serde(deserialize_with = "de_read_timeout_ms")]
    pub read_timeout_ms: u64,
}

impl Default for MavlinkConfig {
    fn default() -> Self {
        MavlinkConfig {
            address: "udpin:127.0.0.1:14660".to_string(),
            system_id: 255,
            component_id: 191,
            target_system: 0,
            target_component: 0,
            heartbeat_ms: 1000,
            link_timeout_ms: 3000,
            imu_message: ImuMessage::ScaledImu2,
            imu_rate_hz: 100.0,
            attitude_rate_hz: 50.0,
            pressure_message: PressureMessage::Auto,
            pressure_rate_hz: 20.0,
            gyro_source: GyroSource::Imu,
            output: OutputMode::MotorTest,
            max_override_hold_s: 1.0,
            resend_ms: 100,
            motor_test_timeout_ms: 500,
            command_timeout_ms: 1000,
            command_retries: 3,
            arm: false,
            fluid_density_kg_m3: 997.0,
            surface_pressure_hpa: 1013.25,
            depth_timeout_ms: 500,
            read_timeout_ms: 50,
        }
    }
}

impl MavlinkConfig {
    /// Highest output channel the output mode can address.
    pub fn max_channel(&self) -> u32 {
        match self.output {
            OutputMode::MotorTest => 16,
            // ArduSub's pilot-input failsafe, what takes an override we leave back to
            // neutral, resets the six RCMAP channels only (1-6 by default; `override_hold`).
            OutputMode::RcOverride => 6,
        }
    }
}
