//! A night city: box buildings on the blocks of a square street grid, street
//! lamps along both sides of every street and lit windows on the façades,
//! all on the ground plane `z = 0` with `+z` up (the `city` and `shadows`
//! examples); and [`city_shadows`], its shading points on the streets and
//! the façades (the report's occluded scene).

use glam::Vec3;
use manylights::{Aabb, PointLight};
use rand::RngExt;

use super::{Material, Scene, SceneRng, ShadingPoint, light_bounds, rng};
use crate::bvh::Occluders;

/// Distance between neighbouring street centre lines.
const BLOCK_PITCH: f32 = 40.0;
/// Street width, kerb to kerb.
const STREET_WIDTH: f32 = 16.0;
/// Pavement between the kerb and the buildings.
const PAVEMENT: f32 = 2.0;
/// Lamps stand this far inside the kerb, on both sides of every street.
const LAMP_INSET: f32 = 4.0;
/// Lamp heights, uniform in this range.
const LAMP_HEIGHT: (f32, f32) = (5.0, 8.0);
/// Mean radiant intensity of a lamp: about 1 radiance unit on the street
/// below it.
const LAMP_INTENSITY: f32 = 40.0;
/// Lamp (and window) brightness varies by this factor range.
const LAMP_VARIATION: (f32, f32) = (0.7, 1.3);
/// Colours of low-pressure sodium and warm-white lamps; each lamp is a random
/// mix of the two.
const SODIUM: Vec3 = Vec3::new(1.0, 0.45, 0.12);
const WARM_WHITE: Vec3 = Vec3::new(1.0, 0.75, 0.45);
/// Share of the lights that are lit windows (the rest are street lamps).
const WINDOW_SHARE: f64 = 0.2;
/// Window grid on the façades: storey height and window spacing.
const STOREY_HEIGHT: f32 = 3.5;
const WINDOW_SPACING: f32 = 3.0;
/// Height of the first row of windows above the ground.
const FIRST_WINDOW_HEIGHT: f32 = 2.0;
/// A window light floats this far in front of its façade.
const WINDOW_OFFSET: f32 = 0.3;
/// Radiant intensity of a lit window.
const WINDOW_INTENSITY: f32 = 1.5;
/// Window colours: mostly warm interiors, some cool screens.
const WINDOW_WARM: Vec3 = Vec3::new(1.0, 0.78, 0.5);
const WINDOW_COOL: Vec3 = Vec3::new(0.6, 0.72, 1.0);
const COOL_WINDOW_SHARE: f64 = 0.15;
/// Share of the blocks left without a building (squares, parks).
const PARK_SHARE: f64 = 0.08;
/// Share of the built blocks split in two buildings with an alley between.
const SPLIT_SHARE: f64 = 0.4;
/// Where a split block is cut, as a fraction of the lot.
const SPLIT_AT: (f32, f32) = (0.3, 0.7);
/// Width of the alley between the two halves of a split block.
const ALLEY_WIDTH: f32 = 3.0;
/// Building heights: `min + (max - min) * u^3`, mostly low with a few towers.
const BUILDING_HEIGHT: (f32, f32) = (6.0, 60.0);
/// Albedos: asphalt, and façades of varying brightness and warmth.
pub const GROUND_ALBEDO: Vec3 = Vec3::new(0.4, 0.4, 0.42);
const FACADE_ALBEDO: (f32, f32) = (0.15, 0.35);
const FACADE_GREEN: (f32, f32) = (0.9, 1.0);
const FACADE_BLUE: (f32, f32) = (0.8, 1.0);

/// A box building and its colour.
#[derive(Clone, Copy, Debug)]
pub struct Building {
    /// Footprint times height, standing on the ground `z = 0`.
    pub bounds: Aabb,
    /// Diffuse albedo of its walls and roof.
    pub albedo: Vec3,
}

/// A city at night. A city of `blocks x blocks` blocks covers
/// `[0, blocks * 40]` in `x` and `y`; street centre lines run at the
/// multiples of 40 units.
pub struct City {
    /// Street lamps first, then windows.
    pub lights: Vec<PointLight>,
    /// The buildings.
    pub buildings: Vec<Building>,
    /// The buildings' boxes in a BVH: what occludes and what primary rays
    /// hit (box `i` is building `i`).
    pub occluders: Occluders,
}

impl City {
    /// Builds a city of `blocks x blocks` blocks with exactly `light_count`
    /// lights: a fifth lit windows (or every window, if there are fewer),
    /// the rest street lamps spread evenly along the streets.
    pub fn new(blocks: u32, light_count: usize, seed: u64) -> City {
        let mut rng = rng(seed);
        let buildings = buildings(&mut rng, blocks);
        let window_count = (light_count as f64 * WINDOW_SHARE).round() as usize;
        let windows = windows(&mut rng, &buildings, window_count);
        let mut lights = street_lamps(&mut rng, blocks, light_count - windows.len());
        lights.extend(windows);
        let boxes: Vec<Aabb> = buildings.iter().map(|b| b.bounds).collect();
        City {
            lights,
            occluders: Occluders::new(&boxes),
            buildings,
        }
    }

