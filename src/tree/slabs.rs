//! Slab moments: for each large node, its lights' moments in slices
//! ("bins") across the thinnest axis of its box, for bounding a node that
//! the tangent plane of a shading point runs through (see
//! [`Lambert`](crate::Lambert)'s docs, "Nodes the tangent plane cuts").
//!
//! A node of at least [`SLAB_MIN_LIGHTS`] lights whose box has a positive
//! extent along its thinnest axis `a` gets [`SLAB_BINS`] bins: slices of
//! its box along `a` between the edges of [`bin_edges`], finer at both
//! faces of the box (their widths grow by [`SLAB_RATIO`] towards the
//! middle). Each bin stores, per channel `k` and about the node's stored
//! centroid `c` (`y = x - c`), over the lights `i` in its slice, the
//! zeroth to third moments of the intensity, divided by the node's
//! intensity `I_k` and by `R^j` for a moment of degree `j` (`R` the node's
//! radius), so that every stored value lies in `[-1, 1]`:
//!
//! `W = sum I_ik / I_k`, `m1 = sum I_ik y / (I_k R)`,
//! `M2 = sum I_ik y y^T / (I_k R^2)` (entries `xx, yy, zz, xy, xz, yz`),
//! `m3 = sum I_ik |y|^2 y / (I_k R^3)`.
//!
//! They are stored as running sums from the lowest bin, so that a run of
//! bins (those wholly above a plane are one) is one difference. The sums
//! run in `f64` and are rounded to nearest `f32`; each stored
//! value is within [`SlabTable::error`] of its exact value (in the
//! normalised units above). A light on an edge belongs to the bin above
//! it; the bins' slices are recomputed from the node's box by
//! [`bin_edges`] when a bound reads them, by the same operations, so every
//! light lies in its bin's slice.

use glam::DVec3;

use super::layout::LightTree;
use super::pool::Pool;
use crate::PointLight;

/// Bins per node.
pub(crate) const SLAB_BINS: usize = 16;

/// Nodes of fewer lights get no bins: they are summed or split soon enough,
/// and every bin table costs [`size_of::<SlabTable>`] bytes.
pub(crate) const SLAB_MIN_LIGHTS: u32 = 64;

/// Each bin is this much wider than its neighbour towards the nearer face
/// of the node's box.
pub(crate) const SLAB_RATIO: f64 = 1.5;

/// A bin's stored floats per channel: `W`, `m1` (3), `M2` (6), `m3` (3).
pub(crate) const BIN_FLOATS: usize = 13;

/// The node carries no bins.
pub(crate) const NO_SLABS: u32 = u32::MAX;

/// A node's entry holds its table's index in these bits, and its bins' axis
/// in the two above them.
const TABLE_BITS: u32 = (1 << 30) - 1;

/// One node's bins.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SlabTable {
    /// The axis the bins slice (0, 1 or 2): the box's thinnest.
    pub(crate) axis: u32,
    /// Bound on the distance of every stored value from its exact value,
    /// in the normalised units of the module's docs.
    pub(crate) error: f32,
    /// Per bin `j`, the moments of the bins `0..=j` together: `[W, m1 (x,
    /// y, z), M2 (xx, yy, zz, xy, xz, yz), m3 (x, y, z)]`, each entry's
    /// three channels side by side; so a run of bins is one difference.
    pub(crate) prefix: [[[f32; 3]; BIN_FLOATS]; SLAB_BINS],
}

/// Every large node's bins.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Slabs {
    /// Per node, the index of its table in `tables` (low 30 bits) and its
    /// bins' axis (the top two), or [`NO_SLABS`]; empty when no node has
    /// bins.
    pub(crate) node_tables: Vec<u32>,
    pub(crate) tables: Vec<SlabTable>,
    /// Bit `a` set where some node's bins slice axis `a`.
    pub(crate) axes: u32,
}

impl Slabs {
    /// The bins of node `index`, if it has any.
    #[inline]
    pub(crate) fn of(&self, index: usize) -> Option<&SlabTable> {
        let entry = *self.node_tables.get(index)?;
        self.tables.get((entry & TABLE_BITS) as usize)
    }

