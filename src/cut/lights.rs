//! The lights a point's cut sums: one at a time, a few at a time in `f64`,
//! coarsely in `f32` lanes with a certified bound on their rounding, with
//! the host asked about those of unknown visibility; and small scenes
//! summed whole.

use glam::{DVec3, Vec3};

use super::engine::Cut;
use super::error_list::Seen;
use super::point::{Point, coarse_share, reported_bound};
use super::policy::{
    ASK_MAX, COARSE_LIGHTS_MAX, COARSE_MISSES_MAX, SMALL_SCENE_LIGHTS_COARSE, SUM_LIGHTS_MAX,
    TINY_SCENE_LIGHTS,
};
use super::result::{ShadeResult, Stop};
use super::threshold::Threshold;
use crate::geometry::Surface;
use crate::numeric::{CompensatedSum, NAIVE_DOT_ACCEPT, plain_dot_of_difference};
use crate::shader::{Seal, Shader};
use crate::tree::LightTree;
use crate::visibility::Visibility;
use crate::{LightLanes, PointLight};

impl<'p, S: Shader, V: Visibility> Cut<'_, S, V, Point<'p, S>> {
    /// One light's exact contribution, times `weight`, added to the settled
    /// sum, unless the host says it is hidden: a light of unknown visibility
    /// that contributes anything is asked about point-to-point at once (it
    /// enters the cut only when its node is refined, and one ray settles it
    /// exactly); dark lights and lights behind the surface need no ray.
    #[inline(always)]
    pub(crate) fn exact_light(
        &mut self,
        position: Vec3,
        intensity: DVec3,
        seen: Seen,
        weight: f64,
    ) {
        let value = self.shader.eval(
            &self.region.per_point,
            self.region.surface,
            position.as_dvec3(),
            intensity,
        );
        self.settle_light(position, value, seen, weight);
    }

    /// [`exact_light`](Self::exact_light) after the evaluation, `value`
    /// being the light's exact contribution.
    #[inline(always)]
    fn settle_light(&mut self, position: Vec3, value: DVec3, seen: Seen, weight: f64) {
        self.work.lights += 1;
        if value == DVec3::ZERO {
            return;
        }
        if seen != Seen::Visible {
            self.work.point_queries += 1;
            if !self.visibility.visible(self.region.point, position) {
                return;
            }
        }
        self.region.settled.add(value * weight);
    }

    /// Each light of `range` (leaf order) exactly, see
    /// [`exact_light`](Self::exact_light).
    #[inline(always)]
    pub(crate) fn sum_lights(&mut self, range: core::ops::Range<usize>, seen: Seen, weight: f64) {
        const CHUNK: usize = SUM_LIGHTS_MAX;
        let tree = self.tree;
        if seen == Seen::Visible && !self.region.one_by_one {
            self.work.lights += range.len() as u32;
            if let Some(share) = self.region.coarse {
                if let Some(lanes) = self.region.small_lanes
                    && !lanes.is_empty()
                    && range == (0..tree.lights.len())
                {
                    // The whole of a small scene: its lights side by side.
                    let region = &mut self.region;
                    let scene = SmallScene {
                        shader: self.shader,
                        per_point: &region.per_point,
                        surface: region.surface,
                        lights: &tree.lights,
                        lanes,
                        share,
                    };
                    let whole = scene.whole();
                    scene.settle(
                        whole,
                        weight,
                        &mut region.settled,
                        &mut region.settled_error,
                    );
                    return;
                }
                // Each chunk's lights start loading while the one before
                // is summed (the first's mostly did when the cut took
                // them, see `refine`).
                let lights = &tree.lights[range];
                let mut chunks = lights.chunks(COARSE_LIGHTS_MAX).peekable();
                if let Some(first) = chunks.peek() {
                    tree.prefetch_lights(first);
                }
                while let Some(chunk) = chunks.next() {
                    if let Some(next) = chunks.peek() {
                        tree.prefetch_lights(next);
                    }
                    self.sum_seen_coarse(chunk, share, weight);
                }
                return;
            }
            self.sum_visible(&tree.lights[range], weight);
            return;
        }
        if !V::ALWAYS_VISIBLE
            && seen != Seen::Visible
            && let (Some(share), Some(horizon)) = (self.region.coarse, self.region.horizon)
        {
            self.sum_asked_coarse(&tree.lights[range], horizon, share, weight);
            return;
        }
        let mut values = [DVec3::ZERO; CHUNK];
        for lights in tree.lights[range].chunks(CHUNK) {
            let values = &mut values[..lights.len()];
            self.shader
                .eval_lights(&self.region.per_point, self.region.surface, lights, values);
            if seen == Seen::Visible || V::ALWAYS_VISIBLE {
                for (light, value) in lights.iter().zip(values.iter()) {
                    self.settle_light(light.position, *value, seen, weight);
                }
            } else {
                self.settle_asked(lights, values, weight);
            }
        }
    }

    /// Each light of `range` (leaf order) of a tree of emitters, times
    /// `weight`: its exact term times its profile's value (crate docs, "The
    /// model"), [`SUM_LIGHTS_MAX`] lights at a time. Lights whose profile
    /// is 0 at the point are neither evaluated (nor counted as evaluated)
    /// nor asked about; the host is asked about the others of unknown
    /// visibility together.
    #[inline(always)]
    pub(crate) fn sum_emitters(&mut self, range: core::ops::Range<usize>, seen: Seen, weight: f64) {
        const CHUNK: usize = SUM_LIGHTS_MAX;
        let tree = self.tree;
        let Some(orientation) = tree.orientation.as_deref() else {
            return self.sum_lights(range, seen, weight);
        };
        let p = self.region.surface.point;
        let mut lit = [PointLight::default(); CHUNK];
        let mut factors = [0.0f64; CHUNK];
        let mut values = [DVec3::ZERO; CHUNK];
        let lights = tree.lights[range.clone()].chunks(CHUNK);
        let profiles = orientation.profiles[range].chunks(CHUNK);
        for (lights, profiles) in lights.zip(profiles) {
            let mut n = 0;
            for (light, profile) in lights.iter().zip(profiles) {
                let f = profile.factor(light.position, p);
                if f > 0.0 {
                    lit[n] = *light;
                    factors[n] = f;
                    n += 1;
                }
            }
            if n == 0 {
                continue;
            }
            // Counted as evaluated: the lights whose terms are.
            self.work.lights += n as u32;
            let values = &mut values[..n];
            self.shader.eval_lights(
                &self.region.per_point,
                self.region.surface,
                &lit[..n],
                values,
            );
            for (value, f) in values.iter_mut().zip(&factors) {
                *value *= *f;
            }
            if seen == Seen::Visible || V::ALWAYS_VISIBLE {
                for value in values.iter() {
                    self.region.settled.add(*value * weight);
                }
            } else {
                let (asked, which, seen) =
                    self.ask_together(&lit[..n], |k, _| values[k] != DVec3::ZERO);
                for (&k, &seen) in which[..asked].iter().zip(&seen[..asked]) {
                    if seen {
                        self.region.settled.add(values[usize::from(k)] * weight);
                    }
                }
            }
        }
    }

    /// [`settle_light`](Self::settle_light) for each of `lights` (at most
    /// [`SUM_LIGHTS_MAX`]) of unknown visibility, with their exact
    /// contributions `values`: the host is asked about those that
    /// contribute anything all at once ([`Visibility::visible_lights`]),
    /// and the visible ones are settled in order.
    #[inline(always)]
    fn settle_asked(&mut self, lights: &[PointLight], values: &[DVec3], weight: f64) {
        self.work.lights += lights.len() as u32;
        let (asked, which, seen) = self.ask_together(lights, |k, _| values[k] != DVec3::ZERO);
        for (&k, &seen) in which[..asked].iter().zip(&seen[..asked]) {
            if seen {
                self.region.settled.add(values[usize::from(k)] * weight);
            }
        }
    }

    /// Asks the host about the lights of `chunk` (at most [`ASK_MAX`])
    /// that `ask` picks (by index and light), all at
    /// once ([`Visibility::visible_lights`]): how many were asked, and for
    /// each in order its index in `chunk` and whether it is visible.
    #[inline(always)]
    fn ask_together(
        &mut self,
        chunk: &[PointLight],
        ask: impl Fn(usize, &PointLight) -> bool,
    ) -> (usize, [u8; ASK_MAX], [bool; ASK_MAX]) {
        let mut positions = [Vec3::ZERO; ASK_MAX];
        let mut which = [0u8; ASK_MAX];
        let mut asked = 0;
        for (k, light) in chunk.iter().enumerate() {
            if ask(k, light) {
                positions[asked] = light.position;
                which[asked] = k as u8;
                asked += 1;
            }
        }
        self.work.point_queries += asked as u32;
        let mut seen = [false; ASK_MAX];
        self.visibility
            .visible_lights(self.region.point, &positions[..asked], &mut seen[..asked]);
        (asked, which, seen)
    }

    /// The lights of `lights` (leaf order) of unknown visibility, where
    /// coarse sums are used and the shader has a horizon: those that may
    /// contribute (lit, and not surely at or below the horizon plane) are
    /// asked about together ([`Visibility::visible_lights`], at most
    /// [`ASK_MAX`] at a time), and the visible ones summed coarsely
    /// where the sum's error is a small enough share of it, else exactly
    /// as [`settle_asked`](Self::settle_asked) would. No light is
    /// evaluated before the host has answered for it.
    ///
    /// A light is left out only when it is dark or `a . (x - p) < 0`
    /// exactly, `a` the horizon's vector: there the shader's term is exactly
    /// 0 ([`Shader::horizon`]). The sign is taken from the plain `f64` dot
    /// product where it is certain (at most `-NAIVE_DOT_ACCEPT` times the
    /// terms' magnitude, see [`NAIVE_DOT_ACCEPT`]); lights nearer the plane
    /// are asked about, and their terms, at most rounding, go through the
    /// sums' own bounds.
    #[inline(always)]
    fn sum_asked_coarse(&mut self, lights: &[PointLight], horizon: Vec3, share: f64, weight: f64) {
        let (p, a) = (self.region.surface.point, horizon.as_dvec3());
        self.work.lights += lights.len() as u32;
        for chunk in lights.chunks(ASK_MAX) {
            let (asked, which, seen) = self.ask_together(chunk, |_, light| {
                let (z, magnitude) = plain_dot_of_difference(a, light.position.as_dvec3(), p);
                light.intensity != Vec3::ZERO && z > -NAIVE_DOT_ACCEPT * magnitude
            });
            let mut visible = [PointLight::new(Vec3::ZERO, Vec3::ZERO); ASK_MAX];
            let mut count = 0;
            for (&k, &seen) in which[..asked].iter().zip(&seen[..asked]) {
                visible[count] = chunk[usize::from(k)];
                count += usize::from(seen);
            }
            if count > 0 {
                self.sum_seen_coarse(&visible[..count], share, weight);
            }
        }
    }

    /// The sum of `lights` (at most [`COARSE_LIGHTS_MAX`]), visible, times
    /// `weight`, settled: coarsely ([`Shader::sum_lights_coarse`]) where
    /// the sum's error is at most `share` of it channel by channel, the
    /// error joining the settled error; else as
    /// [`sum_seen_plain`](Self::sum_seen_plain), which also takes every
    /// sum once [`COARSE_MISSES_MAX`] coarse sums in a row were not kept.
    /// The caller counts the lights.
    #[inline(always)]
    fn sum_seen_coarse(&mut self, lights: &[PointLight], share: f64, weight: f64) {
        if self.region.coarse_misses >= COARSE_MISSES_MAX {
            self.sum_seen_plain(lights, share, weight);
            return;
        }
        match self.shader.sum_lights_coarse(
            Seal,
            &self.region.per_point,
            self.region.surface,
            lights,
        ) {
            Some((sum, error)) if error.cmple(sum * share).all() => {
                self.region.settled.add(sum * weight);
                self.region.settled_error += error * weight;
                self.region.coarse_misses = 0;
            }
            _ => {
                self.region.coarse_misses += 1;
                self.sum_seen_plain(lights, share, weight);
            }
        }
    }

    /// `lights`, known visible, times `weight`, where their coarse sum was
    /// not kept: the shader's plain `f64` sum
    /// ([`Shader::sum_lights_plain`]) where its error is at most `share` of
    /// it channel by channel, else [`sum_visible`](Self::sum_visible). The
    /// caller counts the lights.
    #[inline(always)]
    fn sum_seen_plain(&mut self, lights: &[PointLight], share: f64, weight: f64) {
        let region = &mut self.region;
        if !settle_plain(
            self.shader,
            &region.per_point,
            region.surface,
            lights,
            share,
            weight,
            (&mut region.settled, &mut region.settled_error),
        ) {
            self.sum_visible(lights, weight);
        }
    }

    /// The sum of `lights`, known visible, times `weight`, settled: a
    /// chunk at a time, each chunk a plain sum of non-negative terms (see
    /// [`Shader::sum_lights`]). The caller counts the lights.
    #[inline(always)]
    fn sum_visible(&mut self, lights: &[PointLight], weight: f64) {
        let (shader, per_point, surface) =
            (self.shader, &self.region.per_point, self.region.surface);
        settle_visible(
            shader,
            per_point,
            surface,
            lights,
            weight,
            &mut self.region.settled,
        );
    }
}

