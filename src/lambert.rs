//! Diffuse (Lambert) reflection with a certified node bound.

use glam::{DVec3, Vec3};

use crate::ShadeError;
use crate::geometry::{Cone, Surface};
use crate::numeric::{COS_SLACK, POINT_SLACK, SECOND_ORDER_SLACK, SERIES_SLACK, dot_of_difference};
use crate::shader::{NodeEstimate, Shader, ViewIndependent, colour_or_clamped, try_colour};
use crate::tree::Node;

/// Which node bound a shader uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum BoundKind {
    /// The paper's bound: the interval of the shading term over the node's
    /// ball, around the virtual light's value.
    Paper,
    /// The second-order Taylor bound: first-order colour correction in the
    /// estimate, Hessian bounds over the ball for the remainder, and the box
    /// refinements (the crate's default up to 0.1's development).
    Taylor,
    /// The dipole multipole series: the estimate sums the expansion through
    /// second order from per-channel moments, the remainder is bounded degree
    /// by degree from harmonic norms, with the box refinements.
    #[default]
    Series,
}

#[allow(non_upper_case_globals)]
impl BoundKind {
    /// The tightest bound the crate ships, currently
    /// [`BoundKind::Series`].
    pub const Tight: Self = Self::Series;
}

/// Diffuse reflection: a light of intensity `I` at distance `d` in direction
/// `w` contributes `I * kd * max(0, n . w) / d^2` (per channel; a light at
/// `d = 0` contributes 0).
///
/// # Node bound
/// For a node of intensity `I`, centroid `c`, radius `R`, seen at distance
/// `D = |c - p| > R` (a [`Cone`] with half-angle `delta`, `sin delta = R/D`,
/// and angle `theta_c` between `n` and the axis), three bounds are available
/// ([`BoundKind`]). All hold per channel `k`, whenever the cone exists
/// (`D - R > D * MIN_CLEARANCE`, see [`Cone::new`]), for any unit normal,
/// including nodes that straddle the tangent plane.
///
/// **Paper's bound** (slides "Diffuse Reflection Error Bound"):
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
/// **Box refinements** (with [`BoundKind::Taylor`] and [`BoundKind::Series`]),
/// from the node's tight box ([`Node::aabb`]) with `z_lo`, `z_hi` the lowest
/// and highest `n.(x - p)` over it: if `z_hi <= 0` every member is at or
/// below the tangent plane and the node is exactly 0; always
/// `exact <= I kd z_hi / (D - R)^3` (as `cos/d^2 = z/d^3`). Both refined
/// bounds work with the smooth `g(x) = n.(x - p) / |x - p|^3` and account
/// for the clamp `f = max(0, g)` separately: `f - g` is non-zero only below
/// the tangent plane, where `0 <= f - g = -z/d^3 <= depth / (D - R)^3`, with
/// `depth = max(0, min(R - n.(c - p), -z_lo))` how far the members reach
/// below the plane. So if `sum_i I_ik g(x_i)` lies in `[A, B]`, the exact
/// value lies in `kd_k [A, B + I_k depth / (D - R)^3]`; the extra term
/// vanishes when the box lies above the plane, which keeps the bound
/// continuous in `p` as a node crosses it. Each refined interval is
/// intersected with the paper's and the box's.
///
/// **Multipole series** ([`BoundKind::Series`], the default). Notation:
/// `y = x - c`, `u = c - p`, `uh = u / D`, `sigma = R / D < 1`,
/// `s = |y| / D <= sigma`, `t = -uh . y^` (the cosine between `y` and `-uh`),
/// `c0 = n . uh`, `nperp = n - c0 uh`, `nu = |nperp|`, `P_m` the Legendre
/// polynomials, and per channel `k` the node's intensity `I_k`, first moment
/// `o_k` ([`Node::channel_offsets`]) and second moment matrix `S_k`
/// ([`Node::channel_covariances`]).
///
/// *Expansion.* `g(u + y) = -n . grad_y (1 / |u + y|)` (a dipole), and
/// `1 / |u + y| = sum_l |y|^l P_l(t) / D^(l+1)` for `|y| < D` (the generating
/// function of the Legendre polynomials). Differentiating term by term with
/// `grad_y (r^l P_l(t)) = -r^(l-1) [P_(l-1)'(t) y^ + P_l'(t) uh]` (from
/// `l P_l - t P_l' = -P_(l-1)'`) and then `P_(m+1)' - t P_m' = (m+1) P_m`:
///
/// ```text
/// g(u + y) = D^-2 sum_(m>=0) a_m(y),
/// a_m(y) = s^m [c0 (m+1) P_m(t) + (nperp . y^) P_m'(t)],
/// ```
///
/// absolutely convergent for `s < 1`; `D^-2 a_m` is the degree-`m` Taylor
/// term of `g` about `c`, a homogeneous harmonic polynomial of degree `m` in
/// `y`. Degrees 0 to 2 written out (`sum_i I_ik y_i = I_k o_k`,
/// `sum_i I_ik y_i y_i^T = I_k S_k`):
///
/// ```text
/// E_k = I_k / D^2 [c0 + (n.o_k - 3 c0 uh.o_k) / D
///                  + (15 c0 uh.S_k.uh - 3 c0 tr S_k - 6 uh.S_k.n) / (2 D^2)]
/// ```
///
/// is the exact sum of the first three terms over the members.
///
/// *Degrees 3 to 5: harmonic norms.* Write
/// `nperp . y^ = nu sqrt(1 - t^2) cos phi` (`phi` the azimuth of `y^` about
/// `uh`, from `nperp`). On the unit sphere `a_m` is a spherical harmonic `Y`
/// of degree `m`; expand it in the `2m + 1` Schmidt
/// semi-normalised real harmonics, `Y = sum_j beta_j R_mj`. Their mean
/// squares over the sphere are `1 / (2m + 1)`, so
/// `|beta|^2 = (2m + 1) mean(Y^2)`, and from `mean(P_m^2) = 1 / (2m + 1)`,
/// `mean((1 - t^2) P_m'^2 cos^2 phi) = m (m+1) / (2 (2m + 1))` and a cross
/// term odd in `cos phi`:
/// `|beta|^2 = c0^2 (m+1)^2 + nu^2 m (m+1) / 2 =: A_m^2`. With the node's
/// moments `C_j = sum_i I_ik |y_i|^m R_mj(y^_i)`, whose norm is
/// `|C| = q_mk I_k R^m` ([`Node::harmonic_norms`]), Cauchy-Schwarz gives
///
/// ```text
/// |sum_i I_ik a_m(y_i)| = D^-m |beta . C| <= I_k A_m sigma^m q_mk.
/// ```
///
/// This captures the cancellation between members that pointwise bounds
/// miss. The zonal part alone (`Y = P_m(t)`, `|beta| = 1` by the addition
/// theorem) gives `|c0| (m+1) sigma^m q_mk` for the `c0` term, and the
/// `nperp` term is bounded pointwise with `|P_m'| <= m (m+1) / 2` and
/// `|nperp . y| <= hperp`, the largest `|nperp . (x - c)|` over the node's box:
///
/// ```text
/// |sum_i I_ik a_m(y_i)| <= I_k [|c0| (m+1) sigma^m q_mk + (hperp / D) m (m+1) / 2 mu_(m-1)],
/// ```
///
/// with `mu_j = sum_i I_ik s_i^j / I_k <= sigma^(j-2) mu_2`,
/// `mu_2 = tr(S_k) / D^2`. At grazing angles (`c0` small) over flat clusters
/// (`hperp` small) this second form is far smaller. Each degree takes the
/// smaller. (The classical pointwise bound, `|a_m| <= s^m (m+1)` from
/// Sonin's inequality, is never smaller than the first form, since
/// `A_m <= m + 1` and `sigma^m q_mk <= mu_m`.)
///
/// *Tail from degree 6.* Sonin's inequality
/// `m (m+1) P_m^2 + (1 - t^2) P_m'^2 <= m (m+1)` (by Legendre's equation
/// `F = P_m^2 + (1 - t^2) P_m'^2 / (m (m+1))` has `F' = 2 t P_m'^2 / (m (m+1))`,
/// so `F` is largest at `t = +-1`, where it is 1) and Cauchy-Schwarz on
/// `a_m / s^m = c0 (m+1) P_m + nu sqrt(1 - t^2) P_m' cos phi`, pairing
/// `(c0 sqrt((m+1)/m), nu cos phi)` with `(sqrt(m (m+1)) P_m, sqrt(1 - t^2) P_m')`,
/// give `|a_m| <= (m+1) s^m`.
/// With `mu_m <= sigma^(m-6) mu_6` the tail closes:
/// `sum_(m>=6) (m+1) mu_m <= mu_6 G1`, `G1 = 7 / (1 - sigma) + sigma / (1 - sigma)^2`.
/// The `hperp` form gives `|c0| mu_6 G1 + (hperp / D) mu_5 G2` with
/// `G2 = sum_(j>=0) (6+j)(7+j)/2 sigma^j
///     = [42 / (1 - sigma) + 13 sigma / (1 - sigma)^2 + sigma (1 + sigma) / (1 - sigma)^3] / 2`;
/// the smaller is used.
///
/// *Interval.* With `rho_k` the sum of the degree 3 to 5 bounds and the tail
/// (times `I_k / D^2`), `sum_i I_ik g(x_i)` lies in `[E_k - rho_k, E_k + rho_k]`,
/// which the clamp term above widens upward; intersected with the paper's
/// interval and the box's, times `kd_k`. The estimate is the final
/// interval's midpoint, which minimises the certified error
/// `max(estimate - lower, upper - estimate)`.
///
/// **Second-order Taylor bound** ([`BoundKind::Taylor`]). Taylor's theorem
/// for `g` about `c` gives, per channel `k`,
///
/// ```text
/// sum_i I_ik g(x_i) = I_k g(c) + grad g(c) . (I_k o_k) + sum_i I_ik rem_i,
/// |rem_i| <= 1/2 sum_jl sup|H_jl| |x_ij - c_j| |x_il - c_l|
/// ```
///
/// with `H` the Hessian of `g` over the ball. The estimate includes the
/// first-order term, so the error is second order. By Cauchy-Schwarz,
/// `sum_i I_ik |x_ij - c_j||x_il - c_l| <= I_k sqrt(S_k,jj S_k,ll)` with
/// `S_k` expressed in a frame `e1` (horizontal, towards `c`), `e2`
/// (horizontal), `e3 = n`. In units of `D` (`rho = 1 - R/D`,
/// `z+ = |cos theta_c| + R/D`, `a+ = sin theta_c + R/D`, `b+ = R/D`,
/// `t_a = min(1, (a+/rho)^2)`, likewise `t_b`, `t_z`, `q = z+/rho^5`) the
/// Hessian entries are bounded over the ball by
///
/// ```text
/// |H11| <= q max(3, 15 t_a - 3)     |H12| <= 15 q min(sqrt(t_a t_b), 1/2)
/// |H22| <= q max(3, 15 t_b - 3)     |H13| <= sqrt(t_a) max(3, 15 t_z - 3) / rho^4
/// |H33| <= 9 q                      |H23| <= sqrt(t_b) max(3, 15 t_z - 3) / rho^4
/// ```
///
/// and, isotropically, `||H|| <= 6 / rho^4` (the spectral norm of the Hessian
/// of `z/r^3` at unit distance is at most 6, reached along the normal). The
/// remainder uses the smaller of the per-axis and the isotropic sums. The
/// estimate, the Taylor sum plus half the clamp term, is clamped into the
/// final interval.
///
/// Every piece of every bound is continuous in `p`, so a node's estimate and
/// error are too.
///
/// # Rounding
/// Cosine bounds are widened by [`COS_SLACK`]. The series
/// bound widens its estimate by [`SERIES_SLACK`] of its terms' magnitudes,
/// by [`POINT_SLACK`] for the offset `c - p`, by
/// `f32::EPSILON (|o_k|_1 / D + 33 tr(S_k) / D^2)` for the `f32` storage of
/// the moments (offsets rounded to nearest move the degree-1 term by at most
/// `|grad| |o|_1 f32::EPSILON / 2 / D`, `|grad| <= 2`; the stored entries of
/// `S_k` are within `f32::EPSILON tr(S_k)` of the `f64` ones, moving each
/// quadratic form by at most `3 f32::EPSILON tr(S_k)`, and the degree-2 term
/// by `(15 * 3 + 3 + 6 * 3) / 2 = 33` of those), and by
/// `2 delta (sigma + 18 sigma^2)` for the build's `f64` sums of the
/// members' moments (each entry within `delta I_k R^j` of exact,
/// `delta` the node's [`Node::moment_error`]);
/// its remainder by [`SERIES_SLACK`] as documented there. Stored diagonals
/// of `S_k` and harmonic norms are rounded upward at build time, after an
/// allowance for their `f64` sums. The Taylor bound widens its estimate by
/// [`SECOND_ORDER_SLACK`] of its terms' magnitudes, by [`COS_SLACK`] times
/// `I_k / D^2` for the cosine, and by `f32::EPSILON` of the first-order
/// term, and by the same `2 delta (sigma + 18 sigma^2)` as the series for
/// the build's moment sums; the quadratic forms of `S_k` by
/// `f32::EPSILON * tr(S_k)`.
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
            kind: BoundKind::Series,
        }
    }

    /// Like [`Lambert::new`], but refuses a NaN, infinite or negative channel.
    ///
    /// # Errors
    /// [`ShadeError::InvalidMaterial`].
    pub fn try_new(kd: Vec3) -> Result<Self, ShadeError> {
        Ok(Self {
            kd: try_colour(kd, "kd must be finite and >= 0")?,
            kind: BoundKind::Series,
        })
    }

    /// Selects the node bound (default [`BoundKind::Series`]).
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
#[inline(always)]
fn quadratic_form(s: &[f64; 6], e: DVec3) -> f64 {
    s[0] * e.x * e.x
        + s[1] * e.y * e.y
        + s[2] * e.z * e.z
        + 2.0 * (s[3] * e.x * e.y + s[4] * e.x * e.z + s[5] * e.y * e.z)
}

