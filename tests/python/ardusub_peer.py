"""An ArduSub stand-in written with pymavlink (MAVLink's reference implementation, not the
`mavlink` crate our driver and our own fake autopilot use), for
tests/tests/mavlink_reference_peer.rs: what thruster-hw sends is decoded, and what it reads is
encoded, by code we did not write.

It talks first (udpout to the driver's udpin port, as a BlueOS endpoint does) and behaves as
ArduSub does for what the driver uses: HEARTBEAT (submarine, ArduPilot, armed) and SYS_STATUS
once a second; COMMAND_ACK for SET_MESSAGE_INTERVAL, then the message at that interval
(SCALED_IMU2, ATTITUDE, SCALED_PRESSURE2); COMMAND_ACK ACCEPTED for DO_MOTOR_TEST while armed;
PARAM_VALUE for a PARAM_REQUEST_READ of a parameter it has, nothing otherwise. After
--seconds it prints one JSON object with what it received and exits.

usage: ardusub_peer.py --port PORT --seconds S [--param NAME=VALUE ...]
(parameters default to ArduSub's: FS_PILOT_INPUT 2, FS_PILOT_TIMEOUT 3, RC_OVERRIDE_TIME 3;
a Navigator's barometers: BARO1_DEVID a BMP280, BARO2_DEVID the Bar30, BARO3_DEVID none, sent
as ArduPilot sends an INT32 parameter: its value as a float, type INT32; BATT_OPTIONS 0)
"""

import argparse
import json
import os
import sys
import time

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

m = mavutil.mavlink

