//! [`Shadows`], the visibility host of the scenes with occluders: a
//! conservative shaft classifier (Haines and Wallace 1994) and any-hit shadow
//! rays, both against opaque boxes in an `obvhs` BVH ([`Occluders`]), and
//! the candidate lists of the shafts it has built, which later shafts and
//! shadow rays inside them test instead of the BVH. It is the recipe for
//! plugging a renderer's own ray tracer into the crate's `Visibility` trait.
//! Its shafts are those of `manylights_mesh::shaft`, which the triangle
//! host of `manylights-mesh` builds too.

use std::ops::Range;

use glam::{BVec3A, BVec4A, Vec3, Vec3A, Vec4};
use manylights::{Aabb, Coverage, NodeRegion, PointGroup, Visibility};
use obvhs::aabb::Aabb as BvhAabb;

use manylights_mesh::shaft::{Fan, PAIR_AXES, PointShaft, Shaft};

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

/// Most occluders a candidate list holds (see "Candidate lists" in
/// [`Shadows`]). A shaft that meets more is answered without a list (by the
/// single-blocker test, else partial). In the report's city a small node's
/// shaft meets about ten buildings; the shafts of the top few levels of the
/// light tree meet most of the city's 325, and stop the BVH's traversal
/// early. Lists of up to 128 let the levels below filter a list rather
/// than traverse the BVH (3% fewer instructions in the city than lists of
/// at most 32).
pub const CANDIDATES_MAX: usize = 128;

/// Longest candidate list a shadow ray tests; a ray whose smallest list is
/// longer traverses the BVH (under the canopy a small node's shaft meets
/// dozens of leaves, and testing them all would cost a ray more than the
/// traversal does).
pub const RAY_LIST_MAX: u32 = 32;

/// Longest list of the parent whose boxes are tried as the single blocker
/// before the shaft is built (an occluded node then skips the shaft and
/// the gathering); from a longer list the gathered boxes are tried after
/// (3% fewer instructions in the city than trying every parent's list
/// first).
pub const EARLY_BLOCKER_LIST: usize = 32;

/// Shafts of small nodes (see [`SMALL_NODE_LIGHTS`]) that met more than
/// [`RAY_LIST_MAX`] occluders before a host judges its lists useless and
/// stops gathering them, as long as more than half of the small nodes'
/// shafts did: under many small occluders every shaft is crowded, its list
/// serves no shadow ray, and gathering it costs a traversal of the BVH (up
/// to [`CANDIDATES_MAX`] boxes) besides the single-blocker test.
pub const GIVE_UP_CROWDED: u32 = 16;

