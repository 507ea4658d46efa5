//! A chandelier: a dense cluster of lights on rings over a room's floor.

use std::f32::consts::TAU;

use glam::Vec3;
use manylights::PointLight;
use rand::RngExt;

use super::{Material, Scene, floor_points, rng};

/// Number of tiers (rings) of the chandelier.
const TIERS: usize = 6;
/// Radius of the lowest tier and growth per tier.
const RADIUS: (f32, f32) = (0.4, 0.3);
/// Height of the lowest tier and rise per tier.
const HEIGHT: (f32, f32) = (3.8, 0.25);
/// Random displacement of a crystal light about its ring.
const SPREAD: f32 = 0.06;
/// Random tint of a crystal: green and blue factors.
const TINT_GREEN: (f32, f32) = (0.9, 1.1);
const TINT_BLUE: (f32, f32) = (0.8, 1.2);
/// Half-size of the square room floor under the chandelier.
const ROOM_HALF_SIZE: f32 = 8.0;
/// Total radiant intensity of the chandelier (shared by its lights).
const POWER: f32 = 600.0;
const WARM_WHITE: Vec3 = Vec3::new(1.0, 0.85, 0.6);
/// Seed offset of the shading points.
const POINTS_SEED: u64 = 0xC4A;

/// `chandelier`: a dense cluster of `lights` lights on `TIERS` rings within
/// a ball of radius about 2 units, 4-5 units above a floor; shading points on
/// the room's floor.
pub fn chandelier(lights: usize, points: usize, seed: u64) -> Scene {
    let mut rng = rng(seed);
    let radii: Vec<f32> = (0..TIERS).map(|t| RADIUS.0 + RADIUS.1 * t as f32).collect();
    let total_radius: f32 = radii.iter().sum();
    let per_light = POWER / lights as f32;
    let mut all = Vec::with_capacity(lights);
    for (t, &radius) in radii.iter().enumerate() {
        // Lights per tier in proportion to its circumference; the last tier
        // takes the remainder.
        let n = if t + 1 == TIERS {
            lights - all.len()
        } else {
            (lights as f32 * radius / total_radius) as usize
        };
        let height = HEIGHT.0 + HEIGHT.1 * t as f32;
        for k in 0..n {
            let angle = TAU * k as f32 / n as f32;
            let r = radius + rng.random_range(-SPREAD..SPREAD);
            let position = Vec3::new(
                r * angle.cos(),
                r * angle.sin(),
                height + rng.random_range(-SPREAD..SPREAD),
            );
            let tint = Vec3::new(
                1.0,
                rng.random_range(TINT_GREEN.0..TINT_GREEN.1),
                rng.random_range(TINT_BLUE.0..TINT_BLUE.1),
            );
            all.push(PointLight::new(position, WARM_WHITE * tint * per_light));
        }
    }
    let half = Vec3::new(ROOM_HALF_SIZE, ROOM_HALF_SIZE, 0.0);
    let camera = Vec3::new(0.0, -ROOM_HALF_SIZE, 3.0);
    let points = floor_points(
        &mut super::rng(seed ^ POINTS_SEED),
        points,
        -half,
        half,
        camera,
    );
    Scene {
        name: "chandelier",
        description: format!(
            "{} lights on {TIERS} rings (radius {:.1}-{:.1}, height {:.2}-{:.2}), floor {}x{}",
            all.len(),
            radii[0],
            radii[TIERS - 1],
            HEIGHT.0,
            HEIGHT.0 + HEIGHT.1 * (TIERS - 1) as f32,
            2.0 * ROOM_HALF_SIZE,
            2.0 * ROOM_HALF_SIZE
        ),
        lights: all,
        points,
        material: Material::diffuse(Vec3::new(0.6, 0.5, 0.4)),
    }
}
