//! Does the hold watch (`machine.lost_hold_*`) ever fire on a vehicle that is held? The false
//! alarm side of `daemon/core/tests/lost_hold.rs`.

use nalgebra::DMatrix;
use thruster_inprocess::holding::PitchSteps;
use thruster_inprocess::run::{env_list, rel_err, Run, VEHICLES};
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::NoisePreset;
use thrusterd_core::machine::{actuated_error_deg, Event, State};

/// A measuring tool, not a check: every vehicle file (LH_VEHICLES, a comma list; default all),
/// in each water (LH_WATER, default still,current,moderate,rough; the water comes up after the
/// first model), at LH_NOISE (none|realistic|paper, default realistic), seeds LH_SEEDS (default
/// 1,2), flies +-20 deg pitch steps every 4 s for LH_MINUTES (default 5) with every check on
/// (a mismatch re-estimates, as shipped). Per run: the hold-lost events, the mismatches, the
/// largest 10 s mean of the true angle to the setpoint on the axes the model actuates while
/// the machine controlled (the watch's quantity, from the truth rather than the filter) and
/// the time not in Active. LH_DEG (default the shipped `machine.lost_hold_deg`): the limit.
/// LH_CAL, LH_MON_CAL (s): `refinement.change_calibration_s` and `monitor.calibration_s` (the
/// calibrations against the water; default the shipped 120, 0 = off); LH_CAL_WHEN (in_a_sea |
/// always): when both apply (default the shipped "in_a_sea"). LH_NAME_MARGIN:
/// `refinement.change_name_margin` (default the shipped 20).
/// LH_LEVEL=1: hold level at the starting heading instead of the pitch steps. The last column
/// is the sea-state gauge at the end (`identification/sea_state.rs`, deg RMS; NaN: not known).
/// LH_WHY: print each mismatch's reason. LH_TRACE: print the machine's status as it changes,
/// with the angle to the setpoint, the sea-state gauge every 10 s, and each model swap against
/// the truth (the new and the old model, the new one's bound, the sea state; the first model
/// too, as a swap from none). LH_CURVE_CONFIRM (s): `identification.curve_confirm_min_s`.
/// LH_GAIN_GAP: `refinement.gain_gap_min` (0: off); LH_GAIN: print the refinement's pooled
/// common gain at each window; every bound widened for it is printed.
///   `cargo run --release -p thrusterctl -- study sweep lost_hold_soak`
pub(super) fn lost_hold_soak() {
    let minutes: f64 = std::env::var("LH_MINUTES").map_or(5.0, |v| v.parse().unwrap());
    let seeds: Vec<u64> = env_list("LH_SEEDS", &[1, 2]);
    let noise = match std::env::var("LH_NOISE").as_deref() {
        Ok("none") => NoisePreset::None,
        Ok("paper") => NoisePreset::Paper,
        _ => NoisePreset::Realistic,
    };
    let vehicles: Vec<String> = std::env::var("LH_VEHICLES").map_or_else(
        |_| VEHICLES.iter().map(|s| s.to_string()).collect(),
        |v| v.split(',').map(|s| s.trim().to_string()).collect(),
    );
    let waters: Vec<WaterPreset> = std::env::var("LH_WATER")
        .unwrap_or_else(|_| "still,current,moderate,rough".into())
        .split(',')
        .map(|w| {
            use clap::ValueEnum;
            WaterPreset::from_str(w.trim(), true).unwrap_or_else(|e| panic!("LH_WATER: {e}"))
        })
        .collect();
    let limit: Option<f64> = std::env::var("LH_DEG").ok().map(|v| v.parse().unwrap());
    let level = std::env::var("LH_LEVEL").is_ok_and(|v| v == "1");
    let change_calibration_s: Option<f64> =
        std::env::var("LH_CAL").ok().map(|v| v.parse().unwrap());
    let monitor_calibration_s: Option<f64> =
        std::env::var("LH_MON_CAL").ok().map(|v| v.parse().unwrap());
    let calibrate_when = super::calibrate_when_from_env("LH_CAL_WHEN");
    let name_margin: Option<f64> = std::env::var("LH_NAME_MARGIN")
        .ok()
        .map(|v| v.parse().unwrap());
    // LH_SETTLE_DECISION: `identification.settle_decision_s` (1: the settle wait decided once
    // a segment, as until 2026-12-06).
    let settle_decision_s: Option<f64> = std::env::var("LH_SETTLE_DECISION")
        .ok()
        .map(|v| v.parse().unwrap());
    let flight = if level {
        "held level"
    } else {
        "of +-20 deg pitch steps every 4 s"
    };
    println!("{noise:?}, {minutes} min {flight}, limit {limit:?}, name margin {name_margin:?}");
    println!(
        "{:>15} {:>9} {:>5} {:>5} {:>10} {:>13} {:>12} {:>9} {:>13}",
        "vehicle",
        "water",
        "seed",
        "lost",
        "mismatches",
        "max 10s mean",
        "not Active s",
        "sea deg",
        "last 60s mean"
    );
    // LH_NO_LEARN: a curve the identification names is refused, not learned (the decisive
    // run for `identification.learn_thrust_curve`).
    let no_learn = std::env::var_os("LH_NO_LEARN").is_some();
    let mut total_lost = 0;
    for name in &vehicles {
        for water in &waters {
            for &seed in &seeds {
                let mut run = Run::new(name, noise, seed);
                // One setup (each `with_setup` starts from the shipped one).
                let knobs = [
                    limit,
                    change_calibration_s,
                    monitor_calibration_s,
                    name_margin,
                    settle_decision_s,
                ];
                let curve_confirm: Option<f64> = std::env::var("LH_CURVE_CONFIRM")
                    .ok()
                    .map(|v| v.parse().unwrap());
                let gain_gap: Option<f64> = std::env::var("LH_GAIN_GAP")
                    .ok()
                    .map(|v| v.parse().unwrap());
                if knobs.iter().any(Option::is_some)
                    || calibrate_when.is_some()
                    || no_learn
                    || curve_confirm.is_some()
                    || gain_gap.is_some()
                {
                    run.with_setup(|c| {
                        c.identification.learn_thrust_curve = !no_learn;
                        if let Some(w) = calibrate_when {
                            c.refinement.change_calibrate_when = w;
                            c.monitor.calibrate_when = w;
                        }
                        if let Some(deg) = limit {
                            c.machine.lost_hold_deg = deg;
                        }
                        if let Some(s) = change_calibration_s {
                            c.refinement.change_calibration_s = s;
                        }
                        if let Some(s) = monitor_calibration_s {
                            c.monitor.calibration_s = s;
                        }
                        if let Some(m) = name_margin {
                            c.refinement.change_name_margin = m;
                        }
                        if let Some(s) = settle_decision_s {
                            c.identification.settle_decision_s = s;
                        }
                        if let Some(s) = curve_confirm {
                            c.identification.curve_confirm_min_s = s;
                        }
                        if let Some(g) = gain_gap {
                            c.refinement.gain_gap_min = g;
                        }
                    });
                }
                run.learn_then_water(*water);
                let (lost, mismatches, worst, away, tail) = fly(&mut run, minutes * 60.0, level);
                let sea = run.machine.sea_state_deg().unwrap_or(f64::NAN);
                total_lost += lost;
                println!(
                    "{name:>15} {:>9} {seed:>5} {lost:>5} {mismatches:>10} {worst:>13.1} {away:>12.1} {sea:>9.1} {tail:>13.1}",
                    format!("{water:?}").to_lowercase()
                );
            }
        }
    }
    println!("hold lost {total_lost} times in all");
}

