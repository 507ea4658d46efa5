//! The light hierarchy's layout: flat storage of virtual-light nodes.

use core::fmt;
use core::ops::Range;

use glam::{DVec3, Vec3};

use super::build::TreeBuilder;
use super::groups::NodeGroups;
use crate::PointLight;
use crate::geometry::{Aabb, Cone};

/// One node of a [`LightTree`]: a *virtual light* standing for every light
/// below it, with the data the bounds need.
///
/// With `w_i = max_k I_ik` the weight of light `i` ([`PointLight::weight`]),
/// the node stores, over its member lights `i` (positions `x_i`, RGB
/// intensities `I_i`):
///
/// * [`intensity`](Self::intensity) `= sum_i I_i` (per channel, in `f64` so
///   that sums of lights near `f32::MAX` do not overflow);
/// * [`weight`](Self::weight) `W = sum_i w_i` (summed in `f64`, stored
///   rounded to `f32`, at most `f32::MAX`);
/// * [`centroid`](Self::centroid) `c = sum_i w_i x_i / W` rounded to `f32`
///   (the virtual light's position; the plain mean of the positions when
///   `W = 0`). Every other moment is taken about this *stored* `c`, so the
///   bounds hold for the value actually stored;
/// * [`radius`](Self::radius) `R >= max_i |x_i - c|`, rounded upward;
/// * [`channel_offsets`](Self::channel_offsets) `o_k = sum_i I_ik (x_i - c) / I_k`
///   per channel `k` (zero when `I_k = 0`): the first moment that the scalar
///   weight does not cancel when member colours differ;
/// * [`channel_covariances`](Self::channel_covariances)
///   `S_k = sum_i I_ik (x_i - c)(x_i - c)^T / I_k` per channel (zero when
///   `I_k = 0`), diagonals rounded upward;
/// * [`harmonic_norms`](Self::harmonic_norms) `q_lk` for degrees `l = 3, 4,
///   5` per channel: the norm of the node's degree-`l` multipole,
///   `q_lk^2 = sum_ij I_ik I_jk |y_i|^l |y_j|^l P_l(y^_i . y^_j) / (I_k R^l)^2`
///   with `y_i = x_i - c`, `y^_i = y_i / |y_i|` and `P_l` the Legendre
///   polynomial, rounded upward (at most 1, far less where the members'
///   multipoles cancel);
/// * [`aabb`](Self::aabb): the tight box of the members;
/// * [`moment_error`](Self::moment_error) `delta`: the build's certified
///   bound on the rounding of the `f64` first and second moment sums behind
///   `o_k` and `S_k` (each entry of `I_k o_k` within `delta I_k R` of its
///   exact value, each entry of `I_k S_k` within `delta I_k R^2`), before
///   their rounding to `f32`.
///
/// Its lights occupy a contiguous range of the tree's leaf order; its children,
/// if any, a contiguous range of the node array.
///
/// Every statistic is taken over the members as stored in the tree, so a
/// [`refit`](LightTree::refit) recomputes them all.
#[derive(Clone, Copy, Debug, PartialEq)]
// In this order: what the cut reads of every node entering it (intensity,
// radius, counts and ranges, the moments' rounding bound, the centroid) in
// its first 60 bytes, which lie in one or two cache lines; the statistics
// that the children's blocks copy (see `groups`) after them.
#[repr(C)]
pub struct Node {
    pub(crate) intensity: DVec3,
    pub(crate) radius: f32,
    pub(crate) light_count: u32,
    pub(crate) first_light: u32,
    pub(crate) first_child: u32,
    pub(crate) child_count: u32,
    pub(crate) moment_error: f32,
    pub(crate) centroid: Vec3,
    pub(crate) weight: f32,
    pub(crate) aabb: Aabb,
    pub(crate) channel_offsets: [Vec3; 3],
    /// Per channel: xx, yy, zz, xy, xz, yz.
    pub(crate) channel_covariances: [[f32; 6]; 3],
    /// Per degree 3, 4, 5: the three channels' norms.
    pub(crate) harmonic_norms: [Vec3; 3],
}

