//! A leaf's moments, summed directly over its lights: four lights side by
//! side, a block of chunks at a time, in a copy compiled for AVX2 and FMA
//! where the processor has them (the same bits). The error bound of these
//! sums is derived in [`moments`](super::moments)' docs.

use glam::DVec3;

use super::moments::{DEGREE, Lanes, MONOMIALS, Moments, RECIPROCALS};
use crate::PointLight;

/// Writes the 56 products `px[a_x] py[a_y] pz[a_z]`, lane by lane, into
/// `out` in the order of [`EXPONENTS`](super::moments::EXPONENTS)
/// (straight-line code, which lets the compiler share the products
/// `px[a_x] py[a_y]` and skip the factors 1).
macro_rules! monomial_values {
    ($out:expr, $px:ident, $py:ident, $pz:ident) => {
        monomial_values!(@ $out, $px, $py, $pz; (0, 0, 0, 0), (1, 1, 0, 0), (2, 0, 1, 0), (3, 0, 0, 1), (4, 2, 0, 0), (5, 1, 1, 0), (6, 1, 0, 1), (7, 0, 2, 0), (8, 0, 1, 1), (9, 0, 0, 2), (10, 3, 0, 0), (11, 2, 1, 0), (12, 2, 0, 1), (13, 1, 2, 0), (14, 1, 1, 1), (15, 1, 0, 2), (16, 0, 3, 0), (17, 0, 2, 1), (18, 0, 1, 2), (19, 0, 0, 3), (20, 4, 0, 0), (21, 3, 1, 0), (22, 3, 0, 1), (23, 2, 2, 0), (24, 2, 1, 1), (25, 2, 0, 2), (26, 1, 3, 0), (27, 1, 2, 1), (28, 1, 1, 2), (29, 1, 0, 3), (30, 0, 4, 0), (31, 0, 3, 1), (32, 0, 2, 2), (33, 0, 1, 3), (34, 0, 0, 4), (35, 5, 0, 0), (36, 4, 1, 0), (37, 4, 0, 1), (38, 3, 2, 0), (39, 3, 1, 1), (40, 3, 0, 2), (41, 2, 3, 0), (42, 2, 2, 1), (43, 2, 1, 2), (44, 2, 0, 3), (45, 1, 4, 0), (46, 1, 3, 1), (47, 1, 2, 2), (48, 1, 1, 3), (49, 1, 0, 4), (50, 0, 5, 0), (51, 0, 4, 1), (52, 0, 3, 2), (53, 0, 2, 3), (54, 0, 1, 4), (55, 0, 0, 5))
    };
    (@ $out:expr, $px:ident, $py:ident, $pz:ident; $(($n:literal, $a:literal, $b:literal, $c:literal)),*) => {
        $($out[$n] = product(&$px[$a], &$py[$b], &$pz[$c]);)*
    };
}

/// Lights a leaf's sums take side by side.
const LIGHT_LANES: usize = 4;

type LightLanes = [f64; LIGHT_LANES];

/// `a b c`, lane by lane.
#[inline(always)]
fn product(a: &LightLanes, b: &LightLanes, c: &LightLanes) -> LightLanes {
    let mut out = [0.0; LIGHT_LANES];
    for k in 0..LIGHT_LANES {
        out[k] = a[k] * b[k] * c[k];
    }
    out
}

/// [`scaled_powers`](super::moments::scaled_powers) lane by lane.
#[inline(always)]
fn scaled_power_lanes(x: &LightLanes) -> [LightLanes; DEGREE + 1] {
    let mut out = [[1.0; LIGHT_LANES]; DEGREE + 1];
    for p in 1..=DEGREE {
        for k in 0..LIGHT_LANES {
            out[p][k] = out[p - 1][k] * x[k] * RECIPROCALS[p];
        }
    }
    out
}

/// `acc[ch] += v * i[ch]` per channel, lane by lane.
#[inline(always)]
fn add_products(acc: &mut [LightLanes; 3], v: &LightLanes, i: &[LightLanes; 3]) {
    for (acc, i) in acc.iter_mut().zip(i) {
        for k in 0..LIGHT_LANES {
            acc[k] = v[k].mul_add(i[k], acc[k]);
        }
    }
}

