//! Measured thruster tables: bollard thrust and current draw against the ESC's PWM input at
//! several supply voltages, interpolated linearly in both, and the inverse (the command that
//! gives a thrust at a voltage).
//!
//! The one table shipped is the Blue Robotics T200's (`data/t200.csv`, source and licence in
//! its header): the simulator's `model = "t200"` thrusters take their thrust and current from
//! it, and the daemon refers its commands to a reference voltage with it, so both sides read
//! the same numbers. No IO: the data is compiled in and parsed from text.
//!
//! Commands are normalised: `u` in [-1, 1] is the PWM pulse `1500 + 400 u` us (the ESC's
//! 1100-1900 us), with no deadband jump: the ESC's own dead zone (about +-25 us, wider at low
//! voltage) is in the data, as is the forward/reverse asymmetry.

use std::sync::OnceLock;

/// Neutral PWM pulse, us.
pub const PWM_NEUTRAL_US: f64 = 1500.0;
/// PWM pulse change for a full command, us (1100-1900 us).
pub const PWM_HALF_RANGE_US: f64 = 400.0;
/// Standard gravity, N per kgf (the data is in kgf).
pub const KGF_N: f64 = 9.80665;

/// The T200 table's CSV text (see its header for source and licence).
pub const T200_CSV: &str = include_str!("../data/t200.csv");

/// PWM pulse (us) for a normalised command; non-finite is neutral, beyond +-1 is clamped.
pub fn command_to_pwm(u: f64) -> f64 {
    let u = if u.is_finite() {
        u.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    PWM_NEUTRAL_US + PWM_HALF_RANGE_US * u
}

/// Normalised command for a PWM pulse (us), clamped to [-1, 1].
pub fn pwm_to_command(pwm_us: f64) -> f64 {
    ((pwm_us - PWM_NEUTRAL_US) / PWM_HALF_RANGE_US).clamp(-1.0, 1.0)
}

/// A table that cannot be used, with the place that says why.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// A line that is not `voltage_v,pwm_us,force_kgf,current_a` with finite numbers.
    #[error("{origin}:{line}: {message}")]
    Line {
        origin: String,
        line: usize,
        message: String,
    },
    /// The rows do not form a grid (every voltage on the same PWM points, both sorted, at
    /// least two of each, neutral among them).
    #[error("{origin}: {message}")]
    Shape { origin: String, message: String },
}

/// Thrust and current on a grid of voltages x PWM points.
#[derive(Debug, Clone, PartialEq)]
pub struct ThrusterTable {
    voltages: Vec<f64>,
    pwm_us: Vec<f64>,
    /// Thrust, N, `[voltage][pwm]`, signed (negative in reverse), as published.
    force_n: Vec<Vec<f64>>,
    current_a: Vec<Vec<f64>>,
    /// The thrust made monotone outward from neutral (running max forward, running min in
    /// reverse): the published data has a few 0.01 kgf steps backwards, and the inverse needs
    /// one answer. Only the inverse uses it.
    envelope_n: Vec<Vec<f64>>,
    /// Index of the neutral PWM point.
    neutral: usize,
}

/// Where `x` falls in sorted `grid`: the lower index and the weight of the upper one, clamped
/// to the grid's ends.
fn bracket(grid: &[f64], x: f64) -> (usize, f64) {
    let last = grid.len() - 1;
    if x.is_nan() || x <= grid[0] {
        return (0, 0.0);
    }
    if x >= grid[last] {
        return (last - 1, 1.0);
    }
    let hi = grid.partition_point(|g| *g <= x).min(last);
    let lo = hi - 1;
    (lo, (x - grid[lo]) / (grid[hi] - grid[lo]))
}

fn lerp(a: f64, b: f64, w: f64) -> f64 {
    a + (b - a) * w
}

