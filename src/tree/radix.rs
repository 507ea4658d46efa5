//! A stable radix sort of 64-bit keys with their indices, in linear time:
//! one most significant digit pass into buckets, then each bucket sorted on
//! its own, in cache. The Morton order's sort (see [`morton`](super::morton)).

use super::pool::Pool;

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
    // The buckets of more than one key.
    let mut runs = Vec::with_capacity(ends.len());
    let (mut rest_keys, mut rest_order) = (&mut keys[..], &mut order[..]);
    let mut start = 0;
    for &end in &ends {
        let len = end as usize - start;
        let (run_keys, k) = rest_keys.split_at_mut(len);
        let (run_order, o) = rest_order.split_at_mut(len);
        (rest_keys, rest_order) = (k, o);
        if len > 1 {
            runs.push(Bucket {
                keys: run_keys,
                order: run_order,
            });
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
        |scratch, bucket: Bucket<'_>| sort_run(bucket.keys, bucket.order, scratch),
    );
    keys
}

/// One bucket of the first pass: its run of the keys, and of their indices
/// in step.
struct Bucket<'a> {
    keys: &'a mut [u64],
    order: &'a mut [u32],
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

/// A splitmix64 stream, for the tests of the sort and of the Morton codes.
#[cfg(test)]
pub(super) fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn sort_matches_a_stable_reference_on_structured_inputs() {
        let mut state = 7;
        let mut cases: Vec<Vec<u64>> = vec![vec![], vec![9], vec![9, 2], vec![2, 9], vec![5, 5]];
        for n in [INSERTION_MAX, INSERTION_MAX + 1, 1000, 60_000] {
            let r = &mut state;
            cases.push(vec![0x1234_5678; n]);
            cases.push(
                (0..n)
                    .map(|_| if splitmix(r) & 1 == 0 { 5 } else { 1 << 60 })
                    .collect(),
            );
            // Only the low bits, or only the top bits, vary.
            cases.push(
                (0..n)
                    .map(|_| 0x7000_0000_0000_0000 | (splitmix(r) & 0xff))
                    .collect(),
            );
            cases.push(
                (0..n)
                    .map(|_| splitmix(r) & 0xff80_0000_0000_0000)
                    .collect(),
            );
            cases.push((0..n as u64).map(|i| i * 7919).collect());
            cases.push((0..n as u64).rev().map(|i| i * 7919).collect());
            cases.push((0..n).map(|_| splitmix(r)).collect());
            // Half the codes equal, the rest random.
            cases.push(
                (0..n)
                    .map(|i| if i % 2 == 0 { 1 << 40 } else { splitmix(r) })
                    .collect(),
            );
            // One code far above the rest: a single top bucket holds all
            // the others, which differ in their 40 low bits (for 60 000
            // codes, the widest digits of a run).
            let mut far: Vec<u64> = (0..n).map(|_| splitmix(r) & 0xff_ffff_ffff).collect();
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
                    let r = splitmix(&mut state);
                    let high = highs[r as usize % highs.len()] & high_mask;
                    let mid = mids[(r >> 20) as usize % mids.len()] << mid_shift;
                    let low = lows[(r >> 40) as usize % lows.len()] & low_mask & !random_mask;
                    high | mid | low | (splitmix(&mut state) & random_mask)
                })
                .collect();
            let (order, sorted) = sort(&codes);
            proptest::prop_assert_eq!(&order, &stable_reference(&codes));
            proptest::prop_assert!(sorted.iter().zip(&order).all(|(&c, &k)| c == codes[k as usize]));
        }
    }
}