/// Per channel, its lanes' sum, pairwise (`(l0 + l1) + (l2 + l3)`), and
/// 0 in the spare lane: written as sums of the transposed lanes, so that
/// the additions are vertical.
#[inline(always)]
fn lane_sums(x: &[LightLanes; 3]) -> Lanes {
    let lane = |l: usize| [x[0][l], x[1][l], x[2][l], 0.0];
    let add = |a: Lanes, b: Lanes| [a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]];
    add(add(lane(0), lane(1)), add(lane(2), lane(3)))
}

/// Chunks of [`LIGHT_LANES`] lights whose terms a leaf's sums prepare at
/// once.
const BLOCK_CHUNKS: usize = 8;

/// Sums a pass over a block's chunks takes side by side (their
/// accumulators in registers).
const GROUP: usize = 4;

/// Sums a leaf carries per lane: the moments, then the scaled powers of
/// the 1-norms (for the bounds), then two that stay 0, so that the sums
/// come in whole groups.
const SUMS: usize = 64;

/// Where the powers of the 1-norms start among the sums.
const NORMS: usize = MONOMIALS;

/// Per channel, one sum's lanes.
type Accumulator = [LightLanes; 3];

/// One chunk's lanes: the values it adds to each sum (the monomials `y^a /
/// a!` of its offsets, the scaled powers of their 1-norms) and its
/// intensities. Padded lanes are at the centre, dark.
#[derive(Clone, Copy)]
struct ChunkTerms {
    values: [LightLanes; SUMS],
    intensity: [LightLanes; 3],
}

impl ChunkTerms {
    const ZERO: Self = Self {
        values: [[0.0; LIGHT_LANES]; SUMS],
        intensity: [[0.0; LIGHT_LANES]; 3],
    };

    /// Sets these to the terms of `chunk` (at most [`LIGHT_LANES`] lights)
    /// about `centre`; returns the largest of 0 and the lights' squared
    /// distances from `centre`, each computed in `f64` as `(x - c) . (x -
    /// c)` from the offsets the terms use.
    #[inline(always)]
    fn set(&mut self, chunk: &[PointLight], centre: DVec3) -> f64 {
        let mut y = [[0.0; LIGHT_LANES]; 3];
        let mut intensity = [[0.0; LIGHT_LANES]; 3];
        for (k, l) in chunk.iter().enumerate() {
            let offset = (l.position.as_dvec3() - centre).to_array();
            let i = l.intensity.as_dvec3().to_array();
            for axis in 0..3 {
                y[axis][k] = offset[axis];
                intensity[axis][k] = i[axis];
            }
        }
        let (px, py, pz) = (
            scaled_power_lanes(&y[0]),
            scaled_power_lanes(&y[1]),
            scaled_power_lanes(&y[2]),
        );
        monomial_values!(self.values, px, py, pz);
        let mut norm = [0.0; LIGHT_LANES];
        for k in 0..LIGHT_LANES {
            norm[k] = y[0][k].abs() + y[1][k].abs() + y[2][k].abs();
        }
        self.values[NORMS..NORMS + DEGREE + 1].copy_from_slice(&scaled_power_lanes(&norm));
        self.intensity = intensity;
        // The padded lanes' offsets are 0. A maximum is exact, so the
        // lanes' order does not matter; no distance is NaN or -0.
        let mut farthest = 0.0f64;
        for ((x, y), z) in y[0].iter().zip(&y[1]).zip(&y[2]) {
            let d2 = x * x + y * y + z * z;
            farthest = if d2 > farthest { d2 } else { farthest };
        }
        farthest
    }
}

/// Room for one block of a leaf's chunk terms, and for the accumulators
/// carried from block to block in leaves of more than one block, kept from
/// leaf to leaf.
pub(super) struct LeafScratch {
    terms: Vec<ChunkTerms>,
    carry: Vec<Accumulator>,
}

impl LeafScratch {
    /// Empty buffers, grown to the largest leaf filled.
    pub(super) fn new() -> Self {
        Self {
            terms: Vec::new(),
            carry: Vec::new(),
        }
    }

