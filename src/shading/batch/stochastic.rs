//! The stochastic cut for a batch of points: one certified coarse cut
//! shared by each group of neighbouring points, then, at each point, lights
//! sampled inside every node that cut leaves (after Lin and Yuksel 2020,
//! who share stochastic lightcuts between neighbouring pixels).

use glam::{DVec3, Vec3};

use super::BatchStats;
use super::group::{
    BUDGET_SHARE, GROUP_MIN_POINTS, MIN_BUDGET_PER_POINT, group_geometry, note_alone_cost,
};
use crate::cut::{Cut, Shared, Spend};
use crate::geometry::Surface;
use crate::sampling::{At, Stochastic, Tally};
use crate::shader::{Seal, Shader};
use crate::shading::grouping::{Groups, groups};
use crate::shading::{Accepts, Query, Shading};
use crate::visibility::Visibility;
use crate::{Lambert, ShadeError, Stop, Threshold};

/// The group's cut grew past what its points may spend.
struct TooCostly;

/// What the points of one batch share besides the session: the queries,
/// the threshold, the random numbers and where the results go.
struct Call<'a, M, U> {
    queries: &'a [Query<M>],
    threshold: Threshold,
    uniform: U,
    results: &'a mut [Stochastic],
    stats: BatchStats,
    /// Running estimate of what a point's own stochastic cut costs, in
    /// node bounds (0: none yet), as the certified batch call keeps it.
    alone_cost: f64,
}

