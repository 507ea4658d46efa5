//! Phong specular reflection with a certified node bound.

use glam::{DVec3, Vec3};

use crate::ShadeError;
use crate::geometry::{Cone, Surface};
use crate::numeric::{
    ExactSum, NAIVE_DOT_ACCEPT, PHONG_SINE_ROUTE_ABOVE, dot2_of_difference, dot2_value,
    exact_dot_of_difference, plain_dot_of_difference,
};
use crate::shader::{NodeEstimate, Shader, colour_or_clamped, try_colour};
use crate::tree::Node;

/// Below this value `cos^e` is computed together with its scale factor in
/// log space, so that a lobe value that would underflow `f64` on its own but
/// is multiplied by a large intensity is not flushed to zero. `1e-280` leaves
/// 28 decades above the smallest normal `f64`.
const LOBE_LOG_SPACE_BELOW: f64 = 1e-280;

/// Phong specular reflection: a light of intensity `I` at distance `d` in
/// direction `w` contributes `I * ks * max(0, r . w)^e / d^2`, with
/// `r = 2 (n . v) n - v` the mirror image of the view direction `v` about the
/// normal `n`.
///
/// Conventions: a light at `d = 0` contributes 0; `max(0, r.w)^e` is 0
/// whenever `r . w <= 0`, including for `e = 0` (so `e = 0` is the indicator
/// of the hemisphere around `r`). The model is applied as written for every
/// view: when `n . v < 0` (the eye below the surface) `r` points below the
/// tangent plane and lights there are reflected; a host shading two-sided
/// surfaces flips the normal towards the eye first. Lights below the tangent
/// plane are not culled by this term (the model has no `n . w` factor).
///
/// # The lobe's border, exactly
/// `n` and `v` are the given normal `N` and view `V` normalized exactly, so
/// `r` involves square roots; but `r.w` has the sign of `R.(x - p)` with
/// `R = 2 (N.V) N - (N.N) V = |N|^2 |V| r` ([`Mirror`]), a polynomial in the
/// given `f32` values. Each light's term decides that sign exactly (plain
/// `f64` when it is safely away from 0, then a compensated dot product,
/// then exact expansion arithmetic). So a
/// light on the border (`r.w = 0`) contributes exactly 0, also for `e = 0`
/// where the model jumps there, and no allowance is widened near the
/// border. The value: the cosine is `R.(x - p) / (|R| d)`, its numerator
/// taken in plain `f64` only while that error times `e` stays below
/// `2^-40` (compensated otherwise, within an ulp), `|R|` and `d` adding
/// about 10 ulps; for `e <= 512` the lobe inherits `e` times that, below
/// about `1.3e-12`, and an integer exponent up to 512 takes the power by
/// repeated multiplication, at most `e - 1` roundings more (`5.7e-14` at
/// 512; other exponents take `exp(e ln cos)`). Above
/// (exponents above 512),
/// lights near the axis take `1 - cos = sin^2 / (1 + cos)` from a
/// compensated cross product, which makes the lobe's relative error about
/// `|e ln cos|` times 30 ulps: every lobe that does not underflow is within
/// about `4e-12` relative, up to `e = 1e6`. A cosine below the
/// smallest positive `f64` (only for inputs whose coordinates span hundreds
/// of binary orders of magnitude) flushes the lobe to 0 when `e > 0`.
///
/// # Node bound
/// The paper's (slides "Specular Reflection"), valid whenever `D > R`: with
/// `alpha_c` the angle between `r` and the node's axis and `delta` the cone
/// half-angle,
///
/// ```text
/// I ks max(0, cos(alpha_c + delta))^e / (D + R)^2
///     <= exact <= I ks max(0, cos(max(0, alpha_c - delta)))^e / (D - R)^2
/// ```
///
/// with cosines from [`Cone::cos_range`] (sines and cosines, never `acos`,
/// whose error near 0 is raised to the `e`-th power). The distances are
/// tightened by the node's box, which also holds every member: `D - R` is
/// replaced by the larger of it and the box's nearest distance, `D + R` by
/// the smaller of it and the box's farthest corner
/// ([`Aabb::distance_range`](crate::Aabb::distance_range), rounded outward). The estimate is the
/// virtual light `I ks max(0, cos alpha_c)^e / D^2`. The power is taken in log
/// space when it would underflow, so no bound is lost to a `cos^e` that
/// flushed to zero while `I/d^2` is large; for an integer exponent up to
/// 512 it is otherwise taken by repeated multiplication, and both ends
/// move outward by `e f64::EPSILON`, twice its rounding. Among subnormal
/// values, where a rounding is absolute (up to half the smallest
/// subnormal), both ends also move outward by the smallest subnormal per
/// member light (the lower end not below 0). Exponents `0 <= e <= 1e6`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Phong {
    ks: DVec3,
    exponent: f64,
}

