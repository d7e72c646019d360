//! A model that does not hold the vehicle (`machine.lost_hold_*`, `machine::hold_watch`), on
//! the simulator: the `aligned` vehicle (five thrusters along x, L a left-handed screw) has
//! its front thruster T turned 45 deg about z, and the operator's declaration of the new
//! geometry names L as remounted and declares it right-handed by mistake. The nominal model of
//! that declaration pushes L the wrong way and the carried-over prior has no column for it:
//! yaw runs away and the identification under control dithers on a tumbling vehicle.
//!
//! Without the watch (seeds 1-8, realistic IMU, 120 s): seed 2 held 69 deg off its setpoint
//! on the nominal model (0.99 off) for good, status "Active". With it: thrusters neutral, the
//! vehicle rights itself, an estimation from rest learns the vehicle as it is, and it is held
//! again.

use nalgebra::{Unit, UnitQuaternion, Vector3};
use thruster_sim::NoisePreset;
use thrusterd_core::adaptation::identification::IdentificationConfig;
use thrusterd_core::machine::{Event, MachineSetup, Reconfig, State, ThrusterChange};
use thrusterd_core::model::ModelSource;

mod common;
use common::{geometry, rel_err, vehicle, Run};

/// What the run did after the wrong announcement.
struct Outcome {
    /// Vehicle time of the first `HoldLost` event after the announcement, s.
    lost_at_s: Option<f64>,
    /// Largest angle to the setpoint over the last 10 s, deg.
    last_err_deg: f64,
    /// The state and the model's source at the end.
    state: State,
    source: ModelSource,
    err_rot: f64,
    err_acc: f64,
    /// `HoldLost` events in the whole run.
    lost_events: usize,
    /// Vehicle time of the first estimated model swapped in, s after the declaration.
    first_model_s: Option<f64>,
    /// The largest command sent since the harness's counter was last reset.
    max_cmd: f64,
}

fn wrongly_declared(seed: u64, lost_hold_s: f64, run_s: f64) -> Outcome {
    wrongly_declared_then(seed, lost_hold_s, run_s, |_| {})
}

/// [`wrongly_declared`] with the watch off and the fight's rule (`identification::fight`)
/// on or off (`min_dither_share` 0 turns it off), the hold before the dither `lead_in_s`.
fn wrongly_declared_unwatched(seed: u64, min_dither_share: f64, lead_in_s: f64) -> Outcome {
    wrongly_declared_set(seed, 0.0, 120.0, min_dither_share, lead_in_s, |_| {})
}

/// [`wrongly_declared`], calling `on_lost` with the run at the first `HoldLost` event.
fn wrongly_declared_then(
    seed: u64,
    lost_hold_s: f64,
    run_s: f64,
    on_lost: impl FnMut(&mut Run),
) -> Outcome {
    let d = IdentificationConfig::default();
    wrongly_declared_set(
        seed,
        lost_hold_s,
        run_s,
        d.min_dither_share,
        d.lead_in_s,
        on_lost,
    )
}

