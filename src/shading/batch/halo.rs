//! Group borders with interpolation: each group's cut also serves the
//! points of neighbouring groups near its border (its halo), and each point
//! blends the results of the groups whose halo holds it.

use core::ops::Range;

use glam::DVec3;

use super::HaloResult;
use crate::shading::Query;
use crate::shading::grouping::{GROUP_NORMAL_SPREAD, points_box};
use crate::{ShadeResult, Stop, Target, Threshold};

/// A group's halo: points of other groups (indices into the queries) with
/// their blend weights.
pub(super) type Halo = Vec<(u32, f64)>;

/// With interpolation, a group's cut also serves the points of other groups
/// within this share of the largest side of its points' box (its halo), and
/// each point blends the results of its own group and of the groups whose
/// halo holds it (see [`blend_halos`]). A group of 128 pixels is about 11
/// pixels across, so a quarter blends over about 3 pixels on each side of
/// a border; wider halos smooth borders more and cost more (the seams
/// table of `cargo run --release -p manylights-report -- batch` measures
/// both; `docs/tuning.md` has the measurements behind the choice).
const HALO_SHARE: f64 = 0.25;
/// Each group's halo when `threshold` interpolates (none otherwise, and
/// none for Lightcuts' per-node target): the points of other groups whose
/// distance to the group's points' box is less than the halo width,
/// [`HALO_SHARE`] of the box's largest side, and whose normals lie within
/// [`GROUP_NORMAL_SPREAD`] of the group's first; each with the weight
/// `1 - distance / width`, which is 1 on the box and falls to 0 at the
/// halo's edge.
pub(super) fn halos<M>(
    queries: &[Query<M>],
    order: &[u32],
    runs: &[Range<usize>],
    threshold: &Threshold,
) -> Vec<Halo> {
    if threshold.interpolation().is_none() || matches!(threshold.target(), Target::PerNode(_)) {
        return Vec::new();
    }
    let surface = |k: usize| queries[order[k] as usize].surface();
    let boxes: Vec<(DVec3, DVec3, f64)> = runs
        .iter()
        .map(|run| {
            let (lo, hi) = points_box(queries, &order[run.clone()]);
            (lo, hi, HALO_SHARE * (hi - lo).max_element())
        })
        .collect();
    let mut halos = vec![Vec::new(); runs.len()];
    // The points of group `s` in the halo of group `r`.
    let mut add = |r: usize, s: usize| {
        let (lo, hi, width) = boxes[r];
        let first = surface(runs[r].start).normal;
        for k in runs[s].clone() {
            let at = surface(k);
            let distance = (lo - at.point).max(at.point - hi).max(DVec3::ZERO).length();
            if distance < width && (at.normal - first).length() <= GROUP_NORMAL_SPREAD {
                halos[r].push((order[k], 1.0 - distance / width));
            }
        }
    };
    // The pairs of groups whose boxes, grown by their halo widths, meet: a
    // sweep along x over the grown boxes.
    let mut by_x: Vec<usize> = (0..runs.len()).collect();
    by_x.sort_by(|&a, &b| (boxes[a].0.x - boxes[a].2).total_cmp(&(boxes[b].0.x - boxes[b].2)));
    let mut active: Vec<usize> = Vec::new();
    for &r in &by_x {
        let (lo, hi, width) = boxes[r];
        active.retain(|&s| boxes[s].1.x + boxes[s].2 >= lo.x - width);
        for &s in &active {
            let (lo_s, hi_s, width_s) = boxes[s];
            let meet = (lo - width).cmple(hi_s + width_s).all()
                && (lo_s - width_s).cmple(hi + width).all();
            if meet {
                add(r, s);
                add(s, r);
            }
        }
        active.push(r);
    }
    halos
}

/// Blends each point's own result with the results of the groups whose
/// halo holds it, weighted by the halo weights (its own with weight 1).
///
/// Each result is within its certified bound of the exact value, so a
/// weighted mean with non-negative weights is within the weighted mean of
/// the bounds; the mean of `m` non-negative terms rounds within
/// `(2m + 2)` ulps, and `2m + 4` are added to the bound, relative to the
/// blended value. A point keeps its own result when that missed its
/// target, or when the blend would.
///
/// Inside a group every weight but its own falls continuously to 0 at the
/// halo's edge, so the blend changes continuously from one group to the
/// next: the seams that two groups' different cuts leave at their border
/// are spread over the halo.
pub(super) fn blend_halos(
    results: &mut [ShadeResult],
    mut halo: Vec<HaloResult>,
    threshold: &Threshold,
) {
    halo.sort_unstable_by_key(|h| (h.point, h.run));
    for same in halo.chunk_by(|a, b| a.point == b.point) {
        let own = &mut results[same[0].point as usize];
        if own.stop != Stop::ThresholdMet {
            continue;
        }
        let (mut weight, mut radiance, mut bound) = (1.0, own.radiance, own.error_bound);
        let mut blended = *own;
        for h in same {
            weight += h.weight;
            radiance += h.result.radiance * h.weight;
            bound += h.result.error_bound * h.weight;
            blended.nodes_evaluated = blended
                .nodes_evaluated
                .saturating_add(h.result.nodes_evaluated);
            blended.lights_evaluated = blended
                .lights_evaluated
                .saturating_add(h.result.lights_evaluated);
            blended.point_queries = blended.point_queries.saturating_add(h.result.point_queries);
        }
        let rounding = (2 * same.len() + 6) as f64 * f64::EPSILON;
        blended.radiance = radiance / weight;
        blended.error_bound = bound / weight * (1.0 + rounding) + blended.radiance * rounding;
        // No largest node error: halos are only formed for relative and
        // absolute targets, whose check does not read it.
        if threshold.met(blended.radiance, blended.error_bound, 0.0) {
            *own = blended;
        }
    }
}
