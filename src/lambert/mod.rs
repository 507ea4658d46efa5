//! Diffuse (Lambert) reflection with a certified node bound.

use glam::{DVec3, Vec3};

#[cfg(test)]
mod bound_tests;
mod coarse;
mod group;
mod series;

use series::{Rgb, WidthInput, degree_two_lanes, rgb, series_width};
mod shared;

use crate::geometry::{Cone, GroupView, Surface};
use crate::lanes::{Lanes, Vec3Lanes, array};
use crate::numeric::{
    COS_SLACK, NAIVE_DOT_ACCEPT, SECOND_ORDER_SLACK, SERIES_SLACK, dot_of_difference,
};
use crate::shader::{
    ChildrenOf, NodeEstimate, Seal, Shader, ViewIndependent, colour_or_clamped, try_colour,
};
use crate::tree::Node;
use crate::tree::groups::{Block, with_block};
use crate::{LightLanes, PointLight, ShadeError};

/// Which node bound a shader uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum BoundKind {
    /// The paper's bound: the interval of the shading term over the node's
    /// ball, around the virtual light's value.
    Paper,
    /// The second-order Taylor bound: first-order colour correction in the
    /// estimate, Hessian bounds over the ball for the remainder, and the box
    /// refinements.
    Taylor,
    /// The dipole multipole series: the estimate sums the expansion through
    /// second order from per-channel moments, the remainder is bounded degree
    /// by degree from harmonic norms, with the box refinements.
    #[default]
    Series,
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
/// Cosine bounds are widened by `16 f64::EPSILON`. The series
/// bound widens its estimate by `1024 f64::EPSILON` of its terms' magnitudes,
/// by `2 f64::EPSILON` for the offset `c - p`, by
/// `f32::EPSILON (|o_k|_1 / D + 33 tr(S_k) / D^2)` for the `f32` storage of
/// the moments (offsets rounded to nearest move the degree-1 term by at most
/// `|grad| |o|_1 f32::EPSILON / 2 / D`, `|grad| <= 2`; the stored entries of
/// `S_k` are within `f32::EPSILON tr(S_k)` of the `f64` ones, moving each
/// quadratic form by at most `3 f32::EPSILON tr(S_k)`, and the degree-2 term
/// by `(15 * 3 + 3 + 6 * 3) / 2 = 33` of those), and by
/// `2 delta (sigma + 18 sigma^2)` for the build's `f64` sums of the
/// members' moments (each entry within `delta I_k R^j` of exact,
/// `delta` the node's [`Node::moment_error`](crate::shader::Node::moment_error));
/// its remainder by `1024 f64::EPSILON` likewise. Stored diagonals
/// of `S_k` and harmonic norms are rounded upward at build time, after an
/// allowance for their `f64` sums. The Taylor bound widens its estimate by
/// `64 f64::EPSILON` of its terms' magnitudes, by `16 f64::EPSILON` times
/// `I_k / D^2` for the cosine, and by `f32::EPSILON` of the first-order
/// term, and by the same `2 delta (sigma + 18 sigma^2)` as the series for
/// the build's moment sums; the quadratic forms of `S_k` by
/// `f32::EPSILON * tr(S_k)`.
///
/// **Single precision.** [`Shader::bound_children_coarse`] evaluates the
/// same series, paper and box intervals for a node's children side by side
/// in `f32` lanes, every quantity dimensionless (in units of `D` and of
/// `I_k kd_k / D^2`) so that `f32`'s range holds at any scale, and the
/// final scaling in `f64`. Each step is widened by its own `f32` rounding,
/// derived operation by operation (`c0` within `8.6 u`, the degree-0 to 2
/// estimate within `u (11 + 69 x + 416 y)` with `u = 2^-24`, `x = |o_k|_1 /
/// D`, `y` the stored `S_k`'s magnitudes over `D^2`, the offset's rounding
/// as a point moved by `u D`, and so on; the allowances used are about
/// twice these), and a test checks every step against the same formula in
/// `f64`. Children with squared distances outside `[2^-120, 2^120]`, or
/// whose ball comes within `2^-6 D` of the point (where the offset's
/// rounding, magnified by `(D / (D - R))^3`, would dominate), are bounded
/// in `f64` as above. The harmonic norms are read from half-precision
/// copies rounded upward (at most `2^-10` larger).
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
/// Nodes bounded side by side by [`Shader::bound_nodes`]: two 4-wide AVX2
/// vectors of `f64`.
const GROUP: usize = 8;

/// The coarse sum of the `coarse` module's AVX2 copy `$avx2` where the
/// processor has AVX2, else of its baseline `$baseline`, on the same
/// arguments (the same bits either way): the body of each of `Lambert`'s
/// coarse sums, whose callers allow the unsafe call.
macro_rules! coarse_sum {
    ($avx2:ident, $baseline:ident, $($arg:expr),+) => {{
        #[cfg(target_arch = "x86_64")]
        {
            if crate::dispatch::avx2() {
                // SAFETY: the processor has AVX2 (`dispatch::avx2` checked).
                return unsafe { coarse::$avx2($($arg),+) };
            }
        }
        coarse::$baseline($($arg),+)
    }};
}

impl Shader for Lambert {
    type PerPoint = ();

    /// Always `Some(kd)`, whichever [`BoundKind`]: shared cuts use their own
    /// bound (the series, enlarged over the group of points).
    #[inline]
    fn diffuse_albedo(&self, _: Seal) -> Option<DVec3> {
        Some(self.kd)
    }

