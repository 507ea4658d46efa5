//! [`Shadows`], the visibility host of the scenes with occluders: a
//! conservative shaft classifier (Haines and Wallace 1994) and any-hit shadow
//! rays, both against opaque boxes in an `obvhs` BVH ([`Occluders`]). It is
//! the recipe for plugging a renderer's own ray tracer into the crate's
//! `Visibility` trait.

use glam::{Vec2, Vec3, Vec3A};
use manylights::{Aabb, Coverage, NodeRegion, PointGroup, Visibility};
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
/// Every `f32` test here (the shadow ray's slab test, the corner segments'
/// slab tests, a shaft plane's dot product with a box corner, measured in
/// units of the plane normal's 1-norm, by which its margin is scaled too)
/// errs by a few ulps of the coordinates, below `1e-3` in all. Occluders are
/// grown by the margin before a shaft is declared to miss them and shrunk
/// by it before one is said to block a node, so rounding cannot turn a
/// conservative answer into a wrong one.
pub const MARGIN: f32 = 0.01;

/// Boxes tried as the single occluder of a node: the first few that the
/// segment to the centre of the node's box meets, in the BVH's traversal
/// order (nearer child first). A blocker of a whole node is nearly always
/// among them, and a long segment through foliage meets many boxes that
/// cannot be one.
pub const OCCLUDER_CANDIDATES: usize = 4;

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
/// * [`Coverage::Occluded`] when one occluder, shrunk by [`MARGIN`], meets
///   the segments from `p` to all eight corners of `N`. For a convex box `B`
///   the set `{q : [p, q] meets B} = {p + s (b - p) : b in B, s >= 1}` is
///   convex, so it then holds the corners' convex hull, `N`: every segment
///   from `p` to the node, so every light's shadow ray, passes at least
///   [`MARGIN`] deep through `B`, and [`Visibility::visible`] reports it
///   blocked. Such a box also meets the segment to the centre of `N`, so the
///   candidates are the first [`OCCLUDER_CANDIDATES`] boxes that an any-hit
///   traversal of the BVH along that segment meets. This test runs first:
///   it costs about one shadow ray, and most nodes the cut asks about in a
///   city are hidden behind a single building.
/// * [`Coverage::Visible`] when no occluder, grown by [`MARGIN`], meets the
///   shaft's bounding box and all its planes: a box that lies wholly outside
///   one half-space containing `H` meets no segment from `p` to `N`. The BVH
///   is descended through the nodes whose bounds pass the same test (a node
///   holds its boxes, so a node outside the shaft holds none inside it).
///   Each plane's offset is the largest value over the hull's vertices (`p`
///   and the corners of `N`) of the stored normal's dot product, so a
///   rounded normal tilts the plane but never lets it cut into the shaft;
///   the rounding of the dot products themselves is within [`MARGIN`]. With
///   every face of `H` tested, a box is culled exactly when a face plane or
///   an axis separates it from `H`: in the projection along each axis the
///   test is the complete separating-axis test of a convex polygon and a
///   rectangle, and those projections hold every separating axis of two
///   convex bodies whose edges are axis-parallel or through `p`.
/// * [`Coverage::Partial`] otherwise, which is always correct; without
///   building the shaft when a box meets the segment to the centre of `N`
///   (then the node is not visible).
///
/// Both `Visible` and `Occluded` are therefore conservative with respect to
/// this host's own [`Visibility::visible`], which is what the crate's
/// certified bound needs (the contract of [`Visibility`]); the member's
/// tests compare the classifier with rays to many points of random node
/// boxes and to every light of the nodes the cut asks about.
///
/// # Visible fraction
///
/// Off by default; [`Shadows::with_visible_fraction`] turns it on: a
/// partially occluded node is then estimated at the share of
/// [`FRACTION_POINTS`] (and the virtual light's position) that a shadow ray
/// reaches, five rays per `Partial` answer. The fraction moves the estimate,
/// never the certified interval `[0, upper]`, and the crate's cut asks for
/// it right after a `Partial` answer, when that node's interval is the
/// largest error in the cut: unless a budget stops the cut first, the node
/// is refined next and its estimate is rarely used. Five rays per partial
/// answer then only add cost (in the report's city at a certified 1%, 1.4
/// times the time for the same errors), so the host casts them only when
/// asked to, for renderers that shade with a budget.
pub struct Shadows<'o> {
    occluders: &'o Occluders,
    /// `SHADOW_OFFSET` times the surface normal: queries start at the shading
    /// point plus this.
    lift: Vec3,
    /// Classifications answered: visible, occluded, partial.
    pub answers: [u32; 3],
    /// Shadow rays cast: point-to-point queries and the visible fraction's.
    pub rays: u32,
    /// Whether [`Visibility::visible_fraction`] casts its rays.
    fraction: bool,
}

