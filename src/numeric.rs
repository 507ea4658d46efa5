//! Rounding: the compensated sum, outward rounding to `f32`, every slack
//! the certified bounds widen by (each with its derivation), and the
//! error-free transformations that decide signs exactly.
//!
//! The contract (see [`ShadeResult::ROUNDING_ALLOWANCE`](crate::ShadeResult::ROUNDING_ALLOWANCE))
//! lets *relative* rounding of order `1e-12` pass; everything that can
//! cancel (cosines near 0, Taylor sums whose terms cancel) is widened here by
//! an *absolute* amount instead, so no bound is lost to rounding.
//!
//! Where the model itself changes at a sign (a light in the tangent plane,
//! at the border of a Phong lobe), no slack can help: a light's term must be
//! exactly 0 on one side. There the sign is computed exactly from the
//! caller's `f32` data, with error-free transformations (Knuth's TwoSum,
//! Dekker's TwoProduct), a compensated dot product in the style of Ogita,
//! Rump and Oishi's `Dot2` (*Accurate sum and dot product*, SIAM J. Sci.
//! Comput. 26(6), 2005) as a fast path, and Shewchuk's exact expansion
//! arithmetic (*Adaptive precision floating-point arithmetic and fast robust
//! geometric predicates*, Discrete Comput. Geom. 18, 1997) where the fast
//! path cannot decide.

use glam::DVec3;

/// Absolute widening of every cosine bound computed by
/// [`Cone::cos_range`](crate::shader::Cone::cos_range).
///
/// The cosine and sine of the angle to the cone's axis come from a dot and a
/// cross product of unit `f64` vectors, each within a few `f64::EPSILON` of
/// the exact value; the sum-of-angles formula adds two products. `16 *
/// f64::EPSILON` (about `3.6e-15`) covers the accumulated absolute error, so
/// the returned range contains every true cosine even when it is near 0,
/// where a relative allowance would not help.
pub const COS_SLACK: f64 = 16.0 * f64::EPSILON;

/// Relative allowance for `f64` rounding in the second-order Taylor
/// estimate ([`BoundKind::Taylor`](crate::BoundKind::Taylor)): it is a sum of a handful of products,
/// each within a few ulps; the slack is applied to the magnitudes of its two
/// terms, so it stays valid when they cancel. `64 * f64::EPSILON` is about
/// `1.4e-14`.
pub const SECOND_ORDER_SLACK: f64 = 64.0 * f64::EPSILON;

/// Rounding allowance of the multipole series bound ([`BoundKind::Series`](crate::BoundKind::Series)),
/// about `2.3e-13`. It is used three ways:
///
/// * absolutely, on the estimate, times the magnitude
///   `1 + |o_k|_1 / D + tr(S_k) / D^2` (in units of `I_k / D^2`). The inputs
///   `uh = (c - p) / D`, `c0 = n . uh`, `nu = |n x uh|` and
///   `nperp = n - c0 uh` are within `10 * f64::EPSILON` (absolute) of the
///   exact values for the computed offset `c - p` (`D` within 2 ulps, `uh`
///   within 3 per component, a dot or cross product of unit vectors adding
///   2). The three series terms are bounded by `1`, `2 |o|/D` and
///   `12 tr(S)/D^2` (using `|e^T S f| <= tr S` for unit `e`, `f`), are
///   computed with at most 10 roundings each, and move by at most
///   `(1 + 10 |o|/D + 30 tr(S)/D^2)` times the input error (each occurrence
///   of a unit vector contributes once). Together at most
///   `10 eps (2 + 14 |o|/D + 42 tr(S)/D^2) <= 420 eps (1 + |o|/D + tr(S)/D^2)`;
///   `1024 eps` leaves a factor 2.4.
/// * absolutely, added to `|c0|`, `nu` and (times `R`) `hperp`, the
///   quantities the remainder grows with, for the same input errors
///   (`hperp`: `nperp` within `10 eps` moves `nperp . y` by at most
///   `10 sqrt(3) eps R`);
/// * relatively, on the remainder, times `D / (D - R)`: the remainder is a
///   sum of products of non-negative factors (at most 20 roundings), and it
///   grows with `sigma = R/D` (computed within 3 ulps) at most like
///   `sigma^6 / (1 - sigma)^3`, whose relative sensitivity to `sigma` is
///   `6 / sigma + 3 / (1 - sigma) <= 9 D / (D - R)` per unit of relative
///   error; `20 + 3 * 9 * 3 < 1024`.
pub const SERIES_SLACK: f64 = 1024.0 * f64::EPSILON;

