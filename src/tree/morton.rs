//! Morton order: lights sorted along a Z-order curve over the scene's box,
//! so that every octree cell is a contiguous run, and the octree's cells
//! read off the sorted codes. The sort itself is in [`radix`](super::radix).

use glam::{DVec3, Vec3};

use super::pool::Pool;
pub(crate) use super::radix::{sort, sort_into};
use crate::geometry::Aabb;

/// Bits of a Morton code per axis: three interleaved 21-bit coordinates
/// fill 63 bits of a `u64`.
pub(crate) const BITS_PER_AXIS: u32 = 21;

/// Morton codes of `positions` over the cube of side the largest extent of
/// `scene`, their box (cubic cells, so a flat scene is split across its
/// thin axis only once cells are as small as its thickness). The tree
/// codes its lights, the batch call its shading points.
pub(crate) fn codes(positions: impl Iterator<Item = Vec3>, scene: Aabb) -> Vec<u64> {
    let grid = Grid::over(scene);
    positions.map(|p| grid.code(p)).collect()
}

/// The cells of [`codes`]: the cube over a scene's box.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Grid {
    min: DVec3,
    scale: f64,
}

impl Grid {
    /// The grid of cubic cells over the box `scene`.
    pub(crate) fn over(scene: Aabb) -> Self {
        let min = scene.min.as_dvec3();
        let extent = (scene.max.as_dvec3() - min).max_element();
        let cells = f64::from(1u32 << BITS_PER_AXIS);
        let scale = if extent > 0.0 { cells / extent } else { 0.0 };
        Self { min, scale }
    }

    /// The Morton code of the cell holding `p`.
    #[inline(always)]
    pub(crate) fn code(&self, p: Vec3) -> u64 {
        let top = f64::from(1u32 << BITS_PER_AXIS) - 1.0;
        let q = ((p.as_dvec3() - self.min) * self.scale).clamp(DVec3::ZERO, DVec3::splat(top));
        spread(q.x as u32) | spread(q.y as u32) << 1 | spread(q.z as u32) << 2
    }
}

/// Lights per part of [`Grid::codes_of`] on a pool.
const CODE_PART: usize = 1 << 14;

impl Grid {
    /// The codes of `lights`' positions, in order, on `pool`: the same
    /// values as [`code`](Self::code), in a copy compiled for AVX2 where
    /// the processor has it (integer and conversion operations only, so the
    /// same bits).
    pub(crate) fn codes_of(&self, lights: &[crate::PointLight], pool: Pool) -> Vec<u64> {
        let mut out = vec![0u64; lights.len()];
        let parts: Vec<_> = lights
            .chunks(CODE_PART)
            .zip(out.chunks_mut(CODE_PART))
            .collect();
        pool.for_each_with(
            parts,
            || (),
            |(), (lights, out)| self.fill_codes(lights, out),
        );
        out
    }

    /// The codes of `lights` into `out`: four at a time with AVX2
    /// instructions where the processor has them
    /// ([`dispatch`](crate::dispatch)).
    fn fill_codes(&self, lights: &[crate::PointLight], out: &mut [u64]) {
        crate::dispatch::avx2_or!(
            Self::fill_codes_avx2,
            Self::fill_codes_body,
            self,
            lights,
            out
        );
    }

