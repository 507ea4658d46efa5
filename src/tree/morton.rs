//! Morton order: lights sorted along a Z-order curve over the scene's box,
//! so that every octree cell is a contiguous run.

use glam::{DVec3, Vec3};

use super::pool::Pool;
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

    // Calling the AVX2 copy is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    fn fill_codes(&self, lights: &[crate::PointLight], out: &mut [u64]) {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::dispatch::avx2() {
                // SAFETY: the processor has AVX2 (`dispatch::avx2` checked).
                unsafe { self.fill_codes_avx2(lights, out) };
                return;
            }
        }
        self.fill_codes_body(lights, out);
    }

    /// [`fill_codes_body`](Self::fill_codes_body) four lights at a time,
    /// the cells of an axis as one vector: the same subtraction, product,
    /// clamp (`maxpd` and `minpd` keep their first operand exactly where
    /// `DVec3::max` and `DVec3::min` keep `self`) and truncation (the
    /// clamped values fit an `i32`), so the same codes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
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
#[target_feature(enable = "avx2")]
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

/// Width of the digit of the first pass, over all the codes: 2^11 buckets.
/// Wider digits scatter more slowly (more write streams than the caches and
/// the TLB follow at once); narrower ones leave larger buckets. With it, a
/// bucket of 10^7 codes of a flat scene (whose thin axis leaves 3 of these
/// 11 bits constant) holds some 40 000 codes, about 470 KiB: small enough
/// for its own passes to run from the second-level cache.
const TOP_BITS: u32 = 11;

/// Widest digit of a pass over one run: 2^15 counters, 128 KiB.
const RUN_BITS: u32 = 15;

/// Runs this short or shorter are sorted by insertion, the input itself
/// included: longer ones go through radix passes.
const INSERTION_MAX: usize = 16;

/// Most passes over one run. A run of `m <= 2^32` keys (their indices are
/// `u32`) is sorted on `2 log2 m <= 64` bits: in at most two digits below
/// `2^16` keys, in digits of at most [`RUN_BITS`] bits beyond.
const MAX_PASSES: usize = 5;

/// Indices of `codes` in increasing code order, stable (equal codes keep
/// their input order), and the codes in that order. Linear time.
///
/// One most significant digit pass scatters the codes, with their indices,
/// into buckets on the highest bits that vary (at most [`TOP_BITS`] of
/// them, fewer for small inputs, so that there are at most `2n` buckets).
/// It is the one pass that writes arrays larger than the cache; before it
/// the codes are only read, twice (for the bits that vary, then the bucket
/// sizes). Each bucket is then sorted on its own, in cache, by
/// [`sort_run`]. The scatter is stable and so is each bucket's sort.
pub(crate) fn sort(codes: &[u64]) -> (Vec<u32>, Vec<u64>) {
    let mut order = Vec::new();
    let keys = sort_into(codes, Pool::ONE, &mut order);
    (order, keys)
}

/// [`sort`], the buckets sorted on `pool` (the same result), the indices
/// written into `order` (its previous contents dropped, its memory
/// reused): returns the sorted codes.
pub(crate) fn sort_into(codes: &[u64], pool: Pool, order: &mut Vec<u32>) -> Vec<u64> {
    let n = codes.len();
    order.clear();
    let varying = varying_bits(codes);
    if varying == 0 {
        order.extend(0..n as u32);
        return codes.to_vec();
    }
    if n <= INSERTION_MAX {
        let mut keys = codes.to_vec();
        order.extend(0..n as u32);
        insertion_sort(&mut keys, order);
        return keys;
    }
    let digit = Digit::highest(varying, TOP_BITS.min(n.ilog2() + 1));
    let mut ends = vec![0u32; digit.buckets()];
    for &code in codes {
        ends[digit.of(code)] += 1;
    }
    counts_to_starts(&mut ends);
    let mut keys = vec![0u64; n];
    order.resize(n, 0);
    scatter(
        codes.iter().copied().zip(0u32..),
        digit,
        &mut ends,
        &mut keys,
        order,
    );

    let mut largest = 0;
    let mut start = 0;
    for &end in &ends {
        largest = largest.max(end as usize - start);
        start = end as usize;
    }
    // The buckets, each a run of the keys and of the indices.
    let mut runs = Vec::with_capacity(ends.len());
    let (mut rest_keys, mut rest_order) = (&mut keys[..], &mut order[..]);
    let mut start = 0;
    for &end in &ends {
        let len = end as usize - start;
        let (run_keys, k) = rest_keys.split_at_mut(len);
        let (run_order, o) = rest_order.split_at_mut(len);
        (rest_keys, rest_order) = (k, o);
        if len > 1 {
            runs.push((run_keys, run_order));
        }
        start = end as usize;
    }
    pool.for_each_with(
        runs,
        || Scratch {
            keys: vec![0; largest],
            order: vec![0; largest],
            counts: Vec::new(),
        },
        |scratch, (keys, order)| sort_run(keys, order, scratch),
    );
    keys
}

