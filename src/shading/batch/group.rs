//! One group of a batch: its shared cut (the cut's engine for the group's
//! region), each point's sum over it, further rounds for the points that
//! missed their target, and points shaded on their own where sharing does
//! not pay.

use glam::DVec3;

use super::{Batch, HaloResult, Members, Outcome};
use crate::cut::{Cut, GroupCut, SAMPLES, Samples, Shared, Spend, reported_bound};
use crate::geometry::GroupBounds;
use crate::numeric::CompensatedSum;
use crate::shader::{Seal, Shader};
use crate::shading::packed::{Limits, WIDE};
use crate::shading::{Accepts, Query, Shading};
use crate::visibility::Visibility;
use crate::{BatchStats, ShadeError, ShadeResult, Stop, Threshold};

/// Fewest points worth a shared cut: smaller groups are shaded point by
/// point.
pub(super) const GROUP_MIN_POINTS: usize = 4;
/// What a group's shared cut may cost, per point, before the group is
/// shaded point by point: this share of what a point shaded on its own
/// costs (node bounds, single lights and host queries), as measured on the
/// points shaded alone so far in the chunk of groups; at least
/// [`MIN_BUDGET_PER_POINT`]. Less lets through only the groups that share
/// best and shades more points alone; more lets costly cuts through.
/// `cargo run --release -p manylights-report -- batch` measures the call;
/// `docs/tuning.md` records the shares compared.
pub(super) const BUDGET_SHARE: f64 = 0.6;
/// See [`BUDGET_SHARE`].
pub(super) const MIN_BUDGET_PER_POINT: u64 = 32;
/// Lights a point shaded alone evaluates exactly in the time of one node
/// bound, in the estimate of what a point costs alone.
pub(super) const LIGHTS_PER_BOUND: f64 = 4.0;
/// Rounds of further refinement for the points of a group that missed
/// their target, before they are shaded on their own.
const ROUNDS: usize = 3;

/// The group's cut grew past what its points may spend.
struct TooCostly;