/// Pitch steps (or, `level`, a level hold at the starting heading) for `seconds`: (hold-lost
/// events, mismatches, largest 10 s mean angle to the setpoint while controlling (deg), vehicle
/// time outside Active (s), the mean angle over the last 60 s of control (deg): what the
/// vehicle flies on once its model has settled).
fn fly(run: &mut Run, seconds: f64, level: bool) -> (usize, usize, f64, f64, f64) {
    let mut plan = PitchSteps::new(run);
    let level_at =
        nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, run.sim.roll_pitch_yaw()[2]);
    if level {
        run.machine
            .on_setpoint(level_at, Some(run.sim.position_ned().z));
    }
    let start = run.sim.time_s();
    let (mut lost, mut mismatches, mut away) = (0, 0, 0.0);
    // 10 s of 1 s block means of the angle to the setpoint.
    let (mut blocks, mut sum, mut k, mut worst) = (Vec::<f64>::new(), 0.0, 0u32, 0.0f64);
    // Every 1 s block mean while controlling, for the last minute's.
    let mut every = Vec::<f64>::new();
    let dt = 1.0 / 200.0;
    let trace = std::env::var_os("LH_TRACE").is_some();
    let why_each = std::env::var_os("LH_WHY").is_some();
    let mut last = String::new();
    // Traced, the first model is shown too (as a swap from none).
    let mut last_b = run
        .machine
        .model()
        .filter(|_| !trace)
        .map(|m| m.effectiveness.clone());
    // A model restated in place (its bound, not its B) is a swap to trace too.
    let mut last_version = run.machine.model().filter(|_| !trace).map(|m| m.version);
    // LH_DRIFT: how far the refinement carries the model from the last estimated one, as the
    // common scale of the columns per row group over the estimate's own bound (the largest).
    let drift = std::env::var_os("LH_DRIFT").is_some();
    let mut estimated: Option<(DMatrix<f64>, [f64; 2])> = None;
    let mut worst_drift = [0.0f64; 2];
    // LH_GAIN: the refinement's pooled common gain over the model in force, at each window.
    let gain_trace = std::env::var_os("LH_GAIN").is_some();
    let mut gain_windows = 0u32;
    while run.sim.time_s() - start < seconds {
        let t = run.sim.time_s() - start;
        let sp = if level { level_at } else { plan.at(run, t) };
        run.tick();
        if gain_trace {
            let pooled = run.machine.refinement_gain();
            let w = pooled.map_or(0, |p| p.windows);
            if w != gain_windows {
                gain_windows = w;
                if let (Some(p), Some(m)) = (pooled, run.machine.model()) {
                    let truth = run.truth();
                    let err = |rows| err_vs_truth(Some(&m.effectiveness), &truth, rows);
                    println!(
                        "    {t:6.1} s gain {} windows: rot {:.3} +- {:.3}, acc {:.3} +- {:.3}; model v{} {:.3} / {:.3} under {:.3} / {:.3}",
                        p.windows, p.gain[0], p.std_err[0], p.gain[1], p.std_err[1],
                        m.version, err(0), err(3), m.rel_err_rot, m.rel_err_acc
                    );
                }
            }
        }
        if drift {
            if let Some(m) = run.machine.model() {
                if m.refinements == 0 {
                    if estimated
                        .as_ref()
                        .is_none_or(|(b, _)| *b != m.effectiveness)
                    {
                        estimated = Some((m.effectiveness.clone(), [m.rel_err_rot, m.rel_err_acc]));
                    }
                } else if let Some((b0, bound)) = &estimated {
                    for (g, w) in worst_drift.iter_mut().enumerate() {
                        let rows = 3 * g..3 * g + 3;
                        let r = b0.rows(rows.start, 3);
                        let n = m.effectiveness.rows(rows.start, 3);
                        let scale = n.dot(&r) / r.dot(&r) - 1.0;
                        *w = w.max(scale.abs() / bound[g]);
                    }
                }
            }
        }
        let b = run.machine.model().map(|m| &m.effectiveness);
        let version = run.machine.model().map(|m| m.version);
        if trace && (b != last_b.as_ref() || version != last_version) {
            trace_swap(run, t, last_b.as_ref(), b);
            last_b = b.cloned();
            last_version = version;
        }
        if trace && ((t * 200.0).round() as u64).is_multiple_of(2000) {
            println!(
                "    {t:6.1} s sea state {:?} ({:.1} s counted), in a sea {}",
                run.machine.sea_state_deg(),
                run.machine.sea_state_counted_s(),
                run.machine.in_a_sea()
            );
        }
        if trace {
            let text = run.machine.status().text;
            if text != last {
                let d = run.sim.attitude().angle_to(&sp).to_degrees();
                println!(
                    "    {t:6.1} s {d:5.1} deg {:?}: {}",
                    run.machine.state(),
                    text
                );
                last = text;
            }
        }
        for e in run.machine.take_events() {
            match e {
                Event::HoldLost(why) => {
                    println!("    {t:.1} s: {why}");
                    lost += 1;
                }
                // The thrust-curve check's refusals, always shown: on these vehicles (every
                // thruster linear, or a T200 linearized) each one is a false alarm.
                Event::ModelRejected(why) if why.contains("not follow the command linearly") => {
                    println!("    {t:.1} s: curve refusal: {why}");
                }
                // Every widening shown: on a linear vehicle in still water it is a false
                // alarm of the hold's gain (`gain_gap`).
                Event::BoundWidened(why) => {
                    let truth = run.truth();
                    let b = run.machine.model().map(|m| &m.effectiveness);
                    let errs = [0, 3].map(|rows| err_vs_truth(b, &truth, rows));
                    println!(
                        "    {t:.1} s: bound widened (model {:.3} / {:.3} off): {why}",
                        errs[0], errs[1]
                    );
                }
                Event::MismatchDetected(why) => {
                    mismatches += 1;
                    if why_each {
                        println!("    {t:.1} s: mismatch: {why}");
                    }
                }
                _ => {}
            }
        }
        let model = run.machine.model().map(|m| m.actuated);
        if let (true, Some(actuated)) = (
            matches!(run.machine.state(), State::Active | State::Identify),
            model,
        ) {
            sum += actuated_error_deg(&run.sim.attitude(), &sp, actuated);
            k += 1;
            if k >= 200 {
                blocks.push(sum / f64::from(k));
                every.push(sum / f64::from(k));
                (sum, k) = (0.0, 0);
                if blocks.len() > 10 {
                    blocks.remove(0);
                }
                if blocks.len() == 10 {
                    worst = worst.max(blocks.iter().sum::<f64>() / 10.0);
                }
            }
        } else {
            away += dt;
            (blocks, sum, k) = (Vec::new(), 0.0, 0);
        }
    }
    if drift {
        println!(
            "    refinement's common scale drift over the estimate's bound, largest: rot {:.2}, acc {:.2}",
            worst_drift[0], worst_drift[1]
        );
    }
    let last = &every[every.len().saturating_sub(60)..];
    let tail = last.iter().sum::<f64>() / last.len().max(1) as f64;
    (lost, mismatches, worst, away, tail)
}

