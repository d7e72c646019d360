use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use crate::wire::FixedText;

/// Capacity of [`CheckpointMsg::data`], bytes of base64 text (12 KiB of the machine's state
/// per part): a checkpoint of an idle or holding daemon fits in a few parts, and the
/// message stays the size of a [`crate::ConfigMsg`].
pub const CHECKPOINT_PART_CAPACITY: usize = 16 * 1024;

/// Most parts one checkpoint may take (768 KiB of state): a larger one is not published
/// (the daemon warns), and a recording then replays from the next one that fits.
pub const CHECKPOINT_MAX_PARTS: u32 = 64;

/// Part of a checkpoint of the daemon's state machine (daemon -> anyone, service
/// `checkpoint`): its whole state (attitude filter, controller, model slot, estimation run,
/// monitor, refinement, ...), serialised, at a well-defined place in the input journal. A
/// recording started late replays from its first checkpoint (`thrusterd replay`). The state
/// is split into parts of at most [`CHECKPOINT_PART_CAPACITY`] bytes of base64; a reader
/// joins the parts of one `id`, in order, and decodes them.
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[repr(C)]
#[derive(ZeroCopySend, Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[type_name("thrusterd.CheckpointMsg.v1")]
pub struct CheckpointMsg {
    /// Sequence number, +1 per message (per part).
    pub seq: u64,
    /// The checkpoint's number, from 0 at the daemon's start; every part of one checkpoint
    /// carries it.
    pub id: u64,
    /// Where it was taken: after the daemon handed its machine this many accepted IMU
    /// samples (the input journal's `imu_count`) ...
    pub imu_count: u64,
    /// ... the last of which had this `seq` ...
    pub imu_seq: u64,
    /// ... and this time, ns ...
    pub t_ns: u64,
    /// ... and before the input journal entry with this `seq`: every entry from it on came
    /// after the checkpoint, every earlier one is in it.
    pub journal_next: u64,
    /// The version of the model in force at the checkpoint (0: none). Swaps after the
    /// checkpoint have higher versions.
    pub model_version: u64,
    /// Size of the serialised state, bytes (before base64).
    pub bytes: u64,
    /// This part's number, from 0.
    pub part: u32,
    /// How many parts the checkpoint has.
    pub parts: u32,
    /// Why it was taken: 0 periodically, 1 after a model swap.
    pub reason: u32,
    /// Written as zero.
    pub reserved: u32,
    /// The part's share of the state, base64 (standard alphabet, padded only in the last
    /// part).
    pub data: FixedText<CHECKPOINT_PART_CAPACITY>,
}

impl CheckpointMsg {
    /// `reason` for a periodic checkpoint.
    pub const PERIODIC: u32 = 0;
    /// `reason` for a checkpoint after a model swap.
    pub const AFTER_SWAP: u32 = 1;
}
