//! The experiment's text report and its output folder (per-run CSV, the figure, the JSON).

use super::*;

pub(super) fn fmt(v: Num) -> String {
    match v.value() {
        Some(x) => format!("{x:.2}"),
        None => "-".into(),
    }
}

/// What followed a change, in the order it happens; what did not happen is said in words, not
/// as "-" (the oracle does not re-estimate; an announced change is told, not detected).
pub(super) fn hot_swap_events(h: &HotSwapScores) -> String {
    let after = |x: Num| x.value().map(|v| format!("{v:.2} s"));
    let mut parts = vec![match after(h.reestimation_start_delay_s) {
        Some(t) => format!("re-estimation began after {t}"),
        None => "no re-estimation".to_string(),
    }];
    if let Some(t) = after(h.detection_delay_s) {
        parts.push(format!("mismatch in status after {t}"));
    }
    if let Some(t) = after(h.first_swap_delay_s) {
        let source = h.first_swap_source.as_deref().unwrap_or("unknown source");
        parts.push(format!("first swap after {t} ({source})"));
    }
    if let Some(t) = after(h.new_model_delay_s) {
        parts.push(format!("new model after {t}"));
    }
    let threshold = fmt(h.recovery_threshold_deg);
    parts.push(match after(h.recovered_after_s) {
        Some(t) => format!("recovered (2 s windows < {threshold} deg) after {t}"),
        None => format!("not recovered (2 s windows < {threshold} deg)"),
    });
    parts.join(", ")
}

/// A settled error in words: "settled 1.23 deg", or "not settled" where no step was held long enough
/// to count (issue 27: it read "settled - deg").
pub(super) fn settled(v: Num) -> String {
    match v.value() {
        Some(x) => format!("settled {x:.2} deg"),
        None => "not settled".into(),
    }
}

pub(super) fn print_report(name: Name, outs: &[RunOutput], summary: &Summary) -> Result<()> {
    println!(
        "experiment {} (noise {}, seed {})",
        name.id(),
        summary.noise,
        summary.seed
    );
    for o in outs {
        let v = summary.runs.get(o.spec.label)?;
        println!();
        println!("run {}: {}", o.spec.label, o.spec.title);
        let m = &v.model;
        println!(
            "  model: {} ({} {}), actuated {}, error vs truth rot {} acc {}",
            m.start,
            m.source,
            m.method,
            m.actuated.join(","),
            fmt(m.rel_err_rot_vs_truth),
            fmt(m.rel_err_acc_vs_truth),
        );
        if let (Some(e), Some(pulses)) = (v.estimation_vehicle_s.value(), v.estimation_pulses) {
            println!("  estimated in {e:.1} vehicle s ({pulses} pulses)");
        }
        println!(
            "  mean angular error {} deg ({}; max {}), mean |yaw error| {} deg over {} s of hold",
            fmt(v.mean_err_deg),
            settled(v.settled_mean_err_deg),
            fmt(v.max_err_deg),
            fmt(v.mean_abs_yaw_err_deg),
            fmt(v.hold_s),
        );
        for (g, s) in v.per_maneuver.made() {
            println!(
                "    {g:>5}: mean {} deg, {}, |yaw error| mean {} max {} deg",
                fmt(s.mean_err_deg),
                settled(s.settled_mean_err_deg),
                fmt(s.mean_abs_yaw_err_deg),
                fmt(s.max_abs_yaw_err_deg),
            );
        }
        let osc = &v.oscillation;
        println!(
            "  oscillation: roll rate rms {} deg/s, sway {} / heave {} m/s rms, high-passed error rms {} deg, thrust activity {} /s",
            fmt(osc.roll_rate_rms_deg_s),
            fmt(osc.sway_vel_rms_m_s),
            fmt(osc.heave_vel_rms_m_s),
            fmt(osc.high_passed_err_rms_deg),
            fmt(osc.thrust_activity_per_s),
        );
        if v.monitor_mismatch_at_s.value().is_some() {
            println!(
                "  model-mismatch monitor fired at {} s",
                fmt(v.monitor_mismatch_at_s)
            );
        }
        if let Some(h) = &v.hot_swap {
            // One clock with the figure: its x axis is time since this run's hold began (the
            // first estimation takes a different time per run, so the change, at one vehicle
            // time for all, sits at a different x per row).
            let since_hold = match (h.t_change_s.value(), v.hold_start_s.value()) {
                (Some(c), Some(h0)) => format!("{:.2}", c - h0),
                _ => "-".into(),
            };
            // The re-estimation's start is its first command's sample time; the mismatch is
            // seen in a status, published up to a status period after the monitor fired and
            // started the re-estimation: so the status can read later than the start.
            println!(
                "  change {since_hold} s after the hold began (vehicle time {} s): {}",
                fmt(h.t_change_s),
                hot_swap_events(h)
            );
            if let Some(r) = &h.reestimation {
                println!(
                    "  while re-estimating ({} vehicle-s): largest tilt {} deg, heading change {} deg, error from the setpoint {} deg",
                    fmt(r.vehicle_s),
                    fmt(r.max_tilt_deg),
                    fmt(r.max_heading_change_deg),
                    fmt(r.max_err_deg),
                );
            }
            for (part, p) in [
                ("before", &h.before),
                ("during", &h.during),
                ("after", &h.after),
            ] {
                println!(
                    "    {part:>6}: mean error {} deg (max {}), |yaw error| {} deg, while pitching {} deg",
                    fmt(p.mean_err_deg),
                    fmt(p.max_err_deg),
                    fmt(p.mean_abs_yaw_err_deg),
                    fmt(p.mean_abs_yaw_err_pitching_deg),
                );
            }
        }
        println!(
            "  {:.1} s wall clock{}, shutdown {}",
            o.wall_s,
            o.pace.map(|p| format!(" at pace {p}")).unwrap_or_default(),
            if o.shutdown.clean {
                "clean"
            } else {
                "NOT clean"
            }
        );
    }
    println!();
    println!("headline: {}", summary.headline);
    Ok(())
}

pub(super) fn write_out(
    dir: &Path,
    name: Name,
    outs: &[RunOutput],
    summary: &Summary,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for o in outs {
        let mut csv = String::from(
            "t_s,setpoint_roll_deg,setpoint_pitch_deg,setpoint_yaw_deg,roll_deg,pitch_deg,yaw_deg,err_deg,yaw_err_deg,state,step\n",
        );
        for r in &o.rows {
            let _ = writeln!(
                csv,
                "{:.3},{:.2},{:.2},{:.2},{:.3},{:.3},{:.3},{:.3},{:.3},{},{}",
                r.t,
                r.sp[0],
                r.sp[1],
                r.sp[2],
                r.tru[0],
                r.tru[1],
                r.tru[2],
                r.err,
                r.yaw_err,
                r.state.name(),
                o.spec.plan.steps[r.step].label.replace(' ', "_"),
            );
        }
        let path = dir.join(format!("{}_{}.csv", name.id(), o.spec.label));
        std::fs::write(&path, csv).with_context(|| format!("writing {}", path.display()))?;
    }
    let svg = figure(name, outs);
    let path = dir.join(format!("{}.svg", name.id()));
    std::fs::write(&path, svg).with_context(|| format!("writing {}", path.display()))?;
    let path = dir.join(format!("{}.json", name.id()));
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&summary.json()?)? + "\n",
    )
    .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
