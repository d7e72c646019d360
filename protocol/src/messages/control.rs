use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::Text;
use crate::wire::{wire_enum, FixedText, UnknownEnumValue};

wire_enum! {
    /// What the operator asks of the daemon (service `control`, request/response).
    pub enum RequestKind {
        /// Reply with a one-line status (no state change).
        #[default]
        Status = 0,
        /// Start (or restart) estimation. `value`: excitation power in (0, 1], 0 = default.
        Estimate = 1,
        /// Abort whatever runs, zero thrust, back to Idle.
        Abort = 2,
        /// Control with the current model (hold attitude/depth setpoint).
        Hold = 3,
        /// Stop controlling, zero thrust.
        Idle = 4,
        /// Save the current model. `text`: file path, empty = default location.
        Save = 5,
        /// Go back to the previous model.
        Revert = 6,
        /// Load a model from file. `text`: file path.
        Load = 7,
        /// Stop the daemon cleanly.
        Shutdown = 8,
        /// Emergency stop: thrusters neutral from the next command on, in any state (unlike
        /// `Abort`, which stops only an estimation, and `Idle`, after which a reconfiguration
        /// or a cleared fault may start thrusters again), and held off: nothing drives them
        /// again (no automatic re-estimation, no resumed hold) until an operator asks for
        /// `Estimate` or `Hold`.
        Stop = 9,
    }
}

wire_enum! {
    /// Outcome of a control request.
    pub enum ResponseCode {
        /// Done (or started, for long operations such as Estimate).
        #[default]
        Ok = 0,
        /// Not allowed in the current state (text says why).
        Rejected = 1,
        /// The request failed validation (unknown kind, bad argument).
        InvalidRequest = 2,
        /// The daemon is busy with an operation that must finish first.
        Busy = 3,
        /// The operation was attempted and failed (e.g. file error).
        Failed = 4,
        /// Known request that this daemon does not implement.
        Unsupported = 5,
    }
}

/// Capacity in bytes of [`ControlRequest::text`].
pub const REQUEST_TEXT_CAPACITY: usize = 128;

/// A control request (thrusterctl -> daemon).
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.ControlRequest.v1")]
pub struct ControlRequest {
    /// Sequence number, assigned by [`crate::services::ControlClient`]; echoed in the
    /// response.
    pub seq: u64,
    /// [`RequestKind`] as `u32`.
    pub kind: u32,
    /// Kind-specific flags; must be zero in this protocol version.
    pub flags: u32,
    /// Kind-specific number (see [`RequestKind`]); must be finite.
    pub value: f64,
    /// Kind-specific text, e.g. a file path (see [`RequestKind`]).
    pub text: FixedText<REQUEST_TEXT_CAPACITY>,
}

impl ControlRequest {
    /// A request of `kind` with no arguments.
    pub fn new(kind: RequestKind) -> Self {
        Self {
            kind: kind.as_u32(),
            ..Self::default()
        }
    }

    /// A request of `kind` with a numeric argument.
    pub fn with_value(kind: RequestKind, value: f64) -> Self {
        Self {
            value,
            ..Self::new(kind)
        }
    }

    /// A request of `kind` with a text argument (truncated to fit).
    pub fn with_text(kind: RequestKind, text: &str) -> Self {
        Self {
            text: FixedText::from_str_truncated(text),
            ..Self::new(kind)
        }
    }

    /// Decoded `kind`.
    pub fn kind(&self) -> Result<RequestKind, UnknownEnumValue> {
        RequestKind::try_from(self.kind)
    }
}

/// The daemon's answer to a [`ControlRequest`].
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.ControlResponse.v1")]
pub struct ControlResponse {
    /// `seq` of the request answered.
    pub seq: u64,
    /// 1 when `code` is `Ok`, 0 otherwise (a `u32`, not `bool`, so any bit pattern is
    /// valid; validation checks it agrees with `code`).
    pub ok: u32,
    /// [`ResponseCode`] as `u32`.
    pub code: u32,
    /// Human-readable message (status line, reason for refusal).
    pub text: Text,
}

impl ControlResponse {
    /// A response with `code` and `text`; `ok` follows `code`. `seq` is filled in by
    /// [`crate::services::ControlServer`].
    pub fn new(code: ResponseCode, text: &str) -> Self {
        Self {
            seq: 0,
            ok: u32::from(code == ResponseCode::Ok),
            code: code.as_u32(),
            text: Text::from_str_truncated(text),
        }
    }

    /// Success with a message.
    pub fn ok(text: &str) -> Self {
        Self::new(ResponseCode::Ok, text)
    }

    /// Decoded `code`.
    pub fn code(&self) -> Result<ResponseCode, UnknownEnumValue> {
        ResponseCode::try_from(self.code)
    }

    /// True when the request succeeded.
    pub fn is_ok(&self) -> bool {
        self.ok == 1 && self.code == ResponseCode::Ok.as_u32()
    }

    /// The human-readable message.
    pub fn text(&self) -> &str {
        self.text.as_str()
    }
}
