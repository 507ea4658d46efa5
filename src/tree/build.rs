//! Building the tree: an adaptive octree over point lights, and the node
//! statistics that building and refitting share.

use glam::{DVec3, Vec3};

use super::layout::{LightTree, Node};
use crate::geometry::Aabb;
use crate::numeric::{BUILD_LENGTH_SLACK, round_up_f32};
use crate::{BuildError, PointLight};

impl LightTree {
    /// Builds a tree with the default options of [`TreeBuilder`].
    ///
    /// An empty slice gives an empty tree, which shades to zero with zero
    /// error.
    ///
    /// # Errors
    /// A [`BuildError`] naming the first light with a non-finite or
    /// out-of-range position, or a non-finite or negative intensity channel.
    pub fn build(lights: &[PointLight]) -> Result<Self, BuildError> {
        TreeBuilder::new().build(lights)
    }

    /// A builder carrying the options (maximum lights per leaf, maximum depth).
    pub fn builder() -> TreeBuilder {
        TreeBuilder::new()
    }
}

/// Options for building a [`LightTree`].
///
/// The tree is the paper's octree, adapted to its content: each node's cell
/// is the tight box of its lights, split at the box's centre along every axis
/// whose extent is at least half the largest extent (so flat or thin light
/// sets get 2- or 4-way splits instead of empty octants). Empty cells are
/// dropped, so a node has 2 to 8 children.
///
/// A node becomes a leaf when it holds at most
/// [`max_leaf_lights`](Self::max_leaf_lights) lights, when it reaches
/// [`max_depth`](Self::max_depth), or when all its lights are coincident
/// (zero extent): thousands of coincident lights make one leaf, never an
/// endless recursion, and the cut evaluates such a leaf as one light of
/// their summed intensity. Below half the maximum depth, nodes are halved at
/// the median of their longest axis instead of split at the box centre, so
/// that however deep the clustering (lights at `2^-k`, say), leaves stay
/// small: the median splits need at most `log2(n) <= 32` more levels. Nearly coincident lights are always separated by a
/// split (the `f64` midpoint of two distinct `f32` values lies strictly
/// between them), so depth is bounded by `max_depth` and by the `f32`
/// resolution of the coordinates.
#[derive(Clone, Copy, Debug)]
#[must_use]
pub struct TreeBuilder {
    max_leaf_lights: usize,
    max_depth: u32,
}

impl Default for TreeBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl TreeBuilder {
    /// Default options: at most 4 lights per leaf, depth at most 64.
    pub const fn new() -> Self {
        Self {
            max_leaf_lights: 4,
            max_depth: 64,
        }
    }

    /// Maximum number of lights a leaf holds (at least 1; leaves deeper than
    /// `max_depth` or of coincident lights may hold more).
    pub const fn max_leaf_lights(mut self, n: usize) -> Self {
        self.max_leaf_lights = n;
        self
    }

    /// Maximum depth of the tree (the root is at depth 0).
    pub const fn max_depth(mut self, depth: u32) -> Self {
        self.max_depth = depth;
        self
    }

