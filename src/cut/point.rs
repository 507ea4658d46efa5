//! The cut for one shading point: node entries are the shader's certified
//! intervals at the point, single lights are evaluated and summed at once,
//! and the host is asked about a node when the list takes it.

use core::cell::Cell;

use glam::{DVec3, Vec3};

use super::engine::{Cut, Outcome, Pending, Region, seen};
use super::error_list::{Class, Entry, ErrorList, Seen};
use super::interpolate::{self, Item, NO_PARENT, Nesting};
use super::policy::{
    COARSE_NODES_MAX, COARSE_SHARE_DIVISOR, COARSE_TARGET_MIN, EXACT_NODE_LIGHTS, NEAR_NODE_LIGHTS,
    NODE_WORK, REST_MIN_LIGHTS, REST_SHARE_DIVISOR, SMALL_SCENE_LIGHTS, SMALL_SCENE_LIGHTS_COARSE,
    is_near,
};
use super::result::{ShadeResult, Stop};
use super::threshold::{Target, Threshold};
use crate::LightLanes;
use crate::geometry::{Cone, Surface};
use crate::lambert::diffuse_lobe_bound;
use crate::numeric::{CompensatedSum, SUM_SLACK};
use crate::shader::{ChildrenOf, NodeEstimate, Seal, Shader};
use crate::tree::orientation::Factor;
use crate::tree::slabs::SLAB_MIN_LIGHTS;
use crate::tree::{LightTree, NO_PLANE, Node};
use crate::visibility::Visibility;

/// The region of one shading point: what the cut reads of it and what it
/// has settled there.
pub(crate) struct Point<'a, S: Shader> {
    pub(crate) surface: &'a Surface,
    pub(crate) per_point: S::PerPoint,
    /// The shading point as the host was given it.
    pub(crate) point: Vec3,
    /// Largest visible node summed light by light instead of bounded: 0
    /// with interpolation, whose blend ramps through bounded nodes.
    exact_lights: u32,
    /// Largest visible node summed light by light when near the point (see
    /// [`NEAR_NODE_LIGHTS`]): 0 with interpolation, or with a budget, which
    /// such a sum could spend at once.
    near_lights: u32,
    /// Whether visible lights are added one at a time to the compensated
    /// sum (a target of 0, see [`Threshold::zero`]) rather than a few at a
    /// time.
    pub(crate) one_by_one: bool,
    /// Whether node bounds are narrowed from the tree's slab moments
    /// ([`Shader::narrow_bound`]): where the shader does, but not with
    /// interpolation, whose blend needs estimates continuous in the point
    /// (the slab interval changes where a bin crosses the tangent plane).
    slabs: bool,
    /// The share of a coarse sum its error may be for the sum to be kept
    /// (`1/32` of a relative target), or `None` where coarse sums are not
    /// used; where they are, children are bounded coarsely too.
    pub(crate) coarse: Option<f64>,
    /// For a small scene, its lights side by side (see
    /// [`Point::sums_whole_scene`]); `None` for other trees.
    pub(crate) small_lanes: Option<&'a [LightLanes]>,
    /// Exact leaves and nodes that need no refinement.
    pub(crate) settled: CompensatedSum,
    /// The certified error of what was settled by coarse sums of lights.
    pub(crate) settled_error: DVec3,
    /// Coarse (`f32`) sums of lights not kept since the last one kept:
    /// from [`COARSE_MISSES_MAX`](super::policy::COARSE_MISSES_MAX) on,
    /// lights go to the plain `f64` sum first.
    pub(crate) coarse_misses: u32,
    /// The shader's [`horizon`](Shader::horizon) at this point.
    pub(crate) horizon: Option<Vec3>,
    /// The last plane asked about and whether it lies at or below the
    /// tangent plane (a coplanar node's descendants share its plane).
    dark_plane: (u32, bool),
    /// Children of the node being refined, waiting to be bounded together
    /// (kept here so that it is set up once per call, not per refinement).
    children: Children,
    /// What a tree of emitters keeps for this point (held apart, so that a
    /// tree of isotropic lights neither sets it up nor moves it); `None`
    /// for isotropic lights.
    emitters: Option<&'a EmitterScratch>,
}

