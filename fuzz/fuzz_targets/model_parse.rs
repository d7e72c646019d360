//! Arbitrary bytes into the saved-model parser (`model.json`): never a panic, an error always
//! names the file and says something, and a parsed model can be checked for a swap.
#![no_main]

use libfuzzer_sys::fuzz_target;
use thrusterd_core::model_file as store;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match store::from_json(text, "fuzz.json") {
        Ok(model) => {
            let n = model.thrusters();
            assert!((1..=16).contains(&n));
            // The daemon's hot-swap check runs on every loaded model; it must not panic either.
            let _ = model.check(n, 0.25);
            // A parsed model serialises and parses back to the same matrices.
            let back = store::from_json(&store::to_json(&model), "again.json").expect("round trip");
            assert_eq!(back.effectiveness, model.effectiveness);
            assert_eq!(back.allocation, model.allocation);
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.starts_with("fuzz.json: "), "{msg}");
            assert!(msg.len() > "fuzz.json: ".len(), "empty reason");
        }
    }
});
