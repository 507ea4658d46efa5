//! Microfacet reflection (Cook-Torrance with the GGX distribution) with a
//! certified node bound.
//!
//! The model and its bound are stated on [`Ggx`]; this module's text
//! proves the bound, inequality by inequality, and derives its rounding.
//!
//! # The per-light factor
//!
//! A light's term is `I f (n.l) / d^2` with the BRDF
//! `f = D(h) G2(l, v) F(v.h) / (4 (n.l)(n.v))`. Write `a = n.l`,
//! `b = n.v`, `k = 1 - alpha^2` (in `[0, 1)`), and
//! `m(c) = sqrt(alpha^2 + k c^2)`. Since `c sqrt(1 + alpha^2 tan^2
//! theta) = m(c)` for `c = cos theta > 0`, the height-correlated Smith
//! term gives
//!
//! ```text
//! G2 / (4 a b) = 1 / (4 a b (1 + Lambda(l) + Lambda(v)))
//!              = 1 / (2 (b m(a) + a m(b)))  =: Vis(a)          (P1)
//! ```
//!
//! (Heitz 2014, eq. 99; the form every real-time renderer uses).
//! `Vis` is *decreasing* in `a` on `[0, 1]`: `b m(a) + a m(b)` is a sum of
//! two non-decreasing functions of `a` (`m` is non-decreasing for `k >=
//! 0`), the second strictly increasing. At `a = 0` it is finite,
//! `Vis(0) = 1 / (2 alpha b)`: the model has no singularity at a grazing
//! light, and the factor `a` of the term, `(n.l)`, stays outside `f`.
//!
//! With `s = sin theta_h = |n x h|`, `(n.h)^2 (alpha^2 - 1) + 1 = alpha^2 +
//! k s^2`, so
//!
//! ```text
//! D = alpha^2 / (pi (alpha^2 + k s^2)^2)                         (P2)
//! ```
//!
//! is *decreasing* in `s` on `[0, 1]` (constant for `alpha = 1`). It
//! depends on `s^2` only, and reaches `1 / (pi alpha^2)` at `s = 0`.
//!
//! Schlick's `F(c) = F0 + (1 - F0)(1 - c)^5` is *decreasing* in `c = v.h`
//! on `[0, 1]` for `F0 <= 1` (the reason for the domain of `F0`).
//!
//! So for every light above the tangent plane (`a > 0`), with `n.v > 0`:
//!
//! ```text
//! f = D(s) Vis(a) F(v.h),  each factor positive and monotone.    (P3)
//! ```
//!
//! # The node bound: a product of intervals
//!
//! A node's exact value is `sum_i f_i q_i`, with `q_i = I_i max(0,
//! n.l_i) / d_i^2 >= 0` [`Lambert`]'s term for albedo 1 and `f_i` the
//! BRDF of light `i` (only lights with `q_i > 0` matter). If every such
//! light has `s`, `a` and `v.h` in intervals `[s_lo, s_hi]`, `[a_lo,
//! a_hi]`, `[c_lo, c_hi]`, then by (P3)
//!
//! ```text
//! f_lo = D(s_hi) Vis(a_hi) F(c_hi)  <=  f_i  <=  D(s_lo) Vis(a_lo) F(c_lo) = f_hi
//! ```
//!
//! and with `[Q_lo, Q_hi]` Lambert's certified interval of `sum_i q_i`
//! (its default series bound, see [`Lambert`]), since every `q_i >= 0`,
//!
//! ```text
//! f_lo Q_lo  <=  sum_i f_i q_i  <=  f_hi Q_hi.                    (P4)
//! ```
//!
//! Per channel `k`, only `F` depends on it (`F0_k`). The intervals:
//!
//! * **`a = n.l`**: Phong's cone interval of the cosine to `n`
//!   ([`Cone::cos_range`]), intersected with the box's: with `z_lo`,
//!   `z_hi` the lowest and highest `n.(x - p)` over the node's box and
//!   `d_near`, `d_far` the nearest and farthest member distance (box and
//!   ball), `a <= z_hi / d_near` and, if `z_lo > 0`, `a >= z_lo / d_far`;
//!   never below 0 (only lights above the plane count).
//! * **`c = v.h`**: `|l + v|^2 = 2 (1 + v.l)` and `h = (l + v) / |l + v|`
//!   give `v.h = |l + v| / 2 = sqrt((1 + v.l) / 2)`, increasing in `v.l`,
//!   whose range is the cone's cosine interval to `v`: `v.l >=
//!   cos(theta_v + delta)` while `theta_v + delta <= pi` (`theta_v` the
//!   angle between `v` and the axis), and `v.l >= -1` otherwise, where the
//!   cone holds `-v` (its sine, `sin theta_v cos delta + cos theta_v sin
//!   delta`, is then negative: the sum-of-angles value has wrapped past
//!   `pi`). Also `|l + v| >= n.(l + v) = a + b`, so `c >= (a_lo + b) / 2`.
//! * **`s = sin theta_h`**, from two facts, intersected:
//!   1. *The half-vector cone.* Every member direction `l` is within the
//!      cone's half-angle `delta` of its axis `l_c` (`sin delta = R/D`), so
//!      `|l - l_c| <= eps = 2 sin(delta / 2)`. With `H_c = l_c + v`,
//!      `H = l + v = H_c + (l - l_c)`: if `|H_c| > eps`, the angle between
//!      `H` and `H_c` is at most `delta_h`, `sin delta_h = eps / |H_c|`
//!      (a vector within `eps` of `H_c` lies in that cone about it). With
//!      `theta_c` the angle between `n` and `H_c`, the angle `theta_h`
//!      between `n` and `h` lies in `[theta_c - delta_h, theta_c +
//!      delta_h]`, so `s >= sin(theta_c - delta_h)` when `theta_c >
//!      delta_h` (0 otherwise) and `s <= sin(theta_c + delta_h)` while
//!      `theta_c + delta_h < pi/2` (1 otherwise), both by sum-of-angles
//!      formulas from `sin`, `cos` of `theta_c` (a cross and a dot
//!      product) and `delta_h`, never `acos`. Lit lights have `n.h > 0`
//!      (`n.(l + v) = a + b > 0`), so `theta_h < pi/2`: where
//!      `theta_c - delta_h >= pi/2` no light of the node is lit, and `s_lo
//!      = 1` is vacuous. The cone narrows as `alpha` does not: it is
//!      geometry alone, and a node far off the lobe gets `s_lo` well above
//!      `alpha`, so `D(s_lo)` is tiny and the node settles at once.
//!   2. *The ratio.* `n.h = n.(l + v) / |l + v| = (a + b) / (2 v.h)`, so
//!      `n.h` lies in `[(a_lo + b) / (2 c_hi), (a_hi + b) / (2 c_lo)]`,
//!      and `s = sqrt((1 - n.h)(1 + n.h))` in the matching interval
//!      (reversed). This one holds where the cone says nothing (`l` near
//!      `-v`).
//!
//! The estimate is the final interval's midpoint, which minimises the
//! certified error `max(estimate - lower, upper - estimate)`, as
//! [`Lambert`]'s series bound does.
//!
//! # Rounding
//!
//! `D`, `Vis` and `F` are sums and products of non-negative terms: at
//! given arguments each is within a few ulps relative, in the bound and in
//! [`eval`](crate::shader::Shader::eval) alike, and both ends of `f` move
//! outward by [`PRODUCT_SLACK`]. What can cancel is the arguments:
//!
//! * each interval of a *true* quantity is rounded outward (the cone's
//!   cosines by [`COS_SLACK`](crate::numeric::COS_SLACK) plus
//!   [`DIRECTION_SLACK`] for the unit normal and view themselves, the box
//!   heights and distances by their own slacks, quotients and square roots
//!   by a few ulps);
//! * then each is widened once more to hold the *computed* quantity `eval`
//!   uses for a light: `n.l` is the exactly signed height over the
//!   distance, within `2^-40` relative plus a few ulps ([`Lambert`]'s
//!   `eval`), so `a` moves by [`HEIGHT_RELATIVE_SLACK`] relative and
//!   [`DIRECTION_SLACK`] absolute; `v.h = |l + v| / 2` is within a few
//!   ulps absolute (`l` and `v` unit vectors each within a few ulps);
//!   `s = |n x (l + v)| / |l + v|` is within about `30 u / |l + v|`
//!   absolute (`u = 2^-53`): `l + v` is within `20 u` of its true value
//!   (absolute, componentwise sums of unit vectors), which tilts it by
//!   `20 u / |l + v|`, and the cross product and quotient add a few ulps
//!   of `|n| |l + v|` over `|l + v|`. The bound's own `H_c`, `theta_c` and
//!   `delta_h` carry the same errors. So both ends of `s` move by
//!   [`DIRECTION_SLACK`]` (1 + 1 / H_min)`, `H_min` a lower bound on
//!   `|l + v|` over the node (the larger of `|H_c| - eps`, `2 c_lo` and
//!   `a_lo + b`; never below `b > 0`).
//!
//! A light on the half vector of a grazing view (`|l + v| = 2 n.v`, tiny)
//! is thus within about `30 u / n.v` of its exact angle, and `D` moves by
//! at most `2 / alpha` times that, relatively (`d ln D / d theta_h =
//! -4 k s cos / (alpha^2 + k s^2) >= -2 / alpha`): `6e-8` at `n.v = 1e-6`,
//! `alpha = 1e-3`, in the worst light; where `s` is 0 the slope is 0. The
//! reference ([`Shading::exact_query`](crate::Shading::exact_query)) sums
//! `eval` itself, so the contract holds regardless; the figure says how
//! far `eval` can be from the real-number model there. Away from grazing
//! views `eval` is within about `1e-12` relative of the model.

