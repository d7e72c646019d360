//! The operator's requests as Foxglove WebSocket services: `estimate`, `abort`, `hold`,
//! `idle`, `stop` (the emergency stop) and `setpoint`, each answered by the daemon through the operator's own client
//! (`thrusterctl_operator::client::Daemon`), so a topside operator needs no shell on the
//! vehicle and every request passes the checks `thrusterctl` applies.
//!
//! The SDK calls a handler on its network runtime; a control call can take up to its timeout,
//! and the client's iceoryx2 ports belong to one thread. So the handlers only parse the
//! request and hand it, with its responder, to one operator thread over a small bounded queue;
//! a full queue answers "busy" at once. Requests and responses are JSON (schemas below).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::time::Duration;

use anyhow::Result;
use foxglove::websocket::service::{Request, Responder, Service, ServiceSchema};
use foxglove::Schema;
use serde::Deserialize;
use serde_json::json;
use thruster_protocol::{ControlRequest, RequestKind, Validate};
use thrusterctl_operator::client::Daemon;
use thrusterctl_operator::{attitude, cli, publish};

/// Requests waiting for the operator thread; one more is refused as busy.
const PENDING: usize = 4;
/// How often the operator thread looks at the stop flag while idle.
const POLL: Duration = Duration::from_millis(100);
/// Every service's name starts with this.
pub const PREFIX: &str = "thrusterd/";

/// One operator request, parsed.
#[derive(Debug, Clone, PartialEq)]
pub enum Call {
    /// `value` as the excitation power in (0, 1]; 0 = the daemon's default.
    Estimate {
        power: f64,
    },
    Abort,
    Hold,
    Idle,
    /// The emergency stop (`RequestKind::Stop`).
    Stop,
    Setpoint(cli::SetpointArgs),
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct EstimateRequest {
    power: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct SetpointRequest {
    roll_deg: Option<f64>,
    pitch_deg: Option<f64>,
    yaw_deg: Option<f64>,
    depth_m: Option<f64>,
    /// true: release the depth hold (heave free). Exclusive with `depth_m`.
    depth_free: Option<bool>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Empty {}

/// JSON body, with an empty payload read as `{}` (a call without arguments).
fn body<T: for<'de> Deserialize<'de> + Default>(payload: &[u8]) -> Result<T, String> {
    if payload.iter().all(u8::is_ascii_whitespace) {
        return Ok(T::default());
    }
    serde_json::from_slice(payload).map_err(|e| format!("request is not the expected JSON: {e}"))
}

/// Parses a call to service `name` (without [`PREFIX`]) with a JSON `payload`.
pub fn parse(name: &str, payload: &[u8]) -> Result<Call, String> {
    match name {
        "estimate" => {
            let r: EstimateRequest = body(payload)?;
            let power = r.power.unwrap_or(0.0);
            if r.power.is_some() && !(power.is_finite() && power > 0.0 && power <= 1.0) {
                return Err(format!("power must be in (0, 1], got {power}"));
            }
            Ok(Call::Estimate { power })
        }
        "abort" => body::<Empty>(payload).map(|_| Call::Abort),
        "hold" => body::<Empty>(payload).map(|_| Call::Hold),
        "idle" => body::<Empty>(payload).map(|_| Call::Idle),
        "stop" => body::<Empty>(payload).map(|_| Call::Stop),
        "setpoint" => {
            let r: SetpointRequest = body(payload)?;
            // As on the command line: depth left out keeps the depth held.
            let depth = match (r.depth_m, r.depth_free) {
                (Some(_), Some(true)) => {
                    return Err("depth_m and depth_free: true together".to_string())
                }
                (Some(d), _) => Some(cli::Depth::Hold(d)),
                (None, Some(true)) => Some(cli::Depth::Free),
                (None, _) => None,
            };
            cli::setpoint_args(r.roll_deg, r.pitch_deg, r.yaw_deg, depth)
                .map(Call::Setpoint)
                .map_err(|e| {
                    // The operator's words name command-line flags; here they are JSON keys.
                    e.to_string()
                        .replace("--roll", "roll_deg")
                        .replace("--pitch", "pitch_deg")
                        .replace("--yaw", "yaw_deg")
                        .replace("--depth", "depth_m")
                })
        }
        other => Err(format!("no service {other}")),
    }
}

/// The request schema of each service (JSON Schema), for the Foxglove app's service panel.
fn request_schema(name: &str) -> serde_json::Value {
    let number = |doc: &str| json!({"type": "number", "description": doc});
    let properties = match name {
        "estimate" => {
            json!({"power": number("excitation power in (0, 1]; left out: the daemon's default")})
        }
        "setpoint" => json!({
            "roll_deg": number("roll, degrees in [-180, 180]; left out: kept"),
            "pitch_deg": number("pitch, degrees in [-90, 90]; left out: kept"),
            "yaw_deg": number("yaw, degrees in [-360, 360]; left out: kept"),
            "depth_m": number("depth to hold, m; left out: the depth held now is kept"),
            "depth_free": {"type": "boolean", "description": "true: release the depth hold (heave free)"},
        }),
        _ => json!({}),
    };
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": format!("thrusterd.{name}.Request"),
        "type": "object",
        "properties": properties,
        "additionalProperties": false,
    })
}

fn response_schema() -> serde_json::Value {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "thrusterd.Response",
        "type": "object",
        "properties": {
            "text": {"type": "string", "description": "the daemon's answer"},
            "error": {
                "type": "string",
                "description": "why the call was refused; only to clients of the old protocol \
                    name foxglove.websocket.v1 (the others get a service call failure)"
            },
        },
    })
}

