//! The replay's answer: text for a person, JSON (`--json`) for scripts and tests.

use serde_json::{json, Value};
use thruster_protocol::{ModelMethod, ModelMsg, ModelSource, DOF_COUNT};

use crate::Replayed;

const DOFS: [&str; DOF_COUNT] = ["roll", "pitch", "yaw", "surge", "sway", "heave"];

/// Which configuration ran, for both forms.
pub struct Context<'a> {
    pub files: &'a str,
    /// `None`: the recording's own.
    pub config: Option<&'a str>,
}

fn config_name(ctx: &Context) -> String {
    ctx.config
        .map_or_else(|| "the recording's".to_string(), str::to_string)
}

fn actuated(m: &ModelMsg) -> Vec<&'static str> {
    (0..DOF_COUNT)
        .filter(|d| m.actuated & (1 << d) != 0)
        .map(|d| DOFS[d])
        .collect()
}

fn describe(m: &ModelMsg) -> String {
    let source = m.source().map_or("?", ModelSource::name);
    let method = m.method().map_or("?", ModelMethod::name);
    format!(
        "model v{}: {source} ({method}, {} pulses), error bounds rot {:.4} acc {:.4}, actuated {}",
        m.version,
        m.pulses,
        m.rel_err_rot,
        m.rel_err_acc,
        actuated(m).join(" ")
    )
}

/// The report as text.
pub fn text(ctx: &Context, r: &Replayed) -> String {
    use std::fmt::Write;
    let o = &r.outcome;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "replay of {} with {} configuration: {} IMU samples ({} reached the daemon, {} accepted), {} inputs, {:.1} vehicle-s; the machine ends {}: {}",
        ctx.files,
        config_name(ctx),
        o.imu_recorded,
        o.imu_recorded as u64 - o.imu_not_received,
        o.imu_accepted,
        o.inputs_applied,
        o.vehicle_s,
        o.final_state.name(),
        o.final_text
    );
    if let Some(c) = &r.checkpoint {
        let _ = writeln!(
            s,
            "started from checkpoint {} ({} bytes; taken after accepted IMU sample {} (seq {}, t {:.3} s), before input journal entry {}, model v{} in force): the recording began after the daemon's start; {} recorded samples before it only validated",
            c.id,
            c.bytes,
            c.place.imu_count,
            c.place.imu_seq,
            c.place.t_ns as f64 * 1e-9,
            c.place.journal_next,
            c.place.model_version,
            o.imu_before_checkpoint
        );
    }
    for (m, valid) in o.models.iter().zip(&o.models_valid) {
        let note = if *valid {
            ""
        } else {
            " [made after the commands diverged: not this setting's answer]"
        };
        let _ = writeln!(s, "{}{note}", describe(m));
    }
    match o.models.last() {
        Some(m) => {
            let _ = writeln!(s, "effectiveness per unit command (rad/s^2, m/s^2):");
            let n = m.thruster_count();
            let _ = write!(s, "{:>7}", "");
            for t in 0..n {
                let _ = write!(s, " {:>10}", format!("t{t}"));
            }
            let _ = writeln!(s);
            for (d, name) in DOFS.iter().enumerate() {
                let _ = write!(s, "{name:>7}");
                for t in 0..n {
                    let _ = write!(s, " {:>10.5}", m.effectiveness[d][t]);
                }
                let _ = writeln!(s);
            }
        }
        None => {
            let _ = writeln!(s, "no model was swapped in");
        }
    }
    let _ = match &o.diverged_at {
        None => writeln!(
            s,
            "commands: the replay answered all {} compared samples as the daemon did",
            o.commands_compared
        ),
        Some(d) => writeln!(
            s,
            "commands: the replay's left the daemon's at accepted sample {} (seq {}, {:.3} s); from there the recorded samples answer the daemon's commands, not the replay's",
            d.imu_count, d.imu_seq, d.t_s
        ),
    };
    let recorded = r.recorded_models.len();
    let after = if r.checkpoint.is_some() {
        " after the checkpoint"
    } else {
        ""
    };
    let _ = match &r.difference {
        None => writeln!(
            s,
            "the recording's {recorded} model swap(s){after}: reproduced, identical entry for entry ({} entries)",
            crate::compare::entries(&o.models)
        ),
        Some(d) => writeln!(
            s,
            "the recording's {recorded} model swap(s){after}: the replay differs ({d})"
        ),
    };
    if o.inputs_after_end > 0 {
        let _ = writeln!(
            s,
            "{} input(s) after the recording's last IMU sample not applied",
            o.inputs_after_end
        );
    }
    for d in &o.divergences {
        let _ = writeln!(s, "diverged: {d}");
    }
    s
}

/// The report as one JSON object: `models` holds every swap as the daemon's `model` channel
/// carries it (the `ModelMsg` JSON), so a script compares them field for field.
pub fn json(ctx: &Context, r: &Replayed) -> Value {
    let o = &r.outcome;
    // `actuated` stays the channel's bit mask (compared with the recording field for field);
    // `actuated_dof` beside it names the axes (issue 27: `"actuated": 47` said nothing).
    let named = |m: &ModelMsg| {
        let mut v = serde_json::to_value(m).unwrap_or(Value::Null);
        if let Value::Object(fields) = &mut v {
            fields.insert("actuated_dof".into(), json!(actuated(m)));
        }
        v
    };
    let models: Vec<Value> = o.models.iter().map(named).collect();
    json!({
        "files": ctx.files,
        "config": ctx.config.unwrap_or("recording"),
        "imu_samples": o.imu_recorded,
        "imu_not_received": o.imu_not_received,
        "imu_accepted": o.imu_accepted,
        "imu_rejected": o.imu_rejected,
        "inputs_applied": o.inputs_applied,
        "inputs_after_end": o.inputs_after_end,
        "vehicle_s": o.vehicle_s,
        "final_state": o.final_state.name(),
        "final_text": o.final_text,
        "models": models,
        "model": o.models.last().map(named),
        "models_valid": o.models_valid,
        "model_valid": o.models_valid.last(),
        "commands_compared": o.commands_compared,
        "commands_diverged_at": o.diverged_at.map(|d| json!({
            "imu_count": d.imu_count,
            "imu_seq": d.imu_seq,
            "t_s": d.t_s,
        })),
        "actuated": o.models.last().map(actuated),
        "recorded_models": r.recorded_models.len(),
        "reproduces_recording": r.difference.is_none(),
        "first_difference": r.difference,
        "entries_compared": crate::compare::entries(&o.models),
        "divergences": o.divergences,
        "checkpoint": r.checkpoint.map(|c| json!({
            "id": c.id,
            "bytes": c.bytes,
            "imu_count": c.place.imu_count,
            "imu_seq": c.place.imu_seq,
            "t_ns": c.place.t_ns,
            "journal_next": c.place.journal_next,
            "model_version": c.place.model_version,
            "imu_before": o.imu_before_checkpoint,
        })),
    })
}