    /// The series width at the group's worst view ([`shared::errors`]).
    #[inline(always)]
    fn group_errors<const N: usize>(
        &self,
        _: Seal,
        nodes: &[&Node; N],
        views: &[GroupView; N],
    ) -> Option<[DVec3; N]> {
        Some(shared::errors::<N>(self.kd, nodes, views))
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
    /// `f64::EPSILON` near the plane (error-free transformations): a light in the tangent plane
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

    /// Four lights at a time side by side, with the very same operations
    /// per light as [`eval`](Shader::eval) (lights within about 0.1 degree
    /// of the tangent plane, whose height needs the compensated or exact
    /// dot product, go through `eval` itself): the same results, bit for
    /// bit.
    #[inline]
    fn eval_lights(&self, _: &(), surface: &Surface, lights: &[PointLight], out: &mut [DVec3]) {
        self.eval_group(surface, lights, out);
    }

    /// Four lights at a time side by side, each lane summing its lights'
    /// `intensity * height / (|N| d^3)` where the height is positive (the
    /// terms of [`eval`](Shader::eval) before `kd`, the height accepted as
    /// `eval` accepts it); lights within about 0.1 degree of the tangent
    /// plane go through `eval` itself.
    #[inline]
    fn sum_lights(&self, _: Seal, _: &(), surface: &Surface, lights: &[PointLight]) -> DVec3 {
        self.sum_group(surface, lights)
    }

    /// In `f32`, eight lights side by side: within `32 * 2^-24` of `kd`
    /// times `sum max_k I_k / d^2` over the lights (per channel), for
    /// squared distances between `2^-60` and `2^60` and intensities up to
    /// `2^40` (else `None`), at a point that is an `f32` value.
    // Calling the AVX2 copy is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    #[inline]
    fn sum_lights_coarse(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        coarse_sum!(sum_avx2, sum_baseline, self.kd, surface, lights)
    }

    /// The same bits as [`sum_lights_coarse`](Shader::sum_lights_coarse)
    /// on the same lights, each quantity of eight lights loaded at once.
    // Calling the AVX2 copy is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    #[inline]
    fn sum_lanes_coarse(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        lanes: &[LightLanes],
        count: usize,
    ) -> Option<(DVec3, DVec3)> {
        coarse_sum!(
            sum_lanes_avx2,
            sum_lanes_baseline,
            self.kd,
            surface,
            lanes,
            count
        )
    }

    /// Blocks of 64 lights summed as by
    /// [`sum_lanes_coarse`](Shader::sum_lanes_coarse), their lanes added
    /// in `f64`: the same bound (see the rounding analysis of the coarse
    /// sums), one call for the whole scene.
    // Calling the AVX2 copy is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    #[inline]
    fn sum_scene_coarse(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        lanes: &[LightLanes],
        count: usize,
    ) -> Option<(DVec3, DVec3)> {
        coarse_sum!(
            sum_scene_lanes_avx2,
            sum_scene_lanes_baseline,
            self.kd,
            surface,
            lanes,
            count
        )
    }

    /// With [`BoundKind::Series`], the children side by side in `f32`
    /// lanes (see the `group` module's rounding analysis), each scaled by
    /// `I_k kd_k / D^2` in `f64`; children too far or too near for `f32`
    /// (squared distances outside `[2^-120, 2^120]`, or a ball within
    /// `2^-6 D` of the point) go through [`bound`](Shader::bound), and a
    /// box reaching the tangent plane is tested exactly, as there.
    #[inline]
    fn bound_children_coarse(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        children: ChildrenOf<'_>,
        out: &mut [Option<NodeEstimate>],
    ) -> bool {
        let ChildrenOf {
            tree,
            parent,
            wanted,
        } = children;
        if self.kind != BoundKind::Series {
            return false;
        }
        let Some(node) = tree.nodes().get(parent) else {
            return false;
        };
        let Some(group) = tree.groups.children(parent) else {
            return false;
        };
        let p = surface.point.as_vec3();
        if p.as_dvec3() != surface.point {
            return false;
        }
        let at = group::PointView {
            p: p.to_array(),
            n: surface.normal.as_vec3().to_array(),
        };
        let children = &tree.nodes()[node.children()];
        with_block!(group, block => {
            let lanes = group_bounds(block, &at, &self.scales(children));
            self.fill_children(surface, children, wanted, &lanes, out);
        });
        true
    }

    #[inline]
    fn bound(&self, _: &(), surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        let mut out = [NodeEstimate::ZERO];
        self.bound_group(surface, &[node], core::slice::from_ref(cone), &mut out);
        out[0]
    }

    /// Eight nodes at a time, side by side in vector registers, with the
    /// very same operations per node as [`bound`](Shader::bound): the same
    /// results, bit for bit.
    #[inline(always)]
    fn bound_nodes(
        &self,
        _: &(),
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        let chunks = nodes.chunks(GROUP).zip(cones.chunks(GROUP));
        for ((nodes, cones), out) in chunks.zip(out.chunks_mut(GROUP)) {
            self.bound_group(surface, nodes, cones, out);
        }
    }
}

impl Lambert {
    /// [`Shader::eval_lights`]: on `x86_64` processors with AVX2, in a copy
    /// compiled for AVX2 (the same bits, see [`dispatch`](crate::dispatch)).
    /// Out of line, compiled once.
    // Calling the AVX2 copy is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    #[inline(never)]
    fn eval_group(&self, surface: &Surface, lights: &[PointLight], out: &mut [DVec3]) {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::dispatch::avx2() {
                // SAFETY: the processor has AVX2 (`dispatch::avx2` checked).
                unsafe { self.eval_group_avx2(surface, lights, out) };
                return;
            }
        }
        self.eval_group_inlined(surface, lights, out);
    }

