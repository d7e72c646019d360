//! Reading TOML with errors that name the file, the line and the key.
//!
//! Every table uses `#[serde(deny_unknown_fields)]`, so a typo is an error with a position
//! rather than a silently ignored setting (a misspelt `watchdog_ms` must not quietly leave
//! the default in charge of real thrusters).

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// A configuration file could not be read, parsed or validated.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// Not valid TOML, or not the expected structure (unknown key, wrong type, missing key,
    /// value out of range). `line` and `column` are 1-based; 0 when toml gave no position.
    #[error("{origin}:{line}:{column}: {message}")]
    Parse {
        /// The file (or "defaults").
        origin: String,
        /// Line of the offending text.
        line: usize,
        /// Column of the offending text.
        column: usize,
        /// toml's message (names the key).
        message: String,
    },
    /// The structure is right but values contradict each other (named by key path).
    #[error("{origin}: invalid `{key}`: {reason}")]
    Invalid {
        /// The file.
        origin: String,
        /// Key path, e.g. `thruster[2].neutral_us`.
        key: String,
        /// What is wrong.
        reason: String,
    },
}

impl LoadError {
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
    std::fs::read_to_string(path).map_err(|source| LoadError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Parses `text` into `T`; `origin` (usually the file path) prefixes every error.
pub fn parse_toml<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, LoadError> {
    toml::from_str(text).map_err(|e| {
        let (line, column) = e
            .span()
            .map(|span| line_column(text, span.start))
            .unwrap_or((0, 0));
        LoadError::Parse {
            origin: origin.to_string(),
            line,
            column,
            message: e.message().trim().to_string(),
        }
    })
}

/// 1-based line and column (in characters) of byte offset `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = text.get(..offset).unwrap_or("");
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before.get(line_start..).map_or(0, |s| s.chars().count()) + 1;
    (line, column)
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
    fn parse_error_has_line_and_key() {
        match parse_toml::<Small>("a = 1.0\nbogus = 2\n", "x.toml") {
            Err(LoadError::Parse {
                origin,
                line,
                message,
                ..
            }) => {
                assert_eq!((origin.as_str(), line), ("x.toml", 2));
                assert!(message.contains("bogus"), "{message}");
            }
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    #[test]
    fn line_column_counts_from_one() {
        assert_eq!(line_column("ab\ncd", 0), (1, 1));
        assert_eq!(line_column("ab\ncd", 4), (2, 2));
    }
}