/// Allowance for the one rounding in the offset `c - p` (`f64` difference of
/// the `f32` centroid and shading point), in units of `I_k / D^2` times
/// `(D / (D - R))^3`: the series is evaluated for a point `p'` with
/// `|p' - p| <= 2^-53 D`, and the node's exact sum moves by at most
/// `|p' - p| sup |grad f| <= 2^-53 D * 2 I / (D - R)^3` (the gradient of
/// `max(0, n.v) / |v|^3` has norm at most `2 / |v|^3`). `2 * f64::EPSILON =
/// 2^-51` is twice that.
pub const POINT_SLACK: f64 = 2.0 * f64::EPSILON;

/// Relative widening of a cut's summed error bound for the rounding of its
/// compensated sum: within two ulps of the sum of magnitudes (the terms are
/// non-negative); 8 leaves margin.
pub const SUM_SLACK: f64 = 8.0 * f64::EPSILON;

/// Relative inflation applied to distances and second moments computed in
/// `f64` at build time before they are rounded upward to `f32`: an `f64`
/// length of a difference carries at most a few ulps (`2^-52` each) of
/// error, so `8 * f64::EPSILON` covers it with margin.
pub const BUILD_LENGTH_SLACK: f64 = 8.0 * f64::EPSILON;

/// Relative widening of a distance computed in `f64` from a stored `f32` box
/// corner and the shading point ([`Aabb::distance_range`](crate::Aabb::distance_range)):
/// each coordinate difference is within one rounding (`2^-53` relative) of
/// the exact one, the sum of squares adds three and the square root one,
/// so the length is within about `3 * 2^-53` relative; `8 * f64::EPSILON`
/// (`16 * 2^-53`) covers it with margin.
pub const DISTANCE_SLACK: f64 = 8.0 * f64::EPSILON;

/// Absolute padding of harmonic norms computed from a node's members, in
/// units of `f64::EPSILON`, on top of one `f64::EPSILON` per member light,
/// before they are rounded upward to `f32`.
///
/// The build tracks its own rounding (it merges moments bottom-up, with a
/// certified error bound carried along) and adds twice this padding, so
/// that a stored norm is never below the norm
/// [`LightTree::validate`](crate::LightTree::validate) recomputes from the
/// members directly, which is the computation analysed here.
///
/// A directly computed norm is `q = |C| / I_k` with `C` the `2l + 1` Schmidt
/// semi-normalised solid-harmonic moments of degree `l` of the node's
/// members, scaled by `1 / R` (so `|y / R| <= 1`). Each moment is a
/// recursive `f64` sum of `n` terms; by Minkowski's inequality and
/// `sum_j R_lj(y)^2 = |y|^(2l)` the vector of summation errors has norm at
/// most `(n - 1) 2^-53 P I_k`, `P = sum_i I_ik |y_i / R|^l / I_k <= 1`. Each
/// term is evaluated by the build's solid-harmonic evaluation with at most 20 roundings on
/// intermediate values of at most `20 |y|^l` after normalisation, plus the
/// scaling `y / R` (two roundings, moving a harmonic by at most `2^9 eps |y|^l`):
/// within `2^11 eps |y|^l` each, `2^13 eps P I_k` for the vector of `2l + 1 <= 11`.
/// So the computed `q` is within `(n + 2^13) eps` of the exact one, up to a
/// few relative ulps that the final `1 + BUILD_LENGTH_SLACK` covers;
/// `2^16` leaves a factor 8. A test checks the addition theorem on the
/// evaluated harmonics.
pub const HARMONIC_BUILD_PAD: f64 = 65_536.0;

