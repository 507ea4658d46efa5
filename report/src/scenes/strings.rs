//! Strings of lights: the Christmas tree and garlands of the report's
//! `strings`, the festoons over a glossy plaza of its `specular`, and the
//! `glossy` example's strings over a glossy floor with spheres ([`Glossy`]).

use std::f32::consts::TAU;

use glam::Vec3;
use manylights::query::WithView;
use manylights::{Combined, Lambert, Phong, PointLight, Query, ShadeError};
use rand::RngExt;

use super::{Material, Scene, Specular, floor_points, rng};

/// Colours of Christmas light bulbs, cycled along a string.
const BULB_COLOURS: [Vec3; 5] = [
    Vec3::new(1.0, 0.1, 0.1),
    Vec3::new(0.1, 1.0, 0.2),
    Vec3::new(0.2, 0.3, 1.0),
    Vec3::new(1.0, 0.8, 0.1),
    Vec3::new(1.0, 1.0, 1.0),
];
/// Radiant intensity of a bulb.
const BULB_INTENSITY: f32 = 0.5;

/// `count` bulbs evenly spaced in the parameter of `curve` on `[0, 1]`, the
/// `k`-th of colour `colours(k)`.
fn string_of_lights(
    count: usize,
    colours: impl Fn(usize) -> Vec3,
    curve: impl Fn(f32) -> Vec3,
) -> impl Iterator<Item = PointLight> {
    (0..count).map(move |k| {
        let s = (k as f32 + 0.5) / count as f32;
        PointLight::new(curve(s), colours(k))
    })
}

/// The Christmas bulbs' colour of the `k`-th bulb of a string.
fn bulb(k: usize) -> Vec3 {
    BULB_COLOURS[k % BULB_COLOURS.len()] * BULB_INTENSITY
}

/// A hanging string between `a` and `b`, sagging by `sag` in the middle
/// (a parabola, close enough to a catenary).
fn hanging(a: Vec3, b: Vec3, sag: f32) -> impl Fn(f32) -> Vec3 {
    move |s| a.lerp(b, s) - Vec3::Z * (4.0 * sag * s * (1.0 - s))
}

/// Splits `total` into `parts` counts differing by at most one.
fn share(total: usize, parts: usize, k: usize) -> usize {
    total / parts + usize::from(k < total % parts)
}

/// The Christmas tree: a cone of this height and base radius, base at this
/// height, wound by this many helical strings of so many turns.
const TREE_HEIGHT: f32 = 10.0;
const TREE_BASE_RADIUS: f32 = 4.0;
const TREE_BASE: f32 = 0.5;
const TREE_HELICES: usize = 4;
const TREE_TURNS: f32 = 8.0;
/// Garlands hang from near the tree top to poles around it.
const GARLANDS: usize = 6;
const GARLAND_TOP: f32 = 9.0;
const GARLAND_POLE_DISTANCE: f32 = 25.0;
const GARLAND_POLE_HEIGHT: f32 = 5.0;
const GARLAND_SAG: f32 = 2.0;
/// Half-size of the square of ground around the tree that is shaded.
const STRINGS_GROUND_HALF_SIZE: f32 = 28.0;
/// Where the `strings` camera looks from.
const STRINGS_CAMERA: Vec3 = Vec3::new(0.0, -40.0, 8.0);

/// `strings`: Christmas lights, `lights` bulbs along `TREE_HELICES`
/// helices wound around a conical tree and `GARLANDS` long garlands
/// hanging from its top to poles; shading points on the ground around it.
pub fn strings(lights: usize, points: usize, seed: u64) -> Scene {
    let on_tree = lights / 2;
    let mut all = Vec::with_capacity(lights);
    for h in 0..TREE_HELICES {
        let phase = TAU * h as f32 / TREE_HELICES as f32;
        all.extend(string_of_lights(
            share(on_tree, TREE_HELICES, h),
            bulb,
            |s| {
                let angle = phase + TAU * TREE_TURNS * s;
                let radius = TREE_BASE_RADIUS * (1.0 - s);
                Vec3::new(
                    radius * angle.cos(),
                    radius * angle.sin(),
                    TREE_BASE + TREE_HEIGHT * s,
                )
            },
        ));
    }
    let on_garlands = lights - on_tree;
    for g in 0..GARLANDS {
        let angle = TAU * g as f32 / GARLANDS as f32;
        let direction = Vec3::new(angle.cos(), angle.sin(), 0.0);
        let top = direction * 0.1 * TREE_BASE_RADIUS + Vec3::Z * GARLAND_TOP;
        let pole = direction * GARLAND_POLE_DISTANCE + Vec3::Z * GARLAND_POLE_HEIGHT;
        let n = share(on_garlands, GARLANDS, g);
        all.extend(string_of_lights(n, bulb, hanging(top, pole, GARLAND_SAG)));
    }
    let half = Vec3::new(STRINGS_GROUND_HALF_SIZE, STRINGS_GROUND_HALF_SIZE, 0.0);
    let points = floor_points(&mut rng(seed), points, -half, half, STRINGS_CAMERA);
    Scene {
        name: "strings",
        description: format!(
            "{} bulbs in 5 colours: {TREE_HELICES} helices on a {TREE_HEIGHT}-unit conical tree, \
             {GARLANDS} garlands to poles {GARLAND_POLE_DISTANCE} units away",
            all.len()
        ),
        lights: all,
        points,
        material: Material::diffuse(Vec3::splat(0.8)),
    }
}

