//! Issue 32 item 4, open loop in moving water: the learned lag is where a swell hurts the
//! model. With the lag given, the worst models of AMOUR-5's moderate-water runs were 0.04-0.05
//! off; learned, 0.14-0.17 off under bounds of 0.04-0.05, the lag 5-12 % off with a
//! standard deviation of 0.5-1 % (docs/study.md, "The lag in a swell"). The rotation rows
//! alone and the acceleration rows alone then put the lag many deviations apart
//! (`estimator::dynamic::lag_agreement`), and where that gap would move B past 1.5 times its
//! bound the machine refuses the model (`machine.max_lag_gap_over_bound`). Each case is
//! asserted with the check off as well: the same flight swaps in the confident wrong model.

use thruster_inprocess::estimation::{bare_dynamic, estimate_ideal, Ideal, Outcome};
use thruster_inprocess::swell_phase;
use thruster_sim::disturbance::WaterPreset;
use thruster_sim::{NoisePreset, SensorConfig};
use thrusterd_core::estimator::EstimatorConfig;

/// AMOUR-5 asked for a model 3 s after the moderate preset's water (every wave times
/// `wave_scale`) came up at the swell phase of `seed`, the check at `gap_limit` (None: the
/// shipped 1.5).
fn flight(noise: NoisePreset, seed: u64, wave_scale: f64, gap_limit: Option<f64>) -> Outcome {
    // As these swells were found: a model fitted to the thrust's shape flies them differently
    // (below), and since 2026-12-05 the fit in moving water is made again with the swell's
    // states (`estimator.moving_water_swell_hz`, `the_default_fits_the_swell_as_states`).
    let found = EstimatorConfig {
        moving_water_swell_hz: 0.0,
        ..bare_dynamic()
    };
    flight_with(noise, seed, wave_scale, gap_limit, found)
}

fn flight_with(
    noise: NoisePreset,
    seed: u64,
    wave_scale: f64,
    gap_limit: Option<f64>,
    estimator: EstimatorConfig,
) -> Outcome {
    let sensors = SensorConfig {
        rate_hz: 200.0,
        noise,
        lever_arm_m: [0.0; 3],
        ..SensorConfig::default()
    };
    let ideal = Ideal {
        allow_refusal: true,
        water: WaterPreset::Moderate,
        idle_s: Some(3.0),
        wave_scale: Some(wave_scale),
        wave_phase_rad: Some(swell_phase::of_seed(seed)),
        max_lag_gap_over_bound: gap_limit,
        // With the lag's check off, the tilt rule too (`machine.max_moving_water_tilt_deg`):
        // at a realistic IMU the navigation put seed 5's flight at 118 deg (30 true), and that
        // rule refuses it as well (`thrown_by_the_water.rs`).
        max_moving_water_tilt_deg: (gap_limit == Some(0.0)).then_some(0.0),
        ..Ideal::default()
    };
    estimate_ideal("amour5", sensors, seed, estimator, ideal)
}

/// The largest error over its own bound, of the two row groups.
fn coverage(o: &Outcome) -> f64 {
    (o.err_rot / o.bound[0]).max(o.err_acc / o.bound[1])
}

/// The flight swaps in a model over twice its bound with the check off, and with the
/// shipped check the machine refuses it naming the lag; the refused estimate's groups.
fn refused_only_with_the_check(
    noise: NoisePreset,
    seed: u64,
    wave_scale: f64,
) -> thrusterd_core::estimator::dynamic::lag_agreement::LagAgreement {
    let off = flight(noise, seed, wave_scale, Some(0.0));
    assert!(
        !off.refused && coverage(&off) > 2.0,
        "check off: refused {}, err {:.4} / {:.4} under {:?}",
        off.refused,
        off.err_rot,
        off.err_acc,
        off.bound
    );
    let on = flight(noise, seed, wave_scale, None);
    let why = on.rejection.as_deref().unwrap_or("");
    assert!(on.refused && why.contains("lag"), "check on: {why:?}");
    on.terms.spin_up_groups.expect("the groups judged")
}