/// Nodes of at most this many lights are small: the shafts of larger nodes
/// are crowded wherever there are many occluders (near the root of the
/// light tree a shaft spans much of the scene), so only small nodes' shafts
/// count towards giving up (see [`GIVE_UP_CROWDED`]).
pub const SMALL_NODE_LIGHTS: u32 = 64;

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
/// The occluders that may meet the shaft are *gathered*: a box, grown by
/// [`MARGIN`], that meets the shaft's bounding box and is not wholly beyond
/// one of its planes, taken from the BVH (descended through the nodes whose
/// bounds pass the same test: a node holds its boxes, so a node outside the
/// shaft holds none inside it) or from a candidate list (below), up to
/// [`CANDIDATES_MAX`] of them. Then:
///
/// * [`Coverage::Visible`] when none is gathered: a box that lies wholly
///   outside one half-space containing `H` meets no segment from `p` to `N`.
///   Each plane's offset is the largest value over the hull's vertices (`p`
///   and the corners of `N`) of the stored normal's dot product, so a
///   rounded normal tilts the plane but never lets it cut into the shaft;
///   the rounding of the dot products themselves is within [`MARGIN`]. With
///   every face of `H` tested, a box is culled exactly when a face plane or
///   an axis separates it from `H`: in the projection along each axis the
///   test is the complete separating-axis test of a convex polygon and a
///   rectangle, and those projections hold every separating axis of two
///   convex bodies whose edges are axis-parallel or through `p`.
/// * [`Coverage::Occluded`] when one gathered box, shrunk by [`MARGIN`],
///   meets the segments from `p` to all eight corners of `N` (only boxes
///   that meet the segment to the centre of `N` are tried). For a convex box
///   `B` the set `{q : [p, q] meets B} = {p + s (b - p) : b in B, s >= 1}`
///   is convex, so it then holds the corners' convex hull, `N`: every
///   segment from `p` to the node, so every light's shadow ray, passes at
///   least [`MARGIN`] deep through `B`, and [`Visibility::visible`] reports
///   it blocked. Most nodes the cut asks about in a city are hidden behind a
///   single building.
/// * [`Coverage::Partial`] otherwise, which is always correct. When more
///   than [`CANDIDATES_MAX`] boxes meet the shaft the node is not visible,
///   and the single blocker is looked for among the first
///   [`OCCLUDER_CANDIDATES`] boxes that an any-hit traversal of the BVH
///   along the segment to the centre of `N` meets.
///
/// Both `Visible` and `Occluded` are therefore conservative with respect to
/// this host's own [`Visibility::visible`], which is what the crate's
/// certified bound needs (the contract of [`Visibility`]); the member's
/// tests compare the classifier with rays to many points of random node
/// boxes and to every light of the nodes the cut asks about.
///
/// # Candidate lists
///
/// A node answered `Partial` keeps the boxes gathered for it, its
/// *candidate list* (Haines and Wallace's term), for as long as the shading
/// point stays the same. If a box `Q` lies inside a listed box `N`, every
/// segment from `p` to `Q` is one from `p` to `N`, so the shaft of `Q` lies
/// in the shaft of `N` and every box that meets the (grown) shaft of `Q` is
/// on the list of `N`. Hence:
///
/// * a node inside a listed box (the cut asks about a node only once its
///   parent answered partial) gathers from the smallest such list instead
///   of the BVH: about ten boxes in the report's city, each tested against
///   the shaft's planes four at a time;
/// * a shadow ray to a light inside a listed box tests that list's boxes
///   only. The list holds every box within [`MARGIN`] of the shaft, farther
///   than rounding moves a segment's slab test, so every box whose slab test
///   the segment passes is on the list, and the ray answers as the BVH's
///   any-hit traversal does: that traversal tests the same boxes with the
///   same slab test, and prunes a BVH node only when the segment misses the
///   node's bounds, which hold its boxes (`obvhs` clamps an inverse
///   direction component beyond `1 / f32::EPSILON`, so a segment within
///   about `1e-7` of parallel to a face, and as close to it, could in
///   principle be pruned where the box test hits; the member's tests
///   compare every ray of the cut with the traversal's).
///
/// The listed boxes form a tree (each under the smallest listed box that
/// held it when it was listed), so the smallest list holding a box is found
/// by descending from the roots (from the nearest list that holds the box
/// on the way up from the last list kept, when there is one). A shadow ray moves the box that blocks it to the front of its
/// list, where the next light's ray tries it first. A list keeps its boxes
/// four to a quad too (per axis the four minima, then the maxima), so that
/// a child's shaft filters its parent's list, and the single-blocker test
/// scans a list, four boxes at a time; and the lights of a leaf, which the
/// cut asks about together ([`Visibility::visible_lights`]), are tested
/// four segments at a time against each box of the leaf's list, with the
/// single ray's operations in each lane. Where a branch on the data was
/// mispredicted often the host does without one: a shaft's silhouette
/// planes are found for the three projections at once, one a lane; a
/// child's shaft filters its parent's list by copying every box to the next
/// free place, which moves on past the boxes that meet the shaft only. A
/// host whose small nodes' shafts keep meeting more boxes than a ray tests
/// ([`GIVE_UP_CROWDED`]; foliage) stops gathering and classifies as above
/// without lists.
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
/// answer then only add cost (in the report's city at a certified 1%, 1.2
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
    /// Those of [`rays`](Self::rays) that tested a candidate list rather
    /// than the BVH.
    pub listed_rays: u32,
    /// Whether [`Visibility::visible_fraction`] casts its rays.
    fraction: bool,
    /// The candidate lists of the current apex.
    lists: Candidates,
}

