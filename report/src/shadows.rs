//! `Shadows`, the night city's visibility host: a conservative
//! Warnock-style classifier of shafts from a point to a node's box, and
//! shadow rays, both against the buildings.

use glam::Vec3;
use manylights::{Aabb, Coverage, NodeRegion, Visibility};

use crate::bvh::{Segment, corners, grown, overlaps, union};
use crate::scenes::City;

/// Shadow rays start this far off the surface along its normal, so that a
/// point on a wall is not occluded by its own building. It is part of the
/// host's definition of visibility, used alike by the tree's queries and by
/// the exact sum.
pub const SHADOW_OFFSET: f32 = 0.05;
/// Safety margin of the classifier, in scene units. Coordinates stay below
/// 1,000, where an `f32` ulp is at most `6.1e-5`; the slab tests and the
/// shaft slices' corners err by a few ulps. Occluders are inflated by the
/// margin before a shaft is declared `Visible` and shrunk by it before it is
/// declared `Occluded`, so rounding cannot turn a conservative answer into a
/// wrong one.
pub const MARGIN: f32 = 0.01;

/// Slices of a shaft whose bounding boxes the classifier tests.
pub const SHAFT_PIECES: usize = 8;

/// Occlusion by the city's buildings, for one shading point.
pub struct Shadows<'c> {
    city: &'c City,
    /// `SHADOW_OFFSET` times the surface normal: queries start at the shading
    /// point plus this.
    lift: Vec3,
    /// Classifications answered: visible, occluded, partial.
    pub answers: [u32; 3],
}

impl<'c> Shadows<'c> {
    /// The host for a shading point with unit `normal`.
    pub fn new(city: &'c City, normal: Vec3) -> Self {
        Self {
            city,
            lift: normal * SHADOW_OFFSET,
            answers: [0; 3],
        }
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
}

impl Visibility for Shadows<'_> {
    /// With the shaft the convex hull of the (lifted) point `p` and the
    /// node's box `N`:
    ///
    /// * `Visible` when no building, grown by [`MARGIN`], meets the bounding
    ///   box of any of [`SHAFT_PIECES`] slices of the shaft. The points
    ///   `(1 - t) p + t q` (`q` in `N`) with `t` in `[a, b]` lie in the
    ///   bounding box of the two boxes `(1 - a) p + a N` and `(1 - b) p + b N`
    ///   (each coordinate is linear in `t`), so the slices' boxes cover the
    ///   shaft, much more tightly than one box when it runs diagonally.
    /// * `Occluded` when the segments to all eight corners of `N` meet one
    ///   building shrunk by [`MARGIN`]. For a convex occluder `B` the set
    ///   `{q : [p, q] meets B} = {p + s (b - p) : b in B, s >= 1}` is convex,
    ///   so it then holds the corners' convex hull, `N`: every light's shadow
    ///   ray is blocked. Only buildings on the segment to the centre of `N`
    ///   can qualify, so only those are tried.
    /// * `Partial` otherwise.
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        let apex = point + self.lift;
        let bvh = &self.city.bvh;
        let buildings = &self.city.buildings;
        let slice = |t: f32| Aabb {
            min: apex.lerp(node.aabb.min, t),
            max: apex.lerp(node.aabb.max, t),
        };
        let pieces: [Aabb; SHAFT_PIECES] = std::array::from_fn(|k| {
            let a = slice(k as f32 / SHAFT_PIECES as f32);
            let b = slice((k + 1) as f32 / SHAFT_PIECES as f32);
            grown(&union(a, b), MARGIN)
        });
        let shaft = pieces[1..].iter().fold(pieces[0], |a, &b| union(a, b));
        let near = |b: &Aabb| overlaps(b, &shaft) && pieces.iter().any(|piece| overlaps(b, piece));
        if !bvh.any(near, |i| near(&buildings[i].bounds)) {
            return self.answer(Coverage::Visible);
        }
        let to_centre = Segment::new(apex, 0.5 * (node.aabb.min + node.aabb.max));
        let to_corners = corners(&node.aabb).map(|c| Segment::new(apex, c));
        let blocks_all = |i: usize| {
            let core = grown(&buildings[i].bounds, -MARGIN);
            core.min.cmple(core.max).all()
                && to_centre.hits(&core)
                && to_corners.iter().all(|s| s.hits(&core))
        };
        self.answer(if bvh.any(|b| to_centre.hits(b), blocks_all) {
            Coverage::Occluded
        } else {
            Coverage::Partial
        })
    }

    /// One shadow ray: the segment from the lifted point to the light.
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        let ray = Segment::new(point + self.lift, light);
        let buildings = &self.city.buildings;
        !self
            .city
            .bvh
            .any(|b| ray.hits(b), |i| ray.hits(&buildings[i].bounds))
    }
}
