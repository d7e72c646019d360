//! Python packages we did not write (Foxglove's `mcap` reader for the recording tests, pymavlink
//! for the MAVLink peer): a venv
//! under the target dir, made once from tests/python/requirements.txt, and the reader script
//! tests/python/read_mcap.py run in it.
//!
//! Needs `python3` with the `venv` module (Debian: package python3-venv; `.ci/run` checks for
//! it) and network access to PyPI the first time. A failure is a test failure with the
//! command's output, never a skip.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Once;

use serde_json::Value;

use crate::workspace;

fn requirements() -> PathBuf {
    workspace().join("tests/python/requirements.txt")
}

/// The venv folder: `<target>/python-mcap`, shared by every profile.
fn venv_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test's own path");
    // <target>/<profile>/deps/<test>
    let target = exe
        .ancestors()
        .find(|p| p.join("CACHEDIR.TAG").exists())
        .map_or_else(|| workspace().join("target"), Path::to_path_buf);
    target.join("python-mcap")
}

fn run(cmd: &mut Command, what: &str) {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed ({:?}): {cmd:?}\nstdout: {}\nstderr: {}\n(the recording tests need python3 \
         with venv (Debian: python3-venv) and access to PyPI for tests/python/requirements.txt)",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The venv's python, with the requirements installed (once per requirements file: a stamp
/// holding its text marks a finished install).
pub fn venv_python() -> PathBuf {
    static INSTALL: Once = Once::new();
    let dir = venv_dir();
    let python = dir.join("bin/python3");
    INSTALL.call_once(|| {
        let wanted =
            std::fs::read_to_string(requirements()).expect("tests/python/requirements.txt");
        let stamp = dir.join("installed-requirements.txt");
        if std::fs::read_to_string(&stamp).ok().as_deref() == Some(wanted.as_str())
            && python.exists()
        {
            return;
        }
        run(
            Command::new("python3")
                .args(["-m", "venv", "--clear"])
                .arg(&dir),
            "creating the Python venv",
        );
        run(
            Command::new(&python)
                .args([
                    "-m",
                    "pip",
                    "install",
                    "--disable-pip-version-check",
                    "-q",
                    "-r",
                ])
                .arg(requirements()),
            "installing tests/python/requirements.txt",
        );
        std::fs::write(&stamp, wanted).expect("writing the venv's stamp");
    });
    python
}

/// tests/python/read_mcap.py run with `args` then `files`: its JSON output.
fn reader(args: &[&str], files: &[PathBuf]) -> Value {
    let python = venv_python();
    let out = Command::new(python)
        .arg(workspace().join("tests/python/read_mcap.py"))
        .args(args)
        .args(files)
        .output()
        .expect("running read_mcap.py");
    assert!(
        out.status.success(),
        "read_mcap.py {args:?} {files:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "read_mcap.py {args:?} printed no JSON ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

/// tests/python/read_mcap.py's JSON summary of `files` (one recording, in order).
pub fn read_mcap(files: &[PathBuf]) -> Value {
    reader(&[], files)
}

/// Every message of `topic` in `files`, decoded by Python's `mcap` and `json` (read_mcap.py
/// --messages): what a recording holds, read without our code.
pub fn mcap_messages(files: &[PathBuf], topic: &str) -> Vec<Value> {
    serde_json::from_value(reader(&["--messages", topic], files))
        .expect("read_mcap.py --messages prints a JSON list")
}

/// `files` rewritten into `out` by Python's `mcap` Writer (zstd chunks, its own indexes and
/// summary; read_mcap.py --rewrite): a recording as another MCAP writer makes it. Returns its
/// `{"messages", "compression", "bytes"}`.
pub fn rewrite_mcap(out: &Path, files: &[PathBuf]) -> Value {
    let out = out.to_str().expect("a UTF-8 path");
    reader(&["--rewrite", out], files)
}

/// What Python's `mcap` recovers from `files` read from their start up to the first error
/// (read_mcap.py --recover): the messages of files cut short (no summary), CRC-checked.
pub fn recover_mcap(files: &[PathBuf]) -> Value {
    reader(&["--recover"], files)
}
