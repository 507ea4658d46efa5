//! The BVH over the occluders' boxes (a binary BVH of the `obvhs` crate,
//! built with PLOC and reinsertion) and the two traversals the host needs:
//! every leaf whose bounds pass a test (shafts), and the leaves along a
//! segment (shadow rays), each with its own `f32` slab test.

use std::time::Duration;

use glam::{Vec3, Vec3A};
use manylights::Aabb;
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb as BvhAabb;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::bvh2::node::Bvh2Node;
use obvhs::fast_stack;
use obvhs::faststack::FastStack;

/// A closed segment from `from` to `from + 1 / inv_dir`, set up for slab
/// tests.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Segment {
    pub from: Vec3A,
    /// `1 / (to - from)`, per axis (infinite along an axis the segment is
    /// parallel to).
    pub inv_dir: Vec3A,
}

impl Segment {
    #[inline]
    pub fn new(from: Vec3, to: Vec3) -> Self {
        Self {
            from: from.into(),
            inv_dir: (Vec3A::from(to) - Vec3A::from(from)).recip(),
        }
    }

    /// Whether the segment meets the closed box `b`.
    #[inline]
    pub fn hits(&self, b: &BvhAabb) -> bool {
        self.hits_from(b, 0.0)
    }

    /// Whether the segment meets the closed box `b` at a parameter in
    /// `[t_min, 1]`. Every operation is monotone in the box's bounds, so a
    /// box holding `b` passes whenever `b` does: the BVH prunes no node
    /// whose boxes the segment meets.
    ///
    /// A zero direction component makes `inv_dir` infinite, which the slab
    /// arithmetic handles, except for an origin exactly in the plane of a
    /// face parallel to the segment: there `0 * inf = NaN`, and the segment
    /// (grazing the face in its plane) misses.
    #[inline]
    pub fn hits_from(&self, b: &BvhAabb, t_min: f32) -> bool {
        let t0 = (b.min - self.from) * self.inv_dir;
        let t1 = (b.max - self.from) * self.inv_dir;
        let near = t0.min(t1).max_element();
        let far = t0.max(t1).min_element();
        near <= far && far >= t_min && near <= 1.0
    }
}

/// The BVH over the occluders' boxes; its leaves index the boxes in leaf
/// order directly.
#[derive(Clone, Default)]
pub(crate) struct Bvh {
    bvh: Bvh2,
    /// Depth of the BVH: the traversal stack.
    depth: usize,
}

impl std::fmt::Debug for Bvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bvh")
            .field("nodes", &self.bvh.nodes.len())
            .field("depth", &self.depth)
            .finish()
    }
}

impl Bvh {
    /// The BVH of `boxes` (built with `obvhs`'s medium preset, up to 8 boxes a
    /// leaf) and the order of the boxes in its leaves: slot `k` holds input
    /// box `order[k]`.
    pub fn new(boxes: &[BvhAabb]) -> (Self, Vec<u32>) {
        if boxes.is_empty() {
            return (Self::default(), Vec::new());
        }
        let mut bvh = build_bvh2(
            boxes,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let order = std::mem::take(&mut bvh.primitive_indices);
        bvh.primitive_indices = (0..order.len() as u32).collect();
        let depth = bvh.depth(0);
        (Self { bvh, depth }, order)
    }

    /// Depth-first search: descends into every node whose bounds pass
    /// `enter` and calls `visit` on each slot of the leaves reached, until
    /// `visit` returns `true` (then `any_in` returns `true`). `enter` must
    /// hold for a node's bounds whenever it may hold for a box inside them.
    #[inline]
    pub fn any_in(
        &self,
        mut enter: impl FnMut(&BvhAabb) -> bool,
        mut visit: impl FnMut(usize) -> bool,
    ) -> bool {
        let nodes = &self.bvh.nodes;
        let Some(root) = nodes.first() else {
            return false;
        };
        if !enter(root.aabb()) {
            return false;
        }
        let mut leaf = |node: &Bvh2Node| {
            let slots = node.first_index as usize..(node.first_index + node.prim_count) as usize;
            slots.into_iter().any(&mut visit)
        };
        if root.is_leaf() {
            return leaf(root);
        }
        let mut found = false;
        // A stack as deep as the tree (obvhs sizes its own for the deepest
        // tree it expects and clears it per call).
        fast_stack!(u32, (16, 32, 64, 128), self.depth + 1, stack, {
            // Inner nodes keep their two children side by side; the stack
            // holds the index of the first of a pair.
            stack.push(root.first_index);
            'pairs: while let Some(first) = stack.pop() {
                for index in [first, first + 1] {
                    let node = &nodes[index as usize];
                    if !enter(node.aabb()) {
                        continue;
                    }
                    if !node.is_leaf() {
                        stack.push(node.first_index);
                    } else if leaf(node) {
                        found = true;
                        break 'pairs;
                    }
                }
            }
        });
        found
    }

    /// [`any_in`](Self::any_in) along `segment`: the leaves whose bounds it
    /// meets.
    #[inline]
    pub fn any_along(&self, segment: &Segment, visit: impl FnMut(usize) -> bool) -> bool {
        self.any_in(|b| segment.hits(b), visit)
    }
}

/// The box `b` as `obvhs` stores one.
#[inline]
pub(crate) fn to_bvh(b: &Aabb) -> BvhAabb {
    BvhAabb::new(b.min.into(), b.max.into())
}

/// The eight corners of a box (corner `k` takes the maximum on axis `a`
/// where bit `a` of `k` is set).
pub fn corners(b: &Aabb) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        )
    })
}

/// The distinct corners of a box: its [`corners`] without the repeats of a
/// box flat along some axes (one for a point, two for a segment, four for
/// a rectangle), which span the same convex set.
pub(crate) fn distinct_corners(b: &Aabb) -> impl Iterator<Item = Vec3> + Clone {
    let flat = [0, 1, 2].map(|a| b.min[a] == b.max[a]);
    let all = corners(b);
    (0..8usize)
        .filter(move |k| (0..3).all(|a| !flat[a] || k & (1 << a) == 0))
        .map(move |k| all[k])
}