/// Relative tolerance of [`LightTree::validate`](crate::LightTree::validate)
/// when it compares a node's stored intensity with the sum of its children's:
/// both are `f64` sums of the same `f32` values in different orders, which
/// agree to `n * f64::EPSILON` relative for `n` terms; `1e-9` covers a
/// million lights with margin.
pub const SUM_TOLERANCE: f64 = 1e-9;

/// Acceptance threshold of the plain `f64` evaluation of `a . (x - p)` in
/// the exact-sign dot products behind [`Lambert`](crate::Lambert)'s terms
/// and box test (and, multiplied by the exponent, [`Phong`](crate::Phong)'s
/// terms): its result `z` is kept when `|z| >= NAIVE_DOT_ACCEPT * sum_j
/// |fl(a_j (x_j - p_j))|`; closer to 0 the compensated dot product takes
/// over (see [`DOT2_ACCEPT`]).
///
/// Derivation, with `u = 2^-53` the unit roundoff: one rounded subtraction,
/// one product and two additions per term give `|z - exact| <= gamma_4 T`
/// (Higham, *Accuracy and Stability of Numerical Algorithms*, 2002, 3.1),
/// `gamma_4 = 4u / (1 - 4u)`, `T = sum_j |a_j||x_j - p_j|`, and the computed
/// magnitude is at least `(1 - gamma_3) T`. With `|z| >= 2^-10` times it
/// the relative error is below `4u 2^10 (1 + 8u) < 2^-40` (about `9e-13`,
/// a thousandth of the rounding allowance; the factor 2 to spare also
/// covers the one more addition of Phong's `R_lo . (x - p)`), and the sign
/// is exact. In a
/// scene of lights spread over the hemisphere, all but the lights within
/// about `0.1` degree of the tangent plane pass.
pub const NAIVE_DOT_ACCEPT: f64 = 1.0 / 1024.0;

/// Acceptance threshold of the compensated dot product behind the exact
/// signs of [`Lambert`](crate::Lambert) and [`Phong`](crate::Phong): its
/// result `res` for `a . (x - p)` is kept when
/// `|res| >= DOT2_ACCEPT * sum_j |a_j| |x_j - p_j|`, and the exact expansion
/// decides otherwise.
///
/// Derivation, with `u = 2^-53` the unit roundoff and `T = sum_j |a_j||x_j -
/// p_j|`: the differences and the products with the leading part of `a` are
/// error-free (TwoSum, TwoProduct), and so is the running sum of the
/// products; what is left are at most 12 small terms (the errors of the
/// sums and products, `a_hi e` and `a_lo d` with `e` the subtraction's error
/// and `a_lo <= 2u a_hi`), of total magnitude at most about `6u T`, summed
/// with at most 6 roundings each: an error of at most `37 u^2 T`. The
/// omitted `a_lo e` adds `2 u^2 T` and an `a` given to `4 u^2` of its size
/// (Phong's mirror direction) `4 u^2 T`: `43 u^2 T` in all, plus `u |res|`
/// for the final addition. With `|res| >= 256 u T` (this constant, `128 *
/// f64::EPSILON`, about `2.8e-14`) that is at most `1.17 u |res| <
/// f64::EPSILON * |res|`: the sign of `res` is the exact sign and its
/// relative error is below `f64::EPSILON`. The factor of about 3 between
/// `43 u^2 T` and what the constant allows also covers the rounding of `T`
/// itself (`3u` relative).
pub const DOT2_ACCEPT: f64 = 128.0 * f64::EPSILON;

