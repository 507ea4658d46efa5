//! Street lamps on a square grid of streets, no buildings: the report's
//! `city` (fixed density, so the area grows with the number of lights) and
//! the regular lamp grid of the `seams` example.

use glam::Vec3;
use manylights::PointLight;
use rand::RngExt;

use super::{Material, Scene, floor_points, light_bounds, rng};

/// Spacing of the city's streets (one block), in both directions.
const CITY_BLOCK: f32 = 60.0;
/// Spacing of street lamps along a street.
const CITY_LAMP_SPACING: f32 = 12.0;
/// Distance of a lamp from its street's centre line (lamps line both sides).
const CITY_LAMP_OFFSET: f32 = 5.0;
/// Lamp height above the ground, and its random variation.
const CITY_LAMP_HEIGHT: (f32, f32) = (6.0, 0.5);
/// Random horizontal displacement of a lamp from its nominal place.
const CITY_LAMP_JITTER: f32 = 0.3;
/// Lamps per block: two streets (one along x, one along y), both sides.
const CITY_LAMPS_PER_BLOCK: usize = 4 * (CITY_BLOCK / CITY_LAMP_SPACING) as usize;
/// Radiant intensity of a street lamp, and its random variation factor.
const CITY_LAMP_INTENSITY: f32 = 40.0;
const CITY_LAMP_VARIATION: (f32, f32) = (0.8, 1.2);
/// Fraction of white LED lamps; the rest are sodium orange.
const CITY_WHITE_FRACTION: f64 = 0.2;
const SODIUM: Vec3 = Vec3::new(1.0, 0.55, 0.2);
const LED_WHITE: Vec3 = Vec3::new(0.85, 0.9, 1.0);
/// Seed offset of the city's shading points (the lights use the seed).
const CITY_POINTS_SEED: u64 = 0xC17;

/// Street lamps of a city grid, `count` of them. The density is fixed (one
/// block of `CITY_BLOCK` units square holds `CITY_LAMPS_PER_BLOCK`
/// lamps), so the city's area grows with `count`: blocks are filled row by
/// row on a square grid just large enough.
pub fn city_lights(count: usize, seed: u64) -> Vec<PointLight> {
    let mut rng = rng(seed);
    let blocks_per_side = (count as f64 / CITY_LAMPS_PER_BLOCK as f64).sqrt().ceil() as usize;
    let per_street = (CITY_BLOCK / CITY_LAMP_SPACING) as usize;
    let (jitter, height) = (CITY_LAMP_JITTER, CITY_LAMP_HEIGHT);
    let mut lights = Vec::with_capacity(count);
    'blocks: for by in 0..blocks_per_side {
        for bx in 0..blocks_per_side {
            let corner = Vec3::new(bx as f32 * CITY_BLOCK, by as f32 * CITY_BLOCK, 0.0);
            for k in 0..per_street {
                let along = (k as f32 + 0.5) * CITY_LAMP_SPACING;
                for side in [-CITY_LAMP_OFFSET, CITY_LAMP_OFFSET] {
                    // One lamp on the street along x, one on the street along y.
                    for nominal in [Vec3::new(along, side, 0.0), Vec3::new(side, along, 0.0)] {
                        if lights.len() == count {
                            break 'blocks;
                        }
                        let offset = Vec3::new(
                            rng.random_range(-jitter..jitter),
                            rng.random_range(-jitter..jitter),
                            height.0 + rng.random_range(-height.1..height.1),
                        );
                        let colour = if rng.random_bool(CITY_WHITE_FRACTION) {
                            LED_WHITE
                        } else {
                            SODIUM
                        };
                        let intensity = CITY_LAMP_INTENSITY
                            * rng.random_range(CITY_LAMP_VARIATION.0..CITY_LAMP_VARIATION.1);
                        lights.push(PointLight::new(
                            corner + nominal + offset,
                            colour * intensity,
                        ));
                    }
                }
            }
        }
    }
    lights
}