    /// The terms of `lights` (at most [`BLOCK_CHUNKS`] chunks) about
    /// `centre`, room for the carried accumulators, and the lights' largest
    /// squared distance from `centre` (see [`ChunkTerms::set`]).
    #[inline(always)]
    fn block(
        &mut self,
        lights: &[PointLight],
        centre: DVec3,
    ) -> (&[ChunkTerms], &mut [Accumulator], f64) {
        let chunks = lights.len().div_ceil(LIGHT_LANES);
        if self.terms.len() < chunks {
            self.terms.resize(chunks, ChunkTerms::ZERO);
        }
        let mut farthest = 0.0f64;
        for (terms, chunk) in self.terms.iter_mut().zip(lights.chunks(LIGHT_LANES)) {
            farthest = farthest.max(terms.set(chunk, centre));
        }
        if self.carry.len() < SUMS {
            self.carry.resize(SUMS, [[0.0; LIGHT_LANES]; 3]);
        }
        (&self.terms[..chunks], &mut self.carry, farthest)
    }
}

impl Moments {
    /// The moments of `lights` about `centre`, summed directly.
    #[cfg(test)]
    pub(super) fn of_lights(lights: &[PointLight], centre: DVec3) -> Self {
        let mut out = Self::ZERO;
        let _ = out.set_to_lights(lights, centre, &mut LeafScratch::new());
        out
    }

    /// Sets these to the moments of `lights` about `centre`, summed
    /// directly: [`LIGHT_LANES`] lights side by side, each lane summing its
    /// lights' terms in order, the lanes added pairwise at the end (a sum
    /// of `n` terms in any order rounds each term at most `n - 1` times;
    /// the padded lanes add exact zeros).
    ///
    /// The lights are taken a block of [`BLOCK_CHUNKS`] chunks at a time:
    /// the chunks' terms first (into `scratch`), then [`GROUP`] sums at a
    /// time over the block's chunks, their accumulators in registers
    /// rather than in memory. Each sum still takes its terms in the
    /// lights' order, so the order of the sums changes no bit.
    ///
    /// Returns the largest of 0 and the lights' squared distances from
    /// `centre`, each computed in `f64` as `(x - c) . (x - c)` (a node's
    /// radius, read off the offsets the terms use rather than in a pass of
    /// its own).
    #[inline(always)]
    pub(super) fn set_to_lights(
        &mut self,
        lights: &[PointLight],
        centre: DVec3,
        scratch: &mut LeafScratch,
    ) -> f64 {
        const BLOCK: usize = BLOCK_CHUNKS * LIGHT_LANES;
        let blocks = lights.len().div_ceil(BLOCK);
        let mut farthest = 0.0f64;
        for (k, block) in lights.chunks(BLOCK).enumerate() {
            let (terms, carry, far) = scratch.block(block, centre);
            farthest = farthest.max(far);
            self.sum_block(terms, carry, k == 0, k + 1 == blocks);
        }
        if lights.is_empty() {
            self.sum_block(&[], &mut [], true, true);
        }
        let slack = (lights.len() as f64 + 64.0) * f64::EPSILON;
        for (a, e) in self.abs.iter_mut().zip(self.err.iter_mut()) {
            for (a, e) in a.iter_mut().zip(e.iter_mut()) {
                *a *= 1.0 + slack;
                *e = *a * slack;
            }
        }
        farthest
    }

    /// Adds one block's chunks to the accumulators of the sums: from 0 if
    /// `first`, else from `carry`; into `carry` unless `last`, when their
    /// lanes' sums go into `self.m` and `self.abs`.
    /// The copy written with AVX2 and FMA instructions where the processor
    /// has them ([`dispatch`](crate::dispatch)).
    #[inline(always)]
    fn sum_block(
        &mut self,
        terms: &[ChunkTerms],
        carry: &mut [Accumulator],
        first: bool,
        last: bool,
    ) {
        crate::dispatch::copy_or!(
            avx2_fma,
            Self::sum_block_avx2,
            Self::sum_block_baseline,
            self,
            terms,
            carry,
            first,
            last
        );
    }