impl Phong {
    /// Largest supported exponent. Exponents above it are clamped by
    /// [`Phong::new`] and refused by [`Phong::try_new`]; `1e6` already makes
    /// a lobe narrower than 0.1 degree at half maximum.
    pub const MAX_EXPONENT: f64 = 1e6;

    /// Specular colour `ks` (each channel finite and `>= 0`) and exponent
    /// `e` in `[0, MAX_EXPONENT]`.
    ///
    /// Debug builds assert that the colour is valid and the exponent is not
    /// NaN or negative; release builds keep results finite by reading NaN or
    /// negative channels (and exponents) as 0 and infinite channels as
    /// `f32::MAX`. Exponents above [`MAX_EXPONENT`](Self::MAX_EXPONENT) are
    /// clamped in every build. [`Phong::try_new`] returns an error instead.
    #[must_use]
    pub fn new(ks: Vec3, exponent: f32) -> Self {
        let e = f64::from(exponent);
        debug_assert!(
            e >= 0.0,
            "Phong exponent must be >= 0, got {e} (use try_new for an error)"
        );
        Self {
            ks: colour_or_clamped(ks, "ks"),
            // `+ 0.0` also turns -0.0 into +0.0.
            exponent: if e.is_nan() {
                0.0
            } else {
                e.clamp(0.0, Self::MAX_EXPONENT) + 0.0
            },
        }
    }

    /// Like [`Phong::new`], but refuses bad parameters.
    ///
    /// # Errors
    /// [`ShadeError::InvalidMaterial`] for a NaN, infinite or negative
    /// channel of `ks`, or an exponent outside `[0, MAX_EXPONENT]`.
    pub fn try_new(ks: Vec3, exponent: f32) -> Result<Self, ShadeError> {
        let ks = try_colour(ks, "ks must be finite and >= 0")?;
        let e = f64::from(exponent);
        if !(0.0..=Self::MAX_EXPONENT).contains(&e) {
            return Err(ShadeError::InvalidMaterial(
                "exponent must lie in [0, MAX_EXPONENT]",
            ));
        }
        // `+ 0.0` turns an exponent of -0.0 into +0.0.
        Ok(Self {
            ks,
            exponent: e + 0.0,
        })
    }

    /// The specular colour.
    #[must_use]
    pub fn ks(&self) -> DVec3 {
        self.ks
    }

    /// The exponent.
    #[must_use]
    pub fn exponent(&self) -> f64 {
        self.exponent
    }

    /// The exponent as an integer if it is one of at most
    /// [`PHONG_SINE_ROUTE_ABOVE`] (the lobes [`eval`](Shader::eval) takes
    /// by repeated multiplication).
    #[inline]
    fn small_integer_exponent(&self) -> Option<u32> {
        let n = self.exponent as u32;
        (f64::from(n) == self.exponent && self.exponent <= PHONG_SINE_ROUTE_ABOVE).then_some(n)
    }

    /// `scale * cos^e` for `cos > 0` by repeated multiplication instead of
    /// `exp(e ln cos)` (at most `e - 1` roundings more, see [`power`]), for
    /// an integer exponent up to [`PHONG_SINE_ROUTE_ABOVE`] and a power
    /// that does not underflow; `None` otherwise (the log route).
    #[inline]
    fn lobe_by_power(&self, scale: DVec3, cos: f64) -> Option<DVec3> {
        let lobe = power(cos, self.small_integer_exponent()?);
        (lobe >= LOBE_LOG_SPACE_BELOW).then(|| scale * lobe)
    }

    /// `scale * max(0, cos)^e` per channel, without losing a product that is
    /// representable to an underflowing power.
    #[inline]
    fn lobe(&self, scale: DVec3, cos: f64) -> DVec3 {
        if !(cos > 0.0) {
            return DVec3::ZERO;
        }
        if self.exponent == 0.0 {
            return scale;
        }
        if let Some(lobe) = self.lobe_by_power(scale, cos) {
            return lobe;
        }
        self.lobe_from_log(scale, self.exponent * cos.ln())
    }

