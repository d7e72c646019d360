//! Publishing-only commands: `reconfigure` and `setpoint`.
//!
//! There is no answer to wait for; `Port::send` reports how many subscribers got the
//! message. Neither topic keeps a message for a later reader once we exit (reconfig has
//! no history; the setpoint history lives in our publisher), so zero means the message is
//! lost: we say so and exit [`exit::NOT_RUNNING`].
//!
//! Delivery needs one more step. iceoryx2 (0.10, upstream issue #39) drops a sample whose
//! publisher is gone before the subscriber's next `receive` has connected to it, and a
//! command-line tool exits within milliseconds. So we keep the publisher alive until a
//! control round trip: thrusterd wakes on the topic's event and reads reconfiguration and
//! setpoint inputs before it serves control requests in the same loop iteration, and our
//! request is notified after our message. One round trip can still be answered by an
//! iteration that woke for another client's request before our event arrived; by the
//! second, the daemon has passed the top of its loop with our event pending, so has read
//! our message. Two round trips cost about a millisecond.
//!
//! thrusterd is not the only subscriber: a recorder (`thrusterctl record`) wakes on the IMU
//! or at least every 5 ms and must connect to our publisher too, or the recording lacks the
//! operator's message. No answer tells us it has, so after the barrier we keep the publisher
//! for [`OTHER_SUBSCRIBERS_GRACE`], ten of the recorder's longest sleeps.

use std::path::Path;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::Result;
use thruster_protocol::services::TopicMessage;
use thruster_protocol::{ReconfigEvent, TelemetryMsg, Validate};

use crate::attitude;
use crate::cli::{self, Depth, KindArg, ReconfigArgs, SetpointArgs};
use crate::client::{wait_latest, Daemon, Target};
use crate::console::say;
use crate::exit::{self, Failure};
use crate::geometry::{self, Geometry};
use crate::telemetry;

pub fn reconfigure(
    target: &Target,
    timeout: Duration,
    kind: KindArg,
    thruster: Option<u32>,
    count: u32,
    geometry_file: Option<&Path>,
) -> Result<()> {
    let args = cli::reconfig_args(kind, thruster, count)?;
    let geometry = match geometry_file {
        Some(path) => Some(geometry::load(path).map_err(|e| Failure::usage(format!("{e:#}")))?),
        None => None,
    };
    let event = reconfig_event(&args, geometry.as_ref(), sender_seq())?;
    let daemon = Daemon::connect(target, timeout)?;
    let reached = send(&daemon, &event)?;
    let what = match geometry_file {
        Some(p) => format!(" with the geometry of {}", p.display()),
        None => String::new(),
    };
    say(&format!(
        "reconfiguration sent to {reached} subscriber(s): {} thruster {}, {} thrusters{what}",
        args.kind, args.thruster, args.count
    ))
}

pub fn setpoint(target: &Target, timeout: Duration, args: SetpointArgs) -> Result<()> {
    let sp = attitude::setpoint(&args, sender_seq());
    sp.validate()
        .map_err(|r| anyhow::anyhow!("internal error: setpoint fails validation: {r}"))?;
    let daemon = Daemon::connect(target, timeout)?;
    let reached = send(&daemon, &sp)?;
    let held = held_now(&daemon)?;
    say(&format!(
        "setpoint sent to {reached} subscriber(s): {}; {held}",
        asked(&args)
    ))
}

/// What the operator asked for, in words: left-out values are kept, depth included.
pub fn asked(args: &SetpointArgs) -> String {
    let angle = |a: Option<f64>| match a {
        Some(v) => format!("{v:.1} deg"),
        None => "kept".to_string(),
    };
    let depth = match args.depth {
        Depth::Keep => "depth kept".to_string(),
        Depth::Free => "depth released (free)".to_string(),
        Depth::Hold(d) => format!("depth {d:.2} m"),
    };
    format!(
        "roll {}, pitch {}, yaw {}, {depth}",
        angle(args.roll_deg),
        angle(args.pitch_deg),
        angle(args.yaw_deg)
    )
}

/// What the daemon holds once it has read our setpoint, from the first telemetry message
/// after the delivery barrier (the topic keeps no history, so every message read here was
/// published after the daemon took the setpoint). With telemetry off, says so.
pub fn held_now(daemon: &Daemon) -> Result<String> {
    let inbox = daemon.inbox::<TelemetryMsg>()?;
    Ok(match wait_latest(&inbox, HELD_WAIT)? {
        Some(t) => telemetry::held_text(&t),
        None => "no telemetry within 0.5 s to say what thrusterd holds ([telemetry] every_n = 0?)"
            .to_string(),
    })
}