    /// [`sum_block`](Self::sum_block)'s baseline copy.
    #[inline(always)]
    fn sum_block_baseline(
        &mut self,
        terms: &[ChunkTerms],
        carry: &mut [Accumulator],
        first: bool,
        last: bool,
    ) {
        for start in (0..SUMS).step_by(GROUP) {
            let mut acc = [[[0.0; LIGHT_LANES]; 3]; GROUP];
            if !first {
                acc.copy_from_slice(&carry[start..start + GROUP]);
            }
            for t in terms {
                for (acc, v) in acc.iter_mut().zip(&t.values[start..start + GROUP]) {
                    add_products(acc, v, &t.intensity);
                }
            }
            if !last {
                carry[start..start + GROUP].copy_from_slice(&acc);
                continue;
            }
            for (s, acc) in (start..).zip(&acc) {
                if s < NORMS {
                    self.m[s] = lane_sums(acc);
                } else if s < NORMS + DEGREE + 1 {
                    self.abs[s - NORMS] = lane_sums(acc);
                }
            }
        }
    }

    /// [`sum_block`](Self::sum_block) with AVX2 and FMA instructions: the
    /// same fused multiply-adds lane by lane, and the lanes' sums as
    /// `(l0 + l1) + (l2 + l3)` by horizontal additions, so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn sum_block_avx2(
        &mut self,
        terms: &[ChunkTerms],
        carry: &mut [Accumulator],
        first: bool,
        last: bool,
    ) {
        use crate::dispatch::lane_of;
        use core::arch::x86_64::{
            __m256d, _mm256_add_pd, _mm256_fmadd_pd, _mm256_hadd_pd, _mm256_permute2f128_pd,
            _mm256_set_pd, _mm256_setzero_pd,
        };
        let load = |a: &LightLanes| _mm256_set_pd(a[3], a[2], a[1], a[0]);
        let lanes = |v: __m256d| [lane_of(v, 0), lane_of(v, 1), lane_of(v, 2), lane_of(v, 3)];
        let zero = _mm256_setzero_pd();
        for start in (0..SUMS).step_by(GROUP) {
            let mut acc = [[zero; 3]; GROUP];
            if !first {
                for (acc, carried) in acc.iter_mut().zip(&carry[start..start + GROUP]) {
                    *acc = carried.map(|c| load(&c));
                }
            }
            for t in terms {
                let [i0, i1, i2] = t.intensity.map(|i| load(&i));
                for (acc, v) in acc.iter_mut().zip(&t.values[start..start + GROUP]) {
                    let v = load(v);
                    acc[0] = _mm256_fmadd_pd(v, i0, acc[0]);
                    acc[1] = _mm256_fmadd_pd(v, i1, acc[1]);
                    acc[2] = _mm256_fmadd_pd(v, i2, acc[2]);
                }
            }
            if !last {
                for (carried, acc) in carry[start..start + GROUP].iter_mut().zip(&acc) {
                    *carried = acc.map(lanes);
                }
                continue;
            }
            for (s, [c0, c1, c2]) in (start..).zip(acc) {
                if s > NORMS + DEGREE {
                    break;
                }
                // (c0 l0 + c0 l1, c1 l0 + c1 l1, c0 l2 + c0 l3, c1 l2 + c1 l3)
                // and (c2 l0 + c2 l1, 0, c2 l2 + c2 l3, 0): their halves added.
                let (a, b) = (_mm256_hadd_pd(c0, c1), _mm256_hadd_pd(c2, zero));
                let sum = _mm256_add_pd(
                    _mm256_permute2f128_pd::<0x20>(a, b),
                    _mm256_permute2f128_pd::<0x31>(a, b),
                );
                if s < NORMS {
                    self.m[s] = lanes(sum);
                } else {
                    self.abs[s - NORMS] = lanes(sum);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::tree::moments::{DEGREE_START, EXPONENTS, FACTORIALS, test_lights as lights};

    /// Shifting moments to a new centre agrees with summing about it
    /// directly, within the two error bounds, and the bounds stay small.
    #[test]
    fn shifted_moments_match_direct_sums_within_their_bounds() {
        for seed in 1..40u64 {
            let a = lights(seed, 7, 2.0, Vec3::new(1.0, -3.0, 0.5));
            let b = lights(seed * 31, 12, 0.5, Vec3::new(-2.0, 1.0, 4.0));
            let centre = DVec3::new(0.25, -0.5, 1.75);
            let mut sum = Moments::ZERO;
            for group in [&a, &b] {
                let c = group[0].position.as_dvec3();
                let mut moments = Moments::of_lights(group, c);
                moments.shift_into(c - centre, &mut sum);
            }
            let all: Vec<PointLight> = a.iter().chain(&b).copied().collect();
            let direct = Moments::of_lights(&all, centre);
            for l in 0..=DEGREE {
                for ch in 0..3 {
                    let diff: f64 = (DEGREE_START[l]..DEGREE_START[l + 1])
                        .map(|n| (sum.m[n][ch] - direct.m[n][ch]).abs())
                        .sum();
                    let allowed = sum.err[l][ch] + direct.err[l][ch];
                    assert!(diff <= allowed, "degree {l}: {diff} > {allowed}");
                    assert!(sum.abs[l][ch] >= direct.abs[l][ch] * (1.0 - 1e-12));
                    assert!(sum.err[l][ch] <= 1e-11 * sum.abs[l][ch]);
                }
            }
        }
    }

    /// A leaf's direct sums, over one chunk, part of one, whole blocks
    /// and blocks carried into the next: within their error bound of the
    /// same sums taken light by light (the bound covering that sum's own
    /// rounding too), their 1-norm bounds above them, and the copy for
    /// AVX2 and FMA the same bits as the baseline.
    #[test]
    fn direct_sums_match_sums_light_by_light() {
        for count in [1, 3, 4, 5, 31, 32, 33, 64, 70, 100] {
            let group = lights(count as u64 * 7 + 1, count, 4.0, Vec3::new(-3.0, 2.0, 1.0));
            let centre = DVec3::new(-1.5, 3.5, 2.0);
            let moments = Moments::of_lights(&group, centre);
            let baseline = crate::dispatch::baseline(|| Moments::of_lights(&group, centre));
            assert_eq!(moments.m, baseline.m, "{count} lights");
            assert_eq!(moments.abs, baseline.abs, "{count} lights");
            assert_eq!(moments.err, baseline.err, "{count} lights");
            let mut plain = [[0.0f64; 3]; MONOMIALS];
            let mut norms = [[0.0f64; 3]; DEGREE + 1];
            for l in &group {
                let y = l.position.as_dvec3() - centre;
                let i = l.intensity.as_dvec3();
                let norm = y.x.abs() + y.y.abs() + y.z.abs();
                for (n, [a, b, c]) in EXPONENTS.into_iter().enumerate() {
                    let v = y.x.powi(a as i32) * y.y.powi(b as i32) * y.z.powi(c as i32)
                        / (FACTORIALS[a] * FACTORIALS[b] * FACTORIALS[c]);
                    for ch in 0..3 {
                        plain[n][ch] += v * i[ch];
                    }
                }
                for (d, acc) in norms.iter_mut().enumerate() {
                    for ch in 0..3 {
                        *acc.get_mut(ch).unwrap() += norm.powi(d as i32) / FACTORIALS[d] * i[ch];
                    }
                }
            }
            for l in 0..=DEGREE {
                for ch in 0..3 {
                    let range = DEGREE_START[l]..DEGREE_START[l + 1];
                    let diff: f64 = range.map(|n| (moments.m[n][ch] - plain[n][ch]).abs()).sum();
                    assert!(
                        diff <= 2.0 * moments.err[l][ch],
                        "{count} lights, degree {l}: {diff} > 2 * {}",
                        moments.err[l][ch]
                    );
                    assert!(
                        moments.abs[l][ch] >= norms[l][ch],
                        "{count} lights, degree {l}"
                    );
                    assert!(moments.abs[l][ch] <= norms[l][ch] * (1.0 + 1e-12));
                }
            }
        }
    }
}
