//! Reading and writing sysfs attributes, with the path in every error.
//!
//! Each write opens, writes once and closes, like `echo v > attr`: a sysfs attribute's
//! `store` runs once per write(2) at offset 0, and the truncating open makes the same code
//! correct on the plain files of a fake tree.

use std::fs::OpenOptions;
use std::io::Write;
use std::path::Path;

use crate::backend::BackendError;

/// Writes `value` (a newline is appended) to the attribute at `path`.
pub fn write_attr(path: &Path, value: &str) -> Result<(), BackendError> {
    let mut f = OpenOptions::new()
        .write(true)
        .truncate(true)
        .open(path)
        .map_err(|error| BackendError::File {
            path: path.to_path_buf(),
            op: "open for writing",
            error,
        })?;
    f.write_all(format!("{value}\n").as_bytes())
        .map_err(|error| BackendError::File {
            path: path.to_path_buf(),
            op: "write",
            error,
        })
}

/// The attribute's text, trimmed.
pub fn read_attr(path: &Path) -> Result<String, BackendError> {
    std::fs::read_to_string(path)
        .map(|s| s.trim().to_string())
        .map_err(|error| BackendError::File {
            path: path.to_path_buf(),
            op: "read",
            error,
        })
}

/// The attribute as a number (integer or decimal, as IIO writes scales).
pub fn read_f64(path: &Path) -> Result<f64, BackendError> {
    let text = read_attr(path)?;
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(BackendError::Content {
            path: path.to_path_buf(),
            reason: format!("expected a number, found {text:?}"),
        }),
    }
}

/// The attribute as an unsigned integer.
pub fn read_u64(path: &Path) -> Result<u64, BackendError> {
    let text = read_attr(path)?;
    text.parse::<u64>().map_err(|_| BackendError::Content {
        path: path.to_path_buf(),
        reason: format!("expected an unsigned integer, found {text:?}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors_name_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("duty_cycle");
        std::fs::write(&p, "1500000\n").unwrap();
        write_attr(&p, "900000").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "900000\n");
        assert_eq!(read_u64(&p).unwrap(), 900_000);
        assert_eq!(read_f64(&p).unwrap(), 900_000.0);
        std::fs::write(&p, "0.000133\n").unwrap();
        assert_eq!(read_f64(&p).unwrap(), 0.000133);
        assert!(read_u64(&p).unwrap_err().to_string().contains("duty_cycle"));
        let missing = dir.path().join("enable");
        let e = write_attr(&missing, "1").unwrap_err().to_string();
        assert!(e.contains("enable") && e.contains("open"), "{e}");
        std::fs::write(&p, "nan\n").unwrap();
        assert!(read_f64(&p).is_err());
    }
}
