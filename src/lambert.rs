//! Diffuse (Lambert) reflection with a certified node bound.

use glam::{DVec3, Vec3};

use crate::ShadeError;
use crate::geometry::{Cone, Surface};
use crate::numeric::{SECOND_ORDER_SLACK, dot_of_difference};
use crate::shader::{NodeEstimate, Shader, ViewIndependent, colour_or_clamped, try_colour};
use crate::tree::Node;

/// Which node bound a shader uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum BoundKind {
    /// The paper's bound: the interval of the shading term over the node's
    /// ball, around the virtual light's value.
    Paper,
    /// The tightest certified bound the shader has (for [`Lambert`]: the
    /// paper's interval intersected with the second-order Taylor interval,
    /// with the first-order colour correction in the estimate).
    #[default]
    Tight,
}

/// Diffuse reflection: a light of intensity `I` at distance `d` in direction
/// `w` contributes `I * kd * max(0, n . w) / d^2` (per channel; a light at
/// `d = 0` contributes 0).
///
/// # Node bound
/// For a node of intensity `I`, centroid `c`, radius `R`, seen at distance
/// `D = |c - p| > R` (a [`Cone`] with half-angle `delta`, `sin delta = R/D`,
/// and angle `theta_c` between `n` and the axis):
///
/// **Paper's bound** (slides "Diffuse Reflection Error Bound"), valid
/// whenever `D > R`:
///
/// ```text
/// I kd max(0, cos(theta_c + delta)) / (D + R)^2
///     <= exact <= I kd max(0, cos(max(0, theta_c - delta))) / (D - R)^2
/// ```
///
/// with the cosines from [`Cone::cos_range`] (sines and cosines, never
/// `acos`). The estimate is the virtual light, `I kd max(0, cos theta_c) / D^2`.
/// A ball wholly below the tangent plane contributes exactly 0.
///
/// **Second-order bound** (used by [`BoundKind::Tight`], the default), valid
/// whenever `D > R`. The shading term is `f = max(0, g)` with
/// `g(x) = n.(x - p) / |x - p|^3`, smooth away from `p`. Taylor's theorem
/// for `g` about `c` gives, per channel `k`,
///
/// ```text
/// sum_i I_ik g(x_i) = I_k g(c) + grad g(c) . (I_k o_k) + sum_i I_ik rem_i,
/// |rem_i| <= 1/2 sum_jl sup|H_jl| |x_ij - c_j| |x_il - c_l|
/// ```
///
/// and `0 <= f - g <= max(0, R - n.(c - p)) / (D - R)^3` on the ball (the
/// difference is non-zero only below the tangent plane). So the exact value
/// lies in `kd_k [T_k - rem_k, T_k + rem_k + I_k max(0, R - n.(c-p))/(D - R)^3]`
/// with `T_k` the Taylor sum; the extra term vanishes when the ball lies
/// above the plane, which keeps the bound continuous in `p` as a node crosses
/// it.
///
/// where `o_k` is the node's per-channel first moment
/// ([`Node::channel_offsets`]; it vanishes for members of one colour because
/// the centroid is weight-averaged) and `H` the Hessian of `f` over the ball.
/// The estimate includes the first-order term, so the error is second order.
/// Because `I_ik <= w_i` (the weight is the largest channel) and by
/// Cauchy-Schwarz, `sum_i I_ik |x_ij - c_j||x_il - c_l| <= W sqrt(S_jj S_ll)`
/// with `S` the node's [`covariance`](Node::covariance) expressed in a frame
/// `e1` (horizontal, towards `c`), `e2` (horizontal), `e3 = n`. In units of
/// `D` (`rho = 1 - R/D`, `z+ = |cos theta_c| + R/D`, `a+ = sin theta_c + R/D`,
/// `b+ = R/D`, `t_a = min(1, (a+/rho)^2)`, likewise `t_b`, `t_z`,
/// `q = z+/rho^5`) the Hessian entries are bounded over the ball by
///
/// ```text
/// |H11| <= q max(3, 15 t_a - 3)     |H12| <= 15 q min(sqrt(t_a t_b), 1/2)
/// |H22| <= q max(3, 15 t_b - 3)     |H13| <= sqrt(t_a) max(3, 15 t_z - 3) / rho^4
/// |H33| <= 9 q                      |H23| <= sqrt(t_b) max(3, 15 t_z - 3) / rho^4
/// ```
///
/// and, isotropically, `||H|| <= 6 / rho^4` (the spectral norm of the Hessian
/// of `z/r^3` at unit distance is at most 6, reached along the normal). The
/// remainder uses the smaller of the per-axis and the isotropic sums. At
/// grazing angles the per-axis one is far tighter: the horizontal entries are
/// `O(z/r^5)`. The final interval is the intersection of the paper's and the
/// second-order one; the estimate, the Taylor sum plus half the
/// below-the-plane term, is clamped into it. Every piece is continuous in
/// `p`, so the node's estimate and error are too.
///
/// **Box refinements** (also [`BoundKind::Tight`]), from the node's tight box
/// ([`Node::aabb`]) with `z_lo`, `z_hi` the lowest and highest `n.(x - p)`
/// over it: if `z_hi <= 0` every member is at or below the tangent plane and
/// the node is exactly 0; always `exact <= I kd z_hi / (D - R)^3` (as
/// `cos/d^2 = z/d^3`); and the below-the-plane term above uses
/// `min(R - n.(c - p), -z_lo)`. The box is far tighter than the ball for flat
/// clusters such as street lamps seen from a roof.
///
/// Rounding: cosine bounds are widened by [`COS_SLACK`](crate::numeric::COS_SLACK); the second-order
/// estimate by [`SECOND_ORDER_SLACK`] of its terms' magnitudes and by
/// `f32::EPSILON` of the first-order term for the `f32` storage of the offsets;
/// the quadratic forms of `S` by `f32::EPSILON * trace(S)` for the storage of
/// its off-diagonal entries (its diagonal is rounded upward when stored).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lambert {
    kd: DVec3,
    kind: BoundKind,
}

