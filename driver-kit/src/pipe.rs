//! Exiting quietly when the reader of stdout goes away (`thrusterctl demo | head -1`).
//!
//! Rust ignores SIGPIPE, so a write to a closed pipe fails with EPIPE and `println!` panics on
//! it ("failed printing to stdout: Broken pipe", a panic message and exit 101). Restoring
//! SIGPIPE's default action instead would kill a process on any closed socket, thruster-hw's
//! TCP link to the autopilot included, before it could put the thrusters neutral. So the
//! panic is recognised here: it prints nothing, unwinding drops every port, node and child
//! guard on the way (the namespace stays clean), and the process exits 0 (the reader had
//! what it wanted). Every binary's `main` goes through [`main`].

use std::panic::{self, AssertUnwindSafe};
use std::process::ExitCode;

/// Runs `body` (the real main) so that a broken stdout or stderr pipe ends the process
/// quietly with [`ExitCode::SUCCESS`]; any other panic behaves as usual.
pub fn main(body: impl FnOnce() -> ExitCode) -> ExitCode {
    let previous = panic::take_hook();
    panic::set_hook(Box::new(move |info| {
        if !payload_text(info.payload()).is_some_and(is_broken_pipe_panic) {
            previous(info);
        }
    }));
    // The closure runs once and its state is dropped by the unwind: nothing observes it
    // half-updated afterwards.
    match panic::catch_unwind(AssertUnwindSafe(body)) {
        Ok(code) => code,
        Err(payload) => {
            if payload_text(payload.as_ref()).is_some_and(is_broken_pipe_panic) {
                ExitCode::SUCCESS
            } else {
                panic::resume_unwind(payload)
            }
        }
    }
}

/// True when `error` or one of its sources is an I/O error of kind BrokenPipe: a command
/// that writes with `writeln!` and `?` returns it instead of panicking.
pub fn is_broken_pipe(error: &(dyn std::error::Error + 'static)) -> bool {
    let mut next = Some(error);
    while let Some(e) = next {
        if e.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
        {
            return true;
        }
        next = e.source();
    }
    false
}

/// A panic's message: a `String` for a formatted one (std's print panics), else a `&str`.
/// (`PanicHookInfo::payload_as_str` does this from Rust 1.91, above this project's MSRV.)
fn payload_text(payload: &(dyn std::any::Any + Send)) -> Option<&str> {
    payload
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| payload.downcast_ref::<&str>().copied())
}

/// The message std's `print!`/`eprint!` family panics with on a failed write, for EPIPE.
fn is_broken_pipe_panic(message: &str) -> bool {
    // "Broken pipe (os error 32)" from the OS, "broken pipe" for an error built from the kind.
    message.starts_with("failed printing to std")
        && message.to_ascii_lowercase().contains("broken pipe")
}

/// Exit code of a configuration that cannot be used (a file or the command line), where
/// any other failure exits 1: a script tells "fix the config" from "it failed", and the
/// units' `RestartPreventExitStatus=2` keeps systemd from restarting what a restart cannot fix.
pub const EXIT_CONFIG: u8 = 2;

/// An error that is the configuration's: [`driver_main`] exits [`EXIT_CONFIG`] for it.
/// Prints as the error it wraps, with that error's causes.
#[derive(Debug)]
pub struct BadConfig(pub Box<dyn std::error::Error + Send + Sync>);

impl BadConfig {
    pub fn new(error: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> BadConfig {
        BadConfig(error.into())
    }
}

impl std::fmt::Display for BadConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

impl std::error::Error for BadConfig {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.0.source()
    }
}

/// True when `error` or one of its sources is a [`BadConfig`].
pub fn is_bad_config(error: &(dyn std::error::Error + 'static)) -> bool {
    let mut next = Some(error);
    while let Some(e) = next {
        if e.is::<BadConfig>() {
            return true;
        }
        next = e.source();
    }
    false
}

/// The whole `main` of a driver process: [`main`]'s quiet exit on a closed pipe, logging
/// (journald under systemd, stderr otherwise), then `run`; an error is logged on one line
/// (`{:#}`: anyhow joins its causes) and the process exits [`EXIT_CONFIG`] for a
/// [`BadConfig`], else 1.
pub fn driver_main<E>(run: impl FnOnce() -> Result<(), E>) -> ExitCode
where
    E: std::fmt::Display + AsRef<dyn std::error::Error + Send + Sync + 'static>,
{
    main(|| {
        crate::logging::init("info");
        match run() {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                tracing::error!("{e:#}");
                crate::systemd::report_failure(&format!("{e:#}"));
                let error: &(dyn std::error::Error + 'static) = e.as_ref();
                if is_bad_config(error) {
                    ExitCode::from(EXIT_CONFIG)
                } else {
                    ExitCode::FAILURE
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_config_is_found_under_any_context_and_prints_as_itself() {
        #[derive(Debug, thiserror::Error)]
        #[error("starting the driver")]
        struct Context(#[source] BadConfig);
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "x.toml: no such file");
        let bad = Context(BadConfig::new(io));
        assert!(is_bad_config(&bad));
        assert_eq!(bad.0.to_string(), "x.toml: no such file");
        let other = std::io::Error::other("the PWM chip is gone");
        assert!(!is_bad_config(&other));
    }

    #[test]
    fn a_print_to_a_closed_pipe_exits_quietly_and_other_panics_propagate() {
        // What std panics with when stdout's reader is gone (a real EPIPE: the message
        // names the os error).
        let epipe = std::io::Error::from_raw_os_error(32);
        assert_eq!(epipe.kind(), std::io::ErrorKind::BrokenPipe);
        let msg = format!("failed printing to stdout: {epipe}");
        assert!(is_broken_pipe_panic(&msg), "{msg}");
        assert_eq!(main(|| panic!("{msg}")), ExitCode::SUCCESS);
        let other = panic::catch_unwind(|| main(|| panic!("something else")));
        assert!(other.is_err());
        assert!(!is_broken_pipe_panic(
            "failed printing to stdout: disk full"
        ));
    }

    #[test]
    fn a_broken_pipe_error_is_found_in_the_source_chain() {
        #[derive(Debug, thiserror::Error)]
        #[error("writing the report")]
        struct Wrapper(#[source] std::io::Error);
        let e = Wrapper(std::io::Error::from_raw_os_error(32));
        assert!(is_broken_pipe(&e));
        let e = Wrapper(std::io::Error::other("no"));
        assert!(!is_broken_pipe(&e));
    }
}
