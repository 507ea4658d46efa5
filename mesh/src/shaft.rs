//! Shafts (Haines and Wallace 1994, "Shaft culling for efficient ray-traced
//! radiosity"): the convex region swept by every segment from a point, or
//! from a box, to a box, as a bounding box cut by planes, grown by a margin;
//! and the test of whether an axis-aligned box may meet it.
//!
//! The shaft from a point `p` to a box `N` is the convex hull `H` of `p` and
//! `N`. Every face of `H` is a face of `N` or the plane through `p` and an
//! edge of `N`, and every edge of `N` is parallel to an axis, so `H` is
//! exactly the bounding box of `p` and `N` cut by the planes through `p` and
//! the *silhouette* edges of `N` (between a face turned towards `p` and one
//! turned away); each such plane contains an axis and is found in the
//! projection along it. The shaft between two boxes is their bounding box
//! cut, in each projection along an axis, by the lines through the edges of
//! the two rectangles' convex hull that join one rectangle to the other.
//!
//! A box is culled exactly when a face plane or an axis separates it from
//! the shaft: in the projection along each axis the test is the complete
//! separating-axis test of a convex polygon and a rectangle, and those
//! projections hold every separating axis of two convex bodies whose edges
//! are axis-parallel or through the apex. Each plane's offset is the largest
//! value over the hull's vertices of the *stored* normal's dot product, so a
//! rounded normal tilts a plane but never lets it cut into the shaft; the
//! margin (in units of the normal's 1-norm, by which a dot product's
//! rounding scales too) covers the rounding of the dot products themselves.

use glam::{Vec2, Vec3, Vec3A, Vec4};
use manylights::Aabb;
use obvhs::aabb::Aabb as BvhAabb;

/// Lanes of a shaft's planes. A shaft from a point to a box has at most six
/// planes, two per projection; the shaft between two boxes at most eight.
/// They are stored in two groups of four lanes (the unused ones hold every
/// point), each tested against a box at once.
pub const PLANE_LANES: usize = 8;

/// The shaft from a point to a box, grown by a margin: its bounding box and
/// the half-spaces `normal . x <= offset` through the point and the box's
/// silhouette edges (see the [module documentation](self)), normals
/// stored by component, four planes to a vector.
#[derive(Clone, Copy, Debug)]
pub struct Shaft {
    min: Vec3A,
    max: Vec3A,
    normal: [[Vec4; PLANE_LANES / 4]; 3],
    offset: [Vec4; PLANE_LANES / 4],
}

/// A shaft from a point to a box ([`Shaft::new`]) as it is first found: its
/// bounding box and its planes, each as `[n_i, n_j, offset]` with the axes
/// `(i, j)` of [`PAIR_AXES`] (two planes per projection). A child's shaft
/// filters a list of boxes in this form, four boxes at a time; a shaft
/// tested against a BVH's nodes is set out as a [`Shaft`].
pub struct PointShaft {
    /// Smallest corner of the bounding box (grown by the margin).
    pub min: Vec3A,
    /// Largest corner of the bounding box (grown by the margin).
    pub max: Vec3A,
    /// The planes `[n_i, n_j, offset]`, two per projection, plane `k` on
    /// the axes `PAIR_AXES[k / 2]`; a missing plane is `[0, 0, inf]`.
    pub pairs: [[f32; 3]; 6],
}

impl PointShaft {
    /// The shaft from `apex` to `target`, every face pushed out by `margin`
    /// (see [`Shaft::new`]).
    #[inline]
    pub fn new(apex: Vec3, target: &Aabb, margin: f32) -> PointShaft {
        let (p, lo, hi) = (apex, target.min, target.max);
        // The projections along z (axes x, y), x (y, z) and y (z, x), one a
        // lane, two planes each.
        let lanes = |v: Vec3| [Vec4::new(v.x, v.y, v.z, 0.0), Vec4::new(v.y, v.z, v.x, 0.0)];
        let lines = silhouettes(lanes(p), lanes(lo), lanes(hi), margin);
        let plane = |m: usize, k: usize| {
            let [n_i, n_j, offset] = lines[m].map(|v| v.to_array()[k]);
            [n_i, n_j, offset]
        };
        PointShaft {
            min: Vec3A::from(lo.min(p)) - margin,
            max: Vec3A::from(hi.max(p)) + margin,
            pairs: [
                plane(0, 0),
                plane(1, 0),
                plane(0, 1),
                plane(1, 1),
                plane(0, 2),
                plane(1, 2),
            ],
        }
    }

