//! The stochastic cut (after Stochastic Lightcuts, Yuksel 2019): a
//! certified cut at a coarse threshold, then lights sampled inside each
//! node it leaves, for an unbiased estimate of the whole sum.

use glam::{DVec3, Vec3};

use super::choice::{At, descend};
use crate::Threshold;
use crate::cut::{ErrorList, Seen, Stop, settle_point};
use crate::geometry::Surface;
use crate::shader::{SUM_LIGHTS_MAX, Shader};
use crate::tree::LightTree;
use crate::visibility::Visibility;

/// Samples drawn inside each node the cut leaves: two, so that their
/// difference gives an unbiased estimate of the variance.
pub(crate) const SAMPLES_PER_NODE: u32 = 2;

/// Nodes of at most this many lights, known visible, are summed exactly
/// rather than sampled: two descents evaluate every light of the leaf each
/// reaches (to choose among them by their exact terms), and a node of this
/// many lights spans at most two leaves of the default builder, so its
/// exact sum costs no more than its two samples and leaves no variance.
pub(crate) const SUM_INSTEAD_LIGHTS: usize = 64;

/// An unbiased estimate of one shading point's radiance from
/// [`Shading::shade_stochastic`](crate::Shading::shade_stochastic), with an
/// unbiased estimate of its variance. Not certified: the estimate's error
/// has no bound, only a variance.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct Stochastic {
    /// The estimate: the cut's exactly summed part plus, for each node it
    /// left, the mean of two sampled lights' terms divided by their
    /// probabilities (or, for a node of at most 64 lights known visible,
    /// its exact sum). Its expectation is the model's exact value (with
    /// the host's visibility).
    pub radiance: DVec3,
    /// An unbiased estimate of the variance of `radiance` per channel:
    /// over the nodes sampled, `(x1 - x2)^2 / 4` summed, `x1` and `x2` a
    /// node's two samples (independent, so this is unbiased for the
    /// variance of their mean, and the nodes' samples are independent of
    /// each other's). 0 where the cut settled everything. One call's
    /// estimate is itself noisy, and skewed low: where one light dominates
    /// a node both samples often pick it, and the difference is then 0
    /// however large the node's variance. Average it over many calls (or
    /// points) before judging an error by it.
    pub variance: DVec3,
    /// Nodes the cut left that were sampled, twice each (nodes of at most
    /// 64 lights known visible are summed exactly instead: that costs no
    /// more than their two samples).
    pub nodes_sampled: u32,
    /// Nodes bounded by the cut (as [`ShadeResult::nodes_evaluated`](crate::ShadeResult::nodes_evaluated)).
    pub nodes_evaluated: u32,
    /// Lights the cut evaluated exactly, plus the lights sampled.
    pub lights_evaluated: u32,
    /// Classifications asked of the host by the cut.
    pub classify_queries: u32,
    /// Point-to-point visibility queries: the cut's and one per sampled
    /// light that contributes in a node not known visible.
    pub point_queries: u32,
    /// Why the cut stopped.
    pub stop: Stop,
}

/// Nothing estimated yet, to fill a results slice before a batch call
/// ([`Shading::shade_stochastic_batch`](crate::Shading::shade_stochastic_batch)):
/// radiance 0 with an infinite variance (it estimates nothing), no work,
/// stopped by the budget.
impl Default for Stochastic {
    fn default() -> Self {
        Self {
            radiance: DVec3::ZERO,
            variance: DVec3::INFINITY,
            nodes_sampled: 0,
            nodes_evaluated: 0,
            lights_evaluated: 0,
            classify_queries: 0,
            point_queries: 0,
            stop: Stop::Budget,
        }
    }
}

/// The stochastic cut of one point: see
/// [`Shading::shade_stochastic`](crate::Shading::shade_stochastic).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn shade_stochastic<S: Shader, V: Visibility>(
    tree: &LightTree,
    shader: &S,
    surface: &Surface,
    point: Vec3,
    threshold: &Threshold,
    visibility: V,
    list: &mut ErrorList,
    uniform: &mut impl FnMut() -> f64,
) -> Stochastic {
    let settled = settle_point(tree, shader, surface, point, threshold, visibility, list);
    let mut host = settled.visibility;
    let at = At::new(tree, shader, surface);
    let mut tally = Tally::new(settled.value);
    for (entry, _) in list.waiting() {
        tally.sample_node(&at, entry.node, entry.seen, point, &mut host, uniform);
    }
    tally.finish(
        settled.nodes,
        settled.lights,
        settled.classify_queries,
        settled.point_queries,
        settled.stop,
    )
}

