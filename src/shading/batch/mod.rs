//! Batch shading: the points grouped, one certified cut shared by each
//! group of neighbouring points (the cut's engine for a group), each point
//! summing that cut's estimates at its own position and normal, and a
//! point shaded on its own where its group's cut does not pay.

mod group;
mod halo;
#[cfg(feature = "rayon")]
mod parallel;
mod stochastic;

use super::grouping::{Groups, groups};
use super::packed::Packed;
use super::{Accepts, Query, Shading};
use crate::shader::{Seal, Shader};
use crate::visibility::Visibility;
use crate::{ShadeError, ShadeResult, Threshold};

/// What a batch call did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct BatchStats {
    /// Groups of points that shared a cut.
    pub groups: u32,
    /// Points shaded through a shared cut.
    pub shared_points: u32,
    /// Points shaded on their own: all of them when the call cannot share
    /// (see [`Shading::shade_batch`]), else those of groups too scattered to
    /// share and those whose own check missed the threshold.
    pub points_alone: u32,
    /// Node bounds computed for the shared cuts (each point's own work is in
    /// its [`ShadeResult`]).
    pub shared_evaluations: u64,
    /// Classifications asked of the host for whole groups
    /// ([`Visibility::classify_group`]).
    pub shared_classifications: u64,
}

impl core::ops::AddAssign for BatchStats {
    fn add_assign(&mut self, other: Self) {
        self.groups += other.groups;
        self.shared_points += other.shared_points;
        self.points_alone += other.points_alone;
        self.shared_evaluations += other.shared_evaluations;
        self.shared_classifications += other.shared_classifications;
    }
}

/// Groups shaded with one running estimate of the cost of a point shaded
/// alone, started afresh for each chunk (so that a batch shaded over
/// threads, chunk by chunk, gives the same results). Chunks are what the
/// threads take, one at a time as each finishes its last, so they are
/// small: a few groups cost far more than the rest, and a chunk should not
/// tie them to others. One group a chunk: each group's first cut then
/// starts from the least budget, which costs a little on one thread and
/// shares a frame out evenly over threads (`docs/tuning.md`; `cargo run
/// --release -p manylights-report -- batch`, pinned and unpinned,
/// measures both).
const CHUNK_RUNS: usize = 1;

/// The points of a group: indices into the queries, the points of other
/// groups in its halo with their blend weights, and the group's place in
/// the batch's list of groups.
#[derive(Clone, Copy, Debug)]
struct Members<'a> {
    points: &'a [u32],
    halo: &'a [(u32, f64)],
    run: u32,
}

/// A group's result for a point of its halo, with its blend weight.
#[derive(Clone, Copy, Debug)]
struct HaloResult {
    point: u32,
    run: u32,
    weight: f64,
    result: ShadeResult,
}

/// What shading groups gives besides each point's own result.
#[derive(Debug, Default)]
struct Outcome {
    stats: BatchStats,
    halo: Vec<HaloResult>,
}

/// What the batch call keeps between calls besides the group's cut.
#[derive(Debug, Default)]
pub(crate) struct BatchScratch {
    /// The cut's nodes and lights above every plane, packed for the
    /// points' sums.
    packed: Packed,
    /// Each member's result in the current round, and whether it missed
    /// its target (to be shaded on its own).
    results: Vec<ShadeResult>,
    alone: Vec<bool>,
    /// The halo points' results over the group's cut, in the current round.
    halo_results: Vec<ShadeResult>,
    /// Running estimate of what a point shaded alone costs (0: none yet).
    alone_cost: f64,
}

/// The points of a batch in groups, with their halos.
struct Batch<'q, M> {
    queries: &'q [Query<M>],
    /// The queries in Morton order.
    order: Vec<u32>,
    /// The groups, ranges of `order`.
    runs: Vec<core::ops::Range<usize>>,
    /// Each group's halo.
    halos: Vec<halo::Halo>,
}

