//! [`Shadows`], the visibility host of the scenes with occluders: a
//! conservative shaft classifier (Haines and Wallace 1994) and any-hit shadow
//! rays, both against opaque boxes in an `obvhs` BVH ([`Occluders`]). It is
//! the recipe for plugging a renderer's own ray tracer into the crate's
//! `Visibility` trait.

use glam::{DVec2, Vec3, Vec3A};
use manylights::{Aabb, Coverage, NodeRegion, Visibility};
use obvhs::aabb::Aabb as BvhAabb;

use crate::bvh::{Occluders, Segment, corners};
use crate::measure::{Counted, Queries};

/// Shadow rays start this far off the surface along its normal, so that a
/// point on a wall is not occluded by its own building. It is part of the
/// host's definition of visibility, used alike by the tree's queries and by
/// the exact sum.
pub const SHADOW_OFFSET: f32 = 0.05;

/// Safety margin of the classifier, in scene units, for scenes whose
/// coordinates stay below 1,000, where an `f32` ulp is at most `6.1e-5`.
/// Every `f32` test here (the shadow ray's slab test, a shaft plane's dot
/// product with a box corner, the corner segments' slab tests) errs by a few
/// ulps of the coordinates, below `1e-3` in all. Occluders are grown by the
/// margin before a shaft is declared to miss them and shrunk by it before
/// one is said to block a node, so rounding cannot turn a conservative
/// answer into a wrong one.
pub const MARGIN: f32 = 0.01;

/// Points of a node's box that [`Shadows::visible_fraction`] casts a shadow
/// ray to: the virtual light's position (the lights' intensity-weighted
/// centroid) and, as offsets from the box's centre in half-extents, the
/// four vertices of a tetrahedron inscribed in the box at half its size.
pub const FRACTION_POINTS: [Vec3; 4] = [
    Vec3::new(0.5, 0.5, 0.5),
    Vec3::new(0.5, -0.5, -0.5),
    Vec3::new(-0.5, 0.5, -0.5),
    Vec3::new(-0.5, -0.5, 0.5),
];

/// Occlusion by opaque boxes, for one shading point, with counters of the
/// work asked of it.
///
/// # Classification (shaft culling, Haines and Wallace 1994)
///
/// The *shaft* of a node is the convex hull `H` of the (lifted) shading
/// point `p` and the node's box `N` ([`NodeRegion::aabb`]): the union of
/// every segment from `p` to a point of `N`. Every face of `H` is a face of
/// `N` or the plane through `p` and an edge of `N`, and every edge of `N` is
/// parallel to an axis, so `H` is exactly the bounding box of `p` and `N`
/// cut by the planes through `p` and the *silhouette* edges of `N` (edges
/// between a face turned towards `p` and one turned away); each such plane
/// contains an axis and is found in the projection along it ([`Shaft`]).
///
/// * [`Coverage::Visible`] when no occluder, grown by [`MARGIN`], meets the
///   shaft's bounding box or all its planes: a box that lies wholly outside
///   one half-space containing `H` meets no segment from `p` to `N`. The BVH
///   is descended through the nodes whose bounds pass the same test (a node
///   holds its boxes, so a node outside the shaft holds none inside it).
///   Each plane's offset is the largest value over the hull's vertices (`p`
///   and the corners of `N`) of the stored (rounded) normal's dot product,
///   computed in `f64`: a rounded normal tilts the plane but never lets it
///   cut into the shaft.
/// * [`Coverage::Occluded`] when one occluder, shrunk by [`MARGIN`], meets
///   the segments from `p` to all eight corners of `N`. For a convex box `B`
///   the set `{q : [p, q] meets B} = {p + s (b - p) : b in B, s >= 1}` is
///   convex, so it then holds the corners' convex hull, `N`: every segment
///   from `p` to the node, so every light's shadow ray, passes at least
///   [`MARGIN`] deep through `B`, and [`Visibility::visible`] reports it
///   blocked. Such a box also meets the segment to the centre of `N`, so only
///   the boxes along that segment (an any-hit traversal of the BVH) are
///   tried.
/// * [`Coverage::Partial`] otherwise, which is always correct.
///
/// Both `Visible` and `Occluded` are therefore conservative with respect to
/// this host's own [`Visibility::visible`], which is what the crate's
/// certified bound needs (the contract of [`Visibility`]); the member's
/// tests compare the classifier with rays to many points of random node
/// boxes.
///
/// # Visible fraction
///
/// A partially occluded node is estimated at the share of
/// [`FRACTION_POINTS`] reached by a shadow ray: four rays per `Partial`
/// answer. The fraction moves the estimate, never the certified interval
/// `[0, upper]`; four rays keep the cost to that of refining the node by
/// one level with a ray per light, about a third of what a classification
/// costs, and are enough for a mean error well below the certified one
/// (the report measures it).
pub struct Shadows<'o> {
    occluders: &'o Occluders,
    /// `SHADOW_OFFSET` times the surface normal: queries start at the shading
    /// point plus this.
    lift: Vec3,
    /// Classifications answered: visible, occluded, partial.
    pub answers: [u32; 3],
    /// Shadow rays cast: point-to-point queries and the visible fraction's.
    pub rays: u32,
}

