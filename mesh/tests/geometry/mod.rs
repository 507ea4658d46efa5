//! Scenes of the tests: triangle soups, closed meshes (boxes, spheres) and a
//! grid of buildings made of triangles, generated from a seed.

use glam::Vec3;
use manylights::Aabb;

/// A small reproducible generator (xorshift64*).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    pub fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// A box centred in the cube of half-size `reach`, half-extents up to
    /// `half`, each axis flat with probability `flat`.
    pub fn boxed(&mut self, reach: f32, half: f32, flat: f32) -> Aabb {
        let centre = self.vec(-reach, reach);
        let extent = Vec3::from_array(std::array::from_fn(|_| {
            if self.unit() < flat {
                0.0
            } else {
                self.range(0.01, half)
            }
        }));
        Aabb {
            min: centre - extent,
            max: centre + extent,
        }
    }

    /// A point in the box `b`.
    pub fn in_box(&mut self, b: &Aabb) -> Vec3 {
        b.min + (b.max - b.min) * Vec3::new(self.unit(), self.unit(), self.unit())
    }
}

/// An indexed mesh.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub indices: Vec<u32>,
}

impl Mesh {
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.indices.extend(other.indices.iter().map(|i| i + base));
    }
}

/// The closed surface of a box, 12 triangles wound outwards (the crate's
/// [`box_mesh`](manylights_mesh::box_mesh)).
pub fn box_mesh(b: &Aabb) -> Mesh {
    let (positions, indices) = manylights_mesh::box_mesh(b);
    Mesh {
        positions: positions.to_vec(),
        indices: indices.to_vec(),
    }
}

/// A closed UV sphere of `rings` x `segments` quads (the poles fans).
pub fn sphere_mesh(centre: Vec3, radius: f32, rings: u32, segments: u32) -> Mesh {
    let mut positions = vec![centre + Vec3::Z * radius];
    for r in 1..rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            let dir = Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            positions.push(centre + dir * radius);
        }
    }
    positions.push(centre - Vec3::Z * radius);
    let bottom = positions.len() as u32 - 1;
    let at = |r: u32, s: u32| 1 + (r - 1) * segments + s % segments;
    let mut indices = Vec::new();
    for s in 0..segments {
        indices.extend([0, at(1, s), at(1, s + 1)]);
        indices.extend([bottom, at(rings - 1, s + 1), at(rings - 1, s)]);
    }
    for r in 1..rings - 1 {
        for s in 0..segments {
            let (a, b, c, d) = (at(r, s), at(r + 1, s), at(r + 1, s + 1), at(r, s + 1));
            indices.extend([a, b, c, a, c, d]);
        }
    }
    Mesh { positions, indices }
}

/// A `n x n` grid of box buildings of random heights on a pitch of
/// `pitch`, as one mesh, and their boxes.
pub fn buildings(rng: &mut Rng, n: u32, pitch: f32) -> (Mesh, Vec<Aabb>) {
    let mut mesh = Mesh::default();
    let mut boxes = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let origin = Vec3::new(i as f32, j as f32, 0.0) * pitch;
            let size = pitch * rng.range(0.4, 0.8);
            let b = Aabb {
                min: origin,
                max: origin + Vec3::new(size, size, rng.range(2.0, 3.0 * pitch)),
            };
            mesh.append(&box_mesh(&b));
            boxes.push(b);
        }
    }
    (mesh, boxes)
}

/// `count` random triangles in the cube of half-size `reach`, edges up to
/// `size`.
pub fn soup(rng: &mut Rng, count: usize, reach: f32, size: f32) -> Vec<[Vec3; 3]> {
    (0..count)
        .map(|_| {
            let a = rng.vec(-reach, reach);
            [a, a + rng.vec(-size, size), a + rng.vec(-size, size)]
        })
        .collect()
}

/// Points of `b` a brute force casts rays to: corners, a grid, random points.
pub fn box_points(rng: &mut Rng, b: &Aabb, grid: usize, random: usize) -> Vec<Vec3> {
    let at = |i: usize| i as f32 / (grid - 1).max(1) as f32;
    let mut points = manylights_mesh::corners(b).to_vec();
    for i in 0..grid {
        for j in 0..grid {
            for k in 0..grid {
                points.push(b.min + (b.max - b.min) * Vec3::new(at(i), at(j), at(k)));
            }
        }
    }
    points.extend((0..random).map(|_| rng.in_box(b)));
    points
}
