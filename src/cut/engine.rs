//! The engine: the error list's loop and the refinement of a node, for any
//! [`Region`].

use glam::{DVec3, Vec3};

use super::error_list::{Class, Entry, ErrorList, Seen};
use super::interpolate::{NO_PARENT, Nesting};
use super::policy::{GIVE_UP_AFTER, GIVE_UP_RATIO, SMALL_NODE_LIGHTS};
use super::result::Stop;
use super::threshold::Threshold;
use crate::shader::Shader;
use crate::tree::{LightTree, Node};
use crate::visibility::{Coverage, NodeRegion, Visibility};

/// Where a cut's bounds must hold, and what it does with what it settles:
/// one shading point ([`Point`](super::point::Point)) or every point of a
/// group ([`Shared`](super::group::Shared)). The engine ([`Cut`]) calls these for what
/// depends on it; everything else (the list, refinement, admission of
/// dark, coplanar and single-light nodes, visibility, budgets,
/// interpolation) is the engine's.
pub(crate) trait Region<S: Shader>: Sized {
    /// Whether the lights of plane `plane` lie at or below the tangent
    /// plane of every point, so that a node of that plane is exactly 0.
    fn below_horizon<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, plane: u32) -> bool;

    /// Whether a visible node is summed light by light when it enters the
    /// cut instead of bounded.
    /// `node` is node `index` of the tree.
    fn sums_exactly<V: Visibility>(cut: &Cut<'_, S, V, Self>, index: usize, node: &Node) -> bool;

    /// A single light (or coincident lights) entering the cut, times
    /// `weight`; `leaf` is its node, for the host.
    fn light<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        leaf: usize,
        position: Vec3,
        intensity: DVec3,
        seen: Seen,
        weight: f64,
    );

    /// The lights of `range` (leaf order, those of node `leaf` or of
    /// neighbouring small children of one node), times `weight`.
    fn lights<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        leaf: usize,
        range: core::ops::Range<usize>,
        seen: Seen,
        weight: f64,
    );

    /// Node `index` entering the cut, already admitted (lit, neither a
    /// single light nor below the horizon) and counted: its entry, or
    /// `None` when it was settled or dropped.
    fn enter<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        index: usize,
        visible: bool,
        weight: f64,
    ) -> Option<Entry>;

    /// Bounds the children of node `parent` whose bits are set in `wanted`
    /// (admitted and counted), passing their entries to `pending`.
    fn bound_children<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        parent: usize,
        wanted: u8,
        visible: bool,
        weight: f64,
        pending: &mut impl Pending,
    );

    /// The cut's running `(estimate, error)`: what the threshold is
    /// measured against while the list runs.
    fn sums<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, list: &mut ErrorList) -> (DVec3, DVec3);

    /// The same summed exactly, to confirm a stop: the error as it will be
    /// reported.
    fn confirmed<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        list: &mut ErrorList,
    ) -> (DVec3, DVec3);

    /// Whether refining `node` (known visible if `visible`) fits in what
    /// the cut may spend.
    fn affordable<V: Visibility>(
        cut: &Cut<'_, S, V, Self>,
        list: &ErrorList,
        node: &Node,
        visible: bool,
    ) -> bool;

    /// The entry of slot `slot` was taken from the list.
    fn taken<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, slot: u32);

    /// Whether the whole scene is summed now, its root known visible and
    /// taken by the list (a small scene, where summing costs less than
    /// cutting); `nested` when the cut interpolates.
    fn sums_whole_scene<V: Visibility>(cut: &Cut<'_, S, V, Self>, nested: bool) -> bool;

    /// Whether the cut stops bounding and sums the lights of every entry
    /// left in the list (its work has passed a share of what summing the
    /// scene would cost); `nested` when the cut interpolates.
    fn sums_the_rest<V: Visibility>(cut: &Cut<'_, S, V, Self>, nested: bool) -> bool;

    /// The host answered "visible" for the root: `true` when the region
    /// summed the whole scene at once (a tiny scene; the root's entry then
    /// drops out).
    fn summed_on_visible_root<V: Visibility>(cut: &mut Cut<'_, S, V, Self>) -> bool;

    /// Whether the lights of neighbouring children summed on entry are
    /// summed together in runs (rather than child by child, in the order
    /// of the exact sum).
    fn sums_in_runs<V: Visibility>(cut: &Cut<'_, S, V, Self>) -> bool;

    /// Adds an exact value (an entry whose bound has no width) to what the
    /// cut has settled.
    fn settle<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, value: DVec3);

    /// The point the host is asked about for one point's classifications
    /// and rays.
    fn host_point<V: Visibility>(cut: &Cut<'_, S, V, Self>) -> Vec3;

    /// Runs `f` (a refinement or a classification under frame `frame` of
    /// `nesting`), recording what it settled under that frame.
    fn nested<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        nesting: &mut Nesting,
        frame: u32,
        f: impl FnOnce(&mut Cut<'_, S, V, Self>, &mut Nesting),
    );

    /// Records what the root's entry settled, outside any frame of
    /// `nesting`.
    fn settled_outside<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, nesting: &mut Nesting);
}

/// One cut's state: what it reads (tree, shader), the host it asks, the
/// region it holds for, what the threshold allows and what it has spent.
pub(crate) struct Cut<'a, S: Shader, V, R> {
    pub(crate) tree: &'a LightTree,
    pub(crate) shader: &'a S,
    pub(crate) visibility: V,
    pub(crate) region: R,
    /// The specular criterion: nodes whose upper bound exceeds it are
    /// refined whatever their error.
    pub(crate) max_contribution: Option<f64>,
    /// Evaluations allowed (`u32::MAX`: no budget).
    pub(crate) budget: u32,
    pub(crate) work: Work,
}

/// What a cut has spent.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Work {
    /// Nodes bounded (or settled by a test that needs no bound).
    pub(crate) nodes: u32,
    /// Lights evaluated exactly.
    pub(crate) lights: u32,
    /// Classifications asked of the host.
    pub(crate) classify_queries: u32,
    /// Point-to-point visibility queries.
    pub(crate) point_queries: u32,
    /// Classifications answered visible or occluded.
    decisive_answers: u32,
    /// Classifications of nodes of at most [`SMALL_NODE_LIGHTS`] lights
    /// answered partial.
    small_partials: u32,
}