fn wrongly_declared_set(
    seed: u64,
    lost_hold_s: f64,
    run_s: f64,
    min_dither_share: f64,
    lead_in_s: f64,
    mut on_lost: impl FnMut(&mut Run),
) -> Outcome {
    let v = vehicle("aligned");
    let mut run = Run::new("aligned", NoisePreset::Realistic, seed);
    run.with_setup(|s: &mut MachineSetup| {
        // As found: with the first model fitted to the thrust's shape no seed of 1-5 loses
        // the hold (each is identified under control), and the watch is not exercised.
        common::bare_first_model(s);
        // As found, too: with the acceleration rows stopping at 0.07 seed 6 with the 1 s hold
        // is held within 1.7 deg, and the case the watch is for does not arise there.
        common::acc_target_as_found(s);
        s.machine.lost_hold_s = lost_hold_s;
        s.identification.min_dither_share = min_dither_share;
        s.identification.lead_in_s = lead_in_s;
    });
    run.run_for(1.0);
    run.estimate();
    run.run_for(3.0);
    assert_eq!(run.machine.state(), State::Active);
    let axis = [0.0, 0.0, 1.0];
    run.sim
        .apply(&thruster_sim::Action::Rotate {
            thruster: "T".into(),
            axis,
            angle_deg: 45.0,
        })
        .unwrap();
    let mut declared = geometry(&v);
    let r = UnitQuaternion::from_axis_angle(
        &Unit::new_normalize(Vector3::from(axis)),
        45f64.to_radians(),
    );
    declared.directions[0] = (r * Vector3::from(declared.directions[0])).into();
    // The mistake: L is a left-handed screw (`reversed` in the vehicle file), declared as
    // pushing along its direction.
    let l = v.thrusters.iter().position(|t| t.name == "L").unwrap();
    assert!(v.thrusters[l].reversed);
    declared.directions[l] = declared.directions[l].map(|d| -d);
    // What came before the declaration is not this test's.
    run.machine.take_events();
    run.machine.on_reconfig(Reconfig {
        count: v.thrusters.len(),
        geometry: Some(declared),
        change: ThrusterChange::Moved(l),
        what: "front thruster turned".into(),
    });
    let start = run.sim.time_s();
    let (mut lost_at_s, mut lost_events, mut last_err_deg) = (None, 0, 0.0f64);
    let mut first_model_s = None;
    let mut last_text = String::new();
    while run.sim.time_s() - start < run_s {
        run.tick();
        let st = run.machine.status().text;
        if std::env::var_os("LH_TRACE").is_some() && st != last_text {
            let q = run.sim.attitude();
            let down = q.inverse() * Vector3::z();
            println!(
                "  {:6.2} tilt {:5.1} {:?}: {}",
                run.sim.time_s() - start,
                down.z.clamp(-1.0, 1.0).acos().to_degrees(),
                run.machine.state(),
                st
            );
            last_text = st;
        }
        for e in run.machine.take_events() {
            match e {
                Event::HoldLost(why) => {
                    assert!(why.contains("does not hold it"), "{why}");
                    lost_events += 1;
                    if lost_at_s.is_none() {
                        lost_at_s = Some(run.sim.time_s() - start);
                        on_lost(&mut run);
                    }
                }
                Event::ModelSwapped(m) if m.source == ModelSource::Estimated => {
                    first_model_s.get_or_insert(run.sim.time_s() - start);
                }
                _ => {}
            }
        }
        if run.sim.time_s() - start > run_s - 10.0 {
            // The angle to level (the setpoint held after an estimation is level at the
            // heading it ends at; before the announcement, level at the start's heading).
            let q = run.sim.attitude();
            let down = q.inverse() * Vector3::z();
            let tilt = down.z.clamp(-1.0, 1.0).acos().to_degrees();
            last_err_deg = last_err_deg.max(tilt);
        }
    }
    let model = run.machine.model().unwrap().clone();
    let truth = run.truth();
    Outcome {
        lost_at_s,
        last_err_deg,
        state: run.machine.state(),
        source: model.source,
        err_rot: rel_err(&model.effectiveness, &truth, 0),
        err_acc: rel_err(&model.effectiveness, &truth, 3),
        lost_events,
        first_model_s,
        max_cmd: run.max_abs_cmd,
    }
}