    /// The same shaft set out as a [`Shaft`].
    pub fn planes(&self) -> Shaft {
        let mut shaft = Shaft::boxed(self.min, self.max);
        for (k, &[a, b, offset]) in self.pairs.iter().enumerate() {
            let (i, j) = PAIR_AXES[k / 2];
            shaft.set_plane(k, (i, a), (j, b), offset);
        }
        shaft
    }
}

/// The axes `(i, j)` of the planes `2 k` and `2 k + 1` of a shaft from a
/// point: the projections along z, x and y.
pub const PAIR_AXES: [(usize, usize); 3] = [(0, 1), (1, 2), (2, 0)];

impl Shaft {
    /// Only the bounding box of `min` and `max`: every plane holds every
    /// point.
    fn boxed(min: Vec3A, max: Vec3A) -> Shaft {
        Shaft {
            min,
            max,
            normal: [[Vec4::ZERO; PLANE_LANES / 4]; 3],
            offset: [Vec4::INFINITY; PLANE_LANES / 4],
        }
    }

    /// Sets plane `lane` to `n . x <= offset` with `n` zero but for
    /// components `n_i` and `n_j`.
    fn set_plane(
        &mut self,
        lane: usize,
        (i, n_i): (usize, f32),
        (j, n_j): (usize, f32),
        offset: f32,
    ) {
        self.normal[i][lane / 4][lane % 4] = n_i;
        self.normal[j][lane / 4][lane % 4] = n_j;
        self.offset[lane / 4][lane % 4] = offset;
    }

    /// The shaft from `apex` to `target`, every face pushed out by `margin`
    /// (so that a box grown by `margin` on every side meets the grown shaft
    /// whenever it meets the shaft).
    pub fn new(apex: Vec3, target: &Aabb, margin: f32) -> Shaft {
        PointShaft::new(apex, target, margin).planes()
    }