use glam::{DVec3, Vec3};

use crate::ShadeError;
use crate::geometry::{Cone, Surface};
use crate::lambert::Lambert;
use crate::numeric::{DISTANCE_SLACK, ExactSum, SECOND_ORDER_SLACK, dot_of_difference};
use crate::shader::{NodeEstimate, Shader};
use crate::tree::Node;

/// `u = 2^-53`, the unit roundoff of `f64`.
const U: f64 = f64::EPSILON / 2.0;

/// Absolute allowance on a unit direction or a cosine/sine computed from
/// unit vectors in `f64`: each unit vector (`n`, `v`, a light's `l`, the
/// cone's axis) is within about `4 u` per component of the exact one, a
/// dot or cross product of two adds about `4 u`, a sum-of-angles formula
/// two products more; `64 u` (about `7e-15`) covers these with a factor
/// of two. Used where an absolute error moves a bound.
const DIRECTION_SLACK: f64 = 64.0 * U;

/// Relative allowance on a light's `n.l` in [`Ggx::eval`](Shader::eval):
/// the height `N.(x - p)` is within `2^-40` relative
/// ([`Lambert`]'s `eval`), `|N|` and `d` add a few ulps; `2^-39` covers
/// both.
const HEIGHT_RELATIVE_SLACK: f64 = 1.0 / (1u64 << 39) as f64;