/// [`Cut::sum_visible`]: the plain sum of `lights`, known visible, times
/// `weight`, into `settled`, a chunk of [`SUM_LIGHTS_MAX`] at a time.
#[inline(always)]
fn settle_visible<S: Shader>(
    shader: &S,
    per_point: &S::PerPoint,
    surface: &Surface,
    lights: &[PointLight],
    weight: f64,
    settled: &mut CompensatedSum,
) {
    for lights in lights.chunks(SUM_LIGHTS_MAX) {
        settled.add(shader.sum_lights(Seal, per_point, surface, lights) * weight);
    }
}

/// The shader's plain `f64` sum of `lights`, known visible, times
/// `weight`, settled into `settled` and its error into the second, where
/// that error is at most `share` of the sum channel by channel: whether it
/// was.
#[inline(always)]
fn settle_plain<S: Shader>(
    shader: &S,
    per_point: &S::PerPoint,
    surface: &Surface,
    lights: &[PointLight],
    share: f64,
    weight: f64,
    (settled, error_sum): (&mut CompensatedSum, &mut DVec3),
) -> bool {
    match shader.sum_lights_plain(Seal, per_point, surface, lights) {
        Some((sum, error)) if error.cmple(sum * share).all() => {
            settled.add(sum * weight);
            *error_sum += error * weight;
            true
        }
        _ => false,
    }
}

