//! One function per operator subcommand; `run` dispatches. Commands that only need a control
//! round trip live here; longer ones have their own modules.

use std::time::Duration;

use anyhow::Result;
use thruster_protocol::{
    ControlRequest, DriverStatusMsg, DynamicsMsg, ModelMethod, ModelMsg, ModelSource, RequestKind,
    StatusMsg, Validate,
};

use crate::checks::{model_problem, status_problem, Warner};
use crate::cli::{self, Command, Globals};
use crate::client::{wait_latest, Daemon, Target};
use crate::console::{interrupt_flag, say};
use crate::exit::{self, Failure};
use crate::json::{DriverJson, ModelJson, StatusJson, StatusReportJson};
use crate::{estimate, publish, record, render, watch};

/// The target daemon (namespace, ipc root) and the timeout, from the global options.
pub fn target(globals: Globals) -> Result<(Target, Duration), Failure> {
    let timeout = cli::timeout(globals.timeout_ms)?;
    let target = Target {
        namespace: globals.namespace,
        root_base: globals.ipc_root,
    };
    Ok((target, timeout))
}

/// Runs one operator verb against the daemon `target` (see [`target`]).
pub fn run(target: Target, timeout: Duration, command: Command) -> Result<()> {
    // Checks that need no daemon come first (inside each command, before connecting),
    // so bad input is reported even when the daemon is down.
    match command {
        Command::Status { json } => status(&Daemon::connect(&target, timeout)?, json),
        Command::Estimate {
            wait,
            power,
            max_wait_s,
        } => {
            let power = cli::estimate_power(power)?;
            let max_wait = cli::max_wait(max_wait_s)?;
            if wait {
                // The handler before the node: a SIGTERM while joining the namespace then
                // ends the wait cleanly instead of killing it with its node half made.
                let interrupted = interrupt_flag()?;
                let daemon = Daemon::connect(&target, timeout)?;
                estimate::run_and_wait(&daemon, power, max_wait, interrupted)
            } else {
                let daemon = Daemon::connect(&target, timeout)?;
                let text =
                    daemon.command(ControlRequest::with_value(RequestKind::Estimate, power))?;
                say(&format!("estimation started: {}", or_ok(&text)))
            }
        }
        Command::Abort => simple(&target, timeout, ControlRequest::new(RequestKind::Abort)),
        Command::Hold => simple(&target, timeout, ControlRequest::new(RequestKind::Hold)),
        Command::Idle => simple(&target, timeout, ControlRequest::new(RequestKind::Idle)),
        Command::Stop => simple(&target, timeout, ControlRequest::new(RequestKind::Stop)),
        Command::Revert => simple(&target, timeout, ControlRequest::new(RequestKind::Revert)),
        Command::Shutdown => simple(&target, timeout, ControlRequest::new(RequestKind::Shutdown)),
        Command::Save { path } => {
            let request = match path {
                Some(p) => cli::path_request(RequestKind::Save, &p)?,
                None => ControlRequest::new(RequestKind::Save),
            };
            simple(&target, timeout, request)
        }
        Command::Load { path } => simple(
            &target,
            timeout,
            cli::path_request(RequestKind::Load, &path)?,
        ),
        Command::Model { json } => model(&Daemon::connect(&target, timeout)?, json),
        Command::Watch { json, interval_ms } => {
            let options = watch::Options::new(json, interval_ms)?;
            // The handler before the node (arguments are evaluated in order, and connecting
            // first left a SIGTERM during the join to kill the watch with its node half
            // made, for the daemon's reaper to find).
            let interrupted = interrupt_flag()?;
            watch::run(&Daemon::connect(&target, timeout)?, options, interrupted)
        }
        Command::Record {
            out,
            max_mb,
            duration_s,
            compression,
        } => {
            let mut options = record::options(out, max_mb, duration_s)?;
            // The parser admits only the two names.
            options.compression =
                thruster_recorder::Compression::from_name(&compression).unwrap_or_default();
            record::run(&target, &options, interrupt_flag()?)
        }
        Command::Reconfigure {
            kind,
            thruster,
            count,
            geometry,
        } => publish::reconfigure(&target, timeout, kind, thruster, count, geometry.as_deref()),
        Command::Setpoint {
            roll,
            pitch,
            yaw,
            depth,
        } => publish::setpoint(
            &target,
            timeout,
            cli::setpoint_args(roll, pitch, yaw, depth)?,
        ),
    }
}

/// Sends one request and prints the daemon's answer.
fn simple(target: &Target, timeout: Duration, request: ControlRequest) -> Result<()> {
    let daemon = Daemon::connect(target, timeout)?;
    let text = daemon.command(request)?;
    say(&format!("thrusterd: {}", or_ok(&text)))
}