impl Node {
    /// Summed RGB intensity of the member lights.
    #[inline]
    pub fn intensity(&self) -> DVec3 {
        self.intensity
    }
    /// Summed scalar weight `W` (largest channel per light), rounded to
    /// `f32` and at most `f32::MAX`.
    #[inline]
    pub fn weight(&self) -> f64 {
        f64::from(self.weight)
    }
    /// The build's bound `delta` on the rounding of the `f64` sums behind
    /// [`channel_offsets`](Self::channel_offsets) and
    /// [`channel_covariances`](Self::channel_covariances): each entry of
    /// `I_k o_k` is within `delta I_k R` of the exact sum, each entry of
    /// `I_k S_k` within `delta I_k R^2`, before the `f32` rounding
    /// (diagonals of `S_k` are rounded upward past it). On the street city
    /// of 10^6 lights: `2e-14` for the median node, `5e-13` at the root
    /// (where one `f64::EPSILON` per member light would be `2e-10`).
    #[inline]
    pub fn moment_error(&self) -> f64 {
        f64::from(self.moment_error)
    }
    /// Position of the virtual light: the weight-averaged member position.
    #[inline]
    pub fn centroid(&self) -> Vec3 {
        self.centroid
    }
    /// Radius of a ball about [`centroid`](Self::centroid) holding every member.
    #[inline]
    pub fn radius(&self) -> f32 {
        self.radius
    }
    /// Per-channel first moment about the centroid, divided by the channel's
    /// intensity: `o_k = sum_i I_ik (x_i - c) / I_k`.
    #[inline]
    pub fn channel_offsets(&self) -> [Vec3; 3] {
        self.channel_offsets
    }
    /// Per-channel second moment matrices about the centroid, each
    /// normalized by the channel's intensity, as `[xx, yy, zz, xy, xz, yz]`:
    /// `S_k = sum_i I_ik (x_i - c)(x_i - c)^T / I_k` (zero when `I_k = 0`).
    /// Diagonals are rounded upward, so each trace bounds the channel's
    /// mean squared member distance from above.
    #[inline]
    pub fn channel_covariances(&self) -> [[f32; 6]; 3] {
        self.channel_covariances
    }
    /// Traces of [`channel_covariances`](Self::channel_covariances): per
    /// channel `k`, `sum_i I_ik |x_i - c|^2 / I_k`.
    #[inline]
    pub fn mean_squared_radii(&self) -> DVec3 {
        let t = |s: &[f32; 6]| f64::from(s[0]) + f64::from(s[1]) + f64::from(s[2]);
        let s = &self.channel_covariances;
        DVec3::new(t(&s[0]), t(&s[1]), t(&s[2]))
    }
    /// Harmonic norms of the node's multipoles of degrees 3, 4 and 5
    /// (`[degree 3, degree 4, degree 5]`, each per channel), in units of
    /// `I_k R^l`: `q_lk = |sum_i I_ik R_l(x_i - c)| / (I_k R^l)` with `R_l`
    /// the `2l + 1` Schmidt semi-normalised regular solid harmonics of degree
    /// `l`. By the addition theorem of spherical harmonics
    /// `q_lk^2 R^(2l) I_k^2 = sum_ij I_ik I_jk |y_i|^l |y_j|^l P_l(y^_i . y^_j)`.
    /// Rounded upward; in `[0, 1]` up to that rounding.
    #[inline]
    pub fn harmonic_norms(&self) -> [Vec3; 3] {
        self.harmonic_norms
    }
    /// Tight axis-aligned box of the member lights.
    #[inline]
    pub fn aabb(&self) -> Aabb {
        self.aabb
    }
    /// The cone under which the node's ball is seen from `point`, or `None`
    /// when the ball reaches the point (see [`Cone::new`]): such a node has
    /// no finite bound and is always refined.
    #[inline]
    #[must_use]
    pub fn cone(&self, point: DVec3) -> Option<Cone> {
        Cone::new(point, self.centroid, self.radius)
    }
    /// Whether the node has no children (its lights are evaluated directly).
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.child_count == 0
    }
    /// Range of the node's lights in the tree's leaf order
    /// ([`LightTree::lights`]).
    #[inline]
    pub fn lights(&self) -> Range<usize> {
        self.first_light as usize..(self.first_light + self.light_count) as usize
    }
    /// Number of lights below the node.
    #[inline]
    pub fn light_count(&self) -> usize {
        self.light_count as usize
    }
    /// Range of the node's children in the node array ([`LightTree::nodes`]);
    /// empty for a leaf.
    #[inline]
    pub fn children(&self) -> Range<usize> {
        self.first_child as usize..(self.first_child + self.child_count) as usize
    }
}

/// Most children of a node: the tree is an octree (a node splits into the
/// occupied sub-cells of its cell, some of them merged into one leaf, or
/// in two at a median).
pub(crate) const MAX_CHILDREN: usize = 8;

