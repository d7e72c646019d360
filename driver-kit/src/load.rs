//! Reading TOML configuration with errors that name the file, the line and the key.
//!
//! Every configuration struct of the drivers uses `#[serde(deny_unknown_fields)]`, so a typo is
//! an error with a position rather than a silently ignored setting.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// A configuration file could not be read, parsed or validated.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file could not be read.
    // The OS error is in the message and not a `source`: a chain printed whole ("{:#}", as
    // every binary prints its error) said it twice.
    #[error("{}: cannot read: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// The text is not valid TOML or does not match the expected structure (unknown key, wrong
    /// type, missing field). `line` and `column` are 1-based; 0 when toml gave no position.
    #[error("{origin}:{line}:{column}: {message}")]
    Parse {
        origin: String,
        line: usize,
        column: usize,
        message: String,
    },
    /// A value is not acceptable, with its place in the file when it has one there.
    #[error("{origin}{at}: {key}: {reason}")]
    Value {
        origin: String,
        at: At,
        key: String,
        reason: String,
    },
    /// The structure is right but a value is not acceptable (named by its key path).
    #[error("{origin}: invalid `{key}`: {reason}")]
    Invalid {
        origin: String,
        key: String,
        reason: String,
    },
}

/// Where a value sits in a file: 1-based line and column, or nowhere (a default, or a value
/// from the command line).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct At(pub Option<(usize, usize)>);

impl std::fmt::Display for At {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Some((line, column)) => write!(f, ":{line}:{column}"),
            None => Ok(()),
        }
    }
}

/// An allowed interval, as messages print it: `[0, 1]`, `(0, inf)`, `[1, 16]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    pub lo: f64,
    pub hi: f64,
    pub lo_open: bool,
    pub hi_open: bool,
}

impl Range {
    /// `[lo, hi]`.
    pub fn closed(lo: f64, hi: f64) -> Range {
        Range {
            lo,
            hi,
            lo_open: false,
            hi_open: false,
        }
    }
    /// `(lo, inf)`: strictly above `lo`, finite.
    pub fn above(lo: f64) -> Range {
        Range {
            lo,
            hi: f64::INFINITY,
            lo_open: true,
            hi_open: true,
        }
    }
    /// `[lo, inf)`: at least `lo`, finite.
    pub fn at_least(lo: f64) -> Range {
        Range {
            lo,
            hi: f64::INFINITY,
            lo_open: false,
            hi_open: true,
        }
    }
    /// `(lo, hi]`.
    pub fn above_to(lo: f64, hi: f64) -> Range {
        Range {
            lo,
            hi,
            lo_open: true,
            hi_open: false,
        }
    }
    /// `[lo, hi)`.
    pub fn from_below(lo: f64, hi: f64) -> Range {
        Range {
            lo,
            hi,
            lo_open: false,
            hi_open: true,
        }
    }
    /// True for a value inside (NaN never is).
    pub fn contains(&self, v: f64) -> bool {
        let above = if self.lo_open {
            v > self.lo
        } else {
            v >= self.lo
        };
        let below = if self.hi_open {
            v < self.hi
        } else {
            v <= self.hi
        };
        above && below
    }
}

impl std::fmt::Display for Range {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}{}, {}{}",
            if self.lo_open { '(' } else { '[' },
            self.lo,
            self.hi,
            if self.hi_open { ')' } else { ']' }
        )
    }
}

impl LoadError {
    /// A value outside `range`, located in `text` by its key path (`machine.pulse_s`,
    /// `controller.kp_att[1]`): `file:line:col: key: must be in [a, b], got x`, the form
    /// every binary uses.
    pub fn out_of_range(
        origin: &str,
        text: &str,
        key: &str,
        range: Range,
        got: impl std::fmt::Display,
    ) -> Self {
        Self::value(origin, text, key, format!("must be in {range}, got {got}"))
    }

    /// Any other unusable value, located the same way: `file:line:col: key: reason`.
    pub fn value(origin: &str, text: &str, key: &str, reason: impl Into<String>) -> Self {
        Self::value_shown(origin, text, key, key, reason)
    }