/// Buffers for sorting one run: keys and indices at least as long as the
/// run, and the pass counters.
struct Scratch {
    keys: Vec<u64>,
    order: Vec<u32>,
    counts: Vec<u32>,
}

/// Sorts a run of `keys` with their `order`, in place and stably, in time
/// linear in its length `m`.
///
/// The run is first sorted on `2 log2 m` bits from its highest varying bit
/// down, by least significant digit passes ([`radix_passes`]: at most two
/// below `2^16` keys, none over more than `2m` counters), each digit
/// starting at the highest varying bit below the previous one, so bits that
/// never vary cost nothing. `m` keys spread over some `m^2` values of those
/// bits, so few agree on all of them unless the keys are clustered or
/// equal. Each group that does, now contiguous, is then sorted on the bits
/// below: by insertion up to [`INSERTION_MAX`] keys, else by this function
/// again, whose passes then start at least `2 log2 17 = 8` bits lower. So a
/// key goes through radix passes at most 8 times.
fn sort_run(keys: &mut [u64], order: &mut [u32], scratch: &mut Scratch) {
    let m = keys.len();
    if m <= INSERTION_MAX {
        insertion_sort(keys, order);
        return;
    }
    let varying = varying_bits(keys);
    if varying == 0 {
        return;
    }
    let bits = 2 * m.ilog2();
    let passes = bits.div_ceil(RUN_BITS.min(m.ilog2() + 1));
    let width = bits.div_ceil(passes);
    let mut digits = [Digit::default(); MAX_PASSES];
    let mut used = 0;
    // The varying bits below the digits so far.
    let mut rest = varying;
    while used < passes as usize && rest != 0 {
        let digit = Digit::highest(rest, width);
        rest &= (1u64 << digit.shift) - 1;
        digits[used] = digit;
        used += 1;
    }
    let digits = &digits[..used];
    radix_passes(keys, order, scratch, digits);
    if rest == 0 {
        return;
    }

    // Groups of keys equal at and above the lowest digit: one scan, whose
    // branch is rarely taken.
    let low = digits[used - 1].shift;
    let mut start = 0;
    let mut prefix = keys[0] >> low;
    for i in 1..m {
        let p = keys[i] >> low;
        if p != prefix {
            if i - start > 1 {
                sort_run(&mut keys[start..i], &mut order[start..i], scratch);
            }
            start = i;
            prefix = p;
        }
    }
    if m - start > 1 {
        sort_run(&mut keys[start..], &mut order[start..], scratch);
    }
}

/// Sorts `keys`, with their `order`, stably on `digits` (highest first):
/// one read of the run counts every digit, then one scatter a digit, lowest
/// first, back and forth between the run and the scratch.
fn radix_passes(keys: &mut [u64], order: &mut [u32], scratch: &mut Scratch, digits: &[Digit]) {
    let m = keys.len();
    let counts = &mut scratch.counts;
    counts.clear();
    counts.resize(digits.iter().map(|d| d.buckets()).sum(), 0);
    let mut offsets = [0; MAX_PASSES];
    let mut offset = 0;
    for (o, digit) in offsets.iter_mut().zip(digits) {
        *o = offset;
        offset += digit.buckets();
    }
    for &k in keys.iter() {
        for (digit, &o) in digits.iter().zip(&offsets) {
            counts[o + digit.of(k)] += 1;
        }
    }
    let (scratch_keys, scratch_order) = (&mut scratch.keys[..m], &mut scratch.order[..m]);
    let mut in_scratch = false;
    for (digit, &o) in digits.iter().zip(&offsets).rev() {
        let starts = &mut counts[o..o + digit.buckets()];
        counts_to_starts(starts);
        if in_scratch {
            let source = scratch_keys
                .iter()
                .copied()
                .zip(scratch_order.iter().copied());
            scatter(source, *digit, starts, keys, order);
        } else {
            let source = keys.iter().copied().zip(order.iter().copied());
            scatter(source, *digit, starts, scratch_keys, scratch_order);
        }
        in_scratch = !in_scratch;
    }
    if in_scratch {
        keys.copy_from_slice(scratch_keys);
        order.copy_from_slice(scratch_order);
    }
}