/// Relative outward rounding of a single quotient, product or square root
/// of quantities already bounded: four ulps.
const OP_SLACK: f64 = 4.0 * f64::EPSILON;

/// Relative widening of the BRDF's ends `f_lo` and `f_hi`: `D`, `Vis` and
/// `F` are each at most a dozen roundings of non-negative terms (within
/// about `12 u` each at given arguments, the same in the bound and in
/// `eval`, so their difference is within twice that), and their product
/// two more: `64 f64::EPSILON` (about `1.4e-14`) covers the sum.
const PRODUCT_SLACK: f64 = 64.0 * f64::EPSILON;

/// Microfacet reflection: Cook-Torrance with the GGX (Trowbridge-Reitz)
/// distribution, the height-correlated Smith masking-shadowing term
/// and Schlick's Fresnel approximation, isotropic.
///
/// With unit `n`, `v` (towards the eye), a light at `x`, `d = |x - p|`,
/// `l = (x - p) / d`, half vector `h = (l + v) / |l + v|`, roughness
/// `alpha` and specular colour `F0` (per channel), a light of intensity
/// `I` contributes
///
/// ```text
/// I f(l, v) (n.l) / d^2,   f = D(h) G2(l, v) F(v.h) / (4 (n.l)(n.v)),
///                          when n.l > 0 and n.v > 0, and 0 otherwise;
/// D(h)      = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2)
/// G2(l, v)  = 1 / (1 + Lambda(l) + Lambda(v)),
///             Lambda(x) = (sqrt(1 + alpha^2 tan^2 theta_x) - 1) / 2
/// F(c)      = F0 + (1 - F0) (1 - c)^5
/// ```
///
/// (Walter et al. 2007 for GGX, Heitz 2014 for the height-correlated
/// `G2`, Schlick 1994). Conventions: a light at `d = 0` or at or below the
/// tangent plane (`N.(x - p) <= 0`, its sign decided exactly as
/// [`Lambert`] does) contributes 0; a view at or below the tangent plane
/// (`N.V <= 0`, decided exactly) makes every term 0 (a host shading
/// two-sided surfaces flips the normal towards the eye first). Nothing is
/// singular: at a grazing light `G2 / (n.l)` tends to `1 / (alpha sin
/// theta_l)`-like finite values (see the module's text, (P1)), and `D` is
/// at most `1 / (pi alpha^2)`. The domain: `alpha` in `[1e-3, 1]`
/// ([`Ggx::MIN_ALPHA`], [`Ggx::MAX_ALPHA`]), each channel of `F0` in `[0,
/// 1]`. [`Lambert`] beside it, through [`Combined`](crate::Combined),
/// gives the usual diffuse-plus-specular material.
///
/// # Node bound
/// For a node whose [`Cone`] exists, per channel `k`,
///
/// ```text
/// f_lo,k Q_lo,k  <=  exact_k  <=  f_hi,k Q_hi,k
/// f_lo,k = D(s_hi) Vis(a_hi) F_k(c_hi),   f_hi,k = D(s_lo) Vis(a_lo) F_k(c_lo)
/// Vis(a) = 1 / (2 ((n.v) sqrt(alpha^2 + (1 - alpha^2) a^2)
///                  + a sqrt(alpha^2 + (1 - alpha^2) (n.v)^2)))  = G2 / (4 (n.l)(n.v))
/// ```
///
/// where `[Q_lo, Q_hi]` is [`Lambert`]'s certified interval (series bound,
/// albedo 1) of the node's `sum I max(0, n.l) / d^2`, and `[a_lo, a_hi]`,
/// `[c_lo, c_hi]`, `[s_lo, s_hi]` bound `n.l`, `v.h` and `sin theta_h =
/// |n x h|` over the node's lit members: `n.l` from the cone and the box,
/// `v.h = sqrt((1 + v.l) / 2)` from the cone, and `sin theta_h` from the
/// cone of half vectors that the node's cone of light directions maps to
/// (half-angle `asin(2 sin(delta/2) / |l_c + v|)` about `l_c + v`),
/// intersected with `n.h = (n.l + n.v) / (2 v.h)`. `D`, `Vis` and `F` are
/// each decreasing in their argument, which is all the bound needs. A
/// node far off the lobe has `s_lo` well above `alpha`: its upper end is
/// tiny and it settles without a walk; the specular criterion
/// ([`Threshold::with_max_contribution`](crate::Threshold::with_max_contribution))
/// refines the nodes whose upper end is large, as for [`Phong`](crate::Phong).
/// The estimate is the interval's midpoint. Every interval is rounded
/// outward and widened to hold what [`eval`](Shader::eval) computes for
/// each light, so the bound holds for the terms the reference sums; the
/// proofs and the rounding analysis are in the crate's source
/// (`src/ggx.rs`).
///
/// # Accuracy of a term
/// Within about `1e-12` relative of the model, except where both the
/// light and the view graze the surface on opposite sides of the normal
/// (`|l + v|` small): the half vector's angle is then within about `30
/// 2^-53 / |l + v|`, which moves `D` by at most `2 / alpha` times that,
/// relatively.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ggx {
    f0: DVec3,
    alpha: f64,
    /// `alpha^2`.
    alpha2: f64,
    /// `1 - alpha^2`, in `[0, 1)`.
    k: f64,
    /// The cosine-and-distance factor, Lambert of albedo 1, whose node
    /// bound is the second factor of the product bound.
    unit: Lambert,
}

