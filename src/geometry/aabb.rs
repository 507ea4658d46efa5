//! Axis-aligned boxes.

use glam::{DVec3, Vec3};

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

    /// Lowest and highest value of `dir . (x - origin)` over the box (its
    /// support function in `+dir` and `-dir`), computed in `f64` and widened
    /// outward by `relative_slack` times the magnitude of the coordinates
    /// involved, so that the interval holds every point of the stored box.
    #[must_use]
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
}