/// A field of key bits: `width` bits from bit `shift` up (`mask`, the
/// field's `width` low bits set, kept for [`of`](Self::of)).
#[derive(Clone, Copy, Default)]
struct Digit {
    shift: u32,
    width: u32,
    mask: u64,
}

impl Digit {
    /// The digit `width` bits wide (fewer if it would pass bit 0) whose top
    /// bit is the highest set bit of `varying`, which is nonzero.
    fn highest(varying: u64, width: u32) -> Self {
        let top = u64::BITS - varying.leading_zeros();
        let width = width.min(top);
        Self {
            shift: top - width,
            width,
            mask: (1 << width) - 1,
        }
    }

    #[inline(always)]
    fn of(self, key: u64) -> usize {
        ((key >> self.shift) & self.mask) as usize
    }

    fn buckets(self) -> usize {
        1 << self.width
    }
}

/// The bits in which some key differs from the first (0 for no keys).
fn varying_bits(keys: &[u64]) -> u64 {
    let first = keys.first().copied().unwrap_or(0);
    keys.iter().fold(0, |acc, &k| acc | (k ^ first))
}

/// Replaces bucket sizes by bucket starts.
fn counts_to_starts(counts: &mut [u32]) {
    let mut start = 0;
    for c in counts {
        let count = *c;
        *c = start;
        start += count;
    }
}

/// Writes each `(key, index)` of `source` at its bucket's next free place,
/// in source order within each bucket (stable). `starts` holds each
/// bucket's start, and ends holding its end.
fn scatter(
    source: impl Iterator<Item = (u64, u32)>,
    digit: Digit,
    starts: &mut [u32],
    keys: &mut [u64],
    order: &mut [u32],
) {
    for (k, o) in source {
        let d = digit.of(k);
        let at = starts[d] as usize;
        keys[at] = k;
        order[at] = o;
        starts[d] += 1;
    }
}