impl Ggx {
    /// Smallest supported roughness: `alpha = 1e-3` already makes a lobe
    /// a small fraction of a degree wide (`D` halves at `theta_h` of about
    /// `0.036` degree).
    pub const MIN_ALPHA: f64 = 1e-3;

    /// Largest supported roughness (`D` is then the constant `1 / pi`).
    pub const MAX_ALPHA: f64 = 1.0;

    /// Specular colour `F0` (each channel in `[0, 1]`) and roughness
    /// `alpha` in `[MIN_ALPHA, MAX_ALPHA]`.
    ///
    /// Debug builds assert both; release builds keep results finite by
    /// clamping: NaN channels read as 0, others clamped to `[0, 1]`; a NaN
    /// roughness reads as 1, others are clamped to the range.
    /// [`Ggx::try_new`] returns an error instead.
    #[must_use]
    pub fn new(f0: Vec3, alpha: f32) -> Self {
        debug_assert!(
            f0.cmpge(Vec3::ZERO).all() && f0.cmple(Vec3::ONE).all(),
            "Ggx F0 must lie in [0, 1] per channel, got {f0} (use try_new for an error)"
        );
        let a = f64::from(alpha);
        debug_assert!(
            (Self::MIN_ALPHA..=Self::MAX_ALPHA).contains(&a),
            "Ggx roughness must lie in [1e-3, 1], got {a} (use try_new for an error)"
        );
        let channel = |x: f32| {
            if x.is_nan() {
                0.0
            } else {
                f64::from(x.clamp(0.0, 1.0))
            }
        };
        let alpha = if a.is_nan() {
            Self::MAX_ALPHA
        } else {
            a.clamp(Self::MIN_ALPHA, Self::MAX_ALPHA)
        };
        Self::from_parts(
            DVec3::new(channel(f0.x), channel(f0.y), channel(f0.z)),
            alpha,
        )
    }