/// Phong exponents above which a light near the lobe's axis (cosine above
/// `1/2`) has its lobe computed from `1 - cos = sin^2 / (1 + cos)`, the sine
/// from a compensated cross product, rather than from the cosine itself.
///
/// Derivation, with `u = 2^-53`: the cosine `R.(x - p) / (|R| d)` carries,
/// besides its numerator's relative error (kept below `2^-41 / e`, see
/// [`NAIVE_DOT_ACCEPT`]), about `11u` (`5u` from `|R| = |N|^2 |V|`, `4u`
/// from `d`, two roundings), and the lobe `exp(e ln cos)` `e` times all
/// that: below `2^-41 + 512 * 11u`, about `1.1e-12`, for `e <= 512` (an
/// integer exponent's power by repeated multiplication adds at most
/// `(e - 1) u`). Above
/// it, near the axis, where the lobe of a large exponent lives, that would
/// reach `1e-9` at `e = 1e6`; `1 - cos` from the sine has a relative error of
/// about `30u`, and the lobe then `|e ln cos| 30u`, at most about `4e-12`
/// wherever it does not underflow (`|e ln cos| < 1130` even with the
/// largest `I ks / d^2`). Below `cos = 1/2`, `|ln cos| > 0.69` bounds the
/// cosine route's error the same way.
pub const PHONG_SINE_ROUTE_ABOVE: f64 = 512.0;

/// Rounds a non-negative `f64` up to the nearest `f32` at or above it, so a
/// stored radius or moment never understates the value it bounds.
#[must_use]
#[inline]
pub(crate) fn round_up_f32(x: f64) -> f32 {
    // Where the conversion rounded down, one step up: the next bit pattern
    // of a non-negative `y`, the previous one of a negative `y` (a `y` of
    // -0 never steps: only a positive `x` lies above it, and that rounds
    // to +0; +inf and NaN never step). Branch-free: the build rounds tens
    // of values a node, about half of them downward, at random.
    let y = x as f32;
    let bits = y.to_bits();
    let step = u32::from(f64::from(y) < x);
    let sign = bits >> 31;
    f32::from_bits(bits.wrapping_add(step.wrapping_mul(1u32.wrapping_sub(sign << 1))))
}

/// Neumaier-compensated sum of `DVec3`s: accurate to about two ulps of the
/// sum of magnitudes, whatever the number of terms.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct CompensatedSum {
    sum: DVec3,
    compensation: DVec3,
}

impl CompensatedSum {
    #[inline]
    pub(crate) fn add(&mut self, term: DVec3) {
        let t = self.sum + term;
        let big = self.sum.abs().cmpge(term.abs());
        self.compensation += DVec3::select(big, (self.sum - t) + term, (term - t) + self.sum);
        self.sum = t;
    }

    /// Adds `term` without compensation: faster, and as accurate as plain
    /// summation from here on.
    #[inline]
    pub(crate) fn add_plain(&mut self, term: DVec3) {
        self.sum += term;
    }

    #[inline]
    #[must_use]
    pub(crate) fn value(&self) -> DVec3 {
        self.sum + self.compensation
    }
}

/// Knuth's TwoSum (Knuth, *The Art of Computer Programming* vol. 2;
/// Shewchuk 1997, `TWO-SUM`): `s = fl(a + b)` and `e` with `s + e = a + b`
/// exactly, `|e| <= ulp(s) / 2`, for any finite `a`, `b` whose sum does not
/// overflow. No branch, no precondition on the order of magnitudes.
#[inline]
#[must_use]
pub(crate) fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let b_virtual = s - a;
    let a_virtual = s - b_virtual;
    (s, (a - a_virtual) + (b - b_virtual))
}

/// Dekker's FastTwoSum (Dekker, *A floating-point technique for extending
/// the available precision*, Numer. Math. 18, 1971): like [`two_sum`], exact
/// when `a`'s exponent is at least `b`'s (in particular when `|a| >= |b|`),
/// as Shewchuk's `COMPRESS` guarantees where it is used.
#[inline]
#[must_use]
fn fast_two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    (s, b - (s - a))
}