/// Noise-free first: a third of the preset's swell at seed 3's phase. Measured: with the
/// check off, 0.170 / 0.112 off under 0.054 / 0.053 (3.1x), the lag 0.1069 s for 0.1; the
/// groups 6-11 sd apart.
///
/// As shipped (the fit to the thrust's shape on by default since 2026-12-03?) the same swell
/// gives no confident wrong model: it is refused, or covered by its bound (measured with the
/// shape and the check off: 0.0215 / 0.0233 under 0.0217 / 0.0217).
#[test]
fn noise_free_a_swell_that_pulls_the_lag_apart_is_refused() {
    let groups = refused_only_with_the_check(NoisePreset::None, 3, 0.3);
    assert!(groups.z > 3.0, "{groups:?}");
    let shipped = flight_with(NoisePreset::None, 3, 0.3, None, EstimatorConfig::dynamic());
    println!(
        "shipped: refused {}, {:.4} / {:.4} under {:?}",
        shipped.refused, shipped.err_rot, shipped.err_acc, shipped.bound
    );
    assert!(
        shipped.refused || coverage(&shipped) <= 1.5,
        "shipped: {:.4} / {:.4} under {:?}",
        shipped.err_rot,
        shipped.err_acc,
        shipped.bound
    );
}

/// The realistic IMU in the preset's swell at seed 5's phase: measured 0.140 / 0.131 off
/// under 0.045 / 0.056 (3.1x) with the check off, the lag 0.0883 s; the groups 7 sd and 11 %
/// apart.
#[test]
fn at_a_realistic_imu_the_presets_swell_that_pulls_the_lag_apart_is_refused() {
    refused_only_with_the_check(NoisePreset::Realistic, 5, 1.0);
}

/// Where the groups agree the check lets the model in: the same swell at seed 9's phase,
/// 0.054 / 0.054 off under 0.037 / 0.029 (1.9x; a hole the check does not close: the groups
/// 1 sd apart), and in still water the check never runs (every other test of the estimator).
#[test]
fn a_model_whose_row_groups_agree_on_the_lag_is_not_refused_by_the_check() {
    let o = flight(NoisePreset::Realistic, 9, 1.0, None);
    let groups = o.terms.spin_up_groups.expect("the groups judged");
    assert!(!o.refused && groups.z < 3.0, "{:?} {groups:?}", o.rejection);
}

/// The three swells above as shipped (the thrust's shape, and the fit made again with the
/// swell's states in moving water, `estimator.moving_water_swell_hz`; the check on): none
/// gives a confident wrong model. Measured: noise-free seed 3 at 0.3x, 0.0105 / 0.0203 under
/// 0.0225 / 0.0217 but refused, its fit without states' groups 3.2x apart (a cautious
/// refusal); seed 5, 0.133 / 0.121 under 0.053 / 0.056 (2.5x): its groups agree with the
/// states, and only the fit without them (2.6x) refuses it (`lag_gap_without_states`);
/// seed 9, refused (2.4x), 0.016 / 0.030 under 0.046 / 0.029.
#[test]
fn the_default_fits_the_swell_as_states() {
    for (noise, seed, scale) in [
        (NoisePreset::None, 3, 0.3),
        (NoisePreset::Realistic, 5, 1.0),
        (NoisePreset::Realistic, 9, 1.0),
    ] {
        let o = flight_with(noise, seed, scale, None, EstimatorConfig::dynamic());
        println!(
            "{noise:?} seed {seed} x{scale}: refused {} ({:?}), {:.4} / {:.4} under {:.4} / {:.4} ({:.2}x)",
            o.refused,
            o.rejection,
            o.err_rot,
            o.err_acc,
            o.bound[0],
            o.bound[1],
            coverage(&o)
        );
        assert!(
            o.refused || coverage(&o) <= 1.5,
            "seed {seed}: confident and wrong"
        );
        if seed == 5 {
            let why = o.rejection.as_deref().unwrap_or("");
            assert!(why.contains("without swell states"), "seed 5: {why:?}");
        }
    }
}
