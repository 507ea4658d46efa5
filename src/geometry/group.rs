//! A group of shading points as one region: a ball of points and a cone
//! of normals, and what every point of it sees of a ball of lights.

use glam::{DVec3, Vec3};

use super::{Aabb, Surface};
use crate::numeric::{DISTANCE_SLACK, SECOND_ORDER_SLACK};
use crate::visibility::PointGroup;

/// Where a group of points lies: a ball of points and a cone of normals,
/// all widened for rounding.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GroupBounds {
    pub(crate) centre: DVec3,
    /// Unit (to rounding) mean normal `n0`.
    pub(crate) normal: DVec3,
    /// Every point lies within this distance of `centre`.
    pub(crate) radius: f64,
    /// Largest `n0 . (p - centre)` over the points, at least 0.
    rise: f64,
    /// Largest `n0 . (centre - p)` over the points, at least 0.
    drop: f64,
    /// Largest `|n_p - n0|` over the points' exact unit normals.
    tilt: f64,
    /// The points as the host sees them.
    pub(crate) region: PointGroup,
}

/// What every point of a group sees of a ball of lights (a node), as upper
/// bounds over every point `p` of the group and its exact unit normal `n`:
/// the node's bound for the group is its bound for one point, taken at
/// these worst values.
#[derive(Clone, Copy, Debug, Default)]
pub struct GroupView {
    /// `1 / D` for the smallest distance `D > R` from a point to the
    /// node's centroid.
    pub(crate) inv_nearest: f64,
    /// `|c0| = |n . (c - p)| / |c - p|`, at most 1.
    pub(crate) cosine: f64,
    /// `|n0 . (x - c)|` over the node's box, `n0` the group's mean normal.
    pub(crate) height: f64,
    /// `|n - n0|` (how far `n` is from what `height` was measured along).
    pub(crate) tilt: f64,
    /// How far members reach below some point's tangent plane (0 if none).
    pub(crate) depth: f64,
    /// The smallest distance from a point to the node's centroid less the
    /// node's radius.
    pub(crate) gap: f64,
}

/// Where members lie against the tangent planes of a group's points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Side {
    /// Strictly above every plane, each member at least this high.
    Above(f64),
    /// Strictly below every plane: they contribute exactly 0.
    Below,
    /// On both sides of some plane, reaching at most this far (negated)
    /// below any.
    Across(f64),
}

impl GroupBounds {
    /// The bounds of the points and normals of `surfaces` (at least one).
    pub(crate) fn new(surfaces: impl Iterator<Item = Surface> + Clone) -> Self {
        let (mut sum_p, mut sum_n, mut count) = (DVec3::ZERO, DVec3::ZERO, 0.0);
        let mut first_normal = DVec3::Z;
        for s in surfaces.clone() {
            if count == 0.0 {
                first_normal = s.normal;
            }
            sum_p += s.point;
            sum_n += s.normal;
            count += 1.0;
        }
        let centre = sum_p / count;
        let normal = sum_n.try_normalize().unwrap_or(first_normal);
        let (mut radius, mut rise, mut drop, mut tilt) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        let mut count = 0;
        for s in surfaces {
            let at = s.point.as_vec3();
            (lo, hi, count) = (lo.min(at), hi.max(at), count + 1);
            let offset = s.point - centre;
            radius = radius.max(offset.length());
            let height = normal.dot(offset);
            rise = rise.max(height);
            drop = drop.max(-height);
            tilt = tilt.max((s.normal - normal).length());
        }
        // Lengths and dots of f64 differences: a few ulps of the magnitudes
        // involved; the surfaces' unit normals are within a few ulps of the
        // exact ones.
        let pad = 8.0 * f64::EPSILON * (centre.abs().max_element() + radius);
        Self {
            centre,
            normal,
            radius: radius * (1.0 + DISTANCE_SLACK) + pad,
            rise: rise * (1.0 + DISTANCE_SLACK) + pad,
            drop: drop * (1.0 + DISTANCE_SLACK) + pad,
            tilt: tilt * (1.0 + DISTANCE_SLACK) + 16.0 * f64::EPSILON,
            region: PointGroup {
                aabb: Aabb { min: lo, max: hi },
                count,
            },
        }
    }

    /// What every point of the group sees of a node with centroid
    /// `centroid` and box `aabb`, at centroid distance `distance` from the
    /// centre, no point nearer it than `1 / inv_nearest`: the heights
    /// `n . (c - p)` are within `|n0 . (c - centre)| + max(rise, drop) +
    /// tilt |c - p|` and `|c - p| <= distance + radius`, so `|c0|` is at
    /// most that over the nearest distance; the box's heights about the
    /// centroid along `n0` bound `|n0 . (x - c)|`. `depth` and `gap` are
    /// the caller's.
    #[inline(always)]
    pub(crate) fn view(
        &self,
        centroid: DVec3,
        aabb: &Aabb,
        inv_nearest: f64,
        distance: f64,
        depth: f64,
        gap: f64,
    ) -> GroupView {
        let far = (distance + self.radius) * (1.0 + DISTANCE_SLACK);
        let centre_height = self.normal.dot(centroid - self.centre).abs();
        let height = centre_height + self.rise.max(self.drop) + self.tilt * far;
        let cosine = height * (1.0 + DISTANCE_SLACK) * inv_nearest
            + 16.0 * f64::EPSILON * (centroid.abs().max_element() + far) * inv_nearest;
        let (lo, hi) = aabb.extent_along(centroid, self.normal, SECOND_ORDER_SLACK);
        GroupView {
            inv_nearest,
            cosine,
            height: lo.abs().max(hi.abs()),
            tilt: self.tilt,
            depth,
            gap,
        }
    }

    /// Where members boxed by `aabb` within `reach` of every point lie
    /// against every point's tangent plane.
    ///
    /// For a point `p` with unit normal `n` and a member `x`,
    /// `n.(x - p) = n0.(x - c) + n0.(c - p) + (n - n0).(x - p)`: the first
    /// term ranges over the box's extent along `n0`, the second over
    /// `[-rise, drop]`, the third within `tilt * |x - p|`.
    #[inline(always)]
    pub(crate) fn side(&self, aabb: &Aabb, reach: f64) -> Side {
        let (lo, hi) = aabb.extent_along(self.centre, self.normal, SECOND_ORDER_SLACK);
        self.side_of(lo, hi, reach)
    }

    /// [`side`](Self::side) for members whose heights `n0 . (x - centre)`
    /// lie in `[lo, hi]` up to the rounding of an `f64` dot product of
    /// a difference (covered by the margin).
    #[inline(always)]
    pub(crate) fn side_of(&self, lo: f64, hi: f64, reach: f64) -> Side {
        let spread = self.tilt * reach * (1.0 + DISTANCE_SLACK);
        let margin =
            16.0 * f64::EPSILON * (lo.abs() + hi.abs() + self.rise + self.drop + spread + reach);
        let lowest = lo - self.rise - spread - margin;
        if lowest > 0.0 {
            Side::Above(lowest)
        } else if hi + self.drop + spread + margin < 0.0 {
            Side::Below
        } else {
            Side::Across(lowest)
        }
    }

    /// A lower bound on the distance from every point to a member at least
    /// `distance` from the centre and at least `lowest` above every
    /// tangent plane (a unit normal's height is at most the distance).
    #[inline(always)]
    pub(crate) fn nearest(&self, distance: f64, lowest: f64) -> f64 {
        (distance * (1.0 - DISTANCE_SLACK) - self.radius).max(lowest)
    }
}
