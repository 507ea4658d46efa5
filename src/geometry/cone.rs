//! The cone under which a ball is seen from the shading point.

use glam::{DVec3, Vec3};

use crate::numeric::COS_SLACK;

/// The cone of directions, and the range of distances, under which a node's
/// ball (centre `c`, radius `R`) is seen from the shading point `p`.
///
/// Exists only when the ball clears the point: `D = |c - p| > R` with margin
/// [`Cone::MIN_CLEARANCE`]. Then every member at `x` satisfies
/// `D - R <= |x - p| <= D + R`, and its direction `(x - p)/|x - p|` makes an
/// angle of at most `delta` with the axis `(c - p)/D`, `sin(delta) = R/D`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    /// `c - p`.
    pub offset: DVec3,
    /// `D = |c - p|`.
    pub distance: f64,
    /// `1 / D`.
    pub inv_distance: f64,
    /// Unit axis `(c - p) / D`.
    pub axis: DVec3,
    /// `R`, the node's radius.
    pub radius: f64,
    /// `sin(delta) = R / D`, in `[0, 1)`.
    pub sin_half_angle: f64,
    /// `cos(delta) = sqrt(1 - (R/D)^2)`.
    pub cos_half_angle: f64,
}

impl Cone {
    /// Relative margin below which a ball is treated as containing the
    /// point: when `D - R <= D * MIN_CLEARANCE` (D the distance to the
    /// ball's centre, R its radius), [`Cone::new`] gives `None` and the cut
    /// refines the node instead of bounding it. Bounds grow like
    /// `(D / (D - R))^2` or faster, so such a node's bound would exceed
    /// `2^40` times its estimate anyway.
    pub const MIN_CLEARANCE: f64 = 1.0 / (1u64 << 20) as f64;

    /// The cone of the ball of `radius` about `centre` seen from `point`, or
    /// `None` when the ball comes within [`MIN_CLEARANCE`](Self::MIN_CLEARANCE)
    /// (relative) of the point, including `point` at the centre.
    #[inline]
    #[must_use]
    pub fn new(point: DVec3, centre: Vec3, radius: f32) -> Option<Self> {
        let offset = centre.as_dvec3() - point;
        let radius = f64::from(radius);
        // A point well inside the ball (the computed `D` then below `R`)
        // gets `None` below as well; this skips the square root.
        if offset.length_squared() < 0.25 * (radius * radius) {
            return None;
        }
        let distance = offset.length();
        // Also false for distance == 0.
        if !(distance - radius > distance * Self::MIN_CLEARANCE) {
            return None;
        }
        let inv_distance = 1.0 / distance;
        let s = radius * inv_distance;
        Some(Self {
            offset,
            distance,
            inv_distance,
            axis: offset * inv_distance,
            radius,
            sin_half_angle: s,
            // (1 - s)(1 + s) keeps full relative precision for s near 1.
            cos_half_angle: ((1.0 - s) * (1.0 + s)).sqrt(),
        })
    }

    /// Range `[cos_min, cos_max]` of the cosine of the angle between the unit
    /// vector `dir` and the direction to any point of the ball.
    ///
    /// With `theta_c` the angle between `dir` and the axis and `delta` the
    /// half-angle, the angle lies in `[max(0, theta_c - delta),
    /// min(pi, theta_c + delta)]`, so
    ///
    /// ```text
    /// cos_min = cos(theta_c + delta) = cos_c cos_d - sin_c sin_d
    /// cos_max = 1                              if theta_c <= delta
    ///         = cos_c cos_d + sin_c sin_d      otherwise
    /// ```
    ///
    /// with `cos_c = dir . axis` and `sin_c = |dir x axis|` (no `acos`: it
    /// loses half the digits near 0 and pi). When `theta_c + delta > pi` the
    /// formula for `cos_min` is at most 0, which is all the shaders use. Both
    /// ends are widened by `16 f64::EPSILON` and clamped to `[-1, 1]`.
    #[inline]
    #[must_use]
    pub fn cos_range(&self, dir: DVec3) -> (f64, f64) {
        let cos_c = dir.dot(self.axis);
        let sin_c = dir.cross(self.axis).length();
        self.cos_range_from(cos_c, sin_c)
    }

    /// [`cos_range`](Self::cos_range) from the cosine and sine of the angle
    /// between the direction and the axis, for callers that need them too.
    #[inline]
    #[must_use]
    pub fn cos_range_from(&self, cos_c: f64, sin_c: f64) -> (f64, f64) {
        let (sd, cd) = (self.sin_half_angle, self.cos_half_angle);
        let hi = if cos_c >= cd {
            1.0
        } else {
            cos_c * cd + sin_c * sd
        };
        let lo = cos_c * cd - sin_c * sd;
        ((lo - COS_SLACK).max(-1.0), (hi + COS_SLACK).min(1.0))
    }

    /// `(D / (D - R))^2`: how much the nearest member can exceed the centre's
    /// `1/D^2` falloff.
    #[inline]
    pub fn near_falloff(&self) -> f64 {
        let k = 1.0 / (1.0 - self.sin_half_angle);
        k * k
    }

    /// `(D / (D + R))^2`: how much the farthest member can fall short of the
    /// centre's `1/D^2` falloff.
    #[inline]
    pub fn far_falloff(&self) -> f64 {
        let k = 1.0 / (1.0 + self.sin_half_angle);
        k * k
    }
}