impl<'q, M> Batch<'q, M> {
    /// The groups of `queries` and, where `threshold` interpolates, their
    /// halos.
    fn new(queries: &'q [Query<M>], threshold: &Threshold) -> Self {
        let Groups { order, runs } = groups(queries);
        let halos = halo::halos(queries, &order, &runs, threshold);
        Self {
            queries,
            order,
            runs,
            halos,
        }
    }

    /// The groups of chunk `k`, with the index of the first.
    fn chunk(&self, k: usize) -> (usize, &[core::ops::Range<usize>]) {
        let first = k * CHUNK_RUNS;
        (
            first,
            &self.runs[first..(first + CHUNK_RUNS).min(self.runs.len())],
        )
    }

    /// The number of chunks.
    fn chunks(&self) -> usize {
        self.runs.len().div_ceil(CHUNK_RUNS)
    }

    /// Group `r`'s members.
    fn members(&self, r: usize) -> Members<'_> {
        Members {
            points: &self.order[self.runs[r].clone()],
            halo: self.halos.get(r).map_or(&[], Vec::as_slice),
            run: r as u32,
        }
    }
}

impl<S: Shader> Shading<'_, S> {
    /// Shades a batch of queries into `results` (one per query, same order),
    /// each with the certified contract of
    /// [`shade_query`](Self::shade_query): radiance, certified error bound,
    /// its own cost, and why it stopped.
    ///
    /// Nothing is assumed of the order or layout of the queries; neighbouring
    /// points (a tile of an image, a patch of surface) share work.
    ///
    /// # How points share a cut
    /// The points are sorted along a Morton curve of their positions over
    /// the batch's bounding cube, and grouped by the cells of the Morton
    /// (octree) subdivision: each group is a cell holding at most 128
    /// points, cut further into runs whose normals lie within about 29
    /// degrees of the run's first. For each run the crate picks one cut
    /// through the tree with the error list, bounding each node once for the whole
    /// group: nodes below every point's tangent plane drop out, the others
    /// are bounded by the degree-2 multipole series with its remainder taken
    /// at the group's nearest distance to the node and largest cosine (valid
    /// for every point and normal of the group), plus the clamp term where
    /// members reach below some point's tangent plane; nodes whose ball
    /// comes too near the group are refined, down to single lights. Each
    /// point then sums, at its own position and normal, the cut's node
    /// estimates and single lights; its certified bound is the cut's summed
    /// error.
    ///
    /// A relative target is aimed at with the darkest of four points spread
    /// over the run (virtual-light estimates, with a margin); a point that
    /// still misses its own target gets up to three further shared
    /// refinements and is then shaded on its own. Without interpolation, a
    /// point that met its target keeps the result of the round it met it
    /// in; with interpolation every point of the run takes the last round's
    /// cut. A run whose shared cut
    /// costs more than a share of what its points would cost alone (a
    /// running estimate from the points shaded alone; before there is one,
    /// a small fixed budget, and a run over it first shades one point
    /// alone for the estimate) is shaded point by point, as are runs of
    /// fewer than four points.
    ///
    /// # Group borders with interpolation
    /// Two groups' cuts differ as wholes, so without more the error would
    /// jump where one group ends and the next begins. With interpolation
    /// (relative or absolute targets) each group's cut also serves the
    /// points of other groups within a quarter of the largest side of its
    /// points' box (its halo; only points whose normals are within the
    /// group's normal spread): the group's geometry, and so its certified
    /// bound, takes them in, and each is summed over the cut. A point's
    /// result is then the mean of its own group's result (weight 1) and of
    /// the results of the groups whose halo holds it, each weighted by
    /// `1 - d / w` (`d` its distance to that group's box, `w` the halo's
    /// width). The weights fall to 0 continuously at each halo's edge, so
    /// the result changes continuously across a border. The bound is the
    /// weighted mean of the bounds plus the rounding of the means; a point
    /// keeps its own result when the blend would miss its target. The seams
    /// table of `cargo run --release -p manylights-report -- batch`
    /// measures the jumps between neighbouring points along a scanline and
    /// over a patch, with and without interpolation, and what it costs.
    ///
    /// A point's [`ShadeResult::nodes_evaluated`] then counts the node
    /// estimates it summed (cheaper than bounds) and
    /// [`lights_evaluated`](ShadeResult::lights_evaluated) the single
    /// lights, over every cut it blends; the shared bounds are counted once,
    /// in the returned [`BatchStats`].
    ///
    /// With occluders, a host that classifies nodes for whole groups
    /// ([`Visibility::classify_group`]) is asked once per group about each
    /// node the cut takes: hidden nodes drop out, visible ones are shared
    /// as without occluders, partly hidden ones are refined, and a single
    /// light still partly hidden is asked point-to-point by each point
    /// (counted in its [`point_queries`](ShadeResult::point_queries)).
    ///
    /// Cuts are shared for the crate's diffuse shaders ([`Lambert`](crate::Lambert), and
    /// sums of them), with [`Unoccluded`](crate::Unoccluded)
    /// or a host that classifies groups, and a threshold without a budget or
    /// maximal contribution. Otherwise every point is
    /// shaded on its own, with the same results as calling
    /// [`shade_query`](Self::shade_query) for each.
    ///
    /// Speed: `cargo run --release -p manylights-report -- batch` shades a
    /// camera's view of a street city of 10^6 lights with one call per
    /// threshold and prints the time per pixel against the vectorized exact
    /// sum and against shading each pixel on its own.
    ///
    /// Rounding: where a group's cut is coarse (its certified error at
    /// least `2^-12` of the radiance it aims at), each point sums it in
    /// `f32` lanes and its bound includes a certified bound on that sum's
    /// rounding (see the crate's docs on the certified bound).
    ///
    /// Allocation: a call allocates its Morton order and group list (linear
    /// in the batch); the session's scratch space is reused across calls.
    ///
    /// # Errors
    /// [`ShadeError::BatchLength`] when `results` is not as long as
    /// `queries`; the threshold errors of [`shade_query`](Self::shade_query).
    pub fn shade_batch<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        threshold: Threshold,
        mut visibility: V,
        results: &mut [ShadeResult],
    ) -> Result<BatchStats, ShadeError>
    where
        S: Accepts<M>,
    {
        check_batch(queries.len(), results.len(), &threshold)?;
        if !self.shares::<V>(&threshold) {
            for (query, result) in queries.iter().zip(results.iter_mut()) {
                *result = self.shade_query(query, threshold, &mut visibility)?;
            }
            return Ok(BatchStats {
                points_alone: queries.len() as u32,
                ..BatchStats::default()
            });
        }
        let batch = Batch::new(queries, &threshold);
        let mut out = Outcome::default();
        for k in 0..batch.chunks() {
            let mut write = |i: usize, r| results[i] = r;
            self.shade_chunk(&batch, k, threshold, &mut visibility, &mut write, &mut out)?;
        }
        halo::blend_halos(results, out.halo, &threshold);
        Ok(out.stats)
    }

    /// Whether a batch call with this threshold and visibility shares cuts.
    fn shares<V: Visibility>(&self, threshold: &Threshold) -> bool {
        (V::ALWAYS_VISIBLE || V::CLASSIFIES_GROUPS)
            && self.shader.diffuse_albedo(Seal).is_some()
            && threshold.budget().is_none()
            && threshold.max_contribution().is_none()
    }
}

/// A batch call's arguments: as many results as queries, a valid
/// threshold.
fn check_batch(queries: usize, results: usize, threshold: &Threshold) -> Result<(), ShadeError> {
    if queries != results {
        return Err(ShadeError::BatchLength { queries, results });
    }
    threshold.check()
}
