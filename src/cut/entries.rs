//! A point's certified cut handed back whole: what it settled and the
//! entries it left waiting, for an estimator that samples inside them
//! (the stochastic cut, [`Shading::shade_stochastic`]).
//!
//! [`Shading::shade_stochastic`]: crate::Shading::shade_stochastic

use glam::{DVec3, Vec3};

use super::engine::Cut;
use super::error_list::ErrorList;
use super::point::Point;
use super::result::Stop;
use super::threshold::Threshold;
use crate::geometry::Surface;
use crate::shader::Shader;
use crate::tree::LightTree;
use crate::visibility::Visibility;

/// What a point's cut settled, what it spent, and the host back.
pub(crate) struct Settled<V> {
    /// The exactly summed part: lights summed in `f64` (never the coarse
    /// `f32` sums, whose rounding an unbiased estimator could not absorb)
    /// and nodes settled with no error.
    pub(crate) value: DVec3,
    /// The host, for the rays of the lights sampled inside the entries.
    pub(crate) visibility: V,
    /// Nodes bounded, lights evaluated, classifications and rays asked.
    pub(crate) nodes: u32,
    pub(crate) lights: u32,
    pub(crate) classify_queries: u32,
    pub(crate) point_queries: u32,
    /// Why the list stopped.
    pub(crate) stop: Stop,
}

/// Runs the cut of the point `point` (with surface `surface`) until
/// `threshold` is met or its budget spent, as a shading call would but
/// without coarse sums, a small scene's sum or interpolation: the nodes it
/// leaves waiting are then in `list` ([`ErrorList::waiting`]), and
/// everything else it settled is exact up to `f64` rounding.
#[inline(always)]
pub(crate) fn settle_point<S: Shader, V: Visibility>(
    tree: &LightTree,
    shader: &S,
    surface: &Surface,
    point: Vec3,
    threshold: &Threshold,
    visibility: V,
    list: &mut ErrorList,
) -> Settled<V> {
    let emitters = tree
        .is_oriented()
        .then(super::point::EmitterScratch::default);
    let mut region = Point::new(
        tree,
        shader,
        surface,
        point,
        threshold,
        None,
        emitters.as_ref(),
    );
    region.coarse = None;
    let mut cut = Cut::new(tree, shader, region, threshold, visibility);
    cut.enter_root(list, None);
    let outcome = cut.run(list, threshold, None);
    Settled {
        value: cut.region.settled.value(),
        nodes: cut.work.nodes,
        lights: cut.work.lights,
        classify_queries: cut.work.classify_queries,
        point_queries: cut.work.point_queries,
        stop: outcome.stop,
        visibility: cut.visibility,
    }
}
