//! Shading: the session a renderer keeps per thread, its per-point query,
//! the batch call and the exact reference sum.

mod batch;
mod exact;
mod grouping;
mod packed;
mod query;

use core::fmt;

use glam::{DVec3, Vec3};

use crate::cut::policy::is_small_scene;
use crate::cut::{GroupScratch, Lent, shade_point};
use crate::shader::{Shader, ViewIndependent};
use crate::tree::LightTree;
use crate::visibility::{Unoccluded, Visibility};
use crate::{LightLanes, ShadeError, ShadeResult, Threshold};

pub use batch::BatchStats;
pub use query::{Accepts, NoView, Query, WithView};

/// A shading session: a tree, a shader and reusable scratch space.
///
/// Create one per thread with [`LightTree::shading`]; after the first few
/// calls have grown its scratch, shading allocates nothing.
///
/// Two calls do the work, both for one [`Query`] and the host's
/// [`Visibility`] (pass [`Unoccluded`] when there are no occluders; it
/// compiles every visibility call away):
/// [`shade_query`](Self::shade_query) picks a cut and returns a certified
/// [`ShadeResult`], [`exact_query`](Self::exact_query) sums the model over
/// every light. For view-independent shaders without occluders,
/// [`shade`](Self::shade) and [`exact`](Self::exact) take the point and
/// normal directly. [`shade_batch`](Self::shade_batch) shades many queries
/// at once, neighbouring points sharing one cut.
pub struct Shading<'t, S: Shader> {
    tree: &'t LightTree,
    shader: S,
    /// For a small scene, summed rather than cut where its lights are known
    /// visible, its lights side by side for the shader's coarse sums;
    /// `None` for other trees.
    small_lanes: Option<Vec<LightLanes>>,
    scratch: Scratch,
}

/// What a session reuses from call to call, kept apart from the borrowed
/// tree and shader.
#[derive(Debug, Default)]
struct Scratch {
    point: crate::cut::PointScratch,
    group: GroupScratch,
    batch: batch::BatchScratch,
}

impl LightTree {
    /// A shading session for `shader` over this tree.
    ///
    /// For a small scene (at most 1,024 lights, none of them coincident) the
    /// session keeps a copy of the lights side by side (24 bytes a light),
    /// from which the shader sums them (see
    /// [`shade_query`](Shading::shade_query)).
    #[must_use]
    pub fn shading<S: Shader>(&self, shader: S) -> Shading<'_, S> {
        Shading {
            tree: self,
            shader,
            // Emitters are summed with their profiles, never side by side.
            small_lanes: (is_small_scene(self) && !self.is_oriented())
                .then(|| LightLanes::of(&self.lights)),
            scratch: Scratch::default(),
        }
    }
}

/// The tree summarised, the shader in full, the scratch left out.
impl<S: Shader + fmt::Debug> fmt::Debug for Shading<'_, S> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Shading")
            .field("tree", self.tree)
            .field("shader", &self.shader)
            .finish_non_exhaustive()
    }
}

