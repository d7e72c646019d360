use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// A velocity measurement from a Doppler velocity log (driver -> daemon, service `dvl`),
/// optional: most small vehicles have none. The daemon's navigation during an estimation
/// uses it when one arrives; without it the body velocity is dead-reckoned.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.DvlSample.v1")]
pub struct DvlSample {
    /// Sequence number, +1 per sample from this driver.
    pub seq: u64,
    /// Measurement time, ns, on the same monotonic clock as the IMU's samples.
    pub t_ns: u64,
    /// Velocity over ground along body x, y, z, m/s (the DVL's mounting already rotated
    /// into the body frame).
    pub velocity: [f64; 3],
}