impl Work {
    /// Evaluations so far, in the units of the budget.
    #[inline]
    pub(crate) fn cost(&self) -> u32 {
        self.nodes.saturating_add(self.lights)
    }
}

/// How the error list's loop ended.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Outcome {
    pub(crate) stop: Stop,
    /// The excess over the target before, and the key of, the last
    /// refinement: they place the interpolation level between the last two
    /// steps (`None` for a threshold that does not interpolate).
    pub(crate) last_step: Option<(f64, f64)>,
    /// The excess over the target where the loop stopped (`-inf` when the
    /// list ran empty).
    pub(crate) after: f64,
    /// With nesting, the certified sums that confirmed the stop, if the
    /// threshold stopped the loop.
    pub(crate) confirmed: Option<(DVec3, DVec3)>,
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

/// What [`Cut::admit`] makes of a node entering the cut.
pub(crate) enum Admitted {
    /// Settled, or dropped (dark, below the horizon, a single light).
    Done,
    /// Counted, to be bounded.
    ToBound,
}

/// How a node entering the cut is seen, from whether it is known visible.
#[inline(always)]
pub(crate) fn seen(known_visible: bool) -> Seen {
    if known_visible {
        Seen::Visible
    } else {
        Seen::Unknown
    }
}

impl<'a, S: Shader, V: Visibility, R: Region<S>> Cut<'a, S, V, R> {
    /// A cut over `tree` for `region`, with what `threshold` allows.
    #[inline(always)]
    pub(crate) fn new(
        tree: &'a LightTree,
        shader: &'a S,
        region: R,
        threshold: &Threshold,
        visibility: V,
    ) -> Self {
        Self {
            tree,
            shader,
            visibility,
            region,
            max_contribution: threshold.max_contribution(),
            budget: threshold.budget().unwrap_or(u32::MAX).max(1),
            work: Work::default(),
        }
    }

    /// Whether the node is known visible: from its entry, or because the
    /// host sees everything.
    #[inline(always)]
    pub(crate) fn known(visible: bool) -> bool {
        visible || V::ALWAYS_VISIBLE
    }

