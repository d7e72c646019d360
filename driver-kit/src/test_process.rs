//! The one way tests start a process of ours: [`TestProcess`], killed and reaped however the
//! test ends, its output in a log file (printed when the test panics), signals by name.
//!
//! Every test that runs a binary uses it: the system tests (`system_tests::Proc` adds the
//! binaries' paths and a log folder per world), the simulator's and the hardware driver's
//! process tests, and the conformance suite. One launcher, so a fix to how children are
//! reaped or logged reaches every test at once (the four copies it replaces each had their
//! own idea of both).

use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// A child process of a test: killed and reaped when dropped, whatever happened.
pub struct TestProcess {
    /// What it is called in messages (the binary's name).
    pub name: String,
    /// Where its output goes: stderr always, stdout too unless it is piped or discarded.
    pub log: PathBuf,
    child: Child,
    /// Set once the child is reaped: no signal may go to its pid after that.
    status: Option<ExitStatus>,
    /// The folder the log (and anything the test keeps beside it) lives in, when the process
    /// owns one; removed with it.
    dir: Option<tempfile::TempDir>,
}

/// How a [`TestProcess`] is started.
pub struct Launch<'a> {
    bin: &'a Path,
    name: String,
    args: Vec<String>,
    env: Vec<(String, String)>,
    /// None: a temp folder of the process's own, stdout discarded (a driver, whose stdout
    /// nobody reads). Some: this file, created new, for stdout and stderr.
    log: Option<PathBuf>,
}

