//! Depth from an IIO pressure sensor's absolute pressure, and what a wrong driver formula
//! looks like.
//!
//! The Blue Robotics Bar30 is an MS5837-30BA. Mainline Linux has no driver for that part:
//! `ms5637` binds "ms5837" and computes every part with the 2-bar formula
//! (`ms_sensors_read_temp_and_pressure`): OFF = C2 2^17 plus C4 dT 2^-6, SENS = C1 2^16 plus
//! C3 dT 2^-7, P = (D1 SENS 2^-21 - OFF) 2^-15, in Pa. The 30BA's datasheet has OFF = C2 2^16
//! plus C4 dT 2^-7, SENS = C1 2^15 plus C3 dT 2^-8, P = (D1 SENS 2^-21 - OFF) 2^-13, in
//! 0.1 mbar. Both OFF and SENS are exactly twice the 30BA's, so the driver's number is the
//! 30BA's raw value halved and read as Pa instead of 10 Pa: **1/20 of the pressure** (5.07 kPa
//! at the surface). `pressure_formula = "bar30_read_as_02ba"` multiplies by 20. What stays is
//! the two parts' different second-order temperature terms: under 20 C a constant offset of a
//! few cm (the unit test `the_bar30_under_the_2_bar_formula_is_20_times_short` computes it
//! with both formulas, bit for bit, on the datasheet's example calibration).
//!
//! Whatever the formula, no vehicle's water is at less than [`MIN_WATER_KPA`]: a pressure
//! below it is not used, and the warning names the likely cause.

use crate::config::PressureFormula;

/// Standard gravity, m/s^2, for pressure -> depth.
pub const G: f64 = 9.80665;

/// The lowest absolute pressure a vehicle's water can have, kPa: the air at 6000 m, higher
/// than any lake a vehicle dives in, is 47 kPa; a Bar30 read with the 2-bar formula gives
/// 5 kPa at the surface and stays under this to 60 m.
pub const MIN_WATER_KPA: f64 = 30.0;

/// Why a pressure is not used for depth.
pub fn implausible(kpa: f64, formula: PressureFormula) -> Option<String> {
    if kpa.is_finite() && kpa >= MIN_WATER_KPA {
        return None;
    }
    let hint = match formula {
        PressureFormula::AsReported => {
            "; a Bar30 (MS5837-30BA) under the mainline ms5637 driver (bound as \"ms5837\") \
             reads 1/20 of its pressure: set pressure_formula = \"bar30_read_as_02ba\""
        }
        PressureFormula::Bar30ReadAs02ba => "",
    };
    Some(format!(
        "absolute pressure {kpa:.3} kPa is below {MIN_WATER_KPA} kPa, thinner than any \
         water's surface{hint}"
    ))
}

/// The pressure the sensor measured, kPa, from what its driver reported.
pub fn corrected_kpa(reported_kpa: f64, formula: PressureFormula) -> f64 {
    match formula {
        PressureFormula::AsReported => reported_kpa,
        PressureFormula::Bar30ReadAs02ba => reported_kpa * 20.0,
    }
}