    /// [`fill_codes_body`](Self::fill_codes_body) four lights at a time,
    /// the cells of an axis as one vector: the same subtraction, product,
    /// clamp (`maxpd` and `minpd` keep their first operand exactly where
    /// `DVec3::max` and `DVec3::min` keep `self`) and truncation (the
    /// clamped values fit an `i32`), so the same codes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn fill_codes_avx2(&self, lights: &[crate::PointLight], out: &mut [u64]) {
        use core::arch::x86_64::{
            _mm256_cvtepu32_epi64, _mm256_cvttpd_epi32, _mm256_extract_epi64, _mm256_max_pd,
            _mm256_min_pd, _mm256_mul_pd, _mm256_or_si256, _mm256_set_pd, _mm256_set1_pd,
            _mm256_setzero_pd, _mm256_setzero_si256, _mm256_slli_epi64, _mm256_sub_pd,
        };
        let top = _mm256_set1_pd(f64::from(1u32 << BITS_PER_AXIS) - 1.0);
        let zero = _mm256_setzero_pd();
        let scale = _mm256_set1_pd(self.scale);
        let min = self.min.to_array();
        let min = [
            _mm256_set1_pd(min[0]),
            _mm256_set1_pd(min[1]),
            _mm256_set1_pd(min[2]),
        ];
        let fours = lights.chunks_exact(4);
        let rest = fours.remainder();
        let mut outs = out.chunks_exact_mut(4);
        for (four, out) in fours.zip(&mut outs) {
            let mut cells = [_mm256_setzero_si256(); 3];
            for axis in 0..3 {
                let p = _mm256_set_pd(
                    f64::from(four[3].position[axis]),
                    f64::from(four[2].position[axis]),
                    f64::from(four[1].position[axis]),
                    f64::from(four[0].position[axis]),
                );
                let q = _mm256_mul_pd(_mm256_sub_pd(p, min[axis]), scale);
                let c = _mm256_cvttpd_epi32(_mm256_min_pd(_mm256_max_pd(q, zero), top));
                // At most 21 bits: the same as the `u32` of `code`.
                cells[axis] = spread_lanes(_mm256_cvtepu32_epi64(c));
            }
            let codes = _mm256_or_si256(
                _mm256_or_si256(cells[0], _mm256_slli_epi64::<1>(cells[1])),
                _mm256_slli_epi64::<2>(cells[2]),
            );
            out[0] = _mm256_extract_epi64::<0>(codes) as u64;
            out[1] = _mm256_extract_epi64::<1>(codes) as u64;
            out[2] = _mm256_extract_epi64::<2>(codes) as u64;
            out[3] = _mm256_extract_epi64::<3>(codes) as u64;
        }
        self.fill_codes_body(rest, outs.into_remainder());
    }

    #[inline(always)]
    fn fill_codes_body(&self, lights: &[crate::PointLight], out: &mut [u64]) {
        for (l, o) in lights.iter().zip(out) {
            *o = self.code(l.position);
        }
    }
}

/// [`spread`] of each of four lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn spread_lanes(x: core::arch::x86_64::__m256i) -> core::arch::x86_64::__m256i {
    use core::arch::x86_64::{
        _mm256_and_si256, _mm256_or_si256, _mm256_set1_epi64x, _mm256_slli_epi64,
    };
    let mask = |m: u64| _mm256_set1_epi64x(m as i64);
    let x = _mm256_and_si256(x, mask(0x1f_ffff));
    let x = _mm256_and_si256(
        _mm256_or_si256(x, _mm256_slli_epi64::<32>(x)),
        mask(0x1f_0000_0000_ffff),
    );
    let x = _mm256_and_si256(
        _mm256_or_si256(x, _mm256_slli_epi64::<16>(x)),
        mask(0x1f_0000_ff00_00ff),
    );
    let x = _mm256_and_si256(
        _mm256_or_si256(x, _mm256_slli_epi64::<8>(x)),
        mask(0x100f_00f0_0f00_f00f),
    );
    let x = _mm256_and_si256(
        _mm256_or_si256(x, _mm256_slli_epi64::<4>(x)),
        mask(0x10c3_0c30_c30c_30c3),
    );
    _mm256_and_si256(
        _mm256_or_si256(x, _mm256_slli_epi64::<2>(x)),
        mask(0x1249_2492_4924_9249),
    )
}

