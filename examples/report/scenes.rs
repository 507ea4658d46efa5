//! Procedural scenes of the error-against-time report, shared with the
//! benches (`benches/*.rs` include this file with `#[path]`).
//!
//! Every scene is generated from a fixed seed, so two runs see the same
//! lights and the same shading points. Units are metres-ish: lights a few
//! units above the receiving surfaces, intensities chosen so that radiances
//! are of order 1.

use std::f32::consts::TAU;

use glam::Vec3;
use manylights::PointLight;

/// A small deterministic generator (SplitMix64): enough for scene layout
/// and Monte Carlo sampling, and it keeps the report free of a `rand`
/// dependency.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// SplitMix64's increment (the golden ratio in 64-bit fixed point).
    const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(Self::GAMMA);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    #[inline]
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[0, 1)` with 24 random bits.
    #[inline]
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// Uniform in `[lo, hi)`.
    #[inline]
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }
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
const TILTED_FRACTION: f32 = 0.25;
/// Range of the tilt of tilted normals, in degrees (below a right angle, so
/// every normal faces up).
const TILT_DEGREES: (f32, f32) = (15.0, 60.0);

/// `count` shading points uniform on the rectangle `[min, max]` of the
/// plane `z = 0`, normals up except for [`TILTED_FRACTION`] of them, views
/// towards `camera`.
fn floor_points(
    rng: &mut Rng,
    count: usize,
    min: Vec3,
    max: Vec3,
    camera: Vec3,
) -> Vec<ShadingPoint> {
    (0..count)
        .map(|_| {
            let point = Vec3::new(rng.range(min.x, max.x), rng.range(min.y, max.y), 0.0);
            let normal = if rng.f32() < TILTED_FRACTION {
                let tilt = rng.range(TILT_DEGREES.0, TILT_DEGREES.1).to_radians();
                let azimuth = rng.range(0.0, TAU);
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

/// The bounding rectangle of the lights' ground projection.
fn ground_extent(lights: &[PointLight]) -> (Vec3, Vec3) {
    let (min, max) = lights.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), l| (lo.min(l.position), hi.max(l.position)),
    );
    (min.with_z(0.0), max.with_z(0.0))
}

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
/// Radiant intensity of a street lamp.
const CITY_LAMP_INTENSITY: f32 = 40.0;
/// Fraction of white LED lamps; the rest are sodium orange.
const CITY_WHITE_FRACTION: f32 = 0.2;
const SODIUM: Vec3 = Vec3::new(1.0, 0.55, 0.2);
const LED_WHITE: Vec3 = Vec3::new(0.85, 0.9, 1.0);

/// Street lamps of a city grid, `count` of them. The density is fixed (one
/// block of [`CITY_BLOCK`] units square holds [`CITY_LAMPS_PER_BLOCK`]
/// lamps), so the city's area grows with `count`: blocks are filled row by
/// row on a square grid just large enough.
pub fn city_lights(count: usize, seed: u64) -> Vec<PointLight> {
    let mut rng = Rng::new(seed);
    let blocks_per_side = (count as f64 / CITY_LAMPS_PER_BLOCK as f64).sqrt().ceil() as usize;
    let per_street = (CITY_BLOCK / CITY_LAMP_SPACING) as usize;
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
                        let jitter = Vec3::new(
                            rng.range(-CITY_LAMP_JITTER, CITY_LAMP_JITTER),
                            rng.range(-CITY_LAMP_JITTER, CITY_LAMP_JITTER),
                            CITY_LAMP_HEIGHT.0 + rng.range(-CITY_LAMP_HEIGHT.1, CITY_LAMP_HEIGHT.1),
                        );
                        let colour = if rng.f32() < CITY_WHITE_FRACTION {
                            LED_WHITE
                        } else {
                            SODIUM
                        };
                        let intensity = CITY_LAMP_INTENSITY * rng.range(0.8, 1.2);
                        lights.push(PointLight::new(
                            corner + nominal + jitter,
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
    let (min, max) = ground_extent(&lights);
    let mut rng = Rng::new(seed ^ 0xC17);
    let camera = (min + max) * 0.5 + Vec3::new(0.0, 0.0, 500.0);
    let points = floor_points(&mut rng, points, min, max, camera);
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
        material: Material {
            kd: Vec3::splat(0.5),
            specular: None,
        },
    }
}

/// Number of tiers (rings) of the chandelier.
const CHANDELIER_TIERS: usize = 6;
/// Radius of the lowest tier and growth per tier.
const CHANDELIER_RADIUS: (f32, f32) = (0.4, 0.3);
/// Height of the lowest tier and rise per tier.
const CHANDELIER_HEIGHT: (f32, f32) = (3.8, 0.25);
/// Random displacement of a crystal light about its ring.
const CHANDELIER_SPREAD: f32 = 0.06;
/// Half-size of the square room floor under the chandelier.
const ROOM_HALF_SIZE: f32 = 8.0;
/// Total radiant intensity of the chandelier (shared by its lights).
const CHANDELIER_POWER: f32 = 600.0;
const WARM_WHITE: Vec3 = Vec3::new(1.0, 0.85, 0.6);

/// `chandelier`: a dense cluster of `lights` lights on [`CHANDELIER_TIERS`]
/// rings within a ball of radius about 2 units, 4-5 units above a floor;
/// shading points on the room's floor.
pub fn chandelier(lights: usize, points: usize, seed: u64) -> Scene {
    let mut rng = Rng::new(seed);
    let radii: Vec<f32> = (0..CHANDELIER_TIERS)
        .map(|t| CHANDELIER_RADIUS.0 + CHANDELIER_RADIUS.1 * t as f32)
        .collect();
    let total_radius: f32 = radii.iter().sum();
    let per_light = CHANDELIER_POWER / lights as f32;
    let mut all = Vec::with_capacity(lights);
    for (t, &radius) in radii.iter().enumerate() {
        // Lights per tier in proportion to its circumference; the last tier
        // takes the remainder.
        let n = if t + 1 == CHANDELIER_TIERS {
            lights - all.len()
        } else {
            (lights as f32 * radius / total_radius) as usize
        };
        let height = CHANDELIER_HEIGHT.0 + CHANDELIER_HEIGHT.1 * t as f32;
        for k in 0..n {
            let angle = TAU * k as f32 / n as f32;
            let r = radius + rng.range(-CHANDELIER_SPREAD, CHANDELIER_SPREAD);
            let position = Vec3::new(
                r * angle.cos(),
                r * angle.sin(),
                height + rng.range(-CHANDELIER_SPREAD, CHANDELIER_SPREAD),
            );
            let tint = Vec3::new(1.0, rng.range(0.9, 1.1), rng.range(0.8, 1.2));
            all.push(PointLight::new(position, WARM_WHITE * tint * per_light));
        }
    }
    let mut rng = Rng::new(seed ^ 0xC4A);
    let half = Vec3::new(ROOM_HALF_SIZE, ROOM_HALF_SIZE, 0.0);
    let points = floor_points(
        &mut rng,
        points,
        -half,
        half,
        Vec3::new(0.0, -ROOM_HALF_SIZE, 3.0),
    );
    Scene {
        name: "chandelier",
        description: format!(
            "{} lights on {CHANDELIER_TIERS} rings (radius {:.1}-{:.1}, height {:.2}-{:.2}), \
             floor {}x{}",
            all.len(),
            radii[0],
            radii[CHANDELIER_TIERS - 1],
            CHANDELIER_HEIGHT.0,
            CHANDELIER_HEIGHT.0 + CHANDELIER_HEIGHT.1 * (CHANDELIER_TIERS - 1) as f32,
            2.0 * ROOM_HALF_SIZE,
            2.0 * ROOM_HALF_SIZE
        ),
        lights: all,
        points,
        material: Material {
            kd: Vec3::new(0.6, 0.5, 0.4),
            specular: None,
        },
    }
}

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

/// `count` bulbs evenly spaced in the parameter of `curve` on `[0, 1]`,
/// colours cycling through [`BULB_COLOURS`].
fn string_of_lights(count: usize, curve: impl Fn(f32) -> Vec3) -> impl Iterator<Item = PointLight> {
    (0..count).map(move |k| {
        let s = (k as f32 + 0.5) / count as f32;
        PointLight::new(
            curve(s),
            BULB_COLOURS[k % BULB_COLOURS.len()] * BULB_INTENSITY,
        )
    })
}

/// A hanging string between `a` and `b`, sagging by `sag` in the middle
/// (a parabola, close enough to a catenary).
fn hanging(a: Vec3, b: Vec3, sag: f32) -> impl Fn(f32) -> Vec3 {
    move |s| a.lerp(b, s) - Vec3::Z * (4.0 * sag * s * (1.0 - s))
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

/// `strings`: the paper's Christmas lights: `lights` bulbs along
/// [`TREE_HELICES`] helices wound around a conical tree and [`GARLANDS`]
/// long garlands hanging from its top to poles; shading points on the
/// ground around it.
pub fn strings(lights: usize, points: usize, seed: u64) -> Scene {
    let on_tree = lights / 2;
    let mut all = Vec::with_capacity(lights);
    for h in 0..TREE_HELICES {
        let n = on_tree / TREE_HELICES + usize::from(h < on_tree % TREE_HELICES);
        let phase = TAU * h as f32 / TREE_HELICES as f32;
        all.extend(string_of_lights(n, |s| {
            let angle = phase + TAU * TREE_TURNS * s;
            let radius = TREE_BASE_RADIUS * (1.0 - s);
            Vec3::new(
                radius * angle.cos(),
                radius * angle.sin(),
                TREE_BASE + TREE_HEIGHT * s,
            )
        }));
    }
    let on_garlands = lights - on_tree;
    for g in 0..GARLANDS {
        let n = on_garlands / GARLANDS + usize::from(g < on_garlands % GARLANDS);
        let angle = TAU * g as f32 / GARLANDS as f32;
        let direction = Vec3::new(angle.cos(), angle.sin(), 0.0);
        let top = direction * 0.1 * TREE_BASE_RADIUS + Vec3::Z * GARLAND_TOP;
        let pole = direction * GARLAND_POLE_DISTANCE + Vec3::Z * GARLAND_POLE_HEIGHT;
        all.extend(string_of_lights(n, hanging(top, pole, GARLAND_SAG)));
    }
    let mut rng = Rng::new(seed);
    let half = Vec3::new(STRINGS_GROUND_HALF_SIZE, STRINGS_GROUND_HALF_SIZE, 0.0);
    let points = floor_points(&mut rng, points, -half, half, Vec3::new(0.0, -40.0, 8.0));
    Scene {
        name: "strings",
        description: format!(
            "{} bulbs in 5 colours: {TREE_HELICES} helices on a {TREE_HEIGHT}-unit conical tree, \
             {GARLANDS} garlands to poles {GARLAND_POLE_DISTANCE} units away",
            all.len()
        ),
        lights: all,
        points,
        material: Material {
            kd: Vec3::splat(0.8),
            specular: None,
        },
    }
}

/// Festoon strings over a plaza: this many parallel strings between poles
/// at `x = -+half span`, spread over this range of `y`.
const FESTOON_STRINGS: usize = 8;
const FESTOON_HALF_SPAN: f32 = 20.0;
const FESTOON_HALF_WIDTH: f32 = 14.0;
const FESTOON_POLE_HEIGHT: f32 = 6.0;
const FESTOON_SAG: f32 = 1.5;
/// Half-size of the shaded square of glossy floor.
const PLAZA_HALF_SIZE: f32 = 12.0;
/// Where the camera looks from.
const PLAZA_CAMERA: Vec3 = Vec3::new(0.0, -30.0, 10.0);
/// Phong exponent of the glossy floor.
pub const GLOSSY_EXPONENT: u32 = 100;

/// `specular`: `lights` bulbs on [`FESTOON_STRINGS`] strings hanging over a
/// glossy floor (Lambert `kd = 0.2` plus Phong `ks = 0.6`, exponent
/// [`GLOSSY_EXPONENT`]), seen from a camera.
pub fn specular(lights: usize, points: usize, seed: u64) -> Scene {
    let mut rng = Rng::new(seed);
    let mut all = Vec::with_capacity(lights);
    for k in 0..FESTOON_STRINGS {
        let n = lights / FESTOON_STRINGS + usize::from(k < lights % FESTOON_STRINGS);
        let y = -FESTOON_HALF_WIDTH
            + 2.0 * FESTOON_HALF_WIDTH * k as f32 / (FESTOON_STRINGS - 1) as f32;
        // Poles at slightly different heights, so the strings are not coplanar.
        let a = Vec3::new(
            -FESTOON_HALF_SPAN,
            y,
            FESTOON_POLE_HEIGHT + rng.range(-0.5, 0.5),
        );
        let b = Vec3::new(
            FESTOON_HALF_SPAN,
            y,
            FESTOON_POLE_HEIGHT + rng.range(-0.5, 0.5),
        );
        all.extend(string_of_lights(n, hanging(a, b, FESTOON_SAG)));
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