    /// [`eval_group`](Self::eval_group) compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn eval_group_avx2(&self, surface: &Surface, lights: &[PointLight], out: &mut [DVec3]) {
        self.eval_group_inlined(surface, lights, out);
    }

    #[inline(always)]
    fn eval_group_inlined(&self, surface: &Surface, lights: &[PointLight], out: &mut [DVec3]) {
        const L: usize = 4;
        let normal = surface.given_normal.as_dvec3();
        let n2 = normal.length_squared();
        let p = surface.point;
        for (chunk, out) in lights.chunks(L).zip(out.chunks_mut(L)) {
            // A short last chunk repeats its last light in the unused lanes.
            let last = chunk.len() - 1;
            let position =
                Vec3Lanes::<L>::from_fn(|i| chunk[i.min(last)].position.as_dvec3().to_array());
            let d = position.minus(p.to_array());
            // Plain f64 heights, accepted per lane as dot_of_difference does.
            let terms = Vec3Lanes {
                x: normal.x * d.x,
                y: normal.y * d.y,
                z: normal.z * d.z,
            };
            let height = terms.element_sum();
            let magnitude = terms.abs().element_sum();
            let d2 = d.dot(d);
            let ratio = height / (d2 * (n2 * d2).sqrt());
            for (i, (light, out)) in chunk.iter().zip(out).enumerate() {
                let h = height.0[i];
                *out = if h.abs() >= NAIVE_DOT_ACCEPT * magnitude.0[i] {
                    if h > 0.0 {
                        light.intensity.as_dvec3() * self.kd * ratio.0[i]
                    } else {
                        DVec3::ZERO
                    }
                } else {
                    self.eval(
                        &(),
                        surface,
                        light.position.as_dvec3(),
                        light.intensity.as_dvec3(),
                    )
                };
            }
        }
    }

    /// [`Shader::sum_lights`]: on `x86_64` processors with AVX2, written
    /// with its vector instructions (the same bits, see
    /// [`dispatch`](crate::dispatch)). Out of line, compiled once.
    // Calling the AVX2 copy is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    #[inline(never)]
    fn sum_group(&self, surface: &Surface, lights: &[PointLight]) -> DVec3 {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::dispatch::avx2() {
                // SAFETY: the processor has AVX2 (`dispatch::avx2` checked).
                return unsafe { self.sum_group_avx2(surface, lights) };
            }
        }
        self.sum_group_baseline(surface, lights)
    }

    /// [`sum_group`](Self::sum_group), four lanes of `f64`: lane `i` takes
    /// light `i` of each full chunk of four, then of the short last chunk.
    /// A lane adds `intensity * ratio` where the height `h = N.(x - p)` is
    /// accepted (as in `dot_of_difference`) and positive, with `ratio = h /
    /// (d^2 sqrt(|N|^2 d^2))` as in [`eval`](Shader::eval); lights whose
    /// height is not accepted go through `eval`. The lanes' sums are added
    /// as `(l0 + l1) + (l2 + l3)` and multiplied by `kd`.
    fn sum_group_baseline(&self, surface: &Surface, lights: &[PointLight]) -> DVec3 {
        let terms = LightTerms::new(surface);
        let (mut sums, mut near) = ([[0.0f64; 4]; 3], DVec3::ZERO);
        self.add_to_lanes(surface, &terms, lights, &mut sums, &mut near);
        terms.total(self.kd, sums, near)
    }

    /// Adds `lights` to four lanes' sums, light `i` to lane `i % 4`, and
    /// those whose height is not accepted through [`eval`](Shader::eval)
    /// to `near`: the baseline's whole sum, the AVX2 copy's last short
    /// chunk.
    #[inline(always)]
    fn add_to_lanes(
        &self,
        surface: &Surface,
        terms: &LightTerms,
        lights: &[PointLight],
        sums: &mut [[f64; 4]; 3],
        near: &mut DVec3,
    ) {
        for (i, light) in lights.iter().enumerate() {
            let (weight, accepted) = terms.weight(light.position);
            for (sum, e) in sums.iter_mut().zip(light.intensity.to_array()) {
                sum[i % 4] += f64::from(e) * weight;
            }
            if !accepted {
                *near += self.eval(
                    &(),
                    surface,
                    light.position.as_dvec3(),
                    light.intensity.as_dvec3(),
                );
            }
        }
    }

    /// [`sum_group_baseline`](Self::sum_group_baseline) with AVX2 vector
    /// instructions for the full chunks: the same operations lane by lane
    /// (no fused multiply-add), so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sum_group_avx2(&self, surface: &Surface, lights: &[PointLight]) -> DVec3 {
        use core::arch::x86_64::{
            __m128, __m256d, _CMP_GE_OQ, _CMP_GT_OQ, _mm_movehl_ps, _mm_movelh_ps, _mm_set_ps,
            _mm_unpackhi_ps, _mm_unpacklo_ps, _mm256_add_pd, _mm256_and_pd, _mm256_andnot_pd,
            _mm256_cmp_pd, _mm256_cvtps_pd, _mm256_div_pd, _mm256_movemask_pd, _mm256_mul_pd,
            _mm256_set1_pd, _mm256_setzero_pd, _mm256_sqrt_pd, _mm256_sub_pd,
        };
        let terms = LightTerms::new(surface);
        let n2 = _mm256_set1_pd(terms.n2);
        let [nx, ny, nz] = terms.normal.to_array().map(|v| _mm256_set1_pd(v));
        let [px, py, pz] = terms.point.to_array().map(|v| _mm256_set1_pd(v));
        let accept = _mm256_set1_pd(NAIVE_DOT_ACCEPT);
        let sign = _mm256_set1_pd(-0.0);
        let zero = _mm256_setzero_pd();
        // |v|: the sign bit cleared.
        let strip = |v: __m256d| _mm256_andnot_pd(sign, v);
        let (mut r, mut g, mut b) = (zero, zero, zero);
        let mut near = DVec3::ZERO;
        let chunks = lights.chunks_exact(4);
        let rest = chunks.remainder();
        for chunk in chunks {
            // (x, y, z, red) and (green, blue) of each light, transposed to
            // one vector per coordinate.
            let row = |l: &PointLight| {
                _mm_set_ps(l.intensity.x, l.position.z, l.position.y, l.position.x)
            };
            let [a, b_, c, d] = [
                row(&chunk[0]),
                row(&chunk[1]),
                row(&chunk[2]),
                row(&chunk[3]),
            ];
            let (ab_lo, ab_hi) = (_mm_unpacklo_ps(a, b_), _mm_unpackhi_ps(a, b_));
            let (cd_lo, cd_hi) = (_mm_unpacklo_ps(c, d), _mm_unpackhi_ps(c, d));
            let column = |v: __m128| _mm256_cvtps_pd(v);
            let x = column(_mm_movelh_ps(ab_lo, cd_lo));
            let y = column(_mm_movehl_ps(cd_lo, ab_lo));
            let z = column(_mm_movelh_ps(ab_hi, cd_hi));
            let red = column(_mm_movehl_ps(cd_hi, ab_hi));
            let pair = |l: &PointLight, m: &PointLight| {
                _mm_set_ps(m.intensity.z, m.intensity.y, l.intensity.z, l.intensity.y)
            };
            let (e01, e23) = (pair(&chunk[0], &chunk[1]), pair(&chunk[2], &chunk[3]));
            // (g0, b0, g1, b1) and (g2, b2, g3, b3).
            let (lo, hi) = (_mm_unpacklo_ps(e01, e23), _mm_unpackhi_ps(e01, e23));
            // lo = (g0, g2, b0, b2), hi = (g1, g3, b1, b3).
            let green = column(_mm_unpacklo_ps(lo, hi));
            let blue = column(_mm_unpackhi_ps(lo, hi));
            let (dx, dy, dz) = (
                _mm256_sub_pd(x, px),
                _mm256_sub_pd(y, py),
                _mm256_sub_pd(z, pz),
            );
            let (tx, ty, tz) = (
                _mm256_mul_pd(nx, dx),
                _mm256_mul_pd(ny, dy),
                _mm256_mul_pd(nz, dz),
            );
            let h = _mm256_add_pd(_mm256_add_pd(tx, ty), tz);
            let magnitude = _mm256_add_pd(_mm256_add_pd(strip(tx), strip(ty)), strip(tz));
            let d2 = _mm256_add_pd(
                _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                _mm256_mul_pd(dz, dz),
            );
            let ratio = _mm256_div_pd(h, _mm256_mul_pd(d2, _mm256_sqrt_pd(_mm256_mul_pd(n2, d2))));
            let accepted = _mm256_cmp_pd::<_CMP_GE_OQ>(strip(h), _mm256_mul_pd(accept, magnitude));
            let positive = _mm256_cmp_pd::<_CMP_GT_OQ>(h, zero);
            let weight = _mm256_and_pd(ratio, _mm256_and_pd(accepted, positive));
            r = _mm256_add_pd(r, _mm256_mul_pd(red, weight));
            g = _mm256_add_pd(g, _mm256_mul_pd(green, weight));
            b = _mm256_add_pd(b, _mm256_mul_pd(blue, weight));
            let mask = _mm256_movemask_pd(accepted);
            if mask != 0b1111 {
                for (i, light) in chunk.iter().enumerate() {
                    if mask & (1 << i) == 0 {
                        near += self.eval(
                            &(),
                            surface,
                            light.position.as_dvec3(),
                            light.intensity.as_dvec3(),
                        );
                    }
                }
            }
        }
        let lanes = |v: __m256d| {
            let mut out = [0.0; 4];
            for (i, out) in out.iter_mut().enumerate() {
                *out = crate::dispatch::lane_of(v, i);
            }
            out
        };
        let mut sums = [lanes(r), lanes(g), lanes(b)];
        self.add_to_lanes(surface, &terms, rest, &mut sums, &mut near);
        terms.total(self.kd, sums, near)
    }

    /// Up to [`GROUP`] nodes side by side: on `x86_64` processors with
    /// AVX2, in a copy compiled for AVX2 (the same bits, see
    /// [`dispatch`](crate::dispatch)). Out of line, so that the bound is
    /// compiled once, not into every copy of the cut.
    // Calling the AVX2 copy is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    #[inline(never)]
    fn bound_group(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::dispatch::avx2() {
                // SAFETY: the processor has AVX2 (`dispatch::avx2` checked).
                unsafe { self.bound_group_avx2(surface, nodes, cones, out) };
                return;
            }
        }
        self.bound_group_inlined(surface, nodes, cones, out);
    }

    /// [`bound_group`](Self::bound_group) compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn bound_group_avx2(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        self.bound_group_inlined(surface, nodes, cones, out);
    }

    /// One lane for one node, four (one AVX2 vector) for up to four
    /// nodes, eight for more.
    #[inline(always)]
    fn bound_group_inlined(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        if let ([node], [cone], [out]) = (nodes, cones, &mut *out) {
            let [estimate] = self.bound_lanes(surface, &[node], &[cone]);
            *out = estimate;
        } else if nodes.len() <= 4 {
            self.bound_padded::<4>(surface, nodes, cones, out);
        } else {
            self.bound_padded::<GROUP>(surface, nodes, cones, out);
        }
    }

    /// `N` lanes for at most `N` nodes; unused lanes repeat the last node
    /// and their results are dropped.
    #[inline(always)]
    fn bound_padded<const N: usize>(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        let count = nodes.len().min(cones.len());
        let last = count.max(1) - 1;
        let node_lanes: [&Node; N] = array(nodes[0], |i| nodes[i.min(last)]);
        let cone_lanes: [&Cone; N] = array(&cones[0], |i| &cones[i.min(last)]);
        let estimates = self.bound_lanes(surface, &node_lanes, &cone_lanes);
        for (out, estimate) in out.iter_mut().zip(estimates).take(count) {
            *out = estimate;
        }
    }
}

