//! A leaf's lights one by one in `f64`: [`Lambert`]'s
//! [`Shader::eval_lights`] (each light's term, four side by side, in a copy
//! compiled for AVX2) and [`Shader::sum_lights`] (their sum, four lanes,
//! also written with AVX2 instructions), the very operations of
//! [`Shader::eval`] per light, so the same bits in every copy.

use glam::{DVec3, Vec3};

use super::Lambert;
use crate::PointLight;
use crate::dispatch::avx2_or;
use crate::geometry::Surface;
use crate::lanes::{Lanes, Vec3Lanes};
use crate::numeric::NAIVE_DOT_ACCEPT;
use crate::shader::Shader;

impl Lambert {
    /// [`Shader::eval_lights`]: on `x86_64` processors with AVX2, in a copy
    /// compiled for AVX2 (the same bits, see [`dispatch`](crate::dispatch)).
    /// Out of line, compiled once.
    // Not `with_avx2`: its closure stays out of line, with no AVX2 instructions (measured).
    #[inline(never)]
    pub(super) fn eval_group(&self, surface: &Surface, lights: &[PointLight], out: &mut [DVec3]) {
        avx2_or!(
            Self::eval_group_avx2,
            Self::eval_group_inlined,
            self,
            surface,
            lights,
            out
        );
    }

