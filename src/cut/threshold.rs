//! Thresholds: when the cut stops refining.

use glam::DVec3;

use crate::ShadeError;

/// What the summed error bound is compared with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// Stop when every channel's summed error bound is at most this many
    /// radiance units (the paper's `T_diffuse`; it used 1% of the display
    /// range).
    Absolute(f64),
    /// Stop when the largest channel's summed error bound is at most this
    /// fraction of the largest channel of the estimate (Lightcuts' 2% Weber
    /// threshold, here applied to the certified bound). Since the exact value
    /// is at least `estimate - bound`, a met relative threshold `t < 1`
    /// certifies a relative error of at most `t / (1 - t)` in the largest
    /// channel.
    Relative(f64),
    /// Lightcuts' criterion (Walter et al. 2005): stop when the largest
    /// *single* node error is at most this fraction of the largest channel
    /// of the estimate. Not a bound on the total error: the result's
    /// `error_bound` (the certified sum) may exceed the fraction, and the
    /// stop is reported as met all the same. Far fewer nodes than
    /// [`Target::Relative`] for the same actual error, because node errors
    /// partly cancel while their bounds add.
    PerNode(f64),
}

/// When the cut stops refining.
///
/// Three conditions combine: the error [`Target`] (the paper's error list:
/// refine the node of greatest error while the sum of node errors exceeds
/// the target), an optional *maximal contribution* (the paper's specular
/// criterion: also refine every node whose upper bound exceeds it), and an
/// optional budget that caps the work regardless.
///
/// Thresholds must be non-negative; infinity is allowed (an infinite target
/// evaluates the root only, unless the root's ball contains the shading
/// point). NaN or negative values make the shading call return
/// [`ShadeError::InvalidThreshold`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Threshold {
    target: Target,
    max_contribution: Option<f64>,
    budget: Option<u32>,
    band: Option<f64>,
}

impl Threshold {
    /// Absolute threshold on the summed error bound, in radiance units.
    #[must_use]
    pub const fn absolute(t: f64) -> Self {
        Self {
            target: Target::Absolute(t),
            max_contribution: None,
            budget: None,
            band: None,
        }
    }

    /// Threshold on the summed error bound relative to the estimate.
    #[must_use]
    pub const fn relative(t: f64) -> Self {
        Self {
            target: Target::Relative(t),
            max_contribution: None,
            budget: None,
            band: None,
        }
    }

    /// Lightcuts' per-node criterion ([`Target::PerNode`]): fast, with the
    /// certified bound still reported but not held to `t`.
    #[must_use]
    pub const fn per_node(t: f64) -> Self {
        Self {
            target: Target::PerNode(t),
            max_contribution: None,
            budget: None,
            band: None,
        }
    }

    /// Threshold 0: refine until every remaining node has zero error (the
    /// exact sum, up to rounding). With a target of 0 the cut adds lights
    /// one at a time to its compensated sum, as
    /// [`Shading::exact_query`](crate::Shading::exact_query) does, rather
    /// than a few at a time ([`Shader::sum_lights`](crate::shader::Shader::sum_lights)),
    /// so that it returns the same value.
    #[must_use]
    pub const fn zero() -> Self {
        Self::absolute(0.0)
    }

    /// Caps the work: at most `max_cost` evaluations, counting each node
    /// bound and each exact light evaluation as one. The root is always
    /// evaluated, so budgets 0 and 1 both evaluate the root only. A node is
    /// refined only if all of its children (or lights) fit in what remains.
    /// The cap holds for everything the call does, interpolation included.
    #[must_use]
    pub const fn with_budget(mut self, max_cost: u32) -> Self {
        self.budget = Some(max_cost);
        self
    }

