//! Building the tree: an adaptive octree over point lights, and the node
//! statistics that building and refitting share.

use glam::{DVec3, Vec3};

use super::layout::{LightTree, Node};
use super::morton;
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
/// The tree is the paper's octree over the scene's bounding cube, adapted to
/// its content. The lights are sorted once along a Morton (Z-order) curve
/// with 21 bits per axis (a linear-time radix sort), so every octree cell is
/// a contiguous run of lights; a node's children are the occupied sub-cells
/// at the first level where its lights' cells differ, so levels with a
/// single occupied cell are skipped and a node has 2 to 8 children. Cells
/// are cubes, so a flat scene (a city) is split along its thin axis only
/// where cells become as small as its thickness.
///
/// A node becomes a leaf when it holds at most
/// [`max_leaf_lights`](Self::max_leaf_lights) lights, when it reaches
/// [`max_depth`](Self::max_depth), or when all its lights are coincident
/// (zero extent): thousands of coincident lights make one leaf, never an
/// endless recursion, and the cut evaluates such a leaf as one light of
/// their summed intensity. Lights that share a finest Morton cell (cells
/// are `2^-21` of the scene's extent; exponentially clustered lights, at
/// `2^-k` say) are halved at the median of their longest axis instead, which
/// needs at most `log2(n)` more levels, so leaves stay small however deep
/// the clustering.
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
    /// The sort is linear; node statistics are computed from each node's
    /// contiguous run of lights, `O(n * depth)` in sequential memory
    /// accesses. Memory `O(n)`.
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
        let mut tree = LightTree {
            nodes: Vec::new(),
            lights: Vec::new(),
            order: Vec::new(),
            depth: 0,
        };
        if n == 0 {
            return Ok(tree);
        }
        // Sort once along the Morton curve and gather the lights into that
        // order: every octree cell is then a contiguous run, and every later
        // pass over a node's lights reads memory in sequence.
        let scene = lights
            .iter()
            .fold(Aabb::EMPTY, |b, l| b.union_point(l.position));
        let codes = morton::codes(lights, scene);
        let order = morton::sort(&codes);
        let mut codes: Vec<u64> = order.iter().map(|&k| codes[k as usize]).collect();
        tree.lights = order.iter().map(|&k| lights[k as usize]).collect();
        tree.order = order;
        let identity: Vec<u32> = (0..n as u32).collect();

        // Breadth-first: children of a node are appended together, so they
        // are contiguous. `depths[i]` is node i's depth.
        let mut depths: Vec<u32> = vec![0];
        tree.nodes.push(node_stats(&tree.lights, &identity, 0..n));
        let mut i = 0;
        while i < tree.nodes.len() {
            let node = tree.nodes[i];
            let depth = depths[i];
            tree.depth = tree.depth.max(depth);
            if node.light_count as usize > self.max_leaf_lights && depth < self.max_depth {
                let range = node.lights();
                // The octree cell's occupied sub-cells at the first level
                // where the codes differ; lights in one finest cell are
                // halved at their median instead.
                let groups = match morton::children(&codes[range.clone()]) {
                    Some(groups) => groups,
                    None => median_split(
                        &mut tree.lights[range.clone()],
                        &mut tree.order[range.clone()],
                        node.aabb,
                    ),
                };
                if groups.len() > 1 {
                    tree.nodes[i].first_child = tree.nodes.len() as u32;
                    tree.nodes[i].child_count = groups.len() as u32;
                    for g in groups {
                        let r = range.start + g.start..range.start + g.end;
                        tree.nodes.push(node_stats(&tree.lights, &identity, r));
                        depths.push(depth + 1);
                    }
                }
            }
            i += 1;
        }
        // Median splits reorder lights within a run of equal codes only, so
        // the codes stay valid; they are not needed any more.
        codes.clear();
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

/// Halves a run of lights (and their original indices, kept in step) at
/// the median position along the box's longest axis: two ranges, or one
/// when all lights coincide. Used for lights that share a finest Morton
/// cell (exponentially clustered lights, at `2^-k` say): halving the count
/// bounds the extra depth by `log2(n)`.
fn median_split(
    lights: &mut [PointLight],
    order: &mut [u32],
    aabb: Aabb,
) -> smallvec::SmallVec<[core::ops::Range<usize>; 8]> {
    let extent = aabb.max - aabb.min;
    let mut out = smallvec::SmallVec::new();
    if extent.max_element() <= 0.0 {
        // All lights coincide: nothing can separate them.
        out.push(0..lights.len());
        return out;
    }
    let axis = extent.max_position();
    let mut pairs: Vec<(PointLight, u32)> =
        lights.iter().copied().zip(order.iter().copied()).collect();
    let mid = pairs.len() / 2;
    pairs.select_nth_unstable_by(mid, |a, b| {
        a.0.position[axis].total_cmp(&b.0.position[axis])
    });
    for ((l, o), (pl, po)) in lights.iter_mut().zip(order.iter_mut()).zip(pairs) {
        (*l, *o) = (pl, po);
    }
    out.push(0..mid);
    out.push(mid..lights.len());
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
