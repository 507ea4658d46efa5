//! Axis-aligned boxes.

use glam::{DVec3, Vec3};

use crate::numeric::DISTANCE_SLACK;

use crate::numeric::dot_of_difference;

/// An axis-aligned box, `min <= max` per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Vec3,
    /// Largest corner.
    pub max: Vec3,
}

impl Aabb {
    /// The empty box: the identity of [`union_point`](Self::union_point).
    pub const EMPTY: Self = Self {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    /// Whether `p` lies in the closed box.
    #[must_use]
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// The smallest box holding this one and `p`.
    #[must_use]
    pub fn union_point(self, p: Vec3) -> Self {
        Self {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding this one and `other`.
    #[must_use]
    pub(crate) fn union(self, other: Self) -> Self {
        Self {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// Lowest and highest value of `dir . (x - origin)` over the box (its
    /// support function in `+dir` and `-dir`), computed in `f64` and widened
    /// outward by `relative_slack` times the magnitude of the coordinates
    /// involved, so that the interval holds every point of the stored box.
    #[must_use]
    #[inline(always)]
    pub fn extent_along(&self, origin: DVec3, dir: DVec3, relative_slack: f64) -> (f64, f64) {
        let (min, max) = (self.min.as_dvec3(), self.max.as_dvec3());
        let centre = 0.5 * (min + max);
        let half = 0.5 * (max - min);
        let middle = dir.dot(centre - origin);
        let reach = dir.abs().dot(half);
        let magnitude =
            centre.abs().max_element() + half.max_element() + origin.abs().max_element();
        let slack = relative_slack * magnitude;
        (middle - reach - slack, middle + reach + slack)
    }

    /// Smallest and largest distance from `origin` to a point of the box
    /// (the smallest is 0 when `origin` is inside), widened outward by
    /// `8 f64::EPSILON` (relative) for their `f64` rounding.
    #[must_use]
    pub fn distance_range(&self, origin: DVec3) -> (f64, f64) {
        let (min, max) = (self.min.as_dvec3(), self.max.as_dvec3());
        let nearest = origin.clamp(min, max) - origin;
        let farthest = (min - origin).abs().max((max - origin).abs());
        (
            nearest.length() * (1.0 - DISTANCE_SLACK),
            farthest.length() * (1.0 + DISTANCE_SLACK),
        )
    }

    /// The corner of the box farthest along `dir`: per axis `max` where
    /// `dir`'s component is positive, `min` otherwise. It maximizes
    /// `dir . x` over the box.
    #[must_use]
    pub fn corner_along(&self, dir: Vec3) -> Vec3 {
        Vec3::select(dir.cmpgt(Vec3::ZERO), self.max, self.min)
    }

    /// Whether the whole box lies at or below the plane through `origin`
    /// with normal `normal` (not necessarily unit): `normal . (x - origin)
    /// <= 0` for every point `x` of the box. Decided *exactly* for an
    /// `origin` holding `f32` values (as a [`Surface`](crate::shader::Surface)'s
    /// point does): the sign of the highest corner's height comes from an
    /// error-free compensated dot product, with no slack, so a box lying
    /// exactly in the plane counts as at or below it. The empty box, which
    /// has no point, does too.
    #[must_use]
    pub fn lies_at_or_below(&self, origin: DVec3, normal: Vec3) -> bool {
        if self.min.cmpgt(self.max).any() {
            return true;
        }
        let corner = self.corner_along(normal);
        dot_of_difference(normal.as_dvec3(), corner.as_dvec3(), origin) <= 0.0
    }
}