/// What the cut of a point keeps for emitters, on the stack of the call
/// (in cells: the cut reads and notes factors where it holds its region
/// shared).
#[derive(Debug)]
pub(crate) struct EmitterScratch {
    /// The emission factors last computed for nodes (index and factor),
    /// slot `index % 8`: a node's children are contiguous, so those of one
    /// refinement each have their own slot; bounding a child right after
    /// deciding not to sum it reuses its factor.
    cache: [Cell<(u32, Factor)>; CHILDREN],
    /// The factors of the children waiting to be bounded together.
    children: [Cell<Factor>; CHILDREN],
    /// The shader's albedo where it is exactly diffuse (for
    /// [`diffuse_lobe_bound`]), else `None`; set for each point.
    diffuse: Cell<Option<DVec3>>,
}

impl Default for EmitterScratch {
    fn default() -> Self {
        Self {
            cache: core::array::from_fn(|_| Cell::new((u32::MAX, Factor::ONE))),
            children: core::array::from_fn(|_| Cell::new(Factor::ONE)),
            diffuse: Cell::new(None),
        }
    }
}

impl<S: Shader> Point<'_, S> {
    /// Node `index`'s bound at this point (seen under `cone`) for emitters
    /// whose profiles lie within `factor`, from the shader's isotropic
    /// bound `bound`: [`emitted`], intersected, for a diffuse shader and a
    /// node of diffuse virtual point lights about one axis, with the
    /// second-order expansion of their smooth terms
    /// ([`diffuse_lobe_bound`]).
    #[inline(always)]
    fn oriented(
        &self,
        tree: &LightTree,
        index: usize,
        cone: &Cone,
        bound: NodeEstimate,
        factor: Factor,
    ) -> NodeEstimate {
        let product = emitted(bound, factor);
        let Some(kd) = self.emitters.and_then(|e| e.diffuse.get()) else {
            return product;
        };
        let Some(axis) = tree.diffuse_lobe(index) else {
            return product;
        };
        let node = &tree.nodes[index];
        match diffuse_lobe_bound(node, self.surface, cone, axis, kd) {
            Some(t) => {
                let lower = product.lower.max(t.lower);
                let upper = product.upper.min(t.upper);
                if lower.cmple(upper).all() {
                    NodeEstimate::new(t.estimate, lower, upper)
                } else {
                    product
                }
            }
            None => product,
        }
    }

    /// Notes node `index`'s emission factor at this point.
    #[inline(always)]
    fn remember(&self, index: usize, factor: Factor) {
        if let Some(e) = self.emitters {
            e.cache[index % CHILDREN].set((index as u32, factor));
        }
    }

    /// Node `index`'s emission factor under `cone`, from the note if it is
    /// of that node.
    #[inline(always)]
    fn factor_of(&self, tree: &LightTree, index: usize, cone: &Cone) -> Factor {
        match self.emitters.map(|e| e.cache[index % CHILDREN].get()) {
            Some((i, f)) if i as usize == index => f,
            _ => tree.factor_at(index, self.surface.point, cone),
        }
    }
}

impl<'a, S: Shader> Point<'a, S> {
    /// The region of the point `point` (as the host was given it) with
    /// surface `surface`, for `threshold`; `emitters` (fresh) for a tree of
    /// emitters, else `None`.
    #[inline(always)]
    pub(crate) fn new(
        tree: &LightTree,
        shader: &S,
        surface: &'a Surface,
        point: Vec3,
        threshold: &Threshold,
        small_lanes: Option<&'a [LightLanes]>,
        emitters: Option<&'a EmitterScratch>,
    ) -> Self {
        let interpolating = threshold.interpolation().is_some();
        if let Some(e) = emitters {
            e.diffuse.set(shader.diffuse_albedo(Seal));
        }
        Self {
            surface,
            per_point: shader.prepare(surface),
            point,
            exact_lights: if interpolating { 0 } else { EXACT_NODE_LIGHTS },
            near_lights: if interpolating || threshold.budget().is_some() {
                0
            } else {
                NEAR_NODE_LIGHTS
            },
            one_by_one: threshold.is_zero(),
            slabs: !interpolating
                && shader.narrows_with_slabs(Seal)
                && slabs_may_apply(tree, surface),
            coarse: coarse_share(threshold),
            small_lanes,
            settled: CompensatedSum::default(),
            settled_error: DVec3::ZERO,
            coarse_misses: 0,
            horizon: shader.horizon(surface),
            dark_plane: (NO_PLANE, false),
            children: Children::default(),
            emitters,
        }
    }
}

