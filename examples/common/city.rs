//! The night-city scene of the `city` and `report` examples:
//! street lamps along a grid of streets, lit windows, box buildings on a
//! ground plane, ray casting through a small bounding-volume hierarchy over
//! the buildings, and `Shadows`, the host's conservative visibility
//! classifier.
//!
//! Included with `#[path = "common/city.rs"] mod city;` beside
//! `common/mod.rs`.

// Shared by several examples, each of which uses a part.
#![allow(dead_code)]

use std::cell::Cell;

use glam::Vec3;
use manylights::{Aabb, Coverage, NodeBounds, PointLight, Visibility};
use rayon::prelude::*;

use crate::common::Camera;

// ---------------------------------------------------------------------------
// Deterministic random numbers
// ---------------------------------------------------------------------------

/// SplitMix64: a tiny deterministic generator, so every run builds the same
/// city.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`, 24 random bits.
    fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in `[lo, hi)`.
    fn range(&mut self, (lo, hi): (f32, f32)) -> f32 {
        lo + (hi - lo) * self.uniform()
    }
}

// ---------------------------------------------------------------------------
// The city
// ---------------------------------------------------------------------------

/// Seed of the city's layout and light colours.
const CITY_SEED: u64 = 1998;
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
/// Lamp brightness varies by this factor range.
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
const COOL_WINDOW_SHARE: f32 = 0.15;
/// Share of the blocks left without a building (squares, parks).
const PARK_SHARE: f32 = 0.08;
/// Share of the built blocks split in two buildings with an alley between.
const SPLIT_SHARE: f32 = 0.4;
/// Width of the alley between the two halves of a split block.
const ALLEY_WIDTH: f32 = 3.0;
/// Building heights: `min + (max - min) * u^3`, mostly low with a few towers.
const BUILDING_HEIGHT: (f32, f32) = (6.0, 60.0);
/// Albedos: asphalt, and façades of varying brightness.
const GROUND_ALBEDO: Vec3 = Vec3::new(0.4, 0.4, 0.42);
const FACADE_ALBEDO: (f32, f32) = (0.15, 0.35);

/// A box building and its colour.
#[derive(Clone, Copy, Debug)]
pub struct Building {
    /// Footprint times height, standing on the ground `z = 0`.
    pub bounds: Aabb,
    /// Diffuse albedo of its walls and roof.
    pub albedo: Vec3,
}

/// A city at night: street lamps along a square grid of streets, lit windows
/// on the façades, box buildings on the blocks, all on the ground plane
/// `z = 0`, with `+z` up. A city of `blocks x blocks` blocks covers
/// `[0, blocks * BLOCK_PITCH]` in `x` and `y`; street centre lines run at
/// the multiples of [`BLOCK_PITCH`].
pub struct City {
    /// Street lamps first, then windows.
    pub lights: Vec<PointLight>,
    /// The buildings.
    pub buildings: Vec<Building>,
    /// Hierarchy over the buildings' boxes.
    pub bvh: Bvh,
}

impl City {
    /// Builds a city of `blocks x blocks` blocks with exactly `light_count`
    /// lights: a [`WINDOW_SHARE`] of lit windows (or every window, if there
    /// are fewer), the rest street lamps spread evenly along the streets.
    pub fn new(blocks: u32, light_count: usize) -> City {
        let mut rng = Rng(CITY_SEED);
        let buildings = buildings(&mut rng, blocks);
        let window_count = (light_count as f64 * WINDOW_SHARE).round() as usize;
        let windows = windows(&mut rng, &buildings, window_count);
        let mut lights = street_lamps(&mut rng, blocks, light_count - windows.len());
        lights.extend(windows);
        let boxes: Vec<Aabb> = buildings.iter().map(|b| b.bounds).collect();
        City {
            lights,
            bvh: Bvh::new(&boxes),
            buildings,
        }
    }