    /// The paper's specular criterion: additionally refine every node whose
    /// maximal possible contribution (the upper bound of its largest channel)
    /// exceeds `t`.
    ///
    /// Choose it for glossy highlights: a narrow lobe gives a few nodes a
    /// large upper bound and a tiny estimate, and the error list alone may
    /// stop before it finds the few lights inside the lobe when the rest of
    /// the scene's error is small. Combine it with [`Threshold::absolute`]
    /// `(f64::INFINITY)` for the paper's specular algorithm on its own.
    #[must_use]
    pub const fn with_max_contribution(mut self, t: f64) -> Self {
        self.max_contribution = Some(t);
        self
    }

    /// Interpolation across levels, so that the estimate varies
    /// continuously with the shading point instead of jumping where the cut
    /// changes (the seams of the paper's difference image).
    ///
    /// With interpolation the error list works on *nested* intervals: a
    /// refined node's certified interval and the sum of its children's both
    /// hold the node's exact value, so the cut counts their intersection.
    /// Refining a node then never widens the cut's bound, even where its
    /// children's errors outweigh its own (common near the horizon, where
    /// nodes straddle the tangent plane). And a node's priority in the list
    /// is its error capped at its parent's priority, so nodes are refined
    /// in decreasing priority down every path.
    ///
    /// After the error list has met the target, the cut is blended at a
    /// level `tau`: every node of the cut, including those the list
    /// refined, with priority `e` is given a refinement weight
    /// `alpha = clamp((e - tau/band) / (tau - tau/band), 0, 1)` (1 from
    /// `e >= tau` on; nodes the maximal contribution forced the list to
    /// refine keep weight 1; a node whose ball nears the shading point
    /// weighs at least `1 - q / (1/3)`, `q = (D - R) / D` its clearance, so
    /// that its weight reaches 1 where its ball reaches the point and it has
    /// no finite bound) and counts for `(1 - alpha) A + alpha (A ∩ C)`,
    /// with `A` its own certified interval and `C` the sum of its
    /// children's blended intervals, recursively. That interval holds the
    /// exact value (a mixture of two intervals that both hold it) and lies
    /// within `A`; the estimate is its midpoint and the bound its
    /// half-width.
    ///
    /// The level is where the blended cut just meets the target: the root
    /// of `g(tau)`, the excess of the blended bound over the target. In each
    /// channel a lower level narrows the interval and moves the estimate by
    /// no more than it narrows it, so `g` is non-decreasing in `tau` for an
    /// absolute target and for a relative target below 1 whose channels
    /// move together (grey or evenly coloured lights; with strongly
    /// coloured ones `g` may have several roots and one of them is taken).
    /// The list's cut brackets the root: blended at the priority of the
    /// list's last refinement, the cut refines at least what the list did
    /// and meets the target; above `band` times that priority it refines
    /// less than the list had before its last step, which missed it. The
    /// root is found by regula falsi (the Illinois variant, on `1/tau`, in
    /// which every weight is linear between its clamps) to within 1e-4 of
    /// the bound, each step a plain re-summation of the blended cut; the
    /// nodes in the band are bounded once, and the level found is summed
    /// again with compensated sums for the certified result.
    ///
    /// Why this removes the seams: without it a node jumps between "used"
    /// and "refined" where the error list's decision flips; with it, a
    /// node's weight is a continuous function of its priority and the level.
    /// Node intervals and priorities are continuous in the shading point
    /// (the bounds are built from continuous pieces), so the blend is
    /// continuous in the point and the level together, and so is the root
    /// `g(tau) = 0`, whatever order the list happened to refine nodes of
    /// nearly equal priority in. A node the list refined and one the blend
    /// expands count the same, intersection included.
    ///
    /// With a [`Target::PerNode`] target (whose excess does not depend on
    /// the blend) the level is placed between the list's last two steps
    /// instead: with `h_k` the largest priority left unrefined, `h_{k-1}` the
    /// priority of the last node refined, and `g_k`, `g_{k-1}` the excess
    /// after and before that refinement, `tau = h_{k-1} + beta (h_k -
    /// h_{k-1})` with `beta = g_{k-1} / (g_{k-1} - g_k)`; the largest single
    /// error compared is the largest priority.
    ///
    /// Cost: the nodes whose priorities lie within the band below the level
    /// are bounded once more, and the search re-sums the blended cut about
    /// seven times. In evaluations (node bounds and lights,
    /// [`ShadeResult::cost`](crate::ShadeResult::cost)) the cut stays within twice the discrete cut's
    /// and is usually below it, points inside clusters, shells and thin
    /// layers of lights included (a property test checks the factor 2 on
    /// such scenes); in time a point takes a few times longer, as the
    /// blend's bounds are not taken in `f32` and the search re-sums. A budget caps the blend too: when it stops the error
    /// list there is no blending, and when blending would exceed it the
    /// unblended result is returned, as it is should the certified
    /// re-summation miss the target. `band` must be finite and greater than
    /// 1 ([`ShadeError::InvalidBand`] otherwise).
    ///
    /// With band 2 the jumps of the relative error that remain shrink in
    /// proportion to the spacing of the points (the error's smooth
    /// variation, not seams); the cut needs fewer evaluations than without
    /// interpolation (the nested intervals meet the target sooner) but each
    /// point takes longer. `cargo run --release --example seams` measures
    /// the jumps, evaluations and time along scanlines with and without
    /// interpolation; the repository's `docs/tuning.md` records the
    /// measurement behind band 2.
    #[must_use]
    pub const fn with_interpolation(mut self, band: f64) -> Self {
        self.band = Some(band);
        self
    }