    /// As [`LoadError::value`], but the message shows `shown` for the key, e.g.
    /// `thruster[2] ("L").forward_max_n` for the value located by `thruster[2].forward_max_n`.
    pub fn value_shown(
        origin: &str,
        text: &str,
        key: &str,
        shown: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        LoadError::Value {
            origin: origin.to_string(),
            at: At(locate(text, key)),
            key: shown.into(),
            reason: reason.into(),
        }
    }

    /// Shorthand for [`LoadError::Invalid`].
    pub fn invalid(origin: &str, key: impl Into<String>, reason: impl Into<String>) -> Self {
        LoadError::Invalid {
            origin: origin.to_string(),
            key: key.into(),
            reason: reason.into(),
        }
    }
}

/// Reads a whole file as UTF-8 text.
pub fn read_text(path: &Path) -> Result<String, LoadError> {
    std::fs::read_to_string(path).map_err(|error| LoadError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// Parses `text` into `T`; `origin` (usually the file path) prefixes every error. An error
/// about a value names its key when serde's message does not (a wrong type, a range check
/// inside deserialisation): `file:line:col: sensors.rate_hz: invalid type: string "fast",
/// expected f64`.
pub fn parse_toml<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, LoadError> {
    toml::from_str(text).map_err(|e| {
        let (line, column) = e
            .span()
            .map(|span| line_column(text, span.start))
            .unwrap_or((0, 0));
        // Some syntax errors carry their reason only in the rendered form (the last line,
        // under the caret), not in `message()`.
        let message = match e.message().trim() {
            "" => e
                .to_string()
                .lines()
                .rev()
                .map(str::trim)
                .find(|l| !l.is_empty() && !l.ends_with('|') && !l.contains('^'))
                .unwrap_or("invalid TOML")
                .to_string(),
            m => m.to_string(),
        };
        let key = e.span().and_then(|span| key_at(text, span.start));
        LoadError::Parse {
            origin: origin.to_string(),
            line,
            column,
            message: match key {
                Some(key) if !names(&message, &key) => format!("{key}: {message}"),
                _ => message,
            },
        }
    })
}

/// Whether `message` already names `key`'s last part as a word (`unknown field `spinn_us``,
/// `rate_hz: ...`), so the key is not repeated in front of it.
fn names(message: &str, key: &str) -> bool {
    let leaf = key.rsplit('.').next().unwrap_or(key);
    let leaf = leaf.split('[').next().unwrap_or(leaf);
    if leaf.is_empty() {
        return true;
    }
    let word = |c: char| c.is_alphanumeric() || c == '_' || c == '-';
    message.match_indices(leaf).any(|(i, _)| {
        let before = message[..i].chars().next_back();
        let after = message[i + leaf.len()..].chars().next();
        !before.is_some_and(word) && !after.is_some_and(word)
    })
}

/// The key path (`lockstep.timeout_ms`, `thruster[1].position_m[2]`) of the innermost key or
/// value of `text` whose text contains byte `offset`; None when `text` is not valid TOML or
/// nothing there contains it.
pub fn key_at(text: &str, offset: usize) -> Option<String> {
    let doc = toml_edit::ImDocument::parse(text).ok()?;
    let mut found = None;
    find_in_table(doc.as_table(), "", offset, &mut found);
    found
}

fn contains(span: Option<std::ops::Range<usize>>, offset: usize) -> bool {
    span.is_some_and(|s| s.contains(&offset))
}

fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

// Parents are visited before their children, so the innermost match is the last one kept.
fn find_in_table(table: &toml_edit::Table, path: &str, offset: usize, found: &mut Option<String>) {
    for (name, item) in table.iter() {
        let path = join(path, name);
        if contains(table.key(name).and_then(toml_edit::Key::span), offset) {
            *found = Some(path.clone());
        }
        find_in_item(item, &path, offset, found);
    }
}

fn find_in_item(item: &toml_edit::Item, path: &str, offset: usize, found: &mut Option<String>) {
    match item {
        toml_edit::Item::Value(v) => find_in_value(v, path, offset, found),
        toml_edit::Item::Table(t) => {
            if contains(t.span(), offset) {
                *found = Some(path.to_string());
            }
            find_in_table(t, path, offset, found);
        }
        toml_edit::Item::ArrayOfTables(a) => {
            for (i, t) in a.iter().enumerate() {
                let path = format!("{path}[{i}]");
                if contains(t.span(), offset) {
                    *found = Some(path.clone());
                }
                find_in_table(t, &path, offset, found);
            }
        }
        toml_edit::Item::None => {}
    }
}

fn find_in_value(value: &toml_edit::Value, path: &str, offset: usize, found: &mut Option<String>) {
    if contains(value.span(), offset) {
        *found = Some(path.to_string());
    }
    match value {
        toml_edit::Value::Array(a) => {
            for (i, v) in a.iter().enumerate() {
                find_in_value(v, &format!("{path}[{i}]"), offset, found);
            }
        }
        toml_edit::Value::InlineTable(t) => {
            for (name, v) in t.iter() {
                let path = join(path, name);
                if contains(t.key(name).and_then(toml_edit::Key::span), offset) {
                    *found = Some(path.clone());
                }
                find_in_value(v, &path, offset, found);
            }
        }
        _ => {}
    }
}

/// Line and column of the value of `key` (dotted path, `[i]` for an array element or a
/// table of an array of tables) in `text`; None when the file does not set it.
pub fn locate(text: &str, key: &str) -> Option<(usize, usize)> {
    let doc = toml_edit::ImDocument::parse(text).ok()?;
    let mut item: &toml_edit::Item = doc.as_item();
    let mut span = None;
    for part in key.split('.') {
        let (name, indices) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        item = item.get(name)?;
        span = item.span();
        for index in indices
            .split(['[', ']'])
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<usize>().ok())
        {
            // An element of an array, or a table of an array of tables.
            item = item.get(index?)?;
            span = item.span();
        }
    }
    span.map(|s| line_column(text, s.start))
}

/// 1-based line and column (in characters) of byte offset `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    // The span comes from toml and lies on a char boundary; fall back to the line start if not.
    let before = text.get(..offset).unwrap_or("");
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before.get(line_start..).map_or(0, |s| s.chars().count()) + 1;
    (line, column)
}