/// Festoon strings over a plaza: this many parallel strings between poles
/// at `x = -+half span`, spread over this range of `y`.
const FESTOON_STRINGS: usize = 8;
const FESTOON_HALF_SPAN: f32 = 20.0;
const FESTOON_HALF_WIDTH: f32 = 14.0;
const FESTOON_POLE_HEIGHT: f32 = 6.0;
/// Random variation of a pole's height, so the strings are not coplanar.
const FESTOON_POLE_VARIATION: f32 = 0.5;
const FESTOON_SAG: f32 = 1.5;
/// Half-size of the shaded square of glossy floor.
const PLAZA_HALF_SIZE: f32 = 12.0;
/// Where the camera looks from.
const PLAZA_CAMERA: Vec3 = Vec3::new(0.0, -30.0, 10.0);
/// Phong exponent of the glossy floor.
pub const GLOSSY_EXPONENT: u32 = 100;

/// `specular`: `lights` bulbs on `FESTOON_STRINGS` strings hanging over a
/// glossy floor (Lambert `kd = 0.2` plus Phong `ks = 0.6`, exponent
/// [`GLOSSY_EXPONENT`]), seen from a camera.
pub fn specular(lights: usize, points: usize, seed: u64) -> Scene {
    let mut rng = rng(seed);
    let mut all = Vec::with_capacity(lights);
    let variation = -FESTOON_POLE_VARIATION..FESTOON_POLE_VARIATION;
    for k in 0..FESTOON_STRINGS {
        let y = -FESTOON_HALF_WIDTH
            + 2.0 * FESTOON_HALF_WIDTH * k as f32 / (FESTOON_STRINGS - 1) as f32;
        let mut pole = |x: f32| {
            let height = FESTOON_POLE_HEIGHT + rng.random_range(variation.clone());
            Vec3::new(x, y, height)
        };
        let (a, b) = (pole(-FESTOON_HALF_SPAN), pole(FESTOON_HALF_SPAN));
        let n = share(lights, FESTOON_STRINGS, k);
        all.extend(string_of_lights(n, bulb, hanging(a, b, FESTOON_SAG)));
    }
    let half = Vec3::new(PLAZA_HALF_SIZE, PLAZA_HALF_SIZE, 0.0);
    let points = floor_points(&mut rng, points, -half, half, PLAZA_CAMERA);
    Scene {
        name: "specular",
        description: format!(
            "{} bulbs on {FESTOON_STRINGS} festoon strings over a glossy floor \
             (Lambert 0.2 + Phong 0.6, exponent {GLOSSY_EXPONENT}), camera at {PLAZA_CAMERA}",
            all.len()
        ),
        lights: all,
        points,
        material: Material {
            kd: Vec3::splat(0.2),
            specular: Some(Specular {
                ks: Vec3::splat(0.6),
                exponent: GLOSSY_EXPONENT,
            }),
        },
    }
}

/// The `glossy` example's strings: this many, along `x`, one every
/// `GAP` in `y`, hung at this height with this sag.
const GLOSSY_STRINGS: usize = 8;
const GLOSSY_STRING_GAP: f32 = 3.0;
const GLOSSY_STRING_SPAN: f32 = 24.0;
const GLOSSY_STRING_HEIGHT: f32 = 4.5;
const GLOSSY_STRING_SAG: f32 = 1.2;
/// One colour per string, cycled, times this intensity.
const GLOSSY_PALETTE: [Vec3; 4] = [
    Vec3::new(1.0, 0.25, 0.15),
    Vec3::new(1.0, 0.75, 0.2),
    Vec3::new(0.3, 1.0, 0.35),
    Vec3::new(0.3, 0.5, 1.0),
];
const GLOSSY_INTENSITY: f32 = 0.05;
/// Materials: a dark glossy floor and glossy spheres (`kd`, `ks`).
const FLOOR_MATERIAL: (f32, f32) = (0.02, 0.6);
const SPHERE_MATERIAL: (f32, f32) = (0.04, 0.8);
/// Phong exponent of the floor and the spheres.
pub const GLOSSY_SCENE_EXPONENT: f32 = 300.0;
/// Spheres resting on the floor: centre `(x, y)` and radius.
const SPHERES: [(f32, f32, f32); 3] = [(-4.0, 6.0, 1.2), (3.0, 9.0, 1.6), (7.5, 4.0, 0.9)];