impl<'t, S: Shader> Shading<'t, S> {
    /// The tree.
    #[must_use]
    pub fn tree(&self) -> &'t LightTree {
        self.tree
    }

    /// The shader.
    #[must_use]
    pub fn shader(&self) -> &S {
        &self.shader
    }

    /// Shades one query: picks a cut through the tree with the paper's error
    /// list until `threshold` is met (or its budget runs out) and returns
    /// the radiance, its certified error bound and the work done.
    ///
    /// Where bounding costs more than summing, the cut sums: visible nodes
    /// of at most 32 lights, and without a budget those of at most 512
    /// lights near the point for their size (`n D^2 <= 512 R^2` for `n`
    /// lights within `R` of a centroid at distance `D`), are summed light by
    /// light when they enter the cut, and a tree of at most 256 lights (1,024
    /// where the threshold lets lights be summed coarsely; none of them
    /// coincident) whose lights are known visible is summed whole when its
    /// root alone does not meet the threshold (not with interpolation across
    /// levels, whose blend needs bounded nodes, nor beyond the budget).
    /// Summed lights carry no error beyond the coarse sums' certified
    /// rounding. A scene of at most 192 lights is summed whole wherever the
    /// point lies, once known visible (the sum costs less than bounding the
    /// root).
    ///
    /// `visibility` is the host's ray tracer ([`Visibility`]); pass
    /// [`Unoccluded`] for none, or `&mut host` to keep the host.
    ///
    /// # Errors
    /// [`ShadeError::InvalidThreshold`] (NaN or negative threshold),
    /// [`ShadeError::InvalidBand`] (bad interpolation band). The query was
    /// validated when it was built.
    pub fn shade_query<M, V: Visibility>(
        &mut self,
        query: &Query<M>,
        threshold: Threshold,
        visibility: V,
    ) -> Result<ShadeResult, ShadeError>
    where
        S: Accepts<M>,
    {
        threshold.check()?;
        Ok(self.shade_checked(query, &threshold, visibility))
    }

    /// [`shade_query`](Self::shade_query) after its checks, compiled for
    /// AVX2 where the processor has it ([`dispatch`](crate::dispatch)).
    #[inline]
    fn shade_checked<M, V: Visibility>(
        &mut self,
        query: &Query<M>,
        threshold: &Threshold,
        visibility: V,
    ) -> ShadeResult {
        let lent = Lent {
            tree: self.tree,
            shader: &self.shader,
            small_lanes: self.small_lanes.as_deref(),
        };
        let scratch = &mut self.scratch.point;
        let (surface, point) = (query.surface(), query.point());
        crate::dispatch::with_avx2(
            #[inline(always)]
            || shade_point(lent, surface, point, threshold, visibility, scratch),
        )
    }

    /// The exact model (crate docs, "The model") for one query, summed over
    /// every light in `f64` with compensated summation, with the host's
    /// point-to-point visibility `V_i` ([`Unoccluded`] for none): the
    /// reference [`shade_query`](Self::shade_query) is certified against.
    #[must_use]
    pub fn exact_query<M, V: Visibility>(&self, query: &Query<M>, visibility: V) -> DVec3
    where
        S: Accepts<M>,
    {
        exact::exact_sum(
            &self.shader,
            query.surface(),
            query.point(),
            self.tree,
            visibility,
        )
    }
}

impl<S: Shader> Shading<'_, S> {
    /// An unbiased estimate of the radiance at `query`, with an unbiased
    /// estimate of its variance: a certified cut at `threshold` (a coarse
    /// one, say a relative 10% to 30%), then two lights sampled inside each
    /// node it leaves (a node of at most 64 lights known visible is summed
    /// exactly instead, which costs no more), as
    /// [`LightSampler`](crate::LightSampler) descends the tree from that
    /// node (Stochastic Lightcuts, Yuksel 2019, with the
    /// cut's own certified bounds choosing the cut). What the cut settled
    /// it sums exactly (lights in `f64`; no coarse `f32` sums, no
    /// interpolation); each node's two samples `f / p` are averaged. The
    /// result's expectation is the exact model with the host's visibility:
    /// unbiased, *not* certified (see [`Stochastic`](crate::Stochastic)).
    ///
    /// `uniform` supplies the random numbers, independent and uniform in
    /// `[0, 1)` (clamped into it, NaN read as 0): two per node sampled. A
    /// sampled light that contributes, in a node the host has not said is
    /// visible, costs one point-to-point query
    /// ([`Visibility::visible`]). Without occluders pass [`Unoccluded`].
    ///
    /// ```
    /// use glam::Vec3;
    /// use manylights::{Lambert, LightTree, PointLight, Query, Threshold, Unoccluded};
    ///
    /// let lights: Vec<PointLight> = (0..5000)
    ///     .map(|i| PointLight::new(Vec3::new((i % 70) as f32, (i / 70) as f32, 3.0), Vec3::ONE))
    ///     .collect();
    /// let tree = LightTree::build(&lights)?;
    /// let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
    /// let query = Query::new(Vec3::new(30.0, 30.0, 0.0), Vec3::Z)?;
    /// let mut state = 1u64;
    /// let mut uniform = move || {
    ///     // Any uniform generator; a renderer passes its sampler's numbers.
    ///     state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ///     (state >> 11) as f64 / (1u64 << 53) as f64
    /// };
    /// // The mean of 64 calls, and its variance from the reported ones.
    /// let (mut sum, mut variance) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
    /// for _ in 0..64 {
    ///     let r = shading.shade_stochastic(&query, Threshold::relative(0.2), Unoccluded, &mut uniform)?;
    ///     (sum, variance) = (sum + r.radiance, variance + r.variance);
    /// }
    /// let (mean, sigma) = (sum / 64.0, (variance.max_element() / (64.0 * 64.0)).sqrt());
    /// let exact = shading.exact_query(&query, Unoccluded);
    /// // Within five standard deviations, almost surely.
    /// assert!((mean - exact).abs().max_element() <= 5.0 * sigma + 1e-9 * exact.max_element());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`ShadeError::InvalidThreshold`] (NaN or negative threshold),
    /// [`ShadeError::InvalidBand`] (bad interpolation band; the band is
    /// otherwise ignored).
    pub fn shade_stochastic<M, V: Visibility>(
        &mut self,
        query: &Query<M>,
        threshold: Threshold,
        visibility: V,
        mut uniform: impl FnMut() -> f64,
    ) -> Result<crate::Stochastic, ShadeError>
    where
        S: Accepts<M>,
    {
        threshold.check()?;
        let (tree, shader) = (self.tree, &self.shader);
        let list = &mut self.scratch.point.list;
        let (surface, point) = (query.surface(), query.point());
        Ok(crate::dispatch::with_avx2(
            #[inline(always)]
            || {
                crate::sampling::shade_stochastic(
                    tree,
                    shader,
                    surface,
                    point,
                    &threshold,
                    visibility,
                    list,
                    &mut uniform,
                )
            },
        ))
    }
}