/// Whether slab moments may narrow any node's bound for this point: the
/// tree has some, the tangent plane runs through the root's box (else it
/// runs through no node's), and the normal is not perpendicular to every
/// axis the bins slice (else no bin lies wholly above or below the plane).
fn slabs_may_apply(tree: &LightTree, surface: &Surface) -> bool {
    let slabs = &tree.slabs;
    let Some(root) = tree.nodes.first() else {
        return false;
    };
    let n = surface.normal;
    let across = (0..3).any(|a| slabs.axes & (1 << a) != 0 && n[a] != 0.0);
    across && box_may_be_cut(n.as_vec3(), surface.point.as_vec3(), root)
}

/// Whether the plane through `point` with normal `n` may run through
/// `node`'s box, judged in `f32` with a margin (a node wrongly judged uncut
/// only keeps its bound; [`Shader::narrow_bound`] decides in `f64`).
#[inline(always)]
fn box_may_be_cut(n: Vec3, point: Vec3, node: &Node) -> bool {
    let (lo, hi) = (node.aabb.min, node.aabb.max);
    let offset = (lo + hi) * 0.5 - point;
    let half = (hi - lo) * 0.5;
    let middle = n.dot(offset);
    let reach = n.abs().dot(half);
    let margin = 1e-5 * (offset.abs().max_element() + half.max_element());
    middle.abs() <= reach + margin
}

impl<S: Shader> Point<'_, S> {
    /// Whether the tangent plane may run through `node`'s box, judged in
    /// `f32` with a margin (a node wrongly judged uncut only keeps its
    /// bound; [`Shader::narrow_bound`] decides in `f64`).
    #[inline(always)]
    fn may_cut(&self, node: &Node) -> bool {
        box_may_be_cut(self.surface.normal.as_vec3(), self.point, node)
    }
}

/// The share of its sum a coarse sum's error may be for the sum to be kept
/// (`1/32` of a relative target of at least [`COARSE_TARGET_MIN`], without
/// interpolation), or `None` where the cut does not sum coarsely.
#[inline(always)]
pub(crate) fn coarse_share(threshold: &Threshold) -> Option<f64> {
    match threshold.target() {
        Target::Relative(t)
            if threshold.interpolation().is_none() && t >= COARSE_TARGET_MIN && t.is_finite() =>
        {
            Some(t / COARSE_SHARE_DIVISOR)
        }
        _ => None,
    }
}