impl<'o> Shadows<'o> {
    /// The host for a shading point with unit `normal`.
    pub fn new(occluders: &'o Occluders, normal: Vec3) -> Self {
        Self {
            occluders,
            lift: normal * SHADOW_OFFSET,
            answers: [0; 3],
            rays: 0,
            listed_rays: 0,
            fraction: false,
            lists: Candidates::default(),
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
    /// lifted here): see the type's documentation, "Classification" and
    /// "Candidate lists". Counted as a small node's box (see
    /// [`GIVE_UP_CROWDED`]).
    pub fn classify_box(&mut self, point: Vec3, target: &Aabb) -> Coverage {
        self.classify_shaft(point, target, true)
    }

    /// [`classify_box`](Self::classify_box), `small` saying whether the box
    /// is a small node's.
    fn classify_shaft(&mut self, point: Vec3, target: &Aabb, small: bool) -> Coverage {
        let apex = point + self.lift;
        if !self.lists.gathering() {
            return self.classify_from(apex, &[apex], target, || Shaft::new(apex, target, MARGIN));
        }
        self.lists.aim(apex);
        let parent = self.lists.find_near_last(target);
        let parent_list = self.lists.range(parent);
        let early = parent_list
            .as_ref()
            .is_some_and(|l| l.len() <= EARLY_BLOCKER_LIST);
        if let Some(list) = parent_list
            && early
            && self.blocks_all(list, apex, target)
        {
            // A single blocker is on the list that holds every box meeting
            // the shaft: tried before the shaft is built (see
            // `EARLY_BLOCKER_LIST`).
            return self.answer(Coverage::Occluded);
        }
        let shaft = PointShaft::new(apex, target, MARGIN);
        let Some(gathered) = self.lists.gather(self.occluders, parent, &shaft, small) else {
            // Too many boxes meet the shaft: not visible.
            let (occluded, _) = self.single_blocker(apex, &[apex], target);
            return self.answer(if occluded {
                Coverage::Occluded
            } else {
                Coverage::Partial
            });
        };
        let start = gathered.start;
        let coverage = if gathered.is_empty() {
            Coverage::Visible
        } else if !early && self.blocks_all(gathered.clone(), apex, target) {
            // (From a short list, the boxes were tried above.)
            Coverage::Occluded
        } else {
            Coverage::Partial
        };
        if coverage == Coverage::Partial {
            self.lists.keep(parent, target, gathered);
        } else {
            self.lists.truncate(start);
        }
        self.answer(coverage)
    }

    /// Whether one of the listed boxes in `slots` (a range of
    /// `Candidates::slots`), shrunk by [`MARGIN`], meets every segment from
    /// `apex` to `target` (see "Classification"): the boxes that meet the
    /// segment to the target's centre, found four at a time, are tried
    /// against the segments to its eight corners.
    fn blocks_all(&self, slots: Range<usize>, apex: Vec3, target: &Aabb) -> bool {
        let between = Segment::new(apex, 0.5 * (target.min + target.max));
        let mut fan = None;
        self.lists.quads(slots).any(|(quad, lanes)| {
            let mut mask = quad.core_hit_by(MARGIN, &between) & lanes;
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let o = quad.lane(lane);
                let core = BvhAabb::new(o.min + MARGIN, o.max - MARGIN);
                if fan
                    .get_or_insert_with(|| Fan::new(apex, target))
                    .all_meet(&core)
                {
                    return true;
                }
            }
            false
        })
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
    /// No candidate lists: they belong to one apex.
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
    /// `starts` (`centre` among them or inside their box) to `target`,
    /// without candidate lists: occluded by a
    /// [`single_blocker`](Self::single_blocker); else partial if a box meets
    /// the segment from `centre` to the target's centre; else visible if no
    /// box meets `shaft()`.
    fn classify_from(
        &mut self,
        centre: Vec3,
        starts: &[Vec3],
        target: &Aabb,
        shaft: impl FnOnce() -> Shaft,
    ) -> Coverage {
        let (occluded, centre_blocked) = self.single_blocker(centre, starts, target);
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

    /// Whether one box blocks every segment from the points whose corners
    /// are `starts` to `target`, and whether a box meets the segment from
    /// `centre` to the target's centre. An occluder that blocks every segment
    /// meets that one; the first [`OCCLUDER_CANDIDATES`] boxes along it, in
    /// the BVH's traversal order (nearer child first), shrunk by [`MARGIN`],
    /// are tried against the segments between the starts and the target's
    /// corners. A blocker of a whole node is nearly always among them, and a
    /// long segment through foliage meets many boxes that cannot be one.
    fn single_blocker(&self, centre: Vec3, starts: &[Vec3], target: &Aabb) -> (bool, bool) {
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
        (occluded, centre_blocked)
    }

    /// One shadow ray from the lifted point `apex`, counted: through the
    /// smallest candidate list whose box holds `to` if there is one for this
    /// apex, else the BVH.
    fn ray(&mut self, apex: Vec3, to: Vec3) -> bool {
        self.rays += 1;
        match self.lists.holding(apex, to) {
            Some(range) => {
                self.listed_rays += 1;
                let segment = Segment::new(apex, to);
                let start = range.start;
                let occluders = self.occluders;
                match self.lists.slots[range]
                    .iter()
                    .position(|&slot| segment.hits(occluders.get(slot as usize)))
                {
                    Some(0) => false,
                    Some(k) => {
                        // The next light's ray tries this box first:
                        // neighbouring lights hide behind the same
                        // building.
                        self.lists.swap(start, start + k);
                        false
                    }
                    None => true,
                }
            }
            None => !self.occluders.blocked(apex, to),
        }
    }
}

impl Visibility for Shadows<'_> {
    /// Groups of points are classified too, for batches whose points share
    /// the host's normal (the lift).
    const CLASSIFIES_GROUPS: bool = true;

    /// [`Shadows::classify_box`] of the node's box.
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        self.classify_shaft(point, &node.aabb, node.light_count <= SMALL_NODE_LIGHTS)
    }

    /// [`Shadows::classify_boxes`] of the points' box and the node's box.
    fn classify_group(&mut self, group: &PointGroup, node: &NodeRegion) -> Coverage {
        self.classify_boxes(&group.aabb, &node.aabb)
    }

    /// One any-hit shadow ray: the segment from the lifted point to the
    /// light (through a candidate list when one holds the light).
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.ray(point + self.lift, light)
    }