impl<'o> Shadows<'o> {
    /// The host for a shading point with unit `normal`.
    pub fn new(occluders: &'o Occluders, normal: Vec3) -> Self {
        Self {
            occluders,
            lift: normal * SHADOW_OFFSET,
            answers: [0; 3],
            rays: 0,
            fraction: false,
        }
    }

    /// The same host with the visible fraction on (see "Visible fraction").
    #[must_use]
    pub fn with_visible_fraction(mut self) -> Self {
        self.fraction = true;
        self
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
        self.classify_from(apex, &[apex], target, || Shaft::new(apex, target, MARGIN))
    }

    /// Classifies the box `target` as seen from every point of the box
    /// `points` (shading points, lifted here), for a batch of points that
    /// share this host's normal: `Occluded` when one occluder, shrunk by
    /// [`MARGIN`], meets all 64 segments between the corners of the two
    /// boxes (the points from which every segment to `target` meets a convex
    /// occluder form a convex set, and so do the targets seen through it
    /// from one point, so the corners decide); `Visible` when no occluder,
    /// grown by [`MARGIN`], meets the shaft of the two boxes, which holds
    /// their convex hull (every segment between them); `Partial` otherwise.
    pub fn classify_boxes(&mut self, points: &Aabb, target: &Aabb) -> Coverage {
        let from = Aabb {
            min: points.min + self.lift,
            max: points.max + self.lift,
        };
        let centre = 0.5 * (from.min + from.max);
        self.classify_from(centre, &corners(&from), target, || {
            Shaft::between(&from, target, MARGIN)
        })
    }

    /// The classification from the (lifted) points whose corners are
    /// `starts` (`centre` among them or inside their box) to `target`.
    /// Occluded: an occluder that blocks every segment from the starts to
    /// the target meets the segment from `centre` to the target's centre;
    /// the first few boxes along that segment are tried against the
    /// segments between the starts and the target's corners. Visible: no
    /// box meets `shaft()`.
    fn classify_from(
        &mut self,
        centre: Vec3,
        starts: &[Vec3],
        target: &Aabb,
        shaft: impl FnOnce() -> Shaft,
    ) -> Coverage {
        let middle = 0.5 * (target.min + target.max);
        let between = Segment::new(centre, middle);
        let ends = corners(target);
        let (mut tried, mut occluded, mut centre_blocked) = (0, false, false);
        self.occluders.any_along(centre, middle, |o| {
            centre_blocked |= between.hits(o);
            let core = BvhAabb::new(o.min + MARGIN, o.max - MARGIN);
            if !(core.valid() && between.hits(&core)) {
                return false;
            }
            tried += 1;
            occluded = starts
                .iter()
                .all(|&p| ends.iter().all(|&q| Segment::new(p, q).hits(&core)));
            occluded || tried == OCCLUDER_CANDIDATES
        });
        if occluded {
            return self.answer(Coverage::Occluded);
        }
        if centre_blocked {
            // A box meets one of the segments, so the node is not visible.
            return self.answer(Coverage::Partial);
        }
        // Visible: no box meets the shaft.
        let shaft = shaft();
        let meets = |o: &BvhAabb| shaft.meets(o);
        self.answer(if self.occluders.any_in(meets, meets) {
            Coverage::Partial
        } else {
            Coverage::Visible
        })
    }

    /// One shadow ray from the lifted point `apex`, counted.
    fn ray(&mut self, apex: Vec3, to: Vec3) -> bool {
        self.rays += 1;
        !self.occluders.blocked(apex, to)
    }
}

