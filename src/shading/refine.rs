//! Refinement: evaluating nodes as they enter the cut, and the error list's
//! loop that replaces the worst node by its children until the threshold is
//! met.

use glam::{DVec3, Vec3};

use super::blend::{NO_PARENT, Nesting};
use super::error_list::{Class, Entry, ErrorList, Seen};
use super::result::{ShadeResult, Stop};
use super::threshold::Threshold;
use crate::geometry::{Cone, Surface};
use crate::numeric::{CompensatedSum, NAIVE_DOT_ACCEPT, SUM_SLACK, plain_dot_of_difference};
use crate::shader::{COARSE_LIGHTS_MAX, COARSE_TARGET_MIN, NodeEstimate, SUM_LIGHTS_MAX, Shader};
use crate::tree::{LightTree, NO_PLANE, Node, SMALL_SCENE_LIGHTS, SMALL_SCENE_LIGHTS_COARSE};
use crate::visibility::{Coverage, NodeRegion, Visibility};
use crate::{LightLanes, PointLight, Target};

/// One shading call's state: what it reads (tree, shader, the point), the
/// host it asks, and what it has settled and spent so far.
pub(crate) struct Cut<'a, S: Shader, V> {
    pub(crate) tree: &'a LightTree,
    pub(crate) shader: &'a S,
    pub(crate) surface: &'a Surface,
    pub(crate) per_point: S::PerPoint,
    /// The shading point as the host was given it.
    pub(crate) point: Vec3,
    pub(crate) max_contribution: Option<f64>,
    pub(crate) budget: u32,
    /// Largest visible node summed light by light instead of bounded: 0
    /// with interpolation, whose blend ramps through bounded nodes.
    exact_lights: u32,
    /// Largest visible node summed light by light when near the point (see
    /// [`NEAR_NODE_LIGHTS`]): 0 with interpolation, or with a budget, which
    /// such a sum could spend at once.
    near_lights: u32,
    /// Whether visible lights are added one at a time to the compensated
    /// sum (a target of 0, see [`Threshold::exact`]) rather than a few at a
    /// time ([`Shader::sum_lights`]).
    one_by_one: bool,
    /// For a small scene, summed light by light rather than cut (see
    /// [`Cut::sums_whole_scene`]), its lights side by side for the shader's
    /// [`Shader::sum_lanes_coarse`]; `None` for other trees.
    small_lanes: Option<&'a [LightLanes]>,
    pub(crate) visibility: V,
    /// Exact leaves and nodes that need no refinement.
    pub(crate) settled: CompensatedSum,
    /// The certified error of what was settled by coarse sums of lights
    /// ([`Shader::sum_lights_coarse`]).
    pub(crate) settled_error: DVec3,
    /// The share of a coarse sum its error may be for the sum to be kept
    /// (`1/32` of a relative target), or `None` where coarse sums are not
    /// used; where they are, children are bounded coarsely too
    /// ([`Shader::bound_children_coarse`]).
    coarse: Option<f64>,
    pub(crate) nodes: u32,
    pub(crate) lights: u32,
    pub(crate) classify_queries: u32,
    /// Classifications answered visible or occluded.
    decisive_answers: u32,
    /// Classifications of nodes of at most [`SMALL_NODE_LIGHTS`] lights
    /// answered partial.
    small_partials: u32,
    pub(crate) point_queries: u32,
    /// The shader's [`horizon`](Shader::horizon) at this point.
    horizon: Option<Vec3>,
    /// The last plane asked about and whether it lies at or below the
    /// tangent plane (a coplanar node's descendants share its plane).
    dark_plane: (u32, bool),
    /// Children of the node being refined, waiting to be bounded together
    /// (kept here so that it is set up once per call, not per refinement).
    group: Group,
}

/// How the error list's loop ended.
pub(crate) struct Outcome {
    pub(crate) stop: Stop,
    /// The excess over the target before, and the key of, the last
    /// refinement: they place the interpolation level between the last two
    /// steps (`None` for a threshold that does not interpolate).
    pub(crate) last_step: Option<(f64, f64)>,
    /// With nesting, the certified sums that confirmed the stop, if the
    /// threshold stopped the loop.
    pub(crate) confirmed: Option<(DVec3, DVec3)>,
}

impl<'a, S: Shader, V: Visibility> Cut<'a, S, V> {
    pub(crate) fn new(
        tree: &'a LightTree,
        shader: &'a S,
        surface: &'a Surface,
        point: Vec3,
        threshold: &Threshold,
        visibility: V,
        small_lanes: Option<&'a [LightLanes]>,
    ) -> Self {
        Self {
            tree,
            shader,
            surface,
            per_point: shader.prepare(surface),
            point,
            max_contribution: threshold.max_contribution(),
            budget: threshold.budget().unwrap_or(u32::MAX).max(1),
            exact_lights: if threshold.interpolation().is_some() {
                0
            } else {
                EXACT_NODE_LIGHTS
            },
            near_lights: if threshold.interpolation().is_some() || threshold.budget().is_some() {
                0
            } else {
                NEAR_NODE_LIGHTS
            },
            one_by_one: threshold.is_exact(),
            small_lanes,
            visibility,
            settled: CompensatedSum::default(),
            settled_error: DVec3::ZERO,
            coarse: coarse_share(threshold),
            nodes: 0,
            lights: 0,
            classify_queries: 0,
            decisive_answers: 0,
            small_partials: 0,
            point_queries: 0,
            horizon: shader.horizon(surface),
            dark_plane: (NO_PLANE, false),
            group: Group::default(),
        }
    }