    /// `scale * exp(log_lobe)` per channel, in log space where the power
    /// alone would underflow.
    #[inline]
    fn lobe_from_log(&self, scale: DVec3, log_lobe: f64) -> DVec3 {
        let lobe = log_lobe.exp();
        if lobe >= LOBE_LOG_SPACE_BELOW {
            return scale * lobe;
        }
        let f = |s: f64| {
            if s > 0.0 {
                (log_lobe + s.ln()).exp()
            } else {
                0.0
            }
        };
        DVec3::new(f(scale.x), f(scale.y), f(scale.z))
    }
}

/// Phong's per-point data ([`Shader::PerPoint`]): the mirror direction of
/// the view about the normal, as a unit vector for the node bounds and,
/// unnormalized, for the exact sign of each light's cosine.
///
/// With `N` and `V` the normal and view exactly as given
/// ([`Surface::given_normal`], [`Surface::given_view`]), the unit mirror
/// direction `r = 2 (n.v) n - v` of their normalizations is `R / |R|` with
///
/// ```text
/// R = 2 (N.V) N - (N.N) V,     |R| = |N|^2 |V|,
/// ```
///
/// a polynomial in the given `f32` values: no square root stands between
/// the inputs and the sign of `R . (x - p)`, which is the sign of `r.w`.
/// `R` is kept as a double-double (each component within `4 u^2` of its
/// size, `u = 2^-53`), from its exact expansion. Zero without a view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mirror {
    /// Unit `r`, within a few ulps per component.
    unit: DVec3,
    /// Leading part of `R`: the largest component of its exact expansion.
    unnormalized_hi: DVec3,
    /// The rest of `R`, rounded: `|lo| <= 2u |hi|`.
    unnormalized_lo: DVec3,
    /// `|R| = |N|^2 |V|`, within a few ulps.
    unnormalized_length: f64,
}

impl Mirror {
    /// The mirror direction `r` of the view about the normal, unit (zero
    /// without a view).
    #[must_use]
    pub fn direction(&self) -> DVec3 {
        self.unit
    }

    /// `R x (x - p)`, each component a compensated `Dot2` of a permuted `R`
    /// with `x - p`: within `u` of itself plus `43 u^2 |R| |x - p|`
    /// ([`DOT2_ACCEPT`](crate::numeric::DOT2_ACCEPT), `u = 2^-53`).
    fn cross(&self, x: DVec3, p: DVec3) -> DVec3 {
        let (h, l) = (self.unnormalized_hi, self.unnormalized_lo);
        let component = |a: [f64; 3], b: [f64; 3]| dot2_value(a.into(), b.into(), x, p).0;
        DVec3::new(
            component([0.0, -h.z, h.y], [0.0, -l.z, l.y]),
            component([h.z, 0.0, -h.x], [l.z, 0.0, -l.x]),
            component([-h.y, h.x, 0.0], [-l.y, l.x, 0.0]),
        )
    }

    /// `R` and `|R|` for `surface`'s given normal and view.
    fn new(surface: &Surface) -> Self {
        let (n, v) = (surface.given_normal, surface.given_view);
        let mut hi = [0.0; 3];
        let mut lo = [0.0; 3];
        for j in 0..3 {
            let mut r_j = mirror_component(n, v, j);
            if let Some((&top, rest)) = r_j.expansion().split_last() {
                hi[j] = top;
                let mut rest_sum = ExactSum::<12>::new();
                rest.iter().for_each(|&c| rest_sum.add(c));
                lo[j] = rest_sum.value();
            }
        }
        let squared_length = |a: Vec3| {
            let mut sum = ExactSum::<6>::new();
            a.to_array()
                .map(f64::from)
                .iter()
                .for_each(|&c| sum.add_product(c, c));
            sum.value()
        };
        let length = squared_length(n) * squared_length(v).sqrt();
        let (hi, lo) = (DVec3::from(hi), DVec3::from(lo));
        Self {
            unit: if length > 0.0 {
                (hi + lo) / length
            } else {
                DVec3::ZERO
            },
            unnormalized_hi: hi,
            unnormalized_lo: lo,
            unnormalized_length: length,
        }
    }
}