/// Stable insertion sort of `keys`, with their `order`: quadratic, for
/// short runs only.
fn insertion_sort(keys: &mut [u64], order: &mut [u32]) {
    for i in 1..keys.len() {
        let (k, o) = (keys[i], order[i]);
        let mut j = i;
        while j > 0 && keys[j - 1] > k {
            keys[j] = keys[j - 1];
            order[j] = order[j - 1];
            j -= 1;
        }
        keys[j] = k;
        order[j] = o;
    }
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
    // Per bit of the digit, its cuts (after which code): at most one, four
    // and two, for the highest, lowest and middle bits.
    let mut cuts = [[0usize; 4]; 3];
    let mut counts = [0usize; 3];
    let mut cut_in = |at: usize, step: &[u8]| {
        for (i, &l) in step.iter().enumerate() {
            if l > base {
                let bit = usize::from(l - 1 - base);
                cuts[bit][counts[bit]] = at + i + 1;
                counts[bit] += 1;
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
    halve(&mut out, &cuts, &counts, 0..levels.len() + 1, 3, max_lights);
    Some(out)
}

/// Appends the parts of `run` (see [`children`]): whole if it holds at
/// most `max_lights` codes or no bit of the digit is left (`bits` is the
/// number left, the highest of them next), else cut at its cut of that bit
/// (if any) and each side halved along the bits below.
fn halve(
    out: &mut smallvec::SmallVec<[core::ops::Range<usize>; 8]>,
    cuts: &[[usize; 4]; 3],
    counts: &[usize; 3],
    run: core::ops::Range<usize>,
    bits: usize,
    max_lights: usize,
) {
    if bits == 0 || run.len() <= max_lights {
        out.push(run);
        return;
    }
    let bit = bits - 1;
    let cut = cuts[bit][..counts[bit]]
        .iter()
        .copied()
        .find(|&c| run.start < c && c < run.end);
    match cut {
        Some(c) => {
            halve(out, cuts, counts, run.start..c, bit, max_lights);
            halve(out, cuts, counts, c..run.end, bit, max_lights);
        }
        None => halve(out, cuts, counts, run, bit, max_lights),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn sort_is_stable_and_ordered() {
        let codes = [5u64, 3, 5, 1 << 40, 0, 3];
        let (order, sorted) = sort(&codes);
        assert_eq!(sorted, vec![0, 3, 3, 5, 5, 1 << 40]);
        assert_eq!(order, vec![4, 1, 5, 0, 2, 3]);
    }

    /// The indices of `codes` by the standard library's stable sort.
    fn stable_reference(codes: &[u64]) -> Vec<u32> {
        let mut order: Vec<u32> = (0..codes.len() as u32).collect();
        order.sort_by_key(|&i| codes[i as usize]);
        order
    }

    /// A splitmix64 stream.
    fn random(state: &mut u64) -> u64 {
        *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    #[test]
    fn sort_matches_a_stable_reference_on_structured_inputs() {
        let mut state = 7;
        let mut cases: Vec<Vec<u64>> = vec![vec![], vec![9], vec![9, 2], vec![2, 9], vec![5, 5]];
        for n in [INSERTION_MAX, INSERTION_MAX + 1, 1000, 60_000] {
            let r = &mut state;
            cases.push(vec![0x1234_5678; n]);
            cases.push(
                (0..n)
                    .map(|_| if random(r) & 1 == 0 { 5 } else { 1 << 60 })
                    .collect(),
            );
            // Only the low bits, or only the top bits, vary.
            cases.push(
                (0..n)
                    .map(|_| 0x7000_0000_0000_0000 | (random(r) & 0xff))
                    .collect(),
            );
            cases.push((0..n).map(|_| random(r) & 0xff80_0000_0000_0000).collect());
            cases.push((0..n as u64).map(|i| i * 7919).collect());
            cases.push((0..n as u64).rev().map(|i| i * 7919).collect());
            cases.push((0..n).map(|_| random(r)).collect());
            // Half the codes equal, the rest random.
            cases.push(
                (0..n)
                    .map(|i| if i % 2 == 0 { 1 << 40 } else { random(r) })
                    .collect(),
            );
            // One code far above the rest: a single top bucket holds all
            // the others, which differ in their 40 low bits (for 60 000
            // codes, the widest digits of a run).
            let mut far: Vec<u64> = (0..n).map(|_| random(r) & 0xff_ffff_ffff).collect();
            far[n / 2] = 1 << 62;
            cases.push(far);
        }
        for codes in &cases {
            let (order, sorted) = sort(codes);
            assert_eq!(order, stable_reference(codes), "{} codes", codes.len());
            let gathered: Vec<u64> = order.iter().map(|&k| codes[k as usize]).collect();
            assert_eq!(sorted, gathered, "{} codes", codes.len());
        }
    }

    proptest::proptest! {
        /// `sort` agrees with a stable reference on codes made of a few
        /// shared high parts, a few middle parts a gap above the low bits,
        /// a few shared low parts and random lowest bits: so with shared
        /// prefixes, duplicates, and groups of codes longer than
        /// `INSERTION_MAX` that agree on all the bits a run's passes look
        /// at and differ below. Lengths range from either side of
        /// `INSERTION_MAX` to thousands, whose buckets take the radix
        /// passes.
        #[test]
        fn sort_matches_a_stable_reference(
            len in proptest::prop_oneof![0..=3 * INSERTION_MAX, 0usize..6000],
            highs in proptest::collection::vec(proptest::prelude::any::<u64>(), 1..4),
            mids in proptest::collection::vec(0u64..4, 1..4),
            lows in proptest::collection::vec(proptest::prelude::any::<u64>(), 1..4),
            low_bits in 0u32..=40,
            gap in 0u32..=20,
            random_bits in 0u32..=12,
            mut state: u64,
        ) {
            let mid_shift = low_bits + gap;
            let high_mask = u64::MAX << (mid_shift + 2);
            let low_mask = (1u64 << low_bits) - 1;
            let random_mask = low_mask & ((1 << random_bits) - 1);
            let codes: Vec<u64> = (0..len)
                .map(|_| {
                    let r = random(&mut state);
                    let high = highs[r as usize % highs.len()] & high_mask;
                    let mid = mids[(r >> 20) as usize % mids.len()] << mid_shift;
                    let low = lows[(r >> 40) as usize % lows.len()] & low_mask & !random_mask;
                    high | mid | low | (random(&mut state) & random_mask)
                })
                .collect();
            let (order, sorted) = sort(&codes);
            proptest::prop_assert_eq!(&order, &stable_reference(&codes));
            proptest::prop_assert!(sorted.iter().zip(&order).all(|(&c, &k)| c == codes[k as usize]));
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