impl Lambert {
    /// What the group kernel reads of the children besides their block:
    /// `I_k kd_k` and the build's rounding bound of their moments; lanes
    /// past the children repeat the last child, as the block does.
    #[inline(always)]
    fn scales<const N: usize>(&self, children: &[Node]) -> group::LaneScales<N> {
        let last = children.len().max(1) - 1;
        let mut scales = group::LaneScales {
            intensity: [[0.0; N]; 3],
            moment_error: [0.0; N],
        };
        for i in 0..N {
            let Some(child) = children.get(i.min(last)) else {
                break;
            };
            let scale = child.intensity * self.kd;
            for k in 0..3 {
                scales.intensity[k][i] = scale[k];
            }
            scales.moment_error[i] = child.moment_error();
        }
        scales
    }

    /// The wanted children's results from their lanes (see
    /// [`Shader::bound_children_coarse`]).
    #[inline(always)]
    fn fill_children<const N: usize>(
        &self,
        surface: &Surface,
        children: &[Node],
        wanted: u8,
        lanes: &group::LaneBounds<N>,
        out: &mut [Option<NodeEstimate>],
    ) {
        for (i, (child, out)) in children.iter().zip(out.iter_mut()).enumerate() {
            if wanted & (1 << i) == 0 {
                continue;
            }
            *out = match lanes.state(i) {
                group::Lane::Fallback => child
                    .cone(surface.point)
                    .map(|cone| self.bound(&(), surface, child, &cone)),
                group::Lane::Dark => Some(NodeEstimate::ZERO),
                group::Lane::Reaching
                    if child
                        .aabb
                        .lies_at_or_below(surface.point, surface.given_normal) =>
                {
                    Some(NodeEstimate::ZERO)
                }
                group::Lane::Reaching | group::Lane::Bounded => {
                    let lane = |v: &[[f64; N]; 3]| DVec3::new(v[0][i], v[1][i], v[2][i]);
                    Some(NodeEstimate {
                        estimate: lane(&lanes.estimate),
                        lower: lane(&lanes.lower),
                        upper: lane(&lanes.upper),
                    })
                }
            };
        }
    }
}