/// TwoProduct (Dekker 1971; here with a fused multiply-add, as in Ogita,
/// Rump and Oishi 2005): `p = fl(a b)` and `e` with `p + e = a b` exactly,
/// provided `a b` does not overflow and `e` does not underflow. The latter
/// holds when `a` and `b` are multiples of `2^-k` and `2^-l` with
/// `k + l <= 1074`. In this crate one factor is an `f32` value, a product of
/// two, or a component of an exact sum of products of three (a multiple of
/// `2^-447`), the other an `f32` value, a difference of two or its rounding
/// error (multiples of `2^-149`): every product is a multiple of `2^-596`.
#[inline]
#[must_use]
pub(crate) fn two_product(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    (p, a.mul_add(b, -p))
}

/// Up to `N` `f64` terms whose *exact* sum is wanted: the terms are kept
/// unrounded (products enter as their [`two_product`] pair) and summed
/// exactly as a floating-point expansion (Shewchuk 1997).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ExactSum<const N: usize> {
    terms: [f64; N],
    len: usize,
}

impl<const N: usize> ExactSum<N> {
    /// No terms.
    #[inline]
    pub(crate) fn new() -> Self {
        Self {
            terms: [0.0; N],
            len: 0,
        }
    }

    /// Adds the term `x` (exactly).
    #[inline]
    pub(crate) fn add(&mut self, x: f64) {
        debug_assert!(self.len < N, "ExactSum capacity {N} exceeded");
        self.terms[self.len] = x;
        self.len += 1;
    }

    /// Adds `a b` exactly, as its [`two_product`] pair (under that
    /// function's no-underflow condition).
    #[inline]
    pub(crate) fn add_product(&mut self, a: f64, b: f64) {
        let (p, e) = two_product(a, b);
        self.add(p);
        self.add(e);
    }

    /// The exact sum as a nonoverlapping expansion, components in
    /// increasing magnitude, none zero (empty for a zero sum): Shewchuk's
    /// (1997) `GROW-EXPANSION` with zero elimination, then `COMPRESS`, both
    /// in place. Their sum equals the sum of the terms exactly; the largest
    /// component has the sign of the sum and, as Shewchuk proves for
    /// `COMPRESS`, differs from it by less than its own ulp.
    pub(crate) fn expansion(&mut self) -> &[f64] {
        let h = &mut self.terms;
        // Grow the expansion h[..len] by one term at a time; it never has
        // more components than terms read, so it never overwrites a term
        // not yet read.
        let mut len = 0;
        for i in 0..self.len {
            let mut q = h[i];
            let mut k = 0;
            for j in 0..len {
                let (s, e) = two_sum(q, h[j]);
                q = s;
                if e != 0.0 {
                    h[k] = e;
                    k += 1;
                }
            }
            if q != 0.0 {
                h[k] = q;
                k += 1;
            }
            len = k;
        }
        self.len = len;
        if len == 0 {
            return &[];
        }
        // COMPRESS: from the top down, then from the bottom up.
        let mut bottom = len - 1;
        let mut q = h[bottom];
        for i in (0..len - 1).rev() {
            let (s, small) = fast_two_sum(q, h[i]);
            if small != 0.0 {
                h[bottom] = s;
                bottom -= 1;
                q = small;
            } else {
                q = s;
            }
        }
        h[bottom] = q;
        let mut top = 0;
        for i in bottom + 1..len {
            let (s, small) = fast_two_sum(h[i], q);
            if small != 0.0 {
                h[top] = small;
                top += 1;
            }
            q = s;
        }
        h[top] = q;
        self.len = top + 1;
        &self.terms[..self.len]
    }

