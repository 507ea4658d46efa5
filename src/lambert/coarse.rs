//! [`Lambert`](crate::Lambert)'s sum of visible lights in `f32`, eight
//! lights side by side, with a certified bound on its error (see
//! [`Shader::sum_lights_coarse`](crate::shader::Shader::sum_lights_coarse)).
//!
//! # The rounding
//!
//! Write `u = 2^-24`, `D` for the exact distance from the point `p` to a
//! light `l`, `n` for the unit normal and `I` for a channel's intensity. The
//! point and the light are `f32` values, the unit normal (the surface's,
//! within a few `f64` ulps) is rounded to `f32` componentwise (within
//! `1.0001 u` of each component), and every operation
//! below is correctly rounded, so to first order in `u` (the constants are
//! rounded up past the second-order terms):
//!
//! * `d = l - p`, componentwise within `u |d_j|`;
//! * the height `h = (n_x d_x + n_y d_y) + n_z d_z`: each product within
//!   `3u` of `n_j d_j`, the two sums `2u` more of the magnitudes, so
//!   within `5.001 u D` of the exact height (`sum_j |n_j d_j| <= D`);
//! * `d2 = (d_x^2 + d_y^2) + d_z^2` within `5.001 u D^2`; its reciprocal
//!   `v = 1 / d2` within `6.002 u / D^2`; `t = sqrt(v)` within `4.002 u /
//!   D`; `r = v t` within `11.01 u / D^3` (one division and one square
//!   root for each eight lights);
//! * `w = max(h r, 0)`, the clamp being 1-Lipschitz: within `(5.001 +
//!   11.01 + 1) u (1 + 12u) / D^2 <= 17.1 u / D^2` of the exact
//!   `max(cos, 0) / D^2` (the height is at most `D`);
//! * the term `I w` within `18.2 u I / D^2`;
//! * a lane's sum of its terms, then the lanes' sums (three pairwise
//!   levels): at most `m + 2` roundings for `m` terms a lane, at most
//!   [`COARSE_MAX`]` / 8 + 2 = 10`, each within `u` of the sum of the
//!   terms' magnitudes (at most `1.00002 I / D^2` each).
//!
//! So the sum is within `28.3 u E` of the exact sum, per channel, with `E =
//! sum I / D^2` over the lights. The same lanes sum `e = max_k I_k v`
//! (each within `7.003 u` of `max_k I_k / D^2`, all positive, then at most
//! ten roundings), so the computed `E'` is at least `E (1 - 17.01 u)`, and
//! `28.4 u E'` bounds the error; [`ERROR_UNITS`] `= 32` leaves a margin.
//! `kd` multiplies sum and bound in `f64`.
//!
//! Lights surely below the tangent plane add nothing to `E`: where the
//! computed `c = h t` is below `-8u`, `h < -8u D (1 - 5.01 u) < -7.9 u D`
//! (as `t` is within `4.002 u / D` of `1 / D`), so the exact height is
//! below `-2.9 u D`, negative: the exact term is 0, and the computed one is
//! `max(h r, 0) = +0` (`h < 0 < r`), which adds nothing to a lane's sum nor
//! to its roundings, nor to the underflow. The sum over the other lights is
//! the whole sum, so `E` need only run over them: `e` adds `max_k I_k v`
//! only where `c >= -8u`. Where every light is surely below the plane, the
//! sum is exactly 0 with a bound of 0 (no underflow allowance either). A
//! point on a wall sees about half of a nearby group of lights behind it;
//! without this, their `1 / D^2` would make the bound a large share of the
//! sum, and the caller would sum them again in `f64`.
//!
//! Range: every lane must have `2^-60 <= d2 <= 2^60` and `max_k I_k <=
//! 2^40`, or the sum returns `None` (the caller then sums in `f64`); then
//! nothing overflows (a term is at most `2^100`, a sum of 64 at most
//! `2^106`, `r` at most `2^90`). Underflow moves a product by at most
//! `2^-150` (sums of subnormal values are exact): at most `2^-126 I` of
//! `I w` against the `2^-80 I` the relative bound allows at the largest
//! distance, except for the product `I w` itself and the envelope's `e`,
//! so the bound adds `2^-140` per light (times `kd`; but see below).
//!
//! # Whole scenes
//!
//! A small scene's lights, side by side, are summed in one call
//! ([`sum_scene_lanes_baseline`] and its AVX2 copy): in blocks of
//! [`COARSE_MAX`] lights as above, each block's eight lane sums (per
//! channel, and the envelope's) converted to `f64` (exactly) and added,
//! lane by lane, to lanes of `f64` carried from block to block, whose eight
//! lanes are added pairwise at the end. Within a block a lane's sum takes
//! at most 8 roundings, fewer than the analysis above allows, so each
//! block's sum is within `28.3 u` of its `E` and the envelope within
//! `17.01 u` of it as before. The `f64` additions (at most `B + 2` on any
//! term's way for `B` blocks) are each within `2^-53` of their result,
//! itself at most `1.00002 E`: so within `(B + 2) 2^-53 E`, inside the
//! margin that [`ERROR_UNITS`] leaves above `28.4 u` (`3.6 u`, about
//! `2^-22`) for fewer than `2^36` lights (the cut passes at most 1,024,
//! whose additions take under `2^-48 E`). So the bound is the one above,
//! and the range conditions are the same, every block's.