impl<'a, S: Shader> Region<S> for Point<'a, S> {
    #[inline(always)]
    fn below_horizon<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, plane: u32) -> bool {
        let Some(normal) = cut.region.horizon else {
            return false;
        };
        if cut.region.dark_plane.0 != plane {
            let dark = cut
                .tree
                .plane_at_or_below(plane, cut.region.surface.point, normal);
            cut.region.dark_plane = (plane, dark);
        }
        cut.region.dark_plane.1
    }

    /// A small node (see [`EXACT_NODE_LIGHTS`]), or one near the shading
    /// point for its size and number of lights (see [`NEAR_NODE_LIGHTS`]).
    ///
    /// Emitters whose profiles may be 0 at the point are tested first: a
    /// node certified dark is left to the bound (which drops it at the
    /// cost of one evaluation rather than a test of each light), and a
    /// near node is summed whole only where every member's profile is 1
    /// at the point, as an isotropic node's would be.
    #[inline(always)]
    fn sums_exactly<V: Visibility>(cut: &Cut<'_, S, V, Self>, index: usize, node: &Node) -> bool {
        if node.radius == 0.0 {
            return false;
        }
        let region = &cut.region;
        let small = node.light_count <= region.exact_lights;
        let near = || {
            node.light_count <= region.near_lights
                && is_near(
                    node,
                    (node.centroid.as_dvec3() - region.surface.point).length_squared(),
                )
        };
        if !cut.tree.is_oriented() {
            return small || near();
        }
        if !small && node.light_count > region.near_lights {
            return false;
        }
        let factor = node.cone(region.surface.point).map(|cone| {
            let f = cut.tree.factor_at(index, region.surface.point, &cone);
            region.remember(index, f);
            f
        });
        match factor {
            Some(f) if f.upper == 0.0 => false,
            Some(f) if f.lower < 1.0 => small,
            _ => small || near(),
        }
    }

    #[inline(always)]
    fn light<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        _leaf: usize,
        position: Vec3,
        intensity: DVec3,
        seen: Seen,
        weight: f64,
    ) {
        cut.exact_light(position, intensity, seen, weight);
    }

    #[inline(always)]
    fn lights<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        _leaf: usize,
        range: core::ops::Range<usize>,
        seen: Seen,
        weight: f64,
    ) {
        if cut.tree.is_oriented() {
            cut.sum_emitters(range, seen, weight);
        } else {
            cut.sum_lights(range, seen, weight);
        }
    }

    #[inline(always)]
    fn enter<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        index: usize,
        visible: bool,
        weight: f64,
    ) -> Option<Entry> {
        let node = &cut.tree.nodes[index];
        match node.cone(cut.region.surface.point) {
            Some(cone) => {
                let factor = cut.region.factor_of(cut.tree, index, &cone);
                if factor.upper == 0.0 {
                    // Every member aimed away from the point.
                    return None;
                }
                let region = &cut.region;
                let bound = cut
                    .shader
                    .bound(&region.per_point, region.surface, node, &cone);
                let bound = region.oriented(cut.tree, index, &cone, bound, factor);
                cut.bounded(index, visible, weight, &bound)
            }
            None => Some(cut.unbounded(index, visible)),
        }
    }

    /// Together and coarsely where the threshold allows and the shader can
    /// ([`Shader::bound_children_coarse`]), else under their cones, up to
    /// [`CHILDREN`] side by side ([`Shader::bound_nodes`]).
    #[inline(always)]
    fn bound_children<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        parent: usize,
        wanted: u8,
        visible: bool,
        weight: f64,
        pending: &mut impl Pending,
    ) {
        let tree = cut.tree;
        let first = tree.nodes[parent].first_child as usize;
        let lanes = (0..CHILDREN).filter(|i| wanted & (1 << i) != 0);
        let oriented = tree.is_oriented();
        if cut.region.coarse.is_some() && cut.work.nodes <= COARSE_NODES_MAX {
            if oriented {
                if coarse_emitters(cut, parent, wanted, visible, weight, pending) {
                    return;
                }
            } else {
                let mut bounds = [None; CHILDREN];
                let region = &cut.region;
                let children = ChildrenOf {
                    tree,
                    parent,
                    wanted,
                };
                if cut.shader.bound_children_coarse(
                    Seal,
                    &region.per_point,
                    region.surface,
                    children,
                    &mut bounds,
                ) {
                    for i in lanes {
                        let entry = match &bounds[i] {
                            Some(bound) => cut.bounded(first + i, visible, weight, bound),
                            None => Some(cut.unbounded(first + i, visible)),
                        };
                        if let Some(entry) = entry {
                            pending.pending(entry);
                        }
                    }
                    return;
                }
            }
        }
        for i in lanes {
            let child = first + i;
            match tree.nodes[child].cone(cut.region.surface.point) {
                Some(cone) if oriented => {
                    let factor = cut.region.factor_of(tree, child, &cone);
                    // A child whose members all aim away is exactly 0.
                    if factor.upper > 0.0 {
                        let region = &mut cut.region;
                        if let Some(e) = region.emitters {
                            e.children[region.children.len].set(factor);
                        }
                        region.children.push(child as u32, cone);
                    }
                }
                Some(cone) => cut.region.children.push(child as u32, cone),
                None => pending.pending(cut.unbounded(child, visible)),
            }
        }
        cut.bound_waiting(visible, weight, pending);
    }

    #[inline(always)]
    fn sums<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, list: &mut ErrorList) -> (DVec3, DVec3) {
        let (estimate, error) = list.sums();
        (
            cut.region.settled.value() + estimate,
            error + cut.region.settled_error,
        )
    }

    #[inline(always)]
    fn confirmed<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        list: &mut ErrorList,
    ) -> (DVec3, DVec3) {
        let (estimate, error) = list.resum();
        (
            cut.region.settled.value() + estimate,
            reported_bound(error + cut.region.settled_error),
        )
    }

    /// Whether refining `node` (its children or its lights) fits in the
    /// budget, `visible` saying whether the node is known visible (its
    /// small children are then summed light by light).
    #[inline(always)]
    fn affordable<V: Visibility>(
        cut: &Cut<'_, S, V, Self>,
        _list: &ErrorList,
        node: &Node,
        visible: bool,
    ) -> bool {
        if cut.budget == u32::MAX {
            // No budget: every cost fits (the sum below saturates at it).
            return true;
        }
        let cost = if node.is_leaf() {
            node.light_count
        } else if Cut::<S, V, Self>::known(visible) {
            node.children()
                .map(|i| {
                    let c = &cut.tree.nodes[i];
                    if Self::sums_exactly(cut, i, c) {
                        c.light_count
                    } else {
                        1
                    }
                })
                .sum()
        } else {
            node.child_count
        };
        cut.work.cost().saturating_add(cost) <= cut.budget
    }

    #[inline(always)]
    fn taken<V: Visibility>(_cut: &mut Cut<'_, S, V, Self>, _slot: u32) {}

    /// A small scene (see [`SMALL_SCENE_LIGHTS`], or
    /// [`SMALL_SCENE_LIGHTS_COARSE`] where the lights are summed coarsely),
    /// within the budget, no interpolation (whose blend needs bounded
    /// nodes), and a target above 0 (with a target of 0 the cut refines as
    /// usual, so that it adds the lights in the order the exact sum does).
    #[inline(always)]
    fn sums_whole_scene<V: Visibility>(cut: &Cut<'_, S, V, Self>, nested: bool) -> bool {
        let region = &cut.region;
        let most = if region.coarse.is_some() {
            SMALL_SCENE_LIGHTS_COARSE
        } else {
            SMALL_SCENE_LIGHTS
        };
        !nested
            && region.small_lanes.is_some()
            && cut.tree.nodes[0].light_count <= most
            && region.exact_lights > 0
            && !region.one_by_one
            && cut
                .work
                .cost()
                .saturating_add(cut.tree.nodes[0].light_count)
                <= cut.budget
    }

    /// Once the cut's work, a node bound counted as [`NODE_WORK`] lights,
    /// reaches `1 /` [`REST_SHARE_DIVISOR`] of the scene's lights (scenes
    /// of at least [`REST_MIN_LIGHTS`], without interpolation or a
    /// budget), where every light is visible: with a host, the lights of
    /// entries of unknown visibility would take a ray each, where the cut's
    /// classifications settle whole nodes.
    #[inline(always)]
    fn sums_the_rest<V: Visibility>(cut: &Cut<'_, S, V, Self>, nested: bool) -> bool {
        let lights = u64::from(cut.tree.nodes[0].light_count);
        let work = u64::from(cut.work.lights) + NODE_WORK * u64::from(cut.work.nodes);
        V::ALWAYS_VISIBLE
            && !nested
            && cut.budget == u32::MAX
            && lights >= REST_MIN_LIGHTS
            && work * REST_SHARE_DIVISOR >= lights
    }

    /// As [`shade_small_scene`](super::lights::shade_small_scene) does without a host, wherever the point
    /// lies: a tiny scene summed coarsely.
    #[inline(always)]
    fn summed_on_visible_root<V: Visibility>(cut: &mut Cut<'_, S, V, Self>) -> bool {
        let tiny = cut.region.coarse.is_some()
            && cut
                .region
                .small_lanes
                .is_some_and(|lanes| super::lights::tiny_scene(cut.tree, lanes))
            && Self::sums_whole_scene(cut, false);
        if tiny {
            let lights = cut.tree.nodes[0].lights();
            cut.sum_lights(lights, Seen::Visible, 1.0);
        }
        tiny
    }

    #[inline(always)]
    fn sums_in_runs<V: Visibility>(cut: &Cut<'_, S, V, Self>) -> bool {
        !cut.region.one_by_one
    }

    #[inline(always)]
    fn settle<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, value: DVec3) {
        cut.region.settled.add(value);
    }

    #[inline(always)]
    fn host_point<V: Visibility>(cut: &Cut<'_, S, V, Self>) -> Vec3 {
        cut.region.point
    }

    #[inline(always)]
    fn nested<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        nesting: &mut Nesting,
        frame: u32,
        f: impl FnOnce(&mut Cut<'_, S, V, Self>, &mut Nesting),
    ) {
        let outer = core::mem::take(&mut cut.region.settled);
        f(cut, nesting);
        let settled = core::mem::replace(&mut cut.region.settled, outer).value();
        cut.region.settled.add(settled);
        nesting.settled(frame, settled);
    }

    #[inline(always)]
    fn settled_outside<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, nesting: &mut Nesting) {
        nesting.settled(NO_PARENT, cut.region.settled.value());
    }
}