    /// The interpolation band, if interpolation is on.
    #[must_use]
    pub const fn interpolation(&self) -> Option<f64> {
        self.band
    }

    /// The error target.
    #[must_use]
    pub const fn target(&self) -> Target {
        self.target
    }

    /// The maximal-contribution (specular) threshold, if any.
    #[must_use]
    pub const fn max_contribution(&self) -> Option<f64> {
        self.max_contribution
    }

    /// The budget, if any.
    #[must_use]
    pub const fn budget(&self) -> Option<u32> {
        self.budget
    }

    pub(crate) fn check(&self) -> Result<(), ShadeError> {
        let t = match self.target {
            Target::Absolute(t) | Target::Relative(t) | Target::PerNode(t) => t,
        };
        // `!(t >= 0)` is also true for NaN.
        if !(t >= 0.0) {
            return Err(ShadeError::InvalidThreshold(t));
        }
        if let Some(m) = self.max_contribution
            && !(m >= 0.0)
        {
            return Err(ShadeError::InvalidThreshold(m));
        }
        if let Some(b) = self.band
            && !(b > 1.0 && b.is_finite())
        {
            return Err(ShadeError::InvalidBand(b));
        }
        Ok(())
    }

    /// Whether the target is 0: the exact sum is asked for.
    #[inline]
    pub(crate) fn is_zero(&self) -> bool {
        match self.target {
            Target::Absolute(t) | Target::Relative(t) | Target::PerNode(t) => t == 0.0,
        }
    }

    /// Whether a cut with this summed estimate, certified error bound and
    /// largest single node error meets the target. Callers pass the bound
    /// exactly as it will be reported, so "met" means the reported bound
    /// meets it.
    #[inline]
    pub(crate) fn met(&self, estimate: DVec3, bound: DVec3, largest: f64) -> bool {
        self.excess(estimate, bound, largest) <= 0.0
    }

    /// How far the cut is from the target (`<= 0` when met), given the
    /// summed estimate and error bound and the largest single node error.
    /// An infinite relative target is met by any finite bound, also when the
    /// estimate is 0 (where `inf * 0` would be NaN).
    #[inline]
    pub(crate) fn excess(&self, estimate: DVec3, bound: DVec3, largest: f64) -> f64 {
        let scaled = |t: f64| {
            if t == f64::INFINITY {
                f64::INFINITY
            } else {
                t * estimate.max_element()
            }
        };
        match self.target {
            Target::Absolute(t) => bound.max_element() - t,
            Target::Relative(t) => bound.max_element() - scaled(t),
            Target::PerNode(t) => largest - scaled(t),
        }
    }
}
