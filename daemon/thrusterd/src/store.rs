//! The state directory: the current model saved atomically (temp file, fsync, rename, fsync of
//! the folder) and loaded at start. The file's format is the core's `model_file`.

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use thrusterd_core::model::Model;
use thrusterd_core::model_file::{from_json, to_json, StoreError};

/// File name of the current model inside the state directory.
pub const MODEL_FILE: &str = "model.json";

/// Write `model` to `path` atomically: readers see the old file or the new one, never half.
pub fn save_atomic(model: &Model, path: &Path) -> Result<(), StoreError> {
    let io = |source: std::io::Error| StoreError::Io {
        path: path.display().to_string(),
        source,
    };
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let tmp: PathBuf = dir.join(format!(
        ".{}.tmp",
        path.file_name()
            .and_then(|n| n.to_str())
            .unwrap_or(MODEL_FILE)
    ));
    let result = (|| {
        let mut f = File::create(&tmp)?;
        f.write_all(to_json(model).as_bytes())?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)?;
        // The rename itself must reach the disk before we call the model saved.
        File::open(dir)?.sync_all()
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result.map_err(io)
}

/// Load the model at `path`; Ok(None) when there is none yet.
pub fn load(path: &Path) -> Result<Option<Model>, StoreError> {
    // Only a regular file: reading a FIFO or a device would block the caller (the daemon's
    // loop, for an operator's load) until someone writes to it.
    match fs::metadata(path) {
        Ok(m) if !m.is_file() => {
            return Err(StoreError::Corrupt {
                path: path.display().to_string(),
                why: "not a regular file".into(),
            })
        }
        _ => {}
    }
    match fs::read_to_string(path) {
        Ok(text) => from_json(&text, &path.display().to_string()).map(Some),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(StoreError::Io {
            path: path.display().to_string(),
            source,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thrusterd_core::model::{nominal_effectiveness, RigidBody};

    /// Two vertical thrusters: the file round trip needs a model, not a particular one (the
    /// format's own tests, in the core's model_file, cover every field).
    fn model() -> Model {
        let pos = [[0.2, 0.0, 0.0], [-0.2, 0.0, 0.0]];
        let dir = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]];
        let mut m = Model::nominal(
            nominal_effectiveness(&RigidBody::default(), &pos, &dir),
            Some(9),
        );
        m.version = 3;
        m.std_err[(2, 1)] = 0.02;
        m
    }

    #[test]
    fn round_trip_through_a_real_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(MODEL_FILE);
        assert!(load(&path).unwrap().is_none());
        let m = model();
        save_atomic(&m, &path).unwrap();
        let back = load(&path).unwrap().unwrap();
        assert_eq!(back.effectiveness, m.effectiveness);
        assert_eq!(back.allocation, m.allocation);
        assert_eq!(back.actuated, m.actuated);
        assert_eq!(back.version, 3);
        assert_eq!(back.geometry_key, Some(9));
        assert_eq!(back.std_err[(2, 1)], 0.02);
        assert!(back.std_err[(0, 0)].is_nan());
        // No temp file left behind.
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn unwritable_directory_is_an_error_not_a_panic() {
        let e = save_atomic(&model(), Path::new("/proc/thrusterd-test/model.json")).unwrap_err();
        assert!(e.to_string().contains("/proc/thrusterd-test"), "{e}");
    }
}