use glam::{DVec3, Vec3};

use crate::geometry::Surface;
use crate::{LightLanes, PointLight};

/// The most lights one call sums (eight a lane at most, see the module
/// docs).
pub(crate) const COARSE_MAX: usize = 64;

/// Lanes summed side by side.
const LANES: usize = 8;

/// The bound, in units of `2^-24` times the computed envelope.
const ERROR_UNITS: f64 = 32.0;

/// `2^-24`.
const U: f64 = 1.0 / 16_777_216.0;

/// Absolute allowance per light for underflow (module docs).
const UNDERFLOW: f64 = 7.174_648_137_343_064e-43; // 2^-140

/// `-8u`: lights whose computed `h t` lies below it are below the tangent
/// plane, exactly 0, and left out of the envelope (module docs).
const BELOW: f32 = -8.0 / 16_777_216.0;

/// The range every lane must be in (module docs).
const D2_MIN: f32 = 1.0 / 1_152_921_504_606_846_976.0; // 2^-60
const D2_MAX: f32 = 1_152_921_504_606_846_976.0; // 2^60
const INTENSITY_MAX: f32 = 1_099_511_627_776.0; // 2^40

/// Per lane: the three channels' sums, the envelope's, and whether every
/// light so far was in range; whether any light was not surely below the
/// plane.
struct Sums {
    rgb: [[f32; LANES]; 3],
    envelope: [f32; LANES],
    in_range: bool,
    any: bool,
}

/// The point and the unit normal in `f32`, or `None` when the point is not
/// an `f32` value.
struct Frame {
    point: Vec3,
    normal: Vec3,
}

impl Frame {
    #[inline(always)]
    fn new(surface: &Surface) -> Option<Self> {
        let point = surface.point.as_vec3();
        // The unit normal in `f64` (within a few of its ulps), rounded.
        let normal = surface.normal.as_vec3();
        (point.as_dvec3() == surface.point && normal.is_finite()).then_some(Self { point, normal })
    }

    /// One light's operations, added to lane `lane`: the same, operation by
    /// operation, as one lane of the AVX2 copy.
    #[inline(always)]
    fn add(&self, light: &PointLight, lane: usize, sums: &mut Sums) {
        let d = light.position - self.point;
        let n = self.normal;
        let h = (n.x * d.x + n.y * d.y) + n.z * d.z;
        let d2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
        let v = 1.0 / d2;
        let t = v.sqrt();
        let hr = h * (v * t);
        let w = if hr > 0.0 { hr } else { 0.0 };
        let i = light.intensity;
        let largest = max(max(i.x, i.y), i.z);
        for (sum, i) in sums.rgb.iter_mut().zip(i.to_array()) {
            sum[lane] += i * w;
        }
        // Lights surely below the plane are left out (module docs).
        let counted = h * t >= BELOW;
        sums.envelope[lane] += if counted { largest * v } else { 0.0 };
        sums.any |= counted;
        sums.in_range &= (D2_MIN..=D2_MAX).contains(&d2) && largest <= INTENSITY_MAX;
    }

