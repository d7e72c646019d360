//! The house rules of docs/architecture.md ("Layout: what each package may depend on"), checked
//! on the sources so a move that breaks them fails here instead of in review:
//! - inside a package, files do not import each other in circles;
//! - the pure core's dependency tree holds no IPC, signal, logging or systemd crate;
//! - no product file is over 900 lines before its unit tests (issue 28);
//! - the core holds no study, no plotting and no dependency on the lab (issue 28).
//! - one IMU reading type, the protocol's: no package defines another.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The workspace's members (the root Cargo.toml's `members`), each with a `src/` tree.
fn packages() -> Vec<String> {
    let text = std::fs::read_to_string(workspace().join("Cargo.toml")).unwrap();
    let root: toml::Value = toml::from_str(&text).unwrap();
    root["workspace"]["members"]
        .as_array()
        .expect("workspace.members")
        .iter()
        .map(|m| m.as_str().unwrap().to_string())
        .collect()
}

type Module = Vec<String>;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs")
            // A module's unit tests in a file of their own (`#[cfg(test)] mod tests;`) are
            // tests, as the part after `mod tests {` of a file is.
            && path.file_name().is_none_or(|n| n != "tests.rs")
        {
            out.push(path);
        }
    }
}

/// `src/a/b.rs` and `src/a/b/mod.rs` are module `a::b`; lib.rs and main.rs the root.
fn module_of(src: &Path, file: &Path) -> Module {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Module = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// The code that counts: no unit tests (they import their parent by design), no comments
/// (doc links are not imports).
fn code(text: &str) -> String {
    let body = text.split("mod tests {").next().unwrap_or(text);
    body.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

fn ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Paths after `crate::` or `super::`, a `{a, b::c}` group expanded into one path each.
fn paths_after(code: &str, keyword: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(at) = rest.find(keyword) {
        let before_ok = rest[..at].chars().last().is_none_or(|c| !ident_char(c));
        rest = &rest[at + keyword.len()..];
        if !before_ok {
            continue;
        }
        let mut prefix = Vec::new();
        let mut tail = rest;
        loop {
            let end = tail.find(|c: char| !ident_char(c)).unwrap_or(tail.len());
            if end == 0 {
                if let Some(group) = tail.strip_prefix('{') {
                    let close = group.find('}').unwrap_or(group.len());
                    for item in group[..close].split(',') {
                        let mut p = prefix.clone();
                        p.extend(
                            item.split("::")
                                .map(|s| s.trim().to_string())
                                .filter(|s| !s.is_empty() && s.chars().all(ident_char)),
                        );
                        out.push(p);
                    }
                } else {
                    out.push(prefix.clone());
                }
                break;
            }
            prefix.push(tail[..end].to_string());
            tail = &tail[end..];
            match tail.strip_prefix("::") {
                Some(t) => tail = t,
                None => {
                    out.push(prefix.clone());
                    break;
                }
            }
        }
    }
    out
}

/// The longest prefix of `path` that is a file's module.
fn target(path: &[String], modules: &BTreeSet<Module>) -> Option<Module> {
    (1..=path.len())
        .rev()
        .map(|k| path[..k].to_vec())
        .find(|m| modules.contains(m))
}

/// Which file imports which, per package; a `mod.rs` naming its own children (re-exports)
/// does not count as using them.
fn imports(package: &str) -> BTreeMap<Module, BTreeSet<Module>> {
    let src = workspace().join(package).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    // src/bin/* are separate crates.
    files.retain(|f| !f.strip_prefix(&src).unwrap().starts_with("bin"));
    let by_module: BTreeMap<Module, PathBuf> = files
        .iter()
        .map(|f| (module_of(&src, f), f.clone()))
        .collect();
    let modules: BTreeSet<Module> = by_module.keys().cloned().collect();
    let mut edges = BTreeMap::new();
    for (module, file) in &by_module {
        let text = code(&std::fs::read_to_string(file).unwrap());
        let parent: Module = module[..module.len().saturating_sub(1)].to_vec();
        let mut deps = BTreeSet::new();
        for path in paths_after(&text, "crate::") {
            deps.extend(target(&path, &modules));
        }
        for path in paths_after(&text, "super::") {
            let mut full = parent.clone();
            full.extend(path);
            deps.extend(target(&full, &modules));
        }
        let is_mod_file = file
            .file_name()
            .is_some_and(|n| n == "mod.rs" || n == "lib.rs" || n == "main.rs");
        deps.retain(|d| d != module);
        if is_mod_file {
            deps.retain(|d| !(d.len() == module.len() + 1 && d.starts_with(module)));
        }
        edges.insert(module.clone(), deps);
    }
    edges
}

/// Every module that reaches itself again, with the circle it takes.
fn circles(edges: &BTreeMap<Module, BTreeSet<Module>>) -> Vec<Vec<Module>> {
    let mut found = Vec::new();
    for start in edges.keys() {
        // Depth-first search for a path back to `start` through modules after it in order, so
        // each circle is reported once (from its smallest module).
        let mut stack = vec![(start.clone(), vec![start.clone()])];
        let mut seen = BTreeSet::new();
        while let Some((at, path)) = stack.pop() {
            for next in edges.get(&at).into_iter().flatten() {
                if next == start {
                    found.push(path.clone());
                } else if next > start && seen.insert(next.clone()) {
                    let mut p = path.clone();
                    p.push(next.clone());
                    stack.push((next.clone(), p));
                }
            }
        }
    }
    found
}

fn show(m: &Module) -> String {
    if m.is_empty() {
        "(root)".into()
    } else {
        m.join("::")
    }
}

#[test]
fn no_package_has_files_importing_each_other_in_circles() {
    let mut report = Vec::new();
    let mut modules = 0;
    let packages = packages();
    assert!(packages.len() >= 10, "{packages:?}");
    for package in &packages {
        let edges = imports(package);
        modules += edges.len();
        for circle in circles(&edges) {
            let names: Vec<String> = circle.iter().map(show).collect();
            report.push(format!("{package}: {}", names.join(" -> ")));
        }
    }
    // The scan itself must see the tree: the packages hold well over a hundred modules.
    assert!(
        modules > 100,
        "only {modules} modules found under {packages:?}"
    );
    assert!(report.is_empty(), "import circles:\n{}", report.join("\n"));
}

#[test]
fn the_circle_finder_finds_a_planted_circle() {
    // The detector on a graph with one circle (a -> b -> c -> a) and one chain: it must fail
    // on the first and pass the second, or the test above proves nothing.
    let m = |s: &str| vec![s.to_string()];
    let mut edges = BTreeMap::new();
    edges.insert(m("a"), BTreeSet::from([m("b")]));
    edges.insert(m("b"), BTreeSet::from([m("c")]));
    edges.insert(m("c"), BTreeSet::from([m("a"), m("d")]));
    edges.insert(m("d"), BTreeSet::new());
    assert_eq!(circles(&edges), vec![vec![m("a"), m("b"), m("c")]]);
    edges.insert(m("c"), BTreeSet::from([m("d")]));
    assert!(circles(&edges).is_empty());
    // And the path reader: groups, nested paths, `super`.
    let paths = paths_after(
        "use crate::x::{Y, z::W};\nlet q = super::v::f();",
        "crate::",
    );
    assert_eq!(
        paths,
        vec![
            vec!["x".to_string(), "Y".into()],
            vec!["x".into(), "z".into(), "W".into()]
        ]
    );
}

/// Names of what the core may not use: IPC, files, clocks, processes, signals, logging.
const IO_IN_SOURCE: &[&str] = &[
    "iceoryx2",
    "std::fs",
    "std::net",
    "std::process",
    "std::env",
    "Instant::now",
    "SystemTime",
    "tracing::",
    "println!",
    "eprintln!",
];

/// Nor threads and channels: its long solves leave as jobs (`solve.rs`) that the daemon runs on
/// its own thread. (The paper's study, which computes its cells on scoped threads, lives in the
/// lab.)
const THREADS_IN_SOURCE: &[&str] = &["std::thread", "mpsc", "Mutex", "Condvar"];

#[test]
fn the_pure_core_does_no_io() {
    // Its own dependencies: protocol (message types and bounds), driver-kit without its
    // `process` feature, maths and serde. protocol brings iceoryx2 along for its zero-copy
    // message types (and the core's config checks a namespace with protocol's IpcConfig),
    // which is why the check below is on the core's sources, not on the whole tree.
    let out = Command::new(env!("CARGO"))
        .args(["tree", "--offline", "-p", "thrusterd-core", "-e", "normal"])
        .args(["--depth", "1", "--prefix", "none", "-f", "{p} {f}"])
        .current_dir(workspace())
        .output()
        .expect("cargo tree runs");
    let tree = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && tree.contains("nalgebra"),
        "cargo tree failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let io: Vec<&str> = tree
        .lines()
        .filter(|l| {
            let name = l.split_whitespace().next().unwrap_or("");
            let io_crate = [
                "iceoryx2",
                "ctrlc",
                "tracing",
                "tracing-subscriber",
                "tracing-journald",
                "sd-notify",
                "mcap",
            ]
            .contains(&name);
            io_crate || (name == "thruster-driver-kit" && l.contains("process"))
        })
        .collect();
    assert!(io.is_empty(), "thrusterd-core depends on {io:?}");

    let src = workspace().join("daemon/core/src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut uses = Vec::new();
    for file in &files {
        let text = code(&std::fs::read_to_string(file).unwrap());
        for (n, line) in text.lines().enumerate() {
            for name in IO_IN_SOURCE
                .iter()
                .chain(THREADS_IN_SOURCE)
                .filter(|name| line.contains(*name))
            {
                uses.push(format!("{}: {name}: {}", file.display(), n + 1));
            }
        }
    }
    assert!(
        files.len() > 30,
        "only {} files under {}",
        files.len(),
        src.display()
    );
    assert!(uses.is_empty(), "IO in the pure core:\n{}", uses.join("\n"));
}

/// The longest a product file may be, in lines before its unit tests (`mod tests {`): one
/// file, one job, read in one sitting (issue 28).
const MAX_LINES: usize = 900;

/// Files still over [`MAX_LINES`]: being split under issue 28. The list only shrinks: a file
/// on it that is back under the limit fails the test below until it is taken off.
const OVER_MAX_LINES: &[&str] = &[];

/// Lines of a file before its unit tests.
fn product_lines(text: &str) -> usize {
    text.split("mod tests {")
        .next()
        .unwrap_or(text)
        .lines()
        .count()
}

#[test]
fn no_product_file_is_over_900_lines() {
    let mut over = Vec::new();
    let mut seen = 0;
    for package in packages() {
        let mut files = Vec::new();
        rust_files(&workspace().join(&package).join("src"), &mut files);
        for file in files {
            seen += 1;
            let lines = product_lines(&std::fs::read_to_string(&file).unwrap());
            let rel = file.strip_prefix(workspace()).unwrap().to_string_lossy();
            // On Windows-style paths too: the list is written with '/'.
            let rel = rel.replace('\\', "/");
            let allowed = OVER_MAX_LINES.contains(&rel.as_str());
            if lines > MAX_LINES && !allowed {
                over.push(format!("{rel}: {lines} lines"));
            }
            if lines <= MAX_LINES && allowed {
                over.push(format!(
                    "{rel}: {lines} lines, now under {MAX_LINES}: take it off OVER_MAX_LINES"
                ));
            }
        }
    }
    assert!(seen > 100, "only {seen} files under the packages' src/");
    for listed in OVER_MAX_LINES {
        assert!(
            workspace().join(listed).exists(),
            "{listed} is on OVER_MAX_LINES but gone: take it off"
        );
    }
    assert!(
        over.is_empty(),
        "files over {MAX_LINES} lines:\n{}",
        over.join("\n")
    );
    // The counter itself: the unit tests after `mod tests {` do not count.
    let text = format!("{}mod tests {{\n{}", "x\n".repeat(3), "y\n".repeat(5000));
    assert_eq!(product_lines(&text), 3);
}

/// What makes a file plotting code: it writes SVG.
fn writes_svg(text: &str) -> bool {
    text.contains("<svg")
}

/// Research lives in the lab (issue 28): the core has no study, no plotting and no way to
/// reach the lab.
#[test]
fn the_core_has_no_study_no_plotting_and_no_lab() {
    let core = workspace().join("daemon/core");
    let src = core.join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    assert!(
        files.len() > 30,
        "only {} files under {}",
        files.len(),
        src.display()
    );
    let mut found = Vec::new();
    for file in &files {
        let module = module_of(&src, file);
        let text = code(&std::fs::read_to_string(file).unwrap());
        if module.iter().any(|m| m == "study" || m.starts_with("plot")) {
            found.push(format!("{}: a study or plot module", file.display()));
        }
        if text.contains("mod study") {
            found.push(format!("{}: declares mod study", file.display()));
        }
        if writes_svg(&text) {
            found.push(format!("{}: writes SVG", file.display()));
        }
    }
    let manifest: toml::Value =
        toml::from_str(&std::fs::read_to_string(core.join("Cargo.toml")).unwrap()).unwrap();
    for section in ["dependencies", "dev-dependencies", "build-dependencies"] {
        if manifest
            .get(section)
            .and_then(|d| d.get("thruster-lab"))
            .is_some()
        {
            found.push(format!(
                "daemon/core/Cargo.toml: thruster-lab in [{section}]"
            ));
        }
    }
    assert!(
        found.is_empty(),
        "research in the core:\n{}",
        found.join("\n")
    );
    // The SVG check itself: the lab's writer is caught by it.
    let lab_plot = workspace().join("daemon/lab/src/plot.rs");
    assert!(writes_svg(&code(
        &std::fs::read_to_string(lab_plot).unwrap()
    )));
}

/// The names an IMU reading type goes by: the ones the drivers and the core used to define
/// each for themselves (`ImuReading`, `SensorReading`, `ImuSi`, `ImuInput`) and any other
/// `Imu...` + `Reading`/`Sample`/`Si`/`Input`/`Payload`/`Measurement`.
fn names_an_imu_reading(name: &str) -> bool {
    let tail = ["Reading", "Sample", "Si", "Input", "Payload", "Measurement"];
    name == "SensorReading" || (name.starts_with("Imu") && tail.iter().any(|t| name.ends_with(t)))
}

/// Every `struct`, `enum` or `type` defined in `text` (comments skipped, unit tests
/// included) whose name [`names_an_imu_reading`]. A `pub use X as Y` is no definition: it
/// names the same type.
fn imu_reading_types(text: &str) -> Vec<String> {
    let mut found = Vec::new();
    for line in text.lines().filter(|l| !l.trim_start().starts_with("//")) {
        let words: Vec<&str> = line.split(|c: char| !ident_char(c)).collect();
        for pair in words.windows(2) {
            if matches!(pair[0], "struct" | "enum" | "type") && names_an_imu_reading(pair[1]) {
                found.push(pair[1].to_string());
            }
        }
    }
    found
}

#[test]
fn there_is_one_imu_reading_type_and_it_is_the_protocols() {
    // The copper-rs cut (one payload type per sensor, shared by every source): the protocol
    // defines the wire sample and the one SI reading with its conversion; the simulator's
    // sensors, the hardware backends and the core use that reading instead of their own.
    let mut outside = Vec::new();
    let mut in_protocol = BTreeSet::new();
    let mut files_seen = 0;
    for package in packages() {
        let root = workspace().join(&package);
        for dir in ["src", "tests", "benches", "examples"] {
            let dir = root.join(dir);
            if !dir.is_dir() {
                continue;
            }
            let mut files = Vec::new();
            rust_files(&dir, &mut files);
            for file in files {
                files_seen += 1;
                // This file names the old types on purpose (the finder's own test).
                if file.ends_with("tests/tests/layout.rs") {
                    continue;
                }
                let text = std::fs::read_to_string(&file).unwrap();
                for name in imu_reading_types(&text) {
                    if package == "protocol" && dir.ends_with("src") {
                        in_protocol.insert(name);
                    } else {
                        outside.push(format!("{}: {name}", file.display()));
                    }
                }
            }
        }
    }
    assert!(files_seen > 200, "only {files_seen} files scanned");
    assert!(
        outside.is_empty(),
        "IMU reading types outside the protocol (use thruster_protocol::ImuReading):\n{}",
        outside.join("\n")
    );
    assert_eq!(
        in_protocol,
        BTreeSet::from(["ImuReading".to_string(), "ImuSample".to_string()]),
        "the protocol's IMU types: the wire sample and the one reading"
    );
}

#[test]
fn the_reading_finder_finds_the_old_reading_types() {
    // What the drivers and the core defined before (so the test above can fail), and what it
    // must let pass: a re-export under another name, the noise settings, a comment.
    let old = "pub struct ImuReading {\nstruct SensorReading { t_ns: u64 }\n\
               pub struct ImuSi {\n#[derive(Debug)] pub struct ImuInput {";
    assert_eq!(
        imu_reading_types(old),
        ["ImuReading", "SensorReading", "ImuSi", "ImuInput"]
    );
    let fine = "pub use thruster_protocol::ImuReading as ImuInput;\npub struct ImuNoise {\n\
                // struct ImuSi was here\nfn imu_sample(r: &ImuReading) -> ImuSample {";
    assert!(imu_reading_types(fine).is_empty());
}
