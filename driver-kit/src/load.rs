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
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
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
    /// The structure is right but a value is not acceptable (named by its key path).
    #[error("{origin}: invalid `{key}`: {reason}")]
    Invalid {
        origin: String,
        key: String,
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
    // The span comes from toml and lies on a char boundary; fall back to the line start if not.
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
    fn line_column_counts_from_one() {
        assert_eq!(line_column("ab\ncd", 0), (1, 1));
        assert_eq!(line_column("ab\ncd", 4), (2, 2));
    }
}