/// One point's stochastic estimate as it is summed: the exactly summed
/// part, each sampled node's mean of two samples, and the variance
/// estimate.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tally {
    radiance: DVec3,
    variance: DVec3,
    nodes: u32,
    lights: u32,
    rays: u32,
}

impl Tally {
    /// A tally whose exactly summed part is `settled`.
    #[inline(always)]
    pub(crate) fn new(settled: DVec3) -> Self {
        Self {
            radiance: settled,
            variance: DVec3::ZERO,
            nodes: 0,
            lights: 0,
            rays: 0,
        }
    }

    /// Adds `value` (a light's exact term at the point) to the exactly
    /// summed part.
    #[inline(always)]
    pub(crate) fn add_exact(&mut self, value: DVec3) {
        self.radiance += value;
        self.lights += 1;
    }

    /// Counts a point-to-point query asked for the exactly summed part.
    #[inline(always)]
    pub(crate) fn add_ray(&mut self) {
        self.rays += 1;
    }

    /// Samples two lights below `node` at the point of `at` (shading
    /// position `point`) and adds the mean of their terms over their
    /// probabilities; the host is asked point-to-point about a light that
    /// contributes unless the node is known visible (`seen`).
    #[inline(always)]
    pub(crate) fn sample_node<S: Shader, V: Visibility>(
        &mut self,
        at: &At<'_, S>,
        node: u32,
        seen: Seen,
        point: Vec3,
        host: &mut V,
        uniform: &mut impl FnMut() -> f64,
    ) {
        let (tree, shader, surface) = (at.tree, at.shader, at.surface);
        let range = tree.nodes[node as usize].lights();
        if (seen == Seen::Visible || V::ALWAYS_VISIBLE) && range.len() <= SUM_INSTEAD_LIGHTS {
            self.sum_lights(at, range);
            return;
        }
        self.nodes += 1;
        let mut x = [DVec3::ZERO; SAMPLES_PER_NODE as usize];
        for x in &mut x {
            let Some((light, p)) = descend(at, node as usize, uniform()) else {
                continue;
            };
            self.lights += 1;
            let profile = tree.profile(light);
            let light = &tree.lights[light];
            let f = shader.eval(
                &at.per_point,
                surface,
                light.position.as_dvec3(),
                light.intensity.as_dvec3(),
            ) * profile.factor(light.position, surface.point);
            if f == DVec3::ZERO {
                continue;
            }
            if seen != Seen::Visible && !V::ALWAYS_VISIBLE {
                self.rays += 1;
                if !host.visible(point, light.position) {
                    continue;
                }
            }
            *x = f / p;
        }
        self.radiance += 0.5 * (x[0] + x[1]);
        let d = x[0] - x[1];
        self.variance += 0.25 * d * d;
    }

    /// Adds the exact terms of the lights `range` (leaf order), known
    /// visible, to the exactly summed part.
    #[inline(always)]
    fn sum_lights<S: Shader>(&mut self, at: &At<'_, S>, range: core::ops::Range<usize>) {
        let tree = at.tree;
        let mut values = [DVec3::ZERO; SUM_LIGHTS_MAX];
        let mut index = range.start;
        for lights in tree.lights[range].chunks(SUM_LIGHTS_MAX) {
            let values = &mut values[..lights.len()];
            at.shader
                .eval_lights(&at.per_point, at.surface, lights, values);
            for (light, value) in lights.iter().zip(values.iter()) {
                self.radiance += if tree.is_oriented() {
                    *value * tree.profile(index).factor(light.position, at.surface.point)
                } else {
                    *value
                };
                index += 1;
            }
            self.lights += lights.len() as u32;
        }
    }

    /// The estimate, with the work of the cut that chose the nodes.
    #[inline(always)]
    pub(crate) fn finish(
        self,
        nodes_evaluated: u32,
        lights: u32,
        classify_queries: u32,
        point_queries: u32,
        stop: Stop,
    ) -> Stochastic {
        Stochastic {
            radiance: self.radiance,
            variance: self.variance,
            nodes_sampled: self.nodes,
            nodes_evaluated,
            lights_evaluated: lights + self.lights,
            classify_queries,
            point_queries: point_queries + self.rays,
            stop,
        }
    }
}
