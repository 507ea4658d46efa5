//! How a batch is cut into groups: the points in Morton order over the
//! batch's bounding cube, the order's cells of at most [`GROUP_POINTS`]
//! points, each cut further where normals turn.
//!
//! The codes and their order are the tree's (over the points' box; a
//! stable radix sort, so equal codes keep the queries' order). The points
//! are copied once from the queries, which are larger, for the two passes
//! over them (the box, then the codes).

use core::ops::Range;

use glam::{DVec3, Vec3};

use super::Query;
use crate::geometry::Aabb;
use crate::tree::morton;

/// Most points in a group: larger cells share each cut among more points
/// but cover more ground, so their cuts serve their points less closely
/// (`docs/tuning.md` has the sizes compared).
pub(super) const GROUP_POINTS: usize = 128;
/// A point joins the group being formed only if its normal is within this
/// distance (`|n - n_first|`, about 29 degrees) of the group's first normal.
pub(super) const GROUP_NORMAL_SPREAD: f64 = 0.5;
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
    /// cut must serve the whole span. `cargo run --release -p
    /// manylights-report -- batch` measures the call; `docs/tuning.md`
    /// records how cells compared with runs and which sizes were tried.
    pub(super) runs: Vec<Range<usize>>,
}

/// The groups of `queries`.
pub(super) fn groups<M>(queries: &[Query<M>]) -> Groups {
    // The points read once from the queries (which are larger).
    let points: Vec<Vec3> = queries.iter().map(Query::point).collect();
    let scene = points.iter().fold(Aabb::EMPTY, |b, &p| b.union_point(p));
    let codes = morton::codes(points.iter().copied(), scene);
    let (order, codes) = morton::sort(&codes);
    let mut cells = Vec::new();
    morton_cells(&codes, 0..order.len(), &mut cells);
    let mut runs = Vec::with_capacity(cells.len());
    for cell in cells {
        normal_runs(queries, &order, cell, &mut runs);
    }
    Groups { order, runs }
}

/// Appends the runs of `cell` (a range of `order`) whose normals lie within
/// [`GROUP_NORMAL_SPREAD`] of the run's first to `runs`, in order.
fn normal_runs<M>(
    queries: &[Query<M>],
    order: &[u32],
    cell: Range<usize>,
    runs: &mut Vec<Range<usize>>,
) {
    let normal = |k: usize| queries[order[k] as usize].surface().normal;
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

/// Appends to `cells` the cells of the Morton tree over the sorted `codes`
/// in `range` holding at most [`GROUP_POINTS`] codes each, in order: a
/// range too large is split where the highest bit in which its first and
/// last codes differ turns on. Points with equal codes (beyond the curve's
/// resolution) are cut into consecutive runs.
fn morton_cells(codes: &[u64], range: Range<usize>, cells: &mut Vec<Range<usize>>) {
    if range.len() <= GROUP_POINTS {
        if !range.is_empty() {
            cells.push(range);
        }
        return;
    }
    let (first, last) = (codes[range.start], codes[range.end - 1]);
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
    let mid = range.start + codes[range.clone()].partition_point(|c| c & bit == 0);
    morton_cells(codes, range.start..mid, cells);
    morton_cells(codes, mid..range.end, cells);
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

    /// Sorted pseudo-random codes, clustered (few distinct high bits) with
    /// runs of equal codes.
    fn codes(n: usize, seed: u64) -> Vec<u64> {
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
        codes.sort_unstable();
        codes
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
            let codes = codes(n, seed);
            let mut cells = Vec::new();
            morton_cells(&codes, 0..n, &mut cells);
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
