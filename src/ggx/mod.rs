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
//! # The node bound near the lobe: a second-order expansion
//!
//! (P4) is first order in the node's angular size: `D` changes by a
//! factor `e` over about `alpha |l + v| / 2` radians of light direction,
//! so a node near the lobe must be far smaller than that before
//! `D(s_lo) / D(s_hi)` comes near 1. Where every point of the node's ball
//! and box is lit (`a_lo >= `[`EXPANSION_MIN_COS`]), lies at least `r_min
//! > 0` from `p` and has `|l + v| >= H >= `[`EXPANSION_MIN_HALF`], each
//! member's term is `I_i G(x_i - p)` with
//!
//! ```text
//! G(y) = g(y) K(y),   g = D(t) / r^2,   K = phi(a) F(c),   phi(a) = a Vis(a)   (P5)
//! ```
//!
//! (`r = |y|`, `l = y / r`, `a = n.l`, `t = n.h = sqrt(1 - s^2)`, `c = v.h
//! = |l + v| / 2`), smooth there. The stored centroid `c_n` lies in the
//! node's box (the build clamps it there) and its ball's centre, so the
//! segment from it to each member lies in both. About it (`y0 = c_n -
//! p`), Taylor's theorem with the mean-value
//! remainder along the segment to each member, summed with channel `k`'s
//! intensities, gives
//!
//! ```text
//! sum_i I_ik G(y_i) = I_k (G(y0) + grad G(y0) . o_k) + R_k,
//! |R_k| <= I_k tr(S_k) M_2 / 2,   M_2 = sup over the hull of |d^2 G / dtau^2|
//! ```
//!
//! over unit directions (`o_k`, `S_k` the node's stored first and second
//! moments; for a symmetric Hessian the largest second directional
//! derivative is its norm). Along a unit direction of `y`, with primes
//! for `d / dtau`:
//!
//! * `|l'| <= 1 / r`, `|l''| <= (2 / sqrt 3) / r^2` (writing `e = cos(A)
//!   l + sin(A) w`, `l'' = -(2 cos A sin A w + sin^2 A l) / r^2`, of
//!   squared length `sin^2 A (1 + 3 cos^2 A) <= 4/3`);
//! * with `m = l + v`, `mu = |m|`, `h = m / mu`: `t' = (P_h n) . l' / mu`
//!   and `t'' = n . h''(m', m') + (P_h n) . l'' / mu`, where `|P_h n| = s`
//!   and `|n . h''| <= (s + t) |m'|^2 / mu^2` (the second derivative of a
//!   unit vector, as above); so `|t'| <= s / (mu r)` and `|t''| <= ((s +
//!   t) / mu^2 + 1.155 s / mu) / r^2`;
//! * `D(t) = alpha^2 / (pi q^2)`, `q = 1 - k t^2 = alpha^2 + k s^2`: `D' =
//!   4 k t D / q`, `D'' = D (24 k^2 t^2 / q^2 + 4 k / q)`;
//! * `rho = r^-2`: `|rho'| <= 2 / r^3`, `|rho''| <= 6 / r^4` (the
//!   Hessian's eigenvalues are `-2 / r^4` and `6 / r^4`).
//!
//! So `g'' = D'' t'^2 rho + D' t'' rho + 2 D' t' rho' + D rho''` is at
//! most
//!
//! ```text
//! M_g2 = [ (sup D'' s^2 + sup D' t + sup D' s) / H^2 + 5.155 sup D' s / H + 6 sup D ] / r_min^4   (P6)
//! ```
//!
//! with the sups over `s` in `[s_lo, s_hi]` (the intervals of (P4), which
//! hold for every point of the ball and box, not only for members): `D`,
//! `D'` are largest at `s_lo`; `s^2 / q^4`, `s^2 / q^3` and `s / q^3` rise
//! to `k s^2 = alpha^2 / 3`, `/ 2`, `/ 5` and fall after, so each is
//! taken at that point clamped into the interval. Likewise `|g| <= sup D
//! / r_min^2 = M_g0` and `|g'| <= (sup D' s / H + 2 sup D) / r_min^3 =
//! M_g1`.
//!
//! For `K`: `a' = n . l'`, `a'' = n . l''`, `c' = h . l' / 2`, `c'' = (h .
//! l'' + |P_h l'|^2 / mu) / 2`. `phi' = b alpha^2 / (2 m(a) u(a)^2) > 0`
//! with `u(a) = b m(a) + a m(b)`, decreasing in `a`; `phi'' = -b alpha^2
//! (m' u + 2 m u') / (2 m^2 u^3)`, whose numerator's factors increase with
//! `a` and denominator's too, so `|phi''|` is at most the numerator at
//! `a_hi` over the denominator at `a_lo`. Schlick's `|F'| = 5 (1 - F0) (1 -
//! c)^4` and `F'' = 20 (1 - F0) (1 - c)^3` are largest at `c_lo`. Then
//!
//! ```text
//! M_K0 = phi(a_hi) F(c_lo),   M_K1 = (phi'(a_lo) F(c_lo) + phi(a_hi) |F'(c_lo)| / 2) / r_min,
//! M_K2 = (|phi''| F + 1.155 phi' F + phi' |F'| + phi |F''| / 4 + phi |F'| (1.155 + 1 / H) / 2) / r_min^2
//! M_2  = M_K0 M_g2 + 2 M_g1 M_K1 + M_g0 M_K2                                     (P7)
//! ```
//!
//! by Leibniz's rule. The node's interval is `I_k (G(y0) + grad G(y0) .
//! o_k) -+ E_k`, its lower end clamped at 0, intersected with (P4)'s.
//! Near the lobe `M_2` is about `7 D / (alpha mu r)^2 r^2`: the expansion's
//! error is second order in the node's angular size over the lobe's,
//! where (P4)'s is first order.
//!
//! `E_k` holds, besides `I_k tr(S_k) M_2 / 2` (P8):
//!
//! * the stored moments' error (the build's `delta`, [`Node::moment_error`],
//!   and the `f32` storage, as in [`Lambert`]'s expansions), through the
//!   gradient's entries;
//! * `eval` against the model: its `s` is within [`DIRECTION_SLACK`]`(1 +
//!   1 / H)` of the true one, which moves `D` by at most `2 / alpha` times
//!   that relatively; its `a` within [`HEIGHT_RELATIVE_SLACK`]` a +
//!   `[`DIRECTION_SLACK`] and its `c` within [`DIRECTION_SLACK`], which
//!   move `K` by at most `delta_K = F(c_lo) phi'(a_lo) (`[`HEIGHT_RELATIVE_SLACK`]`
//!   a_hi + `[`DIRECTION_SLACK`]`) + phi(a_hi) |F'(c_lo)| `[`DIRECTION_SLACK`];
//!   and its products by [`PRODUCT_SLACK`]: an allowance `M_g0 (M_K0
//!   epsilon + delta_K)` per unit intensity (P9);
//! * the expansion's own arithmetic at the centroid: a relative
//!   [`ARITHMETIC`] of its terms, and the same `epsilon` on the gradient
//!   (`epsilon` also carries `64` [`DIRECTION_SLACK`]` (1 / a_lo + 1 /
//!   H)`, the computed `a0`, `c0` and `h` of the centroid's direction).
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