    /// `kd` times the lanes' sums, each added as `((l0 + l1) + (l2 + l3)) +
    /// ((l4 + l5) + (l6 + l7))`, and the bound (module docs), or `None`
    /// out of range.
    #[inline(always)]
    fn total(sums: &Sums, kd: DVec3, lights: usize) -> Option<(DVec3, DVec3)> {
        if !sums.in_range {
            return None;
        }
        let add =
            |s: &[f32; LANES]| ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]));
        Self::finish(
            sums.rgb.each_ref().map(add),
            add(&sums.envelope),
            kd,
            sums.any,
            lights,
        )
    }

    /// `kd` times the summed channels, and the bound from the summed
    /// envelope and the number of lights, or none where no light was counted
    /// (module docs).
    #[inline(always)]
    fn finish(
        rgb: [f32; 3],
        envelope: f32,
        kd: DVec3,
        counted: bool,
        lights: usize,
    ) -> Option<(DVec3, DVec3)> {
        let [r, g, b] = rgb.map(f64::from);
        let lights = if counted { lights } else { 0 };
        let error =
            (ERROR_UNITS * U * f64::from(envelope) + lights as f64 * UNDERFLOW) * (1.0 + 1e-12);
        // With `kd`'s products' own rounding (`2^-53` relative).
        let sum = kd * DVec3::new(r, g, b);
        Some((sum, kd * error * (1.0 + 1e-12) + sum * 1e-15))
    }
}

/// `a` if it is larger, else `b` (the AVX2 instruction's order).
#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The sum and its bound (module docs), light `i` in lane `i % 8`; `None`
/// for more than [`COARSE_MAX`] lights, a point that is not an `f32`
/// value, or lights out of range.
pub(crate) fn sum_baseline(
    kd: DVec3,
    surface: &Surface,
    lights: &[PointLight],
) -> Option<(DVec3, DVec3)> {
    if lights.len() > COARSE_MAX {
        return None;
    }
    let frame = Frame::new(surface)?;
    let mut sums = Sums {
        rgb: [[0.0; LANES]; 3],
        envelope: [0.0; LANES],
        in_range: true,
        any: false,
    };
    for (i, light) in lights.iter().enumerate() {
        frame.add(light, i % LANES, &mut sums);
    }
    Frame::total(&sums, kd, lights.len())
}

/// Lights a block of a whole scene's sum takes (module docs, "Whole
/// scenes"): eight groups of eight lanes.
const BLOCK_GROUPS: usize = COARSE_MAX / LANES;

/// A whole scene's sum takes fewer lights than this (module docs, "Whole
/// scenes"): `2^36`.
const SCENE_LIGHTS_LIMIT: u64 = 1 << 36;

/// A whole scene's lane sums, per channel and the envelope's, carried in
/// `f64` from block to block (module docs, "Whole scenes").
type Wide = [[f64; LANES]; 4];

/// The eight lanes of `wide` added pairwise, `((l0 + l1) + (l2 + l3)) +
/// ((l4 + l5) + (l6 + l7))`, per quantity.
#[inline(always)]
fn wide_totals(wide: &Wide) -> [f64; 4] {
    wide.map(|s| ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7])))
}

/// `kd` times the summed channels and the bound, as [`Frame::finish`],
/// from the `f64` totals of a whole scene (module docs, "Whole scenes").
#[inline(always)]
fn finish_wide(
    [r, g, b, envelope]: [f64; 4],
    kd: DVec3,
    counted: bool,
    lights: usize,
) -> (DVec3, DVec3) {
    let lights = if counted { lights } else { 0 };
    let error = (ERROR_UNITS * U * envelope + lights as f64 * UNDERFLOW) * (1.0 + 1e-12);
    let sum = kd * DVec3::new(r, g, b);
    (sum, kd * error * (1.0 + 1e-12) + sum * 1e-15)
}

