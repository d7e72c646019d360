//! `thrusterd replay`: a recorded session (MCAP from `thrusterctl record` or `demo --record`)
//! run through the daemon's own state machine and estimator offline. With the recording's
//! configuration it reproduces the models the daemon swapped in, bit for bit; with another
//! it answers what that setting would have learned from the same water.
//!
//! - `mcap_read`: the file, every problem named with its byte offset;
//! - `recording`: the channels a replay needs (imu, input, thrust; config, model);
//! - `journal`: the daemon's input journal checked (one whole session, nothing lost);
//! - `start`: from the daemon's start, or from a checkpoint of its state (a late recording);
//! - `rerun`: the machine fed the samples and the journal in the daemon's order;
//! - `compare`: replayed models against the recorded ones, entry for entry;
//! - `report`: text and JSON.

pub mod compare;
pub mod journal;
pub mod mcap_read;
pub mod recording;
pub mod report;
pub mod rerun;
pub mod start;

use thrusterd_core::config::DaemonConfig;

pub use recording::{Recording, RecordingError};

/// Why a recording cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error(transparent)]
    Journal(#[from] journal::JournalError),
    #[error(transparent)]
    Rerun(#[from] rerun::RerunError),
    #[error("no \"config\" channel: the recording does not hold the daemon's configuration; give the settings it ran with (--config FILE)")]
    NoConfig,
    #[error("the recorded configuration was cut to fit its message (the daemon warned): give the settings it ran with (--config FILE)")]
    ConfigTruncated,
    #[error(transparent)]
    Config(#[from] thrusterd_core::config::ConfigError),
    #[error("{why}; {passed}")]
    NoCheckpoint {
        why: journal::JournalError,
        passed: String,
    },
    #[error("checkpoint {id}: {why}")]
    Checkpoint {
        id: u64,
        why: thrusterd_core::machine::CheckpointError,
    },
    #[error("the recording began after the daemon (or the daemon had a model from a file), so the replay starts from a checkpoint of the daemon's state, which its own settings made: it replays only with the recording's configuration (no --config, --thrusters)")]
    CheckpointWithOtherConfig,
}

/// Where the recorded configuration came from, in errors.
pub const RECORDED_CONFIG: &str = "the recording's config channel";

/// The daemon's effective configuration as recorded.
pub fn recorded_config(rec: &Recording) -> Result<DaemonConfig, ReplayError> {
    let msg = rec.config.as_ref().ok_or(ReplayError::NoConfig)?;
    if msg.truncated != 0 {
        return Err(ReplayError::ConfigTruncated);
    }
    Ok(DaemonConfig::from_toml_str(
        msg.toml.as_str(),
        RECORDED_CONFIG,
    )?)
}

/// The result of a replay.
#[derive(Debug, Clone)]
pub struct Replayed {
    pub outcome: rerun::Outcome,
    /// Models the recording holds (the daemon's `model` channel).
    pub recorded_models: Vec<thruster_protocol::ModelMsg>,
    /// The first difference from the recorded models, `None` when identical.
    pub difference: Option<String>,
    /// The checkpoint the replay started from (None: the daemon's start).
    pub checkpoint: Option<start::Started>,
}

/// Replays `rec` with `cfg`.
pub fn replay(rec: &Recording, cfg: &DaemonConfig) -> Result<Replayed, ReplayError> {
    rerun::check_complete(&rec.imu, &rec.thrust)?;
    // When each solve's result reached the daemon's machine holds for the daemon's own
    // settings only: with other settings the jobs are other jobs, run inline and applied at
    // their due samples.
    let own_settings = recorded_config(rec).is_ok_and(|recorded| &recorded == cfg);
    let start = start::choose(&rec.inputs, &rec.checkpoints, cfg)?;
    if start.checkpoint.is_some() && !own_settings {
        return Err(ReplayError::CheckpointWithOtherConfig);
    }
    let inputs = start.inputs;
    let without_deliveries: Vec<thruster_protocol::InputMsg>;
    let inputs = if own_settings {
        inputs
    } else {
        without_deliveries = inputs
            .iter()
            .filter(|m| m.kind() != Ok(thruster_protocol::InputKind::SolveDelivered))
            .copied()
            .collect();
        &without_deliveries
    };
    let outcome = rerun::rerun(cfg, start.resume, &rec.imu, inputs, &rec.thrust)?;
    // From a checkpoint: the swaps after it (the model in force then is in the checkpoint;
    // a recorder that joined late also got it, as the model topic's history).
    let after = start.checkpoint.map_or(0, |c| c.place.model_version);
    let recorded_models: Vec<_> = rec
        .models
        .iter()
        .filter(|m| start.checkpoint.is_none() || m.version > after)
        .copied()
        .collect();
    let difference = compare::first_difference(&outcome.models, &recorded_models);
    Ok(Replayed {
        outcome,
        recorded_models,
        difference,
        checkpoint: start.checkpoint,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The daemon publishes `toml::to_string(&cfg)`; the replay parses it back. It must come
    /// back as the same settings, every float to the bit (toml writes the shortest
    /// round-trip form), and the largest configuration (a declared layout of 16 thrusters,
    /// every float at full length) must fit the message with room for the keys still to
    /// come: half of it. Why not a quarter for the defaults, as before: they passed 4 KiB
    /// with `machine.max_rest_swing_radps` (4107 bytes, 2026-12-06); what must fit is the
    /// largest.
    #[test]
    fn the_configuration_round_trips_through_its_toml() {
        let mut cfg = DaemonConfig::default();
        cfg.estimator.target_rel_err = 0.1 + 0.2;
        cfg.vehicle.thrusters = 6;
        let text = toml::to_string(&cfg).unwrap();
        let back = DaemonConfig::from_toml_str(&text, "test").unwrap();
        assert_eq!(back, cfg);
        let third = 1.0 / 3.0;
        cfg.vehicle.thrusters = 16;
        cfg.vehicle.thruster = (0..16)
            .map(|i| thrusterd_core::config::ThrusterDecl {
                position_m: [0.1 + third * i as f64, -third, third],
                direction: [third.sqrt(), -third.sqrt(), third.sqrt()],
            })
            .collect();
        let text = toml::to_string(&cfg).unwrap();
        assert_eq!(DaemonConfig::from_toml_str(&text, "test").unwrap(), cfg);
        assert!(
            text.len() < thruster_protocol::CONFIG_TEXT_CAPACITY / 2,
            "{}",
            text.len()
        );
    }
}