    /// Evaluations so far, in the units of the budget.
    #[inline]
    pub(crate) fn cost(&self) -> u32 {
        self.nodes.saturating_add(self.lights)
    }

    /// Whether refining `node` (its children or its lights) fits in the
    /// budget, `visible` saying whether the node is known visible (its
    /// small children are then summed light by light, see
    /// [`EXACT_NODE_LIGHTS`]).
    #[inline(always)]
    pub(crate) fn can_refine(&self, node: &Node, visible: bool) -> bool {
        if self.budget == u32::MAX {
            // No budget: every cost fits (the sum below saturates at it).
            return true;
        }
        let cost = if node.is_leaf() {
            node.light_count
        } else if visible || V::ALWAYS_VISIBLE {
            self.tree.nodes[node.children()]
                .iter()
                .map(|c| {
                    if self.sums_exactly(c) {
                        c.light_count
                    } else {
                        1
                    }
                })
                .sum()
        } else {
            node.child_count
        };
        self.cost().saturating_add(cost) <= self.budget
    }

    /// The paper's error list: starting from the root, takes the entry of
    /// greatest (class, error) while the threshold is not met and the
    /// budget allows. A node is refined (its children or lights replace
    /// it); an entry whose visibility is unknown is first asked about, and
    /// the answer decides: occluded entries drop out, visible ones go back
    /// with their unoccluded interval, partial ones are refined.
    ///
    /// With `nesting` (interpolation across levels), priorities are capped
    /// at the parent's and the refined part of the cut is recorded for the
    /// blend (see [`blend`](super::blend)). Inlined into each compiled copy
    /// of the shading call.
    #[inline(always)]
    pub(crate) fn run(
        &mut self,
        list: &mut ErrorList,
        threshold: &Threshold,
        mut nesting: Option<&mut Nesting>,
    ) -> Outcome {
        list.clear();
        if let Some(n) = nesting.as_deref_mut() {
            n.clear();
        }
        if !self.tree.nodes.is_empty()
            && let Some(root) = self.evaluate(0, V::ALWAYS_VISIBLE, 1.0)
        {
            list.push(root);
            if let Some(n) = nesting.as_deref_mut() {
                n.pushed(&root, NO_PARENT);
            }
        }
        if let Some(n) = nesting.as_deref_mut() {
            n.settled(NO_PARENT, self.settled.value());
        }
        let mut outcome = Outcome {
            stop: Stop::ThresholdMet,
            last_step: None,
            confirmed: None,
        };
        loop {
            let largest = list.largest();
            // The cut's sums: the waiting entries' and what is settled, or
            // with nesting each refined node's interval intersected with its
            // children's.
            let sums = match nesting.as_deref() {
                Some(n) => n.totals(),
                None => {
                    let (estimate, error) = list.sums();
                    (self.settled.value() + estimate, error + self.settled_error)
                }
            };
            if list.may_stop() && met(sums, largest, threshold) {
                // Confirm with exact sums: the running ones drift.
                let sums = match nesting.as_deref_mut() {
                    Some(n) => n.fold(list),
                    None => {
                        let (estimate, error) = list.resum();
                        (
                            self.settled.value() + estimate,
                            reported_bound(error + self.settled_error),
                        )
                    }
                };
                if threshold.met(sums.0, sums.1, largest) {
                    outcome.confirmed = nesting.is_some().then_some(sums);
                    break;
                }
            }
            let Some(top) = list.peek().copied() else {
                break;
            };
            let tree = self.tree;
            let node = &tree.nodes[top.node as usize];
            let refining = top.seen != Seen::Unknown || self.gave_up_classifying();
            if refining
                && top.node == 0
                && top.seen == Seen::Visible
                && nesting.is_none()
                && self.sums_whole_scene()
            {
                // A small scene known visible whose root alone does not
                // meet the threshold: summed light by light, which costs
                // less than cutting it (see `SMALL_SCENE_LIGHTS`).
                list.pop_slot();
                self.sum_lights(node.lights(), Seen::Visible, 1.0);
                continue;
            }
            if refining && !self.can_refine(node, top.seen == Seen::Visible) {
                outcome.stop = Stop::Budget;
                break;
            }
            if refining && threshold.interpolation().is_some() {
                // Only refinements place the interpolation level (which only
                // an interpolating threshold reads); asking the host changes
                // what an entry counts for, not the level.
                let before = threshold.excess(sums.0, reported_bound(sums.1), largest);
                outcome.last_step = Some((before, top.key));
            }
            let Some((_, slot)) = list.pop_slot() else {
                break;
            };
            let parent = nesting.as_deref_mut().map(|n| n.taken(&top, slot));
            if refining {
                // The next node to refine is probably the one waiting on top
                // now: its children load while this one's are evaluated.
                if let Some(next) = list.peek() {
                    self.tree.prefetch_refinement(next.node as usize);
                }
                let visible = top.seen == Seen::Visible;
                if let (Some(n), Some(parent)) = (nesting.as_deref_mut(), parent) {
                    // Children's priorities are capped at the parent's.
                    let frame = n.refined(&top, parent);
                    let outer = std::mem::take(&mut self.settled);
                    self.refine(top.node as usize, visible, 1.0, &mut |mut e: Entry| {
                        e.key = e.key.min(top.key);
                        list.push(e);
                        n.pushed(&e, frame);
                    });
                    let settled = std::mem::replace(&mut self.settled, outer).value();
                    self.settled.add(settled);
                    n.settled(frame, settled);
                    n.finish(frame);
                } else {
                    self.refine(top.node as usize, visible, 1.0, &mut *list);
                }
            } else if let (Some(n), Some(parent)) = (nesting.as_deref_mut(), parent) {
                let outer = std::mem::take(&mut self.settled);
                let entry = self.classify(node, top);
                let settled = std::mem::replace(&mut self.settled, outer).value();
                self.settled.add(settled);
                n.settled(parent, settled);
                if let Some(mut e) = entry {
                    e.key = e.key.min(top.key);
                    list.push(e);
                    n.pushed(&e, parent);
                }
                n.finish(parent);
            } else if let Some(e) = self.classify(node, top) {
                list.push(e);
            }
        }
        outcome
    }