    /// The shadow rays of [`visible`](Self::visible), four at a time where
    /// the last list kept holds every light (the lights of the leaf the cut
    /// just asked about): each listed box is tested against four segments
    /// at once, with the operations of the single ray's test, so every
    /// answer is the one `visible` gives.
    fn visible_lights(&mut self, point: Vec3, lights: &[Vec3], seen: &mut [bool]) {
        let apex = point + self.lift;
        let Some(range) = self.lists.holding_all(apex, lights) else {
            for (&light, seen) in lights.iter().zip(seen) {
                *seen = self.ray(apex, light);
            }
            return;
        };
        self.rays += lights.len() as u32;
        self.listed_rays += lights.len() as u32;
        let boxes = &self.lists.slots[range];
        for (lights, seen) in lights.chunks(4).zip(seen.chunks_mut(4)) {
            let fan = Rays::new(apex, lights);
            let all = lanes(lights.len());
            let mut blocked = 0;
            for &slot in boxes {
                blocked |= fan.hit(self.occluders.get(slot as usize));
                if blocked & all == all {
                    break;
                }
            }
            for (k, seen) in seen.iter_mut().enumerate() {
                *seen = blocked & (1 << k) == 0;
            }
        }
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

/// Listed boxes and lists a host makes room for when it keeps its first
/// list (in the report's city a shading point keeps about 160 lists of
/// 1,800 boxes in all, at most about 700 lists of 6,600 boxes): growing
/// from nothing by copies cost 3% of the city's instructions.
const RESERVED_SLOTS: usize = 2048;
const RESERVED_LISTS: usize = 256;

/// No list: the end of a chain of lists.
const NO_LIST: u32 = u32::MAX;

/// The slot that pads a list to a whole number of [`Quad`]s (its lanes are
/// never read).
const PAD: u32 = u32::MAX;

/// A candidate list: the boxes that meet the shaft from the apex to
/// `target`, in `Candidates::slots[start..start + len]`, `start` a multiple
/// of four.
#[derive(Clone, Copy, Debug)]
struct List {
    target: Aabb,
    start: u32,
    len: u32,
    /// The list this one is under (`NO_LIST` for a root), the first list
    /// under this one (listed inside its box), and the next list under the
    /// same parent.
    parent: u32,
    child: u32,
    sibling: u32,
}

/// Four listed boxes side by side: per axis their minima and their maxima,
/// one box a lane, so that a shaft or a segment is tested against four
/// boxes at once.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Quad {
    min: [[f32; 4]; 3],
    max: [[f32; 4]; 3],
}

impl Quad {
    /// Four lanes of nothing (never read).
    const UNUSED: Quad = Quad {
        min: [[0.0; 4]; 3],
        max: [[0.0; 4]; 3],
    };