/// The tail sums from degree 6 for `sigma < 1` and `inv_rho = 1 / (1 - sigma)`:
/// `G1 = sum_(j>=0) (7 + j) sigma^j = 7 / (1 - sigma) + sigma / (1 - sigma)^2`
/// and `G2 = sum_(j>=0) (6 + j)(7 + j) / 2 sigma^j
/// = [42 / (1 - sigma) + 13 sigma / (1 - sigma)^2 + sigma (1 + sigma) / (1 - sigma)^3] / 2`
/// (from `sum j sigma^j = sigma / (1 - sigma)^2` and
/// `sum j^2 sigma^j = sigma (1 + sigma) / (1 - sigma)^3`).
#[inline(always)]
fn tail_sums(sigma: f64, inv_rho: f64) -> (f64, f64) {
    let g1 = 7.0 * inv_rho + sigma * inv_rho * inv_rho;
    let g2 = 0.5 * inv_rho * (42.0 + inv_rho * sigma * (13.0 + (1.0 + sigma) * inv_rho));
    (g1, g2)
}

/// Lowest and highest value of `n.(x - p)` over the node's box (heights
/// above the tangent plane at the shading point), widened outward by the
/// rounding of the box's `f64` support function (a few ulps of the
/// coordinates' magnitude). Whether the box lies at or below the plane is
/// decided exactly ([`Aabb::lies_at_or_below`](crate::Aabb::lies_at_or_below)),
/// with no slack: then the highest value returned is at most 0, so a box
/// lying exactly in the plane is recognised as contributing 0.
#[inline(always)]
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

    /// Always `Some(kd)`, whichever [`BoundKind`]: shared cuts use their own
    /// bound (the series, enlarged over the group of points).
    #[inline]
    fn diffuse_albedo(&self) -> Option<DVec3> {
        Some(self.kd)
    }

    #[inline]
    fn prepare(&self, _surface: &Surface) {}

    /// The given normal: [`eval`](Shader::eval) takes the exact sign of
    /// `N . (x - p)` and returns 0 where it is at most 0.
    #[inline]
    fn horizon(&self, surface: &Surface) -> Option<Vec3> {
        Some(surface.given_normal)
    }

    /// The model's term `I kd max(0, n.w) / d^2` with `n = N / |N|` for the
    /// given normal `N`, computed as `N.(x - p) / (|N| d^3)`. For a
    /// `position` holding `f32` values (every light's), the sign of `N.(x -
    /// p)` is exact and its value within `2^-40` relative, within about
    /// `f64::EPSILON` near the plane (error-free transformations, see
    /// [`numeric`](crate::numeric)): a light in the tangent plane
    /// contributes exactly 0, one barely above it its value to a few ulps.
    #[inline(always)]
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

    #[inline(always)]
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
        // f = max(0, g) exceeds g only below the tangent plane, where
        // 0 <= f - g = -z/r^3 <= depth / (D - R)^3, depth being how far the
        // members reach below the plane: at most R - n.(c - p) (the ball) and
        // at most the box's depth. Zero when the box lies above the plane,
        // and continuous as a node crosses it. In units of 1/D^2.
        let depth = (sd - z).min(-lowest * inv_d).max(0.0);
        let straddle = depth * inv_rho3;
        let geometry = Geometry {
            surface,
            node,
            cone,
            scale,
            z,
            sin_c,
            inv_rho,
            straddle,
        };
        let (lo2, hi2, estimate) = if self.kind == BoundKind::Taylor {
            self.taylor(&geometry)
        } else {
            self.series(&geometry)
        };
        let lo = lower.max(lo2);
        let hi = upper.min(hi2);
        if lo.cmpgt(hi).any() {
            // Both intervals contain the exact value, so they overlap up to
            // rounding; keep the paper's interval if they do not.
            debug_assert!(
                (lo - hi).max_element() <= 1e-9 * upper.max_element(),
                "disjoint bounds: paper [{lower}, {upper}] second [{lo2}, {hi2}]"
            );
            return NodeEstimate::new(virtual_light, lower, upper);
        }
        match estimate {
            Some(estimate) => NodeEstimate::new(estimate, lo, hi),
            // The midpoint minimises the certified error.
            None => NodeEstimate::new(0.5 * (lo + hi), lo, hi),
        }
    }
}