impl<'p, S: Shader, V: Visibility> Cut<'_, S, V, Point<'p, S>> {
    /// The entry of node `index` when it has no finite bound (its ball
    /// reaches the shading point): refined before any other.
    #[inline(always)]
    pub(crate) fn unbounded(&self, index: usize, visible: bool) -> Entry {
        Entry::new(
            Class::Unbounded,
            index as u32,
            seen(Self::known(visible)),
            DVec3::ZERO,
            DVec3::ZERO,
        )
    }

    /// The entry of node `index` with its certified interval `bound`; an
    /// entry with nothing to gain by refining is settled (times `weight`)
    /// instead.
    #[inline(always)]
    pub(crate) fn bounded(
        &mut self,
        index: usize,
        visible: bool,
        weight: f64,
        bound: &NodeEstimate,
    ) -> Option<Entry> {
        let narrowed;
        let node = &self.tree.nodes[index];
        let bound = if self.region.slabs
            && node.light_count >= SLAB_MIN_LIGHTS
            && !self.tree.slabs.tables.is_empty()
            && self.region.may_cut(node)
        {
            narrowed = self.narrow(index, bound);
            &narrowed
        } else {
            bound
        };
        let over = self
            .max_contribution
            .is_some_and(|m| bound.upper.max_element() > m);
        let class = if over {
            Class::OverContribution
        } else {
            Class::Error
        };
        let seen = seen(Self::known(visible));
        let entry = Entry::new(class, index as u32, seen, bound.estimate, bound.error());
        if entry.key <= 0.0 && !over {
            // Nothing to gain by refining (e.g. below the horizon).
            self.region.settled.add(entry.counted().0 * weight);
            return None;
        }
        Some(entry)
    }

    /// [`Shader::narrow_bound`] of node `index`'s `bound`, out of the
    /// cut's hot loop.
    #[inline(never)]
    fn narrow(&self, index: usize, bound: &NodeEstimate) -> NodeEstimate {
        let region = &self.region;
        self.shader.narrow_bound(
            Seal,
            &region.per_point,
            region.surface,
            self.tree,
            index,
            *bound,
        )
    }

    /// Bounds the nodes waiting in the region's children together
    /// ([`Shader::bound_nodes`]) and empties it; entries that stay in the
    /// cut are passed to `pending`.
    #[inline(always)]
    fn bound_waiting(&mut self, visible: bool, weight: f64, pending: &mut impl Pending) {
        let len = self.region.children.len;
        if len == 0 {
            return;
        }
        let tree = self.tree;
        let region = &mut self.region;
        let children = &mut region.children;
        let nodes: [&Node; CHILDREN] = crate::lanes::array(&tree.nodes[0], |i| {
            &tree.nodes[children.indices[i.min(len - 1)] as usize]
        });
        self.shader.bound_nodes(
            &region.per_point,
            region.surface,
            &nodes[..len],
            &children.cones[..len],
            &mut children.bounds[..len],
        );
        children.len = 0;
        let oriented = tree.is_oriented();
        for i in 0..len {
            let children = &self.region.children;
            let (index, mut bound) = (children.indices[i], children.bounds[i]);
            if oriented {
                bound = self.region.oriented(
                    tree,
                    index as usize,
                    &children.cones[i],
                    bound,
                    self.region
                        .emitters
                        .map_or(Factor::ONE, |e| e.children[i].get()),
                );
            }
            if let Some(entry) = self.bounded(index as usize, visible, weight, &bound) {
                pending.pending(entry);
            }
        }
    }
}

