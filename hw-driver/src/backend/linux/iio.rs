//! Linux IIO sensors read through sysfs (`Documentation/ABI/testing/sysfs-bus-iio`):
//! `value = (in_<kind>_<axis>_raw + offset) * scale`, where scale and offset are the
//! per-channel attributes when present, else the shared ones (`in_<kind>_scale`), offset 0
//! when absent. Units after scaling: anglvel rad/s, accel m/s^2, magn gauss, pressure kPa.
//!
//! Scale and offset are read once at start (drivers change them only when reconfigured);
//! raw values are read per sample. The buffered `/dev/iio:deviceN` interface (hardware
//! timestamps, no per-value syscalls) is not used yet.

use std::path::{Path, PathBuf};

use super::sysfs::{read_attr, read_f64};
use crate::backend::BackendError;

/// Finds an IIO device: `iio:deviceN` directly, otherwise the device whose `name` file
/// holds `spec` (numbers can change between boots; names do not).
pub fn find_device(root: &Path, spec: &str) -> Result<PathBuf, BackendError> {
    let devices = root.join("bus/iio/devices");
    if spec.starts_with("iio:device") {
        let dir = devices.join(spec);
        return if dir.is_dir() {
            Ok(dir)
        } else {
            Err(BackendError::Content {
                path: dir,
                reason: "no such IIO device".to_string(),
            })
        };
    }
    let entries = std::fs::read_dir(&devices).map_err(|error| BackendError::File {
        path: devices.clone(),
        op: "list",
        error,
    })?;
    let mut dirs: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    dirs.sort();
    for dir in dirs {
        if read_attr(&dir.join("name")).is_ok_and(|n| n == spec) {
            return Ok(dir);
        }
    }
    Err(BackendError::Content {
        path: devices,
        reason: format!("no IIO device named {spec:?}"),
    })
}

/// One scaled channel.
#[derive(Debug, Clone)]
pub struct Channel {
    raw: PathBuf,
    offset: f64,
    scale: f64,
}

impl Channel {
    /// Channel `in_<kind>_<axis>` of `device` (axis "" for a channel without axis, e.g.
    /// pressure).
    pub fn open(device: &Path, kind: &str, axis: &str) -> Result<Channel, BackendError> {
        let name = if axis.is_empty() {
            format!("in_{kind}")
        } else {
            format!("in_{kind}_{axis}")
        };
        Channel::open_named(device, &name, kind)
    }

    /// Channel `in_voltage<index>` of `device` (millivolts after scale, per the IIO ABI;
    /// indexed channels have no underscore: `in_voltage0_raw`, shared `in_voltage_scale`).
    pub fn open_voltage(device: &Path, index: u32) -> Result<Channel, BackendError> {
        Channel::open_named(device, &format!("in_voltage{index}"), "voltage")
    }

    /// Channel `name` (`<name>_raw`) of `device`, with its own scale and offset or the
    /// shared `in_<kind>_scale` / `_offset`.
    fn open_named(device: &Path, name: &str, kind: &str) -> Result<Channel, BackendError> {
        let raw = device.join(format!("{name}_raw"));
        if !raw.exists() {
            return Err(BackendError::Content {
                path: raw,
                reason: format!("the device has no {name} channel"),
            });
        }
        let shared = |attr: &str| -> Option<PathBuf> {
            [
                device.join(format!("{name}_{attr}")),
                device.join(format!("in_{kind}_{attr}")),
            ]
            .into_iter()
            .find(|p| p.exists())
        };
        let scale = match shared("scale") {
            Some(p) => read_f64(&p)?,
            None => 1.0,
        };
        let offset = match shared("offset") {
            Some(p) => read_f64(&p)?,
            None => 0.0,
        };
        Ok(Channel { raw, offset, scale })
    }

    /// The current value in the channel's IIO unit.
    pub fn read(&self) -> Result<f64, BackendError> {
        Ok((read_f64(&self.raw)? + self.offset) * self.scale)
    }
}

/// Three channels x, y, z of one kind.
#[derive(Debug, Clone)]
pub struct Vector3 {
    axes: [Channel; 3],
}

impl Vector3 {
    /// `in_<kind>_{x,y,z}` of `device`.
    pub fn open(device: &Path, kind: &str) -> Result<Vector3, BackendError> {
        Ok(Vector3 {
            axes: [
                Channel::open(device, kind, "x")?,
                Channel::open(device, kind, "y")?,
                Channel::open(device, kind, "z")?,
            ],
        })
    }