impl<'a> Launch<'a> {
    /// `bin` with `RUST_LOG=info`, stdin closed, named after the file.
    pub fn new(bin: &'a Path) -> Self {
        let name = bin.file_name().map_or_else(
            || bin.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        Launch {
            bin,
            name,
            args: Vec::new(),
            env: vec![("RUST_LOG".into(), "info".into())],
            log: None,
        }
    }

    pub fn name(mut self, name: &str) -> Self {
        self.name = name.to_string();
        self
    }

    pub fn args(mut self, args: &[&str]) -> Self {
        self.args.extend(args.iter().map(|a| a.to_string()));
        self
    }

    /// Extra environment variables (after `RUST_LOG=info`, so they may replace it).
    pub fn envs(mut self, env: &[(&str, &str)]) -> Self {
        self.env
            .extend(env.iter().map(|(k, v)| (k.to_string(), v.to_string())));
        self
    }

    /// stdout and stderr to `path`, which must not exist yet (two processes never share a
    /// log: each would truncate and interleave the other's lines).
    pub fn log_to(mut self, path: PathBuf) -> Self {
        self.log = Some(path);
        self
    }

    /// Starts it.
    pub fn spawn(self) -> io::Result<TestProcess> {
        let (mut cmd, log, dir) = self.command(false)?;
        let child = cmd.spawn().map_err(|e| named(&log, e))?;
        Ok(TestProcess {
            name: self.name,
            log,
            child,
            status: None,
            dir,
        })
    }

    /// Starts it with stdin and stdout piped to the caller (a protocol such as the
    /// simulator's stepping); stderr goes to the log.
    pub fn spawn_piped(self) -> io::Result<(TestProcess, ChildStdin, ChildStdout)> {
        let (mut cmd, log, dir) = self.command(true)?;
        let mut child = cmd.spawn().map_err(|e| named(&log, e))?;
        let (stdin, stdout) = match (child.stdin.take(), child.stdout.take()) {
            (Some(i), Some(o)) => (i, o),
            _ => return Err(io::Error::other("piped stdio missing")),
        };
        let proc = TestProcess {
            name: self.name,
            log,
            child,
            status: None,
            dir,
        };
        Ok((proc, stdin, stdout))
    }

    fn command(&self, piped: bool) -> io::Result<(Command, PathBuf, Option<tempfile::TempDir>)> {
        let (log, dir) = match &self.log {
            Some(path) => (path.clone(), None),
            None => {
                let dir = tempfile::tempdir()?;
                (dir.path().join("stderr.log"), Some(dir))
            }
        };
        // A file, not a pipe: nobody reads it during the run, and a full pipe would block
        // the child.
        let err = fs::File::options()
            .write(true)
            .create_new(true)
            .open(&log)
            .map_err(|e| named(&log, e))?;
        let mut cmd = Command::new(self.bin);
        cmd.args(&self.args)
            .envs(self.env.iter().map(|(k, v)| (k.as_str(), v.as_str())));
        if piped {
            cmd.stdin(Stdio::piped()).stdout(Stdio::piped());
        } else if self.log.is_some() {
            cmd.stdin(Stdio::null()).stdout(err.try_clone()?);
        } else {
            cmd.stdin(Stdio::null()).stdout(Stdio::null());
        }
        cmd.stderr(err);
        Ok((cmd, log, dir))
    }
}

fn named(path: &Path, e: io::Error) -> io::Error {
    io::Error::new(e.kind(), format!("{}: {e}", path.display()))
}

/// The signals tests send, by the names kill(1) takes.
fn signal_number(name: &str) -> Option<i32> {
    Some(match name {
        "INT" => libc::SIGINT,
        "TERM" => libc::SIGTERM,
        "KILL" => libc::SIGKILL,
        "HUP" => libc::SIGHUP,
        "STOP" => libc::SIGSTOP,
        "CONT" => libc::SIGCONT,
        "USR1" => libc::SIGUSR1,
        "USR2" => libc::SIGUSR2,
        "QUIT" => libc::SIGQUIT,
        _ => return None,
    })
}

impl TestProcess {
    /// `bin args...` with `RUST_LOG=info`, its log in a folder of its own ([`Launch`] for
    /// more).
    pub fn spawn(bin: impl AsRef<Path>, args: &[&str]) -> io::Result<TestProcess> {
        Launch::new(bin.as_ref()).args(args).spawn()
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The folder the process owns (for a config file beside its log), when it has one.
    pub fn dir(&self) -> Option<&Path> {
        self.dir.as_ref().map(|d| d.path())
    }

    /// Sends `sig` ("INT", "TERM", "KILL", "STOP", "CONT", "HUP", "USR1", "USR2", "QUIT").
    /// Nothing once the child is reaped: its pid may be another process's by then.
    ///
    /// Panics on a name not in that list (a test's typo).
    pub fn signal(&self, sig: &str) {
        let number = signal_number(sig).unwrap_or_else(|| panic!("no signal named {sig}"));
        self.signal_number(number);
    }

    /// As [`Self::signal`], by number.
    pub fn signal_number(&self, sig: i32) {
        if self.status.is_none() {
            // SAFETY: kill(2) on our own child, which is not reaped yet (status is None until
            // it is), so the pid is still ours.
            unsafe { libc::kill(self.child.id() as i32, sig) };
        }
    }

    /// Waits up to `timeout` for the exit, reaping the child; None while it still runs.
    pub fn wait_timeout(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let end = Instant::now() + timeout;
        loop {
            if let Some(s) = self.status {
                return Some(s);
            }
            self.status = self.child.try_wait().ok().flatten();
            if self.status.is_some() {
                continue;
            }
            if Instant::now() >= end {
                return None;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// SIGTERM, then waits up to `within` for the exit.
    pub fn terminate(&mut self, within: Duration) -> Option<ExitStatus> {
        self.signal_number(libc::SIGTERM);
        self.wait_timeout(within)
    }

    /// SIGTERM, and the exit status within `within`; panics with the log if there is none.
    pub fn stop_within(&mut self, within: Duration) -> ExitStatus {
        match self.terminate(within) {
            Some(s) => s,
            None => panic!(
                "{} did not exit within {:.1} s of SIGTERM\n{}",
                self.name,
                within.as_secs_f64(),
                self.log_text()
            ),
        }
    }

    /// SIGTERM; requires exit code 0 within `within` (a driver's clean stop).
    pub fn stop_cleanly(&mut self, within: Duration) {
        let status = self.stop_within(within);
        assert_eq!(status.code(), Some(0), "{}", self.log_text());
    }

    pub fn is_running(&mut self) -> bool {
        self.wait_timeout(Duration::ZERO).is_none()
    }

    /// Its output so far.
    pub fn log_text(&self) -> String {
        fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The number after ` key=` in the first log line containing `marker` (a process's final
    /// summary, e.g. "thruster-sim stopped"); panics naming what was missing.
    pub fn summary_value(&self, marker: &str, key: &str) -> u64 {
        let log = self.log_text();
        let line = log
            .lines()
            .find(|l| l.contains(marker))
            .unwrap_or_else(|| panic!("no {marker:?} line in log:\n{log}"));
        let at = line
            .find(&format!(" {key}="))
            .unwrap_or_else(|| panic!("no {key} in {line}"));
        line[at + key.len() + 2..]
            .split(|c: char| !c.is_ascii_digit())
            .next()
            .unwrap_or_default()
            .parse()
            .unwrap_or_else(|_| panic!("{key} not a number in {line}"))
    }
}

impl Drop for TestProcess {
    fn drop(&mut self) {
        if self.status.is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        if std::thread::panicking() {
            eprintln!("---- {} log ----\n{}", self.name, self.log_text());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_process_is_logged_signalled_and_reaped() {
        let sh = Path::new("/bin/sh");
        let mut p = Launch::new(sh)
            .args(&[
                "-c",
                "echo started >&2; trap 'echo bye >&2; exit 3' TERM; while :; do sleep 0.01; done",
            ])
            .spawn()
            .unwrap();
        let end = Instant::now() + Duration::from_secs(5);
        while !p.log_text().contains("started") {
            assert!(Instant::now() < end, "no output: {}", p.log_text());
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(p.is_running());
        let status = p.stop_within(Duration::from_secs(5));
        assert_eq!(status.code(), Some(3));
        assert!(p.log_text().contains("bye"), "{}", p.log_text());
        assert!(!p.is_running());
        // Reaped: a second signal goes nowhere (no error, no other process hit).
        p.signal("TERM");
    }

    #[test]
    fn dropping_a_running_process_kills_and_reaps_it() {
        let p = Launch::new(Path::new("/bin/sleep"))
            .args(&["30"])
            .spawn()
            .unwrap();
        let pid = p.pid() as i32;
        let dir = p.dir().unwrap().to_path_buf();
        drop(p);
        // SAFETY: signal 0 only asks whether the pid exists; it was our child, reaped above.
        let alive = unsafe { libc::kill(pid, 0) } == 0;
        assert!(!alive, "pid {pid} still there after drop");
        assert!(!dir.exists(), "{} left behind", dir.display());
    }

    #[test]
    fn a_log_file_is_never_shared() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("x.log");
        let _a = Launch::new(Path::new("/bin/true"))
            .log_to(log.clone())
            .spawn()
            .unwrap();
        let e = Launch::new(Path::new("/bin/true"))
            .log_to(log.clone())
            .spawn()
            .err()
            .expect("a second process on the same log");
        assert!(e.to_string().contains("x.log"), "{e}");
    }
}
