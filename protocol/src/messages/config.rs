use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use crate::wire::FixedText;

/// Capacity of [`ConfigMsg::toml`], bytes: the full default configuration is about 2 KiB,
/// a 16-thruster layout with declared geometry a few more.
pub const CONFIG_TEXT_CAPACITY: usize = 16 * 1024;

/// The daemon's effective configuration (daemon -> anyone, service `config`, history 1):
/// the configuration file with the command line's overrides applied, as TOML, published
/// once at start. A recording keeps it, so a replay runs the machine with the settings the
/// daemon had.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.ConfigMsg.v1")]
pub struct ConfigMsg {
    /// Sequence number, +1 per message.
    pub seq: u64,
    /// 1 when `toml` did not fit [`CONFIG_TEXT_CAPACITY`] and was cut (unusable for a
    /// replay), 0 otherwise.
    pub truncated: u32,
    /// Written as zero.
    pub reserved: u32,
    /// The configuration, TOML.
    pub toml: FixedText<CONFIG_TEXT_CAPACITY>,
}