    /// The minima (or maxima) of the four boxes along `axis`.
    #[inline]
    fn min(&self, axis: usize) -> Vec4 {
        Vec4::from_array(self.min[axis])
    }

    #[inline]
    fn max(&self, axis: usize) -> Vec4 {
        Vec4::from_array(self.max[axis])
    }

    /// Sets lane `lane` to the box `b`.
    #[inline]
    fn set(&mut self, lane: usize, b: &BvhAabb) {
        for axis in 0..3 {
            self.min[axis][lane] = b.min[axis];
            self.max[axis][lane] = b.max[axis];
        }
    }

    /// Sets lane `lane` to lane `from` of `quad`.
    #[inline]
    fn copy_lane(&mut self, lane: usize, quad: &Quad, from: usize) {
        for axis in 0..3 {
            self.min[axis][lane] = quad.min[axis][from];
            self.max[axis][lane] = quad.max[axis][from];
        }
    }

    /// The box in lane `lane`.
    #[inline]
    fn lane(&self, lane: usize) -> BvhAabb {
        let at = |v: &[[f32; 4]; 3]| Vec3A::new(v[0][lane], v[1][lane], v[2][lane]);
        BvhAabb::new(at(&self.min), at(&self.max))
    }

    /// Bit `k` set where box `k`, shrunk by `margin`, is not empty and
    /// meets `segment` (the slab test of [`Segment::hits`], four lanes at a
    /// time).
    #[inline]
    fn core_hit_by(&self, margin: f32, segment: &Segment) -> u32 {
        let margin = Vec4::splat(margin);
        let mut valid = BVec4A::TRUE;
        let mut near = Vec4::NEG_INFINITY;
        let mut far = Vec4::INFINITY;
        for axis in 0..3 {
            let (lo, hi) = (self.min(axis) + margin, self.max(axis) - margin);
            valid &= lo.cmple(hi);
            let from = Vec4::splat(segment.from[axis]);
            let inv = Vec4::splat(segment.inv_dir[axis]);
            let t0 = (lo - from) * inv;
            let t1 = (hi - from) * inv;
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
        }
        (valid & near.cmple(far) & far.cmpge(Vec4::ZERO) & near.cmple(Vec4::ONE)).bitmask()
    }
}

/// The lanes in use of a quad with `left` boxes from its first lane on.
#[inline]
fn lanes(left: usize) -> u32 {
    (1u32 << left.min(4)) - 1
}

/// The candidate lists of one apex (see "Candidate lists" in [`Shadows`]),
/// and how gathering has gone.
#[derive(Debug)]
struct Candidates {
    /// The apex the lists belong to.
    apex: Option<Vec3>,
    /// The lists' occluder slots, back to back up to `end`, each list padded
    /// with [`PAD`] to a multiple of four; the rest is room for the list
    /// being gathered (the vector only grows: no slot is written twice
    /// for its length's sake).
    slots: Vec<u32>,
    /// The boxes of `slots`, four to a quad: those of `slots[4 k..4 k + 4]`
    /// are `quads[k]` (as long as `slots` over four).
    quads: Vec<Quad>,
    end: usize,
    lists: Vec<List>,
    /// The first list under no other, and the last one kept.
    root: u32,
    last: u32,
    /// Small nodes' shafts gathered, and those that met more than
    /// [`RAY_LIST_MAX`] boxes (crowded: their lists serve no shadow ray).
    small_shafts: u32,
    small_crowded: u32,
}

impl Default for Candidates {
    fn default() -> Self {
        Self {
            apex: None,
            slots: Vec::new(),
            quads: Vec::new(),
            end: 0,
            lists: Vec::new(),
            root: NO_LIST,
            last: NO_LIST,
            small_shafts: 0,
            small_crowded: 0,
        }
    }
}

/// Whether the closed box `outer` holds the box `inner`.
#[inline]
fn holds(outer: &Aabb, inner: &Aabb) -> bool {
    // One mask of both comparisons, tested once: the answer depends on the
    // data, and a branch per comparison was mispredicted often.
    let (o_min, o_max) = (Vec3A::from(outer.min), Vec3A::from(outer.max));
    (o_min.cmple(Vec3A::from(inner.min)) & Vec3A::from(inner.max).cmple(o_max)).all()
}

impl Candidates {
    /// Whether lists are still worth gathering (see [`GIVE_UP_CROWDED`]).
    fn gathering(&self) -> bool {
        self.small_crowded < GIVE_UP_CROWDED || 2 * self.small_crowded <= self.small_shafts
    }