/// A small scene's lights, and the same lights side by side in `lanes`,
/// summed at one point by `shader` (per-point data `per_point`), coarse
/// sums kept where their error is at most `share` of them channel by
/// channel.
struct SmallScene<'s, S: Shader> {
    shader: &'s S,
    per_point: &'s S::PerPoint,
    surface: &'s Surface,
    lights: &'s [PointLight],
    lanes: &'s [LightLanes],
    share: f64,
}

impl<S: Shader> SmallScene<'_, S> {
    /// The shader's [`Shader::sum_scene_coarse`] of the whole scene, where
    /// its error is at most `share` of the sum channel by channel (what
    /// [`settle`](Self::settle) takes first).
    #[inline(always)]
    fn whole(&self) -> Option<(DVec3, DVec3)> {
        self.shader
            .sum_scene_coarse(
                Seal,
                self.per_point,
                self.surface,
                self.lanes,
                self.lights.len(),
            )
            .filter(|(sum, error)| error.cmple(*sum * self.share).all())
    }

    /// The sum of the scene, visible, times `weight`, settled into
    /// `settled` and its error into `error_sum`: `whole`, the scene's
    /// [`whole`](Self::whole) sum, where it was kept; else
    /// [`COARSE_LIGHTS_MAX`] lights at a time: the shader's
    /// [`Shader::sum_lanes_coarse`] where it has one, else its
    /// [`Shader::sum_lights_coarse`], kept where the sum's error is at most
    /// `share` of it channel by channel (as `Cut::sum_seen_coarse`); else
    /// the shader's plain `f64` sum where the same holds of it; else
    /// [`settle_visible`].
    #[inline(always)]
    fn settle(
        &self,
        whole: Option<(DVec3, DVec3)>,
        weight: f64,
        settled: &mut CompensatedSum,
        error_sum: &mut DVec3,
    ) {
        let (shader, per_point, surface) = (self.shader, self.per_point, self.surface);
        if let Some((sum, error)) = whole {
            settled.add(sum * weight);
            *error_sum += error * weight;
            return;
        }
        // Lights `start..` and their lanes from `start / 8` (a multiple of
        // eight): an index rather than zipped chunks, whose lengths take
        // divisions.
        let (all, lanes) = (self.lights, self.lanes);
        let mut start = 0;
        while start < all.len() && start / 8 < lanes.len() {
            let end = (start + COARSE_LIGHTS_MAX).min(all.len());
            let first = start / 8;
            let lanes = &lanes[first..(first + COARSE_LIGHTS_MAX / 8).min(lanes.len())];
            let lights = &all[start..end];
            start = end;
            let sum = shader
                .sum_lanes_coarse(Seal, per_point, surface, lanes, lights.len())
                .or_else(|| shader.sum_lights_coarse(Seal, per_point, surface, lights));
            match sum {
                Some((sum, error)) if error.cmple(sum * self.share).all() => {
                    settled.add(sum * weight);
                    *error_sum += error * weight;
                }
                _ => {
                    let sums = (&mut *settled, &mut *error_sum);
                    if !settle_plain(shader, per_point, surface, lights, self.share, weight, sums) {
                        settle_visible(shader, per_point, surface, lights, weight, settled);
                    }
                }
            }
        }
    }
}

