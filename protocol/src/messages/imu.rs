use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// One inertial sample from the vehicle's IMU (driver -> daemon, service `imu`).
///
/// The daemon answers every sample with one [`crate::ThrustCommand`]. Time comes from the
/// sensor's monotonic clock, never the wall clock, so the same code runs in real time and
/// faster than real time against the simulator.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.ImuSample.v1")]
pub struct ImuSample {
    /// Sequence number, +1 per sample from this driver.
    pub seq: u64,
    /// Sample time, ns, on the sensor's monotonic clock (strictly increasing).
    pub t_ns: u64,
    /// Angular rate about body x, y, z, rad/s.
    pub gyro: [f64; 3],
    /// Specific force along body x, y, z, m/s^2, gravity included as a real IMU reports
    /// it: at rest and level it reads about `[0, 0, -9.81]` (x forward, y starboard,
    /// z down).
    pub accel: [f64; 3],
    /// Magnetic field along body x, y, z, uT. Meaningful only with [`ImuSample::HAS_MAG`]
    /// (write zeros otherwise).
    pub mag: [f64; 3],
    /// Depth of the pressure sensor, m, positive down. Meaningful only with
    /// [`ImuSample::HAS_DEPTH`] (write zero otherwise).
    pub depth: f64,
    /// Bit set of `ImuSample::HAS_*` flags.
    pub flags: u64,
}

impl ImuSample {
    /// `mag` holds a measurement.
    pub const HAS_MAG: u64 = 1 << 0;
    /// `depth` holds a measurement.
    pub const HAS_DEPTH: u64 = 1 << 1;
    /// Every flag this protocol version defines; other bits are rejected.
    pub const KNOWN_FLAGS: u64 = Self::HAS_MAG | Self::HAS_DEPTH;

    /// True when `mag` holds a measurement.
    pub fn has_mag(&self) -> bool {
        self.flags & Self::HAS_MAG != 0
    }

    /// True when `depth` holds a measurement.
    pub fn has_depth(&self) -> bool {
        self.flags & Self::HAS_DEPTH != 0
    }
}