# The still vehicle's IMU, SCALED_IMU2 units (mG, mrad/s, mgauss): level, 1 g up in body z.
ACC = (0, 0, -1000)
GYRO = (0, 0, 0)
MAG = (200, 0, 400)
PRESS_HPA = 1013.25
BATTERY_MV = 15800
BATTERY_CA = 1250


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--seconds", type=float, required=True)
    ap.add_argument("--param", action="append", default=[])
    args = ap.parse_args()
    params = {
        "FS_PILOT_INPUT": 2.0,
        "FS_PILOT_TIMEOUT": 3.0,
        "RC_OVERRIDE_TIME": 3.0,
        # AP_HAL device ids: bus type 1 (I2C), address 0x76, device type 0x03 (BMP280) and
        # 0x12 (MS5837-30BA) in bits 16-23.
        "BARO1_DEVID": float(0x037601),
        "BARO2_DEVID": float(0x127601),
        "BARO3_DEVID": 0.0,
        "BATT_OPTIONS": 0.0,
        # ArduSub's RCMAP (roll 2, pitch 1, throttle 3, yaw 4, forward 5, lateral 6) and trims.
        "RCMAP_ROLL": 2.0,
        "RCMAP_PITCH": 1.0,
        "RCMAP_THROTTLE": 3.0,
        "RCMAP_YAW": 4.0,
        "RCMAP_FORWARD": 5.0,
        "RCMAP_LATERAL": 6.0,
        **{f"RC{n}_TRIM": 1500.0 for n in range(1, 9)},
        # Outputs set up for RC override: output n passes RC input n through (RCINn = 50 + n).
        **{f"SERVO{n}_FUNCTION": float(50 + n if n <= 8 else 0) for n in range(1, 17)},
    }
    for p in args.param:
        name, value = p.split("=", 1)
        params[name] = float(value)

    conn = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{args.port}",
        source_system=1,
        source_component=1,
        dialect="ardupilotmega",
    )
    start = time.monotonic()
    next_hb = start
    streams = {}  # message id -> [interval s, next due]
    rc_in = [1500] * 8  # RC channels 1-8 in force, reported in RC_CHANNELS
    seen = {
        "bad_data": 0,
        "types": {},
        "heartbeats": [],
        "intervals": {},
        "motor_tests": [],
        "overrides": [],
        "param_requests": [],
        "imu_sent": 0,
        "rc_channels_sent": 0,
        "other_commands": [],
    }

    def boot_ms():
        return int((time.monotonic() - start) * 1000) & 0xFFFFFFFF

    while time.monotonic() - start < args.seconds:
        msg = conn.recv_match(blocking=True, timeout=0.002)
        if msg is not None:
            kind = msg.get_type()
            seen["types"][kind] = seen["types"].get(kind, 0) + 1
            if kind == "BAD_DATA":
                seen["bad_data"] += 1
            elif kind == "HEARTBEAT":
                who = [msg.get_srcSystem(), msg.get_srcComponent(), msg.type, msg.autopilot]
                if who not in seen["heartbeats"]:
                    seen["heartbeats"].append(who)
            elif kind == "COMMAND_LONG":
                if msg.command == m.MAV_CMD_SET_MESSAGE_INTERVAL:
                    mid = int(msg.param1)
                    seen["intervals"][str(mid)] = msg.param2
                    if msg.param2 > 0:
                        streams[mid] = [msg.param2 / 1e6, time.monotonic()]
                    conn.mav.command_ack_send(msg.command, m.MAV_RESULT_ACCEPTED)
                elif msg.command == m.MAV_CMD_DO_MOTOR_TEST:
                    seen["motor_tests"].append(
                        [msg.param1, msg.param2, msg.param3, msg.param4, msg.param6,
                         msg.target_system, msg.target_component]
                    )
                    conn.mav.command_ack_send(msg.command, m.MAV_RESULT_ACCEPTED)
                else:
                    seen["other_commands"].append(msg.command)
                    conn.mav.command_ack_send(msg.command, m.MAV_RESULT_UNSUPPORTED)
            elif kind == "RC_CHANNELS_OVERRIDE":
                values = [msg.chan1_raw, msg.chan2_raw, msg.chan3_raw, msg.chan4_raw,
                          msg.chan5_raw, msg.chan6_raw, msg.chan7_raw, msg.chan8_raw]
                seen["overrides"].append(values)
                # What ArduSub applies: the newest override per channel (65535: ignore).
                rc_in[:] = [v if v != 65535 else old for v, old in zip(values, rc_in)]
            elif kind == "PARAM_REQUEST_READ":
                name = msg.param_id
                seen["param_requests"].append([name, msg.param_index])
                if name in params:
                    ptype = m.MAV_PARAM_TYPE_INT32 if name.endswith("_DEVID") else m.MAV_PARAM_TYPE_REAL32
                    conn.mav.param_value_send(
                        name.encode(), params[name], ptype, len(params), 0,
                    )
        now = time.monotonic()
        if now >= next_hb:
            conn.mav.heartbeat_send(
                m.MAV_TYPE_SUBMARINE,
                m.MAV_AUTOPILOT_ARDUPILOTMEGA,
                m.MAV_MODE_FLAG_SAFETY_ARMED | m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                19,  # ArduSub MANUAL
                m.MAV_STATE_ACTIVE,
            )
            conn.mav.sys_status_send(
                0, 0, 0, 0, BATTERY_MV, BATTERY_CA, -1, 0, 0, 0, 0, 0, 0
            )
            next_hb = now + 1.0
        for mid, due in streams.items():
            if now < due[1]:
                continue
            due[1] = max(due[1] + due[0], now)
            if mid == m.MAVLINK_MSG_ID_SCALED_IMU2:
                conn.mav.scaled_imu2_send(boot_ms(), *ACC, *GYRO, *MAG)
                seen["imu_sent"] += 1
            elif mid == m.MAVLINK_MSG_ID_ATTITUDE:
                conn.mav.attitude_send(boot_ms(), 0.0, 0.0, 0.0, *[g / 1000 for g in GYRO])
            elif mid == m.MAVLINK_MSG_ID_RC_CHANNELS:
                conn.mav.rc_channels_send(boot_ms(), 16, *rc_in, *([0] * 10), 255)
                seen["rc_channels_sent"] += 1
            elif mid == m.MAVLINK_MSG_ID_SCALED_PRESSURE2:
                conn.mav.scaled_pressure2_send(boot_ms(), PRESS_HPA, 0.0, 2000)
    json.dump(seen, sys.stdout)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
