//! The six rigid-body degrees of freedom, in the order every model matrix uses.

use serde::{Deserialize, Serialize};

/// Degrees of freedom in model row order: rotations first (body x, y, z), then translations.
///
/// Rows 0-2 of an effectiveness matrix are angular accelerations (rad/s^2), rows 3-5 linear
/// accelerations (m/s^2), per unit thruster command. Body frame: x forward, y starboard, z down.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dof {
    Roll,
    Pitch,
    Yaw,
    Surge,
    Sway,
    Heave,
}

impl Dof {
    pub const ALL: [Dof; 6] = [
        Dof::Roll,
        Dof::Pitch,
        Dof::Yaw,
        Dof::Surge,
        Dof::Sway,
        Dof::Heave,
    ];

    /// Row index in a 6 x N effectiveness matrix.
    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            Dof::Roll => "roll",
            Dof::Pitch => "pitch",
            Dof::Yaw => "yaw",
            Dof::Surge => "surge",
            Dof::Sway => "sway",
            Dof::Heave => "heave",
        }
    }
}

/// Which of the six DOFs a thruster configuration can drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
pub struct DofMask(pub [bool; 6]);

impl DofMask {
    pub const NONE: DofMask = DofMask([false; 6]);
    pub const ALL: DofMask = DofMask([true; 6]);

    pub fn contains(self, dof: Dof) -> bool {
        self.0[dof.index()]
    }

    /// Bit i set when DOF i is actuated (the wire format of the model message).
    pub fn bits(self) -> u8 {
        self.0
            .iter()
            .enumerate()
            .fold(0u8, |acc, (i, &on)| if on { acc | (1 << i) } else { acc })
    }

    pub fn from_bits(bits: u8) -> DofMask {
        let mut m = [false; 6];
        for (i, slot) in m.iter_mut().enumerate() {
            *slot = bits & (1 << i) != 0;
        }
        DofMask(m)
    }

    pub fn count(self) -> usize {
        self.0.iter().filter(|&&b| b).count()
    }

    pub fn names(self) -> Vec<&'static str> {
        Dof::ALL
            .iter()
            .filter(|d| self.contains(**d))
            .map(|d| d.name())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_bits_round_trip() {
        let m = DofMask([true, false, true, true, false, false]);
        assert_eq!(m.bits(), 0b001101);
        assert_eq!(DofMask::from_bits(m.bits()), m);
        assert_eq!(m.names(), vec!["roll", "yaw", "surge"]);
        assert_eq!(m.count(), 3);
    }
}
