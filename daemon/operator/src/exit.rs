//! Exit codes and the error type that carries one.
//!
//! Scripts (and the system tests) branch on the exit code, so each outcome an operator may
//! want to handle differently gets its own code. Errors without a [`Failure`] in their chain
//! exit with [`GENERIC`].

use std::fmt;

// 0 is success.
/// Anything else: IPC error, file error, invalid data from the daemon.
pub const GENERIC: u8 = 1;
/// Invalid command line (clap uses 2 for its own parse errors; our range checks match it).
pub const USAGE: u8 = 2;
/// The daemon is not running on the namespace (no control server).
pub const NOT_RUNNING: u8 = 3;
/// The daemon answered and refused (or failed) the request.
pub const REFUSED: u8 = 4;
/// The daemon is there but did not answer, or did not publish, in time.
pub const TIMEOUT: u8 = 5;
/// Estimation ended in Fault, or without producing a new model.
pub const ESTIMATION_FAILED: u8 = 6;
/// This user may not operate the namespace (not the owner or in the group of its ipc root);
/// refused before any file was created.
pub const FORBIDDEN: u8 = 7;
/// Interrupted by Ctrl-C while waiting (128 + SIGINT, the shell convention).
pub const INTERRUPTED: u8 = 130;

/// An error with a specific exit code. The message is what the operator reads.
#[derive(Debug)]
pub struct Failure {
    /// Process exit code.
    pub code: u8,
    message: String,
}

impl Failure {
    pub fn new(code: u8, message: impl Into<String>) -> Self {
        Self {
            code,
            message: message.into(),
        }
    }

    pub fn usage(message: impl Into<String>) -> Self {
        Self::new(USAGE, message)
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Failure {}

/// The exit code for an error: the first [`Failure`] in its chain, else [`GENERIC`].
pub fn code_of(error: &anyhow::Error) -> u8 {
    error
        .chain()
        .find_map(|e| e.downcast_ref::<Failure>())
        .map_or(GENERIC, |f| f.code)
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context;

    #[test]
    fn code_survives_context() {
        let e: anyhow::Result<()> = Err(Failure::new(NOT_RUNNING, "gone").into());
        let e = e.context("reading status").unwrap_err();
        assert_eq!(code_of(&e), NOT_RUNNING);
        assert_eq!(code_of(&anyhow::anyhow!("plain")), GENERIC);
    }
}