/// Problems with a driver's settings: its file, or a setting neither on the command line nor
/// in the file, or a command-line value out of range. One type for every driver (thruster-sim,
/// thruster-hw), so they word these errors alike.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    /// The config file could not be read or parsed, or a value in it is invalid.
    #[error(transparent)]
    File(#[from] LoadError),
    /// A required setting is neither on the command line nor in the file.
    #[error("missing `{key}`: give {flag} or set `{key}` in the config file")]
    Missing {
        /// Key in the config file.
        key: &'static str,
        /// The command-line option.
        flag: &'static str,
    },
    /// A command-line value is out of range.
    #[error("{flag}: {reason}")]
    Argument {
        /// The option, e.g. `--rate`.
        flag: &'static str,
        /// What is wrong.
        reason: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Small {
        a: f64,
    }

    #[test]
    fn parse_error_has_line_and_column() {
        let text = "a = 1.0\nbogus = 2\n";
        match parse_toml::<Small>(text, "x.toml") {
            Err(LoadError::Parse {
                origin,
                line,
                message,
                ..
            }) => {
                assert_eq!(origin, "x.toml");
                assert_eq!(line, 2);
                assert!(message.contains("bogus"), "{message}");
            }
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    #[test]
    fn values_are_located_by_key_path() {
        let text = "[machine]\npulse_s = -3\n[controller]\nkp_att = [1.0, nan, 1.0]\n\
                    [[vehicle.thruster]]\nposition_m = [0, 0, 0]\n[[vehicle.thruster]]\n\
                    direction = [0, 0, 0]\n";
        assert_eq!(locate(text, "machine.pulse_s"), Some((2, 11)));
        assert_eq!(locate(text, "controller.kp_att[1]"), Some((4, 16)));
        assert_eq!(locate(text, "vehicle.thruster[1].direction"), Some((8, 13)));
        assert_eq!(locate(text, "machine.noise_s"), None);
        let e = LoadError::out_of_range("d.toml", text, "machine.pulse_s", Range::above(0.0), -3);
        assert_eq!(
            e.to_string(),
            "d.toml:2:11: machine.pulse_s: must be in (0, inf), got -3"
        );
        let e =
            LoadError::out_of_range("d.toml", "", "machine.pulse_s", Range::closed(1.0, 16.0), 0);
        assert_eq!(
            e.to_string(),
            "d.toml: machine.pulse_s: must be in [1, 16], got 0"
        );
        assert!(
            Range::from_below(0.0, 0.5).contains(0.0) && !Range::from_below(0.0, 0.5).contains(0.5)
        );
        assert!(
            !Range::at_least(0.0).contains(f64::NAN)
                && !Range::at_least(0.0).contains(f64::INFINITY)
        );
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Nested {
        #[serde(default)]
        lockstep: Option<Lockstep>,
        #[serde(default)]
        thruster: Vec<Small>,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Lockstep {
        #[serde(default, deserialize_with = "positive")]
        timeout_ms: u64,
        #[serde(default)]
        pace: f64,
    }

    fn positive<'de, D: serde::Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
        let v = <u64 as serde::Deserialize>::deserialize(d)?;
        if v > 0 {
            Ok(v)
        } else {
            Err(serde::de::Error::custom(format!(
                "must be in [1, 600000] ms, got {v}"
            )))
        }
    }

    #[test]
    fn errors_about_a_value_name_its_key() {
        let parse = |text: &str| {
            parse_toml::<Nested>(text, "s.toml")
                .unwrap_err()
                .to_string()
        };
        // A range check inside deserialisation, shared by several keys, knows no key name.
        assert_eq!(
            parse("[lockstep]\ntimeout_ms = 0\n"),
            "s.toml:2:14: lockstep.timeout_ms: must be in [1, 600000] ms, got 0"
        );
        // A wrong type.
        assert_eq!(
            parse("[lockstep]\npace = \"fast\"\n"),
            "s.toml:2:8: lockstep.pace: invalid type: string \"fast\", expected f64"
        );
        // In a table of an array of tables, and in an inline table.
        assert_eq!(
            parse("[[thruster]]\na = 1.0\n[[thruster]]\na = true\n"),
            "s.toml:4:5: thruster[1].a: invalid type: boolean `true`, expected f64"
        );
        assert_eq!(
            parse("lockstep = { pace = 1.0, timeout_ms = -1 }\n"),
            "s.toml:1:39: lockstep.timeout_ms: invalid value: integer `-1`, expected u64"
        );
        // A message that names the key already is left as it is.
        let e = parse("[lockstep]\ntimeout_ms = 3\nspinn_us = 3\n");
        assert!(e.starts_with("s.toml:3:1: unknown field `spinn_us`"), "{e}");
        assert!(names("unknown field `pace`, expected", "lockstep.pace"));
        assert!(!names("space", "lockstep.pace"));
        assert_eq!(key_at("a = [1, 2]\n", 8), Some("a[1]".to_string()));
        assert_eq!(key_at("a = [1, 2\n", 8), None);
    }

    #[test]
    fn a_file_that_cannot_be_read_says_why_once() {
        let dir = tempfile::tempdir().unwrap();
        let e = read_text(&dir.path().join("nope.toml")).unwrap_err();
        // Not also a `source`: "{:#}" (anyhow, every binary) printed the OS error twice.
        assert!(std::error::Error::source(&e).is_none(), "{e:?}");
        let msg = e.to_string();
        assert!(
            msg.ends_with("nope.toml: cannot read: No such file or directory (os error 2)"),
            "{msg}"
        );
    }

    #[test]
    fn line_column_counts_from_one() {
        assert_eq!(line_column("ab\ncd", 0), (1, 1));
        assert_eq!(line_column("ab\ncd", 4), (2, 2));
    }
}
