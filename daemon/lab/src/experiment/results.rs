//! A run's scores (every run's [`common`] ones, hot-swap's), typed as [`scores`] has them, and
//! the experiment's headline from their fields: a score misnamed does not compile (read by its
//! path in the JSON, a typo once gave NaN and a `null` headline).

use super::*;

pub(super) fn actuated(m: &ModelMsg) -> Vec<&'static str> {
    (0..6)
        .filter(|j| m.actuated & (1 << j) != 0)
        .map(|j| DOFS[j])
        .collect()
}

/// Mean, RMS, max of the rows selected by `keep` for one quantity.
pub(super) fn stat(rows: &[Row], keep: impl Fn(&Row) -> bool, f: impl Fn(&Row) -> f64) -> Stats {
    Stats::of(rows.iter().filter(|r| keep(r)).map(f))
}

/// Scores every run has; its experiment's own are added by the caller.
pub(super) fn common(out: &RunOutput) -> RunScores {
    let rows = &out.rows;
    // The first (level) step is the entry into the hold: after an estimation the vehicle
    // still swings from the last pulses. The maneuver scores start after it, as the paper's
    // plots start with a settled vehicle; the entry is reported as the "level" maneuver.
    let all = |r: &Row| r.step > 0;
    let settled = |r: &Row| r.step > 0 && r.since_step >= SETTLE_S;
    let group = |g: &str| {
        let in_g = |r: &Row| out.spec.plan.steps[r.step].group == g;
        let s = stat(rows, in_g, |r| r.err);
        (s.n > 0).then(|| ManeuverScores {
            mean_err_deg: num(s.mean),
            settled_mean_err_deg: num(stat(rows, |r| in_g(r) && settled(r), |r| r.err).mean),
            mean_abs_yaw_err_deg: num(stat(rows, in_g, |r| r.yaw_err.abs()).mean),
            max_abs_yaw_err_deg: num(stat(rows, in_g, |r| r.yaw_err.abs()).max),
        })
    };
    // Oscillation: what is left after the first step's transient, in the DOFs that matter.
    let steady = |r: &Row| r.t >= out.hold_start + SETTLE_S;
    let hp: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| steady(r))
        .map(|r| (r.t, r.err))
        .collect();
    let activity = Stats::of(
        out.activity
            .iter()
            .filter(|a| a.0 >= out.hold_start + SETTLE_S)
            .map(|a| a.1),
    );
    RunScores {
        vehicle: out.spec.vehicle.into(),
        model: ModelScores {
            // The oracle's model is loaded, not estimated (issue 27: it read "estimated").
            start: match out.spec.start {
                Start::Manual => "manual (declared nominal geometry)",
                Start::Estimate => "estimated",
                Start::Oracle => "the simulator's true model, loaded",
            }
            .into(),
            method: out
                .model
                .method()
                .map(|m| format!("{m:?}"))
                .unwrap_or_default(),
            source: source_name(&out.model),
            version: out.model.version,
            actuated: actuated(&out.model).into_iter().map(String::from).collect(),
            rel_err_rot_vs_truth: num(out.model_truth.relative_error(&out.model, 0)),
            rel_err_acc_vs_truth: num(out.model_truth.relative_error(&out.model, 3)),
        },
        estimation_vehicle_s: opt(out.estimation.map(|e| e.0)),
        estimation_pulses: out.estimation.map(|e| e.1),
        hold_start_s: num(out.hold_start),
        hold_s: num(out.rows.last().map_or(0.0, |r| r.t) - out.hold_start),
        mean_err_deg: num(stat(rows, all, |r| r.err).mean),
        settled_mean_err_deg: num(stat(rows, settled, |r| r.err).mean),
        max_err_deg: num(stat(rows, all, |r| r.err).max),
        mean_abs_yaw_err_deg: num(stat(rows, all, |r| r.yaw_err.abs()).mean),
        per_maneuver: PerManeuver {
            level: group("level"),
            yaw: group("yaw"),
            pitch: group("pitch"),
            roll: group("roll"),
        },
        oscillation: Oscillation {
            roll_rate_rms_deg_s: num(stat(rows, steady, |r| r.rate[0]).rms),
            sway_vel_rms_m_s: num(stat(rows, steady, |r| r.vel[1]).rms),
            heave_vel_rms_m_s: num(stat(rows, steady, |r| r.vel[2]).rms),
            high_passed_err_rms_deg: num(high_pass_rms(&hp, 1.0)),
            thrust_activity_per_s: num(activity.mean),
        },
        monitor_mismatch_at_s: opt(out.mismatch_at),
        monitor_mismatch_reports: out.mismatch_reports,
        monitor_mismatch_lines: out.mismatch_lines.clone(),
        model_refinements: out.refinements,
        model_swaps: out
            .swaps
            .iter()
            .map(|s| SwapScore {
                t_s: num(s.t),
                version: s.version,
                source: s.source.clone(),
            })
            .collect(),
        status_changes: out.notes.len(),
        vehicle_samples_scored: out.rows.len(),
        wall_s: num(out.wall_s),
        pace: opt(out.pace),
        clean_exit: out.shutdown.clean,
        files_left: out.shutdown.leftovers,
        hot_swap: None,
        degrade: None,
        dive: None,
        noise: out.spec.noise.into(),
    }
}