impl ThrusterTable {
    /// The Blue Robotics T200 table, parsed once.
    pub fn t200() -> &'static ThrusterTable {
        static TABLE: OnceLock<ThrusterTable> = OnceLock::new();
        // The compiled-in text is checked by this crate's tests: it cannot fail at run time.
        TABLE.get_or_init(|| {
            ThrusterTable::parse_csv(T200_CSV, "thruster-table/data/t200.csv")
                .expect("the compiled-in T200 table parses")
        })
    }

    /// Parses `voltage_v,pwm_us,force_kgf,current_a` rows (a header line and `#` comments
    /// allowed); `origin` names the text in errors.
    pub fn parse_csv(text: &str, origin: &str) -> Result<ThrusterTable, TableError> {
        let mut rows: Vec<[f64; 4]> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') || line.starts_with("voltage_v") {
                continue;
            }
            let bad = |message: String| TableError::Line {
                origin: origin.to_string(),
                line: i + 1,
                message,
            };
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if fields.len() != 4 {
                return Err(bad(format!("expected 4 fields, got {}", fields.len())));
            }
            let mut row = [0.0; 4];
            for (slot, f) in row.iter_mut().zip(&fields) {
                *slot = f
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| bad(format!("{f:?} is not a finite number")))?;
            }
            rows.push(row);
        }
        let shape = |message: String| TableError::Shape {
            origin: origin.to_string(),
            message,
        };
        let mut voltages: Vec<f64> = Vec::new();
        let mut pwm_us: Vec<f64> = Vec::new();
        let mut force_n: Vec<Vec<f64>> = Vec::new();
        let mut current_a: Vec<Vec<f64>> = Vec::new();
        for [v, pwm, kgf, amps] in rows {
            if voltages.last() != Some(&v) {
                if voltages.last().is_some_and(|last| *last >= v) {
                    return Err(shape(format!("voltages must increase, {v} V comes late")));
                }
                voltages.push(v);
                force_n.push(Vec::new());
                current_a.push(Vec::new());
            }
            let k = force_n.last().map_or(0, Vec::len);
            if voltages.len() == 1 {
                if pwm_us.last().is_some_and(|last| *last >= pwm) {
                    return Err(shape(format!("PWM must increase, {pwm} us comes late")));
                }
                pwm_us.push(pwm);
            } else if pwm_us.get(k) != Some(&pwm) {
                return Err(shape(format!(
                    "{v} V: PWM point {k} is {pwm} us, the first voltage's is {:?}",
                    pwm_us.get(k)
                )));
            }
            if amps < 0.0 {
                return Err(shape(format!("{v} V, {pwm} us: negative current {amps}")));
            }
            force_n.last_mut().expect("pushed").push(kgf * KGF_N);
            current_a.last_mut().expect("pushed").push(amps);
        }
        if voltages.len() < 2 || pwm_us.len() < 3 {
            return Err(shape("needs at least 2 voltages and 3 PWM points".into()));
        }
        if let Some((v, f)) = voltages
            .iter()
            .zip(&force_n)
            .find(|(_, f)| f.len() != pwm_us.len())
        {
            return Err(shape(format!(
                "{v} V has {} PWM points, the first voltage {}",
                f.len(),
                pwm_us.len()
            )));
        }
        let neutral = pwm_us
            .iter()
            .position(|p| *p == PWM_NEUTRAL_US)
            .ok_or_else(|| shape(format!("no row at the neutral {PWM_NEUTRAL_US} us")))?;
        let envelope_n = force_n
            .iter()
            .map(|f| {
                let mut e = f.clone();
                e[neutral] = 0.0;
                for k in neutral + 1..e.len() {
                    e[k] = e[k].max(e[k - 1]);
                }
                for k in (0..neutral).rev() {
                    e[k] = e[k].min(e[k + 1]);
                }
                e
            })
            .collect();
        Ok(ThrusterTable {
            voltages,
            pwm_us,
            force_n,
            current_a,
            envelope_n,
            neutral,
        })
    }

    /// The voltages measured, V, ascending.
    pub fn voltages(&self) -> &[f64] {
        &self.voltages
    }

    /// Lowest and highest voltage measured, V: outside them the nearest one is used.
    pub fn voltage_range(&self) -> (f64, f64) {
        (self.voltages[0], self.voltages[self.voltages.len() - 1])
    }

    /// The PWM points, us, ascending.
    pub fn pwm_points(&self) -> &[f64] {
        &self.pwm_us
    }

    fn at(&self, grid: &[Vec<f64>], voltage_v: f64, pwm_us: f64) -> f64 {
        let (i, wv) = bracket(&self.voltages, voltage_v);
        let (k, wp) = bracket(&self.pwm_us, pwm_us);
        let row = |r: &Vec<f64>| lerp(r[k], r[k + 1], wp);
        lerp(row(&grid[i]), row(&grid[i + 1]), wv)
    }

    /// Thrust, N (negative in reverse), at `voltage_v` and `pwm_us`, bilinear; non-finite
    /// inputs are taken as the lowest voltage and neutral.
    pub fn force_n(&self, voltage_v: f64, pwm_us: f64) -> f64 {
        let pwm = if pwm_us.is_finite() {
            pwm_us
        } else {
            PWM_NEUTRAL_US
        };
        self.at(&self.force_n, voltage_v, pwm)
    }

    /// Current drawn, A, at `voltage_v` and `pwm_us`, bilinear.
    pub fn current_a(&self, voltage_v: f64, pwm_us: f64) -> f64 {
        let pwm = if pwm_us.is_finite() {
            pwm_us
        } else {
            PWM_NEUTRAL_US
        };
        self.at(&self.current_a, voltage_v, pwm)
    }

    /// Thrust, N, for normalised command `u` at `voltage_v`.
    pub fn thrust_at_command(&self, voltage_v: f64, u: f64) -> f64 {
        self.force_n(voltage_v, command_to_pwm(u))
    }

    /// Current, A, for normalised command `u` at `voltage_v`.
    pub fn current_at_command(&self, voltage_v: f64, u: f64) -> f64 {
        self.current_a(voltage_v, command_to_pwm(u))
    }

    /// The normalised command, in [-1, 1], whose thrust at `voltage_v` is `thrust_n` (on the
    /// monotone envelope of the data; beyond what the thruster can give at that voltage, +-1).
    /// Zero thrust is the neutral command.
    pub fn command_for_thrust(&self, voltage_v: f64, thrust_n: f64) -> f64 {
        if !thrust_n.is_finite() || thrust_n == 0.0 {
            return 0.0;
        }
        let (i, wv) = bracket(&self.voltages, voltage_v);
        let env = |k: usize| lerp(self.envelope_n[i][k], self.envelope_n[i + 1][k], wv);
        let last = self.pwm_us.len() - 1;
        // Outward from neutral the envelope is monotone: binary search for the first point
        // that reaches the thrust (`p` steps out from neutral; no allocation, the daemon calls
        // this in its control loop).
        let forward = thrust_n > 0.0;
        let steps = if forward {
            last - self.neutral
        } else {
            self.neutral
        };
        let index = |p: usize| {
            if forward {
                self.neutral + p
            } else {
                self.neutral - p
            }
        };
        let reached = |p: usize| {
            let f = env(index(p));
            if forward {
                f >= thrust_n
            } else {
                f <= thrust_n
            }
        };
        let (mut lo, mut hi) = (0, steps + 1);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if reached(mid) {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        if lo > steps {
            return if forward { 1.0 } else { -1.0 };
        }
        if lo == 0 {
            return 0.0;
        }
        let (inner, k) = (index(lo - 1), index(lo));
        let (f0, f1) = (env(inner), env(k));
        let w = if f1 != f0 {
            (thrust_n - f0) / (f1 - f0)
        } else {
            1.0
        };
        pwm_to_command(lerp(self.pwm_us[inner], self.pwm_us[k], w.clamp(0.0, 1.0)))
    }

    /// The command that gives at `to_v` the thrust command `u` gives at `from_v` (saturating
    /// at +-1 when `to_v` cannot reach it): how a command learned at one supply voltage is
    /// carried to another.
    pub fn refer_command(&self, u: f64, from_v: f64, to_v: f64) -> f64 {
        self.command_for_thrust(to_v, self.thrust_at_command(from_v, u))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kgf(v: f64, pwm: f64) -> f64 {
        ThrusterTable::t200().force_n(v, pwm) / KGF_N
    }

    #[test]
    fn the_t200_table_is_a_full_grid() {
        let t = ThrusterTable::t200();
        assert_eq!(t.voltages(), &[10.0, 12.0, 14.0, 16.0, 18.0, 20.0]);
        assert_eq!(t.pwm_points().len(), 201);
        assert_eq!(t.pwm_points()[0], 1100.0);
        assert_eq!(t.pwm_points()[200], 1900.0);
    }

    #[test]
    fn reproduces_published_points() {
        // Spreadsheet values (Force (Kg f), Current (A)) at grid points.
        let points = [
            (16.0, 1900.0, 5.24504, 23.83),
            (16.0, 1100.0, -4.06948, 24.2983),
            (16.0, 1700.0, 1.82344, 4.58),
            (12.0, 1900.0, 3.71416, 16.9117),
            (10.0, 1900.0, 2.92567, 13.6),
            (20.0, 1100.0, -5.03563, 32.1733),
        ];
        let t = ThrusterTable::t200();
        for (v, pwm, f, a) in points {
            assert!(
                (kgf(v, pwm) - f).abs() < 1e-4,
                "{v} V {pwm} us: {}",
                kgf(v, pwm)
            );
            assert!((t.current_a(v, pwm) - a).abs() < 1e-3, "{v} V {pwm} us");
        }
        // Dead zone as published: nothing at 1500 us nor at 1528 us at 16 V, thrust at 1532.
        assert_eq!(kgf(16.0, 1500.0), 0.0);
        assert_eq!(kgf(16.0, 1528.0), 0.0);
        assert!(kgf(16.0, 1532.0) > 0.03);
    }

    #[test]
    fn interpolates_linearly_between_points() {
        // Halfway between 1896 and 1900 us at 16 V, and halfway between 12 and 14 V.
        let mid = kgf(16.0, 1898.0);
        assert!((mid - 0.5 * (kgf(16.0, 1896.0) + kgf(16.0, 1900.0))).abs() < 1e-12);
        let v13 = kgf(13.0, 1900.0);
        assert!((v13 - 0.5 * (kgf(12.0, 1900.0) + kgf(14.0, 1900.0))).abs() < 1e-12);
        // Outside the measured voltages the nearest one holds.
        assert_eq!(kgf(9.0, 1900.0), kgf(10.0, 1900.0));
        assert_eq!(kgf(25.0, 1900.0), kgf(20.0, 1900.0));
    }

    #[test]
    fn thrust_ratio_16_to_12_volts_is_about_1_4() {
        let t = ThrusterTable::t200();
        let fwd = t.thrust_at_command(16.0, 1.0) / t.thrust_at_command(12.0, 1.0);
        let rev = t.thrust_at_command(16.0, -1.0) / t.thrust_at_command(12.0, -1.0);
        assert!((fwd - 5.24504 / 3.71416).abs() < 1e-6, "{fwd}");
        assert!((1.35..1.45).contains(&rev), "{rev}");
    }

    #[test]
    fn the_inverse_finds_the_command_back() {
        let t = ThrusterTable::t200();
        for v in [10.0, 13.3, 16.0, 19.0] {
            for u in [-0.9, -0.5, -0.2, 0.2, 0.5, 0.9] {
                let f = t.thrust_at_command(v, u);
                let back = t.command_for_thrust(v, f);
                assert!(
                    (t.thrust_at_command(v, back) - f).abs() < 0.02 * f.abs(),
                    "{v} V u {u}: {back}"
                );
            }
        }
        assert_eq!(t.command_for_thrust(16.0, 0.0), 0.0);
        assert_eq!(t.command_for_thrust(12.0, 60.0), 1.0);
        assert_eq!(t.command_for_thrust(12.0, -60.0), -1.0);
        // Referred from 16 V to 12 V a half command needs more.
        let up = t.refer_command(0.5, 16.0, 12.0);
        assert!(up > 0.55 && up < 1.0, "{up}");
        assert!(
            (t.thrust_at_command(12.0, up) - t.thrust_at_command(16.0, 0.5)).abs() < 0.1,
            "thrust matched"
        );
    }

    #[test]
    fn bad_text_names_the_line() {
        let err = ThrusterTable::parse_csv(
            "voltage_v,pwm_us,force_kgf,current_a\n10,1500,x,0\n",
            "t.csv",
        )
        .unwrap_err()
        .to_string();
        assert!(err.starts_with("t.csv:2:"), "{err}");
        let err = ThrusterTable::parse_csv(
            "10,1400,-1,1\n10,1500,0,0\n10,1600,1,1\n12,1400,-1,1\n12,1500,0,0\n",
            "t.csv",
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("12 V has 2 PWM points"), "{err}");
    }
}