/// Every schema the bridge declares: each topic's channel (as in the recordings) and each
/// service's request and response, as `{"channels": [{"topic", "schemaName", "schema"}],
/// "services": [{"name", "request": {"schemaName", "schema"}, "response": ...}]}` with each
/// schema as its JSON text (as the WebSocket protocol carries it).
pub fn every_schema() -> Result<serde_json::Value> {
    let channels: Vec<_> = thruster_recorder::source::all_channels()?
        .into_iter()
        .map(|c| {
            json!({
                "topic": c.topic,
                "schemaName": c.schema_name,
                "schema": String::from_utf8_lossy(&c.schema),
            })
        })
        .collect();
    let services: Vec<_> = NAMES
        .iter()
        .map(|name| {
            json!({
                "name": format!("{PREFIX}{name}"),
                "request": {
                    "schemaName": format!("thrusterd.{name}.Request"),
                    "schema": request_schema(name).to_string(),
                },
                "response": {
                    "schemaName": "thrusterd.Response",
                    "schema": response_schema().to_string(),
                },
            })
        })
        .collect();
    Ok(json!({"channels": channels, "services": services}))
}

/// The names of the services, without [`PREFIX`].
pub const NAMES: [&str; 6] = ["estimate", "abort", "hold", "idle", "stop", "setpoint"];

/// The services, each handing its calls to `queue`.
pub fn services(queue: &SyncSender<Pending>) -> Vec<Service> {
    NAMES
        .iter()
        .map(|&name| {
            let schema = ServiceSchema::new(format!("thrusterd.{name}"))
                .with_request(
                    "json",
                    Schema::new(
                        format!("thrusterd.{name}.Request"),
                        "jsonschema",
                        request_schema(name).to_string().into_bytes(),
                    ),
                )
                .with_response(
                    "json",
                    Schema::new(
                        "thrusterd.Response",
                        "jsonschema",
                        response_schema().to_string().into_bytes(),
                    ),
                );
            let queue = queue.clone();
            Service::builder(format!("{PREFIX}{name}"), schema).handler(Enqueue { name, queue })
        })
        .collect()
}

/// A service's handler: parse on the network runtime, queue for the operator thread.
struct Enqueue {
    name: &'static str,
    queue: SyncSender<Pending>,
}

impl foxglove::websocket::service::Handler for Enqueue {
    fn call(&self, request: Request, responder: Responder) {
        let call = match parse(self.name, request.payload()) {
            Ok(c) => c,
            Err(e) => return responder.respond_err(e),
        };
        match self.queue.try_send((call, responder)) {
            Ok(()) => {}
            Err(TrySendError::Full((_, r))) => {
                r.respond_err("busy: earlier requests are still waiting for the daemon".into())
            }
            Err(TrySendError::Disconnected((_, r))) => {
                r.respond_err("the bridge is shutting down".into())
            }
        }
    }
}

