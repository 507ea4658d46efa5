//! Opaque axis-aligned boxes in a bounding-volume hierarchy from the `obvhs`
//! crate (a binary BVH, [`Bvh2`], built with PLOC and reinsertion, as
//! renderers build theirs): the nearest hits of primary rays, any-hit shadow
//! segments, and the two traversals a shaft test needs. Small box helpers
//! live here too.

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
use obvhs::ray::{Ray, RayHit};

/// Parameter interval `(near, far)` over which `origin + t * dir` lies in the
/// closed box `[min, max]` (empty when `near > far`), from `inv_dir = 1 /
/// dir`.
///
/// A zero direction component makes `inv_dir` infinite, which the slab
/// arithmetic handles, except for an origin exactly in the plane of a face
/// parallel to the ray: there `0 * inf = NaN`, `f32::min` / `f32::max` keep
/// the infinite lane, and the ray (grazing the face in its plane) misses.
#[inline]
pub fn slab(origin: Vec3A, inv_dir: Vec3A, min: Vec3A, max: Vec3A) -> (f32, f32) {
    let t0 = (min - origin) * inv_dir;
    let t1 = (max - origin) * inv_dir;
    (t0.min(t1).max_element(), t0.max(t1).min_element())
}

/// Outward normal of the face of `b` through which the ray enters it.
pub fn entry_normal(origin: Vec3, inv_dir: Vec3, b: &Aabb, dir: Vec3) -> Vec3 {
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

/// A closed segment, set up for slab tests.
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    /// Start point.
    pub from: Vec3A,
    /// `1 / (to - from)`.
    pub inv_dir: Vec3A,
}

impl Segment {
    /// The segment from `from` to `to`.
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
        let (near, far) = slab(self.from, self.inv_dir, b.min, b.max);
        near <= far && far >= 0.0 && near <= 1.0
    }
}

/// Opaque boxes and a BVH over them.
///
/// The boxes are stored in the BVH's leaf order, so that a leaf's range of
/// primitive slots is a range of boxes; [`Occluders::id`] gives a slot's
/// index in the input.
#[derive(Clone)]
pub struct Occluders {
    boxes: Vec<BvhAabb>,
    ids: Vec<u32>,
    bvh: Bvh2,
    /// Depth of the BVH: the traversal stack [`Occluders::any_in`] needs.
    depth: usize,
}

impl Occluders {
    /// The boxes `boxes` (referred to by their index) in a BVH built with
    /// `obvhs`'s medium preset (up to 8 boxes a leaf).
    pub fn new(boxes: &[Aabb]) -> Self {
        let input: Vec<BvhAabb> = boxes
            .iter()
            .map(|b| BvhAabb::new(b.min.into(), b.max.into()))
            .collect();
        if input.is_empty() {
            return Self {
                boxes: Vec::new(),
                ids: Vec::new(),
                bvh: Bvh2::default(),
                depth: 0,
            };
        }
        let mut bvh = build_bvh2(
            &input,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let ids = std::mem::take(&mut bvh.primitive_indices);
        // Leaves now index the reordered boxes directly.
        bvh.primitive_indices = (0..ids.len() as u32).collect();
        Self {
            boxes: ids.iter().map(|&i| input[i as usize]).collect(),
            ids,
            depth: bvh.depth(0),
            bvh,
        }
    }

    /// Number of boxes.
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    /// Whether there are no boxes.
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// The input index of the box in slot `slot`.
    pub fn id(&self, slot: usize) -> usize {
        self.ids[slot] as usize
    }

    /// The box in slot `slot`.
    pub fn get(&self, slot: usize) -> &BvhAabb {
        &self.boxes[slot]
    }

    /// Whether some box meets the closed segment `[from, to]`: an any-hit
    /// query (the traversal stops at the first box hit).
    #[inline]
    pub fn blocked(&self, from: Vec3, to: Vec3) -> bool {
        let segment = Segment::new(from, to);
        self.any_along(from, to, |b| segment.hits(b))
    }

    /// Whether `test` holds for some box in a leaf whose bounds the segment
    /// from `from` to `to` meets; stops at the first. `test` decides about
    /// the box itself (the BVH only prunes).
    #[inline]
    pub fn any_along(&self, from: Vec3, to: Vec3, mut test: impl FnMut(&BvhAabb) -> bool) -> bool {
        let ray = Ray::new(from.into(), Vec3A::from(to) - Vec3A::from(from), 0.0, 1.0);
        let boxes = &self.boxes;
        let missed = self.bvh.ray_traverse_miss(ray, |_, slot| {
            if test(&boxes[slot]) {
                0.0
            } else {
                f32::INFINITY
            }
        });
        !missed
    }

    /// The nearest box the ray `origin + t * dir` enters at some `t > 0`: `t`
    /// and the box's input index.
    pub fn nearest(&self, origin: Vec3, dir: Vec3) -> Option<(f32, usize)> {
        let ray = Ray::new_inf(origin.into(), dir.into());
        let (origin, inv_dir) = (Vec3A::from(origin), Vec3A::from(dir.recip()));
        let boxes = &self.boxes;
        let mut hit = RayHit::none();
        let found = self.bvh.ray_traverse(ray, &mut hit, |_, slot| {
            let b = &boxes[slot];
            let (near, far) = slab(origin, inv_dir, b.min, b.max);
            if near <= far && near > 0.0 {
                near
            } else {
                f32::INFINITY
            }
        });
        found.then(|| (hit.t, self.id(hit.primitive_id as usize)))
    }

    /// Depth-first search: descends into every BVH node whose bounds pass
    /// `enter` and calls `visit` on each box of the leaves reached, until
    /// `visit` returns `true` (then `any_in` returns `true`). `enter` must
    /// hold for a node's bounds whenever it may hold for a box inside them.
    #[inline]
    pub fn any_in(
        &self,
        enter: impl FnMut(&BvhAabb) -> bool,
        mut visit: impl FnMut(&BvhAabb) -> bool,
    ) -> bool {
        self.any_slot_in(enter, |_, b| visit(b))
    }

    /// [`any_in`](Self::any_in), `visit` given each box's slot too.
    #[inline]
    pub fn any_slot_in(
        &self,
        mut enter: impl FnMut(&BvhAabb) -> bool,
        mut visit: impl FnMut(usize, &BvhAabb) -> bool,
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
            slots.into_iter().any(|slot| visit(slot, &self.boxes[slot]))
        };
        if root.is_leaf() {
            return leaf(root);
        }
        let mut found = false;
        // A stack as deep as the tree (obvhs sizes its own for the deepest
        // tree it expects, 96 entries or more, and clears it per call).
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
}

/// Smallest box holding both.
pub fn union(a: Aabb, b: Aabb) -> Aabb {
    Aabb {
        min: a.min.min(b.min),
        max: a.max.max(b.max),
    }
}

/// Whether two closed boxes meet.
pub fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    a.min.cmple(b.max).all() && b.min.cmple(a.max).all()
}

/// `b` grown (or, for negative `by`, shrunk) by `by` on every side.
pub fn grown(b: &Aabb, by: f32) -> Aabb {
    Aabb {
        min: b.min - by,
        max: b.max + by,
    }
}

/// The eight corners of a box.
pub fn corners(b: &Aabb) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        )
    })
}