/// The daemon states in which it estimates (open loop or under control).
pub(super) fn estimating(s: DaemonState) -> bool {
    matches!(
        s,
        DaemonState::MeasureNoise
            | DaemonState::Pulse
            | DaemonState::Settle
            | DaemonState::Solve
            | DaemonState::Identify
    )
}

/// hot-swap scores: before / during / after the change, the swap and recovery times.
pub(super) fn hot_swap(out: &RunOutput) -> HotSwapScores {
    let t_c = out.spec.change.map_or(f64::NAN, |c| c.0);
    let rows = &out.rows;
    // Before: from the settled hold after the first estimation up to the change.
    let before = |r: &Row| r.t >= out.hold_start + 3.0 && r.t < t_c;
    let errs: Vec<(f64, f64)> = rows.iter().map(|r| (r.t, r.err)).collect();
    let last_t = rows.last().map_or(0.0, |r| r.t);
    // Only whole windows: a short last one would be all transient.
    let windows: Vec<(f64, f64)> = window_means(&errs, WINDOW_S)
        .into_iter()
        .filter(|w| w.0 + WINDOW_S <= last_t)
        .collect();
    let before_worst = windows
        .iter()
        .filter(|w| w.0 >= out.hold_start + 3.0 && w.0 + WINDOW_S <= t_c)
        .map(|w| w.1)
        .fold(0.0, f64::max);
    // Back to normal: every later 2 s window below 1.5x the worst such window before the
    // change (the maneuvers' own transients are in both), and at least 2 degrees.
    let threshold = (1.5 * before_worst).max(2.0);
    let recovered = recovered_at(&windows, t_c, threshold);
    let new_model = out
        .swaps
        .iter()
        .find(|s| s.t >= t_c && s.source == "Estimated");
    let first_swap = out.swaps.iter().find(|s| s.t >= t_c);
    let after_from = match (recovered, new_model) {
        (Some(r), Some(m)) => r.max(m.t),
        (Some(r), None) => r,
        _ => f64::INFINITY,
    };
    let during = |r: &Row| r.t >= t_c && r.t < after_from;
    let after = |r: &Row| r.t >= after_from;
    let pitching = |r: &Row| out.spec.plan.steps[r.step].group == "pitch";
    let part = |keep: &dyn Fn(&Row) -> bool| {
        let e = stat(rows, keep, |r| r.err);
        Part {
            mean_err_deg: num(e.mean),
            max_err_deg: num(e.max),
            mean_abs_yaw_err_deg: num(stat(rows, keep, |r| r.yaw_err.abs()).mean),
            mean_abs_yaw_err_pitching_deg: num(stat(
                rows,
                |r| keep(r) && pitching(r),
                |r| r.yaw_err.abs(),
            )
            .mean),
            samples: e.n,
        }
    };
    let worst_after_change = windows
        .iter()
        .filter(|w| w.0 >= t_c)
        .map(|w| w.1)
        .fold(0.0, f64::max);
    // How far the vehicle went while the daemon re-estimated (open loop: from levelling to the
    // new model; closed loop: the identification under control), from the true attitude.
    let mut excursion = crate::excursion::Excursion::default();
    let mut max_err: f64 = 0.0;
    let mut estimating_s = 0.0;
    let mut last_t: Option<f64> = None;
    for r in rows.iter().filter(|r| r.t >= t_c && estimating(r.state)) {
        let [roll, pitch, yaw] = r.tru.map(f64::to_radians);
        excursion.push_attitude(&UnitQuaternion::from_euler_angles(roll, pitch, yaw));
        max_err = max_err.max(r.err);
        if let Some(t0) = last_t {
            estimating_s += (r.t - t0).min(0.1);
        }
        last_t = Some(r.t);
    }
    let reestimation = (excursion.samples > 0).then(|| Reestimation {
        max_tilt_deg: num(excursion.max_tilt_deg),
        max_heading_change_deg: num(excursion.max_heading_deg),
        max_err_deg: num(max_err),
        vehicle_s: num(estimating_s),
    });
    HotSwapScores {
        reestimation,
        t_change_s: num(t_c),
        announced: out.spec.change.is_some_and(|c| c.1),
        truth_changed_at_s: opt(out.truth_changes.first().copied()),
        detection_delay_s: opt(out.mismatch_at.filter(|t| *t >= t_c).map(|t| t - t_c)),
        reestimation_start_delay_s: opt(out.reestimate_at.map(|t| t - t_c)),
        first_swap_delay_s: opt(first_swap.map(|s| s.t - t_c)),
        first_swap_source: first_swap.map(|s| s.source.clone()),
        new_model_delay_s: opt(new_model.map(|s| s.t - t_c)),
        new_model_version: new_model.map(|s| s.version),
        new_model_rel_err_rot_vs_truth: opt(
            new_model.map(|_| out.final_truth.relative_error(&out.final_model, 0))
        ),
        recovery_threshold_deg: num(threshold),
        recovered_after_s: opt(recovered.map(|t| t - t_c)),
        worst_window_after_change_deg: num(worst_after_change),
        before: part(&before),
        during: part(&during),
        after: part(&after),
    }
}

