//! `room`: instant radiosity (Keller 1997) in a furnished room. A few
//! primary lights (spots in the ceiling aimed down, a floor lamp) shoot
//! rays that the report's ray tracer (boxes in an `obvhs` BVH) follows to
//! their first hit; each hit becomes a virtual point light (VPL), a cosine
//! lobe about the surface's normal carrying the ray's flux times the
//! surface's albedo. The primary lights and the VPLs are shaded together,
//! one tree of mixed profiles.
//!
//! Walls, floor and ceiling are slabs around the room's interior, so every
//! surface a ray can hit is the entry face of a box, whose normal faces into
//! the room. VPLs sit [`VPL_OFFSET`] off their surface and shading points
//! [`POINT_OFFSET`] off theirs, so that a shadow segment between the two
//! never touches the boxes they lie on (the shadow host grows boxes by its
//! margin before declaring a miss).

use std::f32::consts::{PI, TAU};

use glam::Vec3;
use manylights::{Aabb, Emission, Emitter, PointLight};
use rand::RngExt;

use super::rng;
use crate::bvh::{Occluders, entry_normal};

/// The room's interior: `[0, SIZE.x] x [0, SIZE.y] x [0, SIZE.z]`.
pub const ROOM_SIZE: Vec3 = Vec3::new(10.0, 7.0, 3.0);
/// Thickness of the walls' slabs.
const WALL: f32 = 0.2;
/// How far a VPL sits off the surface it lies on.
pub const VPL_OFFSET: f32 = 0.03;
/// How far a shading point sits off the surface it lies on.
pub const POINT_OFFSET: f32 = 0.03;
/// Seed offset of the shading points (the VPLs use the seed).
const POINTS_SEED: u64 = 0x800;

/// A box of the room with its diffuse albedo.
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    /// The box.
    pub aabb: Aabb,
    /// Its albedo.
    pub albedo: Vec3,
}

/// A primary light: where it is and what it emits.
#[derive(Clone, Copy, Debug)]
struct Primary {
    position: Vec3,
    intensity: Vec3,
    /// The axis and outer angle of a spot, `None` for an isotropic lamp.
    spot: Option<(Vec3, f32, f32)>,
}

/// The room: its boxes, their BVH, the primary lights.
pub struct Room {
    /// Walls, floor, ceiling and furniture.
    pub surfaces: Vec<Surface>,
    /// The same boxes in a BVH.
    pub occluders: Occluders,
    primaries: Vec<Primary>,
}

fn aabb(min: Vec3, max: Vec3) -> Aabb {
    Aabb { min, max }
}