/// Whether a small scene (its lights side by side in `lanes`) is summed
/// whole wherever the point lies, once known visible: at most
/// [`TINY_SCENE_LIGHTS`] lights (one coarse sum of the scene, which costs
/// less than bounding the root), and no plane recorded at the root. The
/// one rule for [`shade_small_scene`] and `Point::summed_on_visible_root`.
#[inline(always)]
pub(crate) fn tiny_scene(tree: &LightTree, lanes: &[LightLanes]) -> bool {
    !lanes.is_empty()
        && tree
            .nodes
            .first()
            .is_some_and(|root| root.light_count as usize <= TINY_SCENE_LIGHTS)
        && tree.node_plane(0).is_none()
}

/// The cut of a small scene whose lights are known visible (`lanes` side
/// by side, see `Point::sums_whole_scene`), summed without setting up the
/// cut, or `None` where the caller runs the cut:
///
/// * when the shading point lies in the root's ball, which has then no
///   bound: the cut would count the root, find it unbounded and sum the
///   whole scene. This is that sum, so the same bits and counts.
/// * for a scene of at most [`TINY_SCENE_LIGHTS`] lights ([`tiny_scene`]),
///   wherever the point lies: where the cut would bound the root first,
///   setting it up costs more than the sum. The root is counted as
///   evaluated, and a host's cut that is told the root is visible sums the
///   scene the same way (`Point::summed_on_visible_root`), so that it gets these
///   bits.
///
/// Not where the cut would take another step first: a dark root, a plane
/// recorded at the root, a single light, interpolation, a target for which
/// lights are not summed coarsely, a budget the sum would exceed.
#[inline(always)]
pub(crate) fn shade_small_scene<S: Shader, V: Visibility>(
    tree: &LightTree,
    shader: &S,
    lanes: &[LightLanes],
    surface: &Surface,
    threshold: &Threshold,
) -> Option<ShadeResult> {
    let root = tree.nodes.first()?;
    let share = coarse_share(threshold)?;
    let budget = threshold.budget().unwrap_or(u32::MAX).max(1);
    let lights = root.light_count;
    if !V::ALWAYS_VISIBLE
        || lanes.is_empty()
        || lights > SMALL_SCENE_LIGHTS_COARSE
        || 1u32.saturating_add(lights) > budget
        || root.intensity == DVec3::ZERO
        || root.radius == 0.0
        || tree.node_plane(0).is_some()
        || (!tiny_scene(tree, lanes) && root.cone(surface.point).is_some())
    {
        return None;
    }
    let per_point = shader.prepare(surface);
    let scene = SmallScene {
        shader,
        per_point: &per_point,
        surface,
        lights: &tree.lights,
        lanes,
        share,
    };
    // What `SmallScene::settle` leaves in empty sums: where the whole
    // scene's sum is kept, the sum itself (a compensated sum of one term
    // from zero is the term) and its error.
    let (settled, settled_error) = match scene.whole() {
        Some(sum) => sum,
        None => {
            let (mut settled, mut error) = (CompensatedSum::default(), DVec3::ZERO);
            scene.settle(None, 1.0, &mut settled, &mut error);
            (settled.value(), error)
        }
    };
    // As the cut's end with an empty error list: its sums are +0.
    Some(ShadeResult {
        radiance: settled + DVec3::ZERO,
        error_bound: reported_bound(DVec3::ZERO + settled_error),
        nodes_evaluated: 1,
        lights_evaluated: lights,
        classify_queries: 0,
        point_queries: 0,
        stop: Stop::ThresholdMet,
    })
}
