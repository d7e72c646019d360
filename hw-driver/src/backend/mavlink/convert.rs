//! MAVLink units to SI, body frame.
//!
//! SCALED_IMU / SCALED_IMU2 (and ArduPilot's RAW_IMU, which it fills with the same scaled
//! values): acceleration in mG, angular rate in mrad/s, magnetic field in mgauss, body
//! frame FRD (ArduPilot's body frame: x forward, y right, z down), the same axes as the
//! protocol. ArduPilot sends `accel * 1000 / GRAVITY_MSS` of its INS accelerometer, which
//! is specific force: level at rest reads z = -1000 mG, i.e. -9.80665 m/s^2, exactly the
//! protocol's convention. No sign flips are needed.
//!
//! SCALED_PRESSURE / SCALED_PRESSURE2 (barometers 1 and 2; which is the water's: `water_baro`):
//! `press_abs` in hPa.

use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
use thruster_protocol::ImuReading;

use crate::config::ImuMessage;

/// ArduPilot's GRAVITY_MSS, m/s^2 per g.
pub const GRAVITY_MSS: f64 = 9.80665;

/// mG -> m/s^2.
pub const MS2_PER_MG: f64 = GRAVITY_MSS / 1000.0;

/// mrad/s -> rad/s.
pub const RADPS_PER_MRADPS: f64 = 1e-3;

/// mgauss -> uT (1 gauss = 100 uT).
pub const UT_PER_MGAUSS: f64 = 0.1;

/// The reading in the nine fields of a SCALED_IMU-style message: the magnetometer `None` when
/// all three are zero (no compass: ArduPilot sends zeros). The message has no time, depth or
/// number: `t_ns`, `depth` and `seq` are left for the conversation (it stamps the reading on
/// receipt and adds the depth of its own pressure message) and the driver.
pub fn scaled_imu(acc: [i16; 3], gyro: [i16; 3], mag: [i16; 3]) -> ImuReading {
    ImuReading {
        gyro: gyro.map(|v| f64::from(v) * RADPS_PER_MRADPS),
        accel: acc.map(|v| f64::from(v) * MS2_PER_MG),
        mag: (mag != [0, 0, 0]).then(|| mag.map(|v| f64::from(v) * UT_PER_MGAUSS)),
        ..ImuReading::default()
    }
}

/// Largest specific force accepted on any axis, m/s^2 (3 g). An underwater vehicle sees about
/// 1 g plus its own manoeuvring; more means the message does not hold what we think it holds
/// (e.g. an autopilot sending ADC counts in RAW_IMU: 1 g = 4096 counts at +-8 g, which read
/// as mG would be 4.1 g), or a glitch. Publishing it would corrupt the estimate.
pub const MAX_ACCEL_MSS: f64 = 3.0 * GRAVITY_MSS;

/// Largest angular rate accepted on any axis, rad/s (2000 deg/s, the widest range ArduPilot
/// configures its gyros for).
pub const MAX_GYRO_RADPS: f64 = 2000.0 * std::f64::consts::PI / 180.0;

/// Largest magnetic field accepted on any axis, uT (the Earth's field is 25-65 uT; a field
/// of 1 mT near a thruster's magnets is already useless as a compass).
pub const MAX_MAG_UT: f64 = 1000.0;

/// Why a reading is not physically plausible, if it is not. The magnetometer is judged on
/// its own by [`plausible_mag`]: a bad compass must not cost the gyro and accelerometer.
pub fn implausible(imu: &ImuReading) -> Option<&'static str> {
    let over = |v: &[f64; 3], max: f64| v.iter().any(|x| !x.is_finite() || x.abs() > max);
    // ArduPilot sends SCALED_IMU2 when a second IMU *or compass* exists, with the missing
    // IMU's acceleration and rate left at zero (`GCS_MAVLINK::send_scaled_imu`): on a board
    // with one IMU and two compasses (a Navigator) the default `imu_message` gives exact
    // zeros. An accelerometer in the water never reads exactly 0 on every axis (it feels g).
    if imu.accel == [0.0; 3] {
        Some("no acceleration at all (an IMU instance the autopilot does not have)")
    } else if over(&imu.accel, MAX_ACCEL_MSS) {
        Some("acceleration beyond 3 g")
    } else if over(&imu.gyro, MAX_GYRO_RADPS) {
        Some("angular rate beyond 2000 deg/s")
    } else {
        None
    }
}

/// The magnetometer reading if it is plausible.
pub fn plausible_mag(mag: Option<[f64; 3]>) -> Option<[f64; 3]> {
    mag.filter(|m| m.iter().all(|x| x.is_finite() && x.abs() <= MAX_MAG_UT))
}