use crate::dispatch::avx2_or;
use crate::geometry::{Cone, Surface};
use crate::lambert::Lambert;
use crate::lanes::array;
use crate::numeric::{ExactSum, dot_of_difference};
use crate::shader::{NodeEstimate, Seal, Shader};
use crate::tree::Node;
use crate::{PointLight, ShadeError};

mod bound;
mod sum;

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

/// Smallest lower bound on `|l + v|` over a node for which the expansion
/// ((P5)-(P8)) is tried: below it the half vector turns fast and the
/// allowance for `eval`'s rounding (`1 / |l + v|`) grows; the product
/// bound alone serves such nodes (a light and a view grazing the surface
/// on opposite sides of the normal).
const EXPANSION_MIN_HALF: f64 = 1e-3;

/// Smallest lower bound on `n.l` over a node for which the expansion is
/// tried: below it the node may reach the horizon, where each term has a
/// kink, and `phi(a) = a Vis(a)` turns fast; the product bound alone
/// serves such nodes.
const EXPANSION_MIN_COS: f64 = 1e-3;

/// Bound on `|d^2 l / dtau^2|` times `r^2` for the unit direction `l = y /
/// |y|` along a unit direction of `y` ((P6)): `2 / sqrt(3)`, rounded up.
const UNIT_SECOND: f64 = 1.155;