    /// The nearest surface hit by the ray `origin + t * dir`, `t > 0`.
    pub fn intersect(&self, origin: Vec3, dir: Vec3) -> Option<Hit> {
        let inv_dir = dir.recip();
        let ground_t = if dir.z < 0.0 {
            -origin.z / dir.z
        } else {
            f32::INFINITY
        };
        let nearest = Cell::new((ground_t, None::<usize>));
        self.bvh.any(
            |b| {
                let (near, far) = slab(origin, inv_dir, b);
                near <= far && far > 0.0 && near < nearest.get().0
            },
            |i| {
                let (near, far) = slab(origin, inv_dir, &self.buildings[i].bounds);
                if near <= far && near > 0.0 && near < nearest.get().0 {
                    nearest.set((near, Some(i)));
                }
                false
            },
        );
        let (t, building) = nearest.get();
        if !t.is_finite() {
            return None;
        }
        let point = origin + dir * t;
        Some(match building {
            None => Hit {
                point,
                normal: Vec3::Z,
                albedo: GROUND_ALBEDO,
            },
            Some(i) => {
                let b = &self.buildings[i];
                Hit {
                    point,
                    normal: entry_normal(origin, inv_dir, &b.bounds, dir),
                    albedo: b.albedo,
                }
            }
        })
    }

    /// Casts one primary ray per pixel of `camera`'s image (rows in
    /// parallel): the hit of each pixel in row-major order, `None` for the
    /// sky.
    pub fn trace(&self, camera: &Camera) -> Vec<Option<Hit>> {
        let mut hits = vec![None; (camera.width * camera.height) as usize];
        hits.par_chunks_mut(camera.width as usize)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, hit) in row.iter_mut().enumerate() {
                    *hit = self.intersect(camera.eye, camera.ray(x as u32, y as u32));
                }
            });
        hits
    }
}

/// One or two buildings per block, with a few empty blocks.
fn buildings(rng: &mut Rng, blocks: u32) -> Vec<Building> {
    let mut buildings = Vec::new();
    let lot = BLOCK_PITCH - STREET_WIDTH - 2.0 * PAVEMENT;
    for bx in 0..blocks {
        for by in 0..blocks {
            if rng.uniform() < PARK_SHARE {
                continue;
            }
            let x0 = bx as f32 * BLOCK_PITCH + 0.5 * STREET_WIDTH + PAVEMENT;
            let y0 = by as f32 * BLOCK_PITCH + 0.5 * STREET_WIDTH + PAVEMENT;
            let whole = Aabb {
                min: Vec3::new(x0, y0, 0.0),
                max: Vec3::new(x0 + lot, y0 + lot, 0.0),
            };
            let parts = if rng.uniform() < SPLIT_SHARE {
                let axis = usize::from(rng.uniform() < 0.5);
                let cut = whole.min[axis] + lot * rng.range((0.3, 0.7));
                let (mut first, mut second) = (whole, whole);
                first.max[axis] = cut - 0.5 * ALLEY_WIDTH;
                second.min[axis] = cut + 0.5 * ALLEY_WIDTH;
                vec![first, second]
            } else {
                vec![whole]
            };
            for mut bounds in parts {
                let u = rng.uniform();
                bounds.max.z =
                    BUILDING_HEIGHT.0 + (BUILDING_HEIGHT.1 - BUILDING_HEIGHT.0) * u * u * u;
                let grey = rng.range(FACADE_ALBEDO);
                let tint = Vec3::new(1.0, rng.range((0.9, 1.0)), rng.range((0.8, 1.0)));
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
fn street_lamps(rng: &mut Rng, blocks: u32, count: usize) -> Vec<PointLight> {
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
            let position = Vec3::new(x, y, rng.range(LAMP_HEIGHT));
            let colour = SODIUM.lerp(WARM_WHITE, rng.uniform());
            let intensity = colour * LAMP_INTENSITY * rng.range(LAMP_VARIATION);
            PointLight::new(position, intensity)
        })
        .collect()
}

/// `count` lit windows (at most one per slot) chosen uniformly among the
/// window slots of every façade (selection sampling: each slot is taken with
/// probability `still needed / slots left`, which yields exactly `count`
/// when there are enough slots).
fn windows(rng: &mut Rng, buildings: &[Building], count: usize) -> Vec<PointLight> {
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
        let left = (slots.len() - taken_from) as f32;
        let needed = count.saturating_sub(lights.len()) as f32;
        if rng.uniform() * left < needed {
            let colour = if rng.uniform() < COOL_WINDOW_SHARE {
                WINDOW_COOL
            } else {
                WINDOW_WARM
            };
            let intensity = colour * WINDOW_INTENSITY * rng.range(LAMP_VARIATION);
            lights.push(PointLight::new(*position, intensity));
        }
    }
    lights
}

// ---------------------------------------------------------------------------
// Ray casting
// ---------------------------------------------------------------------------

/// A primary-ray hit: the shading point, its outward normal, its albedo.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Point on the surface.
    pub point: Vec3,
    /// Unit outward normal.
    pub normal: Vec3,
    /// Diffuse albedo.
    pub albedo: Vec3,
}