/// A service call waiting for the operator thread, with where its answer goes.
pub type Pending = (Call, Responder);

/// The operator thread's queue: the services' end and the thread's end.
pub fn queue() -> (SyncSender<Pending>, Receiver<Pending>) {
    mpsc::sync_channel(PENDING)
}

/// The operator thread's loop: answers every queued call through `daemon` until `stop` is set
/// (or every service is gone).
pub fn serve(daemon: &Daemon, rx: &Receiver<Pending>, stop: &AtomicBool) {
    while !stop.load(Ordering::Relaxed) {
        let (call, responder) = match rx.recv_timeout(POLL) {
            Ok(c) => c,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        tracing::info!("service call: {call:?}");
        match execute(daemon, &call) {
            Ok(text) => responder.respond_ok(json!({ "text": text }).to_string()),
            Err(e) => {
                tracing::warn!("service call {call:?} failed: {e:#}");
                responder.respond_err(format!("{e:#}"));
            }
        }
    }
}

/// Runs one call against the daemon: its text on success, the operator's error otherwise
/// (a refusal names the daemon's code and reason).
fn execute(daemon: &Daemon, call: &Call) -> Result<String> {
    let request = |kind| daemon.command(ControlRequest::new(kind));
    match call {
        Call::Estimate { power } => {
            daemon.command(ControlRequest::with_value(RequestKind::Estimate, *power))
        }
        Call::Abort => request(RequestKind::Abort),
        Call::Hold => request(RequestKind::Hold),
        Call::Idle => request(RequestKind::Idle),
        Call::Stop => request(RequestKind::Stop),
        Call::Setpoint(args) => {
            let sp = attitude::setpoint(args, publish::sender_seq());
            sp.validate()
                .map_err(|r| anyhow::anyhow!("internal error: setpoint fails validation: {r}"))?;
            let reached = publish::send(daemon, &sp)?;
            let held = publish::held_now(daemon)?;
            Ok(format!(
                "setpoint sent to {reached} subscriber(s): {}; {held}",
                publish::asked(args)
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_parse_with_their_checks() {
        assert_eq!(
            parse("estimate", b"").unwrap(),
            Call::Estimate { power: 0.0 }
        );
        assert_eq!(
            parse("estimate", br#"{"power": 0.5}"#).unwrap(),
            Call::Estimate { power: 0.5 }
        );
        assert!(parse("estimate", br#"{"power": 2}"#)
            .unwrap_err()
            .contains("(0, 1]"));
        assert_eq!(parse("hold", b"{}").unwrap(), Call::Hold);
        assert_eq!(parse("stop", b"").unwrap(), Call::Stop);
        assert!(parse("hold", br#"{"x": 1}"#).unwrap_err().contains("JSON"));
        let Call::Setpoint(a) = parse("setpoint", br#"{"pitch_deg": 10}"#).unwrap() else {
            panic!("not a setpoint")
        };
        assert_eq!((a.pitch_deg, a.roll_deg), (Some(10.0), None));
        // Depth left out is kept, as on the command line; released only when asked.
        assert_eq!(a.depth, thrusterctl_operator::cli::Depth::Keep);
        let Call::Setpoint(a) =
            parse("setpoint", br#"{"pitch_deg": 10, "depth_free": true}"#).unwrap()
        else {
            panic!("not a setpoint")
        };
        assert_eq!(a.depth, thrusterctl_operator::cli::Depth::Free);
        let e = parse("setpoint", br#"{"depth_m": 2, "depth_free": true}"#).unwrap_err();
        assert!(e.contains("together"), "{e}");
        let e = parse("setpoint", br#"{"pitch_deg": 100}"#).unwrap_err();
        assert!(e.contains("pitch_deg must be in"), "{e}");
        assert!(parse("setpoint", b"{}").is_err());
        assert!(parse("reboot", b"").is_err());
    }

    #[test]
    fn every_request_schema_is_an_object_schema() {
        for name in NAMES {
            let s = request_schema(name);
            assert_eq!(s["type"], "object", "{name}");
        }
        assert!(request_schema("setpoint")["properties"]["depth_m"].is_object());
    }
}