impl<S: Shader> Shading<'_, S> {
    /// Shades chunk `k` of `batch`: the estimate of what a point costs
    /// alone starts afresh, so a chunk gives the same results whichever
    /// thread shades it. Each result goes to `write(index, result)`, each
    /// halo point's to `out`.
    pub(super) fn shade_chunk<M, V: Visibility>(
        &mut self,
        batch: &Batch<'_, M>,
        k: usize,
        threshold: Threshold,
        visibility: &mut V,
        write: &mut impl FnMut(usize, ShadeResult),
        out: &mut Outcome,
    ) -> Result<(), ShadeError>
    where
        S: Accepts<M>,
    {
        self.scratch.batch.alone_cost = 0.0;
        let (first, runs) = batch.chunk(k);
        for r in first..first + runs.len() {
            let members = batch.members(r);
            self.shade_members(batch.queries, members, threshold, visibility, write, out)?;
        }
        Ok(())
    }

    /// Shades the queries `members` (indices into `queries`) as one group,
    /// or point by point when a shared cut does not pay.
    fn shade_members<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        members: Members<'_>,
        threshold: Threshold,
        visibility: &mut V,
        write: &mut impl FnMut(usize, ShadeResult),
        out: &mut Outcome,
    ) -> Result<(), ShadeError>
    where
        S: Accepts<M>,
    {
        let points = members.points;
        if points.len() < GROUP_MIN_POINTS {
            return self.shade_each(queries, points, threshold, visibility, write, out);
        }
        // Without an estimate yet of what sharing must beat, the shared cut
        // gets the least budget; if that is too little, the first point is
        // shaded alone for an estimate.
        let unknown = self.scratch.batch.alone_cost == 0.0;
        match self.shade_shared(queries, members, &threshold, visibility, &mut out.stats) {
            Ok(()) => {
                for (k, &i) in points.iter().enumerate() {
                    let i = i as usize;
                    let result = if self.scratch.batch.alone[k] {
                        self.shade_alone(&queries[i], threshold, &mut *visibility)?
                    } else {
                        self.scratch.batch.results[k]
                    };
                    write(i, result);
                }
                let halo = members.halo.iter().zip(&self.scratch.batch.halo_results);
                out.halo
                    .extend(halo.map(|(&(point, weight), &result)| HaloResult {
                        point,
                        run: members.run,
                        weight,
                        result,
                    }));
                Ok(())
            }
            Err(TooCostly) if unknown => {
                // The first point shaded alone sets the estimate, and the
                // whole group is tried again with the budget it gives: its
                // first point is then shaded over the same cut as its
                // neighbours, not by a cut of its own, which may differ
                // from theirs by up to the threshold (a speck on a smooth
                // image).
                let first = &queries[points[0] as usize];
                self.shade_alone(first, threshold, &mut *visibility)?;
                self.shade_members(queries, members, threshold, visibility, write, out)
            }
            // Sharing does not pay here: every point on its own. (Splitting
            // the group in halves and trying again cost more in cuts that
            // failed than the halves saved.)
            Err(TooCostly) => self.shade_each(queries, points, threshold, visibility, write, out),
        }
    }

    /// Shades the queries `points` (indices into `queries`) each on its own.
    fn shade_each<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        points: &[u32],
        threshold: Threshold,
        visibility: &mut V,
        write: &mut impl FnMut(usize, ShadeResult),
        out: &mut Outcome,
    ) -> Result<(), ShadeError>
    where
        S: Accepts<M>,
    {
        for &i in points {
            let i = i as usize;
            write(
                i,
                self.shade_alone(&queries[i], threshold, &mut *visibility)?,
            );
        }
        out.stats.points_alone += points.len() as u32;
        Ok(())
    }

    /// [`shade_query`](Self::shade_query) for a point of a batch shaded on
    /// its own, its cost (node bounds, lights, host queries) folded into the
    /// running estimate that sets the groups' budgets.
    fn shade_alone<M, V: Visibility>(
        &mut self,
        query: &Query<M>,
        threshold: Threshold,
        visibility: V,
    ) -> Result<ShadeResult, ShadeError>
    where
        S: Accepts<M>,
    {
        let r = self.shade_query(query, threshold, visibility)?;
        note_alone_cost(
            &mut self.scratch.batch.alone_cost,
            [
                r.nodes_evaluated,
                r.lights_evaluated,
                r.classify_queries,
                r.point_queries,
            ],
        );
        Ok(r)
    }

    /// Picks a shared cut for `members` and shades them through it; fills
    /// the scratch results and marks the members that still need shading on
    /// their own. Compiled for AVX2 where the processor has it
    /// ([`dispatch`](crate::dispatch)).
    fn shade_shared<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        members: Members<'_>,
        threshold: &Threshold,
        visibility: &mut V,
        stats: &mut BatchStats,
    ) -> Result<(), TooCostly> {
        let Some(kd) = self.shader.diffuse_albedo(Seal) else {
            return Err(TooCostly);
        };

        crate::dispatch::with_avx2(
            #[inline(always)]
            || self.shared_cut(queries, members, threshold, visibility, stats, kd),
        )
    }

    /// [`shade_shared`](Self::shade_shared)'s work: the group's region, its
    /// cut round by round, each point's sum over it.
    #[inline(always)]
    fn shared_cut<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        group_members: Members<'_>,
        threshold: &Threshold,
        visibility: &mut V,
        stats: &mut BatchStats,
        kd: DVec3,
    ) -> Result<(), TooCostly> {
        let members = group_members.points;
        // The group's geometry takes in its halo: the cut serves those
        // points too.
        let halo = group_members.halo.iter().map(|h| &h.0);
        let (group, samples) = group_geometry(queries, members, halo);
        let Shading {
            tree,
            shader,
            scratch,
            ..
        } = self;
        let (tree, batch) = (*tree, &mut scratch.batch);
        let budget_per_point = ((BUDGET_SHARE * batch.alone_cost) as u64).max(MIN_BUDGET_PER_POINT);
        let spend = Spend {
            points: members.len() as u64,
            per_point: budget_per_point,
        };
        let mut region = Shared::new(kd, group, samples, spend, &mut scratch.group);
        if !tree.slabs.tables.is_empty() && shader.narrows_with_slabs(Seal) {
            region.watch_layers();
        }
        let list = &mut scratch.point.list;
        let mut cut = Cut::new(tree, &*shader, region, threshold, visibility);
        cut.enter_root(list, None);
        let packing = Packing {
            kd,
            limits: limits(tree, &cut.region.group, kd),
        };
        batch.alone.clear();
        batch.alone.resize(members.len(), false);
        batch.results.clear();
        batch.results.resize(members.len(), ShadeResult::EMPTY);
        for round in 0..ROUNDS {
            let outcome = cut.run(list, threshold, None);
            let largest = list.largest();
            // Interpolation across levels: the cut's last nodes blended with
            // their children, for now (the next round refines the unblended
            // cut further).
            let blended = match outcome.stop {
                Stop::ThresholdMet => cut.blend(list, threshold, &outcome),
                Stop::Budget => None,
            };
            stats.shared_evaluations += u64::from(cut.work.nodes);
            stats.shared_classifications += u64::from(cut.work.classify_queries);
            (cut.work.nodes, cut.work.classify_queries) = (0, 0);
            if outcome.stop == Stop::Budget {
                return Err(TooCostly);
            }
            let shared = cut.region.group_cut(list, blended.as_ref());
            let over = packing.pack(&mut batch.packed, tree, &shared, &cut.region);
            let points = Points {
                queries,
                members: group_members,
                shader: &*shader,
                cut: &shared,
                over: &over,
            };
            // Without interpolation a point that met its target on an
            // earlier round keeps that result: the further rounds are for
            // the points that missed. (Interpolated points all take the last
            // round's blend, which keeps the group's image smooth.)
            let keep_met = round > 0 && threshold.interpolation().is_none();
            let met = |r: &ShadeResult| threshold.met(r.radiance, r.error_bound, largest);
            let darkest = points.sum(batch, cut.visibility, keep_met, met);
            if let Some(b) = blended {
                cut.unblend(b);
            }
            cut.region.resum_steering(list);
            let reference = cut.region.steering().max_element();
            if darkest == f64::INFINITY || round + 1 == ROUNDS {
                break;
            }
            // Aim below the darkest point that missed, if it is bright
            // enough to be worth it.
            let next = 0.9 * darkest / reference;
            if !(next > 0.05 * cut.region.margin && next < cut.region.margin) {
                break;
            }
            cut.region.margin = next;
        }
        let shared = batch.alone.iter().filter(|a| !**a).count() as u32;
        stats.groups += 1;
        stats.shared_points += shared;
        stats.points_alone += members.len() as u32 - shared;
        Ok(())
    }
}

