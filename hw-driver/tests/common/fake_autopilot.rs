//! A fake ArduSub on loopback UDP, written with the `mavlink` crate: sends HEARTBEATs
//! (1 Hz, armed or not), ACKs MAV_CMD_SET_MESSAGE_INTERVAL and streams SCALED_IMU2,
//! RAW_IMU, ATTITUDE, SCALED_PRESSURE and SCALED_PRESSURE2 at the requested intervals (the
//! two pressures also at ArduSub's default 2 Hz: its RAW_SENS stream; the water's pressure
//! in the water barometer's message, the tube's air in the other), handles DO_MOTOR_TEST
//! like ArduSub (param1 is the 0-based motor index, FAILED when disarmed or for a motor the
//! frame does not have; 500 ms without one ends motor-test mode with a disarm, counted as
//! a lapse), answers PARAM_REQUEST_READ by name from its parameters (ArduSub's defaults for
//! `FS_PILOT_INPUT` 2, `FS_PILOT_TIMEOUT` 3 s, `RC_OVERRIDE_TIME` 3 s, RCMAP and `RCn_TRIM`
//! 1500; outputs 1-8 RCINn passthrough; a Navigator's
//! barometers, `BARO1_DEVID`..`BARO3_DEVID`: BMP280, Bar30, none), sends SYS_STATUS with the battery's voltage and current with each
//! HEARTBEAT (ArduSub streams it by default, SR0_EXT_STAT), and records everything it receives with the CLOCK_MONOTONIC time of
//! reception. Bounded: the thread ends after `MAX_LIFETIME`.

use std::collections::HashMap;
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::*;
use mavlink::{Connectable, ConnectionAddress, MavConnection, MavHeader, UdpConfig, UdpMode};
use thruster_hw::clock::monotonic_ns;

const MAX_LIFETIME: Duration = Duration::from_secs(120);

/// Motors of the fake's frame (a BlueROV2 Heavy: motors 0..=7).
pub const MOTORS: u32 = 8;

/// ArduSub's motor-test timeout (`Sub::verify_motor_test`).
pub const MOTOR_TEST_TIMEOUT_NS: u64 = 500_000_000;

/// The tube's air, hPa: what an onboard barometer reads at any depth.
pub const AIR_HPA: f32 = 1013.25;

/// A barometer's device id as ArduPilot's `make_bus_id` builds it.
pub fn devid(bus_type: u32, address: u32, devtype: u32) -> f32 {
    (bus_type | address << 8 | devtype << 16) as f32
}

/// Barometers 1-3 of a Navigator: a BMP280 onboard (I2C 0x76), the Bar30 (I2C 0x76, type
/// 0x12), none. The water's is instance 1.
pub const NAVIGATOR_BAROS: [(u32, u32, u32); 3] = [(1, 0x76, 0x03), (1, 0x76, 0x12), (0, 0, 0)];
/// A Cube's: two MS5611 on SPI, the Bar30 third (ArduSub reports it in no message).
pub const CUBE_BAROS: [(u32, u32, u32); 3] = [(2, 1, 0x0b), (2, 3, 0x0b), (1, 0x76, 0x12)];

