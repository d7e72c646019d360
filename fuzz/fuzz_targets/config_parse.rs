//! Arbitrary bytes into the daemon's config parser (`thrusterd.toml`): never a panic, and an
//! error always names the file and says something.
#![no_main]

use libfuzzer_sys::fuzz_target;
use thrusterd_core::config::DaemonConfig;

fuzz_target!(|data: &[u8]| {
    // The daemon reads the file with read_to_string: non-UTF-8 is an I/O error before parsing.
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match DaemonConfig::from_toml_str(text, "fuzz.toml") {
        Ok(cfg) => {
            // Whatever parses is usable: a machine setup can be derived from it.
            let setup = cfg.machine_setup();
            assert!((1..=16).contains(&setup.thrusters));
        }
        Err(e) => {
            let msg = e.to_string();
            // `fuzz.toml:line:col: ...` or, for a value the file does not locate, `fuzz.toml: ...`.
            assert!(msg.starts_with("fuzz.toml"), "{msg}");
            assert!(msg.len() > "fuzz.toml: ".len(), "empty reason");
        }
    }
});