    /// Like [`Ggx::new`], but refuses bad parameters.
    ///
    /// # Errors
    /// [`ShadeError::InvalidMaterial`] for a channel of `F0` outside `[0,
    /// 1]` (or NaN), or a roughness outside `[MIN_ALPHA, MAX_ALPHA]` (or
    /// NaN).
    pub fn try_new(f0: Vec3, alpha: f32) -> Result<Self, ShadeError> {
        if !(f0.cmpge(Vec3::ZERO).all() && f0.cmple(Vec3::ONE).all()) {
            return Err(ShadeError::InvalidMaterial(
                "F0 must lie in [0, 1] per channel",
            ));
        }
        let a = f64::from(alpha);
        if !(Self::MIN_ALPHA..=Self::MAX_ALPHA).contains(&a) {
            return Err(ShadeError::InvalidMaterial(
                "roughness must lie in [MIN_ALPHA, MAX_ALPHA]",
            ));
        }
        Ok(Self::from_parts(f0.as_dvec3(), a))
    }

    fn from_parts(f0: DVec3, alpha: f64) -> Self {
        let alpha2 = alpha * alpha;
        Self {
            f0,
            alpha,
            alpha2,
            k: 1.0 - alpha2,
            unit: Lambert::new(Vec3::ONE),
        }
    }

    /// The specular colour `F0`.
    #[must_use]
    pub fn f0(&self) -> DVec3 {
        self.f0
    }

    /// The roughness `alpha`.
    #[must_use]
    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// `D` at `s^2 = sin^2 theta_h` ((P2) in the module's text).
    #[inline(always)]
    fn distribution(&self, s2: f64) -> f64 {
        let t = self.alpha2 + self.k * s2;
        self.alpha2 / (core::f64::consts::PI * (t * t))
    }