/// Parameter interval `(near, far)` over which `origin + t * dir` lies in the
/// closed box `b` (empty when `near > far`), from `inv_dir = 1 / dir`.
///
/// A zero direction component makes `inv_dir` infinite, which the slab
/// arithmetic handles, except for an origin exactly in the plane of a face
/// parallel to the ray: there `0 * inf = NaN`, `f32::min` / `f32::max` keep
/// the infinite lane, and the ray (grazing the face in its plane) misses.
pub fn slab(origin: Vec3, inv_dir: Vec3, b: &Aabb) -> (f32, f32) {
    let t0 = (b.min - origin) * inv_dir;
    let t1 = (b.max - origin) * inv_dir;
    (t0.min(t1).max_element(), t0.max(t1).min_element())
}

/// Outward normal of the face of `b` through which the ray enters it.
fn entry_normal(origin: Vec3, inv_dir: Vec3, b: &Aabb, dir: Vec3) -> Vec3 {
    let t0 = (b.min - origin) * inv_dir;
    let t1 = (b.max - origin) * inv_dir;
    let near = t0.min(t1);
    let axis = if near.x >= near.y && near.x >= near.z {
        0
    } else if near.y >= near.z {
        1
    } else {
        2
    };
    let mut normal = Vec3::ZERO;
    normal[axis] = -dir[axis].signum();
    normal
}

/// Largest number of boxes in a BVH leaf.
const BVH_LEAF_SIZE: usize = 4;
/// Traversal stack depth: median splits give depth `log2(boxes / leaf) + 1`,
/// so 64 covers any box count that fits in memory.
const BVH_STACK: usize = 64;

/// A node of [`Bvh`]: a leaf holds `count > 0` boxes from `start` in
/// `Bvh::items`; an inner node (`count == 0`) has its first child right after
/// it and its second at `start`.
#[derive(Clone, Copy, Debug)]
struct BvhNode {
    bounds: Aabb,
    start: u32,
    count: u32,
}

/// A bounding-volume hierarchy over boxes, split at the median of the longest
/// axis of the centres.
pub struct Bvh {
    nodes: Vec<BvhNode>,
    items: Vec<u32>,
}