/// What the fake does and what it saw.
#[derive(Debug, Clone)]
pub struct ApState {
    /// Send HEARTBEATs.
    pub heartbeat: bool,
    /// Report armed (and accept motor tests).
    pub armed: bool,
    /// Answer SET_MESSAGE_INTERVAL (with `interval_result`).
    pub ack_requests: bool,
    pub interval_result: MavResult,
    /// Streamed IMU (SCALED_IMU2 units: mG, mrad/s, mgauss) and pressure (hPa).
    pub acc: [i16; 3],
    pub gyro: [i16; 3],
    pub mag: [i16; 3],
    pub press_hpa: f32,
    /// The barometer instance in the water (its message carries `press_hpa`; the others
    /// [`AIR_HPA`]). Set with [`ApState::baros`].
    pub water_baro: usize,
    /// SYS_STATUS's battery: voltage, mV (u16::MAX: none), current, cA (-1: none).
    pub battery_mv: u16,
    pub battery_ca: i16,
    /// Requested intervals by message id, us.
    pub intervals: HashMap<u32, u64>,
    /// Received, with reception time (ns, CLOCK_MONOTONIC).
    pub heartbeats: Vec<(u64, MavHeader, HEARTBEAT_DATA)>,
    pub commands: Vec<(u64, MavHeader, COMMAND_LONG_DATA)>,
    pub overrides: Vec<(u64, MavHeader, RC_CHANNELS_OVERRIDE_DATA)>,
    /// IMU messages sent.
    pub imu_sent: u64,
    /// In motor-test mode (a DO_MOTOR_TEST was accepted and none lapsed since).
    pub motor_test_mode: bool,
    pub last_motor_test_ns: u64,
    /// Motor-test timeouts (each disarmed the fake, as on ArduSub).
    pub lapses: u64,
    /// RC channels 1-8 in force (`radio_in`): the newest override per channel, streamed as
    /// RC_CHANNELS (id 65) when asked for.
    pub rc_in: [u16; 8],
    /// A ground station's joystick: these values overwrite `rc_in` every round, as ArduSub's
    /// MANUAL_CONTROL handling overrides channels 1-8 on every message.
    pub joystick: Option<[u16; 8]>,
    /// Parameters answered by name (PARAM_VALUE, REAL32).
    pub params: HashMap<String, f32>,
    /// PARAM_REQUEST_READ received: the name asked for.
    pub param_requests: Vec<(u64, String)>,
}

impl Default for ApState {
    fn default() -> Self {
        ApState {
            heartbeat: true,
            armed: true,
            ack_requests: true,
            interval_result: MavResult::MAV_RESULT_ACCEPTED,
            acc: [0, 0, -1000],
            gyro: [0; 3],
            mag: [0; 3],
            press_hpa: 1013.25,
            water_baro: 1,
            battery_mv: 15_800,
            battery_ca: 1_250,
            // ArduSub's RAW_SENS stream at its default 2 Hz.
            intervals: HashMap::from([(29, 500_000), (137, 500_000)]),
            heartbeats: Vec::new(),
            commands: Vec::new(),
            overrides: Vec::new(),
            imu_sent: 0,
            motor_test_mode: false,
            last_motor_test_ns: 0,
            lapses: 0,
            rc_in: [1500; 8],
            joystick: None,
            params: HashMap::from([
                ("FS_PILOT_INPUT".to_string(), 2.0),
                ("FS_PILOT_TIMEOUT".to_string(), 3.0),
                ("RC_OVERRIDE_TIME".to_string(), 3.0),
                ("BATT_OPTIONS".to_string(), 0.0),
            ])
            .into_iter()
            // ArduSub's RCMAP (Parameters.h: roll 2, pitch 1; throttle 3, yaw 4, forward 5,
            // lateral 6) and RCn_TRIM (1500).
            .chain(
                [
                    ("ROLL", 2.0),
                    ("PITCH", 1.0),
                    ("THROTTLE", 3.0),
                    ("YAW", 4.0),
                ]
                .into_iter()
                .chain([("FORWARD", 5.0), ("LATERAL", 6.0)])
                .map(|(axis, ch)| (format!("RCMAP_{axis}"), ch)),
            )
            .chain((1..=8).map(|n| (format!("RC{n}_TRIM"), 1500.0)))
            // Outputs set up for `rc_override`: output n passes RC input n through.
            .chain((1..=16).map(|n| {
                let f = if n <= 8 { 50.0 + n as f32 } else { 0.0 };
                (format!("SERVO{n}_FUNCTION"), f)
            }))
            .collect(),
            param_requests: Vec::new(),
        }
        .baros(NAVIGATOR_BAROS)
    }
}

impl ApState {
    /// These barometers (bus type, address, device type; bus type 0: none): their device ids
    /// as parameters, and the first water sensor's message carries the water's pressure.
    pub fn baros(mut self, layout: [(u32, u32, u32); 3]) -> Self {
        for (i, (bus, address, devtype)) in layout.into_iter().enumerate() {
            let id = if bus == 0 {
                0.0
            } else {
                devid(bus, address, devtype)
            };
            self.params.insert(format!("BARO{}_DEVID", i + 1), id);
        }
        self.water_baro = layout
            .iter()
            .position(|&(bus, _, t)| bus != 0 && matches!(t, 0x09 | 0x12 | 0x18))
            .unwrap_or(3);
        self
    }

