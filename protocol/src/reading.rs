//! The one IMU reading in SI units every source and the core share, and its one conversion to
//! and from the wire's [`ImuSample`] (the copper-rs pattern: one payload type per sensor kind,
//! used by every source).
//!
//! A driver builds readings (the simulator's sensor models, a hardware backend's decoder),
//! publishes each as an [`ImuSample`] with [`ImuReading::to_sample`]; the daemon takes every
//! sample back with [`ImuReading::from_sample`] and hands the reading to its pure core. The
//! sample is the fixed `#[repr(C)]` layout shared memory needs (zeros and flags for absent
//! channels); the reading says absence with `Option`.

use serde::{Deserialize, Serialize};

use crate::ImuSample;

/// One IMU reading (gyro, accelerometer, optional magnetometer and depth), SI units, body
/// frame (x forward, y starboard, z down).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ImuReading {
    /// The publisher's number for it ([`ImuSample::seq`]). A sensor model or backend that
    /// does not number its readings leaves 0: the driver numbers what it publishes.
    pub seq: u64,
    /// When it was read, ns on the sensor's monotonic clock (the simulator's time since its
    /// start; a hardware driver's CLOCK_MONOTONIC).
    pub t_ns: u64,
    /// Angular rate about body x, y, z, rad/s.
    pub gyro: [f64; 3],
    /// Specific force along body x, y, z, m/s^2, gravity included: level at rest about
    /// `[0, 0, -9.81]`.
    pub accel: [f64; 3],
    /// Magnetic field along body x, y, z, uT, when there is a magnetometer.
    pub mag: Option<[f64; 3]>,
    /// Depth of the pressure sensor, m, positive down, when there is one.
    pub depth: Option<f64>,
}

impl ImuReading {
    /// The wire sample carrying this reading: absent channels as zeros without their flag.
    pub fn to_sample(&self) -> ImuSample {
        let mut flags = 0;
        if self.mag.is_some() {
            flags |= ImuSample::HAS_MAG;
        }
        if self.depth.is_some() {
            flags |= ImuSample::HAS_DEPTH;
        }
        ImuSample {
            seq: self.seq,
            t_ns: self.t_ns,
            gyro: self.gyro,
            accel: self.accel,
            mag: self.mag.unwrap_or([0.0; 3]),
            depth: self.depth.unwrap_or(0.0),
            flags,
        }
    }

    /// The reading a wire sample carries: a channel without its flag is absent, whatever its
    /// field holds.
    pub fn from_sample(s: &ImuSample) -> Self {
        ImuReading {
            seq: s.seq,
            t_ns: s.t_ns,
            gyro: s.gyro,
            accel: s.accel,
            mag: s.has_mag().then_some(s.mag),
            depth: s.has_depth().then_some(s.depth),
        }
    }

    /// True when every value present is finite.
    pub fn is_finite(&self) -> bool {
        self.gyro
            .iter()
            .chain(&self.accel)
            .chain(self.mag.iter().flatten())
            .chain(&self.depth)
            .all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn full() -> ImuReading {
        ImuReading {
            seq: 7,
            t_ns: 5_000_000,
            gyro: [0.1, -0.2, 0.3],
            accel: [0.0, 0.0, -9.81],
            mag: Some([20.0, 0.0, 45.0]),
            depth: Some(5.0),
        }
    }

    #[test]
    fn a_reading_survives_the_wire_with_and_without_channels() {
        let r = full();
        let s = r.to_sample();
        assert!(s.has_mag() && s.has_depth());
        assert_eq!((s.seq, s.t_ns, s.depth), (7, 5_000_000, 5.0));
        assert_eq!(ImuReading::from_sample(&s), r);
        let bare = ImuReading {
            mag: None,
            depth: None,
            ..r
        };
        let s = bare.to_sample();
        assert_eq!((s.flags, s.mag, s.depth), (0, [0.0; 3], 0.0));
        assert_eq!(ImuReading::from_sample(&s), bare);
    }

    #[test]
    fn a_field_without_its_flag_is_not_read() {
        let mut s = full().to_sample();
        s.flags = ImuSample::HAS_DEPTH;
        let r = ImuReading::from_sample(&s);
        assert_eq!((r.mag, r.depth), (None, Some(5.0)));
    }

    #[test]
    fn finiteness_counts_only_present_channels() {
        let mut r = full();
        assert!(r.is_finite());
        r.depth = Some(f64::NAN);
        assert!(!r.is_finite());
        r.depth = None;
        assert!(r.is_finite());
        r.gyro[1] = f64::INFINITY;
        assert!(!r.is_finite());
    }
}