impl Bvh {
    /// Builds the hierarchy over `boxes` (referred to by index).
    pub fn new(boxes: &[Aabb]) -> Bvh {
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * boxes.len() / BVH_LEAF_SIZE + 1),
            items: (0..boxes.len() as u32).collect(),
        };
        if !boxes.is_empty() {
            bvh.split(boxes, 0, boxes.len());
        }
        bvh
    }

    fn split(&mut self, boxes: &[Aabb], start: usize, end: usize) -> usize {
        let items = &mut self.items[start..end];
        let bounds = items
            .iter()
            .map(|&i| boxes[i as usize])
            .reduce(union)
            .expect("split of an empty range");
        let index = self.nodes.len();
        self.nodes.push(BvhNode {
            bounds,
            start: start as u32,
            count: items.len() as u32,
        });
        if items.len() <= BVH_LEAF_SIZE {
            return index;
        }
        let centre = |i: &u32| boxes[*i as usize].min + boxes[*i as usize].max;
        let extent = bounds.max - bounds.min;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |a, b| centre(a)[axis].total_cmp(&centre(b)[axis]));
        self.split(boxes, start, start + mid);
        let second = self.split(boxes, start + mid, end);
        self.nodes[index].start = second as u32;
        self.nodes[index].count = 0;
        index
    }

    /// Depth-first search: descends into every node whose box passes `enter`
    /// and calls `visit` on each box index of the leaves reached, until
    /// `visit` returns `true` (then `any` returns `true`).
    pub fn any(
        &self,
        mut enter: impl FnMut(&Aabb) -> bool,
        mut visit: impl FnMut(usize) -> bool,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let mut stack = [0u32; BVH_STACK];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let index = stack[top];
            let node = &self.nodes[index as usize];
            if !enter(&node.bounds) {
                continue;
            }
            if node.count > 0 {
                let leaf = &self.items[node.start as usize..(node.start + node.count) as usize];
                if leaf.iter().any(|&i| visit(i as usize)) {
                    return true;
                }
            } else {
                // The first child is popped first.
                stack[top] = node.start;
                stack[top + 1] = index + 1;
                top += 2;
            }
        }
        false
    }
}

/// Smallest box holding both.
pub fn union(a: Aabb, b: Aabb) -> Aabb {
    Aabb {
        min: a.min.min(b.min),
        max: a.max.max(b.max),
    }
}

// ---------------------------------------------------------------------------
// Visibility: the host's Warnock-style classifier and shadow rays
// ---------------------------------------------------------------------------

/// Shadow rays start this far off the surface along its normal, so that a
/// point on a wall is not occluded by its own building. It is part of the
/// host's definition of visibility, used alike by the tree's queries and by
/// the exact sum.
pub const SHADOW_OFFSET: f32 = 0.05;
/// Safety margin of the classifier, in scene units. Coordinates stay below
/// 1,000, where an `f32` ulp is at most `6.1e-5`; the slab tests and the
/// shaft slices' corners err by a few ulps. Occluders are inflated by the
/// margin before a shaft is declared `Visible` and shrunk by it before it is
/// declared `Occluded`, so rounding cannot turn a conservative answer into a
/// wrong one.
pub const MARGIN: f32 = 0.01;

/// Slices of a shaft whose bounding boxes the classifier tests.
pub const SHAFT_PIECES: usize = 8;

/// Occlusion by the city's buildings, for one shading point.
pub struct Shadows<'c> {
    city: &'c City,
    /// `SHADOW_OFFSET` times the surface normal: queries start at the shading
    /// point plus this.
    lift: Vec3,
    /// Classifications answered: visible, occluded, partial.
    pub answers: [u32; 3],
}

impl<'c> Shadows<'c> {
    /// The host for a shading point with unit `normal`.
    pub fn new(city: &'c City, normal: Vec3) -> Self {
        Self {
            city,
            lift: normal * SHADOW_OFFSET,
            answers: [0; 3],
        }
    }

    /// Counts and returns `coverage`.
    fn answer(&mut self, coverage: Coverage) -> Coverage {
        let slot = match coverage {
            Coverage::Visible => 0,
            Coverage::Occluded => 1,
            Coverage::Partial => 2,
        };
        self.answers[slot] += 1;
        coverage
    }
}

/// A closed segment, set up for slab tests.
struct Segment {
    from: Vec3,
    /// `1 / (to - from)`.
    inv_dir: Vec3,
}