impl<S: Shader> Shading<'_, S> {
    /// [`shade_stochastic`](Self::shade_stochastic) for a batch of queries,
    /// neighbouring points sharing the certified cut that chooses the nodes
    /// to sample: one result per query into `results`, in the same order.
    ///
    /// The points are grouped as [`shade_batch`](Self::shade_batch) groups
    /// them (runs of neighbouring points with similar normals), and each
    /// group's cut at `threshold` is chosen once with the certified bounds
    /// valid for every point of the group: nodes below every point's
    /// tangent plane, hidden from the whole group (a host that classifies
    /// groups) or aimed away from every point drop out, exactly. Each point
    /// then sums the cut's single lights exactly at its own position and
    /// normal and draws two lights inside each of the cut's nodes, as
    /// [`LightSampler`](crate::LightSampler) descends from that node at the
    /// point, with their exact probabilities. Which nodes are sampled does
    /// not depend on the random numbers, and each node's two samples are
    /// unbiased for its lights' sum at the point, so each result's
    /// expectation is the exact model at its point (with the host's
    /// visibility): unbiased, *not* certified, with an unbiased variance
    /// estimate, as for a single point. The shared cut costs its group
    /// once instead of once per point; the samples are each point's own.
    ///
    /// Cuts are shared under the conditions of [`shade_batch`](Self::shade_batch)
    /// (the crate's diffuse shaders, [`Unoccluded`](crate::Unoccluded) or a
    /// host that classifies groups, no budget or maximal contribution).
    /// Groups of fewer than four points, groups whose shared cut would cost
    /// more than a share of what their points cost on their own (a running
    /// estimate, as in `shade_batch`), and every point of a call that
    /// cannot share are shaded by [`shade_stochastic`](Self::shade_stochastic),
    /// point by point, in the order of the queries' groups. A shared
    /// point's [`Stochastic::nodes_evaluated`] and
    /// [`classify_queries`](Stochastic::classify_queries) are 0: the shared
    /// cut's bounds and classifications are counted once, in the returned
    /// [`BatchStats`].
    ///
    /// `uniform` supplies the random numbers, uniform in `[0, 1)`: two per
    /// node sampled at each point.
    ///
    /// Whether sharing pays: the shared cut costs a group once, but each
    /// point still draws its own samples, and at coarse thresholds the
    /// descents cost more than the cut; a group's cut, valid for all its
    /// points, also leaves more nodes than one point's. `cargo run
    /// --release -p manylights-report -- stochastic-batch` measures the
    /// two ways over a camera's image, time and variance.
    ///
    /// Allocation: as [`shade_batch`](Self::shade_batch), the Morton order
    /// and group list (linear in the batch); the session's scratch space is
    /// reused across calls.
    ///
    /// ```
    /// use glam::Vec3;
    /// use manylights::{Lambert, LightTree, PointLight, Query, Stochastic, Threshold, Unoccluded};
    ///
    /// let lights: Vec<PointLight> = (0..5000)
    ///     .map(|i| PointLight::new(Vec3::new((i % 70) as f32, (i / 70) as f32, 3.0), Vec3::ONE))
    ///     .collect();
    /// let tree = LightTree::build(&lights)?;
    /// let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
    /// // A tile of 8 x 8 points on the ground.
    /// let queries: Vec<Query> = (0..64)
    ///     .map(|k| Query::new(Vec3::new(30.0 + (k % 8) as f32 * 0.1, 30.0 + (k / 8) as f32 * 0.1, 0.0), Vec3::Z))
    ///     .collect::<Result<_, _>>()?;
    /// let mut state = 1u64;
    /// let uniform = move || {
    ///     state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ///     (state >> 11) as f64 / (1u64 << 53) as f64
    /// };
    /// let mut results = vec![Stochastic::default(); queries.len()];
    /// let stats = shading.shade_stochastic_batch(&queries, Threshold::relative(0.2), Unoccluded, uniform, &mut results)?;
    /// assert_eq!(stats.shared_points + stats.points_alone, 64);
    /// assert!(results.iter().all(|r| r.radiance.min_element() > 0.0));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`ShadeError::BatchLength`] when `results` is not as long as
    /// `queries`; the threshold errors of
    /// [`shade_stochastic`](Self::shade_stochastic).
    pub fn shade_stochastic_batch<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        threshold: Threshold,
        mut visibility: V,
        uniform: impl FnMut() -> f64,
        results: &mut [Stochastic],
    ) -> Result<BatchStats, ShadeError>
    where
        S: Accepts<M>,
    {
        super::check_batch(queries.len(), results.len(), &threshold)?;
        let mut call = Call {
            queries,
            threshold,
            uniform,
            results,
            stats: BatchStats::default(),
            alone_cost: 0.0,
        };
        if !self.shares::<V>(&threshold) {
            for i in 0..queries.len() {
                self.stochastic_alone(&mut call, i, &mut visibility)?;
            }
            return Ok(call.stats);
        }
        let Groups { order, runs } = groups(queries);
        for run in runs {
            self.stochastic_group(&mut call, &order[run], &mut visibility)?;
        }
        Ok(call.stats)
    }

    /// Point `i` of the call by its own stochastic cut, its cost folded
    /// into the running estimate.
    fn stochastic_alone<M, V: Visibility, U: FnMut() -> f64>(
        &mut self,
        call: &mut Call<'_, M, U>,
        i: usize,
        visibility: &mut V,
    ) -> Result<(), ShadeError>
    where
        S: Accepts<M>,
    {
        let r = self.shade_stochastic(
            &call.queries[i],
            call.threshold,
            &mut *visibility,
            &mut call.uniform,
        )?;
        note_alone_cost(
            &mut call.alone_cost,
            [
                r.nodes_evaluated,
                r.lights_evaluated,
                r.classify_queries,
                r.point_queries,
            ],
        );
        call.results[i] = r;
        call.stats.points_alone += 1;
        Ok(())
    }

    /// The queries `points` (indices into the call's queries) through one
    /// shared cut, or point by point where sharing does not pay.
    fn stochastic_group<M, V: Visibility, U: FnMut() -> f64>(
        &mut self,
        call: &mut Call<'_, M, U>,
        points: &[u32],
        visibility: &mut V,
    ) -> Result<(), ShadeError>
    where
        S: Accepts<M>,
    {
        let kd = self.shader.diffuse_albedo(Seal);
        if let (Some(kd), true) = (kd, points.len() >= GROUP_MIN_POINTS) {
            let unknown = call.alone_cost == 0.0;
            let shared = crate::dispatch::with_avx2(
                #[inline(always)]
                || self.stochastic_shared(call, points, visibility, kd),
            );
            match shared {
                Ok(()) => return Ok(()),
                Err(TooCostly) if unknown => {
                    // The first point shaded alone sets the estimate; the
                    // rest are tried again with the budget it gives.
                    self.stochastic_alone(call, points[0] as usize, visibility)?;
                    return self.stochastic_group(call, &points[1..], visibility);
                }
                Err(TooCostly) => {}
            }
        }
        for &i in points {
            self.stochastic_alone(call, i as usize, visibility)?;
        }
        Ok(())
    }

    /// The group's shared cut, then each point's exact sum of its single
    /// lights and samples of its nodes.
    #[inline(always)]
    fn stochastic_shared<M, V: Visibility, U: FnMut() -> f64>(
        &mut self,
        call: &mut Call<'_, M, U>,
        points: &[u32],
        visibility: &mut V,
        kd: DVec3,
    ) -> Result<(), TooCostly> {
        let queries = call.queries;
        let (group, samples) = group_geometry(queries, points, [].iter());
        let Shading {
            tree,
            shader,
            scratch,
            ..
        } = self;
        let tree = *tree;
        let per_point = ((BUDGET_SHARE * call.alone_cost) as u64).max(MIN_BUDGET_PER_POINT);
        let spend = Spend {
            points: points.len() as u64,
            per_point,
        };
        let region = Shared::new(kd, group, samples, spend, &mut scratch.group);
        let list = &mut scratch.point.list;
        let mut cut = Cut::new(tree, &*shader, region, &call.threshold, visibility);
        cut.enter_root(list, None);
        let outcome = cut.run(list, &call.threshold, None);
        call.stats.shared_evaluations += u64::from(cut.work.nodes);
        call.stats.shared_classifications += u64::from(cut.work.classify_queries);
        if outcome.stop == Stop::Budget {
            return Err(TooCostly);
        }
        let shared = cut.region.group_cut(list, None);
        let single = shared.scratch;
        // The lights above every tangent plane carry `kd` in their
        // intensities: the diffuse model with an albedo of 1 is their term.
        let diffuse = Lambert::new(Vec3::ONE);
        for &i in points {
            let query = &queries[i as usize];
            let (surface, point): (&Surface, Vec3) = (query.surface(), query.point());
            let at = At::new(tree, &*shader, surface);
            let mut tally = Tally::new(DVec3::ZERO);
            for &(position, scaled) in &single.above {
                tally.add_exact(diffuse.eval(&(), surface, position, scaled));
            }
            for &(position, intensity, profile) in &single.across {
                let f = profile.factor(position.as_vec3(), surface.point);
                if f > 0.0 {
                    tally.add_exact(shader.eval(&at.per_point, surface, position, intensity) * f);
                }
            }
            for &(position, intensity, profile) in &single.shadowed {
                let f = profile.factor(position.as_vec3(), surface.point);
                let value = shader.eval(&at.per_point, surface, position, intensity) * f;
                if value != DVec3::ZERO {
                    tally.add_ray();
                    if cut.visibility.visible(point, position.as_vec3()) {
                        tally.add_exact(value);
                    }
                }
            }
            for (entry, _) in shared.list.waiting() {
                tally.sample_node(
                    &at,
                    entry.node,
                    entry.seen,
                    point,
                    &mut *cut.visibility,
                    &mut call.uniform,
                );
            }
            call.results[i as usize] = tally.finish(0, 0, 0, 0, outcome.stop);
        }
        call.stats.groups += 1;
        call.stats.shared_points += points.len() as u32;
        Ok(())
    }
}