/// `city`: street lamps on a grid (see [`city_lights`]), shading points on
/// the ground anywhere in the city.
pub fn city(lights: usize, points: usize, seed: u64) -> Scene {
    let lights = city_lights(lights, seed);
    let (min, max) = light_bounds(&lights);
    let (min, max) = (min.with_z(0.0), max.with_z(0.0));
    let camera = (min + max) * 0.5 + Vec3::new(0.0, 0.0, 500.0);
    let points = floor_points(&mut rng(seed ^ CITY_POINTS_SEED), points, min, max, camera);
    Scene {
        name: "city",
        description: format!(
            "{} street lamps, {} per {CITY_BLOCK}x{CITY_BLOCK} block (fixed density), \
             ~{}x{} units, ground points",
            lights.len(),
            CITY_LAMPS_PER_BLOCK,
            (max.x - min.x).round(),
            (max.y - min.y).round()
        ),
        lights,
        points,
        material: Material::diffuse(Vec3::splat(0.5)),
    }
}

/// Streets of the lamp grid every this many units, lamps every
/// `GRID_LAMP_SPACING` along them, all at one height.
pub const GRID_BLOCK: f32 = 40.0;
const GRID_LAMP_SPACING: f32 = 4.0;
const GRID_LAMP_HEIGHT: f32 = 6.0;
/// Warm lamp colour; green and blue vary a little from lamp to lamp.
const GRID_GREEN: (f32, f32) = (0.8, 0.9);
const GRID_BLUE: (f32, f32) = (0.5, 0.7);
const GRID_INTENSITY: f32 = 100.0;
/// The rows along `x` are offset from those along `y` by this much, so that
/// no two lamps coincide at a crossing.
const GRID_ROW_OFFSET: f32 = 1.5;

/// A regular grid of `blocks x blocks` blocks of [`GRID_BLOCK`] units: a row
/// of lamps every `GRID_LAMP_SPACING` units along each street in both
/// directions, 6 units above the ground, warm colours varying a little.
pub fn lamp_grid(blocks: usize, seed: u64) -> Vec<PointLight> {
    let mut rng = rng(seed);
    let extent = GRID_BLOCK * blocks as f32;
    let per_street = (extent / GRID_LAMP_SPACING) as usize + 1;
    let mut lights = Vec::with_capacity(2 * (blocks + 1) * per_street);
    for street in 0..=blocks {
        let s = street as f32 * GRID_BLOCK;
        for k in 0..per_street {
            let t = k as f32 * GRID_LAMP_SPACING;
            let warm = Vec3::new(
                1.0,
                rng.random_range(GRID_GREEN.0..GRID_GREEN.1),
                rng.random_range(GRID_BLUE.0..GRID_BLUE.1),
            ) * GRID_INTENSITY;
            let z = GRID_LAMP_HEIGHT;
            lights.push(PointLight::new(Vec3::new(s, t, z), warm));
            lights.push(PointLight::new(Vec3::new(t, s + GRID_ROW_OFFSET, z), warm));
        }
    }
    lights
}

/// Greatest tilt of a spot-lit lamp's axis from straight down.
const SPOT_TILT_DEGREES: f32 = 12.0;
/// Range of the lamps' outer cone angles, radians.
const SPOT_OUTER: (f32, f32) = (0.6, 1.2);
/// Range of the inner angle as a fraction of the outer.
const SPOT_INNER: (f32, f32) = (0.4, 0.85);
/// Seed offset of the spots' axes and angles.
const SPOT_SEED: u64 = 0x5B07;

/// The lamps of [`city_lights`] as glTF spot lights aimed at the ground:
/// each axis tilted from straight down by up to 12 degrees in a
/// random direction, outer angles 0.6 to 1.2 radians, inner angles 40% to
/// 85% of the outer.
pub fn spot_city_lights(count: usize, seed: u64) -> Vec<manylights::Emitter> {
    let mut rng = rng(seed ^ SPOT_SEED);
    city_lights(count, seed)
        .into_iter()
        .map(|light| {
            let tilt = rng.random_range(0.0..SPOT_TILT_DEGREES).to_radians();
            let around = rng.random_range(0.0..std::f32::consts::TAU);
            let axis = Vec3::new(
                tilt.sin() * around.cos(),
                tilt.sin() * around.sin(),
                -tilt.cos(),
            );
            let outer = rng.random_range(SPOT_OUTER.0..SPOT_OUTER.1);
            let inner = outer * rng.random_range(SPOT_INNER.0..SPOT_INNER.1);
            light.with_emission(manylights::Emission::spot(axis, inner, outer))
        })
        .collect()
}