/// The experiment's claim, the numbers behind it, and whether it holds: read from the runs'
/// scores by field, an error naming the run or the maneuver where one is missing.
pub(super) fn headline(name: Name, runs: &Runs) -> Result<Value> {
    Ok(match name {
        Name::ManualVsLearned => {
            let (learned, manual, oracle) = (
                runs.get("learned")?,
                runs.get("manual")?,
                runs.get("oracle")?,
            );
            let (l, m) = (learned.mean_err_deg.get(), manual.mean_err_deg.get());
            let o = oracle.mean_err_deg.get();
            json!({
                "claim": "the learned model holds attitude as well as the manual one",
                "learned_mean_err_deg": num(l),
                "manual_mean_err_deg": num(m),
                "oracle_mean_err_deg": num(o),
                "learned_over_manual": num(l / m),
                "learned_over_oracle": num(l / o),
                "learned_model_err_rot": learned.model.rel_err_rot_vs_truth,
                "learned_model_err_acc": learned.model.rel_err_acc_vs_truth,
            })
        }
        Name::Misaligned => {
            let pitch = |label: &str| runs.get(label)?.per_maneuver.pitch(label);
            let (learned, manual, oracle) = (pitch("learned")?, pitch("manual")?, pitch("oracle")?);
            let (lm, mm) = (
                learned.mean_abs_yaw_err_deg.get(),
                manual.mean_abs_yaw_err_deg.get(),
            );
            json!({
                "claim": "yaw error during pitch maneuvers more than 2x smaller with the re-learned model",
                "manual_yaw_err_mean_deg": num(mm),
                "manual_yaw_err_max_deg": num(manual.max_abs_yaw_err_deg.get()),
                "learned_yaw_err_mean_deg": num(lm),
                "learned_yaw_err_max_deg": num(learned.max_abs_yaw_err_deg.get()),
                "oracle_yaw_err_mean_deg": num(oracle.mean_abs_yaw_err_deg.get()),
                "manual_over_learned": num(mm / lm),
                // How much of the paper's effect this setup can show at all (the true model),
                // and how much of it the learned model captures.
                "manual_over_oracle": num(mm / oracle.mean_abs_yaw_err_deg.get()),
                "learned_model_err_rot": runs.get("learned")?.model.rel_err_rot_vs_truth,
            })
        }
        Name::Aligned => {
            let per = |label: &str| -> Result<Value> {
                let v = runs.get(label)?;
                Ok(json!({
                    "actuated": v.model.actuated,
                    "yaw_err_deg": num(v.per_maneuver.yaw(label)?.mean_err_deg.get()),
                    "pitch_err_deg": num(v.per_maneuver.pitch(label)?.mean_err_deg.get()),
                    "mean_err_deg": num(v.mean_err_deg.get()),
                    "roll_rate_rms_deg_s": num(v.oscillation.roll_rate_rms_deg_s.get()),
                    "high_passed_err_rms_deg": num(v.oscillation.high_passed_err_rms_deg.get()),
                    "thrust_activity_per_s": num(v.oscillation.thrust_activity_per_s.get()),
                }))
            };
            let (paper, forward) = (
                &runs.get("paper")?.oscillation,
                &runs.get("forward")?.oscillation,
            );
            let ratio = |k: fn(&Oscillation) -> Num| num(k(paper).get() / k(forward).get());
            json!({
                "claim": "ours reports roll, sway and heave unactuated and holds yaw and pitch without oscillation; the paper's learns them and oscillates",
                "paper": per("paper")?,
                "forward": per("forward")?,
                "oracle": per("oracle")?,
                "paper_over_forward_thrust_activity": ratio(|o| o.thrust_activity_per_s),
                "paper_over_forward_high_passed_err": ratio(|o| o.high_passed_err_rms_deg),
                "paper_over_forward_roll_rate": ratio(|o| o.roll_rate_rms_deg_s),
            })
        }
        Name::HotSwap => {
            let per = |label: &str| -> Result<Value> {
                let h = runs.get(label)?.hot_swap(label)?;
                Ok(json!({
                    "detection_delay_s": h.detection_delay_s,
                    "new_model_delay_s": h.new_model_delay_s,
                    "new_model_err_rot": h.new_model_rel_err_rot_vs_truth,
                    "recovered_after_s": h.recovered_after_s,
                    "before_mean_err_deg": h.before.mean_err_deg,
                    "during_mean_err_deg": h.during.mean_err_deg,
                    "after_mean_err_deg": h.after.mean_err_deg,
                    "before_yaw_err_pitching_deg": h.before.mean_abs_yaw_err_pitching_deg,
                    "after_yaw_err_pitching_deg": h.after.mean_abs_yaw_err_pitching_deg,
                }))
            };
            let level = runs.get("announced-level")?.hot_swap("announced-level")?;
            let level_reestimation =
                |k: fn(&Reestimation) -> Num| level.reestimation.as_ref().map_or(Num::NONE, k);
            json!({
                "claim": "after the top thruster turns 45 degrees the daemon re-estimates, swaps the new model in and control recovers, with and without a reconfiguration event",
                "announced": per("announced")?,
                "silent": per("silent")?,
                // The change test's run: silent at the paper's noise.
                "silent_paper": per("silent-paper")?,
                // Holding level through the announced change: the largest tilt while the
                // daemon identifies under control (the bound: 10 deg at the paper's
                // noise).
                "announced_level_max_tilt_deg": level_reestimation(|r| r.max_tilt_deg),
                "announced_level_max_heading_change_deg": level_reestimation(|r| r.max_heading_change_deg),
                "announced_level_new_model_delay_s": level.new_model_delay_s,
            })
        }
        Name::Degrade => {
            let d = |label: &str| runs.get(label)?.degrade(label);
            degrade::headline(d("refined")?, d("fixed")?, d("oracle")?)
        }
        Name::Dive => {
            let d = |label: &str| runs.get(label)?.dive(label);
            dive::headline(d("compensated")?, d("uncompensated")?)
        }
    })
}