/// Relative rounding of a stored `f32` moment entry (`2^-24`), doubled.
const F32_ENTRY: f64 = f32::EPSILON as f64;

/// Relative allowance for the `f64` arithmetic of the expansion's value
/// and gradient at the centroid (a few dozen operations), applied to the
/// sum of the terms' magnitudes; `eval`'s own departure from the model is
/// allowed for separately ((P9)).
const ARITHMETIC: f64 = 1e-13;

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
///
/// That product is first order in the node's angular size, and `D` turns
/// over about `alpha` radians of half vector: near the lobe it would
/// leave nodes far smaller than the lobe to settle. Where every point of
/// the node's ball and box is lit (`n.l >= 1e-3`) and keeps `|l + v| >=
/// 1e-3`, the interval is intersected with a second-order expansion of
/// the node's term about its centroid: per channel `k`,
///
/// ```text
/// I_k (G(y0) + grad G(y0) . o_k)  -+  (I_k tr(S_k) M_2 / 2 + rounding)
/// G(y) = D(h) (n.l) Vis(n.l) F(v.h) / |y|^2
/// ```
///
/// with `y0` the centroid less the point, `o_k`, `S_k` the node's first
/// and second moments, and `M_2` a bound on `G`'s second derivative over
/// the node from the same intervals (Leibniz's rule over `D / r^2` and
/// `(n.l) Vis F`, each factor's derivatives bounded in closed form). Its
/// error is second order in the node's size over the lobe's.
/// The estimate is the interval's midpoint. Every interval is rounded
/// outward and widened to hold what [`eval`](Shader::eval) computes for
/// each light, so the bound holds for the terms the reference sums; the
/// proofs and the rounding analysis are in the crate's source
/// (`src/ggx/mod.rs`).
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

    /// Eight lights side by side in `f64`, each term `eval`'s with its
    /// quotients merged (three divisions where `eval` has eight): within
    /// about `5e-12` relative of `eval`'s; lights near the tangent plane,
    /// or with light and view grazing it on opposite sides of the normal,
    /// through `eval` itself (the derivation in the crate's source,
    /// `src/ggx/sum.rs`).
    #[inline]
    fn sum_lights(
        &self,
        _: Seal,
        view: &GgxView,
        surface: &Surface,
        lights: &[PointLight],
    ) -> DVec3 {
        self.sum_group(view, surface, lights)
    }

    /// The product bound ([`Ggx`]'s docs), Lambert's interval (albedo 1)
    /// times the BRDF's, intersected with the expansion's where it holds;
    /// the estimate is the midpoint.
    #[inline]
    fn bound(&self, view: &GgxView, surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        if !view.lit {
            return NodeEstimate::ZERO;
        }
        let q = self.unit.bound(&(), surface, node, cone);
        if q.upper.max_element() <= 0.0 {
            return NodeEstimate::ZERO;
        }
        let [estimate] =
            self.product_lanes(view, surface, &bound::Nodes::new([node], [cone]), &[q]);
        estimate
    }

    /// Lambert's intervals and the rest of the bound, for up to eight
    /// nodes side by side (four lanes for up to four): exactly what
    /// [`bound`](Shader::bound) gives for each.
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
        let chunks = nodes[..n].chunks(8).zip(cones[..n].chunks(8));
        for ((nodes, cones), out) in chunks.zip(out[..n].chunks_mut(8)) {
            self.product_group(view, surface, nodes, cones, out);
        }
    }
}