/// The sum of a whole scene of `count` lights side by side in `lanes`
/// (light `i` in lane `i % 8` of `lanes[i / 8]`) and its bound, in blocks
/// of [`COARSE_MAX`] lights (module docs, "Whole scenes"); `None` for more
/// lights than the lanes hold (or `2^36` or more), a point that is not an
/// `f32` value, or lights out of range.
pub(crate) fn sum_scene_lanes_baseline(
    kd: DVec3,
    surface: &Surface,
    lanes: &[LightLanes],
    count: usize,
) -> Option<(DVec3, DVec3)> {
    if count > lanes.len() * LANES || count as u64 >= SCENE_LIGHTS_LIMIT {
        return None;
    }
    let frame = Frame::new(surface)?;
    let mut wide: Wide = [[0.0; LANES]; 4];
    let (mut in_range, mut any) = (true, false);
    let groups = &lanes[..count.div_ceil(LANES)];
    for (b, block) in groups.chunks(BLOCK_GROUPS).enumerate() {
        let mut sums = Sums {
            rgb: [[0.0; LANES]; 3],
            envelope: [0.0; LANES],
            in_range: true,
            any: false,
        };
        let first = b * COARSE_MAX;
        for i in 0..(count - first).min(COARSE_MAX) {
            let (group, k) = (&block[i / LANES], i % LANES);
            let light = PointLight::new(
                Vec3::new(group.x[k], group.y[k], group.z[k]),
                Vec3::new(group.red[k], group.green[k], group.blue[k]),
            );
            frame.add(&light, k, &mut sums);
        }
        in_range &= sums.in_range;
        any |= sums.any;
        for (wide, lanes) in wide.iter_mut().zip(sums.rgb.iter().chain([&sums.envelope])) {
            for (w, &s) in wide.iter_mut().zip(lanes) {
                *w += f64::from(s);
            }
        }
    }
    in_range.then(|| finish_wide(wide_totals(&wide), kd, any, count))
}

/// The AVX2 sums of [`sum_avx2`] and [`sum_lanes_avx2`]: per lane, the
/// operations of [`Frame::add`] (no fused multiply-add), so the same bits
/// as the baseline. The range is checked in every lane added, those left
/// out included: they repeat a light that is added.
#[cfg(target_arch = "x86_64")]
struct Sums8 {
    point: [core::arch::x86_64::__m256; 3],
    normal: [core::arch::x86_64::__m256; 3],
    rgb: [core::arch::x86_64::__m256; 3],
    envelope: core::arch::x86_64::__m256,
    any: core::arch::x86_64::__m256,
    /// All bits set in the lanes whose every light so far was in range.
    in_range: core::arch::x86_64::__m256,
}

#[cfg(target_arch = "x86_64")]
impl Sums8 {
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn new(frame: &Frame) -> Self {
        use core::arch::x86_64::{_CMP_LE_OQ, _mm256_cmp_ps, _mm256_set1_ps, _mm256_setzero_ps};
        let zero = _mm256_setzero_ps();
        Self {
            point: frame.point.to_array().map(|v| _mm256_set1_ps(v)),
            normal: frame.normal.to_array().map(|v| _mm256_set1_ps(v)),
            rgb: [zero; 3],
            envelope: zero,
            any: zero,
            in_range: _mm256_cmp_ps::<_CMP_LE_OQ>(zero, zero),
        }
    }

