//! The config and model file parsers against bad files, on stable (CI cannot run cargo-fuzz):
//! the fuzz targets' committed seed corpus (fuzz/corpus), every truncation of it, seeded
//! byte mutations, each value of the shipped config replaced by something absurd, and
//! proptest-generated files. Never a panic; every error names the file and gives a reason;
//! TOML errors name the line (file:line:col) and the key.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use thrusterd_core::config::{ConfigError, DaemonConfig};
use thrusterd_core::model_file::{self as store, StoreError};

const CONFIG: &str = "bad.toml";
const MODEL: &str = "bad.json";

fn corpus(target: &str) -> Vec<(PathBuf, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(target);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no seeds in {}", dir.display());
    files
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p).unwrap();
            (p, text)
        })
        .collect()
}

/// Parse a config; an error must be located: the file, then the line and column (TOML
/// syntax, types, unknown keys, values out of range) and the key with its reason.
fn config(text: &str) -> Result<DaemonConfig, String> {
    DaemonConfig::from_toml_str(text, CONFIG).map_err(|e| {
        let msg = e.to_string();
        assert!(msg.starts_with("bad.toml"), "unlocated: {msg}");
        match &e {
            ConfigError::Parse { message, .. } => {
                assert!(!message.is_empty(), "no reason: {msg}\n--- input\n{text}")
            }
            ConfigError::Value { key, reason, .. } => {
                assert!(
                    !key.is_empty() && !reason.is_empty(),
                    "no key or reason: {msg}"
                )
            }
            other => panic!("unexpected error from a string: {other}"),
        }
        msg
    })
}

/// Parse a model file; an error must name the file and give a reason.
fn model(text: &str) -> Result<thrusterd_core::model::Model, String> {
    match store::from_json(text, MODEL) {
        Ok(m) => {
            let n = m.thrusters();
            assert!((1..=16).contains(&n));
            assert_eq!(m.effectiveness.shape(), (6, n));
            assert_eq!(m.allocation.shape(), (n, 6));
            assert!(m.effectiveness.iter().all(|v| v.is_finite()));
            assert!(m.allocation.iter().all(|v| v.is_finite()));
            // The daemon's swap check runs on every loaded model.
            let _ = m.check(n, 0.25);
            Ok(m)
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.starts_with("bad.json: ") && msg.len() > "bad.json: ".len() + 5,
                "unlocated or empty: {msg}"
            );
            assert!(!matches!(e, StoreError::Io { .. }), "{msg}");
            Err(msg)
        }
    }
}