    /// `Vis(a) = G2 / (4 (n.l)(n.v))` at `a = n.l` ((P1)).
    #[inline(always)]
    fn visibility(&self, view: &GgxView, a: f64) -> f64 {
        let m_a = (self.alpha2 + self.k * (a * a)).sqrt();
        0.5 / (view.nv * m_a + a * view.m_v)
    }

    /// Schlick's `F` at `c = v.h`, per channel.
    #[inline(always)]
    fn fresnel(&self, c: f64) -> DVec3 {
        let t = (1.0 - c).max(0.0);
        let t2 = t * t;
        self.f0 + (DVec3::ONE - self.f0) * (t2 * t2 * t)
    }

    /// The interval `[f_lo, f_hi]` of the BRDF over a node's lit members,
    /// widened to hold what `eval` computes for each (the module's text).
    #[inline]
    fn brdf_range(
        &self,
        view: &GgxView,
        surface: &Surface,
        node: &Node,
        cone: &Cone,
    ) -> (DVec3, DVec3) {
        let (n, v, b) = (surface.normal, surface.view, view.nv);

        // a = n.l over the node, true values: cone, then box.
        let (cone_lo, cone_hi) = cone.cos_range(n);
        let (z_lo, z_hi) = node.aabb.extent_along(surface.point, n, SECOND_ORDER_SLACK);
        let (box_near, box_far) = node.aabb.distance_range(surface.point);
        let near = (cone.distance - cone.radius).max(0.0) * (1.0 - DISTANCE_SLACK);
        let near = near.max(box_near);
        let far = ((cone.distance + cone.radius) * (1.0 + DISTANCE_SLACK)).min(box_far);
        let mut a_hi = cone_hi + DIRECTION_SLACK;
        if near > 0.0 {
            a_hi = a_hi.min(z_hi.max(0.0) / near * (1.0 + OP_SLACK));
        }
        let mut a_lo = cone_lo - DIRECTION_SLACK;
        if z_lo > 0.0 && far > 0.0 {
            a_lo = a_lo.max(z_lo / far * (1.0 - OP_SLACK));
        }
        let (a_lo, a_hi) = (a_lo.clamp(0.0, 1.0), a_hi.clamp(0.0, 1.0));

        // c = v.h = sqrt((1 + v.l) / 2) >= (a + b) / 2, true values.
        let (vl_lo, vl_hi) = cone.cos_range(v);
        // `cos_range`'s lower end is `cos(theta_c + delta)`, which is not
        // the minimum once `theta_c + delta > pi` (then `sin(theta_c +
        // delta) < 0`): there the cone reaches `-v` and the minimum is -1.
        let (cos_c, sin_c) = (v.dot(cone.axis), v.cross(cone.axis).length());
        let past_pi = sin_c * cone.cos_half_angle + cos_c * cone.sin_half_angle <= DIRECTION_SLACK;
        let vl_lo = if past_pi { -1.0 } else { vl_lo };
        let half_root = |x: f64| (0.5 * (1.0 + x)).max(0.0).sqrt();
        let c_lo = (half_root(vl_lo - DIRECTION_SLACK) * (1.0 - OP_SLACK))
            .max(0.5 * (a_lo + b) * (1.0 - OP_SLACK));
        let c_hi = (half_root(vl_hi + DIRECTION_SLACK) * (1.0 + OP_SLACK))
            .min(1.0)
            .max(c_lo);

        // s = sin theta_h, true values: the ratio n.h = (a + b) / (2 c).
        let sine_of = |cos: f64| {
            let cos = cos.clamp(0.0, 1.0);
            ((1.0 - cos) * (1.0 + cos)).sqrt()
        };
        let nh_lo = (a_lo + b) / (2.0 * c_hi) * (1.0 - OP_SLACK);
        let mut s_hi = sine_of(nh_lo) * (1.0 + OP_SLACK);
        let mut s_lo = if c_lo > 0.0 {
            sine_of((a_hi + b) / (2.0 * c_lo) * (1.0 + OP_SLACK)) * (1.0 - OP_SLACK)
        } else {
            0.0
        };
        // |l + v| = 2 v.h >= n.(l + v) = a + b.
        let mut h_min = (2.0 * c_lo).max(a_lo + b);

        // The half-vector cone.
        let axis_sum = cone.axis + v;
        let h_len = axis_sum.length();
        // |l - l_c| <= 2 sin(delta / 2) = sqrt(2 sin^2 delta / (1 + cos delta)).
        let (sd, cd) = (cone.sin_half_angle, cone.cos_half_angle);
        let eps = (2.0 * sd * sd / (1.0 + cd)).sqrt() * (1.0 + OP_SLACK) + DIRECTION_SLACK;
        // |H_c| is within about 20 u of the computed length.
        let h_c = h_len - DIRECTION_SLACK;
        if h_c > eps {
            h_min = h_min.max(h_c - eps);
            let sin_h = (eps / h_c * (1.0 + OP_SLACK)).min(1.0);
            let cos_h = ((1.0 - sin_h) * (1.0 + sin_h)).sqrt();
            let cos_c = n.dot(axis_sum) / h_len;
            let sin_c = n.cross(axis_sum).length() / h_len;
            let cone_s_lo = if cos_c >= cos_h {
                0.0
            } else if cos_c * cos_h + sin_c * sin_h <= 0.0 {
                1.0
            } else {
                sin_c * cos_h - cos_c * sin_h
            };
            let cone_s_hi = if cos_c * cos_h - sin_c * sin_h <= 0.0 {
                1.0
            } else {
                sin_c * cos_h + cos_c * sin_h
            };
            s_lo = s_lo.max(cone_s_lo);
            s_hi = s_hi.min(cone_s_hi);
        }

        // Widen to the computed quantities of `eval`.
        let slack = DIRECTION_SLACK * (1.0 + 1.0 / h_min);
        let s_lo = (s_lo - slack).clamp(0.0, 1.0);
        let s_hi = (s_hi + slack).clamp(0.0, 1.0);
        let a_lo = (a_lo * (1.0 - HEIGHT_RELATIVE_SLACK) - DIRECTION_SLACK).max(0.0);
        let a_hi = (a_hi * (1.0 + HEIGHT_RELATIVE_SLACK) + DIRECTION_SLACK).min(1.0);
        let c_lo = (c_lo - DIRECTION_SLACK).max(0.0);
        let c_hi = (c_hi + DIRECTION_SLACK).min(1.0);

        if std::env::var("GGX_DEBUG").is_ok() && node.light_count() == 19 {
            eprintln!(
                "RANGE a [{a_lo}, {a_hi}] c [{c_lo}, {c_hi}] s [{s_lo}, {s_hi}] h_min {h_min} nv {b} vl [{vl_lo}, {vl_hi}] cone a [{cone_lo}, {cone_hi}] z [{z_lo}, {z_hi}] near {near} far {far}"
            );
        }
        let f_hi = self.fresnel(c_lo)
            * (self.distribution(s_lo * s_lo) * self.visibility(view, a_lo))
            * (1.0 + PRODUCT_SLACK);
        let f_lo = self.fresnel(c_hi)
            * (self.distribution(s_hi * s_hi) * self.visibility(view, a_hi))
            * (1.0 - PRODUCT_SLACK);
        (f_lo.max(DVec3::ZERO), f_hi)
    }
}