    /// Eight lights' terms (`x, y, z, red, green, blue`, one vector each),
    /// added to the lanes that `mask` keeps (all for `None`).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn add(
        &mut self,
        [x, y, z, red, green, blue]: [core::arch::x86_64::__m256; 6],
        mask: Option<core::arch::x86_64::__m256>,
    ) {
        use core::arch::x86_64::{
            __m256, _CMP_GE_OQ, _CMP_LE_OQ, _mm256_add_ps, _mm256_and_ps, _mm256_cmp_ps,
            _mm256_div_ps, _mm256_max_ps, _mm256_mul_ps, _mm256_or_ps, _mm256_set1_ps,
            _mm256_setzero_ps, _mm256_sqrt_ps, _mm256_sub_ps,
        };
        let ([px, py, pz], [nx, ny, nz]) = (self.point, self.normal);
        let (dx, dy, dz) = (
            _mm256_sub_ps(x, px),
            _mm256_sub_ps(y, py),
            _mm256_sub_ps(z, pz),
        );
        let h = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(nx, dx), _mm256_mul_ps(ny, dy)),
            _mm256_mul_ps(nz, dz),
        );
        let d2 = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
            _mm256_mul_ps(dz, dz),
        );
        // One division and one square root per eight lights (module docs).
        let v = _mm256_div_ps(_mm256_set1_ps(1.0), d2);
        let t = _mm256_sqrt_ps(v);
        let cube = _mm256_mul_ps(v, t);
        let w = _mm256_max_ps(_mm256_mul_ps(h, cube), _mm256_setzero_ps());
        let largest = _mm256_max_ps(_mm256_max_ps(red, green), blue);
        let kept = |v: __m256| match mask {
            Some(mask) => _mm256_and_ps(v, mask),
            None => v,
        };
        for (sum, channel) in self.rgb.iter_mut().zip([red, green, blue]) {
            *sum = _mm256_add_ps(*sum, kept(_mm256_mul_ps(channel, w)));
        }
        // Lights surely below the plane are left out (module docs).
        let counted = _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_mul_ps(h, t), _mm256_set1_ps(BELOW));
        let envelope = _mm256_and_ps(_mm256_mul_ps(largest, v), counted);
        self.envelope = _mm256_add_ps(self.envelope, kept(envelope));
        self.any = _mm256_or_ps(self.any, kept(counted));
        let ok = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(d2, _mm256_set1_ps(D2_MIN)),
                _mm256_cmp_ps::<_CMP_LE_OQ>(d2, _mm256_set1_ps(D2_MAX)),
            ),
            _mm256_cmp_ps::<_CMP_LE_OQ>(largest, _mm256_set1_ps(INTENSITY_MAX)),
        );
        self.in_range = _mm256_and_ps(self.in_range, ok);
    }

    /// Adds the lanes' sums of the channels and of the envelope to the
    /// `f64` lanes `wide` (`wide[2 q]` lanes 0 to 3 of quantity `q`,
    /// `wide[2 q + 1]` lanes 4 to 7) and clears them; the range and the
    /// lights counted carry on (module docs, "Whole scenes").
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn flush(&mut self, wide: &mut [core::arch::x86_64::__m256d; 8]) {
        use core::arch::x86_64::{
            _mm256_add_pd, _mm256_castps256_ps128, _mm256_cvtps_pd, _mm256_extractf128_ps,
            _mm256_setzero_ps,
        };
        let [r, g, b] = self.rgb;
        for (q, v) in [r, g, b, self.envelope].into_iter().enumerate() {
            let low = _mm256_cvtps_pd(_mm256_castps256_ps128(v));
            let high = _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v));
            wide[2 * q] = _mm256_add_pd(wide[2 * q], low);
            wide[2 * q + 1] = _mm256_add_pd(wide[2 * q + 1], high);
        }
        self.rgb = [_mm256_setzero_ps(); 3];
        self.envelope = _mm256_setzero_ps();
    }

    /// The lanes' sums, each added as `((l0 + l1) + (l2 + l3)) + ((l4 +
    /// l5) + (l6 + l7))`, times `kd`, and the bound for `count` lights; or
    /// `None` out of range (see [`Frame::finish`]).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn finish(&self, kd: DVec3, count: usize) -> Option<(DVec3, DVec3)> {
        use core::arch::x86_64::{
            _mm_add_ps, _mm256_castps128_ps256, _mm256_castps256_ps128, _mm256_extractf128_ps,
            _mm256_hadd_ps, _mm256_movemask_ps,
        };
        if _mm256_movemask_ps(self.in_range) != 0xff {
            return None;
        }
        let [r, g, b] = self.rgb;
        // Per vector, its lanes added pairwise, the four vectors side by
        // side.
        let pairs = _mm256_hadd_ps(_mm256_hadd_ps(r, g), _mm256_hadd_ps(b, self.envelope));
        let sums = _mm_add_ps(
            _mm256_castps256_ps128(pairs),
            _mm256_extractf128_ps::<1>(pairs),
        );
        let lane = |i: usize| crate::dispatch::lane_of_ps(_mm256_castps128_ps256(sums), i);
        let counted = _mm256_movemask_ps(self.any) != 0;
        Frame::finish([lane(0), lane(1), lane(2)], lane(3), kd, counted, count)
    }
}

