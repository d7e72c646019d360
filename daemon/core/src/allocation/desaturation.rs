//! Sequential desaturation: rotation keeps priority over translation.

/// Scale factors (rotation, translation) in [0, 1] so that every |s_rot u_rot + s_lin u_lin|
/// <= 1: translation gives way first; rotation is scaled only if it alone saturates.
pub fn desaturate(u_rot: &[f64], u_lin: &[f64]) -> (f64, f64) {
    desaturate_within(u_rot, u_lin, 1.0, 1.0)
}

/// The same within the asymmetric range [-`reverse`, `forward`] (both > 0): for commands in
/// thrust-shape units, where full forward command gives 1 + k and full reverse 1 - k
/// (`DynamicTerms::thrust_asymmetry`).
pub fn desaturate_within(u_rot: &[f64], u_lin: &[f64], reverse: f64, forward: f64) -> (f64, f64) {
    let room = |v: f64| {
        if v > 0.0 {
            forward / v
        } else if v < 0.0 {
            -reverse / v
        } else {
            f64::INFINITY
        }
    };
    let s_rot = u_rot.iter().fold(1.0_f64, |s, v| s.min(room(*v)));
    // Largest s_lin in [0, 1] with -reverse <= s_rot r_i + s_lin l_i <= forward for every
    // thruster.
    let mut s_lin: f64 = 1.0;
    for (r, l) in u_rot.iter().zip(u_lin) {
        let r = s_rot * r;
        if *l > 0.0 {
            s_lin = s_lin.min(((forward - r) / l).max(0.0));
        } else if *l < 0.0 {
            s_lin = s_lin.min(((-reverse - r) / l).max(0.0));
        }
    }
    (s_rot, s_lin)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn desaturate_scales_translation_first() {
        let (r, l) = desaturate(&[0.5, -0.5], &[1.0, 1.0]);
        assert_eq!(r, 1.0);
        assert!((l - 0.5).abs() < 1e-12);
        let (r, l) = desaturate(&[2.0, -2.0], &[0.1, 0.1]);
        assert!((r - 0.5).abs() < 1e-12);
        assert_eq!(l, 0.0);
    }

    #[test]
    fn desaturate_within_an_asymmetric_range_uses_each_side_s_room() {
        // Forward room 1.2, reverse 0.8: rotation alone at -1.6 is scaled to -0.8.
        let (r, l) = desaturate_within(&[1.0, -1.6], &[0.0, 0.0], 0.8, 1.2);
        assert!((r - 0.5).abs() < 1e-12 && l == 1.0);
        // Translation fills the forward room of thruster 0 up to 1.2.
        let (r, l) = desaturate_within(&[0.2, 0.0], &[2.0, 0.5], 0.8, 1.2);
        assert_eq!(r, 1.0);
        assert!((l - 0.5).abs() < 1e-12);
        // Symmetric range: the same as `desaturate`.
        assert_eq!(
            desaturate_within(&[0.5, -0.5], &[1.0, 1.0], 1.0, 1.0),
            desaturate(&[0.5, -0.5], &[1.0, 1.0])
        );
    }
}