/// Folds what a point shaded alone cost (its node bounds, lights, host
/// classifications and point-to-point queries: `work`) into the running
/// `estimate` that sets the groups' budgets. Lights summed exactly cost a
/// fraction of a node bound each.
#[inline]
pub(super) fn note_alone_cost(estimate: &mut f64, work: [u32; 4]) {
    let [nodes, lights, classify, rays] = work.map(f64::from);
    let cost = nodes + lights / LIGHTS_PER_BOUND + classify + rays;
    *estimate = if *estimate == 0.0 {
        cost.max(1.0)
    } else {
        0.875 * *estimate + 0.125 * cost
    };
}

/// A group's geometry, over its `members` and `extra` points (indices
/// into `queries`), and the members that steer a relative target, spread
/// along the group (at least one member). Inlined into the callers, which
/// are compiled for AVX2 where the processor has it.
#[inline(always)]
pub(super) fn group_geometry<'q, M>(
    queries: &[Query<M>],
    members: &'q [u32],
    extra: impl Iterator<Item = &'q u32> + Clone,
) -> (GroupBounds, Samples) {
    let surfaces = (members.iter().chain(extra)).map(|&i| *queries[i as usize].surface());
    let group = GroupBounds::new(surfaces);
    let last = members.len() - 1;
    let samples = Samples::new(|k| {
        let s = queries[members[k * last / (SAMPLES - 1)] as usize].surface();
        (s.point, s.normal)
    });
    (group, samples)
}