/// Component `j` of `R = 2 (N.V) N - (N.N) V` as an exact sum of twelve
/// terms: each `N_i V_i` and `N_i N_i` is exact in `f64` (48 bits), each
/// product with a third `f32` value an exact TwoProduct pair.
fn mirror_component(n: Vec3, v: Vec3, j: usize) -> ExactSum<12> {
    let (n, v) = (n.as_dvec3(), v.as_dvec3());
    let mut sum = ExactSum::new();
    for i in 0..3 {
        sum.add_product(2.0 * (n[i] * v[i]), n[j]);
        sum.add_product(-(n[i] * n[i]), v[j]);
    }
    sum
}

/// `R . (x - p)` exactly summed (sign exact, within one ulp): the slow
/// path, for lights within about `2^-45` of the lobe's border.
#[cold]
#[inline(never)]
fn mirror_dot_exact(surface: &Surface, position: DVec3) -> f64 {
    let (n, v) = (surface.given_normal, surface.given_view);
    let [mut r_x, mut r_y, mut r_z] = [0, 1, 2].map(|j| mirror_component(n, v, j));
    // At most 12 components per coordinate, four terms each.
    exact_dot_of_difference::<144>(
        [r_x.expansion(), r_y.expansion(), r_z.expansion()],
        position,
        surface.point,
    )
}

impl Shader for Phong {
    /// The mirror direction, unit and unnormalized.
    type PerPoint = Mirror;

    #[inline]
    fn prepare(&self, surface: &Surface) -> Mirror {
        Mirror::new(surface)
    }

    /// The model's term `I ks max(0, r.w)^e / d^2`, with `r.w = R.(x - p) /
    /// (|R| d)` ([`Mirror`]). For a `position` holding `f32` values (every
    /// light's) the sign of `R.(x - p)` is exact: a light on or behind the
    /// lobe's border contributes exactly 0, also for `e = 0`. The value's
    /// accuracy is in [`Phong`]'s docs ("The lobe's border, exactly").
    #[inline]
    fn eval(&self, mirror: &Mirror, surface: &Surface, position: DVec3, intensity: DVec3) -> DVec3 {
        let (hi, lo) = (mirror.unnormalized_hi, mirror.unnormalized_lo);
        // Plain f64 when its relative error, times e (the lobe's
        // sensitivity to it), stays below 2^-40; else compensated; else
        // exact. Adding `lo . d` is one more rounding: `gamma_5` of the
        // magnitude instead of `gamma_4`, still below 2^-40 at the threshold.
        let (plain, magnitude) = plain_dot_of_difference(hi, position, surface.point);
        let plain = plain + lo.dot(position - surface.point);
        let along = if plain.abs() >= NAIVE_DOT_ACCEPT * self.exponent.max(1.0) * magnitude {
            plain
        } else {
            dot2_of_difference(hi, lo, position, surface.point)
                .unwrap_or_else(|| mirror_dot_exact(surface, position))
        };
        // On or behind the lobe's border nothing; a light on the shading
        // point (d = 0) has `along` exactly 0.
        if !(along > 0.0) {
            return DVec3::ZERO;
        }
        let d2 = (position - surface.point).length_squared();
        let scale = intensity * self.ks / d2;
        if self.exponent == 0.0 {
            // The indicator of the open half-space around r: no cosine
            // needed, so none can flush to zero.
            return scale;
        }
        let length_times_d = mirror.unnormalized_length * d2.sqrt();
        let cos = along / length_times_d;
        if let Some(lobe) = self.lobe_by_power(scale, cos) {
            return lobe;
        }
        let log_cos = if cos > 0.5 && self.exponent > PHONG_SINE_ROUTE_ABOVE {
            // Near the axis of a narrow lobe: ln cos = ln(1 - t) with
            // t = 1 - cos = sin^2 / (1 + cos), accurate however small.
            let sin = mirror.cross(position, surface.point) / length_times_d;
            (-(sin.length_squared() / (1.0 + cos))).ln_1p()
        } else {
            cos.ln()
        };
        self.lobe_from_log(scale, self.exponent * log_cos)
    }