    /// Makes the lists those of `apex`, dropping any of another apex.
    fn aim(&mut self, apex: Vec3) {
        if self.apex != Some(apex) {
            self.apex = Some(apex);
            if self.lists.capacity() == 0 {
                // Room for a typical shading point's lists from the start,
                // rather than growing from nothing by copies.
                self.slots.reserve(RESERVED_SLOTS);
                self.quads.reserve(RESERVED_SLOTS / 4);
                self.lists.reserve(RESERVED_LISTS);
            }
            self.end = 0;
            self.lists.clear();
            self.root = NO_LIST;
            self.last = NO_LIST;
        }
    }

    /// The smallest list whose box holds `target`, found down the tree of
    /// lists (`NO_LIST` if none does).
    fn find(&self, target: &Aabb) -> u32 {
        self.descend(NO_LIST, self.root, target)
    }

    /// The smallest list whose box holds `target` among `at`, its siblings
    /// and their descendants, else `found`.
    fn descend(&self, mut found: u32, mut at: u32, target: &Aabb) -> u32 {
        while at != NO_LIST {
            let list = &self.lists[at as usize];
            let held = holds(&list.target, target);
            found = if held { at } else { found };
            at = if held { list.child } else { list.sibling };
        }
        found
    }

    /// A list whose box holds `target`: the smallest under the nearest
    /// list that holds it on the way up from the last list kept to its
    /// root (the cut asks about a node's children soon after the node
    /// answered partial, and about their siblings after their own lists),
    /// else [`find`](Self::find)'s. Any list whose box holds the target
    /// holds every box that meets the target's shaft, so either serves.
    fn find_near_last(&self, target: &Aabb) -> u32 {
        let mut at = self.last;
        while let Some(list) = self.lists.get(at as usize) {
            if holds(&list.target, target) {
                return self.descend(at, list.child, target);
            }
            at = list.parent;
        }
        self.find(target)
    }

    /// Where the boxes of list `index` lie in `slots`, `None` for
    /// `NO_LIST`.
    #[inline]
    fn range(&self, index: u32) -> Option<Range<usize>> {
        let list = self.lists.get(index as usize)?;
        Some(list.start as usize..(list.start + list.len) as usize)
    }

    /// The quads of the listed boxes `slots` (a range starting at a
    /// multiple of four), each with the mask of its lanes in the range.
    #[inline]
    fn quads(&self, slots: Range<usize>) -> impl Iterator<Item = (&Quad, u32)> {
        let first = slots.start / 4;
        let len = slots.len();
        self.quads[first..first + len.div_ceil(4)]
            .iter()
            .enumerate()
            .map(move |(k, quad)| (quad, lanes(len - 4 * k)))
    }

    /// Moves the listed box in slot `at` to slot `to` and the one there to
    /// `at`.
    #[inline]
    fn swap(&mut self, to: usize, at: usize) {
        self.slots.swap(to, at);
        let (q_to, q_at) = (self.quads[to / 4], self.quads[at / 4]);
        self.quads[to / 4].copy_lane(to % 4, &q_at, at % 4);
        self.quads[at / 4].copy_lane(at % 4, &q_to, to % 4);
    }

    /// Drops every slot from `start` (a multiple of four) on.
    fn truncate(&mut self, start: usize) {
        self.end = start;
    }

    /// Makes room for `len` slots from `start` (a multiple of four), and
    /// three more.
    #[inline]
    fn room(&mut self, start: usize, len: usize) {
        let end = start + 4 * (len + 3).div_ceil(4);
        if self.slots.len() < end {
            self.slots.resize(end, PAD);
            self.quads.resize(end / 4, Quad::UNUSED);
        }
    }