    /// The axis node `index`'s bins slice, if it has bins, read without
    /// touching the bins.
    #[inline]
    pub(crate) fn axis_of(&self, index: usize) -> Option<usize> {
        let entry = *self.node_tables.get(index)?;
        (entry != NO_SLABS).then_some((entry >> 30) as usize)
    }

    /// Heap bytes held.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.node_tables.capacity() * size_of::<u32>()
            + self.tables.capacity() * size_of::<SlabTable>()
    }

    pub(crate) fn clear(&mut self) {
        self.node_tables.clear();
        self.tables.clear();
        self.axes = 0;
    }
}

/// `x^k`, in a constant.
const fn power(x: f64, k: usize) -> f64 {
    let mut p = 1.0;
    let mut i = 0;
    while i < k {
        p *= x;
        i += 1;
    }
    p
}

/// The fractions of a box's extent at which the bins' edges lie: widths
/// growing geometrically by [`SLAB_RATIO`] from each face to the middle.
const EDGE_FRACTIONS: [f64; SLAB_BINS + 1] = {
    let half = SLAB_BINS / 2;
    let total = power(SLAB_RATIO, half) - 1.0;
    let mut f = [0.0; SLAB_BINS + 1];
    let mut j = 0;
    while j <= half {
        f[j] = 0.5 * (power(SLAB_RATIO, j) - 1.0) / total;
        f[SLAB_BINS - j] = 1.0 - f[j];
        j += 1;
    }
    f[half] = 0.5;
    f
};

/// The bins' edges along an axis on which the box spans `[lo, hi]`: `lo`
/// and `hi` exactly at the ends, increasing in between.
#[inline(always)]
pub(crate) fn bin_edges(lo: f64, hi: f64) -> [f64; SLAB_BINS + 1] {
    let mut edges = [0.0; SLAB_BINS + 1];
    for (e, f) in edges.iter_mut().zip(EDGE_FRACTIONS) {
        *e = lo + (hi - lo) * f;
    }
    edges[0] = lo;
    edges[SLAB_BINS] = hi;
    edges
}

/// The bin of a coordinate `x` in `[edges[0], edges[SLAB_BINS]]`: the last
/// whose lower edge is at most `x`.
#[inline]
fn bin_of(edges: &[f64; SLAB_BINS + 1], x: f64) -> usize {
    edges[1..SLAB_BINS].iter().take_while(|&&e| e <= x).count()
}

/// The thinnest axis of a box of extents `e`.
fn thinnest(e: DVec3) -> usize {
    if e.x <= e.y && e.x <= e.z {
        0
    } else if e.y <= e.z {
        1
    } else {
        2
    }
}

