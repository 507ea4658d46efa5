//! A canopy: lights above a layer of many small leaves, shading points on
//! the ground below. Almost every shaft from a ground point to a group of
//! lights meets a leaf and no single leaf hides a whole group, so a shaft
//! classifier answers "partial" nearly always: the scene where
//! classification fails.

use glam::Vec3;
use manylights::{Aabb, PointLight};
use rand::RngExt;

use super::{Material, Scene, SceneRng, floor_points, rng};
use crate::bvh::Occluders;

/// Side of the square of ground that holds the shading points.
const GROUND_SIDE: f32 = 40.0;
/// Leaves and lights reach this far beyond the ground square on every side,
/// so that points near its edge are under the canopy too.
const OVERHANG: f32 = 20.0;
/// Heights of the leaves' centres.
const LEAF_HEIGHT: (f32, f32) = (3.0, 7.0);
/// Horizontal and vertical sizes of a leaf (a flat box).
const LEAF_SIZE: (f32, f32) = (0.2, 0.6);
const LEAF_THICKNESS: (f32, f32) = (0.03, 0.1);
/// Leaves per square unit of the canopy: with a mean leaf area of 0.16
/// this blocks about half of the vertical rays (optical depth `0.64`) and
/// most of the slanting ones.
const LEAF_DENSITY: f32 = 4.0;
/// Heights of the lights.
const LIGHT_HEIGHT: (f32, f32) = (9.0, 12.0);
/// Total radiant intensity of the lights (shared by them).
const POWER: f32 = 40_000.0;
/// Colours of the lights: a random mix of a warm and a cool white.
const WARM: Vec3 = Vec3::new(1.0, 0.8, 0.55);
const COOL: Vec3 = Vec3::new(0.75, 0.85, 1.0);
/// Seed offsets of the leaves and the shading points.
const LEAVES_SEED: u64 = 0x1EAF;
const POINTS_SEED: u64 = 0xF0E;

/// Uniform in `[lo, hi)`.
fn uniform(rng: &mut SceneRng, (lo, hi): (f32, f32)) -> f32 {
    rng.random_range(lo..hi)
}

/// `canopy`: `lights` lights 9 to 12 units up over a square of side 80,
/// above a canopy of small flat leaves (about 25,600 of them, 3 to 7 units
/// up, 0.2 to 0.6 wide), and `points` shading points on the central 40 x 40
/// square of the ground (a quarter of them with tilted normals). Returns the
/// scene and the leaves, which occlude.
pub fn canopy(lights: usize, points: usize, seed: u64) -> (Scene, Occluders) {
    let (lo, hi) = (-OVERHANG, GROUND_SIDE + OVERHANG);
    let mut rng = rng(seed);
    let per_light = POWER / lights as f32;
    let all: Vec<PointLight> = (0..lights)
        .map(|_| {
            let position = Vec3::new(
                rng.random_range(lo..hi),
                rng.random_range(lo..hi),
                uniform(&mut rng, LIGHT_HEIGHT),
            );
            let colour = WARM.lerp(COOL, rng.random());
            PointLight::new(position, colour * per_light)
        })
        .collect();
    let mut rng = super::rng(seed ^ LEAVES_SEED);
    let leaf_count = (LEAF_DENSITY * (hi - lo) * (hi - lo)) as usize;
    let leaves: Vec<Aabb> = (0..leaf_count)
        .map(|_| {
            let centre = Vec3::new(
                rng.random_range(lo..hi),
                rng.random_range(lo..hi),
                uniform(&mut rng, LEAF_HEIGHT),
            );
            let half = 0.5
                * Vec3::new(
                    uniform(&mut rng, LEAF_SIZE),
                    uniform(&mut rng, LEAF_SIZE),
                    uniform(&mut rng, LEAF_THICKNESS),
                );
            Aabb {
                min: centre - half,
                max: centre + half,
            }
        })
        .collect();
    let camera = Vec3::new(0.5 * GROUND_SIDE, -OVERHANG, 2.0);
    let points = floor_points(
        &mut super::rng(seed ^ POINTS_SEED),
        points,
        Vec3::ZERO,
        Vec3::new(GROUND_SIDE, GROUND_SIDE, 0.0),
        camera,
    );
    let scene = Scene {
        name: "canopy",
        description: format!(
            "{} lights {}-{} units up over {side}x{side}, above {} small leaves ({}-{} \
             units wide, {}-{} up); points on the ground under the middle {GROUND_SIDE}x\
             {GROUND_SIDE}; reference = exact shadowed sum (one shadow ray per light)",
            all.len(),
            LIGHT_HEIGHT.0,
            LIGHT_HEIGHT.1,
            leaves.len(),
            LEAF_SIZE.0,
            LEAF_SIZE.1,
            LEAF_HEIGHT.0,
            LEAF_HEIGHT.1,
            side = hi - lo,
        ),
        lights: all,
        points,
        material: Material::diffuse(Vec3::new(0.35, 0.45, 0.3)),
    };
    (scene, Occluders::new(&leaves))
}
