//! How a batch is cut into groups: the points in Morton order over the
//! batch's bounding cube, the order's cells of at most [`GROUP_POINTS`]
//! points, each cut further where normals turn.
//!
//! The order is a sort of `(code, index)` pairs by code, stable (so equal
//! codes keep the queries' order): one pass splits the pairs by the
//! highest [`BUCKET_BITS`] bits in which the codes differ, then each bucket
//! is sorted on its own by a least-significant-digit radix sort (a bucket
//! is a cell of the Morton tree, most often small enough to sort in
//! cache). The points are read once from the queries into a compact array
//! first: the queries are larger, and reading them twice (for the box,
//! then the codes) cost more than the sort.

use core::ops::Range;

use glam::{DVec3, Vec3};

use super::Query;
use crate::tree::morton;

/// Most points in a group.
pub(super) const GROUP_POINTS: usize = 128;
/// A point joins the group being formed only if its normal is within this
/// distance (`|n - n_first|`, about 29 degrees) of the group's first normal.
pub(super) const GROUP_NORMAL_SPREAD: f64 = 0.5;
/// The first pass of the sort splits the codes into buckets by this many
/// of their highest varying bits.
const BUCKET_BITS: u32 = 8;

/// A query's Morton code and its index.
type Keyed = (u64, u32);

/// Morton codes of points over a bounding cube.
struct MortonFrame {
    min: DVec3,
    scale: f64,
    top: DVec3,
}

impl MortonFrame {
    /// The frame of the cube at `min` whose side is the box's largest.
    fn new((min, max): (DVec3, DVec3)) -> Self {
        let extent = (max - min).max_element();
        let cells = f64::from(1u32 << morton::BITS_PER_AXIS);
        Self {
            min,
            scale: if extent > 0.0 { cells / extent } else { 0.0 },
            top: DVec3::splat(cells - 1.0),
        }
    }

    fn code(&self, point: DVec3) -> u64 {
        let c = ((point - self.min) * self.scale).clamp(DVec3::ZERO, self.top);
        morton::spread(c.x as u32)
            | morton::spread(c.y as u32) << 1
            | morton::spread(c.z as u32) << 2
    }
}

/// The bounding box of `points`.
fn bounds(points: &[Vec3]) -> (DVec3, DVec3) {
    let (mut min, mut max) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for &p in points {
        (min, max) = (min.min(p), max.max(p));
    }
    (min.as_dvec3(), max.as_dvec3())
}

/// The pairs of `points[first..]` (`out` as long).
fn fill_codes(frame: &MortonFrame, points: &[Vec3], first: usize, out: &mut [Keyed]) {
    for (k, (pair, p)) in out.iter_mut().zip(points).enumerate() {
        *pair = (frame.code(p.as_dvec3()), (first + k) as u32);
    }
}

/// Splits `keyed` (in index order) into `sorted` by the highest
/// [`BUCKET_BITS`] bits of `varying` (the bits in which some codes differ),
/// stably; returns the buckets of more than one pair.
fn buckets(keyed: &[Keyed], sorted: &mut [Keyed], varying: u64) -> Vec<Range<usize>> {
    let shift = (64 - varying.leading_zeros()).saturating_sub(BUCKET_BITS);
    let digit = |code: u64| ((code >> shift) & ((1 << BUCKET_BITS) - 1)) as usize;
    let mut starts = [0usize; (1 << BUCKET_BITS) + 1];
    for &(code, _) in keyed {
        starts[digit(code) + 1] += 1;
    }
    for b in 0..1 << BUCKET_BITS {
        starts[b + 1] += starts[b];
    }
    let mut next = starts;
    for &pair in keyed {
        let d = digit(pair.0);
        sorted[next[d]] = pair;
        next[d] += 1;
    }
    starts
        .windows(2)
        .map(|w| w[0]..w[1])
        .filter(|r| r.len() > 1)
        .collect()
}

/// Sorts `pairs` by code, stably: least significant digit first, 8 bits a
/// pass, passes whose digit is the same for every pair skipped; `scratch`
/// is as long as `pairs`.
fn radix_sort(pairs: &mut [Keyed], scratch: &mut [Keyed]) {
    let Some(&(first, _)) = pairs.first() else {
        return;
    };
    let varying = pairs.iter().fold(0, |acc, &(code, _)| acc | (code ^ first));
    // Whether the pairs are in `scratch` now.
    let mut in_scratch = false;
    for shift in (0..64).step_by(8) {
        if (varying >> shift) & 0xff == 0 {
            continue;
        }
        let (from, to) = if in_scratch {
            (&*scratch, &mut *pairs)
        } else {
            (&*pairs, &mut *scratch)
        };
        let mut next = [0usize; 256];
        for &(code, _) in from {
            next[((code >> shift) & 0xff) as usize] += 1;
        }
        let mut start = 0;
        for n in &mut next {
            (*n, start) = (start, start + *n);
        }
        for &pair in from {
            let d = ((pair.0 >> shift) & 0xff) as usize;
            to[next[d]] = pair;
            next[d] += 1;
        }
        in_scratch = !in_scratch;
    }
    if in_scratch {
        pairs.copy_from_slice(scratch);
    }
}

