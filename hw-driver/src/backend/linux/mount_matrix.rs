//! The kernel's mounting matrix of an IIO sensor: how the chip sits on its board.
//!
//! A device tree may say that a chip is mounted rotated (`mount-matrix`); the IIO driver then
//! shows the matrix in sysfs and leaves the samples in the chip's own axes. The ABI
//! (`Documentation/ABI/testing/sysfs-bus-iio`, `in_accel_mount_matrix`): "Applications should
//! apply this rotation matrix to samples". The device-tree binding
//! (`bindings/iio/mount-matrix.txt`) gives the multiplication, `x' = mxx x + myx y + mzx z`
//! with the property's first three strings `mxx, myx, mzx`, so each `;`-separated group of the
//! sysfs text is one row and board = M chip (as GNOME's iio-sensor-proxy applies it). The kernel prints the strings of the device tree
//! verbatim (`iio_show_mount_matrix`: "%s, %s, %s; %s, %s, %s; %s, %s, %s\n"), so decimals
//! such as 0.866 occur; without a matrix in the device tree it prints the identity.
//!
//! Where the file is: drivers name it by how widely it is shared (`IIO_MOUNT_MATRIX`'s
//! sharing): per channel type (`in_accel_mount_matrix`, `in_anglvel_mount_matrix`:
//! inv_mpu6050), per direction (`in_mount_matrix`: bmi160, ak8975) or per device
//! (`mount_matrix`: st_lsm6dsx). Older kernels have none: the identity.

use std::path::Path;

use super::sysfs::read_attr;
use crate::backend::BackendError;

/// How far a row may be from unit length and two rows from orthogonal. Device trees write
/// cos 30 deg as 0.866 (3 digits); a matrix off by more is not a rotation.
const ROTATION_TOLERANCE: f64 = 0.01;

/// Board axes from chip axes: `board[i] = sum_j m[i][j] chip[j]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountMatrix(pub [[f64; 3]; 3]);