impl Lambert {
    /// Diffuse albedo `kd` per channel, each finite and `>= 0`.
    ///
    /// Debug builds assert that; release builds keep results finite by
    /// reading NaN or negative channels as 0 and infinite ones as
    /// `f32::MAX`. [`Lambert::try_new`] returns an error instead.
    #[must_use]
    pub fn new(kd: Vec3) -> Self {
        Self {
            kd: colour_or_clamped(kd, "kd"),
            kind: BoundKind::Tight,
        }
    }

    /// Like [`Lambert::new`], but refuses a NaN, infinite or negative channel.
    ///
    /// # Errors
    /// [`ShadeError::InvalidMaterial`].
    pub fn try_new(kd: Vec3) -> Result<Self, ShadeError> {
        Ok(Self {
            kd: try_colour(kd, "kd must be finite and >= 0")?,
            kind: BoundKind::Tight,
        })
    }

    /// Selects the node bound (default [`BoundKind::Tight`]).
    #[must_use]
    pub const fn with_bound(mut self, kind: BoundKind) -> Self {
        self.kind = kind;
        self
    }

    /// The albedo.
    #[must_use]
    pub fn kd(&self) -> DVec3 {
        self.kd
    }
}

/// `e^T S e` for the symmetric matrix stored as `[xx, yy, zz, xy, xz, yz]`.
#[inline]
fn quadratic_form(s: &[f64; 6], e: DVec3) -> f64 {
    s[0] * e.x * e.x
        + s[1] * e.y * e.y
        + s[2] * e.z * e.z
        + 2.0 * (s[3] * e.x * e.y + s[4] * e.x * e.z + s[5] * e.y * e.z)
}

