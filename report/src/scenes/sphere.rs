//! City lights on a planet: lights uniform over a sphere, seen by panels in
//! orbit whose tangent planes cut through the sphere, so that many nodes
//! straddle the plane (the `seams` example's horizon scanlines).

use glam::Vec3;
use manylights::PointLight;
use rand::RngExt;

use super::rng;

/// Radius of the sphere of lights, centred at the origin.
pub const SPHERE_RADIUS: f32 = 100.0;

/// `count` white lights uniform over the sphere of radius
/// [`SPHERE_RADIUS`] about the origin, intensities uniform in `[0.5, 1.5)`.
pub fn sphere_lights(count: usize, seed: u64) -> Vec<PointLight> {
    let mut rng = rng(seed);
    (0..count)
        .map(|_| {
            // Archimedes: z uniform in [-1, 1] is uniform on the sphere.
            let z: f32 = rng.random_range(-1.0..1.0);
            let phi: f32 = rng.random_range(0.0..std::f32::consts::TAU);
            let r = (1.0 - z * z).max(0.0).sqrt();
            let p = Vec3::new(r * phi.cos(), r * phi.sin(), z) * SPHERE_RADIUS;
            PointLight::new(p, Vec3::splat(rng.random_range(0.5..1.5)))
        })
        .collect()
}