/// What both refined bounds share: the normal against the axis, the
/// nearest distance, and the below-the-plane term.
struct Geometry<'a> {
    surface: &'a Surface,
    node: &'a Node,
    cone: &'a Cone,
    /// `I kd / D^2` per channel.
    scale: DVec3,
    /// `n . uh`.
    z: f64,
    /// `|n x uh|`.
    sin_c: f64,
    /// `D / (D - R)`.
    inv_rho: f64,
    /// Bound on `sum (f - g) / I` in units of `1/D^2`.
    straddle: f64,
}

impl Lambert {
    /// The second-order Taylor interval `(lower, upper, estimate)`.
    #[inline]
    fn taylor(&self, geo: &Geometry<'_>) -> (DVec3, DVec3, Option<DVec3>) {
        let (surface, node, cone, scale) = (geo.surface, geo.node, geo.cone, geo.scale);
        let n = surface.normal;
        let (z, sin_c, inv_rho) = (geo.z, geo.sin_c, geo.inv_rho);
        let inv_d = cone.inv_distance;
        let sd = cone.sin_half_angle;
        let inv_rho3 = inv_rho * inv_rho * inv_rho;
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
        let straddle = scale * geo.straddle;

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
        let inv_d2 = inv_d * inv_d;
        let traces = node.mean_squared_radii() * inv_d2;
        let mut remainder_unit = DVec3::ZERO;
        for k in 0..3 {
            let cov = &node.channel_covariances[k].map(f64::from);
            let trace = traces[k];
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
            remainder_unit[k] = per_axis.min(isotropic) * (1.0 + SECOND_ORDER_SLACK);
        }
        let remainder = scale * remainder_unit;
        // The cosine z carries an absolute error (up to COS_SLACK) that a
        // relative slack of |z| misses when z is near 0.
        // The build's f64 moment sums, as for the series bound.
        let sums = 2.0 * node.moment_error() * sd * (1.0 + 18.0 * sd);
        let rounding = SECOND_ORDER_SLACK * (scale * z.abs() + first_order.abs() + straddle)
            + COS_SLACK * scale
            + f32::EPSILON as f64 * scale * grad_len * offset_lens
            + scale * sums;
        let lo2 = smooth - remainder - rounding;
        let hi2 = smooth + remainder + straddle + rounding;
        (lo2, hi2, Some(smooth + 0.5 * straddle))
    }