/// A batch's groups.
pub(super) struct Groups {
    /// Indices of the queries in Morton order of their points over the
    /// batch's bounding cube (equal codes in the queries' order).
    pub(super) order: Vec<u32>,
    /// The groups: ranges of `order` that are the cells of the Morton
    /// quadtree (octree) over the points holding at most [`GROUP_POINTS`]
    /// points, each cut further into runs whose normals lie within
    /// [`GROUP_NORMAL_SPREAD`] of the run's first.
    ///
    /// A cell is compact, as a run of the curve need not be: where the
    /// curve jumps between far cells, a run takes in both sides, and its
    /// cut must serve the whole span. At 10^6 lights, certified 1%, cells
    /// of at most 64 points took about 15% less time than runs of 64, and
    /// cells of at most 128 about 8% less again (256 and 512: no further
    /// gain).
    pub(super) runs: Vec<Range<usize>>,
}

/// The groups of `queries`.
pub(super) fn groups<M>(queries: &[Query<M>]) -> Groups {
    // The points read once from the queries (which are larger).
    let points: Vec<Vec3> = queries.iter().map(Query::point).collect();
    let frame = MortonFrame::new(bounds(&points));
    let mut pairs = vec![(0, 0); queries.len()];
    fill_codes(&frame, &points, 0, &mut pairs);
    let mut scratch = vec![(0, 0); queries.len()];
    let runs = sort_and_group(queries, &mut pairs, &mut scratch);
    Groups {
        order: pairs.into_iter().map(|(_, i)| i).collect(),
        runs,
    }
}

/// The bitwise AND and OR of the codes of `pairs`.
fn code_bits(pairs: &[Keyed]) -> (u64, u64) {
    pairs.iter().fold((u64::MAX, 0), |(and, or), &(code, _)| {
        (and & code, or | code)
    })
}

/// Sorts `pairs` (equal codes in index order) by code, stably, and returns
/// their groups as ranges of `pairs`; `scratch` as long.
fn sort_and_group<M>(
    queries: &[Query<M>],
    pairs: &mut [Keyed],
    scratch: &mut [Keyed],
) -> Vec<Range<usize>> {
    let (and, or) = code_bits(pairs);
    for bucket in buckets(pairs, scratch, and ^ or) {
        radix_sort(&mut scratch[bucket.clone()], &mut pairs[bucket]);
    }
    pairs.copy_from_slice(scratch);
    let mut cells = Vec::new();
    morton_cells(pairs, 0..pairs.len(), &mut cells);
    let mut runs = Vec::with_capacity(cells.len());
    for cell in cells {
        normal_runs(queries, pairs, cell, &mut runs);
    }
    runs
}

/// Appends the runs of `cell` (a range of `pairs`) whose normals lie within
/// [`GROUP_NORMAL_SPREAD`] of the run's first to `runs`, in order.
fn normal_runs<M>(
    queries: &[Query<M>],
    pairs: &[Keyed],
    cell: Range<usize>,
    runs: &mut Vec<Range<usize>>,
) {
    let normal = |k: usize| queries[pairs[k].1 as usize].surface().normal;
    let mut start = cell.start;
    while start < cell.end {
        let first = normal(start);
        let mut end = start + 1;
        while end < cell.end && (normal(end) - first).length() <= GROUP_NORMAL_SPREAD {
            end += 1;
        }
        runs.push(start..end);
        start = end;
    }
}

/// Appends to `cells` the cells of the Morton tree over the sorted `pairs`
/// in `range` holding at most [`GROUP_POINTS`] pairs each, in order: a
/// range too large is split where the highest bit in which its first and
/// last codes differ turns on. Points with equal codes (beyond the curve's
/// resolution) are cut into consecutive runs.
fn morton_cells(pairs: &[Keyed], range: Range<usize>, cells: &mut Vec<Range<usize>>) {
    if range.len() <= GROUP_POINTS {
        if !range.is_empty() {
            cells.push(range);
        }
        return;
    }
    let (first, last) = (pairs[range.start].0, pairs[range.end - 1].0);
    if first == last {
        let mut start = range.start;
        while start < range.end {
            let end = (start + GROUP_POINTS).min(range.end);
            cells.push(start..end);
            start = end;
        }
        return;
    }
    let bit = 1u64 << (63 - (first ^ last).leading_zeros());
    let mid = range.start + pairs[range.clone()].partition_point(|&(c, _)| c & bit == 0);
    morton_cells(pairs, range.start..mid, cells);
    morton_cells(pairs, mid..range.end, cells);
}