    /// Builds the tree.
    ///
    /// Time is `O(n * depth)`, memory `O(n)`.
    ///
    /// # Errors
    /// [`BuildError`] for a light with a non-finite or out-of-range
    /// coordinate, a non-finite or negative intensity channel (naming the
    /// first such light), more than `u32::MAX` lights, or
    /// `max_leaf_lights == 0`.
    pub fn build(&self, lights: &[PointLight]) -> Result<LightTree, BuildError> {
        if self.max_leaf_lights == 0 {
            return Err(BuildError::InvalidOption("max_leaf_lights must be >= 1"));
        }
        if lights.len() > u32::MAX as usize {
            return Err(BuildError::TooManyLights {
                count: lights.len(),
                max: u32::MAX as usize,
            });
        }
        check_lights(lights)?;

        let n = lights.len();
        let mut order: Vec<u32> = (0..n as u32).collect();
        let mut tree = LightTree {
            nodes: Vec::new(),
            lights: Vec::new(),
            order: Vec::new(),
            depth: 0,
        };
        if n == 0 {
            return Ok(tree);
        }
        // Breadth-first: children of a node are appended together, so they
        // are contiguous. `depths[i]` is node i's depth.
        let mut depths: Vec<u32> = vec![0];
        let mut scratch: Vec<u32> = Vec::with_capacity(n);
        tree.nodes.push(node_stats(lights, &order, 0..n));
        let mut i = 0;
        while i < tree.nodes.len() {
            let node = tree.nodes[i];
            let aabb = node.aabb;
            let depth = depths[i];
            tree.depth = tree.depth.max(depth);
            if node.light_count as usize > self.max_leaf_lights && depth < self.max_depth {
                let range = node.lights();
                let members = &mut order[range.clone()];
                let groups = if depth < self.max_depth / 2 {
                    split(lights, members, &mut scratch, aabb)
                } else {
                    median_split(lights, members, aabb)
                };
                if groups.len() > 1 {
                    tree.nodes[i].first_child = tree.nodes.len() as u32;
                    tree.nodes[i].child_count = groups.len() as u32;
                    for g in groups {
                        let r = range.start + g.start..range.start + g.end;
                        tree.nodes.push(node_stats(lights, &order, r));
                        depths.push(depth + 1);
                    }
                }
            }
            i += 1;
        }
        tree.lights = order.iter().map(|&k| lights[k as usize]).collect();
        tree.order = order;
        tree.nodes.shrink_to_fit();
        Ok(tree)
    }
}

pub(super) fn check_lights(lights: &[PointLight]) -> Result<(), BuildError> {
    for (index, l) in lights.iter().enumerate() {
        if !l.position.is_finite() {
            return Err(BuildError::NonFinitePosition { index });
        }
        if l.position.abs().max_element() > PointLight::MAX_COORDINATE {
            return Err(BuildError::PositionOutOfRange {
                index,
                max: PointLight::MAX_COORDINATE,
            });
        }
        if !l.intensity.is_finite() {
            return Err(BuildError::NonFiniteIntensity { index });
        }
        // `!(x >= 0)` would also catch NaN, already excluded above.
        if l.intensity.min_element() < 0.0 {
            return Err(BuildError::NegativeIntensity { index });
        }
    }
    Ok(())
}

/// Halves `idx` at the median position along the box's longest axis (two
/// ranges), or returns one range when all lights coincide. Used below half
/// the maximum depth, where spatial splits of exponentially clustered lights
/// (at `2^-k`, say) would separate one light per level: halving the count
/// bounds the remaining depth by `log2(n)`.
fn median_split(
    lights: &[PointLight],
    idx: &mut [u32],
    aabb: Aabb,
) -> smallvec::SmallVec<[core::ops::Range<usize>; 8]> {
    let extent = aabb.max - aabb.min;
    let mut out = smallvec::SmallVec::new();
    if extent.max_element() <= 0.0 {
        // All lights coincide: nothing can separate them.
        out.push(0..idx.len());
        return out;
    }
    let axis = extent.max_position();
    let mid = idx.len() / 2;
    idx.select_nth_unstable_by(mid, |&a, &b| {
        let (a, b) = (
            lights[a as usize].position[axis],
            lights[b as usize].position[axis],
        );
        a.total_cmp(&b)
    });
    out.push(0..mid);
    out.push(mid..idx.len());
    out
}