/// The points of a group (and of its halo) and what they sum over one
/// round's cut.
struct Points<'p, 'c, M, S> {
    queries: &'p [Query<M>],
    members: Members<'p>,
    shader: &'p S,
    cut: &'p GroupCut<'c>,
    over: &'p Packed,
}

impl<M, S: Shader> Points<'_, '_, M, S> {
    /// Each member's result over the cut into the batch scratch, with
    /// whether it missed its target (`met` says), and each halo point's;
    /// with `keep_met`, members that met their target on an earlier round
    /// keep that result. Returns the radiance of the darkest member that
    /// missed its target (infinite if none).
    #[inline(always)]
    fn sum<V: Visibility>(
        &self,
        batch: &mut super::BatchScratch,
        visibility: &mut V,
        keep_met: bool,
        met: impl Fn(&ShadeResult) -> bool,
    ) -> f64 {
        let mut darkest = f64::INFINITY;
        for (k, &i) in self.members.points.iter().enumerate() {
            if keep_met && !batch.alone[k] {
                continue;
            }
            let r = self.result(i, &batch.packed, visibility);
            let alone = !met(&r);
            (batch.results[k], batch.alone[k]) = (r, alone);
            if alone {
                darkest = darkest.min(r.radiance.max_element());
            }
        }
        // The halo's points over the same cut (interpolation only).
        batch.halo_results.clear();
        for &(i, _) in self.members.halo {
            let r = self.result(i, &batch.packed, visibility);
            batch.halo_results.push(r);
        }
        darkest
    }

    /// Query `i`'s result over the cut, `packed` its packed entries.
    #[inline(always)]
    fn result<V: Visibility>(
        &self,
        i: u32,
        packed: &crate::shading::packed::Packed,
        visibility: &mut V,
    ) -> ShadeResult {
        let query = &self.queries[i as usize];
        self.over
            .result(point_sum(self.shader, self.cut, packed, query, visibility))
    }
}

/// What packing a group's cut for its points needs besides the cut: the
/// diffuse albedo and the limits of what the points and entries can be.
struct Packing {
    kd: DVec3,
    limits: Limits,
}

/// A packed cut as each point's result: the bound every point shares and
/// the counts of what each sums.
struct Packed {
    bound: DVec3,
    nodes: u32,
    lights: u32,
}

impl Packing {
    /// Packs the cut's nodes (the waiting ones, or a blend's weighted ones)
    /// and its lights above every plane for the points' sums.
    fn pack(
        &self,
        packed: &mut crate::shading::packed::Packed,
        tree: &crate::LightTree,
        cut: &GroupCut<'_>,
        region: &Shared<'_>,
    ) -> Packed {
        let scratch = cut.scratch;
        packed.start(cut.error, region.steering(), region.spread, self.limits);
        // Each node's diffuse estimate times its emission factor's
        // estimate over the group (1 for isotropic lights).
        let factor = |node: u32| region.node_factor(tree, node as usize).estimate;
        if cut.blended {
            for &(node, weight) in &scratch.weighted {
                packed.push_node(
                    &tree.nodes[node as usize],
                    self.kd * (weight * factor(node)),
                );
            }
        } else {
            for (e, _) in cut.list.waiting() {
                packed.push_node(&tree.nodes[e.node as usize], self.kd * factor(e.node));
            }
        }
        for &(position, intensity) in &scratch.above {
            packed.push_light(position.as_vec3(), intensity);
        }
        Packed {
            bound: packed_bound(cut.error, packed.len()),
            nodes: (packed.len() - scratch.above.len()) as u32,
            lights: (scratch.across.len() + scratch.above.len() + scratch.shadowed.len()) as u32,
        }
    }
}