fn or_ok(text: &str) -> &str {
    if text.is_empty() {
        "ok"
    } else {
        text
    }
}

fn status(daemon: &Daemon, json: bool) -> Result<()> {
    // Subscribe first: the history sample is then on its way while we ask the daemon.
    let inbox = daemon.inbox::<StatusMsg>()?;
    let drivers = daemon.inbox::<DriverStatusMsg>()?;
    let reply = daemon.ensure_running()?;
    let Some(status) = wait_latest(&inbox, daemon.timeout())? else {
        return Err(Failure::new(
            exit::TIMEOUT,
            format!(
                "thrusterd answered ({}) but published no status within {} ms",
                reply.text(),
                daemon.timeout().as_millis()
            ),
        )
        .into());
    };
    Warner::default().warn(status_problem(&status));
    // Drivers report at least every DriverStatusMsg::PERIOD_MS; none after a few periods
    // means no driver publishes one (not an error: a third-party driver may not).
    let driver = wait_latest(
        &drivers,
        daemon
            .timeout()
            .min(Duration::from_millis(3 * DriverStatusMsg::PERIOD_MS)),
    )?
    .filter(|d| d.validate().is_ok());
    if json {
        say(&serde_json::to_string(&StatusReportJson {
            status: StatusJson::from(&status),
            driver: driver.as_ref().map(DriverJson::from),
        })?)
    } else {
        let mut text = render::status_report(daemon.namespace(), &status);
        text.push_str(&render::driver_line(driver.as_ref()));
        say(text.trim_end())
    }
}

/// The dynamics message if it passes the protocol's checks; otherwise None, with a warning
/// saying why (not silently: the operator would see a dynamic model without coefficients).
fn checked_dynamics(d: DynamicsMsg) -> Option<DynamicsMsg> {
    match d.validate() {
        Ok(()) => Some(d),
        Err(reason) => {
            Warner::default().warn(Some(format!(
                "the daemon's dynamic coefficients for model version {} fail the protocol's checks and are not shown: {reason}",
                d.model_version
            )));
            None
        }
    }
}

fn model(daemon: &Daemon, json: bool) -> Result<()> {
    let inbox = daemon.inbox::<ModelMsg>()?;
    let dynamics_inbox = daemon.inbox::<DynamicsMsg>()?;
    daemon.ensure_running()?;
    let Some(mut model) = wait_latest(&inbox, daemon.timeout())? else {
        return Err(Failure::new(
            exit::TIMEOUT,
            format!(
                "thrusterd published no model within {} ms (none estimated or loaded yet?)",
                daemon.timeout().as_millis()
            ),
        )
        .into());
    };
    Warner::default().warn(model_problem(&model));
    // A model the dynamic method learned (in force as estimated, or back from the cache) has
    // its coefficients on their own topic, published with it; a late joiner gets them at the
    // daemon's next connection update (every status round), so wait as long as for the model.
    // A model from a file has them since the file's format 2 (a version 1 file, B only, has
    // none: then this waits out the timeout once and prints B).
    let has_dynamics = model.method() == Ok(ModelMethod::Dynamic)
        && matches!(
            model.source(),
            Ok(ModelSource::Estimated) | Ok(ModelSource::Cache) | Ok(ModelSource::Loaded)
        );
    let mut dynamics = None;
    if has_dynamics {
        // The daemon may swap in a newer version between the two reads (the refinement does
        // every few seconds while it controls): then read the model again, so the pair
        // printed belongs together. A few rounds at most; each waits at most the timeout.
        for _ in 0..4 {
            match wait_latest(&dynamics_inbox, daemon.timeout())? {
                Some(d) if d.model_version > model.version => {
                    match wait_latest(&inbox, daemon.timeout())? {
                        Some(newer) => model = newer,
                        None => break,
                    }
                    if d.model_version == model.version {
                        dynamics = checked_dynamics(d);
                        break;
                    }
                }
                Some(d) => {
                    if d.model_version == model.version {
                        dynamics = checked_dynamics(d);
                    }
                    break;
                }
                None => break,
            }
        }
    }
    if json {
        let mut v = serde_json::to_value(ModelJson::from(&model))?;
        if let Some(d) = &dynamics {
            v["dynamics"] = crate::dynamics::json(d);
        }
        say(&serde_json::to_string(&v)?)
    } else {
        say(render::model_report(&model).trim_end())?;
        match &dynamics {
            Some(d) => say(crate::dynamics::report(
                d,
                crate::dynamics::ReportOptions {
                    actuated: u64::from(model.actuated),
                    navigation_excursion: true,
                },
            )
            .trim_end()),
            None => Ok(()),
        }
    }
}