    /// The shaft between the boxes `a` and `b`, every face pushed out by
    /// `margin`: their bounding box and, in each projection along an axis,
    /// the lines through the edges of the two rectangles' convex hull that
    /// join one rectangle to the other (at most two per projection), each a
    /// half-space holding the hull of the boxes.
    pub fn between(a: &Aabb, b: &Aabb, margin: f32) -> Shaft {
        let mut shaft = Shaft::boxed(
            Vec3A::from(a.min.min(b.min)) - margin,
            Vec3A::from(a.max.max(b.max)) + margin,
        );
        let mut count = 0;
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            let rect = |r: &Aabb| {
                let (lo, hi) = (Vec2::new(r.min[i], r.min[j]), Vec2::new(r.max[i], r.max[j]));
                [lo, Vec2::new(hi.x, lo.y), hi, Vec2::new(lo.x, hi.y)]
            };
            let (ra, rb) = (rect(a), rect(b));
            let mut points: [(Vec2, bool); 8] = std::array::from_fn(|k| {
                if k < 4 {
                    (ra[k], false)
                } else {
                    (rb[k - 4], true)
                }
            });
            let all = points.map(|p| p.0);
            let (chain, len) = hull(&mut points);
            for k in 0..len {
                let (p, q) = (chain[k], chain[(k + 1) % len]);
                if p.1 == q.1 {
                    continue; // an edge of one rectangle: the bounding box holds it
                }
                let u = q.0 - p.0;
                // Counter-clockwise hull: the outward normal is to the right.
                let n = Vec2::new(u.y, -u.x);
                if n == Vec2::ZERO {
                    continue;
                }
                // The largest value over all eight corners, so that the
                // half-plane holds the hull whatever the rounding.
                let reach = all
                    .iter()
                    .map(|c| n.dot(*c))
                    .fold(f32::NEG_INFINITY, f32::max);
                debug_assert!(count < PLANE_LANES, "two joining edges per projection");
                let offset = reach + margin * (n.x.abs() + n.y.abs());
                shaft.set_plane(count, (i, n.x), (j, n.y), offset);
                count += 1;
            }
        }
        shaft
    }

    /// Whether the box `b` may meet the shaft: `false` only when it lies
    /// outside the bounding box or wholly beyond one plane.
    #[inline]
    pub fn meets(&self, b: &BvhAabb) -> bool {
        if (b.min.cmpgt(self.max) | b.max.cmplt(self.min)).any() {
            return false;
        }
        // The smallest `normal . x` over the box, per plane: each term's
        // smaller value over the box's extent along its axis.
        let (lo, hi) = (b.min, b.max);
        (0..PLANE_LANES / 4).all(|h| {
            let [x, y, z] = [self.normal[0][h], self.normal[1][h], self.normal[2][h]];
            let least =
                (x * lo.x).min(x * hi.x) + (y * lo.y).min(y * hi.y) + (z * lo.z).min(z * hi.z);
            !least.cmpgt(self.offset[h]).any()
        })
    }
}

/// The lines through the point `q` and the silhouette corners of the
/// rectangle `[lo, hi]`, in each projection along an axis (lane `k` of
/// each vector holds the projection's axes `(i, j)` of [`PAIR_AXES`]; lane
/// 3 is unused): as `[n_i, n_j, offset]`, the rectangle and `q` in
/// `n . x <= offset`, pushed out by `margin` in the 1-norm of `n` (the dot
/// product's rounding scales alike).
/// A silhouette corner lies between a side of the rectangle turned towards
/// `q` (`q` strictly beyond it) and one turned away: with `q` beyond one
/// pair of sides, the two corners of the near side; beyond both, the two
/// corners off the diagonal through the nearest corner. The offset is the
/// largest value over `q` and the four corners of the stored normal's dot
/// product, so that the half-plane holds the whole projected hull whatever
/// the normal's rounding. A missing line (`q` inside the rectangle's
/// extent on both axes, or on a corner) is `[0, 0, inf]`, which holds
/// every point.
///
/// Returned as the two lines' `(n_i, n_j, offset)`, lane by lane: every
/// lane does the operations of one projection's line in the same order,
/// without a branch (the cases picked by comparisons were mispredicted
/// often).
#[inline(always)]
fn silhouettes(q: [Vec4; 2], lo: [Vec4; 2], hi: [Vec4; 2], margin: f32) -> [[Vec4; 3]; 2] {
    let below = [q[0].cmplt(lo[0]), q[1].cmplt(lo[1])];
    let beyond = [below[0] | q[0].cmpgt(hi[0]), below[1] | q[1].cmpgt(hi[1])];
    let near = |k: usize| Vec4::select(below[k], lo[k], hi[k]);
    let far = |k: usize| Vec4::select(below[k], hi[k], lo[k]);
    // Beyond one pair of sides, the two corners of the near side; beyond
    // both, the two corners off the diagonal through the nearest corner.
    let corners = [
        [
            Vec4::select(beyond[0], near(0), lo[0]),
            Vec4::select(beyond[1], Vec4::select(beyond[0], far(1), near(1)), lo[1]),
        ],
        [
            Vec4::select(beyond[0], Vec4::select(beyond[1], far(0), near(0)), hi[0]),
            Vec4::select(beyond[1], near(1), hi[1]),
        ],
    ];
    let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let some = beyond[0] | beyond[1];
    corners.map(|c| {
        // A normal of the line through q and c (of any length: the
        // half-plane, its margin and the box test scale alike).
        let (n_i, n_j) = (c[1] - q[1], q[0] - c[0]);
        // No line where q is inside the rectangle's extent on both axes or
        // on the corner.
        let line = some & !(n_i.cmpeq(Vec4::ZERO) & n_j.cmpeq(Vec4::ZERO));
        // The rectangle's side is the inside.
        let flip = (n_i * (centre[0] - q[0]) + n_j * (centre[1] - q[1])).cmpgt(Vec4::ZERO);
        let (n_i, n_j) = (Vec4::select(flip, -n_i, n_i), Vec4::select(flip, -n_j, n_j));
        let dot = |x: Vec4, y: Vec4| n_i * x + n_j * y;
        // The rectangle's largest value is at the corner that takes, per
        // axis, the maximum where the normal's component is positive, else
        // the minimum: rounding is monotone, so that corner's computed dot
        // product is the largest of the four computed ones too.
        let support = dot(
            Vec4::select(n_i.cmpgt(Vec4::ZERO), hi[0], lo[0]),
            Vec4::select(n_j.cmpgt(Vec4::ZERO), hi[1], lo[1]),
        );
        let q_dot = dot(q[0], q[1]);
        let reach = Vec4::select(q_dot.cmpgt(support), q_dot, support);
        let offset = reach + margin * (n_i.abs() + n_j.abs());
        [
            Vec4::select(line, n_i, Vec4::ZERO),
            Vec4::select(line, n_j, Vec4::ZERO),
            Vec4::select(line, offset, Vec4::INFINITY),
        ]
    })
}

