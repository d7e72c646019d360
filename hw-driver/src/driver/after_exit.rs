//! `thruster-hw neutral`: the outputs neutral after the driver process is gone, run by
//! systemd's `ExecStopPost` however the driver ended.
//!
//! Why: the driver leaves the outputs neutral on every exit it lives through (a signal, an
//! error, a panic: the backends' `Drop`), but not on the ones it does not: SIGKILL, the
//! SIGABRT systemd sends a hung driver (`WatchdogSec`), the OOM killer. sysfs PWM keeps its
//! last duty when its writer dies, so the ESCs would hold the last command until a
//! restarted driver sets neutral, or for good when systemd gives up restarting it.
//! ArduSub ends its outputs itself (`motor_test` 500 ms after the last test, an RC override
//! through its pilot-input failsafe after `FS_PILOT_TIMEOUT`): nothing is sent there.

use crate::backend::linux::LinuxBackend;
use crate::backend::BackendError;
use crate::config::{BackendKind, MavlinkConfig, OutputMode, Settings};

use super::outputs;

/// What was done, one line each; the first error after trying every output.
pub fn neutral_after_exit(settings: &Settings) -> Result<Vec<String>, BackendError> {
    match settings.backend {
        BackendKind::Linux => {
            let (_, specs) = outputs(settings);
            LinuxBackend::new(settings.linux.clone(), specs).neutral_left_outputs()
        }
        BackendKind::Mavlink => Ok(vec![mavlink_note(&settings.mavlink)]),
    }
}

fn mavlink_note(cfg: &MavlinkConfig) -> String {
    let how = match cfg.output {
        OutputMode::MotorTest => format!(
            "motor_test: ArduSub stops each motor test after {} ms",
            cfg.motor_test_timeout_ms
        ),
        OutputMode::RcOverride => {
            "RC override: ArduSub's pilot-input failsafe takes it to neutral after FS_PILOT_TIMEOUT (3 s by default)".to_string()
        }
    };
    format!("mavlink: nothing written, the autopilot ends the outputs itself ({how})")
}