    /// DO_MOTOR_TEST commands received.
    pub fn motor_tests(&self) -> Vec<(u64, COMMAND_LONG_DATA)> {
        self.commands
            .iter()
            .filter(|(_, _, c)| c.command == MavCmd::MAV_CMD_DO_MOTOR_TEST)
            .map(|(t, _, c)| (*t, c.clone()))
            .collect()
    }

    /// SET_MESSAGE_INTERVAL commands received.
    pub fn interval_requests(&self) -> Vec<(u64, COMMAND_LONG_DATA)> {
        self.commands
            .iter()
            .filter(|(_, _, c)| c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL)
            .map(|(t, _, c)| (*t, c.clone()))
            .collect()
    }
}

pub struct FakeAutopilot {
    port: u16,
    /// Client mode: the port the driver listens on.
    driver_port: Option<u16>,
    raw: UdpSocket,
    state: Arc<Mutex<ApState>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// The fake's ids.
pub const AP_SYS: u8 = 1;
pub const AP_COMP: u8 = 1;

impl FakeAutopilot {
    /// A fake that listens (the driver uses `udpout`).
    pub fn start() -> FakeAutopilot {
        Self::start_on(None)
    }

    /// A fake that sends to a driver listening on `driver_port` (`udpin`), like a BlueOS
    /// "UDP Client" endpoint: it talks first.
    pub fn start_client(driver_port: u16) -> FakeAutopilot {
        Self::start_on(Some(driver_port))
    }