impl Packed {
    /// A point's result over the cut from its [`point_sum`].
    #[inline(always)]
    fn result(&self, (radiance, point_queries, rounding): (DVec3, u32, DVec3)) -> ShadeResult {
        ShadeResult {
            radiance,
            error_bound: self.bound + rounding,
            nodes_evaluated: self.nodes,
            lights_evaluated: self.lights,
            classify_queries: 0,
            point_queries,
            stop: Stop::ThresholdMet,
        }
    }
}

/// One point's sum over a group's cut (`packed` its packed entries),
/// clamped at 0 (the exact value is non-negative), the point-to-point
/// queries it asked, and the bound on the rounding of its packed sum when
/// that was in `f32` (else 0).
#[inline(always)]
fn point_sum<S: Shader, M, V: Visibility>(
    shader: &S,
    cut: &GroupCut<'_>,
    packed: &crate::shading::packed::Packed,
    query: &Query<M>,
    visibility: &mut V,
) -> (DVec3, u32, DVec3) {
    let surface = query.surface();
    let scratch = cut.scratch;
    let mut sum = CompensatedSum::default();
    let mut rays = 0;
    if !scratch.across.is_empty() || !scratch.shadowed.is_empty() {
        let per_point = shader.prepare(surface);
        let p = surface.point;
        for &(position, intensity, profile) in &scratch.across {
            let f = profile.factor(position.as_vec3(), p);
            if f > 0.0 {
                sum.add(shader.eval(&per_point, surface, position, intensity) * f);
            }
        }
        for &(position, intensity, profile) in &scratch.shadowed {
            let f = profile.factor(position.as_vec3(), p);
            let value = shader.eval(&per_point, surface, position, intensity) * f;
            if value != DVec3::ZERO {
                rays += 1;
                if visibility.visible(query.point(), position.as_vec3()) {
                    sum.add(value);
                }
            }
        }
    }
    let packed = packed.sum(surface.point, surface.normal);
    sum.add(packed.value);
    (sum.value().max(DVec3::ZERO), rays, packed.rounding)
}

/// Every entry lies within the root's box and is at most the root's
/// intensity (blend weights are at most 1); the points lie within the
/// group's ball.
fn limits(tree: &crate::LightTree, group: &GroupBounds, kd: DVec3) -> Limits {
    tree.nodes.first().map_or(
        Limits {
            brightest: 0.0,
            extent: 0.0,
            radius: group.radius,
        },
        |root| Limits {
            brightest: (root.intensity * kd).max_element(),
            extent: f64::from(root.aabb.min.abs().max(root.aabb.max.abs()).max_element())
                .max(group.centre.abs().max_element() + group.radius),
            radius: group.radius,
        },
    )
}

/// The certified bound reported for a shared cut's summed `error` whose
/// points sum `entries` packed estimates: the compensated sums' allowance of
/// [`reported_bound`], and the lanes' plain sums. A plain sum of `m` terms
/// is within `m * 2^-53` of the sum of their magnitudes; each term lies
/// within its error of a non-negative exact value, so that is at most
/// `m * 2^-53 (exact + error)`: the exact part falls within the rounding
/// allowance (`m <= 2^16`), the error part is added here.
pub(crate) fn packed_bound(error: DVec3, entries: usize) -> DVec3 {
    let lane_terms = (entries / WIDE + 2) as f64;
    reported_bound(error) * (1.0 + lane_terms * f64::EPSILON)
}