impl Room {
    /// The furnished room with its primary lights.
    pub fn new() -> Self {
        let s = ROOM_SIZE;
        let wall = Vec3::new(0.82, 0.8, 0.74);
        let mut surfaces = vec![
            // Floor (warm wood), ceiling, four walls (one a muted blue).
            Surface {
                aabb: aabb(
                    Vec3::new(-WALL, -WALL, -WALL),
                    Vec3::new(s.x + WALL, s.y + WALL, 0.0),
                ),
                albedo: Vec3::new(0.55, 0.38, 0.22),
            },
            Surface {
                aabb: aabb(
                    Vec3::new(-WALL, -WALL, s.z),
                    Vec3::new(s.x + WALL, s.y + WALL, s.z + WALL),
                ),
                albedo: Vec3::splat(0.85),
            },
            Surface {
                aabb: aabb(
                    Vec3::new(-WALL, -WALL, 0.0),
                    Vec3::new(0.0, s.y + WALL, s.z),
                ),
                albedo: Vec3::new(0.35, 0.45, 0.7),
            },
            Surface {
                aabb: aabb(
                    Vec3::new(s.x, -WALL, 0.0),
                    Vec3::new(s.x + WALL, s.y + WALL, s.z),
                ),
                albedo: wall,
            },
            Surface {
                aabb: aabb(Vec3::new(0.0, -WALL, 0.0), Vec3::new(s.x, 0.0, s.z)),
                albedo: wall,
            },
            Surface {
                aabb: aabb(Vec3::new(0.0, s.y, 0.0), Vec3::new(s.x, s.y + WALL, s.z)),
                albedo: wall,
            },
        ];
        // Furniture: a table, a red sofa, a tall cabinet, a pillar.
        let furniture = [
            (
                Vec3::new(3.5, 2.5, 0.72),
                Vec3::new(5.5, 3.7, 0.78),
                Vec3::new(0.6, 0.6, 0.6),
            ),
            (
                Vec3::new(3.6, 2.6, 0.0),
                Vec3::new(3.7, 2.7, 0.72),
                Vec3::splat(0.3),
            ),
            (
                Vec3::new(5.3, 3.5, 0.0),
                Vec3::new(5.4, 3.6, 0.72),
                Vec3::splat(0.3),
            ),
            (
                Vec3::new(1.0, 5.6, 0.0),
                Vec3::new(3.8, 6.8, 0.8),
                Vec3::new(0.7, 0.15, 0.12),
            ),
            (
                Vec3::new(8.6, 0.2, 0.0),
                Vec3::new(9.8, 1.0, 2.2),
                Vec3::new(0.45, 0.6, 0.4),
            ),
            (
                Vec3::new(6.6, 4.6, 0.0),
                Vec3::new(7.1, 5.1, 3.0),
                Vec3::splat(0.9),
            ),
        ];
        for (min, max, albedo) in furniture {
            surfaces.push(Surface {
                aabb: aabb(min, max),
                albedo,
            });
        }
        let boxes: Vec<Aabb> = surfaces.iter().map(|s| s.aabb).collect();
        let down = Vec3::NEG_Z;
        let warm = Vec3::new(1.0, 0.85, 0.65);
        let primaries = vec![
            Primary {
                position: Vec3::new(2.5, 2.0, 2.9),
                intensity: warm * 60.0,
                spot: Some((down, 0.35, 0.7)),
            },
            Primary {
                position: Vec3::new(4.5, 3.1, 2.9),
                intensity: warm * 80.0,
                spot: Some((Vec3::new(0.0, 0.1, -1.0), 0.3, 0.6)),
            },
            Primary {
                position: Vec3::new(7.5, 2.0, 2.9),
                intensity: warm * 60.0,
                spot: Some((Vec3::new(0.2, -0.1, -1.0), 0.35, 0.7)),
            },
            // A floor lamp beside the sofa.
            Primary {
                position: Vec3::new(0.6, 6.2, 1.6),
                intensity: Vec3::new(1.0, 0.8, 0.55) * 8.0,
                spot: None,
            },
        ];
        Self {
            occluders: Occluders::new(&boxes),
            surfaces,
            primaries,
        }
    }

    /// The primary lights as emitters.
    pub fn primary_lights(&self) -> Vec<Emitter> {
        self.primaries
            .iter()
            .map(|p| {
                let emission = match p.spot {
                    Some((axis, inner, outer)) => Emission::spot(axis, inner, outer),
                    None => Emission::Isotropic,
                };
                PointLight::new(p.position, p.intensity).with_emission(emission)
            })
            .collect()
    }

    /// The surface hit first by the ray from `origin` along `dir`, with
    /// the hit point snapped onto the face and the face's normal (into the
    /// room).
    pub fn hit(&self, origin: Vec3, dir: Vec3) -> Option<(Vec3, Vec3, &Surface)> {
        let (t, id) = self.occluders.nearest(origin, dir)?;
        let surface = &self.surfaces[id];
        let b = &surface.aabb;
        let normal = entry_normal(origin, dir.recip(), b, dir);
        let mut at = origin + dir * t;
        // Onto the face's plane exactly, and within the face.
        for k in 0..3 {
            if normal[k] > 0.0 {
                at[k] = b.max[k];
            } else if normal[k] < 0.0 {
                at[k] = b.min[k];
            } else {
                at[k] = at[k].clamp(b.min[k], b.max[k]);
            }
        }
        Some((at, normal, surface))
    }

