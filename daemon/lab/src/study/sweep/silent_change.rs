//! A silently rotated thruster in moving water, every detector on as shipped (the monitor, the
//! refinement's windows and its change test): how long an unchanged vehicle flies without a
//! false alarm, how soon the rotation is found and by whom, and how good the model learned
//! again is. The decisive runs for the calibrations against the water (issue 32 item 5).

use thruster_inprocess::holding::pitch_with;
use thruster_inprocess::run::{env_list, rel_err, Run};
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::NoisePreset;
use thrusterd_core::machine::State;

/// A measuring tool: AMOUR-5 (SC_VEHICLE, a vehicle file with a thruster "T") learns in still
/// water, the water SC_WATER (a comma list, default still,moderate,rough) comes up and it flies
/// +-20 deg pitch steps for SC_MINUTES (default 5; a mismatch here is a false alarm and ends
/// the run), then its top thruster is rotated 45 deg and it flies on up to 60 s. SC_NOISE
/// (none|realistic|paper, default realistic), SC_SEEDS (default 1-6), SC_CAL and SC_MON_CAL
/// (s): `refinement.change_calibration_s` and `monitor.calibration_s` (default the shipped 120,
/// 0 = off), SC_CAL_WHEN (in_a_sea | always, default the shipped in_a_sea) when both apply;
/// SC_MONITOR_ONLY=1: the refinement (its windows and change test) off, the monitor alone;
/// SC_NO_INSTRUMENT=1: `identification.instrument = "never"`; SC_NAME_MARGIN:
/// `refinement.change_name_margin` (default the shipped 20). Each detection line ends with the
/// sea state the machine had measured before the change and when it was found (deg RMS, None:
/// not known).
/// Per run: the false alarm (time, reason), the detection time and reason, the time to the
/// new model and its error against the new truth (rotation / acceleration rows).
///   `cargo run --release -p thrusterctl -- study sweep silent_change_in_water`
pub(super) fn silent_change_in_water() {
    let vehicle = std::env::var("SC_VEHICLE").unwrap_or_else(|_| "amour5".into());
    let minutes: f64 = std::env::var("SC_MINUTES").map_or(5.0, |v| v.parse().unwrap());
    let seeds: Vec<u64> = env_list("SC_SEEDS", &[1, 2, 3, 4, 5, 6]);
    let noise = match std::env::var("SC_NOISE").as_deref() {
        Ok("none") => NoisePreset::None,
        Ok("paper") => NoisePreset::Paper,
        _ => NoisePreset::Realistic,
    };
    let waters: Vec<WaterPreset> = std::env::var("SC_WATER")
        .unwrap_or_else(|_| "still,moderate,rough".into())
        .split(',')
        .map(|w| {
            use clap::ValueEnum;
            WaterPreset::from_str(w.trim(), true).unwrap_or_else(|e| panic!("SC_WATER: {e}"))
        })
        .collect();
    let knob = |key: &str| -> Option<f64> {
        std::env::var(key)
            .ok()
            .map(|v| v.parse().unwrap_or_else(|_| panic!("{key}: {v}")))
    };
    let (change_cal, monitor_cal) = (knob("SC_CAL"), knob("SC_MON_CAL"));
    let name_margin = knob("SC_NAME_MARGIN");
    let calibrate_when = super::calibrate_when_from_env("SC_CAL_WHEN");
    let monitor_only = std::env::var("SC_MONITOR_ONLY").is_ok_and(|v| v == "1");
    let never_instrument = std::env::var("SC_NO_INSTRUMENT").is_ok_and(|v| v == "1");
    println!(
        "{vehicle}, {noise:?}, {minutes} min unchanged, change test calibration {change_cal:?}, monitor calibration {monitor_cal:?}, applied {calibrate_when:?}, name margin {name_margin:?}"
    );
    for water in &waters {
        for &seed in &seeds {
            let mut run = Run::new(&vehicle, noise, seed);
            if change_cal.is_some()
                || monitor_cal.is_some()
                || calibrate_when.is_some()
                || monitor_only
                || never_instrument
                || name_margin.is_some()
            {
                run.with_setup(|c| {
                    if let Some(w) = calibrate_when {
                        c.refinement.change_calibrate_when = w;
                        c.monitor.calibrate_when = w;
                    }
                    c.refinement.enabled = !monitor_only;
                    if never_instrument {
                        c.identification.instrument =
                            thrusterd_core::adaptation::identification::Instrument::Never;
                    }
                    if let Some(s) = change_cal {
                        c.refinement.change_calibration_s = s;
                    }
                    if let Some(s) = monitor_cal {
                        c.monitor.calibration_s = s;
                    }
                    if let Some(m) = name_margin {
                        c.refinement.change_name_margin = m;
                    }
                });
            }
            run.learn_then_water(*water);
            let w = format!("{water:?}").to_lowercase();
            if let Some((t, why)) = pitch_with(&mut run, minutes * 60.0, |_, _| {}) {
                println!("{w:>9} seed {seed}: FALSE ALARM after {t:.1} s: {why}");
                continue;
            }
            let sea_before = run.machine.sea_state_deg();
            run.rotate_top();
            let Some((t, why)) = pitch_with(&mut run, 60.0, |_, _| {}) else {
                println!("{w:>9} seed {seed}: quiet; rotation not found within 60 s");
                continue;
            };
            let sea = run.machine.sea_state_deg();
            let took = run.run_until(120.0, |m| m.state() == State::Active);
            let truth = run.truth();
            let (rot, acc) = run.machine.model().map_or((f64::NAN, f64::NAN), |m| {
                (
                    rel_err(&m.effectiveness, &truth, 0),
                    rel_err(&m.effectiveness, &truth, 3),
                )
            });
            println!(
                "{w:>9} seed {seed}: quiet; rotation found after {t:.1} s ({why}); new model after {took:.1} s, {rot:.3} / {acc:.3}; {}; sea state before {sea_before:.1?}, then {sea:.1?} deg",
                run.machine.status().text
            );
        }
    }
}