/// [`Ggx`]'s per-point data ([`Shader::PerPoint`]): whether the view is
/// above the tangent plane (decided exactly from the given normal and
/// view) and the view's terms of the BRDF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GgxView {
    /// `N.V > 0`, exactly.
    lit: bool,
    /// `n.v` of the unit vectors, within a few ulps (its numerator summed
    /// exactly), or 0 when not `lit`.
    nv: f64,
    /// `sqrt(alpha^2 + (1 - alpha^2) (n.v)^2)`.
    m_v: f64,
    /// `|N|`, the given normal's length.
    normal_length: f64,
}

impl GgxView {
    /// `n.v`, the cosine of the view to the normal (0 for a view at or
    /// below the tangent plane, where every term is 0).
    #[must_use]
    pub fn cos_view(&self) -> f64 {
        self.nv
    }
}

impl Shader for Ggx {
    /// Whether the view is above the surface, and its cosine.
    type PerPoint = GgxView;

    #[inline]
    fn prepare(&self, surface: &Surface) -> GgxView {
        let (n, v) = (
            surface.given_normal.as_dvec3(),
            surface.given_view.as_dvec3(),
        );
        // Products of two f32 values are exact in f64.
        let mut dot = ExactSum::<3>::new();
        (0..3).for_each(|j| dot.add(n[j] * v[j]));
        let dot = dot.value();
        let normal_length = n.length();
        let lit = dot > 0.0;
        let nv = if lit {
            (dot / (normal_length * v.length())).min(1.0)
        } else {
            0.0
        };
        GgxView {
            lit,
            nv,
            m_v: (self.alpha2 + self.k * (nv * nv)).sqrt(),
            normal_length,
        }
    }