impl MountMatrix {
    pub const IDENTITY: MountMatrix =
        MountMatrix([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);

    /// Parses the kernel's text, e.g. "0, 1, 0; 1, 0, 0; 0, 0, -1". Refuses anything that is
    /// not a rotation or reflection (rows of unit length, orthogonal): applying it would
    /// scale or shear the samples.
    pub fn parse(text: &str) -> Result<MountMatrix, String> {
        let rows: Vec<&str> = text.trim().split(';').collect();
        if rows.len() != 3 {
            return Err(format!("expected 3 rows separated by ';', found {text:?}"));
        }
        let mut m = [[0.0; 3]; 3];
        for (i, row) in rows.iter().enumerate() {
            let cells: Vec<&str> = row.split(',').map(str::trim).collect();
            if cells.len() != 3 {
                return Err(format!("row {} of {text:?} has not 3 numbers", i + 1));
            }
            for (j, cell) in cells.iter().enumerate() {
                m[i][j] = match cell.parse::<f64>() {
                    Ok(v) if v.is_finite() => v,
                    _ => return Err(format!("{cell:?} in {text:?} is not a number")),
                };
            }
        }
        for i in 0..3 {
            for k in i..3 {
                let dot: f64 = (0..3).map(|j| m[i][j] * m[k][j]).sum();
                let want = if i == k { 1.0 } else { 0.0 };
                if (dot - want).abs() > ROTATION_TOLERANCE {
                    return Err(format!(
                        "{text:?} is not a rotation (rows {} and {} give {dot:.3}, not {want})",
                        i + 1,
                        k + 1
                    ));
                }
            }
        }
        Ok(MountMatrix(m))
    }

    /// The matrix `device` gives for channels of `kind` ("accel", "anglvel", "magn"): the
    /// per-type file, else the per-direction one, else the per-device one, else the identity
    /// (a kernel or driver without mounting matrices).
    pub fn read(device: &Path, kind: &str) -> Result<MountMatrix, BackendError> {
        let names = [
            format!("in_{kind}_mount_matrix"),
            "in_mount_matrix".to_string(),
            "mount_matrix".to_string(),
        ];
        let Some(path) = names.iter().map(|n| device.join(n)).find(|p| p.exists()) else {
            return Ok(MountMatrix::IDENTITY);
        };
        let text = read_attr(&path)?;
        MountMatrix::parse(&text).map_err(|reason| BackendError::Content { path, reason })
    }

    /// `a` then `self`: the matrix of `self (a v)`.
    pub fn after(&self, a: &MountMatrix) -> MountMatrix {
        MountMatrix(std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| self.0[i][k] * a.0[k][j]).sum())
        }))
    }

    /// `M v`.
    pub fn apply(&self, v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| (0..3).map(|j| self.0[i][j] * v[j]).sum())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    #[test]
    fn the_kernels_text_is_read_row_by_row_and_must_be_a_rotation() {
        // The identity the kernel prints when the device tree has no matrix.
        assert_eq!(
            MountMatrix::parse("1, 0, 0; 0, 1, 0; 0, 0, 1\n").unwrap(),
            MountMatrix::IDENTITY
        );
        // The ABI's example: x and y swapped, z flipped. Rows are the board's axes.
        let m = MountMatrix::parse("0, 1, 0; 1, 0, 0; 0, 0, -1").unwrap();
        assert_eq!(m.apply([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0]);
        // 30 deg about z as a device tree writes it.
        let r = MountMatrix::parse("0.866, -0.5, 0; 0.5, 0.866, 0; 0, 0, 1").unwrap();
        let v = r.apply([1.0, 0.0, 0.0]);
        assert!((v[0] - 0.866).abs() < 1e-12 && (v[1] - 0.5).abs() < 1e-12);
        for (bad, says) in [
            ("1, 0, 0; 0, 1, 0", "3 rows"),
            ("1, 0; 0, 1, 0; 0, 0, 1", "not 3 numbers"),
            ("1, 0, x; 0, 1, 0; 0, 0, 1", "not a number"),
            ("2, 0, 0; 0, 1, 0; 0, 0, 1", "not a rotation"),
            ("1, 0, 0; 1, 0, 0; 0, 0, 1", "not a rotation"),
            ("0, 0, 0; 0, 0, 0; 0, 0, 0", "not a rotation"),
        ] {
            let e = MountMatrix::parse(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn the_most_specific_file_wins_and_none_is_the_identity() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        assert_eq!(
            MountMatrix::read(d, "accel").unwrap(),
            MountMatrix::IDENTITY
        );
        fs::write(d.join("mount_matrix"), "0, 1, 0; 1, 0, 0; 0, 0, -1\n").unwrap();
        let swap = MountMatrix::read(d, "anglvel").unwrap();
        assert_eq!(swap.apply([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0]);
        fs::write(d.join("in_mount_matrix"), "-1, 0, 0; 0, -1, 0; 0, 0, 1\n").unwrap();
        assert_eq!(
            MountMatrix::read(d, "anglvel")
                .unwrap()
                .apply([1.0, 0.0, 0.0]),
            [-1.0, 0.0, 0.0]
        );
        fs::write(
            d.join("in_accel_mount_matrix"),
            "1, 0, 0; 0, 1, 0; 0, 0, 1\n",
        )
        .unwrap();
        assert_eq!(
            MountMatrix::read(d, "accel").unwrap(),
            MountMatrix::IDENTITY
        );
        fs::write(d.join("in_accel_mount_matrix"), "1, 0, 0\n").unwrap();
        let e = MountMatrix::read(d, "accel").unwrap_err().to_string();
        assert!(
            e.contains("in_accel_mount_matrix") && e.contains("3 rows"),
            "{e}"
        );
        // Composition: first the mount, then the axes.
        let a = MountMatrix([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]);
        assert_eq!(a.after(&swap).apply([1.0, 2.0, 3.0]), [2.0, -1.0, 3.0]);
    }
}