/// The bounding box of the points of `queries` at `indices`.
pub(super) fn points_box<M>(queries: &[Query<M>], indices: &[u32]) -> (DVec3, DVec3) {
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for &i in indices {
        let p = queries[i as usize].surface().point;
        (lo, hi) = (lo.min(p), hi.max(p));
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pseudo-random codes, clustered (few distinct high bits) with many
    /// equal codes; sorted when `sorted`.
    fn codes(n: usize, seed: u64, sorted: bool) -> Vec<u64> {
        let mut state = seed;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            state >> 1
        };
        let mut codes: Vec<u64> = (0..n)
            .map(|_| {
                let r = next();
                match r % 4 {
                    0 => r & 0xff,
                    1 => 42,
                    _ => r,
                }
            })
            .collect();
        if sorted {
            codes.sort_unstable();
        }
        codes
    }

    #[test]
    fn buckets_then_radix_sort_is_a_stable_sort_by_code() {
        for (n, seed) in [(0, 1), (1, 2), (2, 3), (300, 4), (5000, 5), (20_000, 6)] {
            let keyed: Vec<Keyed> = codes(n, seed, false)
                .into_iter()
                .enumerate()
                .map(|(i, c)| (c, i as u32))
                .collect();
            let (and, or) = keyed
                .iter()
                .fold((u64::MAX, 0), |(a, o), &(c, _)| (a & c, o | c));
            let mut sorted = vec![(0, 0); n];
            let mut scratch = keyed.clone();
            for bucket in buckets(&keyed, &mut sorted, and ^ or) {
                radix_sort(&mut sorted[bucket.clone()], &mut scratch[bucket]);
            }
            let mut expected = keyed.clone();
            expected.sort_unstable();
            assert_eq!(sorted, expected, "{n} codes");
        }
    }

    #[test]
    fn groups_keep_equal_codes_in_order_and_cut_where_normals_turn() {
        // Points on a grid, each repeated: many equal codes, whose order is
        // the queries' order; normals that turn, so that cells are cut.
        let queries: Vec<Query> = (0..20_000)
            .map(|k| {
                let p = glam::Vec3::new((k % 37) as f32, ((k / 37) % 23) as f32, 0.5);
                let n = if k % 3 == 0 {
                    glam::Vec3::Z
                } else {
                    glam::Vec3::X
                };
                Query::new(p, n).expect("finite")
            })
            .collect();
        let groups = groups(&queries);
        let point = |k: usize| queries[groups.order[k] as usize].point();
        let code = |k: usize| {
            let p = point(k);
            (p.x as u32, p.y as u32)
        };
        // Equal points in the queries' order, and every query once.
        for k in 1..queries.len() {
            if code(k) == code(k - 1) {
                assert!(groups.order[k] > groups.order[k - 1]);
            }
        }
        let mut seen = groups.order.clone();
        seen.sort_unstable();
        assert!(seen.iter().enumerate().all(|(k, &i)| k == i as usize));
        // The runs cover the order, each within one normal.
        let mut at = 0;
        for run in &groups.runs {
            assert_eq!(run.start, at);
            at = run.end;
            let normal = |k: usize| queries[groups.order[k] as usize].surface().normal;
            assert!(run.clone().all(|k| normal(k) == normal(run.start)));
        }
        assert_eq!(at, queries.len());
    }

    #[test]
    fn morton_cells_are_whole_cells_of_at_most_a_group() {
        for (n, seed) in [(0, 1), (1, 2), (128, 3), (129, 4), (5000, 5), (20_000, 6)] {
            let codes = codes(n, seed, true);
            let pairs: Vec<Keyed> = codes.iter().map(|&c| (c, 0)).collect();
            let mut cells = Vec::new();
            morton_cells(&pairs, 0..n, &mut cells);
            // In order, covering every code once.
            let mut at = 0;
            for cell in &cells {
                assert_eq!(cell.start, at);
                assert!(!cell.is_empty() && cell.len() <= GROUP_POINTS);
                at = cell.end;
            }
            assert_eq!(at, n);
            for cell in &cells {
                let (first, last) = (codes[cell.start], codes[cell.end - 1]);
                if first == last {
                    continue;
                }
                // Some aligned cell of the Morton tree holds exactly these
                // codes: the codes sharing `first`'s bits above some level.
                let lowest = 64 - (first ^ last).leading_zeros();
                let whole = (lowest..64).any(|bits| {
                    let inside = codes.iter().filter(|&&c| c >> bits == first >> bits);
                    inside.count() == cell.len()
                });
                assert!(whole, "{cell:?} of {n}");
            }
        }
    }
}