    /// Gathers the boxes that may meet `shaft` at the end of `slots`, with
    /// their quads: from the list `parent`, the smallest that holds the
    /// shaft's target, four at a time, else from the BVH. Returns the range
    /// of the gathered boxes, or `None` (nothing gathered) when more than
    /// [`CANDIDATES_MAX`] meet it; `small` says whether the target is a
    /// small node's box.
    fn gather(
        &mut self,
        occluders: &Occluders,
        parent: u32,
        shaft: &PointShaft,
        small: bool,
    ) -> Option<Range<usize>> {
        self.small_shafts += u32::from(small);
        let start = self.end;
        debug_assert_eq!(start % 4, 0, "lists start at a quad");
        let mut count = 0;
        if let Some(range) = self.range(parent) {
            let test = QuadShaft::new(shaft);
            let first = range.start / 4;
            let parent_quads = range.len().div_ceil(4);
            // Every lane of the parent's list is copied to the next free
            // place, which moves on past the boxes that meet the shaft only:
            // no branch on the data (a loop over the lanes that meet it was
            // mispredicted often). Room for all of them first.
            self.room(start, range.len());
            for k in 0..parent_quads {
                let quad = self.quads[first + k];
                let mask = test.meets(&quad) & lanes(range.len() - 4 * k);
                for lane in 0..4 {
                    let at = start + count;
                    self.slots[at] = self.slots[range.start + 4 * k + lane];
                    self.quads[at / 4].copy_lane(at % 4, &quad, lane);
                    count += (mask >> lane) as usize & 1;
                }
            }
        } else {
            self.room(start, CANDIDATES_MAX);
            let shaft = shaft.planes();
            let (slots, quads) = (&mut self.slots[start..], &mut self.quads[start / 4..]);
            let overflow = occluders.any_slot_in(
                |b| shaft.meets(b),
                |slot, b| {
                    if !shaft.meets(b) {
                        return false;
                    }
                    if count == CANDIDATES_MAX {
                        return true;
                    }
                    slots[count] = slot as u32;
                    quads[count / 4].set(count % 4, b);
                    count += 1;
                    false
                },
            );
            if overflow {
                self.small_crowded += u32::from(small);
                return None;
            }
        }
        // The list ends at a whole quad; the lanes after its last box are
        // never read (every scan masks them) and their slots are padding.
        self.end = start + 4 * count.div_ceil(4);
        // (Three slots padded whatever the count, with room for them: a
        // loop to the end of the quad was mispredicted often.)
        self.slots[start + count..start + count + 3].fill(PAD);
        let crowded = count > RAY_LIST_MAX as usize;
        self.small_crowded += u32::from(small && crowded);
        Some(start..start + count)
    }

    /// Keeps the boxes `gathered` (the last gathered) as the list of
    /// `target`, under the list `parent` they came from.
    fn keep(&mut self, parent: u32, target: &Aabb, gathered: Range<usize>) {
        let index = self.lists.len() as u32;
        let sibling = if parent == NO_LIST {
            std::mem::replace(&mut self.root, index)
        } else {
            std::mem::replace(&mut self.lists[parent as usize].child, index)
        };
        self.lists.push(List {
            target: *target,
            start: gathered.start as u32,
            len: gathered.len() as u32,
            parent,
            child: NO_LIST,
            sibling,
        });
        self.last = index;
    }

    /// Where the boxes of the last list kept lie in `slots`, if it belongs
    /// to `apex`, holds every one of `points` and has at most
    /// [`RAY_LIST_MAX`] boxes: every box a segment from the apex to one of
    /// the points meets is on it (see "Candidate lists").
    #[inline]
    fn holding_all(&self, apex: Vec3, points: &[Vec3]) -> Option<Range<usize>> {
        if self.apex != Some(apex) {
            return None;
        }
        let list = self.lists.get(self.last as usize)?;
        let (min, max) = (Vec3A::from(list.target.min), Vec3A::from(list.target.max));
        let inside = points.iter().fold(BVec3A::TRUE, |inside, &p| {
            let p = Vec3A::from(p);
            inside & min.cmple(p) & p.cmple(max)
        });
        (list.len <= RAY_LIST_MAX && inside.all()).then(|| self.range(self.last))?
    }

