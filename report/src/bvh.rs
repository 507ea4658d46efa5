//! Axis-aligned boxes and a bounding-volume hierarchy over them: the ray
//! casting of the night city and of its shadow rays.

use glam::Vec3;
use manylights::Aabb;

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

/// A closed segment, set up for slab tests.
pub struct Segment {
    /// Start point.
    pub from: Vec3,
    /// `1 / (to - from)`.
    pub inv_dir: Vec3,
}

impl Segment {
    /// The segment from `from` to `to`.
    pub fn new(from: Vec3, to: Vec3) -> Self {
        Self {
            from,
            inv_dir: (to - from).recip(),
        }
    }

    /// Whether the segment meets the closed box `b`.
    pub fn hits(&self, b: &Aabb) -> bool {
        let (near, far) = slab(self.from, self.inv_dir, b);
        near <= far && far >= 0.0 && near <= 1.0
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