impl<S: ViewIndependent> Shading<'_, S> {
    /// Shades `point` with normal `normal` (any non-zero length; normalized
    /// here), with no occluders: [`shade_query`](Self::shade_query) in one
    /// line.
    ///
    /// # Errors
    /// [`ShadeError::NonFinitePoint`], [`ShadeError::InvalidNormal`] (zero or
    /// non-finite normal), [`ShadeError::InvalidThreshold`] (NaN or
    /// negative), [`ShadeError::InvalidBand`].
    pub fn shade(
        &mut self,
        point: Vec3,
        normal: Vec3,
        threshold: Threshold,
    ) -> Result<ShadeResult, ShadeError> {
        self.shade_query(&Query::new(point, normal)?, threshold, Unoccluded)
    }

    /// The exact model at `point` with no occluders:
    /// [`exact_query`](Self::exact_query) in one line.
    ///
    /// # Errors
    /// [`ShadeError::NonFinitePoint`], [`ShadeError::InvalidNormal`].
    pub fn exact(&self, point: Vec3, normal: Vec3) -> Result<DVec3, ShadeError> {
        Ok(self.exact_query(&Query::new(point, normal)?, Unoccluded))
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::Query;
    use crate::{Lambert, LightTree, PointLight, Unoccluded};
    use crate::{ShadeResult, Threshold};

    fn bits(r: &ShadeResult) -> ([u64; 3], [u64; 3], [u32; 4], crate::Stop) {
        (
            r.radiance.to_array().map(f64::to_bits),
            r.error_bound.to_array().map(f64::to_bits),
            [
                r.nodes_evaluated,
                r.lights_evaluated,
                r.classify_queries,
                r.point_queries,
            ],
            r.stop,
        )
    }

    /// A host that sees every light, answering "visible" for every node.
    struct Clear;

    impl crate::Visibility for Clear {
        fn classify(&mut self, _: Vec3, _: &crate::NodeRegion) -> crate::Coverage {
            crate::Coverage::Visible
        }

        fn visible(&mut self, _: Vec3, _: Vec3) -> bool {
            true
        }
    }

    /// A small scene summed from its lights side by side, without setting
    /// up the cut, gives the counts of the cut over the same tree without
    /// them (which sums the lights 64 records at a time), and its bits
    /// wherever the whole scene is not summed at once; where it is, both
    /// are within their bounds of the exact sum and meet the target: scenes
    /// of 2 to 1,024 lights, points inside and outside the root's ball, and
    /// thresholds with and without coarse sums, budgets and interpolation.
    /// A scene of at most 192 lights is summed wherever the point lies:
    /// outside the root's ball that sum is within its bound of the exact
    /// sum and meets the target, the root is counted, and a host that
    /// answers "visible" at the root gets the same bits.
    #[test]
    fn small_scenes_summed_side_by_side_match_the_cut() {
        let mut state = 37u64;
        let mut uniform = move || crate::testing::uniform(&mut state);
        let (mut fast, mut tiny, mut asked, mut wholes) = (0, 0, 0, 0);
        for (round, count) in [
            2usize, 7, 8, 9, 64, 65, 100, 192, 193, 300, 512, 768, 1023, 1024,
        ]
        .into_iter()
        .enumerate()
        {
            let lights: Vec<PointLight> = (0..count)
                .map(|_| {
                    let p = Vec3::new(uniform() * 40.0, uniform() * 40.0, 4.0 + uniform());
                    let i = Vec3::new(uniform(), uniform(), uniform()) * 10.0;
                    PointLight::new(p, i)
                })
                .collect();
            let tree = LightTree::build(&lights).unwrap();
            let lambert = Lambert::new(Vec3::new(0.8, 0.6, 0.4));
            let mut with = tree.shading(lambert);
            let mut without = tree.shading(lambert);
            assert!(with.small_lanes.as_ref().is_some_and(|l| !l.is_empty()));
            // Still a small scene, its lights summed from their records.
            without.small_lanes = Some(Vec::new());
            for k in 0..40 {
                let far = if k % 4 == 3 { 400.0 } else { 1.0 };
                let point = Vec3::new(uniform() * 40.0, uniform() * 40.0, 0.0) * far;
                let normal = Vec3::new(uniform() - 0.5, uniform() - 0.5, 1.0);
                let query = Query::new(point, normal).unwrap();
                let threshold = match (k + round) % 6 {
                    0 => Threshold::relative(0.3),
                    1 => Threshold::relative(0.01),
                    2 => Threshold::relative(1e-5),
                    3 => Threshold::absolute(1e-3),
                    4 => Threshold::relative(0.01).with_budget(count as u32 / 2 + 1),
                    _ => Threshold::relative(0.01).with_interpolation(2.0),
                };
                let a = with.shade_query(&query, threshold, Unoccluded).unwrap();
                let b = without.shade_query(&query, threshold, Unoccluded).unwrap();
                let summed = crate::cut::shade_small_scene::<_, Unoccluded>(
                    &tree,
                    &lambert,
                    with.small_lanes.as_deref().unwrap(),
                    query.surface(),
                    &threshold,
                );
                fast += usize::from(summed.is_some());
                if let Some(summed) = &summed
                    && tree.nodes[0].cone(query.surface().point).is_some()
                {
                    // Where the cut would bound the root first.
                    tiny += 1;
                    assert!(
                        count <= 192,
                        "{count} lights summed outside the root's ball"
                    );
                    assert_eq!(bits(&a), bits(summed));
                    assert_eq!((a.nodes_evaluated, a.lights_evaluated), (1, count as u32));
                    let exact = with.exact_query(&query, Unoccluded);
                    assert!(a.certifies(exact), "{a:?} against {exact}");
                    assert!(threshold.met(a.radiance, a.error_bound, 0.0));
                    // A host asked about the root (once) changes nothing
                    // else; one is not asked where the root's interval
                    // before its answer, `[0, upper]`, meets the target.
                    let host = with.shade_query(&query, threshold, Clear).unwrap();
                    assert!(host.classify_queries <= 1);
                    if host.classify_queries == 1 {
                        asked += 1;
                        let host = ShadeResult {
                            classify_queries: 0,
                            ..host
                        };
                        assert_eq!(bits(&host), bits(&a), "{count} lights, point {k}");
                    } else {
                        assert!(host.certifies(exact));
                        assert!(threshold.met(host.radiance, host.error_bound, 0.0));
                    }
                } else if bits(&a) != bits(&b) {
                    // The whole scene summed in one call with its lights
                    // side by side, 64 at a time from their records.
                    wholes += 1;
                    let counts = |r: &ShadeResult| (r.nodes_evaluated, r.lights_evaluated, r.stop);
                    assert_eq!(counts(&a), counts(&b), "{count} lights, point {k}");
                    assert_eq!(a.lights_evaluated, count as u32);
                    let exact = with.exact_query(&query, Unoccluded);
                    assert!(
                        a.certifies(exact) && b.certifies(exact),
                        "{a:?} {b:?} {exact}"
                    );
                    assert!(threshold.met(a.radiance, a.error_bound, 0.0));
                }
            }
        }
        assert!(fast > 60 && fast < 500, "{fast} sums without the cut");
        assert!(wholes > 20, "{wholes} whole sums");
        assert!(
            tiny > 10 && asked > 5,
            "{tiny} sums outside the root's ball, {asked} asked"
        );
    }
}