    /// The primary lights and `count` VPLs traced from them (first bounce),
    /// each primary shooting rays in proportion to its power.
    pub fn emitters(&self, count: usize, seed: u64) -> Vec<Emitter> {
        let mut rng = rng(seed);
        let mut out = self.primary_lights();
        // Each primary's power (largest channel) over the directions it
        // emits into: `I * Omega` for a spot's cone (uniform in solid angle
        // within the outer angle, the profile weighting each ray), `4 pi I`
        // for a lamp.
        let solid = |p: &Primary| match p.spot {
            Some((_, _, outer)) => TAU * (1.0 - outer.cos()),
            None => 4.0 * PI,
        };
        let powers: Vec<f32> = self
            .primaries
            .iter()
            .map(|p| p.intensity.max_element() * solid(p))
            .collect();
        let total: f32 = powers.iter().sum();
        for (p, power) in self.primaries.iter().zip(&powers) {
            let rays = ((count as f32 * power / total).round() as usize).max(1);
            let omega = solid(p);
            let emission = match p.spot {
                Some((axis, inner, outer)) => Emission::spot(axis, inner, outer),
                None => Emission::Isotropic,
            };
            let mut made = 0;
            while made < rays {
                let (dir, frame) = match p.spot {
                    Some((axis, _, outer)) => {
                        let z = rng.random_range(outer.cos()..1.0);
                        (
                            cone_direction(axis.normalize(), z, rng.random_range(0.0..TAU)),
                            omega,
                        )
                    }
                    None => {
                        let z = rng.random_range(-1.0f32..1.0);
                        (
                            cone_direction(Vec3::Z, z, rng.random_range(0.0..TAU)),
                            omega,
                        )
                    }
                };
                let Some((at, normal, surface)) = self.hit(p.position, dir) else {
                    continue;
                };
                made += 1;
                let f = emission.factor(p.position, p.position + dir) as f32;
                // Flux of the ray, reflected diffusely: a cosine lobe of
                // peak intensity `albedo * flux / pi`.
                let flux = p.intensity * (f * frame / rays as f32);
                let intensity = surface.albedo * flux / PI;
                if intensity.max_element() > 0.0 {
                    out.push(
                        PointLight::new(at + normal * VPL_OFFSET, intensity)
                            .with_emission(Emission::cosine(normal, 1.0)),
                    );
                }
            }
        }
        out
    }

    /// `count` shading points on the room's surfaces (hits of random rays
    /// from random places inside it), [`POINT_OFFSET`] off them, with their
    /// normals.
    pub fn points(&self, count: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
        let mut rng = rng(seed ^ POINTS_SEED);
        let mut points = Vec::with_capacity(count);
        while points.len() < count {
            let from = Vec3::new(
                rng.random_range(0.2..ROOM_SIZE.x - 0.2),
                rng.random_range(0.2..ROOM_SIZE.y - 0.2),
                rng.random_range(0.9..ROOM_SIZE.z - 0.2),
            );
            let dir = cone_direction(
                Vec3::Z,
                rng.random_range(-1.0f32..1.0),
                rng.random_range(0.0..TAU),
            );
            if let Some((at, normal, _)) = self.hit(from, dir) {
                points.push((at + normal * POINT_OFFSET, normal));
            }
        }
        points
    }
}

impl Default for Room {
    fn default() -> Self {
        Self::new()
    }
}

/// The direction at cosine `z` from the unit `axis`, turned by `phi`
/// about it.
fn cone_direction(axis: Vec3, z: f32, phi: f32) -> Vec3 {
    let (u, v) = axis.any_orthonormal_pair();
    let s = (1.0 - z * z).max(0.0).sqrt();
    (axis * z + u * (s * phi.cos()) + v * (s * phi.sin())).normalize()
}

/// The same VPLs and primary lights with every profile made isotropic:
/// the lights at the same places as the tree would shade them if it knew
/// nothing of orientation.
pub fn isotropic(emitters: &[Emitter]) -> Vec<PointLight> {
    emitters.iter().map(|e| e.light).collect()
}