/// Lowest and highest value of `n.(x - p)` over the node's box (heights
/// above the tangent plane at the shading point), widened outward by the
/// rounding of the box's `f64` support function (a few ulps of the
/// coordinates' magnitude). Whether the box lies at or below the plane is
/// decided exactly ([`Aabb::lies_at_or_below`](crate::Aabb::lies_at_or_below)),
/// with no slack: then the highest value returned is at most 0, so a box
/// lying exactly in the plane is recognised as contributing 0.
#[inline]
fn box_heights(node: &Node, surface: &Surface) -> (f64, f64) {
    let (lowest, highest) =
        node.aabb
            .extent_along(surface.point, surface.normal, SECOND_ORDER_SLACK);
    // Only a box reaching below the plane (lowest <= 0, a necessary
    // condition) but not certainly below it needs the exact test.
    if lowest <= 0.0
        && highest > 0.0
        && node
            .aabb
            .lies_at_or_below(surface.point, surface.given_normal)
    {
        return (lowest.min(0.0), 0.0);
    }
    (lowest, highest)
}

impl Shader for Lambert {
    type PerPoint = ();

    #[inline]
    fn prepare(&self, _surface: &Surface) {}

    /// The model's term `I kd max(0, n.w) / d^2` with `n = N / |N|` for the
    /// given normal `N`, computed as `N.(x - p) / (|N| d^3)`. For a
    /// `position` holding `f32` values (every light's), the sign of `N.(x -
    /// p)` is exact and its value within `2^-40` relative, within about
    /// `f64::EPSILON` near the plane (error-free transformations, see
    /// [`numeric`](crate::numeric)): a light in the tangent plane
    /// contributes exactly 0, one barely above it its value to a few ulps.
    #[inline]
    fn eval(&self, _: &(), surface: &Surface, position: DVec3, intensity: DVec3) -> DVec3 {
        let normal = surface.given_normal.as_dvec3();
        let height = dot_of_difference(normal, position, surface.point);
        // Lights at or below the tangent plane contribute nothing; so does a
        // light on the shading point (d = 0), whose height is exactly 0.
        if !(height > 0.0) {
            return DVec3::ZERO;
        }
        let d2 = (position - surface.point).length_squared();
        // |N| d^3 = d^2 sqrt(|N|^2 d^2): one square root.
        let scale = d2 * (normal.length_squared() * d2).sqrt();
        intensity * self.kd * (height / scale)
    }