    /// The multipole series interval `(lower, upper)` of the smooth sum,
    /// widened upward by the clamp term; the estimate is the final
    /// interval's midpoint.
    #[inline(always)]
    fn series(&self, geo: &Geometry<'_>) -> (DVec3, DVec3, Option<DVec3>) {
        let (surface, node, cone, scale) = (geo.surface, geo.node, geo.cone, geo.scale);
        let n = surface.normal;
        let uh = cone.axis;
        let c0 = geo.z;
        let inv_rho = geo.inv_rho;
        let inv_d = cone.inv_distance;
        let sigma = cone.sin_half_angle;

        let series = degree_two(n, cone, node);
        // Remainder in units of I_k / D^2. The quantities it grows with,
        // widened for their input rounding (see SERIES_SLACK).
        let ac = c0.abs() + SERIES_SLACK;
        let nu = geo.sin_c + SERIES_SLACK;
        // hperp / D: the box's reach across the axis, from the box corners
        // relative to c (each difference one rounding of a value <= R).
        let nperp = n - c0 * uh;
        let c = node.centroid.as_dvec3();
        let (lo, hi) = (node.aabb.min.as_dvec3() - c, node.aabb.max.as_dvec3() - c);
        let reach = nperp.dot(0.5 * (lo + hi)).abs() + nperp.abs().dot(0.5 * (hi - lo));
        let hperp = (reach + SERIES_SLACK * cone.radius) * inv_d;
        let width = series_width(node, (inv_d, sigma, inv_rho), (ac, nu * nu, hperp));
        (
            scale * (series - width),
            scale * (series + width + geo.straddle),
            None,
        )
    }
}