/// The lanes that hold one of the last `rest` lights of a run (lanes 0 to
/// `rest - 1`), or `None` for a full group of eight.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn last_lanes(rest: usize) -> Option<core::arch::x86_64::__m256> {
    use core::arch::x86_64::{_CMP_LT_OQ, _mm256_cmp_ps, _mm256_set1_ps, _mm256_setr_ps};
    (rest < LANES).then(|| {
        _mm256_cmp_ps::<_CMP_LT_OQ>(
            _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
            _mm256_set1_ps(rest as f32),
        )
    })
}

/// [`sum_baseline`] with AVX2 instructions ([`Sums8`]), eight lights at a
/// time, each gathered from its record: the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) fn sum_avx2(
    kd: DVec3,
    surface: &Surface,
    lights: &[PointLight],
) -> Option<(DVec3, DVec3)> {
    use core::arch::x86_64::{
        __m128, _mm_set_ps, _mm256_set_m128, _mm256_shuffle_ps, _mm256_unpackhi_ps,
        _mm256_unpacklo_ps,
    };
    if lights.len() > COARSE_MAX {
        return None;
    }
    let frame = Frame::new(surface)?;
    let mut sums = Sums8::new(&frame);
    // Lane `k` reads light `min(k, len - 1)` where it lies (a padded copy
    // of the last chunk would be stored and loaded back in pieces of
    // different widths, which stalls the loads). A macro rather than a
    // closure: a closure used twice is compiled out of line, a call per
    // eight lights.
    macro_rules! gather {
        ($chunk:expr) => {{
            let chunk: &[PointLight] = $chunk;
            let last = chunk.len() - 1;
            let at = |k: usize| &chunk[k.min(last)];
            // (x, y, z, red) of lights k and k + 4 in one vector's halves,
            // transposed in each half to one vector per coordinate.
            let row = |l: &PointLight| {
                _mm_set_ps(l.intensity.x, l.position.z, l.position.y, l.position.x)
            };
            let pair = |k: usize| _mm256_set_m128(row(at(k + 4)), row(at(k)));
            let (a, b, c, d) = (pair(0), pair(1), pair(2), pair(3));
            let (t0, t1) = (_mm256_unpacklo_ps(a, b), _mm256_unpackhi_ps(a, b));
            let (t2, t3) = (_mm256_unpacklo_ps(c, d), _mm256_unpackhi_ps(c, d));
            // (green, blue) of lights k and k + 1, and k + 4 and k + 5.
            let duo = |k: usize| -> __m128 {
                let (l, m) = (at(k), at(k + 1));
                _mm_set_ps(m.intensity.z, m.intensity.y, l.intensity.z, l.intensity.y)
            };
            let gb01 = _mm256_set_m128(duo(4), duo(0));
            let gb23 = _mm256_set_m128(duo(6), duo(2));
            [
                _mm256_shuffle_ps::<0x44>(t0, t2),
                _mm256_shuffle_ps::<0xEE>(t0, t2),
                _mm256_shuffle_ps::<0x44>(t1, t3),
                _mm256_shuffle_ps::<0xEE>(t1, t3),
                _mm256_shuffle_ps::<0x88>(gb01, gb23),
                _mm256_shuffle_ps::<0xDD>(gb01, gb23),
            ]
        }};
    }
    let chunks = lights.chunks_exact(LANES);
    let rest = chunks.remainder();
    for chunk in chunks {
        sums.add(gather!(chunk), None);
    }
    if !rest.is_empty() {
        // The lanes past the last light are left out (their terms cleared
        // to +0, which adds nothing).
        sums.add(gather!(rest), last_lanes(rest.len()));
    }
    sums.finish(kd, lights.len())
}

/// [`sum_baseline`] of the `count` lights that `lanes` hold side by side
/// (light `i` in lane `i % 8` of `lanes[i / 8]`), `None` for more than
/// [`COARSE_MAX`] or more than the lanes hold: the same lights in the same
/// lanes, so the same bits.
pub(crate) fn sum_lanes_baseline(
    kd: DVec3,
    surface: &Surface,
    lanes: &[LightLanes],
    count: usize,
) -> Option<(DVec3, DVec3)> {
    if count > COARSE_MAX || count > lanes.len() * LANES {
        return None;
    }
    let mut lights = [PointLight::default(); COARSE_MAX];
    for (i, light) in lights[..count].iter_mut().enumerate() {
        let (group, k) = (&lanes[i / LANES], i % LANES);
        *light = PointLight::new(
            Vec3::new(group.x[k], group.y[k], group.z[k]),
            Vec3::new(group.red[k], group.green[k], group.blue[k]),
        );
    }
    sum_baseline(kd, surface, &lights[..count])
}