/// Partitions `idx` (indices into `lights`) into the non-empty cells of the
/// box split and returns the cells' sub-ranges, in cell order. A single range
/// means the split separated nothing (zero extent).
fn split(
    lights: &[PointLight],
    idx: &mut [u32],
    scratch: &mut Vec<u32>,
    aabb: Aabb,
) -> smallvec::SmallVec<[core::ops::Range<usize>; 8]> {
    let min = aabb.min.as_dvec3();
    let max = aabb.max.as_dvec3();
    let extent = max - min;
    let largest = extent.max_element();
    let mut out = smallvec::SmallVec::new();
    if largest <= 0.0 {
        // All lights coincide: nothing can separate them.
        out.push(0..idx.len());
        return out;
    }
    let mid = (min + max) * 0.5;
    let active = [
        extent.x >= 0.5 * largest,
        extent.y >= 0.5 * largest,
        extent.z >= 0.5 * largest,
    ];
    let cell = |p: Vec3| -> usize {
        let p = p.as_dvec3();
        let mut c = 0;
        for axis in 0..3 {
            if active[axis] && p[axis] > mid[axis] {
                c |= 1 << axis;
            }
        }
        c
    };
    let mut counts = [0usize; 8];
    for &k in idx.iter() {
        counts[cell(lights[k as usize].position)] += 1;
    }
    let mut starts = [0usize; 8];
    let mut acc = 0;
    for c in 0..8 {
        starts[c] = acc;
        acc += counts[c];
    }
    scratch.clear();
    scratch.resize(idx.len(), 0);
    let mut cursor = starts;
    for &k in idx.iter() {
        let c = cell(lights[k as usize].position);
        scratch[cursor[c]] = k;
        cursor[c] += 1;
    }
    idx.copy_from_slice(scratch);
    for c in 0..8 {
        if counts[c] > 0 {
            out.push(starts[c]..starts[c] + counts[c]);
        }
    }
    out
}

/// Computes a node's statistics over `lights[idx[range]]` (all in `f64`,
/// then stored as documented on [`Node`]).
pub(super) fn node_stats(
    lights: &[PointLight],
    idx: &[u32],
    range: core::ops::Range<usize>,
) -> Node {
    let members = &idx[range.clone()];
    let mut intensity = DVec3::ZERO;
    let mut weight = 0.0f64;
    let mut weighted_pos = DVec3::ZERO;
    let mut plain_pos = DVec3::ZERO;
    let mut aabb = Aabb::EMPTY;
    for &k in members {
        let l = lights[k as usize];
        let w = f64::from(l.weight());
        let x = l.position.as_dvec3();
        intensity += l.intensity.as_dvec3();
        weight += w;
        weighted_pos += w * x;
        plain_pos += x;
        aabb = aabb.union_point(l.position);
    }
    // Zero total weight: every member is dark; use the plain mean so the node
    // still has a sensible position (its contribution is zero either way).
    let centroid_f64 = if weight > 0.0 {
        weighted_pos / weight
    } else {
        plain_pos / members.len() as f64
    };
    // The average lies in the box in exact arithmetic; clamp away rounding.
    let centroid = centroid_f64.as_vec3().clamp(aabb.min, aabb.max);
    let c = centroid.as_dvec3();

    let mut radius_sq = 0.0f64;
    let mut first = [DVec3::ZERO; 3];
    let mut second = [0.0f64; 6];
    for &k in members {
        let l = lights[k as usize];
        let d = l.position.as_dvec3() - c;
        radius_sq = radius_sq.max(d.length_squared());
        let i = l.intensity.as_dvec3();
        first[0] += i.x * d;
        first[1] += i.y * d;
        first[2] += i.z * d;
        let w = f64::from(l.weight());
        second[0] += w * d.x * d.x;
        second[1] += w * d.y * d.y;
        second[2] += w * d.z * d.z;
        second[3] += w * d.x * d.y;
        second[4] += w * d.x * d.z;
        second[5] += w * d.y * d.z;
    }
    let radius = round_up_f32(radius_sq.sqrt() * (1.0 + BUILD_LENGTH_SLACK));
    let offset = |k: usize| -> Vec3 {
        if intensity[k] > 0.0 {
            (first[k] / intensity[k]).as_vec3()
        } else {
            Vec3::ZERO
        }
    };
    let mut covariance = [0.0f32; 6];
    if weight > 0.0 {
        for (j, out) in covariance.iter_mut().enumerate() {
            let v = second[j] / weight;
            *out = if j < 3 {
                round_up_f32(v * (1.0 + BUILD_LENGTH_SLACK))
            } else {
                v as f32
            };
        }
    }
    Node {
        intensity,
        weight,
        centroid,
        radius,
        channel_offsets: [offset(0), offset(1), offset(2)],
        covariance,
        aabb,
        first_light: range.start as u32,
        light_count: members.len() as u32,
        first_child: 0,
        child_count: 0,
    }
}