/// The bins of one node, or `None` for a node that gets none (too few
/// lights, a flat box, or no radius).
fn table(tree: &LightTree, index: usize) -> Option<SlabTable> {
    let node = &tree.nodes[index];
    if node.light_count < SLAB_MIN_LIGHTS || node.radius <= 0.0 {
        return None;
    }
    let (lo, hi) = (node.aabb.min.as_dvec3(), node.aabb.max.as_dvec3());
    let axis = thinnest(hi - lo);
    if hi[axis] <= lo[axis] {
        return None;
    }
    let edges = bin_edges(lo[axis], hi[axis]);
    let c = node.centroid.as_dvec3();
    let r = f64::from(node.radius);
    let mut sums = [[[0.0f64; BIN_FLOATS]; 3]; SLAB_BINS];
    let lights: &[PointLight] = &tree.lights[node.lights()];
    for light in lights {
        let x = light.position.as_dvec3();
        let bin = &mut sums[bin_of(&edges, x[axis])];
        // Normalised by R so that every term is at most 1 in magnitude.
        let y = (x - c) / r;
        let y2 = y.length_squared();
        let terms = [
            1.0,
            y.x,
            y.y,
            y.z,
            y.x * y.x,
            y.y * y.y,
            y.z * y.z,
            y.x * y.y,
            y.x * y.z,
            y.y * y.z,
            y2 * y.x,
            y2 * y.y,
            y2 * y.z,
        ];
        let intensity = light.intensity.as_dvec3();
        for (k, channel) in bin.iter_mut().enumerate() {
            let weight = intensity[k];
            if weight > 0.0 {
                for (s, t) in channel.iter_mut().zip(terms) {
                    *s += weight * t;
                }
            }
        }
    }
    let total = node.intensity;
    let mut prefix = [[[0.0f32; 3]; BIN_FLOATS]; SLAB_BINS];
    let mut running = [[0.0f64; BIN_FLOATS]; 3];
    for (out, sum) in prefix.iter_mut().zip(&sums) {
        for k in 0..3 {
            for (r, s) in running[k].iter_mut().zip(sum[k]) {
                *r += s;
            }
            if total[k] > 0.0 {
                for (o, r) in out.iter_mut().zip(running[k]) {
                    o[k] = (r / total[k]) as f32;
                }
            }
        }
    }
    // Each term's magnitude is at most its light's intensity over I_k
    // (|y| <= R, the radius rounded upward; the normalised y within a few
    // ulps of its exact value, whose effect on a term of degree <= 3 is
    // under 16 f64 ulps of it). The f64 sums add at most n ulps of the sum
    // of magnitudes (at most 1, or the node's intensity's own rounding
    // over it), the division one more, and the f32 rounding half an f32
    // ulp of a value at most 1.
    let n = lights.len() as f64;
    let error = f64::from(f32::EPSILON) * 0.5 + (n + 32.0) * f64::EPSILON * 2.0;
    Some(SlabTable {
        axis: axis as u32,
        error: (error * (1.0 + 1e-3)) as f32,
        prefix,
    })
}

/// Fills the tree's bins from its nodes' statistics and lights.
pub(super) fn fill_slabs(tree: &mut LightTree, pool: Pool) {
    let mut slabs = core::mem::take(&mut tree.slabs);
    slabs.clear();
    if tree.orientation.is_some() || !tree.options.slab_moments {
        // The slab bound is for isotropic lights.
        tree.slabs = slabs;
        return;
    }
    let large: Vec<usize> = (0..tree.nodes.len())
        .filter(|&i| tree.nodes[i].light_count >= SLAB_MIN_LIGHTS)
        .collect();
    if !large.is_empty() {
        let tables = pool.map(&large, |&i| table(tree, i));
        slabs.node_tables.resize(tree.nodes.len(), NO_SLABS);
        for (&i, t) in large.iter().zip(tables) {
            if let Some(t) = t
                && slabs.tables.len() < TABLE_BITS as usize
            {
                slabs.node_tables[i] = slabs.tables.len() as u32 | (t.axis << 30);
                slabs.axes |= 1 << t.axis;
                slabs.tables.push(t);
            }
        }
    }
    tree.slabs = slabs;
}

#[cfg(test)]
mod tests {
    use super::{EDGE_FRACTIONS, SLAB_BINS, bin_edges, bin_of};

    #[test]
    fn edges_grow_towards_the_middle_and_hold_their_coordinates() {
        let f = EDGE_FRACTIONS;
        assert_eq!(f[0], 0.0);
        assert_eq!(f[SLAB_BINS], 1.0);
        for j in 0..SLAB_BINS / 2 {
            let (near, far) = (f[j + 1] - f[j], f[j + 2] - f[j + 1]);
            if j + 2 <= SLAB_BINS / 2 {
                assert!(far > near * 1.49, "bin {j}: {near} then {far}");
            }
        }
        for (lo, hi) in [(0.0, 1.0), (-3.5, 7.25), (1e6, 1e6 + 0.001), (-1e-30, 0.0)] {
            let edges = bin_edges(lo, hi);
            assert!(edges.windows(2).all(|w| w[0] <= w[1]));
            for i in 0..=1000 {
                let x = lo + (hi - lo) * f64::from(i) / 1000.0;
                let x = x.clamp(lo, hi);
                let b = bin_of(&edges, x);
                assert!(
                    edges[b] <= x && x <= edges[b + 1],
                    "{x} in bin {b} of {edges:?}"
                );
            }
        }
    }
}