impl<'o> Shadows<'o> {
    /// The host for a shading point with unit `normal`.
    pub fn new(occluders: &'o Occluders, normal: Vec3) -> Self {
        Self {
            occluders,
            lift: normal * SHADOW_OFFSET,
            answers: [0; 3],
            rays: 0,
        }
    }

    /// Classifications answered.
    pub fn classifications(&self) -> u32 {
        self.answers.iter().sum()
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

    /// Classifies the box `target` as seen from `point` (the shading point,
    /// lifted here): see the type's documentation, "Classification".
    pub fn classify_box(&mut self, point: Vec3, target: &Aabb) -> Coverage {
        let apex = point + self.lift;
        let shaft = Shaft::new(apex, target, MARGIN);
        if !self
            .occluders
            .any_in(|b| shaft.meets(b), |b| shaft.meets(b))
        {
            return self.answer(Coverage::Visible);
        }
        let centre = 0.5 * (target.min + target.max);
        let to_centre = Segment::new(apex, centre);
        let mut to_corners: Option<[Segment; 8]> = None;
        let blocks_all = |b: &BvhAabb| {
            let core = BvhAabb::new(b.min + MARGIN, b.max - MARGIN);
            core.valid()
                && to_centre.hits(&core)
                && to_corners
                    .get_or_insert_with(|| corners(target).map(|c| Segment::new(apex, c)))
                    .iter()
                    .all(|s| s.hits(&core))
        };
        let occluded = self.occluders.any_along(apex, centre, blocks_all);
        self.answer(if occluded {
            Coverage::Occluded
        } else {
            Coverage::Partial
        })
    }

    /// One shadow ray from the lifted point `apex`, counted.
    fn ray(&mut self, apex: Vec3, to: Vec3) -> bool {
        self.rays += 1;
        !self.occluders.blocked(apex, to)
    }
}

impl Visibility for Shadows<'_> {
    /// [`Shadows::classify_box`] of the node's box.
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        self.classify_box(point, &node.aabb)
    }

    /// One any-hit shadow ray: the segment from the lifted point to the
    /// light.
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.ray(point + self.lift, light)
    }

    /// The share of [`FRACTION_POINTS`] of the node's box (and its centroid)
    /// that a shadow ray reaches: see the type's documentation.
    fn visible_fraction(&mut self, point: Vec3, node: &NodeRegion) -> Option<f32> {
        let apex = point + self.lift;
        let centre = 0.5 * (node.aabb.min + node.aabb.max);
        let half = 0.5 * (node.aabb.max - node.aabb.min);
        let targets = FRACTION_POINTS
            .map(|offset| centre + offset * half)
            .into_iter()
            .chain([node.centroid]);
        let seen = targets.filter(|&q| self.ray(apex, q)).count();
        Some(seen as f32 / (FRACTION_POINTS.len() + 1) as f32)
    }
}