/// A sphere resting on the floor.
#[derive(Clone, Copy, Debug)]
pub struct Sphere {
    /// Centre.
    pub centre: Vec3,
    /// Radius.
    pub radius: f32,
}

/// A surface hit in [`Glossy`]: point, unit normal, direction back along
/// the ray, material `(kd, ks)`.
#[derive(Clone, Copy, Debug)]
pub struct GlossyHit {
    /// Point on the surface.
    pub point: Vec3,
    /// Unit outward normal.
    pub normal: Vec3,
    /// Unit direction towards the ray's origin.
    pub view: Vec3,
    /// Grey diffuse and specular colours `(kd, ks)`.
    pub material: (f32, f32),
}

impl GlossyHit {
    /// The hit as a query with its view.
    pub fn query(&self) -> Result<Query<WithView>, ShadeError> {
        Query::new(self.point, self.normal)?.with_view(self.view)
    }

    /// The surface's shader: Lambert plus Phong of exponent
    /// [`GLOSSY_SCENE_EXPONENT`].
    pub fn shader(&self) -> Combined<Lambert, Phong> {
        let (kd, ks) = self.material;
        Combined::new(
            Lambert::new(Vec3::splat(kd)),
            Phong::new(Vec3::splat(ks), GLOSSY_SCENE_EXPONENT),
        )
    }
}

/// The `glossy` example's scene: coloured strings of lights hung in arcs
/// above a dark glossy floor (`z = 0`) with glossy spheres on it.
pub struct Glossy {
    /// The bulbs.
    pub lights: Vec<PointLight>,
    /// The spheres.
    pub spheres: Vec<Sphere>,
}

impl Glossy {
    /// The scene with `count` bulbs on `GLOSSY_STRINGS` strings.
    pub fn new(count: usize) -> Self {
        let per_string = count.div_ceil(GLOSSY_STRINGS);
        let lights = (0..count)
            .map(|i| {
                let (s, k) = (i / per_string, i % per_string);
                // 0..1 along the string, ends included.
                let u = k as f32 / (per_string - 1).max(1) as f32;
                let x = (u - 0.5) * GLOSSY_STRING_SPAN;
                let y = s as f32 * GLOSSY_STRING_GAP;
                let z = GLOSSY_STRING_HEIGHT - GLOSSY_STRING_SAG * (1.0 - (2.0 * u - 1.0).powi(2));
                let colour = GLOSSY_PALETTE[s % GLOSSY_PALETTE.len()];
                PointLight::new(Vec3::new(x, y, z), colour * GLOSSY_INTENSITY)
            })
            .collect();
        let spheres = SPHERES
            .iter()
            .map(|&(x, y, radius)| Sphere {
                centre: Vec3::new(x, y, radius),
                radius,
            })
            .collect();
        Self { lights, spheres }
    }

    /// Nearest hit of the ray `origin + t dir` (`dir` unit) with the floor or
    /// a sphere.
    pub fn intersect(&self, origin: Vec3, dir: Vec3) -> Option<GlossyHit> {
        let mut best = (dir.z < 0.0).then(|| {
            let t = -origin.z / dir.z;
            let hit = GlossyHit {
                point: origin + t * dir,
                normal: Vec3::Z,
                view: -dir,
                material: FLOOR_MATERIAL,
            };
            (t, hit)
        });
        for sphere in &self.spheres {
            let oc = origin - sphere.centre;
            let b = oc.dot(dir);
            let disc = b * b - (oc.length_squared() - sphere.radius * sphere.radius);
            if disc < 0.0 {
                continue;
            }
            let t = -b - disc.sqrt();
            if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
                let point = origin + t * dir;
                let hit = GlossyHit {
                    point,
                    normal: (point - sphere.centre) / sphere.radius,
                    view: -dir,
                    material: SPHERE_MATERIAL,
                };
                best = Some((t, hit));
            }
        }
        best.map(|(_, h)| h)
    }
}