    /// The current vector, sensor frame, IIO units.
    pub fn read(&self) -> Result<[f64; 3], BackendError> {
        Ok([
            self.axes[0].read()?,
            self.axes[1].read()?,
            self.axes[2].read()?,
        ])
    }
}

/// A pressure channel: `in_pressure_input` (already in kPa) when the driver offers it,
/// else `in_pressure_raw` scaled.
#[derive(Debug, Clone)]
pub enum Pressure {
    /// Processed value, kPa.
    Input(PathBuf),
    /// Raw value with scale and offset.
    Raw(Channel),
}

impl Pressure {
    /// The pressure channel of `device`.
    pub fn open(device: &Path) -> Result<Pressure, BackendError> {
        let input = device.join("in_pressure_input");
        if input.exists() {
            Ok(Pressure::Input(input))
        } else {
            Channel::open(device, "pressure", "").map(Pressure::Raw)
        }
    }

    /// The current pressure, kPa.
    pub fn read_kpa(&self) -> Result<f64, BackendError> {
        match self {
            Pressure::Input(p) => read_f64(p),
            Pressure::Raw(c) => c.read(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn dev(root: &Path, n: u32, name: &str) -> PathBuf {
        let d = root.join(format!("bus/iio/devices/iio:device{n}"));
        fs::create_dir_all(&d).unwrap();
        fs::write(d.join("name"), format!("{name}\n")).unwrap();
        d
    }

    #[test]
    fn per_channel_scale_and_offset_win_over_shared_ones() {
        let root = tempfile::tempdir().unwrap();
        let d = dev(root.path(), 0, "icm20602");
        fs::write(d.join("in_anglvel_x_raw"), "100\n").unwrap();
        fs::write(d.join("in_anglvel_scale"), "0.001\n").unwrap();
        fs::write(d.join("in_anglvel_x_scale"), "0.002\n").unwrap();
        fs::write(d.join("in_anglvel_offset"), "-10\n").unwrap();
        let c = Channel::open(&d, "anglvel", "x").unwrap();
        assert!((c.read().unwrap() - 0.18).abs() < 1e-12);
        fs::write(d.join("in_anglvel_x_raw"), "-50\n").unwrap();
        assert!((c.read().unwrap() + 0.12).abs() < 1e-12);
        assert!(Channel::open(&d, "anglvel", "y")
            .unwrap_err()
            .to_string()
            .contains("in_anglvel_y_raw"));
    }

    #[test]
    fn voltage_channels_are_indexed_without_underscore() {
        let root = tempfile::tempdir().unwrap();
        let d = dev(root.path(), 1, "ads1115");
        fs::write(d.join("in_voltage2_raw"), "1500\n").unwrap();
        fs::write(d.join("in_voltage_scale"), "0.125\n").unwrap();
        let c = Channel::open_voltage(&d, 2).unwrap();
        assert!((c.read().unwrap() - 187.5).abs() < 1e-12);
        fs::write(d.join("in_voltage2_scale"), "0.25\n").unwrap();
        assert!((Channel::open_voltage(&d, 2).unwrap().read().unwrap() - 375.0).abs() < 1e-12);
        assert!(Channel::open_voltage(&d, 0)
            .unwrap_err()
            .to_string()
            .contains("in_voltage0_raw"));
    }

    #[test]
    fn devices_by_number_or_name_and_pressure_variants() {
        let root = tempfile::tempdir().unwrap();
        dev(root.path(), 0, "icm20602");
        let p = dev(root.path(), 3, "ms5837");
        assert_eq!(find_device(root.path(), "ms5837").unwrap(), p);
        assert_eq!(find_device(root.path(), "iio:device3").unwrap(), p);
        assert!(find_device(root.path(), "iio:device7").is_err());
        assert!(find_device(root.path(), "bmp280").is_err());
        fs::write(p.join("in_pressure_raw"), "1000\n").unwrap();
        fs::write(p.join("in_pressure_scale"), "0.1\n").unwrap();
        assert!((Pressure::open(&p).unwrap().read_kpa().unwrap() - 100.0).abs() < 1e-12);
        fs::write(p.join("in_pressure_input"), "120.5\n").unwrap();
        assert_eq!(Pressure::open(&p).unwrap().read_kpa().unwrap(), 120.5);
    }
}