    fn start_on(client_of: Option<u16>) -> FakeAutopilot {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        let port = socket.local_addr().unwrap().port();
        let raw = socket.try_clone().unwrap();
        let mode = match client_of {
            Some(p) => {
                socket.connect(("127.0.0.1", p)).unwrap();
                UdpMode::Udpout
            }
            None => UdpMode::Udpin,
        };
        let cfg = UdpConfig::from_socket(socket, mode)
            .unwrap()
            .read_timeout(Duration::from_millis(1));
        let conn = ConnectionAddress::Udp(cfg).connect::<MavMessage>().unwrap();
        let state = Arc::new(Mutex::new(ApState::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (state, stop) = (state.clone(), stop.clone());
            let client = client_of.is_some();
            std::thread::spawn(move || run(conn, state, stop, client))
        };
        FakeAutopilot {
            port,
            driver_port: client_of,
            raw,
            state,
            stop,
            thread: Some(thread),
        }
    }

    /// The driver's `mavlink.address` for this fake.
    pub fn address(&self) -> String {
        match self.driver_port {
            Some(p) => format!("udpin:127.0.0.1:{p}"),
            None => format!("udpout:127.0.0.1:{}", self.port),
        }
    }

    /// Sends `bytes` as one datagram from the fake's own address to `port` (an empty or
    /// garbage datagram from the autopilot's address).
    pub fn send_raw(&self, bytes: &[u8], port: u16) {
        self.raw.send_to(bytes, ("127.0.0.1", port)).unwrap();
    }

    /// Reads or changes the state.
    pub fn with<R>(&self, f: impl FnOnce(&mut ApState) -> R) -> R {
        f(&mut self.state.lock().unwrap())
    }
}

impl Drop for FakeAutopilot {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn header() -> MavHeader {
    MavHeader {
        system_id: u32::from(AP_SYS),
        component_id: AP_COMP,
        sequence: 0,
    }
}

fn run(
    conn: impl MavConnection<MavMessage>,
    state: Arc<Mutex<ApState>>,
    stop: Arc<AtomicBool>,
    client: bool,
) {
    let end = Instant::now() + MAX_LIFETIME;
    let mut next_hb = monotonic_ns();
    // Like a router that learns its peer from the first packet: the first HEARTBEAT goes
    // out as soon as someone talks to us, then every second. A client talks first.
    let mut peer_seen = client;
    let mut next_stream: HashMap<u32, u64> = HashMap::new();
    let mut streamed_at: HashMap<u32, u64> = HashMap::new();
    let send = |m: &MavMessage| {
        let _ = conn.send(&header(), m);
    };
    while !stop.load(Ordering::Relaxed) && Instant::now() < end {
        if let Ok((h, msg)) = conn.recv() {
            let t = monotonic_ns();
            peer_seen = true;
            let mut s = state.lock().unwrap();
            match msg {
                MavMessage::HEARTBEAT(hb) => s.heartbeats.push((t, h, hb)),
                MavMessage::RC_CHANNELS_OVERRIDE(o) => {
                    let values = [
                        o.chan1_raw,
                        o.chan2_raw,
                        o.chan3_raw,
                        o.chan4_raw,
                        o.chan5_raw,
                        o.chan6_raw,
                        o.chan7_raw,
                        o.chan8_raw,
                    ];
                    // UINT16_MAX: "ignore this channel" (GCS_MAVLINK::handle_rc_channels_override).
                    for (slot, v) in s.rc_in.iter_mut().zip(values) {
                        if v != u16::MAX {
                            *slot = v;
                        }
                    }
                    s.overrides.push((t, h, o))
                }
                MavMessage::PARAM_REQUEST_READ(r) => {
                    let name = r.param_id.to_str().unwrap_or("").trim_end_matches('\0');
                    s.param_requests.push((t, name.to_string()));
                    // ArduPilot's GCS_Param answers a name it has with PARAM_VALUE, and
                    // sends nothing for one it lacks.
                    let value = s.params.get(name).copied();
                    let count = s.params.len() as u16;
                    drop(s);
                    if let Some(param_value) = value {
                        send(&MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
                            param_value,
                            param_count: count,
                            param_index: 0,
                            param_id: name.into(),
                            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
                        }));
                    }
                }
                MavMessage::COMMAND_LONG(c) => {
                    s.commands.push((t, h, c.clone()));
                    let result = match c.command {
                        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL if s.ack_requests => {
                            if s.interval_result == MavResult::MAV_RESULT_ACCEPTED {
                                s.intervals.insert(c.param1 as u32, c.param2 as u64);
                            }
                            Some(s.interval_result)
                        }
                        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => None,
                        // As Sub::handle_do_motor_test -> AP_MotorsMatrix::output_test_num:
                        // param1 is the 0-based motor index; a motor the frame lacks fails.
                        MavCmd::MAV_CMD_DO_MOTOR_TEST
                            if s.armed && c.param1 >= 0.0 && (c.param1 as u32) < MOTORS =>
                        {
                            s.motor_test_mode = true;
                            s.last_motor_test_ns = t;
                            Some(MavResult::MAV_RESULT_ACCEPTED)
                        }
                        MavCmd::MAV_CMD_DO_MOTOR_TEST => Some(MavResult::MAV_RESULT_FAILED),
                        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
                            s.armed = c.param1 == 1.0;
                            Some(MavResult::MAV_RESULT_ACCEPTED)
                        }
                        _ => Some(MavResult::MAV_RESULT_UNSUPPORTED),
                    };
                    drop(s);
                    if let Some(result) = result {
                        send(&MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                            command: c.command,
                            result,
                        }));
                    }
                }
                _ => {}
            }
        }
        let now = monotonic_ns();
        {
            // Sub::verify_motor_test: no DO_MOTOR_TEST for 500 ms ends the test and disarms.
            let mut s = state.lock().unwrap();
            if s.motor_test_mode && now > s.last_motor_test_ns + MOTOR_TEST_TIMEOUT_NS {
                s.motor_test_mode = false;
                s.armed = false;
                s.lapses += 1;
            }
        }
        let s = state.lock().unwrap().clone_controls();
        if now >= next_hb && peer_seen {
            if s.heartbeat {
                send(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 19, // ArduSub MANUAL
                    mavtype: MavType::MAV_TYPE_SUBMARINE,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                    base_mode: if s.armed {
                        MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                            | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    } else {
                        MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    },
                    system_status: MavState::MAV_STATE_ACTIVE,
                    mavlink_version: 3,
                }));
                send(&MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                    voltage_battery: s.battery_mv,
                    current_battery: s.battery_ca,
                    battery_remaining: -1,
                    ..SYS_STATUS_DATA::DEFAULT
                }));
            }
            next_hb = now + 1_000_000_000;
        }
        for (&id, &interval_us) in &s.intervals {
            // A new interval is in force at once, as ArduPilot reschedules the message.
            if streamed_at.insert(id, interval_us) != Some(interval_us) {
                next_stream.insert(id, now);
            }
            let due = next_stream.entry(id).or_insert(now);
            if now < *due {
                continue;
            }
            *due += interval_us * 1000;
            if *due <= now {
                *due = now + interval_us * 1000;
            }
            let boot_ms = (now / 1_000_000) as u32;
            let msg = match id {
                116 => MavMessage::SCALED_IMU2(SCALED_IMU2_DATA {
                    time_boot_ms: boot_ms,
                    xacc: s.acc[0],
                    yacc: s.acc[1],
                    zacc: s.acc[2],
                    xgyro: s.gyro[0],
                    ygyro: s.gyro[1],
                    zgyro: s.gyro[2],
                    xmag: s.mag[0],
                    ymag: s.mag[1],
                    zmag: s.mag[2],
                }),
                27 => MavMessage::RAW_IMU(RAW_IMU_DATA {
                    time_usec: now / 1000,
                    xacc: s.acc[0],
                    yacc: s.acc[1],
                    zacc: s.acc[2],
                    xgyro: s.gyro[0],
                    ygyro: s.gyro[1],
                    zgyro: s.gyro[2],
                    xmag: s.mag[0],
                    ymag: s.mag[1],
                    zmag: s.mag[2],
                }),
                30 => MavMessage::ATTITUDE(ATTITUDE_DATA {
                    time_boot_ms: boot_ms,
                    rollspeed: f32::from(s.gyro[0]) / 1000.0,
                    pitchspeed: f32::from(s.gyro[1]) / 1000.0,
                    yawspeed: f32::from(s.gyro[2]) / 1000.0,
                    ..ATTITUDE_DATA::DEFAULT
                }),
                65 => {
                    let rc = {
                        let mut st = state.lock().unwrap();
                        if let Some(j) = st.joystick {
                            st.rc_in = j;
                        }
                        st.rc_in
                    };
                    MavMessage::RC_CHANNELS(RC_CHANNELS_DATA {
                        time_boot_ms: boot_ms,
                        chancount: 16,
                        chan1_raw: rc[0],
                        chan2_raw: rc[1],
                        chan3_raw: rc[2],
                        chan4_raw: rc[3],
                        chan5_raw: rc[4],
                        chan6_raw: rc[5],
                        chan7_raw: rc[6],
                        chan8_raw: rc[7],
                        ..RC_CHANNELS_DATA::DEFAULT
                    })
                }
                29 => MavMessage::SCALED_PRESSURE(SCALED_PRESSURE_DATA {
                    time_boot_ms: boot_ms,
                    press_abs: if s.water_baro == 0 {
                        s.press_hpa
                    } else {
                        AIR_HPA
                    },
                    press_diff: 0.0,
                    temperature: 2000,
                }),
                137 => MavMessage::SCALED_PRESSURE2(SCALED_PRESSURE2_DATA {
                    time_boot_ms: boot_ms,
                    press_abs: if s.water_baro == 1 {
                        s.press_hpa
                    } else {
                        AIR_HPA
                    },
                    press_diff: 0.0,
                    temperature: 2000,
                }),
                _ => continue,
            };
            send(&msg);
            if id == 116 || id == 27 {
                state.lock().unwrap().imu_sent += 1;
            }
        }
    }
}

impl ApState {
    /// The controls only (cheap to copy out of the lock each round).
    fn clone_controls(&self) -> ApState {
        ApState {
            heartbeat: self.heartbeat,
            armed: self.armed,
            ack_requests: self.ack_requests,
            interval_result: self.interval_result,
            acc: self.acc,
            gyro: self.gyro,
            mag: self.mag,
            press_hpa: self.press_hpa,
            water_baro: self.water_baro,
            battery_mv: self.battery_mv,
            battery_ca: self.battery_ca,
            intervals: self.intervals.clone(),
            heartbeats: Vec::new(),
            commands: Vec::new(),
            overrides: Vec::new(),
            imu_sent: 0,
            motor_test_mode: self.motor_test_mode,
            last_motor_test_ns: self.last_motor_test_ns,
            lapses: self.lapses,
            rc_in: self.rc_in,
            joystick: self.joystick,
            params: HashMap::new(),
            param_requests: Vec::new(),
        }
    }
}
