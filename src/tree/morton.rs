//! Morton order: lights sorted along a Z-order curve over the scene's box,
//! so that every octree cell is a contiguous run.

use glam::{DVec3, Vec3};

use crate::geometry::Aabb;

/// Bits of a Morton code per axis: three interleaved 21-bit coordinates
/// fill 63 bits of a `u64`.
pub(crate) const BITS_PER_AXIS: u32 = 21;

/// Morton codes of `positions` over the cube of side the largest extent of
/// `scene`, their box (cubic cells, so a flat scene is split across its
/// thin axis only once cells are as small as its thickness). The tree
/// codes its lights, the batch call its shading points.
pub(crate) fn codes(positions: impl Iterator<Item = Vec3>, scene: Aabb) -> Vec<u64> {
    let min = scene.min.as_dvec3();
    let extent = (scene.max.as_dvec3() - min).max_element();
    let cells = f64::from(1u32 << BITS_PER_AXIS);
    let scale = if extent > 0.0 { cells / extent } else { 0.0 };
    let top = cells - 1.0;
    positions
        .map(|p| {
            let q = ((p.as_dvec3() - min) * scale).clamp(DVec3::ZERO, DVec3::splat(top));
            spread(q.x as u32) | spread(q.y as u32) << 1 | spread(q.z as u32) << 2
        })
        .collect()
}

/// The 21 low bits of `v`, two zero bits inserted after each.
fn spread(v: u32) -> u64 {
    let mut x = u64::from(v) & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// Indices of `codes` in increasing code order (stable): a least
/// significant digit radix sort, 8 bits a pass, passes whose digit is the
/// same for every code skipped. Linear time.
pub(crate) fn sort(codes: &[u64]) -> Vec<u32> {
    let n = codes.len();
    let mut order: Vec<u32> = (0..n as u32).collect();
    let mut keys = codes.to_vec();
    let mut order_out = vec![0u32; n];
    let mut keys_out = vec![0u64; n];
    let varying = codes.iter().fold(0u64, |acc, &c| acc | (c ^ codes[0]));
    for shift in (0..64).step_by(8) {
        if (varying >> shift) & 0xff == 0 {
            continue;
        }
        let mut counts = [0usize; 256];
        for &k in &keys {
            counts[((k >> shift) & 0xff) as usize] += 1;
        }
        let mut start = 0;
        for c in &mut counts {
            let count = *c;
            *c = start;
            start += count;
        }
        for (&k, &o) in keys.iter().zip(&order) {
            let digit = ((k >> shift) & 0xff) as usize;
            keys_out[counts[digit]] = k;
            order_out[counts[digit]] = o;
            counts[digit] += 1;
        }
        core::mem::swap(&mut keys, &mut keys_out);
        core::mem::swap(&mut order, &mut order_out);
    }
    order
}

/// Splits a run of sorted `codes` at the first octree level where they
/// differ: the sub-runs of equal 3-bit digit at that level (2 to 8 of them,
/// in order), or `None` when every code is equal.
pub(super) fn children(codes: &[u64]) -> Option<smallvec::SmallVec<[core::ops::Range<usize>; 8]>> {
    let (first, last) = (*codes.first()?, *codes.last()?);
    let differ = first ^ last;
    if differ == 0 {
        return None;
    }
    // The highest differing bit, rounded down to the start of its digit.
    let shift = (63 - differ.leading_zeros()) / 3 * 3;
    let digit = |c: u64| (c >> shift) & 7;
    let mut out = smallvec::SmallVec::new();
    let mut start = 0;
    while start < codes.len() {
        let d = digit(codes[start]);
        let end = start + gallop(&codes[start..], |c| digit(c) == d);
        out.push(start..end);
        start = end;
    }
    Some(out)
}

/// The number of leading elements of `run` that satisfy `keep` (which must
/// hold for a prefix of `run` and fail after it): an exponential search from
/// the front, then a binary search in the last doubling, so that finding a
/// sub-run of length `m` reads `O(log m)` codes near its start, in cache,
/// rather than `O(log n)` spread over the whole run.
fn gallop(run: &[u64], keep: impl Fn(u64) -> bool) -> usize {
    let mut bound = 1;
    while bound < run.len() && keep(run[bound]) {
        bound *= 2;
    }
    let low = bound / 2;
    let high = bound.min(run.len());
    low + run[low..high].partition_point(|&c| keep(c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_interleaves() {
        assert_eq!(spread(0b111), 0b1001001);
        assert_eq!(spread(0x1f_ffff).count_ones(), 21);
    }

    #[test]
    fn sort_is_stable_and_ordered() {
        let codes = [5u64, 3, 5, 1 << 40, 0, 3];
        let order = sort(&codes);
        assert_eq!(order, vec![4, 1, 5, 0, 2, 3]);
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
        let runs = children(&codes).unwrap();
        assert_eq!(runs.as_slice(), &[0..2, 2..3, 3..4]);
        assert!(children(&[7, 7, 7]).is_none());
    }
}