    /// The sum: exact sign (0 only for an exact 0), within one ulp (the
    /// largest component of the compressed [`expansion`](Self::expansion);
    /// a relative error of at most about `f64::EPSILON`).
    pub(crate) fn value(&mut self) -> f64 {
        self.expansion().last().copied().unwrap_or(0.0)
    }
}

/// The compensated fast path of `a . (x - p)`, with `a = hi + lo` given as a
/// double-double (`|lo_j| <= 2u |hi_j|`, `u = 2^-53`, and `hi + lo` within
/// `4 u^2 |hi|` of the `a` meant, per component): `Dot2` of Ogita, Rump and
/// Oishi (2005, Algorithm 5.3), extended to the differences `x - p`, which
/// TwoSum splits exactly into `d + e`.
///
/// Returns `Some(res)` when `|res| >= DOT2_ACCEPT * T`, `T = sum_j |hi_j d_j|`:
/// then `res` has the exact sign of `a . (x - p)` (it is not 0) and a
/// relative error below `f64::EPSILON` ([`DOT2_ACCEPT`] derives it). `None`
/// otherwise (the value is within about `2^-45 T` of 0, or 0): the caller
/// decides exactly. Needs [`two_product`]'s no-underflow condition.
#[inline]
#[must_use]
pub(crate) fn dot2_of_difference(hi: DVec3, lo: DVec3, x: DVec3, p: DVec3) -> Option<f64> {
    let (res, magnitude) = dot2_value(hi, lo, x, p);
    (res.abs() >= DOT2_ACCEPT * magnitude).then_some(res)
}

/// The compensated `a . (x - p)` of [`dot2_of_difference`] without its
/// acceptance test, and the magnitude `T = sum_j |fl(hi_j d_j)|`:
/// `|res - a . (x - p)| <= u |res| + 43 u^2 T` (`u = 2^-53`; see
/// [`DOT2_ACCEPT`]), whatever the cancellation.
#[inline]
#[must_use]
pub(crate) fn dot2_value(hi: DVec3, lo: DVec3, x: DVec3, p: DVec3) -> (f64, f64) {
    let (hi, lo, x, p) = (hi.to_array(), lo.to_array(), x.to_array(), p.to_array());
    let mut sum = 0.0;
    let mut small = 0.0;
    let mut magnitude = 0.0;
    for j in 0..3 {
        let (d, e) = two_sum(x[j], -p[j]);
        let (product, product_error) = two_product(hi[j], d);
        let (s, sum_error) = two_sum(sum, product);
        sum = s;
        small += (product_error + sum_error) + (hi[j] * e + lo[j] * d);
        magnitude += product.abs();
    }
    (sum + small, magnitude)
}

/// `a . (x - p)` exactly summed, for `a` given per coordinate as an exact
/// expansion (a slice whose sum is `a_j`, e.g. `&[a_j]`): exact sign,
/// within one ulp ([`ExactSum::value`]). `N`, the capacity, must be at
/// least four times the number of components in all. Needs
/// [`two_product`]'s no-underflow condition. The slow path behind
/// [`dot2_of_difference`].
#[cold]
#[inline(never)]
#[must_use]
pub(crate) fn exact_dot_of_difference<const N: usize>(a: [&[f64]; 3], x: DVec3, p: DVec3) -> f64 {
    let mut sum = ExactSum::<N>::new();
    for (j, a_j) in a.iter().enumerate() {
        let (d, e) = two_sum(x[j], -p[j]);
        for &c in *a_j {
            sum.add_product(c, d);
            sum.add_product(c, e);
        }
    }
    sum.value()
}