/// A hierarchy of point lights whose nodes are virtual lights (Paquette,
/// Poulin and Drettakis 1998, slides "Construction").
///
/// Built once from a slice of [`PointLight`]s with [`LightTree::build`] (or
/// [`LightTree::builder`] for options); shaded through
/// [`LightTree::shading`]. Storage is flat: nodes in one vector (children of
/// a node contiguous, root first), lights reordered into leaf order in
/// another, with [`original_index`](Self::original_index) mapping back to the
/// caller's order.
#[derive(Clone)]
pub struct LightTree {
    pub(crate) nodes: Vec<Node>,
    pub(crate) lights: Vec<PointLight>,
    pub(crate) order: Vec<u32>,
    pub(crate) depth: u32,
    /// Per recorded plane: three lights (leaf order) spanning it.
    pub(crate) planes: Vec<[u32; 3]>,
    /// Per node, the plane all its lights lie in exactly (an index into
    /// `planes`) or [`NO_PLANE`]; empty when no plane was recorded.
    pub(crate) node_planes: Vec<u32>,
    /// Every node's children side by side, for bounding them together.
    pub(crate) groups: NodeGroups,
    /// The options it was built with, for [`rebuild`](Self::rebuild).
    pub(crate) options: TreeBuilder,
}

/// A node whose lights are not known to lie in one plane.
pub(crate) const NO_PLANE: u32 = u32::MAX;

impl LightTree {
    /// The plane all lights of node `index` lie in exactly, if one was
    /// recorded.
    #[inline]
    pub(crate) fn node_plane(&self, index: usize) -> Option<u32> {
        self.node_planes
            .get(index)
            .copied()
            .filter(|&p| p != NO_PLANE)
    }

    /// The nodes, root first; empty for an empty tree.
    #[inline]
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// The root node, `None` for an empty tree.
    #[inline]
    pub fn root(&self) -> Option<&Node> {
        self.nodes.first()
    }

    /// The lights in leaf order (the order node light ranges refer to).
    #[inline]
    pub fn lights(&self) -> &[PointLight] {
        &self.lights
    }

    /// Index in the caller's slice of the light at `leaf_index` in leaf order.
    #[inline]
    pub fn original_index(&self, leaf_index: usize) -> usize {
        self.order[leaf_index] as usize
    }

    /// Number of lights.
    #[inline]
    pub fn len(&self) -> usize {
        self.lights.len()
    }

    /// Whether the tree holds no light.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.lights.is_empty()
    }

    /// Number of levels below the root (0 for a single leaf).
    #[inline]
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// Heap memory held by the tree, in bytes (nodes, lights, index map,
    /// and the nodes' statistics copied side by side for bounding a node's
    /// children together).
    pub fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * size_of::<Node>()
            + self.lights.capacity() * size_of::<PointLight>()
            + self.order.capacity() * size_of::<u32>()
            + self.planes.capacity() * size_of::<[u32; 3]>()
            + self.node_planes.capacity() * size_of::<u32>()
            + self.groups.memory_bytes()
    }
}

/// A summary: a tree of a million lights would print hundreds of megabytes
/// if every node were listed.
impl fmt::Debug for LightTree {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LightTree")
            .field("lights", &self.lights.len())
            .field("nodes", &self.nodes.len())
            .field("depth", &self.depth)
            .field("memory_bytes", &self.memory_bytes())
            .finish_non_exhaustive()
    }
}

impl LightTree {
    /// Asks the processor to start loading what refining node `index` will
    /// read (its children's records and their block of statistics side by
    /// side, or its lights): issued for the node the cut will probably
    /// refine next while it evaluates the current one, so that the loads
    /// overlap the work instead of stalling it.
    #[inline]
    pub(crate) fn prefetch_refinement(&self, index: usize) {
        if self.nodes.len() < PREFETCH_MIN_NODES {
            return;
        }
        let Some(node) = self.nodes.get(index) else {
            return;
        };
        if node.is_leaf() {
            let lights = self.lights.get(node.lights()).unwrap_or(&[]);
            prefetch(as_bytes_range(lights));
        } else {
            // Of the children's records, the fields the cut reads first
            // (see `Node`'s layout); their statistics come from the block.
            for child in self.nodes.get(node.children()).unwrap_or(&[]) {
                let start = core::ptr::from_ref(child) as usize;
                prefetch_line(start);
                prefetch_line(start + HOT_NODE_BYTES - 1);
            }
            if let Some(group) = self.groups.children(index) {
                super::groups::with_block!(group, block => prefetch_value(block));
            }
        }
    }

    /// Asks the processor to start loading `lights`, a run of this tree's
    /// lights that the cut is about to sum (its first
    /// [`PREFETCH_RUN_LINES`] cache lines), in trees large enough to leave
    /// the caches (see [`PREFETCH_MIN_NODES`]). A run's lines are then
    /// requested together rather than as the processor's own prefetcher
    /// finds the run.
    #[inline]
    pub(crate) fn prefetch_lights(&self, lights: &[PointLight]) {
        if self.nodes.len() >= PREFETCH_MIN_NODES {
            prefetch_lines(as_bytes_range(lights), PREFETCH_RUN_LINES);
        }
    }
}

