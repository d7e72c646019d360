//! Sensor axes to body axes (x forward, y starboard, z down) as a signed permutation.

use std::fmt;

/// Body axis `i` is `sign[i] * sensor[index[i]]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisMap {
    index: [usize; 3],
    sign: [f64; 3],
}

impl AxisMap {
    /// Sensor axes already FRD (ArduPilot reports body FRD).
    pub const IDENTITY: AxisMap = AxisMap {
        index: [0, 1, 2],
        sign: [1.0, 1.0, 1.0],
    };

    /// A chip mounted face up, x forward: its y points to port and z up (FLU), so body
    /// y = -sensor y and body z = -sensor z.
    pub const FLU_TO_FRD: AxisMap = AxisMap {
        index: [0, 1, 2],
        sign: [1.0, -1.0, -1.0],
    };

    /// Parses `["x", "-y", "-z"]`-style names (optional `+`); each sensor axis exactly once.
    pub fn parse(names: &[String; 3]) -> Result<AxisMap, String> {
        let mut index = [0; 3];
        let mut sign = [1.0; 3];
        let mut used = [false; 3];
        for (i, name) in names.iter().enumerate() {
            let n = name.trim();
            let (s, axis) = match n.strip_prefix('-') {
                Some(rest) => (-1.0, rest),
                None => (1.0, n.strip_prefix('+').unwrap_or(n)),
            };
            let k = match axis {
                "x" => 0,
                "y" => 1,
                "z" => 2,
                _ => {
                    return Err(format!(
                        "axis {name:?} is not x, y or z (with optional sign)"
                    ))
                }
            };
            if used[k] {
                return Err(format!("sensor axis {axis} is used twice in {names:?}"));
            }
            used[k] = true;
            index[i] = k;
            sign[i] = s;
        }
        Ok(AxisMap { index, sign })
    }

    /// The map as a matrix: row i has `sign[i]` in column `index[i]`.
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                if j == self.index[i] {
                    self.sign[i]
                } else {
                    0.0
                }
            })
        })
    }

    /// Body-frame vector from a sensor-frame vector.
    pub fn apply(&self, v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| self.sign[i] * v[self.index[i]])
    }
}

impl fmt::Display for AxisMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names = ["x", "y", "z"];
        let parts: Vec<String> = (0..3)
            .map(|i| {
                let s = if self.sign[i] < 0.0 { "-" } else { "" };
                format!("{s}{}", names[self.index[i]])
            })
            .collect();
        write!(f, "[{}]", parts.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(a: &str, b: &str, c: &str) -> [String; 3] {
        [a.to_string(), b.to_string(), c.to_string()]
    }

    #[test]
    fn face_up_chip_reads_minus_g_on_body_z_at_rest() {
        let m = AxisMap::parse(&names("x", "-y", "-z")).unwrap();
        assert_eq!(m, AxisMap::FLU_TO_FRD);
        // A face-up accelerometer at rest measures +g along its own z (up).
        assert_eq!(m.apply([0.0, 0.0, 9.81]), [0.0, -0.0, -9.81]);
        assert_eq!(m.to_string(), "[x, -y, -z]");
    }

    #[test]
    fn permutations_and_errors() {
        let m = AxisMap::parse(&names("+y", "x", "-z")).unwrap();
        assert_eq!(m.apply([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0]);
        assert!(AxisMap::parse(&names("x", "x", "z")).is_err());
        assert!(AxisMap::parse(&names("x", "y", "w")).is_err());
        assert_eq!(AxisMap::IDENTITY.apply([1.0, 2.0, 3.0]), [1.0, 2.0, 3.0]);
    }
}
