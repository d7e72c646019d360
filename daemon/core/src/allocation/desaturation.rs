//! Sequential desaturation: rotation keeps priority over translation.

/// Scale factors (rotation, translation) in [0, 1] so that every |s_rot u_rot + s_lin u_lin|
/// <= 1: translation gives way first; rotation is scaled only if it alone saturates.
pub fn desaturate(u_rot: &[f64], u_lin: &[f64]) -> (f64, f64) {
    let peak = |u: &[f64]| u.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let rot_peak = peak(u_rot);
    let s_rot = if rot_peak > 1.0 { 1.0 / rot_peak } else { 1.0 };
    // Largest s_lin in [0, 1] with |s_rot r_i + s_lin l_i| <= 1 for every thruster.
    let mut s_lin: f64 = 1.0;
    for (r, l) in u_rot.iter().zip(u_lin) {
        let r = s_rot * r;
        if *l > 0.0 {
            s_lin = s_lin.min(((1.0 - r) / l).max(0.0));
        } else if *l < 0.0 {
            s_lin = s_lin.min(((-1.0 - r) / l).max(0.0));
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
}