    #[inline]
    fn bound(&self, _: &(), surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        let n = surface.normal;
        // cos and sin of the angle between the normal and the axis.
        let z = n.dot(cone.axis);
        let sin_c = n.cross(cone.axis).length();
        let (cos_lo, cos_hi) = cone.cos_range_from(z, sin_c);
        if cos_hi <= 0.0 {
            // The whole ball lies below the tangent plane.
            return NodeEstimate::ZERO;
        }
        let inv_d = cone.inv_distance;
        let scale = node.intensity * self.kd * (inv_d * inv_d);
        let sd = cone.sin_half_angle;
        // D / (D - R): the nearest member's distance in units of D, inverted.
        let inv_rho = 1.0 / (1.0 - sd);
        let virtual_light = scale * z.max(0.0);
        let lower = scale * (cos_lo.max(0.0) * cone.far_falloff());
        let upper = scale * (cos_hi * inv_rho * inv_rho);
        if self.kind == BoundKind::Paper {
            return NodeEstimate::new(virtual_light, lower, upper);
        }
        let inv_rho3 = inv_rho * inv_rho * inv_rho;
        let (lowest, highest) = box_heights(node, surface);
        if highest <= 0.0 {
            // The whole box lies at or below the tangent plane.
            return NodeEstimate::ZERO;
        }
        // A second upper bound on cos/d^2 = z/d^3 over the members:
        // (highest z in the box) / (D - R)^3, much tighter than the paper's
        // for flat clusters barely above the plane.
        let upper = upper.min(scale * (highest * inv_d * inv_rho3));

        // Second order, in units of D. Gradient of z/r^3 at the unit axis.
        let grad = n - 3.0 * z * cone.axis;
        // Its Euclidean norm bounded by its 1-norm, for the rounding slack.
        let grad_len = grad.abs().element_sum();
        let o = node.channel_offsets;
        let offsets = DVec3::new(
            grad.dot(o[0].as_dvec3()),
            grad.dot(o[1].as_dvec3()),
            grad.dot(o[2].as_dvec3()),
        ) * inv_d;
        // Euclidean norms bounded by the 1-norms (no square roots).
        let l1 = |v: Vec3| f64::from(v.abs().element_sum());
        let offset_lens = DVec3::new(l1(o[0]), l1(o[1]), l1(o[2])) * inv_d;
        let first_order = scale * offsets;
        // Taylor estimate of the smooth g = z/r^3 (not clamped at 0).
        let smooth = scale * z + first_order;
        // f = max(0, g) exceeds g only below the tangent plane, where
        // 0 <= f - g = -z/r^3 <= depth / (D - R)^3, depth being how far the
        // members reach below the plane: at most R - n.(c - p) (the ball) and
        // at most the box's depth. Zero when the box lies above the plane,
        // and continuous as a node crosses it.
        let depth = (sd - z).min(-lowest * inv_d).max(0.0);
        let straddle = scale * (depth * inv_rho3);

        // Hessian entry bounds over the ball.
        // Ratios to the nearest distance, capped at 1: |a|/r, |b|/r, |z|/r.
        let ratio = |x: f64| (x * inv_rho).min(1.0);
        let z_abs_max = z.abs() + sd;
        let (r_a, r_b, r_z) = (ratio(sin_c + sd), ratio(sd), ratio(z_abs_max));
        let (t_a, t_b, t_z) = (r_a * r_a, r_b * r_b, r_z * r_z);
        let p4 = inv_rho3 * inv_rho;
        let q = z_abs_max * p4 * inv_rho;
        let h11 = q * (15.0 * t_a - 3.0).max(3.0);
        let h22 = q * (15.0 * t_b - 3.0).max(3.0);
        let h33 = 9.0 * q;
        let h12 = 15.0 * q * (r_a * r_b).min(0.5);
        let mixed_z = p4 * (15.0 * t_z - 3.0).max(3.0);
        let h13 = r_a * mixed_z;
        let h23 = r_b * mixed_z;

        // Second moments along the local frame, in units of D^2.
        // |axis - z n| = sin_c for unit n and axis.
        let e1 = if sin_c > 0.0 {
            (cone.axis - z * n) / sin_c
        } else {
            n.any_orthonormal_vector()
        };
        let e2 = n.cross(e1);
        let cov = &node.covariance.map(f64::from);
        let inv_d2 = inv_d * inv_d;
        let trace = node.mean_squared_radius() * inv_d2;
        let pad = f32::EPSILON as f64 * trace;
        let s11 = (quadratic_form(cov, e1) * inv_d2).max(0.0) + pad;
        let s22 = (quadratic_form(cov, e2) * inv_d2).max(0.0) + pad;
        let s33 = (quadratic_form(cov, n) * inv_d2).max(0.0) + pad;
        let (d1, d2, d3) = (s11.sqrt(), s22.sqrt(), s33.sqrt());
        let per_axis = 0.5
            * (h11 * s11
                + h22 * s22
                + h33 * s33
                + 2.0 * (h12 * d1 * d2 + h13 * d1 * d3 + h23 * d2 * d3));
        let isotropic = 3.0 * p4 * trace;
        let remainder_unit = per_axis.min(isotropic) * (1.0 + SECOND_ORDER_SLACK);
        let remainder = self.kd * (node.weight * inv_d2 * remainder_unit);
        let rounding = SECOND_ORDER_SLACK * (scale * z.abs() + first_order.abs() + straddle)
            + f32::EPSILON as f64 * scale * grad_len * offset_lens;
        let lo2 = smooth - remainder - rounding;
        let hi2 = smooth + remainder + straddle + rounding;
        let estimate = smooth + 0.5 * straddle;
        let lo = lower.max(lo2);
        let hi = upper.min(hi2);
        if lo.cmpgt(hi).any() {
            // Both intervals contain the exact value, so they overlap up to
            // rounding; keep the paper's interval if they do not.
            debug_assert!(
                (lo - hi).max_element() <= 1e-9 * upper.max_element(),
                "disjoint bounds: paper [{lower}, {upper}] second order [{lo2}, {hi2}]"
            );
            return NodeEstimate::new(virtual_light, lower, upper);
        }
        NodeEstimate::new(estimate, lo, hi)
    }
}

impl ViewIndependent for Lambert {}