/// Depth below the surface, m, from absolute pressure in hPa.
pub fn depth_from_hpa(press_abs_hpa: f64, surface_hpa: f64, density_kg_m3: f64) -> f64 {
    (press_abs_hpa - surface_hpa) * 100.0 / (density_kg_m3 * GRAVITY_MSS)
}

/// The reading in `msg` if it is the configured IMU message.
pub fn imu_reading(msg: &MavMessage, which: ImuMessage) -> Option<ImuReading> {
    match (msg, which) {
        (MavMessage::SCALED_IMU2(d), ImuMessage::ScaledImu2) => Some(scaled_imu(
            [d.xacc, d.yacc, d.zacc],
            [d.xgyro, d.ygyro, d.zgyro],
            [d.xmag, d.ymag, d.zmag],
        )),
        (MavMessage::SCALED_IMU(d), ImuMessage::ScaledImu) => Some(scaled_imu(
            [d.xacc, d.yacc, d.zacc],
            [d.xgyro, d.ygyro, d.zgyro],
            [d.xmag, d.ymag, d.zmag],
        )),
        // ArduPilot fills RAW_IMU with the same scaled values as SCALED_IMU.
        (MavMessage::RAW_IMU(d), ImuMessage::RawImu) => Some(scaled_imu(
            [d.xacc, d.yacc, d.zacc],
            [d.xgyro, d.ygyro, d.zgyro],
            [d.xmag, d.ymag, d.zmag],
        )),
        _ => None,
    }
}

/// ATTITUDE's body rates, rad/s.
pub fn attitude_rates(a: &ATTITUDE_DATA) -> [f64; 3] {
    [
        f64::from(a.rollspeed),
        f64::from(a.pitchspeed),
        f64::from(a.yawspeed),
    ]
}

#[cfg(test)]
mod tests {
    #[test]
    fn implausible_readings_are_named_and_good_ones_pass() {
        use super::*;
        let rest = scaled_imu([0, 0, -1000], [0, 0, 0], [200, 0, 400]);
        assert_eq!(implausible(&rest), None);
        // RAW_IMU from an autopilot that sends ADC counts: 1 g = 4096 counts.
        let counts = scaled_imu([0, 0, -4096], [0, 0, 0], [0, 0, 0]);
        assert_eq!(implausible(&counts), Some("acceleration beyond 3 g"));
        // SCALED_IMU2 of a board with one IMU and a second compass: zeros and a field.
        let absent = scaled_imu([0, 0, 0], [0, 0, 0], [200, 0, 400]);
        assert!(implausible(&absent).unwrap().contains("does not have"));
        // Every i16 mrad/s is within 2000 deg/s; only other sources can exceed it.
        assert_eq!(
            implausible(&scaled_imu([0, 0, -1000], [0, 0, i16::MAX], [0; 3])),
            None
        );
        let spin = ImuReading {
            gyro: [0.0, 0.0, 40.0],
            ..rest
        };
        assert_eq!(implausible(&spin), Some("angular rate beyond 2000 deg/s"));
        let nan = ImuReading {
            accel: [f64::NAN, 0.0, 0.0],
            ..rest
        };
        assert!(implausible(&nan).is_some());
        // Just under 3 g is still accepted; the field of a magnet is not a compass.
        assert_eq!(implausible(&scaled_imu([2990, 0, 0], [0; 3], [0; 3])), None);
        assert_eq!(
            plausible_mag(Some([30.0, 0.0, 40.0])),
            Some([30.0, 0.0, 40.0])
        );
        assert_eq!(plausible_mag(Some([3000.0, 0.0, 0.0])), None);
    }

    use super::*;

    #[test]
    fn level_at_rest_is_minus_g_on_z() {
        let s = scaled_imu([0, 0, -1000], [0, 0, 0], [0, 0, 0]);
        assert_eq!(s.accel, [0.0, 0.0, -GRAVITY_MSS]);
        assert_eq!(s.mag, None);
    }

    #[test]
    fn units() {
        let s = scaled_imu([500, -250, -981], [100, -200, 3000], [200, -50, 400]);
        assert!((s.accel[0] - 4.903325).abs() < 1e-12);
        assert_eq!(s.gyro, [0.1, -0.2, 3.0]);
        let m = s.mag.unwrap();
        for (a, b) in m.iter().zip([20.0, -5.0, 40.0]) {
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn depth() {
        // 10 m of sea water (1025 kg/m^3) is 1005.2 hPa above the surface.
        let p = 1013.25 + 10.0 * 1025.0 * GRAVITY_MSS / 100.0;
        assert!((depth_from_hpa(p, 1013.25, 1025.0) - 10.0).abs() < 1e-9);
        assert!(depth_from_hpa(1000.0, 1013.25, 997.0) < 0.0);
    }
}