    /// Whether `p` lies in the footprint of a building.
    pub fn inside(&self, p: Vec3) -> bool {
        self.buildings.iter().any(|b| {
            let (lo, hi) = (b.bounds.min, b.bounds.max);
            p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y
        })
    }
}

/// Uniform in `[lo, hi)`.
fn uniform(rng: &mut SceneRng, (lo, hi): (f32, f32)) -> f32 {
    rng.random_range(lo..hi)
}

/// One or two buildings per block, with a few empty blocks.
fn buildings(rng: &mut SceneRng, blocks: u32) -> Vec<Building> {
    let mut buildings = Vec::new();
    let lot = BLOCK_PITCH - STREET_WIDTH - 2.0 * PAVEMENT;
    for bx in 0..blocks {
        for by in 0..blocks {
            if rng.random_bool(PARK_SHARE) {
                continue;
            }
            let x0 = bx as f32 * BLOCK_PITCH + 0.5 * STREET_WIDTH + PAVEMENT;
            let y0 = by as f32 * BLOCK_PITCH + 0.5 * STREET_WIDTH + PAVEMENT;
            let whole = Aabb {
                min: Vec3::new(x0, y0, 0.0),
                max: Vec3::new(x0 + lot, y0 + lot, 0.0),
            };
            let parts = if rng.random_bool(SPLIT_SHARE) {
                let axis = usize::from(rng.random_bool(0.5));
                let cut = whole.min[axis] + lot * uniform(rng, SPLIT_AT);
                let (mut first, mut second) = (whole, whole);
                first.max[axis] = cut - 0.5 * ALLEY_WIDTH;
                second.min[axis] = cut + 0.5 * ALLEY_WIDTH;
                vec![first, second]
            } else {
                vec![whole]
            };
            for mut bounds in parts {
                let u: f32 = rng.random();
                bounds.max.z =
                    BUILDING_HEIGHT.0 + (BUILDING_HEIGHT.1 - BUILDING_HEIGHT.0) * u * u * u;
                let grey = uniform(rng, FACADE_ALBEDO);
                let tint = Vec3::new(1.0, uniform(rng, FACADE_GREEN), uniform(rng, FACADE_BLUE));
                buildings.push(Building {
                    bounds,
                    albedo: grey * tint,
                });
            }
        }
    }
    buildings
}

/// `count` lamps at even spacing along both sides of every street, in both
/// directions.
fn street_lamps(rng: &mut SceneRng, blocks: u32, count: usize) -> Vec<PointLight> {
    let streets = blocks + 1;
    let length = f64::from(blocks as f32 * BLOCK_PITCH);
    // Rows of lamps: both directions, both sides of each street.
    let rows = 4 * streets as usize;
    let spacing = rows as f64 * length / count as f64;
    let side_offset = 0.5 * STREET_WIDTH - LAMP_INSET;
    (0..count)
        .map(|i| {
            let arc = (i as f64 + 0.5) * spacing;
            let row = ((arc / length) as usize).min(rows - 1);
            let along = (arc - row as f64 * length) as f32;
            let street = (row / 4) as f32 * BLOCK_PITCH;
            // Each street has four rows: two sides of the street running
            // along x, then two of the one running along y.
            let (x, y) = match row % 4 {
                0 => (along, street + side_offset),
                1 => (along, street - side_offset),
                2 => (street + side_offset, along),
                _ => (street - side_offset, along),
            };
            let position = Vec3::new(x, y, uniform(rng, LAMP_HEIGHT));
            let colour = SODIUM.lerp(WARM_WHITE, rng.random());
            let intensity = colour * LAMP_INTENSITY * uniform(rng, LAMP_VARIATION);
            PointLight::new(position, intensity)
        })
        .collect()
}