impl Visibility for Shadows<'_> {
    /// Groups of points are classified too, for batches whose points share
    /// the host's normal (the lift).
    const CLASSIFIES_GROUPS: bool = true;

    /// [`Shadows::classify_box`] of the node's box.
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        self.classify_box(point, &node.aabb)
    }

    /// [`Shadows::classify_boxes`] of the points' box and the node's box.
    fn classify_group(&mut self, group: &PointGroup, node: &NodeRegion) -> Coverage {
        self.classify_boxes(&group.aabb, &node.aabb)
    }

    /// One any-hit shadow ray: the segment from the lifted point to the
    /// light.
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.ray(point + self.lift, light)
    }

    /// With the fraction on, the share of [`FRACTION_POINTS`] of the node's
    /// box (and its centroid) that a shadow ray reaches; `None` otherwise.
    /// See the type's documentation, "Visible fraction".
    fn visible_fraction(&mut self, point: Vec3, node: &NodeRegion) -> Option<f32> {
        if !self.fraction {
            return None;
        }
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

/// Lanes of a shaft's planes. A shaft from a point to a box has at most six
/// planes, two per projection; they are stored in eight lanes (the unused
/// ones hold every point) so that the box test vectorizes.
const PLANE_LANES: usize = 8;

/// The shaft from a point to a box, grown by a margin: its bounding box and
/// the half-spaces `normal . x <= offset` through the point and the box's
/// silhouette edges (Haines and Wallace 1994; see [`Shadows`]), normals
/// stored by component.
#[derive(Clone, Copy, Debug)]
pub struct Shaft {
    min: Vec3A,
    max: Vec3A,
    normal: [[f32; PLANE_LANES]; 3],
    offset: [f32; PLANE_LANES],
}

impl Shaft {
    /// The shaft from `apex` to `target`, every face pushed out by `margin`
    /// (so that a box grown by `margin` on every side meets the grown shaft
    /// whenever it meets the shaft).
    pub fn new(apex: Vec3, target: &Aabb, margin: f32) -> Shaft {
        let mut shaft = Shaft {
            min: Vec3A::from(target.min.min(apex)) - margin,
            max: Vec3A::from(target.max.max(apex)) + margin,
            normal: [[0.0; PLANE_LANES]; 3],
            offset: [f32::INFINITY; PLANE_LANES],
        };
        let mut count = 0;
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            // The projection along the third axis: the point q and the
            // rectangle [lo, hi].
            let q = Vec2::new(apex[i], apex[j]);
            let lo = Vec2::new(target.min[i], target.min[j]);
            let hi = Vec2::new(target.max[i], target.max[j]);
            let (below, above) = (q.cmplt(lo), q.cmpgt(hi));
            if !(below | above).any() {
                continue; // q projects into the rectangle: no silhouette
            }
            let rect = [lo, Vec2::new(hi.x, lo.y), Vec2::new(lo.x, hi.y), hi];
            let centre = 0.5 * (lo + hi);
            for (k, &c) in rect.iter().enumerate() {
                // A side of the rectangle is turned towards q when q lies
                // strictly beyond it; a corner between a side turned towards
                // q and one turned away is on the silhouette.
                let towards_i = if k & 1 == 0 { below.x } else { above.x };
                let towards_j = if k & 2 == 0 { below.y } else { above.y };
                if towards_i == towards_j {
                    continue;
                }
                // A normal of the line through q and c (of any length: the
                // half-plane, its margin and the box test scale alike).
                let u = c - q;
                let mut n = Vec2::new(u.y, -u.x);
                if n == Vec2::ZERO {
                    continue; // q on the corner: no line through both
                }
                if n.dot(centre - q) > 0.0 {
                    n = -n; // the rectangle's side is the inside
                }
                // The half-plane's offset is the largest value over q and
                // the corners, so that it holds the whole projected hull
                // whatever the normal's rounding.
                let reach = rect.iter().map(|r| n.dot(*r)).fold(n.dot(q), f32::max);
                debug_assert!(count < 6, "two silhouette corners per projection");
                shaft.normal[i][count] = n.x;
                shaft.normal[j][count] = n.y;
                shaft.offset[count] = reach + margin * (n.x.abs() + n.y.abs());
                count += 1;
            }
        }
        shaft
    }

    /// The shaft between the boxes `a` and `b`, every face pushed out by
    /// `margin`: their bounding box and, in each projection along an axis,
    /// the lines through the edges of the two rectangles' convex hull that
    /// join one rectangle to the other (at most two per projection), each a
    /// half-space holding the hull of the boxes.
    pub fn between(a: &Aabb, b: &Aabb, margin: f32) -> Shaft {
        let mut shaft = Shaft {
            min: Vec3A::from(a.min.min(b.min)) - margin,
            max: Vec3A::from(a.max.max(b.max)) + margin,
            normal: [[0.0; PLANE_LANES]; 3],
            offset: [f32::INFINITY; PLANE_LANES],
        };
        let mut count = 0;
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            let rect = |r: &Aabb| {
                let (lo, hi) = (Vec2::new(r.min[i], r.min[j]), Vec2::new(r.max[i], r.max[j]));
                [lo, Vec2::new(hi.x, lo.y), hi, Vec2::new(lo.x, hi.y)]
            };
            let mut points: Vec<(Vec2, bool)> = rect(a)
                .into_iter()
                .map(|p| (p, false))
                .chain(rect(b).into_iter().map(|p| (p, true)))
                .collect();
            let all: Vec<Vec2> = points.iter().map(|p| p.0).collect();
            for (p, q) in hull(&mut points) {
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
                shaft.normal[i][count] = n.x;
                shaft.normal[j][count] = n.y;
                shaft.offset[count] = reach + margin * (n.x.abs() + n.y.abs());
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
        let (lo, hi) = (b.min.to_array(), b.max.to_array());
        let mut beyond = [false; PLANE_LANES];
        for (k, out) in beyond.iter_mut().enumerate() {
            let mut sum = 0.0;
            for axis in 0..3 {
                let n = self.normal[axis][k];
                sum += (n * lo[axis]).min(n * hi[axis]);
            }
            *out = sum > self.offset[k];
        }
        !beyond.iter().any(|&x| x)
    }
}

/// The edges of the convex hull of `points` (each tagged), counter-clockwise
/// (Andrew's monotone chain; collinear points dropped).
fn hull(points: &mut [(Vec2, bool)]) -> Vec<((Vec2, bool), (Vec2, bool))> {
    points.sort_by(|a, b| a.0.x.total_cmp(&b.0.x).then(a.0.y.total_cmp(&b.0.y)));
    let cross = |o: Vec2, a: Vec2, b: Vec2| (a - o).perp_dot(b - o);
    let mut chain: Vec<(Vec2, bool)> = Vec::with_capacity(2 * points.len());
    for pass in 0..2 {
        let start = chain.len();
        let ordered: Box<dyn Iterator<Item = &(Vec2, bool)>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &p in ordered {
            while chain.len() >= start + 2
                && cross(chain[chain.len() - 2].0, chain[chain.len() - 1].0, p.0) <= 0.0
            {
                chain.pop();
            }
            chain.push(p);
        }
        chain.pop(); // the last point starts the other half
    }
    (0..chain.len())
        .map(|k| (chain[k], chain[(k + 1) % chain.len()]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// A group's answer holds for sampled segments between the two boxes:
    /// none blocked when visible, all blocked when occluded.
    #[test]
    fn group_classifications_hold_for_sampled_segments() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let boxed = |centre: Vec3, size: f32, next: &mut dyn FnMut() -> f32| {
            let half = Vec3::new(next(), next(), next()) * size;
            Aabb {
                min: centre - half,
                max: centre + half,
            }
        };
        let walls: Vec<Aabb> = (0..30)
            .map(|_| {
                let c = Vec3::new(next(), next(), next()) * 40.0;
                boxed(c, 4.0, &mut next)
            })
            .collect();
        let occluders = Occluders::new(&walls);
        let mut answers = [0; 3];
        for _ in 0..400 {
            let group = boxed(Vec3::new(next(), next(), 0.0) * 40.0, 1.0, &mut next);
            let target = boxed(Vec3::new(next(), next(), next()) * 40.0, 2.0, &mut next);
            let mut host = Shadows::new(&occluders, Vec3::Z);
            let coverage = host.classify_boxes(&group, &target);
            let lift = Vec3::Z * SHADOW_OFFSET;
            let mut pick = |b: &Aabb| b.min + (b.max - b.min) * Vec3::new(next(), next(), next());
            for _ in 0..64 {
                let (p, q) = (pick(&group) + lift, pick(&target));
                let blocked = occluders.blocked(p, q);
                match coverage {
                    Coverage::Visible => assert!(!blocked, "visible, but {p} to {q} is blocked"),
                    Coverage::Occluded => assert!(blocked, "occluded, but {p} to {q} is free"),
                    Coverage::Partial => {}
                }
            }
            answers[coverage as usize] += 1;
        }
        // All three answers occur, so the test checks something.
        assert!(answers.iter().all(|&a| a > 0), "{answers:?}");
    }
}
