//! Every procedural scene of the examples, the benches and the report.
//!
//! Each scene is generated from a seed with [`rng`] (ChaCha8 from the `rand`
//! family), so two runs see the same lights and the same shading points.
//! Units are metres-ish: lights a few units above the receiving surfaces,
//! intensities chosen so that radiances are of order 1.
//!
//! * [`city`]: street lamps on a grid at fixed density (the report's `city`,
//!   its scaling part and the benches); [`lamp_grid`]: a regular grid of
//!   identical lamps (the `seams` example).
//! * [`City`]: a night city of box buildings with street lamps and lit
//!   windows (the `city` and `shadows` examples), and [`city_shadows`], its
//!   shading points on streets and façades (the report's occluded scene).
//! * [`canopy()`]: lights above a layer of many small leaves, points on the
//!   ground below (the report's occluded scene where classification fails).
//! * [`chandelier()`]: a dense cluster of lights over a floor.
//! * [`strings()`], [`specular`], [`Glossy`]: strings of lights, over a
//!   diffuse ground, a glossy floor, and a glossy floor with spheres.
//! * [`ground_lights`], [`ground_points`]: lights 4 to 6 units above a
//!   1000 x 1000 ground, points on it (the evaluations-per-point table).
//! * [`spot_city_lights`]: the street city's lamps as spots aimed down;
//!   [`Room`]: instant radiosity in a furnished room (virtual point lights
//!   traced from a few primary lights).
//! * [`sphere_lights`]: lights over a sphere, for points whose tangent
//!   plane cuts it (the `seams` example's horizon scanlines).
//! * [`tilted_plane`], [`geometric_cluster`], [`log_spiral`],
//!   [`thin_layer`]: scenes built to defeat the tree (the report's
//!   `hostile` part and the crate's cost tests).

mod canopy;
mod chandelier;
mod ground;
mod hostile;
mod night_city;
mod room;
mod sphere;
mod streets;
mod strings;

pub use canopy::canopy;
pub use chandelier::chandelier;
pub use ground::{GROUND_SIZE, ground_lights, ground_points};
pub use hostile::{
    CLUSTER_CENTRE, TILTED_POINT, geometric_cluster, log_spiral, thin_layer, thin_layer_points,
    tilted_normal, tilted_plane,
};
pub use night_city::{Building, City, GROUND_ALBEDO, SHADOW_BLOCKS, city_shadows};
pub use room::{POINT_OFFSET, ROOM_SIZE, Room, VPL_OFFSET, isotropic};
pub use sphere::{SPHERE_RADIUS, sphere_lights};
pub use streets::{GRID_BLOCK, city, city_lights, lamp_grid, spot_city_lights};
pub use strings::{
    GLOSSY_EXPONENT, GLOSSY_SCENE_EXPONENT, Glossy, GlossyHit, Sphere, specular, strings,
};

use std::f32::consts::TAU;

use glam::Vec3;
use manylights::PointLight;
use rand::{RngExt, SeedableRng};

/// The generator of every scene and sampler: ChaCha8, reproducible across
/// platforms for a given seed.
pub type SceneRng = rand::rngs::ChaCha8Rng;

/// A generator seeded with `seed`.
pub fn rng(seed: u64) -> SceneRng {
    SceneRng::seed_from_u64(seed)
}

/// The Phong part of a glossy material.
#[derive(Clone, Copy, Debug)]
pub struct Specular {
    /// Specular colour `ks`.
    pub ks: Vec3,
    /// Phong exponent (an integer, so the vectorized exact sum can raise to
    /// it by repeated squaring).
    pub exponent: u32,
}

/// The receiving surfaces' material, shared by every shading point of a
/// scene.
#[derive(Clone, Copy, Debug)]
pub struct Material {
    /// Diffuse albedo `kd`.
    pub kd: Vec3,
    /// Phong term, if the surface is glossy.
    pub specular: Option<Specular>,
}

impl Material {
    /// A diffuse (Lambert) material of albedo `kd`.
    pub const fn diffuse(kd: Vec3) -> Self {
        Self { kd, specular: None }
    }
}

/// A shading point: position, normal (unit) and view direction (unit,
/// towards the scene's camera; diffuse scenes ignore it).
#[derive(Clone, Copy, Debug)]
pub struct ShadingPoint {
    /// Position on a receiving surface.
    pub point: Vec3,
    /// Unit surface normal.
    pub normal: Vec3,
    /// Unit direction towards the camera.
    pub view: Vec3,
}

/// A named scene: lights, shading points and the receivers' material.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Short name, used in file names and tables.
    pub name: &'static str,
    /// One line saying what the scene is.
    pub description: String,
    /// The lights.
    pub lights: Vec<PointLight>,
    /// Shading points on the receiving surfaces.
    pub points: Vec<ShadingPoint>,
    /// Material of the receiving surfaces.
    pub material: Material,
}

/// Fraction of shading points whose normal is tilted away from straight up.
const TILTED_FRACTION: f64 = 0.25;
/// Range of the tilt of tilted normals, in degrees (below a right angle, so
/// every normal faces up).
const TILT_DEGREES: (f32, f32) = (15.0, 60.0);

/// `count` shading points uniform on the closed rectangle `[min, max]` of the
/// plane `z = 0`, normals up except for [`TILTED_FRACTION`] of them, views
/// towards `camera`.
fn floor_points(
    rng: &mut SceneRng,
    count: usize,
    min: Vec3,
    max: Vec3,
    camera: Vec3,
) -> Vec<ShadingPoint> {
    (0..count)
        .map(|_| {
            let point = Vec3::new(
                rng.random_range(min.x..=max.x),
                rng.random_range(min.y..=max.y),
                0.0,
            );
            let normal = if rng.random_bool(TILTED_FRACTION) {
                let tilt = rng
                    .random_range(TILT_DEGREES.0..TILT_DEGREES.1)
                    .to_radians();
                let azimuth = rng.random_range(0.0..TAU);
                Vec3::new(
                    tilt.sin() * azimuth.cos(),
                    tilt.sin() * azimuth.sin(),
                    tilt.cos(),
                )
            } else {
                Vec3::Z
            };
            ShadingPoint {
                point,
                normal,
                view: (camera - point).normalize(),
            }
        })
        .collect()
}

/// The bounding box of the lights' positions.
fn light_bounds(lights: &[PointLight]) -> (Vec3, Vec3) {
    lights.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), l| (lo.min(l.position), hi.max(l.position)),
    )
}