    /// Whether the host's classifications have been useless so far in this
    /// call, so that partial nodes are refined without asking and single
    /// lights are asked point-to-point: with many small occluders (foliage,
    /// a lattice) every answer is "partial" and asking costs more than it
    /// saves.
    ///
    /// Useless means: at least [`GIVE_UP_AFTER`] *small* nodes (at most
    /// [`SMALL_NODE_LIGHTS`] lights) answered partial, and fewer than one
    /// visible or occluded answer (for a node of any size) per
    /// [`GIVE_UP_RATIO`] of them. Partial answers for large nodes are not
    /// held against the host: a large node's shaft is wide and the cut
    /// takes the large nodes first, so even a host that classifies most of
    /// a city's small nodes answers "partial" for its first few dozen
    /// nodes.
    #[inline]
    fn gave_up_classifying(&self) -> bool {
        self.small_partials >= GIVE_UP_AFTER
            && self.decisive_answers * GIVE_UP_RATIO < self.small_partials
    }

    /// Asks the host about a node of unknown visibility taken from the
    /// list: `None` when it is occluded (it drops out of the cut), else the
    /// entry to put back: visible, with its unoccluded interval; partial,
    /// estimated at the host's visible fraction if it gives one, and refined
    /// when the cut takes it again.
    fn classify(&mut self, node: &Node, top: Entry) -> Option<Entry> {
        self.classify_queries += 1;
        let region = region(node, top.node as usize);
        let seen = match self.visibility.classify(self.point, &region) {
            Coverage::Occluded => {
                self.decisive_answers += 1;
                return None;
            }
            Coverage::Visible => {
                self.decisive_answers += 1;
                if top.node == 0 && self.sums_tiny_scene() {
                    // As `shade_small_scene` does without a host, wherever
                    // the point lies; the root's entry drops out.
                    self.sum_lights(node.lights(), Seen::Visible, 1.0);
                    return None;
                }
                Seen::Visible
            }
            Coverage::Partial => {
                if node.light_count <= SMALL_NODE_LIGHTS {
                    self.small_partials += 1;
                }
                Seen::Partial(
                    self.visibility
                        .visible_fraction(self.point, &region)
                        .filter(|f| f.is_finite())
                        .map(|f| f.clamp(0.0, 1.0)),
                )
            }
        };
        let e = Entry::new(top.class, top.node, seen, top.estimate, top.error);
        if e.key <= 0.0 && e.class == Class::Error {
            self.settled.add(e.counted().0);
            return None;
        }
        Some(e)
    }

    /// Evaluates node `index` entering the cut with blend weight `weight`:
    /// settles it (dark nodes, error-free nodes, lamps known visible; times
    /// `weight`), or returns it as an entry (not weighted). Nothing is asked of the host here: a node of
    /// unknown visibility enters the cut as anything in `[0, upper]` and is
    /// asked about only when the cut takes it.
    #[inline(always)]
    pub(crate) fn evaluate(&mut self, index: usize, visible: bool, weight: f64) -> Option<Entry> {
        match self.enter(index, visible, weight) {
            Entering::Done(entry) => entry,
            Entering::Bound(cone) => {
                let node = &self.tree.nodes[index];
                let bound = self
                    .shader
                    .bound(&self.per_point, self.surface, node, &cone);
                self.bounded(index, visible, weight, &bound)
            }
        }
    }

    /// The part of [`evaluate`](Self::evaluate) before the node bound: what
    /// needs no bound is settled or returned, the rest is to be bounded
    /// under its cone.
    #[inline(always)]
    fn enter(&mut self, index: usize, visible: bool, weight: f64) -> Entering {
        match self.admit(index, visible, weight) {
            Admitted::Done(entry) => Entering::Done(entry),
            Admitted::ToBound => match self.tree.nodes[index].cone(self.surface.point) {
                Some(cone) => Entering::Bound(cone),
                None => Entering::Done(Some(self.unbounded(index, visible))),
            },
        }
    }

    /// What needs no bound of node `index` entering the cut: dark nodes,
    /// nodes wholly below the horizon, single (or coincident) lights are
    /// settled; the rest is counted as a node evaluation and left to be
    /// bounded.
    #[inline(always)]
    fn admit(&mut self, index: usize, visible: bool, weight: f64) -> Admitted {
        if self.unlit(index) {
            return Admitted::Done(None);
        }
        let node: &Node = &self.tree.nodes[index];
        if node.radius == 0.0 {
            // A single light, or coincident lights (the build makes them one
            // leaf): exactly one light of the summed intensity at the
            // centroid, whatever their number.
            let seen = seen(visible || V::ALWAYS_VISIBLE);
            self.exact_light(node.centroid, node.intensity, seen, weight);
            return Admitted::Done(None);
        }
        self.nodes += 1;
        Admitted::ToBound
    }

