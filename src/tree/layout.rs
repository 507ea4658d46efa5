//! The light hierarchy's layout: flat storage of virtual-light nodes, and
//! what the tree answers about itself.

use core::fmt;

use super::groups::NodeGroups;
use super::node::Node;
use super::options::TreeBuilder;
use super::prefetch::{as_bytes_range, prefetch, prefetch_line, prefetch_lines, prefetch_value};
use crate::PointLight;

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
    /// The lights' emission profiles and the nodes' orientation bounds;
    /// `None` for a tree of isotropic lights, which stores nothing for
    /// them.
    pub(crate) orientation: Option<Box<super::orientation::Orientation>>,
    /// The large nodes' slab moments (see [`slabs`](super::slabs)); empty
    /// for a tree of oriented emitters.
    pub(crate) slabs: super::slabs::Slabs,
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

    /// The options the tree was built with, which
    /// [`rebuild`](Self::rebuild) keeps: to rebuild on rayon's pool with
    /// them, `tree.options().rebuild_parallel(&mut tree, &lights)`.
    ///
    /// ```
    /// use glam::Vec3;
    /// use manylights::{LightTree, PointLight};
    ///
    /// let lights: Vec<PointLight> = (0..100)
    ///     .map(|i| PointLight::new(Vec3::new(i as f32, 0.0, 1.0), Vec3::ONE))
    ///     .collect();
    /// let builder = LightTree::builder().max_leaf_lights(4);
    /// let mut tree = builder.build(&lights)?;
    /// assert_eq!(tree.options(), builder);
    /// tree.rebuild(&lights[..50])?;
    /// assert_eq!(tree.options(), builder);
    /// # Ok::<(), manylights::BuildError>(())
    /// ```
    pub fn options(&self) -> TreeBuilder {
        self.options
    }

    /// Number of levels below the root (0 for a single leaf).
    #[inline]
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// Heap memory held by the tree, in bytes (nodes, lights, index map,
    /// the nodes' statistics copied side by side for bounding a node's
    /// children together, and the large nodes' slab moments).
    pub fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * size_of::<Node>()
            + self.lights.capacity() * size_of::<PointLight>()
            + self.order.capacity() * size_of::<u32>()
            + self.planes.capacity() * size_of::<[u32; 3]>()
            + self.node_planes.capacity() * size_of::<u32>()
            + self.groups.memory_bytes()
            + self.slabs.memory_bytes()
            + self.orientation.as_ref().map_or(0, |o| {
                size_of::<super::orientation::Orientation>() + o.memory_bytes()
            })
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

/// Trees of fewer nodes are not prefetched: their nodes (under 2,048 of
/// 232 bytes, at most 475 KB) mostly stay in a second-level cache from one
/// shading point to the next, where a prefetch only costs its
/// instructions. The alternating passes of `cargo run --release -p
/// manylights-report -- scaling` (each point with the caches cold) measure
/// its effect; `docs/tuning.md` records the measurement.
const PREFETCH_MIN_NODES: usize = 2048;

/// The first bytes of a [`Node`], which hold what the cut reads of a node
/// entering it (intensity, radius, counts, ranges, the moments' rounding
/// bound, and the centroid, which tells whether a near node is summed
/// whole). A field the cut reads past these bytes makes a cold child's
/// record miss the cache a second time, as the centroid did before it was
/// among them. The alternating passes of `cargo run --release -p
/// manylights-report -- scaling` at 10^6 lights measure the effect;
/// `docs/tuning.md` records the measurement.
const HOT_NODE_BYTES: usize = core::mem::offset_of!(Node, weight);

/// Cache lines of a run of lights prefetched at most per call: the 64
/// lights a coarse sum takes at most (1,536 bytes) wherever they start.
/// It pays where the lights are cold in the caches, as a renderer's other
/// work leaves them: the alternating passes of `cargo run --release -p
/// manylights-report -- scaling` at 10^6 lights measure it against no
/// prefetch; `docs/tuning.md` records the measurement.
const PREFETCH_RUN_LINES: usize = 25;

#[cfg(test)]
mod tests {
    use core::mem::{offset_of, size_of};

    use glam::{DVec3, Vec3};

    use super::*;

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