/// A block's bounds ([`group::lane_bounds`]): on `x86_64` processors with
/// AVX2, in a copy compiled for AVX2 (the same bits, see
/// [`dispatch`](crate::dispatch)). Out of line, compiled once per block
/// width.
// Calling the AVX2 copy is one of the crate's unsafe blocks (see
// `dispatch`).
#[allow(unsafe_code)]
#[inline(never)]
fn group_bounds<const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    at: &group::PointView<f32>,
    scales: &group::LaneScales<N>,
) -> group::LaneBounds<N> {
    #[cfg(target_arch = "x86_64")]
    {
        if crate::dispatch::avx2() {
            // SAFETY: the processor has AVX2 (`dispatch::avx2` checked).
            return unsafe { group_bounds_avx2(block, at, scales) };
        }
    }
    group::lane_bounds(block, at, scales)
}

/// [`group::lane_bounds`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn group_bounds_avx2<const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    at: &group::PointView<f32>,
    scales: &group::LaneScales<N>,
) -> group::LaneBounds<N> {
    group::lane_bounds(block, at, scales)
}

/// What [`Lambert`]'s sum of lights needs of the shading point, and one
/// light's weight, shared by both copies of the sum.
struct LightTerms {
    normal: DVec3,
    point: DVec3,
    /// `|N|^2`.
    n2: f64,
}

impl LightTerms {
    #[inline(always)]
    fn new(surface: &Surface) -> Self {
        let normal = surface.given_normal.as_dvec3();
        Self {
            normal,
            point: surface.point,
            n2: normal.length_squared(),
        }
    }

    /// A light's `ratio` (0 unless its height is accepted and positive)
    /// and whether its height is accepted: the operations of one lane of
    /// the AVX2 copy.
    #[inline(always)]
    fn weight(&self, position: Vec3) -> (f64, bool) {
        let (n, p) = (self.normal, self.point);
        let d = position.as_dvec3() - p;
        let (tx, ty, tz) = (n.x * d.x, n.y * d.y, n.z * d.z);
        let h = (tx + ty) + tz;
        let magnitude = (tx.abs() + ty.abs()) + tz.abs();
        let d2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
        let ratio = h / (d2 * (self.n2 * d2).sqrt());
        let accepted = h.abs() >= NAIVE_DOT_ACCEPT * magnitude;
        (if accepted && h > 0.0 { ratio } else { 0.0 }, accepted)
    }

    /// `kd` times the lanes' sums, added as `(l0 + l1) + (l2 + l3)`, plus
    /// the lights summed apart.
    #[inline(always)]
    fn total(&self, kd: DVec3, sums: [[f64; 4]; 3], near: DVec3) -> DVec3 {
        let [r, g, b] = sums.map(|s| (s[0] + s[1]) + (s[2] + s[3]));
        kd * DVec3::new(r, g, b) + near
    }
}

/// What every bound kind computes for `N` nodes seen from one point, one
/// lane each (see [`Lambert`]'s docs).
struct Prefix<const N: usize> {
    /// Unit axes `uh`.
    axis: Vec3Lanes<N>,
    /// `1 / D`.
    inv_d: Lanes<N>,
    /// `sigma = R / D`.
    sd: Lanes<N>,
    /// `c0 = n . uh`.
    z: Lanes<N>,
    /// `|n x uh|`.
    sin_c: Lanes<N>,
    /// The paper's upper cosine bound.
    cos_hi: Lanes<N>,
    /// `D / (D - R)`.
    inv_rho: Lanes<N>,
    /// The box, relative to nothing (its `f32` corners in `f64`).
    box_min: Vec3Lanes<N>,
    box_max: Vec3Lanes<N>,
    /// Lowest and highest `n . (x - p)` over the box, widened outward by
    /// the rounding of the box's support function (a few ulps of the
    /// coordinates' magnitude).
    lowest: Lanes<N>,
    highest: Lanes<N>,
    /// Bound on `sum (f - g) / I` in units of `1/D^2`.
    straddle: Lanes<N>,
    /// `I kd / D^2`.
    scale: Rgb<N>,
    /// The paper's interval and the virtual light.
    virtual_light: Rgb<N>,
    lower: Rgb<N>,
    upper: Rgb<N>,
    /// `I kd z_hi / (D - R)^3`.
    box_upper: Rgb<N>,
}

