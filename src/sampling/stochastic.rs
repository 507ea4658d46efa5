//! The stochastic cut (after Stochastic Lightcuts, Yuksel 2019): a
//! certified cut at a coarse threshold, then lights sampled inside each
//! node it leaves, for an unbiased estimate of the whole sum.

use glam::{DVec3, Vec3};

use super::choice::{At, descend};
use crate::Threshold;
use crate::cut::{ErrorList, Seen, Stop, settle_point};
use crate::geometry::Surface;
use crate::shader::Shader;
use crate::tree::LightTree;
use crate::visibility::Visibility;

/// Samples drawn inside each node the cut leaves: two, so that their
/// difference gives an unbiased estimate of the variance.
pub(crate) const SAMPLES_PER_NODE: u32 = 2;

/// An unbiased estimate of one shading point's radiance from
/// [`Shading::shade_stochastic`](crate::Shading::shade_stochastic), with an
/// unbiased estimate of its variance. Not certified: the estimate's error
/// has no bound, only a variance.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct Stochastic {
    /// The estimate: the cut's exactly summed part plus, for each node it
    /// left, the mean of two sampled lights' terms divided by their
    /// probabilities. Its expectation is the model's exact value (with
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
    /// Nodes the cut left, each sampled twice.
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
    let (mut radiance, mut variance) = (settled.value, DVec3::ZERO);
    let (mut nodes, mut lights, mut rays) = (0u32, 0u32, 0u32);
    for (entry, _) in list.waiting() {
        nodes += 1;
        let mut x = [DVec3::ZERO; SAMPLES_PER_NODE as usize];
        for x in &mut x {
            let Some((light, p)) = descend(&at, entry.node as usize, uniform()) else {
                continue;
            };
            lights += 1;
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
            if entry.seen != Seen::Visible && !V::ALWAYS_VISIBLE {
                rays += 1;
                if !host.visible(point, light.position) {
                    continue;
                }
            }
            *x = f / p;
        }
        radiance += 0.5 * (x[0] + x[1]);
        let d = x[0] - x[1];
        variance += 0.25 * d * d;
    }
    Stochastic {
        radiance,
        variance,
        nodes_sampled: nodes,
        nodes_evaluated: settled.nodes,
        lights_evaluated: settled.lights + lights,
        classify_queries: settled.classify_queries,
        point_queries: settled.point_queries + rays,
        stop: settled.stop,
    }
}