#[test]
fn the_seed_corpus_parses() {
    for (path, text) in corpus("config_parse") {
        config(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
    for (path, text) in corpus("model_parse") {
        model(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
}

fn prefixes(text: &str) -> impl Iterator<Item = &str> {
    (0..text.len())
        .filter(|&i| text.is_char_boundary(i))
        .map(|i| &text[..i])
}

#[test]
fn every_truncated_file_is_refused_or_parses_without_panic() {
    let mut refused = 0;
    for (_, text) in corpus("config_parse") {
        for p in prefixes(&text) {
            refused += config(p).is_err() as usize;
        }
    }
    assert!(refused > 100, "truncated configs refused: {refused}");
    for (path, text) in corpus("model_parse") {
        // A model file cut anywhere is not valid JSON: always refused.
        for p in prefixes(text.trim_end()) {
            let e = model(p).expect_err(&format!("{} truncated to {}", path.display(), p.len()));
            assert!(e.contains("not a thrusterd model file"), "{e}");
        }
    }
}

/// A small deterministic generator, so a failure names a reproducible case.
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// Flip, delete, duplicate or insert bytes (1-4 edits), as a corrupt disk or a bad hand edit.
fn mutate(rng: &mut XorShift, text: &str) -> Vec<u8> {
    const INTERESTING: &[&[u8]] = &[
        b"\0",
        b"\"",
        b"[",
        b"]",
        b"{",
        b"}",
        b"=",
        b"\n",
        b",",
        b"nan",
        b"-inf",
        b"1e999",
        b"-1",
        b"18446744073709551616",
        b"\xff",
        b"\xc3\x28",
        b"[[",
        b"#",
    ];
    let mut bytes = text.as_bytes().to_vec();
    for _ in 0..1 + rng.below(4) {
        if bytes.is_empty() {
            bytes.extend_from_slice(INTERESTING[rng.below(INTERESTING.len())]);
            continue;
        }
        let at = rng.below(bytes.len());
        match rng.below(4) {
            0 => bytes[at] ^= 1 << rng.below(8),
            1 => {
                let end = (at + 1 + rng.below(16)).min(bytes.len());
                bytes.drain(at..end);
            }
            2 => {
                let end = (at + 1 + rng.below(32)).min(bytes.len());
                let chunk = bytes[at..end].to_vec();
                bytes.splice(at..at, chunk);
            }
            _ => {
                let ins = INTERESTING[rng.below(INTERESTING.len())];
                bytes.splice(at..at, ins.iter().copied());
            }
        }
    }
    bytes
}

#[test]
fn mutated_seeds_never_panic_and_errors_are_located() {
    let mut rng = XorShift(0x5eed_cafe_f00d_0001);
    let (mut tried, mut refused) = (0, 0);
    for (target, parse) in [
        (
            "config_parse",
            (|t: &str| config(t).map(|_| ())) as fn(&str) -> Result<(), String>,
        ),
        ("model_parse", |t: &str| model(t).map(|_| ())),
    ] {
        for (_, text) in corpus(target) {
            for _ in 0..1500 {
                // Like the daemon, which reads with read_to_string: invalid UTF-8 never parses.
                if let Ok(s) = String::from_utf8(mutate(&mut rng, &text)) {
                    tried += 1;
                    refused += parse(&s).is_err() as usize;
                }
            }
        }
    }
    assert!(
        tried > 5000 && refused > tried / 4,
        "tried {tried}, refused {refused}"
    );
}

/// Every `key = value` line of the shipped config with its value replaced by something
/// absurd is refused, naming that line or that key: no value is silently taken.
#[test]
fn each_shipped_value_made_absurd_is_refused_naming_its_line_or_key() {
    let shipped = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/thrusterd.toml"),
    )
    .unwrap();
    let lines: Vec<&str> = shipped.lines().collect();
    let mut section = String::new();
    let mut checked = 0;
    for (i, line) in lines.iter().enumerate() {
        let code = line.split('#').next().unwrap().trim();
        if code.starts_with('[') {
            section = code.trim_matches(|c| c == '[' || c == ']').to_string();
            continue;
        }
        let Some((key, value)) = code.split_once('=') else {
            continue;
        };
        let (key, value) = (key.trim(), value.trim());
        let absurd: &[&str] = if value.starts_with('"') {
            &["\"\u{0}\"", "1", "[]"]
        } else if value.starts_with('[') {
            &["[nan, 0.1, 0.1]", "[1.0]", "[-inf, -inf, -inf]", "\"x\""]
        } else if value == "true" || value == "false" {
            &["\"yes\"", "2"]
        } else if value.contains('.') {
            &["nan", "inf", "-inf", "-1.0", "\"x\""]
        } else {
            &["-1", "1e999", "99999999999999999999", "\"x\""]
        };
        for bad in absurd {
            let mut edited = lines.clone();
            let replaced = format!("{key} = {bad}");
            edited[i] = &replaced;
            let text = edited.join("\n");
            let line_no = format!("{CONFIG}:{}:", i + 1);
            let full_key = format!("{section}.{key}");
            match config(&text) {
                // A string or path is free text; the namespace is checked when it is used.
                Ok(_) if value.starts_with('"') && *bad != "1" && *bad != "[]" => {}
                Ok(_) => panic!("{full_key} = {bad} accepted"),
                Err(msg) => {
                    assert!(
                        msg.contains(&line_no) || msg.contains(&full_key),
                        "{full_key} = {bad}: neither {line_no} nor the key in: {msg}"
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 80, "only {checked} absurd values checked");
}

#[test]
fn future_version_and_foreign_files_are_refused_with_the_reason() {
    let (_, text) = corpus("model_parse").into_iter().next().unwrap();
    for (from, to, expect) in [
        (
            "\"format_version\": 1",
            "\"format_version\": 4",
            "format version 4 is newer",
        ),
        (
            "\"format_version\": 1",
            "\"format_version\": 4294967297",
            "format version 4294967297 is newer",
        ),
        (
            "\"format_version\": 1",
            "\"format_version\": -1",
            "format_version -1 is not",
        ),
        (
            "thrusterd-model",
            "someone-elses-model",
            "missing \"format\"",
        ),
        (
            "\"thrusters\":",
            "\"x\": 0, \"thrusters\":",
            "unknown field `x`",
        ),
        (
            "\"thrusters\": 5",
            "\"thrusters\": 17",
            "thrusters = 17 is not 1..16",
        ),
        (
            "\"effectiveness\"",
            "\"effectivenes\"",
            "unknown field `effectivenes`",
        ),
    ] {
        assert!(text.contains(from));
        let e = model(&text.replacen(from, to, 1)).unwrap_err();
        assert!(e.contains(expect), "{to}: {e}");
    }
    let e = model("").unwrap_err();
    assert!(e.contains("EOF"), "{e}");
}

/// Keys of the config file, for generated files that are nearly right.
const KEYS: &[(&str, &str)] = &[
    ("ipc", "namespace"),
    ("runtime", "imu_timeout_ms"),
    ("runtime", "spin_us"),
    ("vehicle", "thrusters"),
    ("body", "mass_kg"),
    ("body", "inertia_kg_m2"),
    ("machine", "pulse_s"),
    ("machine", "settle_min_s"),
    ("machine", "on_reconfig"),
    ("estimator", "k_sigma"),
    ("estimator", "max_pulses"),
    ("controller", "kp_att"),
    ("attitude", "kp"),
    ("nonsense", "key"),
];

fn toml_value() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f64>().prop_map(|v| format!("{v:?}")),
        any::<i64>().prop_map(|v| v.to_string()),
        Just("nan".to_string()),
        Just("-inf".to_string()),
        Just("true".to_string()),
        "\"[a-z_ ]{0,12}\"",
        proptest::collection::vec(any::<f64>(), 0..5).prop_map(|v| format!("{v:?}")),
        "[\\PC]{0,8}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_text_is_never_a_panic(text in "\\PC{0,400}") {
        let _ = config(&text);
        let _ = model(&text);
    }

    #[test]
    fn nearly_right_configs_are_located(
        entries in proptest::collection::vec((0..KEYS.len(), toml_value()), 1..6),
    ) {
        let mut text = String::new();
        for (k, value) in &entries {
            let (section, key) = KEYS[*k];
            text.push_str(&format!("[{section}]\n{key} = {value}\n"));
        }
        // Located or accepted; an accepted file yields a usable machine setup.
        if let Ok(cfg) = config(&text) {
            prop_assert!((1..=16).contains(&cfg.machine_setup().thrusters));
        }
    }

    #[test]
    fn a_model_with_any_leaf_replaced_never_panics(
        pick in any::<u64>(),
        leaf in prop_oneof![
            Just(serde_json::Value::Null),
            any::<f64>().prop_map(|v| serde_json::json!(v)),
            any::<i64>().prop_map(|v| serde_json::json!(v)),
            any::<u64>().prop_map(|v| serde_json::json!(v)),
            "[a-z]{0,8}".prop_map(serde_json::Value::String),
            Just(serde_json::json!([[1.0e308, -1.0e308]])),
            Just(serde_json::json!({})),
        ],
    ) {
        let (_, text) = corpus("model_parse").into_iter().next().unwrap();
        let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let mut leaves = Vec::new();
        collect_leaves(&v, String::new(), &mut leaves);
        let path = &leaves[(pick % leaves.len() as u64) as usize];
        *v.pointer_mut(path).unwrap() = leaf;
        let _ = model(&v.to_string());
    }
}

fn collect_leaves(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Array(items) => {
            out.push(at.clone());
            for (i, item) in items.iter().enumerate() {
                collect_leaves(item, format!("{at}/{i}"), out);
            }
        }
        serde_json::Value::Object(map) => {
            for (k, item) in map {
                collect_leaves(item, format!("{at}/{k}"), out);
            }
        }
        _ => out.push(at),
    }
}
