//! Disturbance states held to their claim (issue 32 item 3): a swell's forcing as states in
//! the dynamic fit (the research hook `EstimatorConfig::disturbance`, and the default refit
//! in moving water, `moving_water_swell_hz`) takes what the swell put in the rotation rows
//! (docs/study.md, "Disturbance states: the swell's part decided"). The sweep's knobs are
//! LA_DIST_HZ, LA_DIST_WORLD, LA_DIST_CONST and LA_DIST_RAMP (`imu_and_water_sweep`).

#[cfg(test)]
mod tests {
    use thruster_inprocess::estimation::{estimate_ideal, Ideal};
    use thruster_sim::disturbance::WaterPreset;
    use thruster_sim::{NoisePreset, SensorConfig};
    use thrusterd_core::estimator::dynamic::disturbance_states::DisturbanceStates;
    use thrusterd_core::estimator::EstimatorConfig;

    /// Noise-free, AMOUR-5, the lag given, the moderate preset's swell moment alone at half
    /// its size (seed 1's phase): without states the swell's moment goes into the rotation
    /// rows (measured 0.027 off); with the swell's states in the fit throughout (the hook)
    /// they are as in still water (0.002), and the default, which fits again with them only
    /// where the water moves (`moving_water_swell_hz`), gives the same model; in still water
    /// the default is the fit without states to the bit, and states throughout cost nothing
    /// there noise-free either (0.0004 / 0.0005).
    #[test]
    fn swell_states_take_the_swells_moment_out_of_the_rotation_rows() {
        let sensors = SensorConfig {
            rate_hz: 200.0,
            noise: NoisePreset::None,
            ..SensorConfig::default()
        };
        let flight = |cfg: EstimatorConfig, water: WaterPreset| {
            let cfg = EstimatorConfig {
                learn_spin_up: false,
                ..cfg
            };
            let ideal = Ideal {
                allow_refusal: true,
                water,
                no_current: true,
                wave_part: Some("torque"),
                wave_scale: Some(0.5),
                wave_phase_rad: Some(thruster_inprocess::swell_phase::of_seed(1)),
                idle_s: Some(3.0),
                ..Ideal::default()
            };
            estimate_ideal("amour5", sensors.clone(), 1, cfg, ideal)
        };
        let off = EstimatorConfig {
            moving_water_swell_hz: 0.0,
            ..EstimatorConfig::dynamic()
        };
        let throughout = EstimatorConfig {
            disturbance: DisturbanceStates {
                swell_hz: Some(0.15),
                ..DisturbanceStates::default()
            },
            ..off.clone()
        };
        let default = EstimatorConfig::dynamic();
        assert_eq!(default.moving_water_swell_hz, 0.15);
        let free = flight(off.clone(), WaterPreset::Moderate);
        let held = flight(throughout.clone(), WaterPreset::Moderate);
        let gated = flight(default.clone(), WaterPreset::Moderate);
        let still = flight(throughout, WaterPreset::Still);
        let still_off = flight(off, WaterPreset::Still);
        let still_default = flight(default, WaterPreset::Still);
        eprintln!(
            "free {:.4} / {:.4}, states {:.4} / {:.4}, default {:.4} / {:.4}, still water with \
             states {:.4} / {:.4}",
            free.err_rot,
            free.err_acc,
            held.err_rot,
            held.err_acc,
            gated.err_rot,
            gated.err_acc,
            still.err_rot,
            still.err_acc
        );
        assert!(!free.refused && !held.refused && !gated.refused && !still.refused);
        assert!(
            free.err_rot > 0.015,
            "the swell made no error to take: {}",
            free.err_rot
        );
        assert!(
            held.err_rot < 0.005,
            "rotation rows {} with states",
            held.err_rot
        );
        assert!(
            held.err_acc < 0.01,
            "acceleration rows {} with states",
            held.err_acc
        );
        assert!(
            (gated.err_rot - held.err_rot).abs() < 1e-6
                && (gated.err_acc - held.err_acc).abs() < 1e-6,
            "the refit in moving water {} / {} is not the fit with states {} / {}",
            gated.err_rot,
            gated.err_acc,
            held.err_rot,
            held.err_acc
        );
        assert!(
            still.err_rot < 0.002 && still.err_acc < 0.002,
            "still water with states {} / {}",
            still.err_rot,
            still.err_acc
        );
        assert_eq!(
            (still_default.err_rot, still_default.err_acc),
            (still_off.err_rot, still_off.err_acc),
            "still water refitted"
        );
    }
}
