//! The machine's whole state as bytes, and a machine made from them that goes on exactly as
//! the original would: the checkpoint a recording started late replays from
//! (`thrusterd replay`, docs/recording.md). Every part of the state derives serde (the
//! attitude filter, controller, model slot with its cache, estimation run with its
//! estimator, monitor, refinement, supply, pending solves); not in it: the configuration
//! (published on its own and given back at `restore`), the events not yet taken (outputs,
//! not state) and the compiled-in thruster table.
//!
//! Format: `TDCK`, a format number, then postcard (a compact binary serde form that keeps
//! every f64 bit, NaN and infinities included, which JSON does not). postcard is not
//! self-describing: a checkpoint is read by the build that wrote it (a replay that must
//! reproduce the daemon's bits needs that build anyway); another build's checkpoint most
//! likely fails to decode (a replay then says so; it does not guess).

use super::config::MachineSetup;
use super::state_machine::Machine;

const MAGIC: &[u8; 4] = b"TDCK";
/// Raised whenever the layout of the serialised state changes in a way a reader could not
/// tell from a decoding error.
pub const FORMAT: u32 = 21;

/// Why a checkpoint cannot be made or used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CheckpointError {
    #[error("the machine's state could not be serialised: {0}")]
    Encode(String),
    #[error("not a machine checkpoint (it does not start with TDCK)")]
    NotACheckpoint,
    #[error("checkpoint format {found}; this build reads format {FORMAT}")]
    Format { found: u32 },
    #[error("the checkpoint does not decode as this build's machine ({0}): made by another build of thrusterd?")]
    Decode(String),
}

impl Machine {
    /// The machine's state as a checkpoint. Complete only when `checkpointable()`.
    pub fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError> {
        let mut out = Vec::with_capacity(16 * 1024);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&FORMAT.to_le_bytes());
        postcard::to_extend(self, out).map_err(|e| CheckpointError::Encode(e.to_string()))
    }

    /// The machine a checkpoint holds, configured with `setup` (the settings it ran with).
    pub fn restore(setup: MachineSetup, bytes: &[u8]) -> Result<Machine, CheckpointError> {
        let body = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or(CheckpointError::NotACheckpoint)?;
        let (format, body) = body
            .split_at_checked(4)
            .ok_or(CheckpointError::NotACheckpoint)?;
        let found = u32::from_le_bytes(format.try_into().expect("4 bytes"));
        if found != FORMAT {
            return Err(CheckpointError::Format { found });
        }
        let machine: Machine =
            postcard::from_bytes(body).map_err(|e| CheckpointError::Decode(e.to_string()))?;
        Ok(machine.with_setup(setup))
    }
}