    /// [`eval_group`](Self::eval_group) compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
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
            let (height, magnitude) = d.plain_dot(normal.to_array());
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
    #[inline(never)]
    pub(super) fn sum_group(&self, surface: &Surface, lights: &[PointLight]) -> DVec3 {
        avx2_or!(
            Self::sum_group_avx2,
            Self::sum_group_baseline,
            self,
            surface,
            lights
        )
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
    #[target_feature(enable = "avx2,fma")]
    fn sum_group_avx2(&self, surface: &Surface, lights: &[PointLight]) -> DVec3 {
        use core::arch::x86_64::{
            __m256d, _CMP_GE_OQ, _CMP_GT_OQ, _mm256_add_pd, _mm256_and_pd, _mm256_andnot_pd,
            _mm256_cmp_pd, _mm256_div_pd, _mm256_movemask_pd, _mm256_mul_pd, _mm256_set1_pd,
            _mm256_setzero_pd, _mm256_sqrt_pd,
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
            let Four {
                h,
                magnitude,
                d2,
                intensity: [red, green, blue],
            } = four_lights(chunk, [nx, ny, nz], [px, py, pz]);
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
}

impl Lambert {
    /// [`Shader::sum_lights_plain`]: on `x86_64` processors with AVX2, in
    /// a copy compiled for AVX2 (the same bits). Out of line, compiled
    /// once.
    #[inline(never)]
    pub(super) fn sum_plain(&self, surface: &Surface, lights: &[PointLight]) -> (DVec3, DVec3) {
        avx2_or!(
            Self::sum_plain_avx2,
            Self::sum_plain_inlined,
            self,
            surface,
            lights
        )
    }

    /// [`sum_plain`](Self::sum_plain) with AVX2 vector instructions for
    /// the full chunks of four (loaded as [`sum_group`](Self::sum_group)'s
    /// AVX2 copy does), the same operations lane by lane as
    /// [`plain_lanes`], so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn sum_plain_avx2(&self, surface: &Surface, lights: &[PointLight]) -> (DVec3, DVec3) {
        use core::arch::x86_64::{
            __m256d, _CMP_GE_OQ, _mm256_add_pd, _mm256_blendv_pd, _mm256_cmp_pd, _mm256_div_pd,
            _mm256_mul_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_sqrt_pd,
        };
        let terms = LightTerms::new(surface);
        let n2 = _mm256_set1_pd(terms.n2);
        let [nx, ny, nz] = terms.normal.to_array().map(|v| _mm256_set1_pd(v));
        let [px, py, pz] = terms.point.to_array().map(|v| _mm256_set1_pd(v));
        let below = _mm256_set1_pd(-PLAIN_HEIGHT_ERROR);
        let zero = _mm256_setzero_pd();
        // `if a >= b { 0 } else { x }`, as `Lanes::select_ge(a, b, 0, x)`.
        let zero_where_ge = |a: __m256d, b: __m256d, x: __m256d| {
            _mm256_blendv_pd(x, zero, _mm256_cmp_pd::<_CMP_GE_OQ>(a, b))
        };
        let mut acc = [zero; 6];
        let chunks = lights.chunks_exact(4);
        let rest = chunks.remainder();
        for chunk in chunks {
            let Four {
                h,
                magnitude,
                d2,
                intensity: [red, green, blue],
            } = four_lights(chunk, [nx, ny, nz], [px, py, pz]);
            let denominator = _mm256_mul_pd(d2, _mm256_sqrt_pd(_mm256_mul_pd(n2, d2)));
            let weight = zero_where_ge(zero, h, _mm256_div_pd(h, denominator));
            let spread = zero_where_ge(
                _mm256_mul_pd(below, magnitude),
                h,
                zero_where_ge(zero, magnitude, _mm256_div_pd(magnitude, denominator)),
            );
            for (k, e) in [red, green, blue].into_iter().enumerate() {
                acc[k] = _mm256_add_pd(acc[k], _mm256_mul_pd(e, weight));
                acc[3 + k] = _mm256_add_pd(acc[3 + k], _mm256_mul_pd(e, spread));
            }
        }
        let lanes = |v: __m256d| Lanes::<4>::from_fn(|i| crate::dispatch::lane_of(v, i));
        let mut sums = [lanes(acc[0]), lanes(acc[1]), lanes(acc[2])];
        let mut envelopes = [lanes(acc[3]), lanes(acc[4]), lanes(acc[5])];
        if !rest.is_empty() {
            plain_lanes(&terms, rest, &mut sums, &mut envelopes);
        }
        self.plain_total(lights.len(), sums, envelopes)
    }

    /// The plain `f64` sum of `lights`' terms, four lanes, and a certified
    /// bound on its error (see [`PLAIN_HEIGHT_ERROR`]): every term as
    /// `I max(0, h) / (d^2 sqrt(|N|^2 d^2))` from the plain heights `h`
    /// and their magnitudes `M`, whatever their cancellation, beside the
    /// envelope `I M / (d^2 sqrt(|N|^2 d^2))` of the lights whose height
    /// may be positive (a computed `h > -PLAIN_HEIGHT_ERROR M`).
    #[inline(always)]
    fn sum_plain_inlined(&self, surface: &Surface, lights: &[PointLight]) -> (DVec3, DVec3) {
        let zero = Lanes::<4>::of(0.0);
        let (mut sums, mut envelopes) = ([zero; 3], [zero; 3]);
        for chunk in lights.chunks(4) {
            plain_lanes(&LightTerms::new(surface), chunk, &mut sums, &mut envelopes);
        }
        self.plain_total(lights.len(), sums, envelopes)
    }

    /// The lanes' sums and envelopes of `count` lights added up, times
    /// `kd`, and the bound they give.
    #[inline(always)]
    fn plain_total(
        &self,
        count: usize,
        sums: [Lanes<4>; 3],
        envelopes: [Lanes<4>; 3],
    ) -> (DVec3, DVec3) {
        let total = |v: Lanes<4>| (v.0[0] + v.0[1]) + (v.0[2] + v.0[3]);
        let sum = self.kd * DVec3::from_array(sums.map(total));
        let envelope = self.kd * DVec3::from_array(envelopes.map(total));
        let roundings = (count + PLAIN_SUM_ROUNDINGS) as f64 * f64::EPSILON / 2.0;
        let error = (envelope * PLAIN_HEIGHT_ERROR + sum * roundings) * (1.0 + PLAIN_SLACK);
        (sum, error)
    }
}

/// At most four `lights` (light `i` in lane `i`) added to the lanes' plain
/// sums and envelopes (see `Lambert::sum_plain_inlined`).
#[inline(always)]
fn plain_lanes(
    terms: &LightTerms,
    chunk: &[PointLight],
    sums: &mut [Lanes<4>; 3],
    envelopes: &mut [Lanes<4>; 3],
) {
    const L: usize = 4;
    let (n, p) = (terms.normal, terms.point.to_array());
    let zero = Lanes::<L>::of(0.0);
    // A short chunk repeats its last light, dark, in the unused lanes.
    let last = chunk.len() - 1;
    let position = Vec3Lanes::<L>::from_fn(|i| chunk[i.min(last)].position.as_dvec3().to_array());
    let dark = |i: usize| if i < chunk.len() { 1.0 } else { 0.0 };
    let light = |i: usize| chunk[i.min(last)].intensity;
    let intensity = [
        Lanes::<L>::from_fn(|i| f64::from(light(i).x) * dark(i)),
        Lanes::<L>::from_fn(|i| f64::from(light(i).y) * dark(i)),
        Lanes::<L>::from_fn(|i| f64::from(light(i).z) * dark(i)),
    ];
    let d = position.minus(p);
    let (tx, ty, tz) = (n.x * d.x, n.y * d.y, n.z * d.z);
    let h = (tx + ty) + tz;
    let magnitude = (tx.abs() + ty.abs()) + tz.abs();
    let d2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
    let denominator = d2 * (terms.n2 * d2).sqrt();
    // 0 where the height is not positive (and for a light on the point,
    // where both quotients are 0 / 0).
    let weight = Lanes::select_ge(zero, h, zero, h / denominator);
    // The envelope, where the height may be positive: below
    // `-PLAIN_HEIGHT_ERROR M` the exact height is negative too, and the
    // term exactly 0 (as computed).
    let spread = Lanes::select_ge(
        -PLAIN_HEIGHT_ERROR * magnitude,
        h,
        zero,
        Lanes::select_ge(zero, magnitude, zero, magnitude / denominator),
    );
    for k in 0..3 {
        sums[k] += intensity[k] * weight;
        envelopes[k] += intensity[k] * spread;
    }
}

/// Four lights' heights `h = N . (x - p)` as plain `f64` sums of products,
/// their magnitudes `sum_j |N_j (x_j - p_j)|`, squared distances and
/// intensities, one lane a light: the loads and operations the AVX2 copies
/// of [`Lambert`]'s sums share.
#[cfg(target_arch = "x86_64")]
struct Four {
    h: core::arch::x86_64::__m256d,
    magnitude: core::arch::x86_64::__m256d,
    d2: core::arch::x86_64::__m256d,
    intensity: [core::arch::x86_64::__m256d; 3],
}

/// [`Four`] of the four lights of `chunk`, for the normal `n` and the point
/// `p` in every lane: each light's `(x, y, z, red)` and `(green, blue)`
/// transposed to one vector per quantity, then the same operations lane
/// by lane as [`LightTerms::weight`] and [`plain_lanes`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn four_lights(
    chunk: &[PointLight],
    n: [core::arch::x86_64::__m256d; 3],
    p: [core::arch::x86_64::__m256d; 3],
) -> Four {
    use core::arch::x86_64::{
        __m128, __m256d, _mm_movehl_ps, _mm_movelh_ps, _mm_set_ps, _mm_unpackhi_ps,
        _mm_unpacklo_ps, _mm256_add_pd, _mm256_andnot_pd, _mm256_cvtps_pd, _mm256_mul_pd,
        _mm256_set1_pd, _mm256_sub_pd,
    };
    let sign = _mm256_set1_pd(-0.0);
    // |v|: the sign bit cleared.
    let strip = |v: __m256d| _mm256_andnot_pd(sign, v);
    let row = |l: &PointLight| _mm_set_ps(l.intensity.x, l.position.z, l.position.y, l.position.x);
    let [a, b, c, d] = [
        row(&chunk[0]),
        row(&chunk[1]),
        row(&chunk[2]),
        row(&chunk[3]),
    ];
    let (ab_lo, ab_hi) = (_mm_unpacklo_ps(a, b), _mm_unpackhi_ps(a, b));
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
        _mm256_sub_pd(x, p[0]),
        _mm256_sub_pd(y, p[1]),
        _mm256_sub_pd(z, p[2]),
    );
    let (tx, ty, tz) = (
        _mm256_mul_pd(n[0], dx),
        _mm256_mul_pd(n[1], dy),
        _mm256_mul_pd(n[2], dz),
    );
    Four {
        h: _mm256_add_pd(_mm256_add_pd(tx, ty), tz),
        magnitude: _mm256_add_pd(_mm256_add_pd(strip(tx), strip(ty)), strip(tz)),
        d2: _mm256_add_pd(
            _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
            _mm256_mul_pd(dz, dz),
        ),
        intensity: [red, green, blue],
    }
}