/// `count` lit windows (at most one per slot) chosen uniformly among the
/// window slots of every façade (selection sampling: each slot is taken with
/// probability `still needed / slots left`, which yields exactly `count`
/// when there are enough slots).
fn windows(rng: &mut SceneRng, buildings: &[Building], count: usize) -> Vec<PointLight> {
    let mut slots = Vec::new();
    for b in buildings {
        let (lo, hi) = (b.bounds.min, b.bounds.max);
        let storeys = ((hi.z - FIRST_WINDOW_HEIGHT) / STOREY_HEIGHT).floor() as u32;
        // (axis along the façade, coordinate of the window plane across it)
        for (axis, side) in [
            (0, lo.y - WINDOW_OFFSET),
            (0, hi.y + WINDOW_OFFSET),
            (1, lo.x - WINDOW_OFFSET),
            (1, hi.x + WINDOW_OFFSET),
        ] {
            let width = hi[axis] - lo[axis];
            let columns = (width / WINDOW_SPACING).floor() as u32;
            let margin = 0.5 * (width - (columns as f32 - 1.0) * WINDOW_SPACING);
            for storey in 0..storeys {
                for column in 0..columns {
                    let along = lo[axis] + margin + column as f32 * WINDOW_SPACING;
                    let z = FIRST_WINDOW_HEIGHT + storey as f32 * STOREY_HEIGHT;
                    let mut position = Vec3::new(0.0, 0.0, z);
                    position[axis] = along;
                    position[1 - axis] = side;
                    slots.push(position);
                }
            }
        }
    }
    let mut lights = Vec::with_capacity(count);
    for (taken_from, position) in slots.iter().enumerate() {
        let left = (slots.len() - taken_from) as f64;
        let needed = count.saturating_sub(lights.len()) as f64;
        if rng.random::<f64>() * left < needed {
            let colour = if rng.random_bool(COOL_WINDOW_SHARE) {
                WINDOW_COOL
            } else {
                WINDOW_WARM
            };
            let intensity = colour * WINDOW_INTENSITY * uniform(rng, LAMP_VARIATION);
            lights.push(PointLight::new(*position, intensity));
        }
    }
    lights
}

/// Blocks along each side of the occluded scene's city (as in the
/// `shadows` example).
pub const SHADOW_BLOCKS: u32 = 16;
/// Share of the occluded scene's shading points on the ground; the rest are
/// on façades.
const GROUND_SHARE: f64 = 0.5;
/// Façade points stay this far below the roof and above the ground.
const FACADE_MARGIN: f32 = 0.5;
/// Seed offset of the occluded scene's shading points.
const SHADOW_POINTS_SEED: u64 = 0x5AD0;

/// `city-shadows`: the city of the `shadows` example, [`SHADOW_BLOCKS`] x
/// [`SHADOW_BLOCKS`] blocks with `lights` lights (80% street lamps, 20% lit
/// windows), and `points` shading points, half on the streets (uniform over
/// the city, outside the buildings) and half on the buildings' walls (a
/// uniform building, wall, position along it and height), grey Lambert.
/// Returns the scene and the city, whose buildings occlude.
pub fn city_shadows(lights: usize, points: usize, seed: u64) -> (Scene, City) {
    let city = City::new(SHADOW_BLOCKS, lights, seed);
    let mut rng = rng(seed ^ SHADOW_POINTS_SEED);
    let (lo, hi) = light_bounds(&city.lights);
    let ground = (points as f64 * GROUND_SHARE).round() as usize;
    let mut shading = Vec::with_capacity(points);
    while shading.len() < ground {
        let p = Vec3::new(
            rng.random_range(lo.x..hi.x),
            rng.random_range(lo.y..hi.y),
            0.0,
        );
        if !city.inside(p) {
            shading.push(ShadingPoint {
                point: p,
                normal: Vec3::Z,
                view: Vec3::Z,
            });
        }
    }
    while shading.len() < points {
        let b = city.buildings[rng.random_range(0..city.buildings.len())].bounds;
        // Axis across the wall, and its side.
        let (across, max_side) = (rng.random_range(0..2), rng.random_bool(0.5));
        let along = 1 - across;
        let mut p = Vec3::ZERO;
        p[across] = if max_side {
            b.max[across]
        } else {
            b.min[across]
        };
        p[along] = rng.random_range(b.min[along]..b.max[along]);
        p.z = rng.random_range(FACADE_MARGIN..b.max.z - FACADE_MARGIN);
        let mut normal = Vec3::ZERO;
        normal[across] = if max_side { 1.0 } else { -1.0 };
        shading.push(ShadingPoint {
            point: p,
            normal,
            view: normal,
        });
    }
    let scene = Scene {
        name: "city-shadows",
        description: format!(
            "the night city with occluders: {} lights (street lamps, a fifth lit windows), {} \
             box buildings, {SHADOW_BLOCKS}x{SHADOW_BLOCKS} blocks, ~{}x{} units; points half on \
             the streets, half on the façades; reference = exact shadowed sum (one shadow ray \
             per light)",
            city.lights.len(),
            city.buildings.len(),
            (hi.x - lo.x).round(),
            (hi.y - lo.y).round()
        ),
        lights: city.lights.clone(),
        points: shading,
        material: Material::diffuse(Vec3::splat(0.5)),
    };
    (scene, city)
}