impl<const N: usize> Prefix<N> {
    #[inline(always)]
    fn new(kd: DVec3, surface: &Surface, nodes: &[&Node; N], cones: &[&Cone; N]) -> Self {
        let n = surface.normal;
        let axis = Vec3Lanes::from_fn(|i| cones[i].axis.to_array());
        let inv_d = Lanes::from_fn(|i| cones[i].inv_distance);
        let sd = Lanes::from_fn(|i| cones[i].sin_half_angle);
        let cd = Lanes::from_fn(|i| cones[i].cos_half_angle);
        // cos and sin of the angle between the normal and the axis, and the
        // range of the cosine over the ball (Cone::cos_range_from).
        let z = axis.dot_with(n.to_array());
        let cross = Vec3Lanes {
            x: n.y * axis.z - axis.y * n.z,
            y: n.z * axis.x - axis.z * n.x,
            z: n.x * axis.y - axis.x * n.y,
        };
        let sin_c = cross.dot(cross).sqrt();
        let hi = Lanes::select_ge(z, cd, Lanes::splat(1.0), z * cd + sin_c * sd);
        let lo = z * cd - sin_c * sd;
        let cos_lo = (lo - COS_SLACK).max(Lanes::splat(-1.0));
        let cos_hi = (hi + COS_SLACK).min(Lanes::splat(1.0));
        let zero = Lanes::splat(0.0);

        let inv_d2 = inv_d * inv_d;
        let scale: Rgb<N> = rgb(|k| Lanes::from_fn(|i| nodes[i].intensity[k]) * kd[k] * inv_d2);
        // D / (D - R): the nearest member's distance in units of D, inverted.
        let inv_rho = (1.0 - sd).recip();
        let far = (1.0 + sd).recip();
        let (far_falloff, z_plus) = (far * far, z.max(zero));
        let lower_cos = cos_lo.max(zero) * far_falloff;
        let upper_cos = cos_hi * inv_rho * inv_rho;

        // Heights of the box above the tangent plane (Aabb::extent_along).
        let box_min = Vec3Lanes::from_fn(|i| nodes[i].aabb.min.as_dvec3().to_array());
        let box_max = Vec3Lanes::from_fn(|i| nodes[i].aabb.max.as_dvec3().to_array());
        let p = surface.point;
        let (centre, half) = Vec3Lanes::centre_and_half(box_min, box_max);
        let from_point = centre.minus(p.to_array());
        let middle = from_point.dot_with(n.to_array());
        let reach = half.dot_with(n.abs().to_array());
        let largest = |v: Vec3Lanes<N>| v.x.max(v.y.max(v.z));
        let magnitude = largest(centre.abs()) + largest(half) + p.abs().max_element();
        let slack = SECOND_ORDER_SLACK * magnitude;
        let lowest = middle - reach - slack;
        let highest = middle + reach + slack;

        let inv_rho3 = inv_rho * inv_rho * inv_rho;
        // A second upper bound on cos/d^2 = z/d^3 over the members:
        // (highest z in the box) / (D - R)^3, much tighter than the paper's
        // for flat clusters barely above the plane.
        let box_cos = highest * inv_d * inv_rho3;
        // f = max(0, g) exceeds g only below the tangent plane, where
        // 0 <= f - g = -z/r^3 <= depth / (D - R)^3, depth being how far the
        // members reach below the plane: at most R - n.(c - p) (the ball) and
        // at most the box's depth. Zero when the box lies above the plane,
        // and continuous as a node crosses it. In units of 1/D^2.
        let depth = (sd - z).min(-lowest * inv_d).max(zero);
        Self {
            axis,
            inv_d,
            sd,
            z,
            sin_c,
            cos_hi,
            inv_rho,
            box_min,
            box_max,
            lowest,
            highest,
            straddle: depth * inv_rho3,
            scale,
            virtual_light: rgb(|k| scale[k] * z_plus),
            lower: rgb(|k| scale[k] * lower_cos),
            upper: rgb(|k| scale[k] * upper_cos),
            box_upper: rgb(|k| scale[k] * box_cos),
        }
    }
}

/// Lane `i` of a per-channel value.
#[inline(always)]
fn lane<const N: usize>(v: &Rgb<N>, i: usize) -> DVec3 {
    DVec3::new(v[0].0[i], v[1].0[i], v[2].0[i])
}