    /// The given normal: [`eval`](Shader::eval) takes the exact sign of
    /// `N . (x - p)` and returns 0 where it is at most 0.
    #[inline]
    fn horizon(&self, surface: &Surface) -> Option<Vec3> {
        Some(surface.given_normal)
    }

    /// The model's term `I f(l, v) (n.l) / d^2`, 0 for a light at or below
    /// the tangent plane (the sign of `N.(x - p)` exact) or a view at or
    /// below it. `n.l` is the height over `|N| d`, `sin theta_h` is `|n x
    /// (l + v)| / |l + v|` and `v.h = |l + v| / 2`; accuracy in [`Ggx`]'s
    /// docs.
    #[inline]
    fn eval(&self, view: &GgxView, surface: &Surface, position: DVec3, intensity: DVec3) -> DVec3 {
        if !view.lit {
            return DVec3::ZERO;
        }
        let normal = surface.given_normal.as_dvec3();
        let height = dot_of_difference(normal, position, surface.point);
        if !(height > 0.0) {
            return DVec3::ZERO;
        }
        let offset = position - surface.point;
        let d2 = offset.length_squared();
        let d = d2.sqrt();
        let a = (height / (view.normal_length * d)).min(1.0);
        let h = offset / d + surface.view;
        let h2 = h.length_squared();
        let s2 = (surface.normal.cross(h).length_squared() / h2).min(1.0);
        let c = (0.5 * h2.sqrt()).min(1.0);
        let f = self.fresnel(c) * (self.distribution(s2) * self.visibility(view, a));
        intensity * f * (a / d2)
    }

    /// The product bound ([`Ggx`]'s docs): Lambert's interval (albedo 1)
    /// times the BRDF's, the midpoint as the estimate.
    #[inline]
    fn bound(&self, view: &GgxView, surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        if !view.lit {
            return NodeEstimate::ZERO;
        }
        let q = self.unit.bound(&(), surface, node, cone);
        self.product(view, surface, node, cone, &q)
    }

    /// Lambert's interval for eight nodes side by side, each times its
    /// BRDF interval: exactly what [`bound`](Shader::bound) gives.
    #[inline]
    fn bound_nodes(
        &self,
        view: &GgxView,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        let n = nodes.len().min(cones.len()).min(out.len());
        if !view.lit {
            out[..n].fill(NodeEstimate::ZERO);
            return;
        }
        self.unit
            .bound_nodes(&(), surface, &nodes[..n], &cones[..n], &mut out[..n]);
        for ((node, cone), out) in nodes.iter().zip(cones).zip(out.iter_mut()) {
            *out = self.product(view, surface, node, cone, out);
        }
    }
}

impl Ggx {
    /// (P4): `[f_lo Q_lo, f_hi Q_hi]` from Lambert's interval `q`.
    #[inline(always)]
    fn product(
        &self,
        view: &GgxView,
        surface: &Surface,
        node: &Node,
        cone: &Cone,
        q: &NodeEstimate,
    ) -> NodeEstimate {
        if q.upper.max_element() <= 0.0 {
            return NodeEstimate::ZERO;
        }
        let (f_lo, f_hi) = self.brdf_range(view, surface, node, cone);
        let lower = q.lower.max(DVec3::ZERO) * f_lo;
        let upper = q.upper * f_hi;
        NodeEstimate::new(0.5 * (lower + upper), lower, upper)
    }
}
