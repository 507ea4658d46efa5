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
    /// exact sum, up to rounding).
    #[must_use]
    pub const fn exact() -> Self {
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
    /// After the error list has met the target, let `tau` be the level at
    /// which it stopped: with `h_k` the largest priority left unrefined,
    /// `h_{k-1}` the priority of the last node refined, and `g_k`, `g_{k-1}`
    /// the excess of the summed error over the target after and before that
    /// refinement (`g_k <= 0 < g_{k-1}`), `tau = h_{k-1} + beta (h_k -
    /// h_{k-1})` with `beta = g_{k-1} / (g_{k-1} - g_k)`. Every unrefined
    /// node of priority `e` is given a refinement weight
    /// `alpha = clamp((e - tau/band) / (tau - tau/band), 0, 1)` and counts
    /// for `(1 - alpha) A + alpha (A ∩ C)`, with `A` its own certified
    /// interval and `C` the sum of its children's blended intervals,
    /// recursively (children with `e >= tau` are refined fully, as the error
    /// list would). That interval holds the exact value (a mixture of two
    /// intervals that both hold it) and lies within `A`; the estimate is its
    /// midpoint and the bound its half-width.
    ///
    /// Why this removes the seams: without it a node jumps between "used"
    /// and "refined" where the error list's decision flips; with it, a node
    /// is fully refined exactly when its priority reaches the level `tau`,
    /// and its weight falls continuously to 0 as its priority falls to
    /// `tau/band`. Node intervals and priorities are continuous in the
    /// shading point (the bounds are built from continuous pieces), so the
    /// blend is continuous for a fixed `tau`; a node the list refined and
    /// one the blend refines fully count the same, intersection included.
    /// And `tau` is continuous where the stopping step changes: as `g_{k-1}`
    /// falls to 0, `beta -> 0` and `tau -> h_{k-1}`; on the other side the
    /// list stops one step earlier with `beta -> 1` and the same `tau`. What
    /// remains are points where two nodes of nearly equal priority swap
    /// their order near the last step and only one of the two orders meets
    /// the target a step earlier: there `tau` moves by up to the gap between
    /// consecutive priorities.
    ///
    /// Cost: nodes with priorities within the band are refined once more
    /// (partially). A budget caps the blend too: when it stops the error list
    /// there is no blending, and when blending would exceed it the unblended
    /// result is returned. The blended bound never exceeds the unblended
    /// one; should a relative target still be missed (the blended estimate
    /// being lower), the unblended result is returned. With a
    /// [`Target::PerNode`] target, the largest single error compared is the
    /// largest priority. `band` must be finite and greater than 1
    /// ([`ShadeError::InvalidBand`] otherwise). Measured on a street-light
    /// city along a scanline of 100,000 points (`cargo run --release
    /// --example seams`), band 2 makes the largest jump of the relative
    /// error 15 to 90 times smaller at thresholds of 1% to 20%, with about
    /// 0.56 times the evaluations (the nested intervals meet the target
    /// sooner) and twice the time; on scanlines whose tangent plane cuts a
    /// sphere of lights, 8 to 180 times smaller at 5% and 20%, and only
    /// 2.6 to 3.5 times at 1%, where near-ties remain.
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