impl Lambert {
    /// The node bound of [`Lambert`]'s docs for `N` nodes, one lane each:
    /// the geometry and the series side by side, then each node's
    /// intersection of intervals and its rare cases (a ball or box below the
    /// tangent plane, the exact test for a box reaching it).
    #[inline(always)]
    fn bound_lanes<const N: usize>(
        &self,
        surface: &Surface,
        nodes: &[&Node; N],
        cones: &[&Cone; N],
    ) -> [NodeEstimate; N] {
        let g = Prefix::new(self.kd, surface, nodes, cones);
        let series = if self.kind == BoundKind::Series {
            Some(series_lanes(&g, surface, nodes, cones))
        } else {
            None
        };
        array(NodeEstimate::ZERO, |i| {
            if g.cos_hi.0[i] <= 0.0 {
                // The whole ball lies below the tangent plane.
                return NodeEstimate::ZERO;
            }
            let (virtual_light, lower) = (lane(&g.virtual_light, i), lane(&g.lower, i));
            let upper = lane(&g.upper, i);
            if self.kind == BoundKind::Paper {
                return NodeEstimate::new(virtual_light, lower, upper);
            }
            let (lowest, highest) = (g.lowest.0[i], g.highest.0[i]);
            // Whether the box lies at or below the plane is decided exactly,
            // with no slack, so that a box lying exactly in the plane is
            // recognised as contributing 0; only a box reaching below the
            // plane (lowest <= 0, a necessary condition) needs the test.
            if highest <= 0.0
                || (lowest <= 0.0
                    && highest > 0.0
                    && nodes[i]
                        .aabb
                        .lies_at_or_below(surface.point, surface.given_normal))
            {
                return NodeEstimate::ZERO;
            }
            let upper = upper.min(lane(&g.box_upper, i));
            let (lo2, hi2, estimate) = match &series {
                Some((lo2, hi2)) => (lane(lo2, i), lane(hi2, i), None),
                None => self.taylor(&Geometry {
                    surface,
                    node: nodes[i],
                    cone: cones[i],
                    scale: lane(&g.scale, i),
                    z: g.z.0[i],
                    sin_c: g.sin_c.0[i],
                    inv_rho: g.inv_rho.0[i],
                    straddle: g.straddle.0[i],
                }),
            };
            let lo = lower.max(lo2);
            let hi = upper.min(hi2);
            if lo.cmpgt(hi).any() {
                // Both intervals contain the exact value, so they overlap up
                // to rounding; keep the paper's interval if they do not.
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
        })
    }
}

/// The multipole series interval `(lower, upper)` of the smooth sum for each
/// lane, widened upward by the clamp term; the estimate is the final
/// interval's midpoint.
#[inline(always)]
fn series_lanes<const N: usize>(
    g: &Prefix<N>,
    surface: &Surface,
    nodes: &[&Node; N],
    cones: &[&Cone; N],
) -> (Rgb<N>, Rgb<N>) {
    let n = surface.normal;
    let (uh, c0, inv_d) = (g.axis, g.z, g.inv_d);
    let series = degree_two_lanes(n, uh, inv_d, nodes);
    // Remainder in units of I_k / D^2. The quantities it grows with,
    // widened for their input rounding (see SERIES_SLACK).
    let ac = c0.abs() + SERIES_SLACK;
    let nu = g.sin_c + SERIES_SLACK;
    // hperp / D: the box's reach across the axis, from the box corners
    // relative to c (each difference one rounding of a value <= R).
    let nperp = Vec3Lanes::scaled_from(n.to_array(), c0, uh);
    let c = Vec3Lanes::from_fn(|i| nodes[i].centroid.as_dvec3().to_array());
    let (middle, half) = Vec3Lanes::centre_and_half(g.box_min - c, g.box_max - c);
    let reach = nperp.dot(middle).abs() + nperp.abs().dot(half);
    let radius = Lanes::from_fn(|i| cones[i].radius);
    let hperp = (reach + SERIES_SLACK * radius) * inv_d;
    let width = series_width(
        nodes,
        &WidthInput {
            inv_d,
            sigma: g.sd,
            inv_rho: g.inv_rho,
            ac,
            nu2: nu * nu,
            hperp,
        },
    );
    let lo2 = rgb(|k| g.scale[k] * (series[k] - width[k]));
    let hi2 = rgb(|k| g.scale[k] * (series[k] + width[k] + g.straddle));
    (lo2, hi2)
}

/// What the Taylor bound reads of the shared geometry, for one node.
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
}