impl Ggx {
    /// The bound of up to eight nodes side by side (the module `bound`),
    /// given Lambert's intervals in `out`: on `x86_64` processors with
    /// AVX2, in a copy compiled for AVX2 (the same bits, see
    /// [`dispatch`](crate::dispatch)). Out of line, compiled once.
    #[inline(never)]
    fn product_group(
        &self,
        view: &GgxView,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        avx2_or!(
            Self::product_group_avx2,
            Self::product_group_inlined,
            self,
            view,
            surface,
            nodes,
            cones,
            out
        );
    }

    /// [`product_group`](Self::product_group) compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn product_group_avx2(
        &self,
        view: &GgxView,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        self.product_group_inlined(view, surface, nodes, cones, out);
    }

    /// Four lanes (one AVX2 vector) for up to four nodes, eight for more.
    #[inline(always)]
    fn product_group_inlined(
        &self,
        view: &GgxView,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        if nodes.len() <= 4 {
            self.product_padded::<4>(view, surface, nodes, cones, out);
        } else {
            self.product_padded::<8>(view, surface, nodes, cones, out);
        }
    }

    /// `N` lanes for at most `N` nodes, given Lambert's intervals in
    /// `out`; unused lanes repeat the last node and their results are
    /// dropped.
    #[inline(always)]
    fn product_padded<const N: usize>(
        &self,
        view: &GgxView,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        let n = nodes.len().min(cones.len()).min(out.len()).min(N);
        if n == 0 {
            return;
        }
        let last = n - 1;
        let group = bound::Nodes::<N>::new(
            array(nodes[0], |i| nodes[i.min(last)]),
            array(&cones[0], |i| &cones[i.min(last)]),
        );
        let q: [NodeEstimate; N] = array(NodeEstimate::ZERO, |i| out[i.min(last)]);
        let result = self.product_lanes(view, surface, &group, &q);
        out[..n].copy_from_slice(&result[..n]);
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::testing::uniform;
    use crate::{LightTree, PointLight, ShadeResult};

    /// Street lamps in a layer 4 to 6 units up, seen from the ground below
    /// them at views 10 to 80 degrees up, for roughness from the narrowest
    /// to 1: every node the expansion takes holds its exact sum (of
    /// `eval`, what the reference sums), and many are far narrower than
    /// the product bound, which is first order in the node's size.
    #[test]
    fn the_expansion_holds_every_node_it_takes() {
        let mut seed = 5u64;
        let mut next = move || uniform(&mut seed);
        let lights: Vec<_> = (0..4000)
            .map(|_| {
                let at = Vec3::new(40.0 * next(), 40.0 * next(), 4.0 + 2.0 * next());
                let colour = Vec3::new(next(), next(), next()) + Vec3::splat(0.05);
                PointLight::new(at, colour)
            })
            .collect();
        let tree = LightTree::builder()
            .max_leaf_lights(4)
            .build(&lights)
            .unwrap();
        let (mut taken, mut narrower) = (0, 0);
        for &alpha in &[1e-3f32, 0.02, 0.1, 0.5, 1.0] {
            let f0 = Vec3::new(0.04, 0.5 * next(), 1.0);
            let ggx = Ggx::new(f0, alpha);
            for _ in 0..24 {
                let p = Vec3::new(5.0 + 30.0 * next(), 5.0 + 30.0 * next(), 0.0);
                let normal = Vec3::new(0.3 * (next() - 0.5), 0.3 * (next() - 0.5), 1.0);
                let up = (10.0 + 70.0 * next()).to_radians();
                let around = std::f32::consts::TAU * next();
                let v = Vec3::new(up.cos() * around.cos(), up.cos() * around.sin(), up.sin());
                let surface = Surface::new(p, normal, Some(v)).unwrap();
                let view = ggx.prepare(&surface);
                for node in tree.nodes() {
                    let Some(cone) = node.cone(surface.point) else {
                        continue;
                    };
                    if node.light_count() < 2 {
                        continue;
                    }
                    let group = bound::Nodes::new([node], [&cone]);
                    let r = ggx.ranges(&view, &surface, &group);
                    let (holds, lo, hi) = ggx.expansion(&view, &surface, &group, &r);
                    if !holds[0] {
                        continue;
                    }
                    let at = |v: &[crate::lanes::Lanes<1>; 3]| {
                        DVec3::new(v[0].0[0], v[1].0[0], v[2].0[0])
                    };
                    let (lo, hi) = (at(&lo), at(&hi));
                    taken += 1;
                    let exact: DVec3 = tree.lights()[node.lights()]
                        .iter()
                        .map(|l| {
                            ggx.eval(
                                &view,
                                &surface,
                                l.position.as_dvec3(),
                                l.intensity.as_dvec3(),
                            )
                        })
                        .sum();
                    let slack = exact * ShadeResult::ROUNDING_ALLOWANCE;
                    assert!(
                        lo.cmple(exact + slack).all() && (exact - slack).cmple(hi).all(),
                        "alpha {alpha}: {exact} outside [{lo}, {hi}] ({} lights)",
                        node.light_count()
                    );
                    let q = ggx.unit.bound(&(), &surface, node, &cone);
                    let (f_lo, f_hi) = ggx.brdf_range(&view, &r);
                    let (f_lo, f_hi) = (at(&f_lo), at(&f_hi));
                    let product = (q.upper * f_hi - q.lower.max(DVec3::ZERO) * f_lo).max_element();
                    narrower += usize::from(10.0 * (hi - lo).max_element() < product);
                }
            }
        }
        assert!(taken > 100_000 && narrower > 20_000, "{taken} {narrower}");
    }

    /// Each node's bound is the same bits alone, beside up to seven others
    /// (four and eight lanes), and in the baseline copy of the lanes.
    #[test]
    fn a_node_bound_is_the_same_alone_and_in_lanes() {
        let mut seed = 9u64;
        let mut next = move || uniform(&mut seed);
        let lights: Vec<_> = (0..3000)
            .map(|_| {
                let at = Vec3::new(30.0 * next(), 30.0 * next(), 6.0 * next() - 1.0);
                PointLight::new(at, Vec3::new(next(), next(), next()))
            })
            .collect();
        let tree = LightTree::builder()
            .max_leaf_lights(4)
            .build(&lights)
            .unwrap();
        let mut compared = 0;
        for &alpha in &[1e-3f32, 0.05, 0.3, 1.0] {
            let ggx = Ggx::new(Vec3::new(0.04, 0.5, 0.9), alpha);
            for _ in 0..8 {
                let p = Vec3::new(30.0 * next(), 30.0 * next(), 0.0);
                let v = Vec3::new(next() - 0.5, next() - 0.5, 0.2 + next());
                let surface = Surface::new(p, Vec3::Z, Some(v)).unwrap();
                let view = ggx.prepare(&surface);
                let nodes: Vec<_> = tree
                    .nodes()
                    .iter()
                    .filter_map(|node| Some((node, node.cone(surface.point)?)))
                    .collect();
                for len in [2, 3, 4, 5, 8] {
                    for group in nodes.chunks(len) {
                        let refs: Vec<_> = group.iter().map(|(node, _)| *node).collect();
                        let cones: Vec<_> = group.iter().map(|(_, cone)| *cone).collect();
                        let mut lanes = vec![NodeEstimate::ZERO; group.len()];
                        let mut baseline = lanes.clone();
                        ggx.bound_nodes(&view, &surface, &refs, &cones, &mut lanes);
                        crate::dispatch::baseline(|| {
                            ggx.bound_nodes(&view, &surface, &refs, &cones, &mut baseline);
                        });
                        for (((node, cone), a), b) in group.iter().zip(&lanes).zip(&baseline) {
                            let alone = ggx.bound(&view, &surface, node, cone);
                            let bits = |e: &NodeEstimate| {
                                [e.estimate, e.lower, e.upper]
                                    .map(|v| v.to_array().map(f64::to_bits))
                            };
                            assert_eq!(bits(&alone), bits(a));
                            assert_eq!(bits(&alone), bits(b));
                            compared += usize::from(alone.upper != DVec3::ZERO);
                        }
                    }
                }
            }
        }
        assert!(compared > 10_000, "{compared}");
    }
}
