/// Last line of defence before commands reach the thrusters: replaces every non-finite
/// value with 0 (stop that thruster rather than guess) and clamps the rest to [-1, 1].
/// Returns how many entries were changed, so callers can count and report it; a
/// correct controller never needs it.
pub fn sanitize_thrust(thrust: &mut [f64]) -> usize {
    let mut changed = 0;
    for t in thrust.iter_mut() {
        let fixed = if t.is_finite() {
            t.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        // Compare bits so that -0.0 stays untouched and NaN always counts as changed.
        if fixed.to_bits() != t.to_bits() {
            *t = fixed;
            changed += 1;
        }
    }
    changed
}
