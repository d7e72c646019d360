//! Random thruster configurations from a seed, as in the paper's simulation study (which drew
//! 100 random configurations each for 2, 4, 6 and 8 thrusters).
//!
//! Unlike the paper, which drew the effectiveness matrix entries directly, this draws physical
//! geometry: positions uniform (by area) on the surface of a BlueROV2-sized box around the CO
//! and directions uniform on the sphere, so the effectiveness follows from the body model.

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::load::LoadError;
use crate::vehicle::{Body, ThrusterSpec, Vehicle};
use thruster_protocol::MAX_THRUSTERS;

/// Half extents of the hull box, m: a standard BlueROV2 is 0.457 x 0.338 x 0.254 m.
pub const HULL_HALF_EXTENTS_M: [f64; 3] = [0.2285, 0.169, 0.127];

/// A vehicle with the default (BlueROV2) body and `n` T200-class thrusters named `T0..`,
/// placed and oriented at random from `seed`. The same seed always gives the same vehicle.
pub fn random_vehicle(n: usize, seed: u64) -> Result<Vehicle, LoadError> {
    let origin = "random vehicle";
    if !(1..=MAX_THRUSTERS).contains(&n) {
        return Err(LoadError::invalid(
            origin,
            "n",
            format!("{n} thrusters: must be in [1, {MAX_THRUSTERS}]"),
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let thrusters = (0..n)
        .map(|i| {
            let position = point_on_box(&mut rng, &Vector3::from(HULL_HALF_EXTENTS_M));
            let direction = unit_vector(&mut rng);
            ThrusterSpec::new(format!("T{i}"), position.into(), direction.into())
        })
        .collect();
    let mut vehicle = Vehicle {
        name: format!("random-{n}-{seed}"),
        description: format!("{n} thrusters at random positions and directions, seed {seed}"),
        body: Body::default(),
        thrusters,
        battery: None,
    };
    vehicle.validate(origin)?;
    Ok(vehicle)
}

/// Uniform on the unit sphere (normalised Gaussian).
fn unit_vector(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            rng.sample::<f64, _>(StandardNormal),
            rng.sample::<f64, _>(StandardNormal),
            rng.sample::<f64, _>(StandardNormal),
        );
        let n = v.norm();
        // Reject the (practically impossible) near-zero draw rather than divide by it.
        if n > 1e-6 {
            return v / n;
        }
    }
}

/// Uniform by area on the surface of the box with half extents `h`.
fn point_on_box(rng: &mut ChaCha8Rng, h: &Vector3<f64>) -> Vector3<f64> {
    // Face pairs normal to x, y, z have areas proportional to h.y*h.z, h.x*h.z, h.x*h.y.
    let areas = [h.y * h.z, h.x * h.z, h.x * h.y];
    let total: f64 = areas.iter().sum();
    let mut pick = rng.random::<f64>() * total;
    let mut axis = 2;
    for (i, a) in areas.iter().enumerate() {
        if pick < *a {
            axis = i;
            break;
        }
        pick -= a;
    }
    let mut p = Vector3::zeros();
    for i in 0..3 {
        p[i] = if i == axis {
            if rng.random::<bool>() {
                h[i]
            } else {
                -h[i]
            }
        } else {
            rng.random_range(-h[i]..h[i])
        };
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_on_the_hull() {
        let a = random_vehicle(8, 42).expect("valid");
        let b = random_vehicle(8, 42).expect("valid");
        let c = random_vehicle(8, 43).expect("valid");
        assert_eq!(a, b);
        assert_ne!(a, c);
        for t in &a.thrusters {
            let d = Vector3::from(t.direction);
            assert!((d.norm() - 1.0).abs() < 1e-12);
            let on_face =
                (0..3).any(|i| (t.position_m[i].abs() - HULL_HALF_EXTENTS_M[i]).abs() < 1e-12);
            assert!(on_face, "{:?}", t.position_m);
        }
        assert!(random_vehicle(17, 0).is_err());
        assert!(random_vehicle(0, 0).is_err());
    }
}