/// A model's rows from `rows` against the truth; NaN without one or of another shape.
fn err_vs_truth(b: Option<&DMatrix<f64>>, truth: &DMatrix<f64>, rows: usize) -> f64 {
    b.filter(|b| b.shape() == truth.shape())
        .map_or(f64::NAN, |b| rel_err(b, truth, rows))
}

/// LH_TRACE: a model swap, the new and the old model against the truth, the new one's own
/// bound, and how far the new one is from the old (relative, per row group).
fn trace_swap(run: &Run, t: f64, old: Option<&DMatrix<f64>>, new: Option<&DMatrix<f64>>) {
    let truth = run.truth();
    let err = |b: Option<&DMatrix<f64>>, rows| err_vs_truth(b, &truth, rows);
    let apart = |rows| match (old, new) {
        (Some(o), Some(n)) if o.shape() == n.shape() => rel_err(n, o, rows),
        _ => f64::NAN,
    };
    let bound = run
        .machine
        .last_estimate()
        .map_or([f64::NAN; 2], |e| [e.rel_err_rot, e.rel_err_acc]);
    // What the model in force claims (a restated one's differs from its estimate's).
    let claims = run
        .machine
        .model()
        .map_or([f64::NAN; 2], |m| [m.rel_err_rot, m.rel_err_acc]);
    // The curve the commands go out through and what the fit's probe said of what is left.
    let curve = run
        .machine
        .model()
        .and_then(|m| m.dynamics.as_ref())
        .map(|d| {
            (
                d.command_exponent,
                d.thrust_curve
                    .map(|c| (c.fitted_exponent, c.log_likelihood_ratio)),
            )
        });
    println!(
        "    {t:6.1} s swap: new {:.3} / {:.3} (estimate's bound {:.3} / {:.3}, model's {:.3} / {:.3}), old {:.3} / {:.3}, new vs old {:.3} / {:.3}, curve {curve:?}, sea state {:?}",
        err(new, 0),
        err(new, 3),
        bound[0],
        bound[1],
        claims[0],
        claims[1],
        err(old, 0),
        err(old, 3),
        apart(0),
        apart(3),
        run.machine.sea_state_deg()
    );
}