/// [`Region::bound_children`] for a tree of emitters through the shader's
/// coarse bound of the children ([`Shader::bound_children_coarse`]): each
/// child's factor first (a child whose members all aim away is exactly 0,
/// and one whose ball holds the point has none: it enters unbounded), then
/// each coarse isotropic interval scaled by its factor, as
/// `bound_waiting` scales the `f64` ones. `false` (nothing done) where the
/// shader has no coarse bound for these children.
#[inline(always)]
fn coarse_emitters<S: Shader, V: Visibility>(
    cut: &mut Cut<'_, S, V, Point<'_, S>>,
    parent: usize,
    wanted: u8,
    visible: bool,
    weight: f64,
    pending: &mut impl Pending,
) -> bool {
    let tree = cut.tree;
    let first = tree.nodes[parent].first_child as usize;
    let lanes = (0..CHILDREN).filter(|i| wanted & (1 << i) != 0);
    let mut factors = [(Factor::ONE, None); CHILDREN];
    let mut lit = wanted;
    for i in lanes.clone() {
        let child = first + i;
        factors[i] = match tree.nodes[child].cone(cut.region.surface.point) {
            Some(cone) => (cut.region.factor_of(tree, child, &cone), Some(cone)),
            None => (Factor::ONE, None),
        };
        if factors[i].0.upper <= 0.0 {
            lit &= !(1 << i);
        }
    }
    let mut bounds = [None; CHILDREN];
    let region = &cut.region;
    let children = ChildrenOf {
        tree,
        parent,
        wanted: lit,
    };
    if !cut.shader.bound_children_coarse(
        Seal,
        &region.per_point,
        region.surface,
        children,
        &mut bounds,
    ) {
        return false;
    }
    for i in lanes.filter(|i| lit & (1 << i) != 0) {
        let entry = match (&bounds[i], &factors[i]) {
            (Some(bound), (factor, Some(cone))) => {
                let bound = cut.region.oriented(tree, first + i, cone, *bound, *factor);
                cut.bounded(first + i, visible, weight, &bound)
            }
            _ => Some(cut.unbounded(first + i, visible)),
        };
        if let Some(entry) = entry {
            pending.pending(entry);
        }
    }
    true
}

