//! A child process of the lab (thrusterd, thruster-sim) that dies with the lab and is killed
//! and reaped on drop, with its log for error messages.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

/// Whether the session's folder (the children's logs and config) is kept for a post-mortem
/// (`THRUSTERCTL_KEEP_LOGS` set).
pub(crate) fn keep_logs() -> bool {
    std::env::var_os("THRUSTERCTL_KEEP_LOGS").is_some()
}

/// A child process killed and reaped on drop, whatever happens.
pub struct ChildProc {
    pub(crate) name: &'static str,
    child: Option<Child>,
    pub(crate) log: PathBuf,
}

impl ChildProc {
    /// `piped`: standard input and output are pipes to this process (a stepped simulator's
    /// protocol, [`thruster_sim::stepper`]); the log is then standard error only.
    pub(crate) fn spawn(
        name: &'static str,
        exe: &Path,
        args: &[String],
        dir: &Path,
        piped: bool,
    ) -> Result<ChildProc> {
        let log = dir.join(format!("{name}.log"));
        let out = std::fs::File::create(&log)?;
        let (stdin, stdout) = if piped {
            (Stdio::piped(), Stdio::piped())
        } else {
            (Stdio::null(), Stdio::from(out.try_clone()?))
        };
        let mut cmd = Command::new(exe);
        cmd.args(args).stdin(stdin).stdout(stdout).stderr(out);
        // A lab killed by a signal runs no destructor: without this its daemon (which in
        // lockstep never takes the silence for a lost IMU) would run on, orphaned, forever.
        // SAFETY: prctl is async-signal-safe and the closure touches nothing of the parent.
        unsafe {
            cmd.pre_exec(|| {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        let child = cmd
            .spawn()
            .with_context(|| format!("starting {}", exe.display()))?;
        Ok(ChildProc {
            name,
            child: Some(child),
            log,
        })
    }

    /// SIGTERM and wait (SIGKILL after 5 s); true when it exited cleanly.
    pub(crate) fn stop(&mut self) -> bool {
        let Some(mut child) = self.child.take() else {
            return true;
        };
        // Already gone (and reaped by `alive`): its pid may be another process's by now, and
        // kill(1) said "No such process" on the demo's output (issue 27). Signal only a child
        // not yet reaped, whose pid is still ours; kill(1)'s own words go nowhere.
        if let Ok(Some(status)) = child.try_wait() {
            return status.success();
        }
        let _ = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .stderr(Stdio::null())
            .status();
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(5) {
            if let Ok(Some(status)) = child.try_wait() {
                return status.success();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = child.kill();
        let _ = child.wait();
        false
    }

    /// The pipes of a process spawned `piped`.
    pub(crate) fn take_pipes(
        &mut self,
    ) -> Option<(std::process::ChildStdin, std::process::ChildStdout)> {
        let child = self.child.as_mut()?;
        Some((child.stdin.take()?, child.stdout.take()?))
    }

    pub(crate) fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    pub(crate) fn alive(&mut self) -> bool {
        self.child
            .as_mut()
            .is_some_and(|c| matches!(c.try_wait(), Ok(None)))
    }

    /// The whole log (the monitor's findings, for instance).
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The end of the process's log, for error messages.
    /// Names the log file only when it is kept: the session's folder is removed at the end
    /// otherwise, and a failed demo named a file already deleted (issue 27).
    pub(crate) fn tail(&self) -> String {
        let text = self.log_text();
        let lines: Vec<&str> = text.lines().collect();
        let source = if keep_logs() {
            self.log.display().to_string()
        } else {
            "last lines of its log; THRUSTERCTL_KEEP_LOGS=1 keeps it".to_string()
        };
        format!(
            "--- {} ({source}) ---\n{}",
            self.name,
            lines[lines.len().saturating_sub(15)..].join("\n")
        )
    }
}

impl Drop for ChildProc {
    fn drop(&mut self) {
        self.kill();
    }
}
