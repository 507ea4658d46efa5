//! The ground scene of the evaluations-per-point table: unit white lights uniform in a
//! slab 4 to 6 units above a 1000 x 1000 ground, shading points on the
//! ground facing up.

use glam::Vec3;
use manylights::PointLight;
use rand::RngExt;

use super::rng;

/// Side of the square ground, in units.
pub const GROUND_SIZE: f32 = 1000.0;
/// Heights of the lights above the ground.
const LIGHT_HEIGHT: (f32, f32) = (4.0, 6.0);
/// Seed offset of the shading points.
const POINTS_SEED: u64 = 0x600;

/// `count` unit white lights, uniform over the ground and in height.
pub fn ground_lights(count: usize, seed: u64) -> Vec<PointLight> {
    let mut rng = rng(seed);
    (0..count)
        .map(|_| {
            let p = Vec3::new(
                rng.random_range(0.0..GROUND_SIZE),
                rng.random_range(0.0..GROUND_SIZE),
                rng.random_range(LIGHT_HEIGHT.0..LIGHT_HEIGHT.1),
            );
            PointLight::new(p, Vec3::ONE)
        })
        .collect()
}

/// `count` points uniform on the ground (their normal is `+z`).
pub fn ground_points(count: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = rng(seed ^ POINTS_SEED);
    (0..count)
        .map(|_| {
            Vec3::new(
                rng.random_range(0.0..GROUND_SIZE),
                rng.random_range(0.0..GROUND_SIZE),
                0.0,
            )
        })
        .collect()
}