    /// Where the boxes of the smallest list of `apex` whose box holds
    /// `point` lie in `slots` (the last list kept is tried first: the cut
    /// casts rays to a node's lights right after the node answered partial),
    /// if there is one of at most [`RAY_LIST_MAX`] boxes.
    #[inline]
    fn holding(&self, apex: Vec3, point: Vec3) -> Option<Range<usize>> {
        if self.apex != Some(apex) {
            return None;
        }
        let at = Aabb {
            min: point,
            max: point,
        };
        let mut index = self.last;
        if index == NO_LIST || !holds(&self.lists[index as usize].target, &at) {
            index = self.find(&at);
        }
        self.range(index)
            .filter(|range| range.len() <= RAY_LIST_MAX as usize)
    }
}

/// A shaft from a point ([`PointShaft`]) set up for [`Quad`]s: its bounding
/// box and its planes `[n_i, n_j, offset]` (axes of [`PAIR_AXES`]), each
/// number in every lane.
struct QuadShaft {
    min: [Vec4; 3],
    max: [Vec4; 3],
    planes: [[Vec4; 3]; 6],
}

impl QuadShaft {
    #[inline]
    fn new(shaft: &PointShaft) -> QuadShaft {
        QuadShaft {
            min: [shaft.min.x, shaft.min.y, shaft.min.z].map(Vec4::splat),
            max: [shaft.max.x, shaft.max.y, shaft.max.z].map(Vec4::splat),
            planes: shaft.pairs.map(|plane| plane.map(Vec4::splat)),
        }
    }

    /// [`Shaft::meets`] for the four boxes of `quad` at once: bit `k` set
    /// where box `k` may meet the shaft (the same sums, without the zero
    /// terms of the axis each plane of a shaft from a point lacks).
    #[inline]
    fn meets(&self, quad: &Quad) -> u32 {
        let mut out = BVec4A::FALSE;
        for axis in 0..3 {
            out |= quad.min(axis).cmpgt(self.max[axis]) | quad.max(axis).cmplt(self.min[axis]);
        }
        for (k, [n_i, n_j, offset]) in self.planes.iter().enumerate() {
            let (i, j) = PAIR_AXES[k / 2];
            let least = (*n_i * quad.min(i)).min(*n_i * quad.max(i))
                + (*n_j * quad.min(j)).min(*n_j * quad.max(j));
            out |= least.cmpgt(*offset);
        }
        !out.bitmask() & 0xF
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

/// Up to four segments from one point, set up for slab tests four at a time:
/// lane `k` is the segment of [`Segment::new`] to the `k`-th end (the last
/// end fills the lanes beyond the ends).
struct Rays {
    from: Vec3A,
    /// Per axis, `1 / (end - from)`.
    inv_dir: [Vec4; 3],
}

impl Rays {
    #[inline]
    fn new(from: Vec3, ends: &[Vec3]) -> Rays {
        let end = |k: usize| ends[k.min(ends.len() - 1)];
        let [a, b, c, d] = [end(0), end(1), end(2), end(3)];
        // Written out axis by axis: an array's `map` over the axes was not
        // unrolled, and indexing a `Vec3` by a variable branches.
        let x = Vec4::new(a.x, b.x, c.x, d.x) - Vec4::splat(from.x);
        let y = Vec4::new(a.y, b.y, c.y, d.y) - Vec4::splat(from.y);
        let z = Vec4::new(a.z, b.z, c.z, d.z) - Vec4::splat(from.z);
        Rays {
            from: from.into(),
            inv_dir: [Vec4::ONE / x, Vec4::ONE / y, Vec4::ONE / z],
        }
    }

    /// Bit `k` set where segment `k` meets the closed box `b`: the slab test
    /// of [`Segment::hits`], lane by lane with the same operations in the
    /// same order (`Vec3A`'s smallest and largest element reduce as
    /// `min(min(x, z), min(y, z))`), so each answer is bit for bit the one
    /// segment's.
    #[inline]
    fn hit(&self, b: &BvhAabb) -> u32 {
        let (lo, hi) = (b.min - self.from, b.max - self.from);
        let t = |axis: usize| {
            let t0 = Vec4::splat(lo[axis]) * self.inv_dir[axis];
            let t1 = Vec4::splat(hi[axis]) * self.inv_dir[axis];
            (t0.min(t1), t0.max(t1))
        };
        let ((near_x, far_x), (near_y, far_y), (near_z, far_z)) = (t(0), t(1), t(2));
        let near = near_x.max(near_z).max(near_y.max(near_z));
        let far = far_x.min(far_z).min(far_y.min(far_z));
        (near.cmple(far) & far.cmpge(Vec4::ZERO) & near.cmple(Vec4::ONE)).bitmask()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