    #[inline]
    fn bound(&self, mirror: &Mirror, surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        let r = mirror.unit;
        let (cos_lo, cos_hi) = cone.cos_range(r);
        if cos_hi <= 0.0 {
            return NodeEstimate::ZERO;
        }
        let inv_d = cone.inv_distance;
        let scale = node.intensity * self.ks * (inv_d * inv_d);
        // Every member lies in the ball and in the box: its distance is at
        // least the larger of D - R and the box's nearest distance, and at
        // most the smaller of D + R and the box's farthest corner.
        let (box_near, box_far) = node.aabb.distance_range(surface.point);
        let near_falloff = cone.near_falloff().min(square(cone.distance / box_near));
        let far_falloff = cone.far_falloff().max(square(cone.distance / box_far));
        // A lobe by repeated multiplication is within `(e - 1) u` of
        // itself (see `power`): the ends move outward by `2 e u`.
        let widen = if self.small_integer_exponent().is_some() {
            self.exponent * f64::EPSILON
        } else {
            0.0
        };
        // Among subnormals a term, a sum and each end are within half the
        // smallest one of their exact values, absolutely, which no relative
        // allowance covers (a lobe of a large exponent far off its axis
        // lives there): both ends move outward by the smallest subnormal
        // per member.
        let pad = DVec3::splat(f64::from(node.light_count) * f64::from_bits(1));
        NodeEstimate::new(
            self.lobe(scale, r.dot(cone.axis)),
            (self.lobe(scale * far_falloff, cos_lo) * (1.0 - widen) - pad).max(DVec3::ZERO),
            self.lobe(scale * near_falloff, cos_hi) * (1.0 + widen) + pad,
        )
    }
}

#[inline]
fn square(x: f64) -> f64 {
    x * x
}

/// `x^n` for `n >= 1` by binary powering: one rounding per multiplication,
/// and a product of two powers with relative errors of at most `(a - 1) u`
/// and `(b - 1) u` has at most `(a + b - 1) u` (to first order, `u =
/// 2^-53`), so `x^n` is within `(n - 1) u` of itself. For `x <= 1` every
/// power taken on the way is at least `x^n`: none underflows unless the
/// result does.
#[inline]
fn power(mut x: f64, mut n: u32) -> f64 {
    let mut out = 1.0;
    loop {
        if n & 1 == 1 {
            out *= x;
        }
        n >>= 1;
        if n == 0 {
            return out;
        }
        x *= x;
    }
}

#[cfg(test)]
mod tests {
    use super::power;

    /// `a b` in double-double arithmetic: `(hi, lo)` with `hi + lo` within
    /// a few `u^2` of the exact product, relatively.
    fn mul(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
        let p = a.0 * b.0;
        let e = a.0.mul_add(b.0, -p) + (a.0 * b.1 + a.1 * b.0);
        let hi = p + e;
        (hi, e - (hi - p))
    }

    /// `x^n` in double-double arithmetic, `(hi, lo)`: `hi + lo` within
    /// about `n u^2` of itself.
    fn reference(x: f64, n: u32) -> (f64, f64) {
        let (mut out, mut square, mut k) = ((1.0, 0.0), (x, 0.0), n);
        while k > 0 {
            if k & 1 == 1 {
                out = mul(out, square);
            }
            square = mul(square, square);
            k >>= 1;
        }
        out
    }

    proptest::proptest! {
        /// Binary powering stays within `(n - 1) u` of the power, `u =
        /// 2^-53`, as the lobe's error budget and the node bound's widening
        /// assume (cosines up to a few ulps above 1 included).
        #[test]
        fn power_is_within_n_minus_one_roundings(
            x in 0.25f64..=1.0 + 4.0 * f64::EPSILON,
            n in 1u32..=512,
        ) {
            let (exact, low) = reference(x, n);
            // Smaller lobes take the log route (`LOBE_LOG_SPACE_BELOW`).
            if exact < super::LOBE_LOG_SPACE_BELOW {
                return Ok(());
            }
            let u = f64::EPSILON / 2.0;
            let allowed = f64::from(n - 1) * u * exact * (1.0 + 1e-6);
            // The error against the double-double reference, not against
            // it rounded to `f64` (which would add up to half an ulp):
            // `power - exact` is exact for these neighbouring values
            // (Sterbenz), and subtracting `low` rounds once, far below
            // the allowance.
            let error = ((power(x, n) - exact) - low).abs();
            proptest::prop_assert!(
                error <= allowed,
                "{x}^{n}: {} against {exact} + {low}", power(x, n)
            );
        }
    }
}