impl Segment {
    fn new(from: Vec3, to: Vec3) -> Self {
        Self {
            from,
            inv_dir: (to - from).recip(),
        }
    }

    /// Whether the segment meets the closed box `b`.
    fn hits(&self, b: &Aabb) -> bool {
        let (near, far) = slab(self.from, self.inv_dir, b);
        near <= far && far >= 0.0 && near <= 1.0
    }
}

/// Whether two closed boxes meet.
fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    a.min.cmple(b.max).all() && b.min.cmple(a.max).all()
}

/// `b` grown (or, for negative `by`, shrunk) by `by` on every side.
fn grown(b: &Aabb, by: f32) -> Aabb {
    Aabb {
        min: b.min - by,
        max: b.max + by,
    }
}

/// The eight corners of a box.
fn corners(b: &Aabb) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        )
    })
}

impl Visibility for Shadows<'_> {
    /// With the shaft the convex hull of the (lifted) point `p` and the
    /// node's box `N`:
    ///
    /// * `Visible` when no building, grown by [`MARGIN`], meets the bounding
    ///   box of any of [`SHAFT_PIECES`] slices of the shaft. The points
    ///   `(1 - t) p + t q` (`q` in `N`) with `t` in `[a, b]` lie in the
    ///   bounding box of the two boxes `(1 - a) p + a N` and `(1 - b) p + b N`
    ///   (each coordinate is linear in `t`), so the slices' boxes cover the
    ///   shaft, much more tightly than one box when it runs diagonally.
    /// * `Occluded` when the segments to all eight corners of `N` meet one
    ///   building shrunk by [`MARGIN`]. For a convex occluder `B` the set
    ///   `{q : [p, q] meets B} = {p + s (b - p) : b in B, s >= 1}` is convex,
    ///   so it then holds the corners' convex hull, `N`: every light's shadow
    ///   ray is blocked. Only buildings on the segment to the centre of `N`
    ///   can qualify, so only those are tried.
    /// * `Partial` otherwise.
    fn classify(&mut self, point: Vec3, node: &NodeBounds) -> Coverage {
        let apex = point + self.lift;
        let bvh = &self.city.bvh;
        let buildings = &self.city.buildings;
        let slice = |t: f32| Aabb {
            min: apex.lerp(node.aabb.min, t),
            max: apex.lerp(node.aabb.max, t),
        };
        let pieces: [Aabb; SHAFT_PIECES] = std::array::from_fn(|k| {
            let a = slice(k as f32 / SHAFT_PIECES as f32);
            let b = slice((k + 1) as f32 / SHAFT_PIECES as f32);
            grown(&union(a, b), MARGIN)
        });
        let shaft = pieces[1..].iter().fold(pieces[0], |a, &b| union(a, b));
        let near = |b: &Aabb| overlaps(b, &shaft) && pieces.iter().any(|piece| overlaps(b, piece));
        if !bvh.any(near, |i| near(&buildings[i].bounds)) {
            return self.answer(Coverage::Visible);
        }
        let to_centre = Segment::new(apex, 0.5 * (node.aabb.min + node.aabb.max));
        let to_corners = corners(&node.aabb).map(|c| Segment::new(apex, c));
        let blocks_all = |i: usize| {
            let core = grown(&buildings[i].bounds, -MARGIN);
            core.min.cmple(core.max).all()
                && to_centre.hits(&core)
                && to_corners.iter().all(|s| s.hits(&core))
        };
        self.answer(if bvh.any(|b| to_centre.hits(b), blocks_all) {
            Coverage::Occluded
        } else {
            Coverage::Partial
        })
    }

    /// One shadow ray: the segment from the lifted point to the light.
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        let ray = Segment::new(point + self.lift, light);
        let buildings = &self.city.buildings;
        !self
            .city
            .bvh
            .any(|b| ray.hits(b), |i| ray.hits(&buildings[i].bounds))
    }
}