/// What a group of shading points knows of a node's geometry for
/// [`shared_width`], as upper bounds over every point `p` of the group and
/// its exact unit normal `n`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SharedView {
    /// `1 / D` for the smallest distance `D > R` from a point to the
    /// node's centroid.
    pub(crate) inv_nearest: f64,
    /// `|c0| = |n . (c - p)| / |c - p|`, at most 1.
    pub(crate) cosine: f64,
    /// `|n . (x - c)|` over the node's box.
    pub(crate) height: f64,
    /// `|n - n0|` for the group's mean normal `n0` (how far `n` is from
    /// what `height` was measured along).
    pub(crate) tilt: f64,
}

/// The width of the series interval shared by every shading point of a
/// group, per channel in units of `I_k / D^2` (`D` the group's nearest
/// distance, [`SharedView`]): for each point `p`, the smooth sum (`g`
/// unclamped) over the members of `node` lies within that width times
/// `I_k kd_k / D^2` of `I_k kd_k / D_p^2 * degree_two(..)` at `p`; where
/// members lie below `p`'s tangent plane the exact sum exceeds the smooth
/// one by at most the clamp term of [`Lambert`]'s docs, which the caller
/// adds.
///
/// Why it holds: the width of [`Lambert::series`] at `p` is a sum of terms
/// that grow as `D_p` falls (`sigma = R / D_p`, `|o_k| / D_p`,
/// `tr(S_k) / D_p^2`, the tail sums, `D_p / (D_p - R)`) and as `|c0|` and
/// `hperp` grow, so it is largest at the smallest distance with the largest
/// `|c0|` and `hperp`; `A_m^2 = c0^2 (m+1)^2 + nu^2 m (m+1) / 2` with
/// `nu <= 1`; `|nperp . y| <= |n . y| + |c0| |uh . y|`,
/// `|n . y| <= |n0 . y| + |n - n0| |y|` and `|y| <= R` give
/// `hperp <= height + (tilt + |c0|) R`; and `I_k / D_p^2 <= I_k / D^2`.
#[inline(always)]
pub(crate) fn shared_width(node: &Node, view: &SharedView) -> DVec3 {
    let inv_d = view.inv_nearest;
    let radius = f64::from(node.radius);
    let sigma = radius * inv_d;
    let inv_rho = 1.0 / (1.0 - sigma);
    let ac = view.cosine.min(1.0) + SERIES_SLACK;
    let hperp = (view.height + (view.tilt + ac + SERIES_SLACK) * radius) * inv_d;
    series_width(node, (inv_d, sigma, inv_rho), (ac, 1.0, hperp))
}