    /// Whether node `index` is exactly 0 at this point whatever its
    /// geometry, so that it needs neither a bound nor a sum: a dark node
    /// (even when its ball holds the shading point; no query is needed), or
    /// one whose lights all lie at or below the tangent plane, where the
    /// shader's model is exactly 0 (counted as a node evaluation).
    #[inline(always)]
    fn unlit(&mut self, index: usize) -> bool {
        if self.tree.nodes[index].intensity == DVec3::ZERO {
            return true;
        }
        if let Some(plane) = self.tree.node_plane(index)
            && self.below_horizon(plane)
        {
            self.nodes += 1;
            return true;
        }
        false
    }

    /// The entry of node `index` when it has no finite bound (its ball
    /// reaches the shading point): refined before any other.
    #[inline(always)]
    fn unbounded(&self, index: usize, visible: bool) -> Entry {
        Entry::new(
            Class::Unbounded,
            index as u32,
            seen(visible || V::ALWAYS_VISIBLE),
            DVec3::ZERO,
            DVec3::ZERO,
        )
    }

    /// The part of [`evaluate`](Self::evaluate) after the node bound.
    #[inline(always)]
    fn bounded(
        &mut self,
        index: usize,
        visible: bool,
        weight: f64,
        bound: &NodeEstimate,
    ) -> Option<Entry> {
        let over = self
            .max_contribution
            .is_some_and(|m| bound.upper.max_element() > m);
        let class = if over {
            Class::OverContribution
        } else {
            Class::Error
        };
        let seen = seen(visible || V::ALWAYS_VISIBLE);
        let entry = Entry::new(class, index as u32, seen, bound.estimate, bound.error());
        if entry.key <= 0.0 && !over {
            // Nothing to gain by refining (e.g. below the horizon).
            self.settled.add(entry.counted().0 * weight);
            return None;
        }
        Some(entry)
    }

    /// Whether the lights of plane `plane` lie at or below the plane of the
    /// shader's [`horizon`](Shader::horizon) (never without one).
    #[inline(always)]
    fn below_horizon(&mut self, plane: u32) -> bool {
        let Some(normal) = self.horizon else {
            return false;
        };
        if self.dark_plane.0 != plane {
            let dark = self
                .tree
                .plane_at_or_below(plane, self.surface.point, normal);
            self.dark_plane = (plane, dark);
        }
        self.dark_plane.1
    }

    /// One light's exact contribution, times `weight`, added to the settled
    /// sum, unless the host says it is hidden: a light of unknown visibility
    /// that contributes anything is asked about point-to-point at once (it
    /// enters the cut only when its node is refined, and one ray settles it
    /// exactly); dark lights and lights behind the surface need no ray.
    #[inline(always)]
    fn exact_light(&mut self, position: Vec3, intensity: DVec3, seen: Seen, weight: f64) {
        let value = self.shader.eval(
            &self.per_point,
            self.surface,
            position.as_dvec3(),
            intensity,
        );
        self.settle_light(position, value, seen, weight);
    }

    /// [`exact_light`](Self::exact_light) after the evaluation, `value`
    /// being the light's exact contribution.
    #[inline(always)]
    fn settle_light(&mut self, position: Vec3, value: DVec3, seen: Seen, weight: f64) {
        self.lights += 1;
        if value == DVec3::ZERO {
            return;
        }
        if seen != Seen::Visible {
            self.point_queries += 1;
            if !self.visibility.visible(self.point, position) {
                return;
            }
        }
        self.settled.add(value * weight);
    }

    /// Whether the whole scene is summed light by light when its root,
    /// known visible, is refined: a small scene (see
    /// [`SMALL_SCENE_LIGHTS`], or [`SMALL_SCENE_LIGHTS_COARSE`] where the
    /// lights are summed coarsely), within the budget, no interpolation
    /// (whose blend needs bounded nodes), and a target above 0 (with a
    /// target of 0 the cut refines as usual, so that it adds the lights in
    /// the order [`Shading::exact_query`](crate::Shading::exact_query)
    /// does).
    #[inline(always)]
    fn sums_whole_scene(&self) -> bool {
        let most = if self.coarse.is_some() {
            SMALL_SCENE_LIGHTS_COARSE
        } else {
            SMALL_SCENE_LIGHTS
        };
        self.small_lanes.is_some()
            && self.tree.nodes[0].light_count <= most
            && self.exact_lights > 0
            && !self.one_by_one
            && self.cost().saturating_add(self.tree.nodes[0].light_count) <= self.budget
    }

    /// Whether the whole scene is summed once its root is known visible,
    /// however far the point, and whether or not the root's interval
    /// already meets the threshold: a [`tiny_scene`], summed coarsely,
    /// that [`sums_whole_scene`](Self::sums_whole_scene). These are the
    /// conditions under which [`shade_small_scene`] sums such a scene
    /// without a host, so that a host answering "visible" at the root gets
    /// the same bits.
    #[inline(always)]
    fn sums_tiny_scene(&self) -> bool {
        self.coarse.is_some()
            && self
                .small_lanes
                .is_some_and(|lanes| tiny_scene(self.tree, lanes))
            && self.sums_whole_scene()
    }

    /// Whether a visible node is summed light by light when it enters the
    /// cut instead of bounded: a small one (see [`EXACT_NODE_LIGHTS`]), or
    /// one near the shading point for its size and number of lights (see
    /// [`NEAR_NODE_LIGHTS`]).
    #[inline(always)]
    fn sums_exactly(&self, node: &Node) -> bool {
        if node.radius == 0.0 {
            return false;
        }
        if node.light_count <= self.exact_lights {
            return true;
        }
        // `n D^2 <= NEAR_NODE_REACH R^2` in f64, where neither side can
        // overflow for finite f32 inputs.
        node.light_count <= self.near_lights && {
            let d2 = (node.centroid.as_dvec3() - self.surface.point).length_squared();
            let r = f64::from(node.radius);
            f64::from(node.light_count) * d2 <= NEAR_NODE_REACH * r * r
        }
    }