/// Depth below the surface, m, from absolute pressure (kPa).
pub fn depth_m(pressure_kpa: f64, surface_kpa: f64, density_kg_m3: f64) -> f64 {
    (pressure_kpa - surface_kpa) * 1000.0 / (density_kg_m3 * G)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_from_pressure() {
        // 10 m of fresh water.
        let p = 101.325 + 10.0 * 997.0 * G / 1000.0;
        assert!((depth_m(p, 101.325, 997.0) - 10.0).abs() < 1e-9);
        assert!(depth_m(101.325, 101.325, 997.0).abs() < 1e-12);
    }

    /// An MS5837's calibration (PROM C1..C6), the datasheet's example (MS5837-30BA, rev. A5).
    const PROM: [i64; 7] = [0, 34982, 36352, 20328, 22354, 26646, 26146];

    /// The mainline kernel's `ms_sensors_read_temp_and_pressure`, bit for bit: Pa.
    fn kernel_02ba_pa(d1: i64, d2: i64) -> i64 {
        let dt = d2 - (PROM[5] << 8);
        let temp = 2000 + ((dt * PROM[6]) >> 23);
        let (off2, sens2) = if temp < 2000 {
            let tmp = temp - 2000;
            let (mut o, mut s) = ((61 * tmp * tmp) >> 4, (29 * tmp * tmp) >> 4);
            if temp < -1500 {
                let tmp = temp + 1500;
                o += 17 * tmp * tmp;
                s += 9 * tmp * tmp;
            }
            (o, s)
        } else {
            (0, 0)
        };
        let off = (PROM[2] << 17) + ((PROM[4] * dt) >> 6) - off2;
        let sens = (PROM[1] << 16) + ((PROM[3] * dt) >> 7) - sens2;
        (((d1 * sens) >> 21) - off) >> 15
    }

    /// The MS5837-30BA datasheet's first and second order: Pa, and the temperature, C.
    fn datasheet_30ba_pa(d1: i64, d2: i64) -> (i64, f64) {
        let dt = d2 - (PROM[5] << 8);
        let temp = 2000 + ((dt * PROM[6]) >> 23);
        let (ti, offi, sensi) = if temp < 2000 {
            let tmp = temp - 2000;
            let (mut o, mut s) = (3 * tmp * tmp / 2, 5 * tmp * tmp / 8);
            if temp < -1500 {
                let tmp = temp + 1500;
                o += 7 * tmp * tmp;
                s += 4 * tmp * tmp;
            }
            ((3 * dt * dt) >> 33, o, s)
        } else {
            let tmp = temp - 2000;
            ((2 * dt * dt) >> 37, tmp * tmp / 16, 0)
        };
        let off = (PROM[2] << 16) + ((PROM[4] * dt) >> 7) - offi;
        let sens = (PROM[1] << 15) + ((PROM[3] * dt) >> 8) - sensi;
        let p_01mbar = (((d1 * sens) >> 21) - off) >> 13;
        (p_01mbar * 10, (temp - ti) as f64 / 100.0)
    }

    /// The D1 that makes the 30BA formula give `pa` at `d2` (bisection; monotone in D1).
    fn d1_for(pa: i64, d2: i64) -> i64 {
        let (mut lo, mut hi) = (0_i64, 1 << 24);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if datasheet_30ba_pa(mid, d2).0 < pa {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }

    #[test]
    fn the_bar30_under_the_2_bar_formula_is_20_times_short() {
        // The datasheet's worked example: 3999.8 mbar at 19.81 C.
        assert_eq!(datasheet_30ba_pa(4958179, 6815414), (399980, 19.81));
        // Over the water's temperatures (d2 from 0 to 35 C) and a dive's pressures, what the
        // kernel reports, corrected, against the 30BA's own formula.
        let mut worst_m: f64 = 0.0;
        let mut worst_warm_m: f64 = 0.0;
        for d2 in (6_600_000..=7_000_000).step_by(20_000) {
            for pa in [101_325, 150_000, 500_000, 1_000_000, 3_000_000] {
                let d1 = d1_for(pa, d2);
                let (truth_pa, temp_c) = datasheet_30ba_pa(d1, d2);
                if !(0.0..=35.0).contains(&temp_c) {
                    continue;
                }
                let reported_kpa = kernel_02ba_pa(d1, d2) as f64 / 1000.0;
                // About 1/20 as reported; the plausibility check catches it at the surface.
                if pa == 101_325 {
                    assert!((4.9..5.2).contains(&reported_kpa), "{reported_kpa}");
                    assert!(implausible(reported_kpa, PressureFormula::AsReported)
                        .unwrap()
                        .contains("bar30_read_as_02ba"));
                }
                let fixed = corrected_kpa(reported_kpa, PressureFormula::Bar30ReadAs02ba);
                let err_m = (fixed * 1000.0 - truth_pa as f64) / (997.0 * G);
                worst_m = worst_m.max(err_m.abs());
                if temp_c >= 15.0 {
                    worst_warm_m = worst_warm_m.max(err_m.abs());
                }
            }
        }
        // The second-order terms differ under 20 C: the corrected depth is off by a few
        // cm (docs/hardware.md), against 9.8 m uncorrected at the surface.
        assert!(worst_m < 0.06, "worst {worst_m} m over 0-35 C");
        assert!(worst_warm_m < 0.025, "worst {worst_warm_m} m over 15-35 C");
        eprintln!("corrected Bar30 depth error: {worst_m:.4} m over 0-35 C, {worst_warm_m:.4} m over 15-35 C");
        assert!(implausible(101.325, PressureFormula::AsReported).is_none());
        assert!(implausible(f64::NAN, PressureFormula::Bar30ReadAs02ba).is_some());
    }
}