/// The width of the series interval, per channel in units of `I_k / D^2`:
/// the remainder from degree 3 (harmonic norms for degrees 3 to 5, the tail
/// from degree 6; see [`Lambert`]) and the rounding slack, for
/// `(1/D, sigma = R/D, D/(D - R))` and the (widened) `|c0|`, `nu^2` and
/// `hperp / D`.
#[inline(always)]
fn series_width(
    node: &Node,
    (inv_d, sigma, inv_rho): (f64, f64, f64),
    (ac, nu2, hperp): (f64, f64, f64),
) -> DVec3 {
    let o = node.channel_offsets.map(|v| v.as_dvec3());
    let offset_lens = DVec3::new(
        o[0].abs().element_sum(),
        o[1].abs().element_sum(),
        o[2].abs().element_sum(),
    ) * inv_d;
    let mu2 = node.mean_squared_radii() * (inv_d * inv_d);
    let c2 = ac * ac;
    let mut remainder = DVec3::ZERO;
    // mu_(m-1) <= sigma^(m-3) mu_2 and sigma^m, from m = 3.
    let mut mu_prev = mu2;
    let mut sigma_m = sigma * sigma * sigma;
    // A_m for m = 3, 4, 5, side by side (one vector square root where the
    // processor has it).
    let harmonics = [3.0f64, 4.0, 5.0]
        .map(|m| c2 * (m + 1.0) * (m + 1.0) + nu2 * (0.5 * m * (m + 1.0)))
        .map(f64::sqrt);
    for (d, (q, harmonic)) in node.harmonic_norms.iter().zip(harmonics).enumerate() {
        let m = (d + 3) as f64;
        let q = q.as_dvec3() * sigma_m;
        let across = q * (ac * (m + 1.0)) + mu_prev * (hperp * 0.5 * m * (m + 1.0));
        remainder += (q * harmonic).min(across);
        mu_prev *= sigma;
        sigma_m *= sigma;
    }
    // Tail from degree 6: mu_5 = mu_prev, mu_6 <= sigma mu_5.
    let mu6 = mu_prev * sigma;
    let (g1, g2) = tail_sums(sigma, inv_rho);
    let tail = mu6 * g1;
    remainder += tail.min(tail * ac + mu_prev * (hperp * g2));

    let remainder = remainder * (1.0 + SERIES_SLACK * inv_rho);
    let sums = 2.0 * node.moment_error() * sigma * (1.0 + 18.0 * sigma);
    let slack = SERIES_SLACK * (1.0 + offset_lens + mu2)
        + f32::EPSILON as f64 * (offset_lens + 33.0 * mu2)
        + sums
        + POINT_SLACK * inv_rho * inv_rho * inv_rho;
    remainder + slack
}