/// `a . (x - p)` for `a`, `x`, `p` holding `f32` values (any [`Surface`]'s
/// point and given normal, any light's position): the sign is exact, the
/// relative error below `2^-40`, and about `f64::EPSILON` at most when the
/// value is within `2^-10` of its terms' magnitude (a light within about 0.1
/// degree of the plane). Three tiers, each taken only when the one before
/// cannot
/// certify its result: plain `f64` ([`NAIVE_DOT_ACCEPT`]), the compensated
/// [`dot2_of_difference`] ([`DOT2_ACCEPT`]), an exact expansion.
///
/// [`Surface`]: crate::shader::Surface
#[inline(always)]
#[must_use]
pub(crate) fn dot_of_difference(a: DVec3, x: DVec3, p: DVec3) -> f64 {
    let (z, magnitude) = plain_dot_of_difference(a, x, p);
    if z.abs() >= NAIVE_DOT_ACCEPT * magnitude {
        return z;
    }
    dot2_of_difference(a, DVec3::ZERO, x, p)
        .unwrap_or_else(|| exact_dot_of_difference::<12>([&[a.x], &[a.y], &[a.z]], x, p))
}

/// `a . (x - p)` in plain `f64`, and the magnitude `sum_j |fl(a_j (x_j -
/// p_j))|` its error is measured against: the result is within `gamma_4`
/// (`4u / (1 - 4u)`, `u = 2^-53`) times the exact magnitude of the exact
/// value (see [`NAIVE_DOT_ACCEPT`]).
#[inline(always)]
#[must_use]
pub(crate) fn plain_dot_of_difference(a: DVec3, x: DVec3, p: DVec3) -> (f64, f64) {
    let terms = a * (x - p);
    (terms.x + terms.y + terms.z, terms.abs().element_sum())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rounding of [`round_up_f32`] with `next_up`, as a reference.
    fn round_up_reference(x: f64) -> f32 {
        let y = x as f32;
        if f64::from(y) < x { y.next_up() } else { y }
    }

    proptest::proptest! {
        #[test]
        fn round_up_steps_as_next_up(bits: u64, scale in -160i32..160) {
            // Any bit pattern, and values near f32's range and its
            // subnormals, of both signs.
            let near = f64::from_bits(bits & 0x800f_ffff_ffff_ffff | 0x3ff0_0000_0000_0000)
                * 2f64.powi(scale);
            for x in [f64::from_bits(bits), near] {
                let (got, want) = (round_up_f32(x), round_up_reference(x));
                proptest::prop_assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "{x:e}: {got:e} against {want:e}"
                );
            }
        }
    }

    #[test]
    fn round_up_steps_at_the_edges() {
        for x in [
            0.0,
            -0.0,
            1e-300,
            -1e-300,
            1e-45,
            -1e-45,
            f64::from(f32::MAX) * 1.5,
            -f64::from(f32::MAX) * 1.5,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::from(f32::MIN_POSITIVE) * 0.75,
        ] {
            assert_eq!(
                round_up_f32(x).to_bits(),
                round_up_reference(x).to_bits(),
                "{x:e}"
            );
        }
        assert!(round_up_f32(f64::NAN).is_nan());
    }

    #[test]
    fn round_up_never_rounds_down() {
        for x in [0.1f64, 1.0 / 3.0, 1e-40, 3.4e38, 0.0, 1.0] {
            assert!(f64::from(round_up_f32(x)) >= x, "{x}");
        }
    }

    #[test]
    fn two_sum_and_two_product_are_error_free() {
        let (s, e) = two_sum(1.0, 1e-30);
        assert_eq!((s, e), (1.0, 1e-30));
        // 0.1 + 0.2 of the two doubles is 0.3000000000000000166..., the
        // double above it 0.3000000000000000444...: 2^-55 apart.
        assert_eq!(two_sum(0.1, 0.2), (0.1 + 0.2, -(2f64.powi(-55))));
        // (1 + 2^-30)^2 = 1 + 2^-29 + 2^-60: the last term is the error.
        let a = 1.0 + 2f64.powi(-30);
        assert_eq!(two_product(a, a), (1.0 + 2f64.powi(-29), 2f64.powi(-60)));
    }

    #[test]
    fn exact_sum_survives_any_cancellation() {
        let tiny = 2f64.powi(-1000);
        for (terms, sum) in [
            (vec![1e16, 1.0, -1e16, 1.0], 2.0),
            (vec![1.0, tiny, -1.0], tiny),
            (vec![2f64.powi(300), -tiny, -(2f64.powi(300))], -tiny),
            (vec![3.0, -1.0, -2.0], 0.0),
            (vec![], 0.0),
        ] {
            let mut exact = ExactSum::<8>::new();
            terms.iter().for_each(|&t| exact.add(t));
            assert_eq!(exact.value(), sum, "{terms:?}");
        }
        // 0.1 + 0.2 - 0.3 in exact arithmetic on the three doubles.
        let mut exact = ExactSum::<4>::new();
        [0.1, 0.2, -0.3].iter().for_each(|&t| exact.add(t));
        assert_eq!(exact.value(), 2f64.powi(-55));
    }

    /// Integer terms (53-bit odd multiples of powers of two) with heavy
    /// cancellation, checked against their exact `i128` sum.
    #[test]
    fn exact_sum_matches_integer_arithmetic() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..2000 {
            let mut exact = ExactSum::<16>::new();
            let mut reference = 0i128;
            for _ in 0..8 {
                let mantissa = (next() >> 11) as i64 | 1;
                let shift = next() % 60;
                let sign = if next() % 2 == 0 { 1 } else { -1 };
                let term = i128::from(sign * mantissa) << shift;
                // Each term and its near-negation: most bits cancel.
                for t in [term, -(term >> 1 << 1) + (next() % 4) as i128] {
                    exact.add(t as f64);
                    reference += (t as f64) as i128;
                }
            }
            let value = exact.value();
            let reference_f64 = reference as f64;
            assert_eq!((value > 0.0, value == 0.0), (reference > 0, reference == 0));
            assert!(
                (value - reference_f64).abs() <= 2.0 * f64::EPSILON * reference_f64.abs(),
                "{value} vs {reference}"
            );
        }
    }

    #[test]
    fn each_tier_of_the_exact_dot_gets_the_sign_right() {
        let n = DVec3::ONE;
        let light = DVec3::new(20.0, -19.0, -1.0);
        // Exactly in the plane: the exact expansion decides, 0.
        assert_eq!(dot_of_difference(n, light, DVec3::ZERO), 0.0);
        // 2^-30 off: the compensated tier (exact here).
        let p = DVec3::new(0.0, 0.0, -(2f64.powi(-30)));
        assert_eq!(
            dot2_of_difference(n, DVec3::ZERO, light, p),
            Some(2f64.powi(-30))
        );
        assert_eq!(dot_of_difference(n, light, p), 2f64.powi(-30));
        // 2^-40 off: within 2^-45 of the terms' magnitude 40, so exact.
        let p = DVec3::new(0.0, 0.0, -(2f64.powi(-40)));
        assert_eq!(dot2_of_difference(n, DVec3::ZERO, light, p), None);
        assert_eq!(dot_of_difference(n, light, p), 2f64.powi(-40));
        // 2^-149 off (the smallest f32): only the exact expansion sees it.
        let p = DVec3::new(0.0, 0.0, -f64::from(f32::from_bits(1)));
        assert_eq!(dot2_of_difference(n, DVec3::ZERO, light, p), None);
        assert_eq!(dot_of_difference(n, light, p), f64::from(f32::from_bits(1)));
        assert_eq!(
            dot_of_difference(n, light, -p),
            -f64::from(f32::from_bits(1))
        );
        // Far from the plane: plain f64.
        assert_eq!(
            dot_of_difference(n, DVec3::new(1.0, 2.0, 3.0), DVec3::ZERO),
            6.0
        );
    }

    #[test]
    fn compensated_sum_recovers_cancelled_terms() {
        let mut s = CompensatedSum::default();
        for t in [1e16, 1.0, -1e16, 1.0] {
            s.add(DVec3::splat(t));
        }
        assert_eq!(s.value(), DVec3::splat(2.0));
    }
}