    /// Each light of `range` (leaf order) exactly, see
    /// [`exact_light`](Self::exact_light).
    #[inline(always)]
    fn sum_lights(&mut self, range: core::ops::Range<usize>, seen: Seen, weight: f64) {
        const CHUNK: usize = SUM_LIGHTS_MAX;
        let tree = self.tree;
        if seen == Seen::Visible && !self.one_by_one {
            self.lights += range.len() as u32;
            if let Some(share) = self.coarse {
                if let Some(lanes) = self.small_lanes
                    && !lanes.is_empty()
                    && range == (0..tree.lights.len())
                {
                    // The whole of a small scene: its lights side by side.
                    let (shader, per_point) = (self.shader, &self.per_point);
                    let whole = whole_scene_sum(
                        shader,
                        per_point,
                        self.surface,
                        lanes,
                        &tree.lights,
                        share,
                    );
                    settle_small_scene(
                        shader,
                        per_point,
                        self.surface,
                        (&tree.lights, lanes, whole),
                        (share, weight),
                        (&mut self.settled, &mut self.settled_error),
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
            && let (Some(share), Some(horizon)) = (self.coarse, self.horizon)
        {
            self.sum_asked_coarse(&tree.lights[range], horizon, share, weight);
            return;
        }
        let mut values = [DVec3::ZERO; CHUNK];
        for lights in tree.lights[range].chunks(CHUNK) {
            let values = &mut values[..lights.len()];
            self.shader
                .eval_lights(&self.per_point, self.surface, lights, values);
            if seen == Seen::Visible || V::ALWAYS_VISIBLE {
                for (light, value) in lights.iter().zip(values.iter()) {
                    self.settle_light(light.position, *value, seen, weight);
                }
            } else {
                self.settle_asked(lights, values, weight);
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
        self.lights += lights.len() as u32;
        let (asked, which, seen) = self.ask_together(lights, |k, _| values[k] != DVec3::ZERO);
        for (&k, &seen) in which[..asked].iter().zip(&seen[..asked]) {
            if seen {
                self.settled.add(values[usize::from(k)] * weight);
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
        self.point_queries += asked as u32;
        let mut seen = [false; ASK_MAX];
        self.visibility
            .visible_lights(self.point, &positions[..asked], &mut seen[..asked]);
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
        let (p, a) = (self.surface.point, horizon.as_dvec3());
        self.lights += lights.len() as u32;
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
    /// [`sum_visible`](Self::sum_visible). The caller counts the lights.
    #[inline(always)]
    fn sum_seen_coarse(&mut self, lights: &[PointLight], share: f64, weight: f64) {
        match self
            .shader
            .sum_lights_coarse(&self.per_point, self.surface, lights)
        {
            Some((sum, error)) if error.cmple(sum * share).all() => {
                self.settled.add(sum * weight);
                self.settled_error += error * weight;
            }
            _ => self.sum_visible(lights, weight),
        }
    }

    /// The sum of `lights`, known visible, times `weight`, settled: a
    /// chunk at a time, each chunk a plain sum of non-negative terms (see
    /// [`Shader::sum_lights`]). The caller counts the lights.
    #[inline(always)]
    fn sum_visible(&mut self, lights: &[PointLight], weight: f64) {
        let (shader, per_point, surface) = (self.shader, &self.per_point, self.surface);
        settle_visible(
            shader,
            per_point,
            surface,
            lights,
            weight,
            &mut self.settled,
        );
    }

    /// Refines node `index`: its lights exactly if it is a leaf, its
    /// children otherwise, each with blend weight `weight`; entries that
    /// stay in the cut are passed to `pending`.
    #[inline(always)]
    pub(crate) fn refine(
        &mut self,
        index: usize,
        visible: bool,
        weight: f64,
        pending: &mut impl Pending,
    ) {
        let tree = self.tree;
        let node = &tree.nodes[index];
        if node.is_leaf() {
            self.sum_lights(node.lights(), seen(visible || V::ALWAYS_VISIBLE), weight);
            return;
        }
        let known = visible || V::ALWAYS_VISIBLE;
        // Lights of children summed, not yet added: neighbouring
        // children's lights are neighbours in the tree's order, and are
        // summed together (up to a coarse sum's most), unless the lights
        // are added one at a time.
        let mut summing: Option<core::ops::Range<usize>> = None;
        // Children to bound, as bits (child `first_child + i` is bit `i`),
        // bounded together once all are known.
        let mut wanted = 0u8;
        for (i, child) in node.children().enumerate() {
            let c = &tree.nodes[child];
            if known && self.sums_exactly(c) {
                // Summing a few visible lights, or those of a near node,
                // costs less than bounding them (the budget counted them in
                // `can_refine`); a node that is exactly 0 needs neither.
                if self.unlit(child) {
                    continue;
                }
                let lights = c.lights();
                if self.one_by_one {
                    // In the children's order, as `exact_query` adds.
                    self.sum_lights(lights, Seen::Visible, weight);
                    continue;
                }
                // The lights start loading now; they are summed with their
                // neighbours' once the run ends.
                tree.prefetch_lights(&tree.lights[lights.clone()]);
                match &mut summing {
                    Some(run)
                        if run.end == lights.start
                            && lights.end - run.start <= COARSE_LIGHTS_MAX =>
                    {
                        run.end = lights.end;
                    }
                    _ => {
                        if let Some(run) = summing.replace(lights) {
                            self.sum_lights(run, Seen::Visible, weight);
                        }
                    }
                }
                continue;
            }
            match self.admit(child, visible, weight) {
                Admitted::Done(Some(entry)) => pending.pending(entry),
                Admitted::Done(None) => {}
                Admitted::ToBound => wanted |= 1 << i,
            }
        }
        if let Some(run) = summing {
            self.sum_lights(run, Seen::Visible, weight);
        }
        if wanted != 0 {
            self.bound_children(index, wanted, visible, weight, pending);
        }
    }

    /// Bounds the children of node `index` whose bits are set in `wanted`
    /// (already counted as evaluations): together and coarsely where the
    /// threshold allows and the shader can
    /// ([`Shader::bound_children_coarse`]), else under their cones, up to
    /// [`GROUP`] side by side ([`Shader::bound_nodes`]). Entries that stay
    /// in the cut are passed to `pending`.
    #[inline(always)]
    fn bound_children(
        &mut self,
        index: usize,
        wanted: u8,
        visible: bool,
        weight: f64,
        pending: &mut impl Pending,
    ) {
        let tree = self.tree;
        let first = tree.nodes[index].first_child as usize;
        let lanes = (0..GROUP).filter(|i| wanted & (1 << i) != 0);
        if self.coarse.is_some() && self.nodes <= COARSE_NODES_MAX {
            let mut bounds = [None; GROUP];
            if self.shader.bound_children_coarse(
                &self.per_point,
                self.surface,
                tree,
                index,
                wanted,
                &mut bounds,
            ) {
                for i in lanes {
                    let entry = match &bounds[i] {
                        Some(bound) => self.bounded(first + i, visible, weight, bound),
                        None => Some(self.unbounded(first + i, visible)),
                    };
                    if let Some(entry) = entry {
                        pending.pending(entry);
                    }
                }
                return;
            }
        }
        for i in lanes {
            let child = first + i;
            match tree.nodes[child].cone(self.surface.point) {
                Some(cone) => self.group.push(child as u32, cone),
                None => pending.pending(self.unbounded(child, visible)),
            }
        }
        self.bound_group(visible, weight, pending);
    }

    /// Bounds the nodes waiting in `self.group` together
    /// ([`Shader::bound_nodes`]) and empties it; entries that stay in the
    /// cut are passed to `pending`.
    #[inline(always)]
    fn bound_group(&mut self, visible: bool, weight: f64, pending: &mut impl Pending) {
        let len = self.group.len;
        if len == 0 {
            return;
        }
        let (tree, group) = (self.tree, &mut self.group);
        let nodes: [&Node; GROUP] = crate::lanes::array(&tree.nodes[0], |i| {
            &tree.nodes[group.indices[i.min(len - 1)] as usize]
        });
        self.shader.bound_nodes(
            &self.per_point,
            self.surface,
            &nodes[..len],
            &group.cones[..len],
            &mut group.bounds[..len],
        );
        group.len = 0;
        for i in 0..len {
            let (index, bound) = (self.group.indices[i], self.group.bounds[i]);
            if let Some(entry) = self.bounded(index as usize, visible, weight, &bound) {
                pending.pending(entry);
            }
        }
    }
}

/// The share of its sum a coarse sum's error may be for the sum to be kept
/// (`1/32` of a relative target of at least [`COARSE_TARGET_MIN`], without
/// interpolation), or `None` where the cut does not sum coarsely.
#[inline(always)]
fn coarse_share(threshold: &Threshold) -> Option<f64> {
    match threshold.target() {
        Target::Relative(t)
            if threshold.interpolation().is_none() && t >= COARSE_TARGET_MIN && t.is_finite() =>
        {
            Some(t / 32.0)
        }
        _ => None,
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
        settled.add(shader.sum_lights(per_point, surface, lights) * weight);
    }
}

/// The shader's [`Shader::sum_scene_coarse`] of a whole small scene,
/// `lights` side by side in `lanes`, where its error is at most `share` of
/// the sum channel by channel (what [`settle_small_scene`] takes first).
#[inline(always)]
fn whole_scene_sum<S: Shader>(
    shader: &S,
    per_point: &S::PerPoint,
    surface: &Surface,
    lanes: &[LightLanes],
    lights: &[PointLight],
    share: f64,
) -> Option<(DVec3, DVec3)> {
    shader
        .sum_scene_coarse(per_point, surface, lanes, lights.len())
        .filter(|(sum, error)| error.cmple(*sum * share).all())
}

/// The sum of a whole small scene, `lights` and the same lights side by
/// side in `lanes`, visible, times `weight`, settled into `settled` and its
/// error into `error_sum`: `whole`, the scene's [`whole_scene_sum`], where
/// it was kept; else [`COARSE_LIGHTS_MAX`] lights at a time: the shader's
/// [`Shader::sum_lanes_coarse`] where it has one, else its
/// [`Shader::sum_lights_coarse`], kept where the sum's error is at most
/// `share` of it channel by channel (as [`Cut::sum_seen_coarse`]); else
/// [`settle_visible`].
#[inline(always)]
fn settle_small_scene<S: Shader>(
    shader: &S,
    per_point: &S::PerPoint,
    surface: &Surface,
    (lights, lanes, whole): (&[PointLight], &[LightLanes], Option<(DVec3, DVec3)>),
    (share, weight): (f64, f64),
    (settled, error_sum): (&mut CompensatedSum, &mut DVec3),
) {
    if let Some((sum, error)) = whole {
        settled.add(sum * weight);
        *error_sum += error * weight;
        return;
    }
    // Lights `start..` and their lanes from `start / 8` (a multiple of
    // eight): an index rather than zipped chunks, whose lengths take
    // divisions.
    let mut start = 0;
    while start < lights.len() && start / 8 < lanes.len() {
        let end = (start + COARSE_LIGHTS_MAX).min(lights.len());
        let first = start / 8;
        let lanes = &lanes[first..(first + COARSE_LIGHTS_MAX / 8).min(lanes.len())];
        let lights = &lights[start..end];
        start = end;
        let sum = shader
            .sum_lanes_coarse(per_point, surface, lanes, lights.len())
            .or_else(|| shader.sum_lights_coarse(per_point, surface, lights));
        match sum {
            Some((sum, error)) if error.cmple(sum * share).all() => {
                settled.add(sum * weight);
                *error_sum += error * weight;
            }
            _ => settle_visible(shader, per_point, surface, lights, weight, settled),
        }
    }
}

/// Whether a small scene (its lights side by side in `lanes`) is summed
/// whole wherever the point lies, once known visible: at most
/// [`TINY_SCENE_LIGHTS`] lights (one coarse sum of the scene, which costs
/// less than bounding the root), and no plane recorded at the root. The
/// one rule for [`shade_small_scene`] and [`Cut::sums_tiny_scene`].
#[inline(always)]
fn tiny_scene(tree: &LightTree, lanes: &[LightLanes]) -> bool {
    !lanes.is_empty()
        && tree
            .nodes
            .first()
            .is_some_and(|root| root.light_count as usize <= TINY_SCENE_LIGHTS)
        && tree.node_plane(0).is_none()
}

/// Scenes summed whole wherever the point lies ([`tiny_scene`]). Measured
/// with lights in a 10 x 10 x 1 box 5 units above the ground and points on
/// the ground up to 500 units away (the mean of 20,000 passes over 128
/// points, one core, certified 1%): the sum of 128, 192 and 256 lights
/// took 0.15, 0.22 and 0.25 us per point, the cut of 129, 192 and 256
/// lights, whose root alone met the target, 0.26, 0.27 and 0.24.
const TINY_SCENE_LIGHTS: usize = 192;

/// The cut of a small scene whose lights are known visible (`lanes` side
/// by side, see [`Cut::sums_whole_scene`]), summed without setting up the
/// cut, or `None` where the caller runs the cut:
///
/// * when the shading point lies in the root's ball, which has then no
///   bound: the cut would count the root, find it unbounded and sum the
///   whole scene. This is that sum, so the same bits and counts.
/// * for a scene of at most [`TINY_SCENE_LIGHTS`] lights ([`tiny_scene`]),
///   wherever the point lies: where the cut would bound the root first,
///   setting it up costs more than the sum. The root is counted as
///   evaluated, and a host's cut that is told the root is visible sums the
///   scene the same way ([`Cut::sums_tiny_scene`]), so that it gets these
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
    // What `settle_small_scene` leaves in empty sums: where the whole
    // scene's sum is kept, the sum itself (a compensated sum of one term
    // from zero is the term) and its error.
    let (settled, settled_error) =
        match whole_scene_sum(shader, &per_point, surface, lanes, &tree.lights, share) {
            Some(sum) => sum,
            None => {
                let (mut settled, mut error) = (CompensatedSum::default(), DVec3::ZERO);
                settle_small_scene(
                    shader,
                    &per_point,
                    surface,
                    (&tree.lights, lanes, None),
                    (share, 1.0),
                    (&mut settled, &mut error),
                );
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

/// Node evaluations after which a cut bounds children in `f64` only
/// ([`Shader::bound_children_coarse`] no longer). The single-precision
/// bounds carry a rounding allowance of a few dozen `f32` ulps of `I kd /
/// D^2`, while a node seen at a grazing angle (the lights of a whole city
/// from a point on the ground beyond its edge) is worth the cosine of that
/// angle times as much: there the allowance can stay above a relative
/// target until the nodes are very small, and the cut would refine far
/// deeper than the `f64` bounds need. Ordinary cuts stop long before this
/// many evaluations (about 50 to 150 nodes on the street city at 10^4 to
/// 10^6 lights at a certified 1%); the entries already bounded keep their
/// certified coarse intervals.
pub(crate) const COARSE_NODES_MAX: u32 = 512;

/// The most children bounded together: an octree's.
const GROUP: usize = 8;

/// Children of a node waiting to be bounded together.
struct Group {
    len: usize,
    indices: [u32; GROUP],
    cones: [Cone; GROUP],
    /// Their bounds, once bounded.
    bounds: [NodeEstimate; GROUP],
}

impl Default for Group {
    #[inline(always)]
    fn default() -> Self {
        const NONE: Cone = Cone {
            offset: DVec3::ZERO,
            distance: 0.0,
            inv_distance: 0.0,
            axis: DVec3::ZERO,
            radius: 0.0,
            sin_half_angle: 0.0,
            cos_half_angle: 0.0,
        };
        Self {
            len: 0,
            indices: [0; GROUP],
            cones: [NONE; GROUP],
            bounds: [NodeEstimate::ZERO; GROUP],
        }
    }
}

impl Group {
    #[inline(always)]
    fn push(&mut self, index: u32, cone: Cone) {
        self.indices[self.len] = index;
        self.cones[self.len] = cone;
        self.len += 1;
    }
}

/// What [`Cut::admit`] makes of a node entering the cut.
enum Admitted {
    /// Settled, or an entry that needs no bound (`None`: nothing to keep).
    Done(Option<Entry>),
    /// To be bounded.
    ToBound,
}

/// What [`Cut::enter`] makes of a node entering the cut.
enum Entering {
    /// Settled, or an entry that needs no bound (`None`: nothing to keep).
    Done(Option<Entry>),
    /// To be bounded under this cone.
    Bound(Cone),
}

/// How a node entering the cut is seen, from whether it is known visible.
#[inline(always)]
fn seen(known_visible: bool) -> Seen {
    if known_visible {
        Seen::Visible
    } else {
        Seen::Unknown
    }
}

/// Where [`Cut::refine`] puts the entries that stay in the cut: the error
/// list itself (pushed in place, inlined into each compiled copy of the
/// cut), or a closure.
pub(crate) trait Pending {
    fn pending(&mut self, entry: Entry);
}

impl Pending for ErrorList {
    #[inline(always)]
    fn pending(&mut self, entry: Entry) {
        self.push(entry);
    }
}

impl<F: FnMut(Entry)> Pending for F {
    #[inline(always)]
    fn pending(&mut self, entry: Entry) {
        self(entry);
    }
}

/// Nodes of at most this many lights, known visible, are summed light by
/// light when they enter the cut instead of bounded (without interpolation
/// across levels, whose blend needs the bounded nodes to ramp through): a
/// node bound costs about as much as summing a few tens of lights, and an
/// exact sum leaves no error to refine later. Measured on the street city
/// at a certified 1%, one point at a time: against bounding every node,
/// summing nodes of at most 16 lights was 1.5x faster per point at 100 and
/// 1,000 lights, 1.3x at 10^4 and 1.15x at 10^6; once the lights were
/// summed four at a time in vector registers, 32 took 13.5 us per point at
/// 10^5 lights against 15.7 with 16, 18.7 against 20.6 at 10^6, and the
/// same within noise at 10^4 (8.5-8.7 us; medians of 9 alternating scratch
/// runs; 48 and 64 did as well as 32, 128 worse).
pub(crate) const EXACT_NODE_LIGHTS: u32 = 32;

/// Nodes of at most this many lights, known visible, are also summed light
/// by light when they are near the shading point for their size: `n D^2 <=`
/// [`NEAR_NODE_REACH`]` R^2`, `n` the node's lights, `D` the distance from
/// the point to its centroid and `R` its radius (without interpolation
/// across levels, as [`EXACT_NODE_LIGHTS`], nor under a budget, which one
/// such sum could spend at once). A certified cut takes a near node down
/// to its lights anyway: summing it at once skips the bounds and the steps
/// on the way down. The reach shrinks as the lights grow in number (a node
/// of 64 lights within `2.8 R`, of 512 within `R`), as the larger the
/// node, the nearer it must be for the cut to need all of its lights.
///
/// Measured on the street city at a certified 1%, one point at a time
/// (callgrind instructions of the cut, and alternating timed passes):
/// 0.77x the instructions at 10^3 and 10^4 lights, 0.88x at 10^5 and 0.89x
/// at 10^6; among 64, 128, 256 and 512 lights and reaches of 4 to 2,048
/// (and a plain distance test, `D <= 4 R` up to 64 lights), 512 and 512
/// gave the fewest instructions at 10^3 to 10^5. A glossy scene's cut
/// (string lights, Phong exponent 100) was unchanged.
const NEAR_NODE_LIGHTS: u32 = 512;

/// See [`NEAR_NODE_LIGHTS`].
const NEAR_NODE_REACH: f64 = 512.0;

/// Partial answers for small nodes before the cut may judge classification
/// useless (see [`Cut::gave_up_classifying`]).
const GIVE_UP_AFTER: u32 = 32;
/// Fewer useful (visible or occluded) answers than one per this many partial
/// answers for small nodes and the cut stops asking.
const GIVE_UP_RATIO: u32 = 8;
/// Nodes of at most this many lights are small: after a partial answer for
/// one, its few lights are soon asked one by one, so the classification did
/// not pay.
const SMALL_NODE_LIGHTS: u32 = 16;

/// Most lights asked about in one call of [`Visibility::visible_lights`]:
/// where coarse sums are used, a whole leaf of the default builder (at
/// most 32 lights); elsewhere the lights of one exact evaluation, at most
/// [`SUM_LIGHTS_MAX`].
const ASK_MAX: usize = 32;

/// Whether a cut of summed `(estimate, error)` meets the threshold, with
/// the error bound exactly as it will be reported.
#[inline]
fn met((estimate, error): (DVec3, DVec3), largest: f64, threshold: &Threshold) -> bool {
    threshold.met(estimate, reported_bound(error), largest)
}

/// The certified bound reported for a summed error: the error list's sums
/// carry their own rounding bound ([`ErrorList::resum`]) and the settled
/// compensated sum is within a few ulps of its magnitude, which the rounding
/// allowance of the exact value covers (its terms are non-negative); the
/// rounding of the last additions (settled plus waiting, estimate plus
/// error) is folded in here.
#[inline]
pub(crate) fn reported_bound(error: DVec3) -> DVec3 {
    error * (1.0 + SUM_SLACK)
}

/// What the host is told about node `index`.
pub(crate) fn region(node: &Node, index: usize) -> NodeRegion {
    NodeRegion {
        index: index as u32,
        aabb: node.aabb,
        centroid: node.centroid,
        radius: node.radius,
        light_count: node.light_count,
    }
}