/// The six quantities of the eight lights of a group, one vector each
/// (each one load: the compiler folds the eight lanes). A macro rather than
/// a closure, as in `sum_avx2`.
#[cfg(target_arch = "x86_64")]
macro_rules! load_lanes {
    ($group:expr) => {{
        let g: &LightLanes = $group;
        let load = |a: &[f32; 8]| {
            core::arch::x86_64::_mm256_setr_ps(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7])
        };
        [
            load(&g.x),
            load(&g.y),
            load(&g.z),
            load(&g.red),
            load(&g.green),
            load(&g.blue),
        ]
    }};
}

/// [`sum_lanes_baseline`] with AVX2 instructions ([`Sums8`]): each
/// quantity of eight lights one load, so the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) fn sum_lanes_avx2(
    kd: DVec3,
    surface: &Surface,
    lanes: &[LightLanes],
    count: usize,
) -> Option<(DVec3, DVec3)> {
    if count > COARSE_MAX || count > lanes.len() * LANES {
        return None;
    }
    let frame = Frame::new(surface)?;
    let mut sums = Sums8::new(&frame);
    let (full, rest) = (count / LANES, count % LANES);
    for group in &lanes[..full] {
        sums.add(load_lanes!(group), None);
    }
    if rest > 0 {
        // The lanes past the last light are left out.
        sums.add(load_lanes!(&lanes[full]), last_lanes(rest));
    }
    sums.finish(kd, count)
}

/// [`sum_scene_lanes_baseline`] with AVX2 instructions ([`Sums8`]): each
/// quantity of eight lights one load, each block's lanes carried in `f64`
/// vectors, so the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) fn sum_scene_lanes_avx2(
    kd: DVec3,
    surface: &Surface,
    lanes: &[LightLanes],
    count: usize,
) -> Option<(DVec3, DVec3)> {
    use core::arch::x86_64::{
        _mm_add_pd, _mm_cvtsd_f64, _mm_unpackhi_pd, _mm256_castpd256_pd128, _mm256_extractf128_pd,
        _mm256_hadd_pd, _mm256_movemask_ps, _mm256_setzero_pd,
    };
    if count > lanes.len() * LANES || count as u64 >= SCENE_LIGHTS_LIMIT {
        return None;
    }
    let frame = Frame::new(surface)?;
    let mut sums = Sums8::new(&frame);
    let mut wide = [_mm256_setzero_pd(); 8];
    let (full, rest) = (count / LANES, count % LANES);
    for (b, block) in lanes[..count.div_ceil(LANES)]
        .chunks(BLOCK_GROUPS)
        .enumerate()
    {
        for (j, group) in block.iter().enumerate() {
            // The lanes past the last light are left out.
            let mask = if b * BLOCK_GROUPS + j == full {
                last_lanes(rest)
            } else {
                None
            };
            sums.add(load_lanes!(group), mask);
        }
        sums.flush(&mut wide);
    }
    if _mm256_movemask_ps(sums.in_range) != 0xff {
        return None;
    }
    // As `wide_totals`, the operations side by side: `(l0 + l1, l4 + l5,
    // l2 + l3, l6 + l7)`, its halves added, then those two lanes.
    let totals: [f64; 4] = core::array::from_fn(|q| {
        let pairs = _mm256_hadd_pd(wide[2 * q], wide[2 * q + 1]);
        let halves = _mm_add_pd(
            _mm256_castpd256_pd128(pairs),
            _mm256_extractf128_pd::<1>(pairs),
        );
        _mm_cvtsd_f64(halves) + _mm_cvtsd_f64(_mm_unpackhi_pd(halves, halves))
    });
    let counted = _mm256_movemask_ps(sums.any) != 0;
    Some(finish_wide(totals, kd, counted, count))
}

#[cfg(test)]
#[path = "coarse_tests.rs"]
mod tests;