impl ViewIndependent for Lambert {}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};

    use super::{BoundKind, Lambert};
    use crate::dispatch::baseline;
    use crate::shader::{Cone, Node, NodeEstimate, Seal, Shader, Surface};
    use crate::{Combined, LightTree, Phong, PointLight};

    fn bits(e: &NodeEstimate) -> [u64; 9] {
        let mut out = [0; 9];
        let values = [e.estimate, e.lower, e.upper].map(|v| v.to_array());
        for (out, v) in out.iter_mut().zip(values.iter().flatten()) {
            *out = v.to_bits();
        }
        out
    }

    /// Every node's children bounded together ([`Shader::bound_nodes`], up
    /// to eight side by side, in both compiled copies) give exactly the bits
    /// of bounding each alone ([`Shader::bound`]), for every bound kind and
    /// a sum of shaders, from points above, below and among the lights; and
    /// lights evaluated together ([`Shader::eval_lights`]) the bits of each
    /// alone, lights in and next to the tangent plane included.
    fn check<S: Shader>(shader: &S, tree: &LightTree, surface: &Surface) -> usize {
        let point = shader.prepare(surface);
        let mut compared = 0;
        for parent in tree.nodes() {
            let (nodes, cones): (Vec<&Node>, Vec<Cone>) = tree.nodes()[parent.children()]
                .iter()
                .filter_map(|c| Some((c, c.cone(surface.point)?)))
                .unzip();
            let single: Vec<NodeEstimate> = nodes
                .iter()
                .zip(&cones)
                .map(|(n, c)| shader.bound(&point, surface, n, c))
                .collect();
            for copy in [false, true] {
                let mut together = vec![NodeEstimate::ZERO; nodes.len()];
                let run = |out: &mut [NodeEstimate]| {
                    shader.bound_nodes(&point, surface, &nodes, &cones, out);
                };
                if copy {
                    baseline(|| run(&mut together));
                } else {
                    run(&mut together);
                }
                for (a, b) in single.iter().zip(&together) {
                    assert_eq!(bits(a), bits(b), "{a:?} against {b:?}");
                }
            }
            compared += nodes.len();
        }
        // Lights, with some in the tangent plane and just off it.
        let mut lights = tree.lights().to_vec();
        for (k, light) in lights.iter_mut().enumerate().step_by(7) {
            let n = surface.given_normal;
            let offset = [0.0, 1e-7, -1e-7][k % 3];
            light.position =
                surface.point.as_vec3() + n.any_orthonormal_vector() * 3.0 + n * offset;
        }
        let single: Vec<[u64; 3]> = lights
            .iter()
            .map(|l| {
                let v = shader.eval(
                    &point,
                    surface,
                    l.position.as_dvec3(),
                    l.intensity.as_dvec3(),
                );
                v.to_array().map(f64::to_bits)
            })
            .collect();
        for copy in [false, true] {
            let mut together = vec![DVec3::ZERO; lights.len()];
            let run = |out: &mut [DVec3]| shader.eval_lights(&point, surface, &lights, out);
            if copy {
                baseline(|| run(&mut together));
            } else {
                run(&mut together);
            }
            for (a, b) in single.iter().zip(&together) {
                assert_eq!(*a, b.to_array().map(f64::to_bits), "{b}");
            }
        }
        compared
    }

    #[test]
    fn nodes_bounded_together_give_the_bits_of_each_alone() {
        let mut state = 3u64;
        let mut u = || crate::testing::uniform(&mut state);
        let lights: Vec<PointLight> = (0..12000)
            .map(|_| {
                let p = Vec3::new(u() * 40.0 - 20.0, u() * 40.0 - 20.0, u() * 6.0);
                PointLight::new(p, Vec3::new(u(), u() * 3.0, u() * 0.1))
            })
            .collect();
        let tree = LightTree::build(&lights).unwrap();
        let mut compared = 0;
        for (point, normal) in [
            (Vec3::new(1.0, 2.0, 0.0), Vec3::Z),
            (Vec3::new(-5.0, 3.0, 3.0), Vec3::new(0.3, -0.2, 1.0)),
            (Vec3::new(25.0, 0.0, 2.0), Vec3::new(-1.0, 0.0, 0.001)),
            (Vec3::new(0.0, 0.0, 10.0), Vec3::NEG_Z),
        ] {
            let view = Vec3::new(0.2, -0.4, 1.0);
            let surface = Surface::new(point, normal, Some(view)).unwrap();
            for kind in [BoundKind::Series, BoundKind::Taylor, BoundKind::Paper] {
                let lambert = Lambert::new(Vec3::new(0.8, 0.5, 0.3)).with_bound(kind);
                compared += check(&lambert, &tree, &surface);
            }
            let glossy = Combined::new(
                Lambert::new(Vec3::splat(0.4)),
                Phong::new(Vec3::splat(0.3), 30.0),
            );
            compared += check(&glossy, &tree, &surface);
        }
        assert!(compared > 10_000, "{compared} nodes compared");
    }

    /// Slices of different lengths: entries past the shortest are ignored
    /// and their outputs left alone, with no panic.
    #[test]
    fn mismatched_slices_leave_the_extra_outputs_alone() {
        let lights: Vec<PointLight> = (0..200)
            .map(|i| PointLight::new(Vec3::new(i as f32, (i % 7) as f32, 3.0), Vec3::ONE))
            .collect();
        let tree = LightTree::build(&lights).unwrap();
        let surface = Surface::new(Vec3::new(-5.0, 0.0, 0.0), Vec3::Z, None).unwrap();
        let nodes: Vec<&Node> = tree.nodes().iter().take(6).collect();
        let cones: Vec<Cone> = nodes
            .iter()
            .map(|n| n.cone(surface.point).unwrap())
            .collect();
        let lambert = Lambert::new(Vec3::ONE);
        let mark = NodeEstimate::new(DVec3::splat(-1.0), DVec3::splat(-1.0), DVec3::splat(-1.0));
        for (n, c) in [(6, 2), (2, 6), (6, 5), (1, 0), (0, 1)] {
            let mut out = [mark; 6];
            lambert.bound_nodes(&(), &surface, &nodes[..n], &cones[..c], &mut out);
            for (i, out) in out.iter().enumerate() {
                if i < n.min(c) {
                    assert_eq!(*out, lambert.bound(&(), &surface, nodes[i], &cones[i]));
                } else {
                    assert_eq!(*out, mark, "entry {i} of {n} nodes and {c} cones");
                }
            }
        }
        let mut out = [DVec3::splat(-1.0); 5];
        lambert.eval_lights(&(), &surface, &lights[..3], &mut out);
        assert_eq!(out[3], DVec3::splat(-1.0));
        assert!(out[..3].iter().all(|v| v.min_element() >= 0.0));
    }

    /// `sum_lights` against the compensated sum of `eval` over the same
    /// lights, for every count from 0 to 16 (full and short chunks of
    /// four): lights above, below and exactly in the tangent plane, lights
    /// within a hair of it (whose heights go through `eval`), on the point
    /// itself, with a tilted normal of any length; the AVX2 copy and the
    /// baseline give the same bits.
    #[test]
    fn summed_lights_match_the_sum_of_their_terms() {
        let mut state = 11u64;
        let mut uniform = move || crate::testing::uniform(&mut state);
        let lambert = Lambert::new(Vec3::new(0.9, 0.5, 0.25));
        let mut checked = 0;
        for round in 0..400 {
            let p = Vec3::new(uniform() * 8.0, uniform() * 8.0, uniform() * 2.0);
            let normal = Vec3::new(uniform() - 0.5, uniform() - 0.5, 1.0) * (0.1 + 3.0 * uniform());
            let surface = Surface::new(p, normal, None).unwrap();
            let count = round % 17;
            let lights: Vec<PointLight> = (0..count)
                .map(|i| {
                    let offset =
                        Vec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5) * 20.0;
                    let position = match (round + i) % 6 {
                        // On the point itself.
                        0 => p,
                        // In the tangent plane, or a hair above or below it
                        // (rounded to f32, so near, not in, the plane).
                        1 | 2 => {
                            let n = normal.normalize();
                            let flat = offset - n * offset.dot(n);
                            p + flat + n * (i as f32 - 1.0) * 1e-6
                        }
                        _ => p + offset,
                    };
                    PointLight::new(
                        position,
                        Vec3::new(uniform(), uniform() * 4.0, uniform() * 0.1),
                    )
                })
                .collect();
            let mut exact = crate::numeric::CompensatedSum::default();
            for light in &lights {
                exact.add(lambert.eval(
                    &(),
                    &surface,
                    light.position.as_dvec3(),
                    light.intensity.as_dvec3(),
                ));
            }
            let exact = exact.value();
            let sum = lambert.sum_lights(Seal, &(), &surface, &lights);
            let baseline = baseline(|| lambert.sum_lights(Seal, &(), &surface, &lights));
            assert_eq!(
                sum.to_array().map(f64::to_bits),
                baseline.to_array().map(f64::to_bits)
            );
            for k in 0..3 {
                assert!(sum[k] >= 0.0, "round {round}: {sum}");
                assert!(
                    (sum[k] - exact[k]).abs() <= 32.0 * f64::EPSILON * exact[k],
                    "round {round}, {count} lights: {sum} against {exact}"
                );
            }
            checked += usize::from(exact.max_element() > 0.0);
        }
        assert!(checked > 300, "only {checked} sums were positive");
    }
}