/// The address range of a slice.
#[inline]
pub(super) fn as_bytes_range<T>(items: &[T]) -> core::ops::Range<usize> {
    let start = items.as_ptr() as usize;
    start..start + core::mem::size_of_val(items)
}

/// Trees of fewer nodes are not prefetched: their nodes (under 2,048 of
/// 232 bytes, at most 475 KB) mostly stay in a second-level cache from one
/// shading point to the next, where a prefetch only costs its
/// instructions. Measured on the street city at a certified 1%: 0.97 times
/// the time per point at 10^4 lights (1,113 nodes), the same within noise
/// at 10^5.
const PREFETCH_MIN_NODES: usize = 2048;

/// The first bytes of a [`Node`], which hold what the cut reads of a node
/// entering it (intensity, radius, counts, ranges, the moments' rounding
/// bound, and the centroid, which tells whether a near node is summed
/// whole). Until the centroid was among them a cold child's record often
/// missed the cache a second time; with it, on the street city of 10^6
/// lights at a certified 1%, each point after an exact sum over the scene
/// took 0.99x the time (median of 16 alternating pairs of runs).
const HOT_NODE_BYTES: usize = core::mem::offset_of!(Node, weight);

/// Cache lines of a run of lights prefetched at most per call: the 64
/// lights a coarse sum takes at most (1,536 bytes) wherever they start.
/// Measured on the street city of 10^6 lights at a certified 1%, each
/// point after 24 MB of other reads (caches cold), against no prefetch of
/// the runs: 0.95x the time per point (median of 15 alternating pairs of
/// runs), the same within noise with the tree warm in the caches and at
/// 10^5 lights.
const PREFETCH_RUN_LINES: usize = 25;

/// Cache lines prefetched at most per call.
const PREFETCH_LINES: usize = 16;

/// Prefetches the cache lines of an address range (at most
/// [`PREFETCH_LINES`] of them) into every cache level. A hint only: it
/// reads no memory the program can observe and never faults.
#[inline]
pub(super) fn prefetch(range: core::ops::Range<usize>) {
    prefetch_lines(range, PREFETCH_LINES);
}

/// Prefetches the cache lines of an address range, at most `most` of
/// them, into every cache level.
#[inline]
fn prefetch_lines(range: core::ops::Range<usize>, most: usize) {
    let mut line = range.start & !63;
    let end = range.end.min(range.start + most * 64);
    while line < end {
        prefetch_line(line);
        line += 64;
    }
}

/// Prefetches the cache lines of `value`, as [`prefetch`] its range: as
/// many lines as a value of its size can touch wherever it starts (at most
/// [`PREFETCH_LINES`]), a number known when compiling, so that the loop
/// unrolls.
#[inline(always)]
fn prefetch_value<T>(value: &T) {
    let start = core::ptr::from_ref(value) as usize & !63;
    let lines = (size_of::<T>() + 126) / 64;
    for k in 0..lines.min(PREFETCH_LINES) {
        prefetch_line(start + 64 * k);
    }
}

/// Prefetches the cache line holding `address` into every cache level.
#[inline(always)]
fn prefetch_line(address: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: a prefetch is a hint that never dereferences the address
        // architecturally and cannot fault, whatever the address.
        #[allow(unsafe_code)]
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(address as *const i8);
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{offset_of, size_of};

    #[test]
    fn the_hot_bytes_hold_what_the_cut_reads_first() {
        let ends = [
            offset_of!(Node, intensity) + size_of::<DVec3>(),
            offset_of!(Node, radius) + size_of::<f32>(),
            offset_of!(Node, light_count) + size_of::<u32>(),
            offset_of!(Node, first_light) + size_of::<u32>(),
            offset_of!(Node, first_child) + size_of::<u32>(),
            offset_of!(Node, child_count) + size_of::<u32>(),
            offset_of!(Node, moment_error) + size_of::<f32>(),
            offset_of!(Node, centroid) + size_of::<Vec3>(),
        ];
        assert!(ends.iter().all(|&end| end <= HOT_NODE_BYTES));
        // Records start 8-byte aligned (and so at most 56 bytes into a
        // line), so hot bytes of at most 72 span at most two lines: those
        // of their first and last bytes, which `prefetch_refinement` asks
        // for.
        assert_eq!(core::mem::align_of::<Node>() % 8, 0);
        assert_eq!(size_of::<Node>() % 8, 0);
        let (first, last) = (56, 56 + HOT_NODE_BYTES - 1);
        assert!(last / 64 - first / 64 <= 1, "{HOT_NODE_BYTES}");
    }
}