/// The most children bounded together: an octree's.
const CHILDREN: usize = 8;

/// The certified bound of a node of emitters whose isotropic bound (the
/// shader's, for the same lights emitting alike in every direction) is
/// `bound` and whose members' profile values at the point lie within
/// `factor`: each member's term is its isotropic term (non-negative) times
/// its profile's value, so the node's sum lies within the isotropic
/// interval scaled by the factor's ends.
#[inline(always)]
pub(crate) fn emitted(bound: NodeEstimate, factor: Factor) -> NodeEstimate {
    NodeEstimate::new(
        bound.estimate * factor.estimate,
        bound.lower * factor.lower,
        bound.upper * factor.upper,
    )
}

/// Children of a node waiting to be bounded together.
struct Children {
    len: usize,
    indices: [u32; CHILDREN],
    cones: [Cone; CHILDREN],
    /// Their bounds, once bounded.
    bounds: [NodeEstimate; CHILDREN],
}

impl Default for Children {
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
            indices: [0; CHILDREN],
            cones: [NONE; CHILDREN],
            bounds: [NodeEstimate::ZERO; CHILDREN],
        }
    }
}

impl Children {
    #[inline(always)]
    fn push(&mut self, index: u32, cone: Cone) {
        self.indices[self.len] = index;
        self.cones[self.len] = cone;
        self.len += 1;
    }
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

/// What a point's scratch holds between calls: the error list, the nesting
/// of an interpolated cut and the blend's items.
#[derive(Debug, Default)]
pub(crate) struct PointScratch {
    pub(crate) list: ErrorList,
    pub(crate) nesting: Nesting,
    pub(crate) items: Vec<Item>,
}

/// What a session lends a point's cut: the tree, the shader and, for a
/// small scene, its lights side by side.
#[derive(Clone, Copy)]
pub(crate) struct Lent<'a, S> {
    pub(crate) tree: &'a LightTree,
    pub(crate) shader: &'a S,
    pub(crate) small_lanes: Option<&'a [LightLanes]>,
}