/// The multipole series of `g` through degree 2, summed over the node's
/// members, per channel in units of `I_k / D^2` (see [`Lambert`]'s docs):
/// `c0 + (n.o - 3 c0 uh.o) / D + (15 c0 uh.S.uh - 3 c0 tr S - 6 uh.S.n) / (2 D^2)`.
/// The node bound and the shared cuts of batch shading both evaluate it
/// here, so its rounding is the one [`SERIES_SLACK`] accounts for.
#[inline(always)]
pub(crate) fn degree_two(n: DVec3, cone: &Cone, node: &Node) -> DVec3 {
    let uh = cone.axis;
    let c0 = n.dot(uh);
    let inv_d = cone.inv_distance;
    let grad = n - 3.0 * c0 * uh;
    let o = node.channel_offsets.map(|v| v.as_dvec3());
    let first = DVec3::new(grad.dot(o[0]), grad.dot(o[1]), grad.dot(o[2])) * inv_d;
    // The degree-2 bracket is linear in S: one weight per stored entry
    // [xx, yy, zz, xy, xz, yz], shared by the three channels.
    let (a, b) = (15.0 * c0, 3.0 * c0);
    let weights = [
        a * uh.x * uh.x - b - 6.0 * uh.x * n.x,
        a * uh.y * uh.y - b - 6.0 * uh.y * n.y,
        a * uh.z * uh.z - b - 6.0 * uh.z * n.z,
        2.0 * a * uh.x * uh.y - 6.0 * (uh.x * n.y + uh.y * n.x),
        2.0 * a * uh.x * uh.z - 6.0 * (uh.x * n.z + uh.z * n.x),
        2.0 * a * uh.y * uh.z - 6.0 * (uh.y * n.z + uh.z * n.y),
    ];
    let mut second = DVec3::ZERO;
    for k in 0..3 {
        let mut form = 0.0;
        for (entry, weight) in node.channel_covariances[k].iter().zip(weights) {
            form += f64::from(*entry) * weight;
        }
        second[k] = form;
    }
    c0 + first + second * (0.5 * inv_d * inv_d)
}

impl ViewIndependent for Lambert {}

#[cfg(test)]
mod tests {
    use super::tail_sums;

    /// The closed forms of the tail sums against the series summed term by
    /// term.
    #[test]
    fn tail_sums_match_their_series() {
        for i in 0..=99 {
            let sigma = f64::from(i) / 100.0;
            let (g1, g2) = tail_sums(sigma, 1.0 / (1.0 - sigma));
            let (mut s1, mut s2, mut power) = (0.0, 0.0, 1.0);
            for j in 0..20_000 {
                let j = f64::from(j);
                s1 += (7.0 + j) * power;
                s2 += (6.0 + j) * (7.0 + j) / 2.0 * power;
                power *= sigma;
            }
            assert!(
                (g1 - s1).abs() <= 1e-12 * s1,
                "G1 at {sigma}: {g1} against {s1}"
            );
            assert!(
                (g2 - s2).abs() <= 1e-12 * s2,
                "G2 at {sigma}: {g2} against {s2}"
            );
        }
    }
}
