//! Foxglove's WebSocket client (`FoxgloveClient` of the npm package `@foxglove/ws-protocol`, not
//! ours) for the bridge test: installed with `npm ci` from tests/node/package.json and its
//! package-lock.json into `<target>/node-ws` (once per lock file), and the client script
//! tests/node/bridge_client.js run with Node.
//!
//! Needs `node` and `npm` (Node 20 or newer) and access to the npm registry the first time. A
//! failure is a test failure with the command's output, never a skip.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Once;

use crate::workspace;

fn node_dir() -> PathBuf {
    workspace().join("tests/node")
}

/// `<target>/node-ws`, shared by every profile (as the Python venv beside it).
fn install_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test's own path");
    let target = exe
        .ancestors()
        .find(|p| p.join("CACHEDIR.TAG").exists())
        .map_or_else(|| workspace().join("target"), Path::to_path_buf);
    target.join("node-ws")
}

fn run(cmd: &mut Command, what: &str) {
    let out = cmd.output().unwrap_or_else(|e| {
        panic!("{what}: cannot run {cmd:?}: {e} (the bridge test needs Node 20+ and npm)")
    });
    assert!(
        out.status.success(),
        "{what} failed ({:?}): {cmd:?}\nstdout: {}\nstderr: {}\n(the bridge test needs node and \
         npm, and access to the npm registry for tests/node/package-lock.json)",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The `node_modules` folder with the locked packages installed (once per lock file: a stamp
/// holding its text marks a finished install).
pub fn node_modules() -> PathBuf {
    static INSTALL: Once = Once::new();
    let dir = install_dir();
    let modules = dir.join("node_modules");
    INSTALL.call_once(|| {
        let lock = std::fs::read_to_string(node_dir().join("package-lock.json"))
            .expect("tests/node/package-lock.json");
        let stamp = dir.join("installed-lock.json");
        if std::fs::read_to_string(&stamp).ok().as_deref() == Some(lock.as_str())
            && modules.join("@foxglove/ws-protocol").exists()
        {
            return;
        }
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("creating the npm install folder");
        for f in ["package.json", "package-lock.json"] {
            std::fs::copy(node_dir().join(f), dir.join(f)).expect("copying tests/node's files");
        }
        // `npm ci`: exactly the lock file's versions (and integrity hashes); no install scripts.
        run(
            Command::new("npm")
                .args([
                    "ci",
                    "--ignore-scripts",
                    "--no-audit",
                    "--no-fund",
                    "--loglevel=error",
                ])
                .current_dir(&dir),
            "npm ci (tests/node)",
        );
        std::fs::write(&stamp, lock).expect("writing the npm stamp");
    });
    modules
}

/// A `node` command running tests/node/`script` with the installed packages on its path.
pub fn script(script: &str) -> Command {
    let modules = node_modules();
    let mut cmd = Command::new("node");
    cmd.env("NODE_PATH", &modules).arg(node_dir().join(script));
    cmd
}