/// The convex hull of `points` (each tagged), counter-clockwise (Andrew's
/// monotone chain; collinear points dropped): its first `len` vertices, an
/// edge from each to the next (the last to the first). No allocation: a
/// shaft between two boxes is built per classification.
fn hull(points: &mut [(Vec2, bool); 8]) -> ([(Vec2, bool); 17], usize) {
    // (A stable sort of 8 elements sorts in place.)
    points.sort_by(|a, b| a.0.x.total_cmp(&b.0.x).then(a.0.y.total_cmp(&b.0.y)));
    let cross = |o: Vec2, a: Vec2, b: Vec2| (a - o).perp_dot(b - o);
    let mut chain = [(Vec2::ZERO, false); 17];
    let mut len = 0;
    for pass in 0..2 {
        let start = len;
        for k in 0..points.len() {
            let p = points[if pass == 0 { k } else { points.len() - 1 - k }];
            while len >= start + 2 && cross(chain[len - 2].0, chain[len - 1].0, p.0) <= 0.0 {
                len -= 1;
            }
            chain[len] = p;
            len += 1;
        }
        len -= 1; // the last point starts the other half
    }
    (chain, len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::corners;

    /// Every point of segments between two boxes lies in their shaft, and a
    /// box well away from both does not meet it.
    #[test]
    fn the_shaft_between_two_boxes_holds_every_segment_between_them() {
        let a = Aabb {
            min: Vec3::new(0.0, 0.0, 0.0),
            max: Vec3::new(1.0, 2.0, 0.5),
        };
        let b = Aabb {
            min: Vec3::new(10.0, 5.0, 3.0),
            max: Vec3::new(11.0, 5.5, 6.0),
        };
        let shaft = Shaft::between(&a, &b, 0.0);
        let (ca, cb) = (corners(&a), corners(&b));
        for p in ca {
            for q in cb {
                for k in 0..=10 {
                    let x = p + (q - p) * (k as f32 / 10.0);
                    let tiny = BvhAabb::new((x - 1e-4).into(), (x + 1e-4).into());
                    assert!(shaft.meets(&tiny), "{x} outside the shaft");
                }
            }
        }
        // Beside the segments, inside the bounding box: outside the shaft.
        let aside = BvhAabb::new(Vec3A::new(9.0, 0.0, 0.0), Vec3A::new(9.5, 0.5, 0.5));
        assert!(!shaft.meets(&aside));
    }

    /// Every point of segments from a point to a box lies in their shaft,
    /// wherever the point is (beyond one, two or three pairs of the box's
    /// sides, inside its extent along some axes, on a corner or an edge's
    /// line), and boxes that lie beside the segments are culled.
    #[test]
    fn the_shaft_from_a_point_holds_every_segment_to_the_box() {
        let target = Aabb {
            min: Vec3::new(2.0, -1.0, 4.0),
            max: Vec3::new(3.0, 1.5, 4.5),
        };
        let reach = [-3.0, 2.0, 2.5, 3.0, 8.0];
        let mut culled = 0;
        for x in reach {
            for y in reach.map(|v| v - 1.0) {
                for z in reach.map(|v| v + 2.0) {
                    let apex = Vec3::new(x, y, z);
                    let shaft = Shaft::new(apex, &target, 0.0);
                    for q in corners(&target) {
                        for k in 0..=8 {
                            let at = apex + (q - apex) * (k as f32 / 8.0);
                            let tiny = BvhAabb::new((at - 1e-4).into(), (at + 1e-4).into());
                            assert!(shaft.meets(&tiny), "{at} outside the shaft from {apex}");
                        }
                    }
                    // A small box halfway along the segment to the centre,
                    // pushed off it sideways by more than the target's
                    // size: outside the hull, and culled whenever a plane
                    // separates it.
                    let centre = 0.5 * (target.min + target.max);
                    let middle = 0.5 * (apex + centre);
                    let side = (centre - apex).normalize().any_orthonormal_vector() * 6.0;
                    let aside = middle + side;
                    let off = BvhAabb::new((aside - 0.1).into(), (aside + 0.1).into());
                    culled += usize::from(!shaft.meets(&off));
                }
            }
        }
        assert!(culled > 0, "no box beside the segments culled");
    }
}

/// The segments from a point to the eight corners of a box, set up for
/// slab tests four at a time: whether a convex occluder (a box) meets all
/// of them decides whether it hides the whole box from the point.
#[derive(Clone, Copy, Debug)]
pub struct Fan {
    from: Vec3A,
    /// Per axis, `1 / (corner - from)` of corners 0-3 and 4-7 (in the order
    /// of [`corners`](crate::corners)).
    inv_dir: [[Vec4; 2]; 3],
}

impl Fan {
    /// The segments from `from` to the corners of `target`.
    #[inline]
    pub fn new(from: Vec3, target: &Aabb) -> Fan {
        let (lo, hi) = (target.min - from, target.max - from);
        let x = Vec4::new(lo.x, hi.x, lo.x, hi.x).recip();
        let y = Vec4::new(lo.y, lo.y, hi.y, hi.y).recip();
        Fan {
            from: from.into(),
            inv_dir: [
                [x, x],
                [y, y],
                [Vec4::splat(lo.z).recip(), Vec4::splat(hi.z).recip()],
            ],
        }
    }

    /// Whether every segment meets the closed box `b`: per segment the slab
    /// test of a shadow ray against a box's bounds, four lanes at a time.
    #[inline]
    pub fn all_meet(&self, b: &BvhAabb) -> bool {
        let (lo, hi) = (b.min - self.from, b.max - self.from);
        (0..2).all(|h| {
            let t = |axis: usize, v: Vec3A| Vec4::splat(v[axis]) * self.inv_dir[axis][h];
            let (x0, x1) = (t(0, lo), t(0, hi));
            let (y0, y1) = (t(1, lo), t(1, hi));
            let (z0, z1) = (t(2, lo), t(2, hi));
            let near = x0.min(x1).max(y0.min(y1)).max(z0.min(z1));
            let far = x0.max(x1).min(y0.max(y1)).min(z0.max(z1));
            (near.cmple(far) & far.cmpge(Vec4::ZERO) & near.cmple(Vec4::ONE)).all()
        })
    }
}