/// Measured (realistic IMU, 120 s after the declaration, seeds 1-8): with the watch, every
/// seed held within 1.8 deg at the end on a model 0.004-0.006 / 0.008-0.016 off the truth,
/// seven of eight after losing the hold at 10.0 s (seeds 1-5: their first learned model
/// 21.2-22.7 s after the declaration); seed 4 identified under control in 6 s without losing
/// it. Without: seed 2 69 deg off on the nominal model for good; the others' identifications
/// under control recovered, with models up to 0.016 / 0.053 off. Since the hold before the
/// dither is 0.5 s (`identification.lead_in_s`, 2026-12-02), seeds 1-4 are identified under
/// control in 3.5-8.5 s without losing the hold (0.002-0.006 / 0.010-0.017 off, within 1.5
/// deg at the end) and seed 5 loses it at 10.0 s and is learned from rest at 22.2 s.
#[test]
fn a_wrongly_declared_thruster_is_caught_and_the_vehicle_learned_from_rest() {
    let mut lost = 0;
    for seed in 1..=5 {
        let o = wrongly_declared(seed, 10.0, 120.0);
        println!(
            "seed {seed}: lost at {:?} s ({} events), first model at {:?} s, end {:?} {:?}, \
             tilt over the last 10 s {:.1} deg, model {:.3} / {:.3}",
            o.lost_at_s,
            o.lost_events,
            o.first_model_s,
            o.state,
            o.source,
            o.last_err_deg,
            o.err_rot,
            o.err_acc
        );
        assert_eq!(o.state, State::Active, "seed {seed}");
        assert_eq!(o.source, ModelSource::Estimated, "seed {seed}");
        assert!(o.err_rot < 0.03 && o.err_acc < 0.05, "seed {seed}");
        assert!(
            o.last_err_deg < 5.0,
            "seed {seed}: {:.1} deg",
            o.last_err_deg
        );
        assert!(
            o.lost_events <= 1,
            "seed {seed}: lost {} times",
            o.lost_events
        );
        if o.lost_events == 1 {
            // Lost at 10 s, settled, estimated from rest.
            assert!(o.first_model_s.is_some_and(|t| t < 30.0), "seed {seed}");
        }
        lost += o.lost_events;
    }
    assert!(
        lost >= 1,
        "the hold was never lost: the watch is not exercised"
    );
    // Without the watch, and without the fight's rule (below): with the 1 s hold before the
    // dither of before 2026-12-02 (`lead_in_s = 1`), seed 6 is held 26 deg off (seed 2 69 deg
    // before 2026-12-03) on the nominal
    // model, for good. With the 0.5 s lead-in no seed of 1-10 is held far off: each is
    // identified under control and held (measured: seed 8 6.4 deg over the last 10 s, the
    // others within 1.5 deg).
    for seed in 1..=10 {
        let o = wrongly_declared_unwatched(seed, 0.0, IdentificationConfig::default().lead_in_s);
        assert!(
            o.last_err_deg < 10.0,
            "seed {seed}: {:.1} deg",
            o.last_err_deg
        );
    }
    // Seed 2 until 2026-12-03; since the open-loop fit's lags start at the first pulse (not
    // its first sample) the flights differ: of seeds 1-12, 1, 6, 7, 9 and 12 are held 26-45
    // deg off this way (before: 1, 2, 6, 7 and 9).
    let o = wrongly_declared_unwatched(6, 0.0, 1.0);
    println!(
        "off, 1 s hold, seed 6: end {:?} {:?}, tilt over the last 10 s {:.1} deg, model {:.3} / {:.3}",
        o.state, o.source, o.last_err_deg, o.err_rot, o.err_acc
    );
    assert_eq!(o.lost_events, 0);
    assert_eq!(o.state, State::Active);
    assert!(o.last_err_deg > 20.0, "{:.1} deg", o.last_err_deg);
    assert!(o.err_rot > 0.5, "{:.3}", o.err_rot);
    // The watch off, the fight's rule on (`identification::fight`, since 2026-12-02): the
    // identification's fit was the controller's fight twice, and the daemon let go and
    // learned the vehicle from rest on its own (measured: 1.3 deg over the last 10 s, 0.006 /
    // 0.009 off).
    // It is a backstop, not the watch: of those five it saves seeds 6 and 12, and seeds 1, 7
    // and 9 stay 27-45 deg off on the nominal model (before 2026-12-03 it saved 1, 2 and 6,
    // and not 7 and 9; docs/reliability.md).
    let o = wrongly_declared_unwatched(6, IdentificationConfig::default().min_dither_share, 1.0);
    println!(
        "fight's rule only, 1 s hold, seed 6: end {:?} {:?}, tilt over the last 10 s {:.1} deg, model \
         {:.3} / {:.3}",
        o.state, o.source, o.last_err_deg, o.err_rot, o.err_acc
    );
    assert_eq!(o.state, State::Active);
    assert_eq!(o.source, ModelSource::Estimated);
    assert!(o.last_err_deg < 5.0, "{:.1} deg", o.last_err_deg);
    assert!(
        o.err_rot < 0.03 && o.err_acc < 0.05,
        "{:.3} / {:.3}",
        o.err_rot,
        o.err_acc
    );
}

/// The operator aborts the estimation from rest the daemon waits to start after a lost hold:
/// the thrusters stay neutral, idle, until an estimate or hold request.
#[test]
fn an_abort_while_waiting_to_estimate_from_rest_keeps_the_thrusters_neutral() {
    let mut aborted = None;
    // Seed 5: the one whose hold is lost (the test above).
    let o = wrongly_declared_then(5, 10.0, 60.0, |run| {
        assert_eq!(run.machine.state(), State::Idle);
        assert!(run
            .machine
            .status()
            .text
            .starts_with("hold lost: thrusters neutral"));
        aborted = Some(
            run.machine
                .on_request(thrusterd_core::machine::Request::Abort),
        );
        run.max_abs_cmd = 0.0;
    });
    assert_eq!(aborted, Some(Ok("aborted".to_string())));
    assert_eq!(o.lost_events, 1);
    assert_eq!(o.state, State::Idle);
    assert_eq!(o.source, ModelSource::Nominal);
    assert!(o.first_model_s.is_none(), "{:?}", o.first_model_s);
    assert_eq!(o.max_cmd, 0.0, "thrust after the abort");
}