/// The bound on a plain `f64` height's error, per unit of its magnitude:
/// `8u`, `u = 2^-53`. A light's height `h = N . (x - p)` computed as one
/// rounded difference, one product and two additions per coordinate is
/// within `gamma_4 T` of the exact one (Higham 2002, 3.1), `T = sum_j
/// |N_j| |x_j - p_j|`, and the computed magnitude `M` is at least `(1 -
/// gamma_4) T`, so the error is at most `4.001u M`; `max(0, .)` does not
/// increase it, and the rounded division by the denominator and the
/// product with the intensity add at most `3u` of it. Twice the `4.01u`
/// that leaves.
const PLAIN_HEIGHT_ERROR: f64 = 8.0 * f64::EPSILON / 2.0;

/// Roundings, beyond one per light, that bound the relative error of a
/// plain sum's value as a sum of exact-height terms: the denominator (at
/// most 12 roundings: the differences, squares and sums of `d^2`, `|N|^2`,
/// the product, the square root and the last product), the division and
/// the product with the intensity, the lanes' last two additions and the
/// product with `kd`: 18, with room to spare. The lanes' own sums take one
/// rounding per light.
const PLAIN_SUM_ROUNDINGS: usize = 24;

/// The relative slack on a plain sum's bound for the bound's own rounding:
/// `2^-40`.
const PLAIN_SLACK: f64 = 1.0 / (1u64 << 40) as f64;

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

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use crate::dispatch::baseline;
    use crate::shader::{Seal, Shader, Surface};
    use crate::{Lambert, PointLight};

    /// The lights' terms summed one by one, compensated.
    fn exact_sum(lambert: &Lambert, surface: &Surface, lights: &[PointLight]) -> glam::DVec3 {
        let mut exact = crate::numeric::CompensatedSum::default();
        for light in lights {
            exact.add(lambert.eval(
                &(),
                surface,
                light.position.as_dvec3(),
                light.intensity.as_dvec3(),
            ));
        }
        exact.value()
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
            let exact = exact_sum(&lambert, &surface, &lights);
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

    /// The plain sum with its bound against the compensated sum of `eval`
    /// (within the bound, up to the terms' own `2^-40`), for every count
    /// from 0 to 64 (full and short chunks of four): lights exactly in a
    /// plane through the point with a normal `1e-7` to `1e-3` off the
    /// plane's, lights within `1e-9` to `1e-3` of the tangent plane on
    /// either side, on the point, and far off it, with a tilted normal of
    /// any length; the AVX2 copy and
    /// the baseline give the same bits. Lights near the plane make the
    /// bound positive; lights clearly below add nothing to it.
    #[test]
    fn plain_sums_hold_their_bounds() {
        let mut state = 23u64;
        let mut uniform = move || crate::testing::uniform(&mut state);
        let lambert = Lambert::new(Vec3::new(0.9, 0.5, 0.25));
        let (mut near, mut below) = (0, 0);
        for round in 0..600 {
            let count = round % 65;
            let side = match round % 3 {
                0 => -1.0,
                1 => 1.0,
                _ => 0.0,
            };
            // In the plane: points and lights exactly on x + y + z = 0
            // (multiples of 1/64), the normal `e` off the plane's.
            let on_plane = |u: f32, v: f32| {
                let (x, y) = (
                    ((u - 0.5) * 640.0).round() / 64.0,
                    ((v - 0.5) * 640.0).round() / 64.0,
                );
                Vec3::new(x, y, -(x + y))
            };
            let p = if side == 0.0 {
                on_plane(uniform(), uniform())
            } else {
                Vec3::new(uniform() * 8.0, uniform() * 8.0, uniform() * 2.0) - 4.0
            };
            let normal = if side == 0.0 {
                Vec3::new(1.0, 1.0, 1.0 + 10f32.powf(-7.0 + 4.0 * uniform()))
            } else {
                Vec3::new(uniform() - 0.5, uniform() - 0.5, 1.0) * (0.1 + 3.0 * uniform())
            };
            let surface = Surface::new(p, normal, None).unwrap();
            let n = normal.normalize();
            let lights: Vec<PointLight> = (0..count)
                .map(|i| {
                    if side == 0.0 && i % 4 != 3 {
                        let (u, v) = (uniform(), uniform());
                        return PointLight::new(on_plane(u, v), Vec3::new(1.0, 2.0, 0.5));
                    }
                    let offset =
                        Vec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5) * 20.0;
                    let flat = offset - n * offset.dot(n);
                    let height = 10f32.powf(-9.0 + 6.0 * uniform());
                    let position = match (round + i) % 5 {
                        0 if i == 0 => p,
                        0 | 1 => p + flat + n * height * side,
                        2 => p + flat - n * height,
                        _ => p + offset,
                    };
                    PointLight::new(
                        position,
                        Vec3::new(uniform(), uniform() * 4.0, uniform() * 0.1),
                    )
                })
                .collect();
            let exact = exact_sum(&lambert, &surface, &lights);
            let (sum, error) = lambert
                .sum_lights_plain(Seal, &(), &surface, &lights)
                .unwrap();
            let (b_sum, b_error) = baseline(|| {
                lambert
                    .sum_lights_plain(Seal, &(), &surface, &lights)
                    .unwrap()
            });
            assert_eq!(
                [sum, error].map(|v| v.to_array().map(f64::to_bits)),
                [b_sum, b_error].map(|v| v.to_array().map(f64::to_bits))
            );
            for k in 0..3 {
                assert!(
                    sum[k] >= 0.0 && error[k] >= 0.0,
                    "round {round}: {sum} {error}"
                );
                assert!(
                    (sum[k] - exact[k]).abs() <= error[k] + 1e-12 * exact[k],
                    "round {round}, {count} lights: {sum} +- {error} against {exact}"
                );
            }
            // The roundings' part of the bound alone, and more where some
            // height's envelope entered it.
            let roundings = (count + super::PLAIN_SUM_ROUNDINGS) as f64 * f64::EPSILON;
            if count > 0 && side == 0.0 && error.x > roundings * sum.x {
                near += 1;
            }
            if count > 0 && side < 0.0 && error.x <= roundings * sum.x {
                below += 1;
            }
        }
        assert!(near > 20 && below > 20, "{near} near, {below} below");
    }
}