/// Shades one point: the cut through the tree for the shader at `surface`
/// (`point` as the host gave it) until `threshold` is met, with the
/// interpolation across levels where it asks for one. Inlined into each
/// compiled copy of the shading call.
#[inline(always)]
pub(crate) fn shade_point<S: Shader, V: Visibility>(
    lent: Lent<'_, S>,
    surface: &Surface,
    point: Vec3,
    threshold: &Threshold,
    visibility: V,
    scratch: &mut PointScratch,
) -> ShadeResult {
    let Lent {
        tree,
        shader,
        small_lanes,
    } = lent;
    if let Some(lanes) = small_lanes
        && let Some(result) =
            super::lights::shade_small_scene::<S, V>(tree, shader, lanes, surface, threshold)
    {
        return result;
    }
    // Set up only for a tree of emitters.
    let emitters = tree.is_oriented().then(EmitterScratch::default);
    let region = Point::new(
        tree,
        shader,
        surface,
        point,
        threshold,
        small_lanes,
        emitters.as_ref(),
    );
    let mut cut = Cut::new(tree, shader, region, threshold, visibility);
    let interpolating = threshold.interpolation().is_some();
    let (list, nesting) = (&mut scratch.list, &mut scratch.nesting);
    nesting.point = cut.region.surface.point;
    cut.enter_root(list, interpolating.then_some(&mut *nesting));
    let outcome: Outcome = cut.run(list, threshold, interpolating.then_some(&mut *nesting));
    let unbounded = list.has_unbounded();
    // With nothing left waiting the cut is the exact sum of what it
    // settled, as without interpolation: no nesting, and no rounding
    // allowance of the nested intervals (which would exceed a zero target).
    let (mut radiance, mut bound) = if interpolating && !unbounded && list.len() > 0 {
        // Each refined node's interval intersected with its children's.
        outcome.confirmed.unwrap_or_else(|| nesting.fold(list))
    } else {
        let (estimate, error) = list.resum();
        (
            cut.region.settled.value() + estimate,
            reported_bound(error + cut.region.settled_error),
        )
    };
    if outcome.stop == Stop::ThresholdMet
        // The blend's bound is re-checked; for the per-node target the
        // blend refines no node less than the error list did, so the
        // largest single error cannot grow.
        && let Some((r, e)) =
            interpolate::interpolate(&mut cut, scratch, threshold, outcome.last_step, radiance, bound)
        && e.is_finite()
        && threshold.met(r, e, 0.0)
    {
        (radiance, bound) = (r, e);
    }
    ShadeResult {
        radiance,
        error_bound: if unbounded { DVec3::INFINITY } else { bound },
        nodes_evaluated: cut.work.nodes,
        lights_evaluated: cut.work.lights,
        classify_queries: cut.work.classify_queries,
        point_queries: cut.work.point_queries,
        stop: outcome.stop,
    }
}