/// The 21 low bits of `v`, two zero bits inserted after each.
#[inline(always)]
fn spread(v: u32) -> u64 {
    let mut x = u64::from(v) & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// One more than the index of the highest bit in which two codes differ
/// (1 to 63), 0 for equal codes: the octree level of the difference is
/// that bit's 3-bit digit, and its place in the digit tells which halving
/// of the cell separates them (see [`children`]).
#[inline(always)]
fn split_level(a: u64, b: u64) -> u8 {
    (u64::BITS - (a ^ b).leading_zeros()) as u8
}

/// [`split_level`] of each pair of neighbours of the sorted `codes`: entry
/// `i` for codes `i` and `i + 1` (one entry fewer than codes). One byte a
/// code, which [`children`] scans instead of searching the codes.
pub(crate) fn split_levels(codes: &[u64]) -> Vec<u8> {
    codes.windows(2).map(|w| split_level(w[0], w[1])).collect()
}

/// Splits a run of sorted codes at the first octree level where they
/// differ, or `None` when every code is equal. Reads only the run's
/// [`split_levels`] (one fewer than its codes).
///
/// The run's occupied sub-cells at that level (2 to 8 of them) are the
/// leaves of three halvings of its cell, one per bit of the level's digit:
/// the sub-runs are found by halving along those bits in turn, and a part
/// of at most `max_lights` codes is kept whole rather than halved further.
/// So occupied sub-cells that together hold at most `max_lights` lights
/// come out as one part, a half or a quarter of the cell (or two of its
/// neighbouring sub-cells), instead of as several small ones; a part of
/// more than `max_lights` codes is always one sub-cell. The parts are in
/// order and cover the run.
pub(super) fn children(
    levels: &[u8],
    max_lights: usize,
) -> Option<smallvec::SmallVec<[core::ops::Range<usize>; 8]>> {
    let top = levels.iter().copied().max()?;
    if top == 0 {
        return None;
    }
    // The digit's bits are `base` to `base + 2`: a neighbour pair whose
    // level is above `base` is cut at bit `level - 1 - base` of the digit.
    let base = (top - 1) / 3 * 3;
    let mut cuts = Cuts {
        at: [[0; 4]; 3],
        counts: [0; 3],
    };
    let mut cut_in = |at: usize, step: &[u8]| {
        for (i, &l) in step.iter().enumerate() {
            if l > base {
                let bit = usize::from(l - 1 - base);
                cuts.at[bit][cuts.counts[bit]] = at + i + 1;
                cuts.counts[bit] += 1;
            }
        }
    };
    // A step of levels without one above `base` (most of them: at most
    // seven cuts in the run) is passed over after one test of them all,
    // which vector instructions take.
    const STEP: usize = 32;
    let steps = levels.chunks_exact(STEP);
    let rest = steps.remainder();
    for (k, step) in steps.enumerate() {
        if step.iter().fold(0u8, |any, &l| any | u8::from(l > base)) != 0 {
            cut_in(STEP * k, step);
        }
    }
    cut_in(levels.len() - rest.len(), rest);
    let mut out = smallvec::SmallVec::new();
    halve(&mut out, &cuts, 0..levels.len() + 1, 3, max_lights);
    Some(out)
}

/// Per bit of a level's digit, where a run of codes is cut along it (after
/// which code): at most one, four and two cuts, for the highest, lowest
/// and middle bits.
#[derive(Clone, Copy, Debug)]
struct Cuts {
    /// Per bit, its cuts, the first `counts[bit]` of them.
    at: [[usize; 4]; 3],
    /// Per bit, the number of its cuts.
    counts: [usize; 3],
}

impl Cuts {
    /// The cuts along `bit`.
    fn of(&self, bit: usize) -> &[usize] {
        &self.at[bit][..self.counts[bit]]
    }
}

/// Appends the parts of `run` (see [`children`]): whole if it holds at
/// most `max_lights` codes or no bit of the digit is left (`bits` is the
/// number left, the highest of them next), else cut at its cut of that bit
/// (if any) and each side halved along the bits below.
fn halve(
    out: &mut smallvec::SmallVec<[core::ops::Range<usize>; 8]>,
    cuts: &Cuts,
    run: core::ops::Range<usize>,
    bits: usize,
    max_lights: usize,
) {
    if bits == 0 || run.len() <= max_lights {
        out.push(run);
        return;
    }
    let bit = bits - 1;
    let cut = cuts
        .of(bit)
        .iter()
        .copied()
        .find(|&c| run.start < c && c < run.end);
    match cut {
        Some(c) => {
            halve(out, cuts, run.start..c, bit, max_lights);
            halve(out, cuts, c..run.end, bit, max_lights);
        }
        None => halve(out, cuts, run, bit, max_lights),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tree::radix::splitmix as random;

    #[test]
    fn spread_interleaves() {
        assert_eq!(spread(0b111), 0b1001001);
        assert_eq!(spread(0x1f_ffff).count_ones(), 21);
    }

    /// The codes of many lights at once (four at a time where the
    /// processor has AVX2) are the codes one by one, and so are the
    /// baseline copy's: on the box's corners and faces, outside the box
    /// (clamped), at `-0`, and on runs of every length up to two steps.
    #[test]
    fn codes_of_lights_are_the_codes_one_by_one() {
        let mut state = 5;
        let scene = Aabb {
            min: Vec3::new(-3.0, 0.0, 1.0e-3),
            max: Vec3::new(250.0, 1.0e4, 2.5),
        };
        let mut coordinate = |axis: usize| {
            let (lo, hi) = (scene.min[axis], scene.max[axis]);
            match random(&mut state) % 8 {
                0 => lo,
                1 => hi,
                2 => -0.0,
                3 => lo - 1.0,
                4 => hi * 2.0,
                _ => lo + (hi - lo) * (random(&mut state) >> 40) as f32 / (1u64 << 24) as f32,
            }
        };
        let lights: Vec<crate::PointLight> = (0..1000)
            .map(|_| {
                let p = Vec3::new(coordinate(0), coordinate(1), coordinate(2));
                crate::PointLight::new(p, Vec3::ONE)
            })
            .collect();
        for grid in [
            Grid::over(scene),
            Grid::over(Aabb::EMPTY.union_point(Vec3::ONE)),
        ] {
            for len in (0..=9).chain([1000]) {
                let lights = &lights[..len];
                let one_by_one: Vec<u64> = lights.iter().map(|l| grid.code(l.position)).collect();
                assert_eq!(grid.codes_of(lights, Pool::ONE), one_by_one);
                let baseline = crate::dispatch::baseline(|| grid.codes_of(lights, Pool::ONE));
                assert_eq!(baseline, one_by_one);
            }
        }
    }

    #[test]
    fn children_split_at_the_first_differing_digit() {
        // Same top digits; they differ in the digit at bits 3..6.
        let codes = [
            0b000_001_000u64,
            0b000_001_111,
            0b000_011_000,
            0b000_111_000,
        ];
        let levels = split_levels(&codes);
        let runs = children(&levels, 1).unwrap();
        assert_eq!(runs.as_slice(), &[0..2, 2..3, 3..4]);
        // The first three lie in one half of the cell (bit 5 clear).
        let runs = children(&levels, 3).unwrap();
        assert_eq!(runs.as_slice(), &[0..3, 3..4]);
        assert!(children(&split_levels(&[7, 7, 7]), 1).is_none());
    }

    /// The parts of the sorted `codes` found code by code: at the highest
    /// digit where the first and last differ, each part of more than
    /// `max_lights` codes halved where that digit's bits change, highest
    /// bit first.
    fn children_reference(
        codes: &[u64],
        max_lights: usize,
    ) -> Option<Vec<core::ops::Range<usize>>> {
        fn parts(
            codes: &[u64],
            run: core::ops::Range<usize>,
            bit: i32,
            base: i32,
            max_lights: usize,
            out: &mut Vec<core::ops::Range<usize>>,
        ) {
            if run.len() <= max_lights || bit < base {
                out.push(run);
                return;
            }
            let set = |i: usize| (codes[i] >> bit) & 1 == 1;
            let cut = (run.start..run.end).find(|&i| set(i)).unwrap_or(run.end);
            for half in [run.start..cut, cut..run.end] {
                if !half.is_empty() {
                    parts(codes, half, bit - 1, base, max_lights, out);
                }
            }
        }
        let differ = codes.first()? ^ codes.last()?;
        if differ == 0 {
            return None;
        }
        let base = (63 - differ.leading_zeros() as i32) / 3 * 3;
        let mut out = Vec::new();
        parts(codes, 0..codes.len(), base + 2, base, max_lights, &mut out);
        Some(out)
    }

    /// The split levels give the parts found code by code, on runs of
    /// every length around the steps the scan takes, with cuts anywhere,
    /// for leaves of every size up to the run's.
    #[test]
    fn children_match_a_reference() {
        let mut state = 11;
        for len in (2..=100).chain([255, 256, 257, 1000, 4096]) {
            for trial in 0..20 {
                let r = &mut state;
                // Codes below a shared prefix: few distinct values, spread
                // over a few digits, so that equal codes and cuts at
                // several levels occur.
                let bits = 1 + trial % 12;
                let mut codes: Vec<u64> = (0..len)
                    .map(|_| 0x5a5a_0000_0000_0000 | (random(r) & ((1 << bits) - 1)) << (trial % 5))
                    .collect();
                codes.sort_unstable();
                let levels = split_levels(&codes);
                assert_eq!(levels.len() + 1, codes.len());
                let max_lights = [1, 2, 5, 32, len - 1][trial % 5];
                let runs = children(&levels, max_lights).map(|runs| runs.to_vec());
                assert_eq!(
                    runs,
                    children_reference(&codes, max_lights),
                    "{len} codes, trial {trial}, leaves of {max_lights}"
                );
            }
        }
    }
}