impl Counted for Shadows<'_> {
    fn queries(&self) -> Queries {
        Queries {
            shadow_rays: self.rays,
            classify: self.classifications(),
        }
    }
}

/// Most planes a shaft from a point to a box has: two per pair of axes.
const MAX_PLANES: usize = 6;

/// A half-space `normal . x <= offset`, `normal` of unit length.
#[derive(Clone, Copy, Debug, Default)]
struct Plane {
    normal: Vec3A,
    offset: f32,
}

/// The shaft from a point to a box, grown by a margin: its bounding box and
/// the planes through the point and the box's silhouette edges (Haines and
/// Wallace 1994; see [`Shadows`]).
#[derive(Clone, Copy, Debug)]
pub struct Shaft {
    min: Vec3A,
    max: Vec3A,
    planes: [Plane; MAX_PLANES],
    count: usize,
}

impl Shaft {
    /// The shaft from `apex` to `target`, every face pushed out by `margin`
    /// (so that a box grown by `margin` on every side meets the grown shaft
    /// whenever it meets the shaft).
    pub fn new(apex: Vec3, target: &Aabb, margin: f32) -> Shaft {
        let (lo, hi) = (target.min.min(apex), target.max.max(apex));
        let mut shaft = Shaft {
            min: Vec3A::from(lo) - margin,
            max: Vec3A::from(hi) + margin,
            planes: [Plane::default(); MAX_PLANES],
            count: 0,
        };
        let p = apex.as_dvec3();
        let (min, max) = (target.min.as_dvec3(), target.max.as_dvec3());
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            let q = DVec2::new(p[i], p[j]);
            let rect = [
                DVec2::new(min[i], min[j]),
                DVec2::new(max[i], min[j]),
                DVec2::new(min[i], max[j]),
                DVec2::new(max[i], max[j]),
            ];
            for (k, c) in rect.iter().enumerate() {
                // The face of the rectangle on the corner's side of axis i
                // (j) is turned towards the point when the point lies
                // strictly beyond it.
                let towards_i = if k & 1 == 0 { q.x < c.x } else { q.x > c.x };
                let towards_j = if k & 2 == 0 { q.y < c.y } else { q.y > c.y };
                if towards_i == towards_j {
                    continue; // not a silhouette corner
                }
                let u = *c - q;
                let mut n = DVec2::new(u.y, -u.x);
                // The rectangle lies on one side of the line through q and
                // its silhouette corner: make that side the inside.
                let side: f64 = rect.iter().map(|r| n.dot(*r - q)).sum();
                if side == 0.0 {
                    continue; // degenerate rectangle on the line: no plane
                }
                if side > 0.0 {
                    n = -n;
                }
                n = n.normalize();
                let mut normal = Vec3A::ZERO;
                normal[i] = n.x as f32;
                normal[j] = n.y as f32;
                let stored = (f64::from(normal[i]), f64::from(normal[j]));
                let dot = |v: DVec2| stored.0 * v.x + stored.1 * v.y;
                let reach = rect.iter().map(|r| dot(*r)).fold(dot(q), f64::max);
                let slack = f64::from(margin) * (stored.0.abs() + stored.1.abs());
                shaft.planes[shaft.count] = Plane {
                    normal,
                    offset: (reach + slack) as f32,
                };
                shaft.count += 1;
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
        self.planes[..self.count].iter().all(|plane| {
            let nearest = Vec3A::select(plane.normal.cmpge(Vec3A::ZERO), b.min, b.max);
            plane.normal.dot(nearest) <= plane.offset
        })
    }
}