/// Telemetry comes at 20 Hz by default; a tenth of a second on a loaded machine is common.
const HELD_WAIT: Duration = Duration::from_millis(500);

/// Builds the event and runs the protocol's own check, so the daemon will not reject it.
pub fn reconfig_event(
    args: &ReconfigArgs,
    geometry: Option<&Geometry>,
    seq: u64,
) -> Result<ReconfigEvent, Failure> {
    let mut event = ReconfigEvent {
        seq,
        thruster: args.thruster,
        count: args.count,
        ..ReconfigEvent::default()
    };
    event.set_kind(args.kind);
    if let Some(g) = geometry {
        if g.count() != args.count as usize {
            return Err(Failure::usage(format!(
                "the geometry file declares {} thrusters but --count is {}",
                g.count(),
                args.count
            )));
        }
        event.has_geometry = 1;
        event.position[..g.count()].copy_from_slice(&g.position);
        event.direction[..g.count()].copy_from_slice(&g.direction);
    }
    event
        .validate()
        .map_err(|r| Failure::usage(format!("the daemon would reject this event: {r}")))?;
    Ok(event)
}

/// Publishes `msg` and returns once thrusterd has read it (see the module docs). Also used by
/// the Foxglove bridge's setpoint service.
pub fn send<T: TopicMessage>(daemon: &Daemon, msg: &T) -> Result<usize> {
    let port = daemon.port::<T>()?;
    let reached = port.send(msg).map_err(|e| daemon.ipc_failure(e))?;
    if reached == 0 {
        return Err(Failure::new(
            exit::NOT_RUNNING,
            format!(
                "nobody subscribes to {} (is thrusterd running on namespace {}?); \
                 the message was not delivered",
                port.service_name(),
                daemon.namespace()
            ),
        )
        .into());
    }
    // The delivery barrier; `port` must outlive it.
    if let Err(e) = daemon
        .ensure_running()
        .and_then(|_| daemon.ensure_running())
    {
        let code = exit::code_of(&e);
        return Err(Failure::new(
            code,
            format!(
                "sent to {reached} subscriber(s) of {}, but thrusterd did not confirm, \
                 so it may not have read it: {e:#}",
                port.service_name()
            ),
        )
        .into());
    }
    if reached > 1 {
        std::thread::sleep(OTHER_SUBSCRIBERS_GRACE);
    }
    drop(port);
    Ok(reached)
}

/// How long the publisher outlives thrusterd's confirmation when others subscribe too.
const OTHER_SUBSCRIBERS_GRACE: Duration = Duration::from_millis(50);

/// Sequence number for our one message. Each run is a new sender; starting from the wall
/// clock keeps successive runs increasing, should a reader ever drop repeats.
pub fn sender_seq() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(1, |d| d.as_nanos() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::ReconfigKind;

    fn args(kind: KindArg, thruster: u32, count: u32) -> ReconfigArgs {
        cli::reconfig_args(kind, Some(thruster), count).unwrap()
    }

    #[test]
    fn event_without_geometry() {
        let ev = reconfig_event(&args(KindArg::Moved, 0, 5), None, 9).unwrap();
        assert_eq!(ev.kind().unwrap(), ReconfigKind::ThrusterMoved);
        assert_eq!(
            (ev.seq, ev.thruster, ev.count, ev.has_geometry),
            (9, 0, 5, 0)
        );
    }

    #[test]
    fn event_with_geometry_fills_every_thruster() {
        let g = geometry::parse(
            "[[thruster]]\nposition_m = [0.1, 0, 0.02]\ndirection = [0, 0, -1]\n\
             [[thruster]]\nposition_m = [0, 0.2, 0.02]\ndirection = [1, 0, 0]\n",
        )
        .unwrap();
        let ev = reconfig_event(&args(KindArg::Added, 1, 2), Some(&g), 1).unwrap();
        assert!(ev.geometry_declared());
        assert_eq!(ev.position[0], [0.1, 0.0, 0.0]);
        assert_eq!(ev.direction[1], [1.0, 0.0, 0.0]);
        assert_eq!(ev.position[2], [0.0; 3]);
        let e = reconfig_event(&args(KindArg::Added, 2, 3), Some(&g), 1).unwrap_err();
        assert_eq!(e.code, exit::USAGE);
        assert!(
            e.to_string()
                .contains("declares 2 thrusters but --count is 3"),
            "{e}"
        );
    }
}
