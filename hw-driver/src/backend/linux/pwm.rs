//! sysfs PWM (`Documentation/driver-api/pwm.rst`): one exported channel per thruster.
//!
//! ```text
//! <root>/class/pwm/pwmchipN/export         write M      -> pwmM/ appears
//! <root>/class/pwm/pwmchipN/pwmM/period     ns
//! <root>/class/pwm/pwmchipN/pwmM/duty_cycle ns (the pulse width)
//! <root>/class/pwm/pwmchipN/pwmM/polarity   "normal"
//! <root>/class/pwm/pwmchipN/pwmM/enable     1
//! ```
//! Set-up writes the neutral duty before enabling, so the first pulse an ESC ever sees is
//! neutral. On stop the duty goes to neutral and the channel stays enabled and exported:
//! the pulse train never stops (an ESC that loses its signal may beep, re-arm or, with
//! other firmware, hold its last command).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::sysfs::{read_attr, read_u64, write_attr};
use crate::backend::BackendError;
use crate::core::pwm::Pwm;

/// What [`neutral_left_channel`] found and did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeftChannel {
    /// The channel was exported: its duty is now neutral.
    Neutral,
    /// Not exported: nothing drives its ESC, nothing to write.
    NotExported,
}

/// The outputs neutral after the process that drove them is gone (`thruster-hw neutral`,
/// systemd's `ExecStopPost`): writes the neutral duty to channel `index` of `chip_dir` if it
/// is exported. Why: the kernel keeps a channel's last duty when its writer dies without
/// reaching `Drop` (SIGKILL, SIGABRT from systemd's watchdog, the OOM killer), so the ESC
/// would hold the last command. Nothing is exported, enabled or disabled here: a pulse train
/// that runs keeps running, at neutral.
pub fn neutral_left_channel(
    chip_dir: &Path,
    index: u32,
    neutral: Pwm,
) -> Result<LeftChannel, BackendError> {
    let duty = chip_dir.join(format!("pwm{index}")).join("duty_cycle");
    if !duty.exists() {
        return Ok(LeftChannel::NotExported);
    }
    write_attr(&duty, &neutral.ns().to_string())?;
    Ok(LeftChannel::Neutral)
}

/// One exported PWM channel.
#[derive(Debug)]
pub struct PwmChannel {
    dir: PathBuf,
    duty_path: PathBuf,
    /// The last duty written, ns (writes are skipped when nothing changed).
    duty_ns: Option<u64>,
}

/// The calling process may write `path` (access(2) with W_OK).
fn writable(path: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(path.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: a valid NUL-terminated path; access(2) only reads it.
    unsafe { libc::access(c.as_ptr(), libc::W_OK) == 0 }
}

impl PwmChannel {
    /// Exports channel `index` of `chip_dir` (unless it already is), waits up to `timeout`
    /// for it to appear and accept writes, and starts it at `neutral` with `period_ns`.
    pub fn open(
        chip_dir: &Path,
        index: u32,
        period_ns: u64,
        neutral: Pwm,
        timeout: Duration,
    ) -> Result<PwmChannel, BackendError> {
        if !chip_dir.is_dir() {
            return Err(BackendError::Content {
                path: chip_dir.to_path_buf(),
                reason: "no such PWM chip (is the PWM overlay / driver loaded?)".to_string(),
            });
        }
        let dir = chip_dir.join(format!("pwm{index}"));
        if !dir.is_dir() {
            write_attr(&chip_dir.join("export"), &index.to_string())?;
        }
        let mut ch = PwmChannel {
            duty_path: dir.join("duty_cycle"),
            dir,
            duty_ns: None,
        };
        ch.wait_writable(timeout)?;
        ch.configure(period_ns, neutral)?;
        Ok(ch)
    }

    /// The channel's directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Its `duty_cycle` attribute.
    pub fn duty_path(&self) -> &Path {
        &self.duty_path
    }

    /// Forget the duty last written (someone else wrote the attribute): the next `set`
    /// writes whatever it is given.
    pub fn forget(&mut self) {
        self.duty_ns = None;
    }

    /// Waits until the freshly exported channel's attributes accept a write: the kernel
    /// creates them at once, but udev may change their owner a moment later. Probed with
    /// access(2), not by opening: nothing is written before the set-up proper.
    fn wait_writable(&self, timeout: Duration) -> Result<(), BackendError> {
        let enable = self.dir.join("enable");
        let end = Instant::now() + timeout;
        loop {
            if writable(&enable) {
                return Ok(());
            }
            if Instant::now() >= end {
                let why = if enable.exists() {
                    "exists but is not writable (udev rule / group membership?)"
                } else {
                    "does not exist"
                };
                return Err(BackendError::Timeout(format!(
                    "{} {why} {} ms after export",
                    enable.display(),
                    timeout.as_millis()
                )));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    fn configure(&mut self, period_ns: u64, neutral: Pwm) -> Result<(), BackendError> {
        let dir = self.dir.clone();
        let attr = |name: &str| dir.join(name);
        // Polarity can only change while disabled; at start-up the ESC is not armed yet,
        // so a short gap in the pulse train is harmless then (and only then).
        let polarity = attr("polarity");
        if polarity.exists() && read_attr(&polarity)? != "normal" {
            write_attr(&attr("enable"), "0")?;
            write_attr(&polarity, "normal")?;
        }
        // The kernel refuses duty > period at every step, so the order depends on the
        // channel's current duty (another program may have left a long one).
        let current_duty = read_u64(&self.duty_path).unwrap_or(0);
        if current_duty > period_ns {
            self.write_duty(neutral)?;
            write_attr(&attr("period"), &period_ns.to_string())?;
        } else {
            write_attr(&attr("period"), &period_ns.to_string())?;
            self.write_duty(neutral)?;
        }
        write_attr(&attr("enable"), "1")
    }

    /// Sets the pulse width (skipped when unchanged).
    pub fn set(&mut self, pwm: Pwm) -> Result<(), BackendError> {
        if self.duty_ns == Some(pwm.ns()) {
            return Ok(());
        }
        self.write_duty(pwm)
    }

    fn write_duty(&mut self, pwm: Pwm) -> Result<(), BackendError> {
        // Forget the cached value first: after a failed write the hardware state is unknown.
        self.duty_ns = None;
        write_attr(&self.duty_path, &pwm.ns().to_string())?;
        self.duty_ns = Some(pwm.ns());
        Ok(())
    }
}