    /// The paper's error list: starting from the root, takes the entry of
    /// greatest (class, error) while the threshold is not met and the
    /// budget allows. A node is refined (its children or lights replace
    /// it); an entry whose visibility is unknown is first asked about, and
    /// the answer decides: occluded entries drop out, visible ones go back
    /// with their unoccluded interval, partial ones are refined.
    ///
    /// `margin` scales the estimate the threshold is measured against (1
    /// for a point; a group aims below its darkest sample). With `nesting`
    /// (interpolation across levels for a point), priorities are capped at
    /// the parent's and the refined part of the cut is recorded for the
    /// blend (see [`interpolate`](super::interpolate)). Inlined into each
    /// compiled copy of the shading call.
    #[inline(always)]
    pub(crate) fn run(
        &mut self,
        list: &mut ErrorList,
        threshold: &Threshold,
        mut nesting: Option<&mut Nesting>,
    ) -> Outcome {
        let mut outcome = Outcome {
            stop: Stop::ThresholdMet,
            last_step: None,
            after: f64::NEG_INFINITY,
            confirmed: None,
        };
        let interpolating = threshold.interpolation().is_some();
        loop {
            let largest = list.largest();
            // The cut's sums: the region's, or with nesting each refined
            // node's interval intersected with its children's.
            let sums = match nesting.as_deref() {
                Some(n) => n.totals(),
                None => R::sums(self, list),
            };
            let may_stop = list.may_stop();
            // The excess over the target: whether the list may stop, and
            // where an interpolation level lies.
            let before = if may_stop || interpolating {
                threshold.excess(sums.0, super::reported_bound(sums.1), largest)
            } else {
                f64::INFINITY
            };
            if may_stop && before <= 0.0 {
                // Confirm with exact sums: the running ones drift.
                let sums = match nesting.as_deref_mut() {
                    Some(n) => n.fold(list),
                    None => R::confirmed(self, list),
                };
                let after = threshold.excess(sums.0, sums.1, largest);
                if after <= 0.0 {
                    outcome.confirmed = nesting.is_some().then_some(sums);
                    outcome.after = after;
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
                && R::sums_whole_scene(self, nesting.is_some())
            {
                // A small scene known visible whose root alone does not
                // meet the threshold: summed light by light, which costs
                // less than cutting it.
                list.pop_slot();
                R::lights(self, 0, node.lights(), Seen::Visible, 1.0);
                continue;
            }
            if refining && R::sums_the_rest(self, nesting.is_some()) {
                // The bounds settle too little here: what is left is summed
                // light by light, each entry's lights once.
                while let Some((entry, slot)) = list.pop_slot() {
                    R::taken(self, slot);
                    let node = &tree.nodes[entry.node as usize];
                    R::lights(self, entry.node as usize, node.lights(), entry.seen, 1.0);
                }
                continue;
            }
            if refining && !R::affordable(self, list, node, top.seen == Seen::Visible) {
                outcome.stop = Stop::Budget;
                break;
            }
            if refining && interpolating {
                // Only refinements place the interpolation level (which only
                // an interpolating threshold reads); asking the host changes
                // what an entry counts for, not the level.
                outcome.last_step = Some((before, top.key));
            }
            let Some((_, slot)) = list.pop_slot() else {
                break;
            };
            R::taken(self, slot);
            if refining {
                // The next node to refine is probably the one waiting on top
                // now: its children load while this one's are evaluated.
                if let Some(next) = list.peek() {
                    self.tree.prefetch_refinement(next.node as usize);
                }
                self.refine_taken(list, nesting.as_deref_mut(), top, slot);
            } else {
                self.classify_taken(list, nesting.as_deref_mut(), top, slot);
            }
        }
        outcome
    }

    /// Refines `top`, just taken from slot `slot` of the list: its
    /// children (or lights) enter the cut. With `nesting` they are recorded
    /// under a new frame, their priorities capped at `top`'s.
    #[inline(always)]
    fn refine_taken(
        &mut self,
        list: &mut ErrorList,
        nesting: Option<&mut Nesting>,
        top: Entry,
        slot: u32,
    ) {
        let visible = top.seen == Seen::Visible;
        let Some(n) = nesting else {
            self.refine(top.node as usize, visible, 1.0, list);
            return;
        };
        let parent = n.taken(&top, slot);
        let near = super::interpolate::near(&self.tree.nodes[top.node as usize], n.point);
        let frame = n.refined(&top, parent, near);
        R::nested(self, n, frame, |cut, n| {
            cut.refine(top.node as usize, visible, 1.0, &mut |mut e: Entry| {
                e.key = e.key.min(top.key);
                list.push(e);
                n.pushed(&e, frame);
            });
        });
        // Both running sums changed: the parent's lost `top` and the new
        // frame gained its children. Where the frame's interval comes out
        // as it started (a node whose children all settled to 0),
        // finishing it stops there, so the parent is finished too.
        n.finish(frame);
        n.finish(parent);
    }

    /// Asks the host about `top`, just taken from slot `slot` of the list,
    /// and puts it back as the answer says (see
    /// [`classify`](Self::classify)).
    #[inline(always)]
    fn classify_taken(
        &mut self,
        list: &mut ErrorList,
        nesting: Option<&mut Nesting>,
        top: Entry,
        slot: u32,
    ) {
        let node = &self.tree.nodes[top.node as usize];
        let Some(n) = nesting else {
            if let Some(e) = self.classify(node, top) {
                list.push(e);
            }
            return;
        };
        let parent = n.taken(&top, slot);
        let mut entry = None;
        R::nested(self, n, parent, |cut, _| entry = cut.classify(node, top));
        if let Some(mut e) = entry {
            e.key = e.key.min(top.key);
            list.push(e);
            n.pushed(&e, parent);
        }
        n.finish(parent);
    }

    /// The root entering the cut: `None` when it was settled or dropped.
    #[inline(always)]
    pub(crate) fn enter_root(&mut self, list: &mut ErrorList, nesting: Option<&mut Nesting>) {
        list.clear();
        let root = if self.tree.nodes.is_empty() {
            None
        } else {
            self.evaluate(0, V::ALWAYS_VISIBLE, 1.0)
        };
        if let Some(n) = nesting {
            n.clear();
            if let Some(root) = root {
                list.push(root);
                n.pushed(&root, NO_PARENT);
            }
            R::settled_outside(self, n);
        } else if let Some(root) = root {
            list.push(root);
        }
    }

    /// Whether the host's classifications have been useless so far in this
    /// cut, so that partial nodes are refined without asking and single
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
        self.work.small_partials >= GIVE_UP_AFTER
            && self.work.decisive_answers * GIVE_UP_RATIO < self.work.small_partials
    }

    /// Records a classification's answer for node `node` (for
    /// [`gave_up_classifying`](Self::gave_up_classifying)).
    #[inline(always)]
    pub(crate) fn answered(&mut self, node: &Node, answer: Coverage) {
        self.work.classify_queries += 1;
        match answer {
            Coverage::Visible | Coverage::Occluded => self.work.decisive_answers += 1,
            Coverage::Partial => {
                if node.light_count <= SMALL_NODE_LIGHTS {
                    self.work.small_partials += 1;
                }
            }
        }
    }

    /// Asks the host about a node of unknown visibility taken from the
    /// list: `None` when it is occluded (it drops out of the cut), else the
    /// entry to put back: visible, with its unoccluded interval; partial,
    /// estimated at the host's visible fraction if it gives one, and refined
    /// when the cut takes it again.
    fn classify(&mut self, node: &Node, top: Entry) -> Option<Entry> {
        let region = node_region(node, top.node as usize);
        let point = R::host_point(self);
        let answer = self.visibility.classify(point, &region);
        self.answered(node, answer);
        let seen = match answer {
            Coverage::Occluded => return None,
            Coverage::Visible => {
                if top.node == 0 && R::summed_on_visible_root(self) {
                    return None;
                }
                Seen::Visible
            }
            Coverage::Partial => Seen::Partial(
                self.visibility
                    .visible_fraction(point, &region)
                    .filter(|f| f.is_finite())
                    .map(|f| f.clamp(0.0, 1.0)),
            ),
        };
        let e = Entry::new(top.class, top.node, seen, top.estimate, top.error);
        if e.key <= 0.0 && e.class == Class::Error {
            R::settle(self, e.counted().0);
            return None;
        }
        Some(e)
    }

    /// Evaluates node `index` entering the cut with blend weight `weight`:
    /// settles it (dark nodes, error-free nodes, single lights; times
    /// `weight`), or returns it as an entry (not weighted).
    #[inline(always)]
    pub(crate) fn evaluate(&mut self, index: usize, visible: bool, weight: f64) -> Option<Entry> {
        match self.admit(index, visible, weight) {
            Admitted::Done => None,
            Admitted::ToBound => R::enter(self, index, visible, weight),
        }
    }

    /// What needs no bound of node `index` entering the cut: dark nodes,
    /// nodes wholly below the horizon, single (or coincident) lights are
    /// settled or dropped; the rest is counted as a node evaluation and
    /// left to be bounded.
    #[inline(always)]
    pub(crate) fn admit(&mut self, index: usize, visible: bool, weight: f64) -> Admitted {
        if self.unlit(index) {
            return Admitted::Done;
        }
        let node: &Node = &self.tree.nodes[index];
        if node.radius == 0.0 {
            // A single light, or coincident lights (the build makes them one
            // leaf): exactly one light of the summed intensity at the
            // centroid, whatever their number; coincident emitters, whose
            // profiles may differ, one by one.
            let seen = seen(Self::known(visible));
            if self.tree.is_oriented() {
                R::lights(self, index, node.lights(), seen, weight);
            } else {
                R::light(self, index, node.centroid, node.intensity, seen, weight);
            }
            return Admitted::Done;
        }
        self.work.nodes += 1;
        Admitted::ToBound
    }

    /// Whether node `index` is exactly 0 whatever its geometry, so that it
    /// needs neither a bound nor a sum: a dark node (even when its ball
    /// holds a shading point; no query is needed), or one whose lights all
    /// lie at or below the tangent plane, where the shader's model is
    /// exactly 0 (counted as a node evaluation).
    #[inline(always)]
    pub(crate) fn unlit(&mut self, index: usize) -> bool {
        if self.tree.nodes[index].intensity == DVec3::ZERO {
            return true;
        }
        if let Some(plane) = self.tree.node_plane(index)
            && R::below_horizon(self, plane)
        {
            self.work.nodes += 1;
            return true;
        }
        false
    }

    /// Refines node `index`: its lights if it is a leaf, its children
    /// otherwise, each with blend weight `weight`; entries that stay in the
    /// cut are passed to `pending`.
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
        let known = Self::known(visible);
        if node.is_leaf() {
            R::lights(self, index, node.lights(), seen(known), weight);
            return;
        }
        // Lights of children summed, not yet added: neighbouring
        // children's lights are neighbours in the tree's order, and are
        // summed together (up to a coarse sum's most).
        let mut summing: Option<(usize, core::ops::Range<usize>)> = None;
        // Children to bound, as bits (child `first_child + i` is bit `i`),
        // bounded together once all are known.
        let mut wanted = 0u8;
        for (i, child) in node.children().enumerate() {
            let c = &tree.nodes[child];
            if known && R::sums_exactly(self, child, c) {
                // Summing a few visible lights, or those of a near node,
                // costs less than bounding them (the budget counted them);
                // a node that is exactly 0 needs neither.
                if self.unlit(child) {
                    continue;
                }
                let lights = c.lights();
                if !R::sums_in_runs(self) {
                    // In the children's order, as the exact sum adds.
                    R::lights(self, child, lights, Seen::Visible, weight);
                    continue;
                }
                // The lights start loading now; they are summed with their
                // neighbours' once the run ends.
                tree.prefetch_lights(&tree.lights[lights.clone()]);
                match &mut summing {
                    Some((_, run))
                        if run.end == lights.start
                            && lights.end - run.start <= super::policy::COARSE_LIGHTS_MAX =>
                    {
                        run.end = lights.end;
                    }
                    _ => {
                        if let Some((leaf, run)) = summing.replace((child, lights)) {
                            R::lights(self, leaf, run, Seen::Visible, weight);
                        }
                    }
                }
                continue;
            }
            if let Admitted::ToBound = self.admit(child, visible, weight) {
                wanted |= 1 << i;
            }
        }
        if let Some((leaf, run)) = summing {
            R::lights(self, leaf, run, Seen::Visible, weight);
        }
        if wanted != 0 {
            R::bound_children(self, index, wanted, visible, weight, pending);
        }
    }
}

/// What the host is told about node `index`.
pub(crate) fn node_region(node: &Node, index: usize) -> NodeRegion {
    NodeRegion {
        index: index as u32,
        aabb: node.aabb,
        centroid: node.centroid,
        radius: node.radius,
        light_count: node.light_count,
    }
}
