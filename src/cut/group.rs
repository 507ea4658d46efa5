//! The cut for a group of shading points (the batch call): the same engine
//! as for one point, each node's bound widened to hold at every point of
//! the group, the estimates left to the points.
//!
//! A node enters with one error for the whole group: the shader's bound
//! for one point, taken at the worst the group allows ([`GroupView`]: the
//! nearest distance from any point, the largest cosine and heights over
//! every point and normal), plus, where members reach below some point's
//! tangent plane, the clamp term at that depth. Its estimate is each
//! point's own: once the cut is chosen, every point sums the cut's
//! estimates at its own position and normal, and its certified bound is
//! the sum of the shared errors. Single lights are kept for the points:
//! those above every tangent plane are summed with the node estimates,
//! those across some plane are evaluated by the shader at each point, and
//! those the host sees partly from the group are asked about point to
//! point. Nodes below every tangent plane drop out; nodes whose ball comes
//! too near the group, and nodes the host sees partly, have no shared
//! bound and are refined.
//!
//! A relative target is aimed at with the darkest of a few points spread
//! over the group ([`Samples`]), whose virtual-light estimates steer the
//! list; what the cut may cost is capped per point of the group, so that
//! a group whose cut does not pay is shaded point by point instead.

use glam::{DVec3, Vec3};

use super::engine::{Cut, Pending, Region, node_region};
use super::error_list::{Class, Entry, ErrorList, Seen};
use super::interpolate::{Nesting, Ramp, level};
use super::point::reported_bound;
use super::policy::{ENTRIES_PER_BOUND, LAYER_NODES_MAX, MAX_SHARED_ENTRIES};
use super::steering::{SAMPLES, Samples, Spread, darkest};
use super::threshold::Threshold;
use crate::emission::Profile;
use crate::geometry::{Aabb, Cone, GroupBounds, GroupView, Side, Surface};
use crate::lambert::slabs_apply;
use crate::numeric::{CompensatedSum, POINT_SLACK, SERIES_SLACK};
use crate::shader::{Seal, Shader};
use crate::tree::orientation::Factor;
use crate::tree::slabs::SLAB_MIN_LIGHTS;
use crate::tree::{LightTree, MAX_CHILDREN, Node};
use crate::visibility::{Coverage, NodeRegion, Visibility};

/// What a group's cut keeps between calls: the list, and what the points
/// sum besides the waiting nodes.
#[derive(Debug, Default)]
pub(crate) struct GroupScratch {
    /// Single lights on both sides of some tangent plane, or emitters
    /// whose profile varies over the group, evaluated exactly at each
    /// point: position, intensity and profile.
    pub(crate) across: Vec<(DVec3, DVec3, Profile)>,
    /// Single lights the host saw partially from the group: asked
    /// point-to-point and evaluated exactly at each point.
    pub(crate) shadowed: Vec<(DVec3, DVec3, Profile)>,
    /// Single lights above every tangent plane: position, intensity times
    /// `kd`.
    pub(crate) above: Vec<(DVec3, DVec3)>,
    /// Each entry's values at the samples, by slot.
    steer: Vec<[DVec3; SAMPLES]>,
    /// Nodes of a blended cut with their weights.
    pub(crate) weighted: Vec<(u32, f64)>,
    /// Nodes a blend still has to refine: index, weight, known visible.
    blending: Vec<(u32, f64, bool)>,
}

impl GroupScratch {
    /// Empties everything the cut fills.
    pub(crate) fn clear(&mut self) {
        self.across.clear();
        self.shadowed.clear();
        self.above.clear();
        self.steer.clear();
    }
}

/// What a group's cut may spend: its points would each cost alone about
/// as much as `per_point` shared evaluations.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Spend {
    /// Points in the group.
    pub(crate) points: u64,
    /// Shared evaluations allowed a point.
    pub(crate) per_point: u64,
}

/// The shared cut aims at this fraction of the darkest sample's estimate
/// for a relative target, leaving room for points darker than it.
const FIRST_MARGIN: f64 = 0.9;

/// The region of a group of points.
pub(crate) struct Shared<'s> {
    /// The shader's diffuse albedo: the points' sums and the samples are
    /// the diffuse model's.
    pub(crate) kd: DVec3,
    pub(crate) group: GroupBounds,
    /// The points whose estimates steer a relative target.
    samples: Samples,
    /// The estimate steering the target is the darkest sample's times this.
    pub(crate) margin: f64,
    /// The samples' values of the cut's single lights.
    steer_settled: [DVec3; SAMPLES],
    /// Running sums of the samples' values of the waiting entries.
    steer_waiting: [DVec3; SAMPLES],
    /// The summed errors of the single lights above every plane (times
    /// `kd`), summed plainly.
    pub(crate) light_error: DVec3,
    /// How far the entries that may be packed lie from the group.
    pub(crate) spread: Spread,
    /// Points in the group.
    points: u64,
    /// What the cut may cost per point.
    budget_per_point: u64,
    /// A point at the group's centre with its mean normal, where the
    /// shader narrows bounds from slab moments: the shared cut gives up
    /// once [`LAYER_NODES_MAX`] of its nodes are cut by that point's tangent
    /// plane with bins wholly above or below it (a point alone settles
    /// those nodes early; the shared cut would walk them to the leaves).
    layer_probe: Option<Surface>,
    /// The nodes met so far that [`layer_probe`](Self::layer_probe) counts.
    layer_nodes: u32,
    scratch: &'s mut GroupScratch,
}

/// What the group's cut looks like for the points: the waiting nodes, or
/// the weighted nodes of a blend, with the single lights and the summed
/// error.
pub(crate) struct GroupCut<'c> {
    pub(crate) scratch: &'c GroupScratch,
    pub(crate) list: &'c ErrorList,
    /// Whether the nodes are `scratch.weighted` (a blend) rather than the
    /// list's waiting entries.
    pub(crate) blended: bool,
    /// The certified bound every point of the group shares, before its own
    /// rounding.
    pub(crate) error: DVec3,
}

impl<'s> Shared<'s> {
    /// The region of a group of points lying within `group`, steered by
    /// `samples` (aiming at their darkest estimate times
    /// [`FIRST_MARGIN`]), with diffuse albedo `kd`, allowed to `spend`.
    pub(crate) fn new(
        kd: DVec3,
        group: GroupBounds,
        samples: Samples,
        spend: Spend,
        scratch: &'s mut GroupScratch,
    ) -> Self {
        scratch.clear();
        Self {
            kd,
            group,
            samples,
            margin: FIRST_MARGIN,
            steer_settled: [DVec3::ZERO; SAMPLES],
            steer_waiting: [DVec3::ZERO; SAMPLES],
            light_error: DVec3::ZERO,
            spread: Spread::default(),
            points: spend.points,
            budget_per_point: spend.per_point,
            layer_probe: None,
            layer_nodes: 0,
            scratch,
        }
    }

    /// Watch for nodes the group's tangent planes cut through a layer of
    /// lights (see [`layer_probe`](Self::layer_probe)).
    pub(crate) fn watch_layers(&mut self) {
        let g = &self.group;
        self.layer_probe = Surface::new(g.centre.as_vec3(), g.normal.as_vec3(), None).ok();
    }

    /// The emission bounds of node `index` over the group
    /// ([`LightTree::group_factor`]): the factor its estimate at each
    /// point takes.
    #[inline(always)]
    pub(crate) fn node_factor(&self, tree: &LightTree, index: usize) -> Factor {
        if tree.is_oriented() {
            tree.group_factor(index, self.group.centre, self.group.radius)
        } else {
            Factor::ONE
        }
    }

    /// A node's shared error `error` (of its diffuse estimate, as
    /// [`Shader::group_errors`] bounds it) widened for its members'
    /// emission profiles, whose values over the group lie in `factor`: each
    /// point's estimate is its diffuse estimate `E` times
    /// `factor.estimate`, and the node's exact sum `T` lies in `[lower (E -
    /// e), upper (E + e)]` (each member's term is its isotropic term times
    /// its profile's value), so `|T - estimate E| <= max(estimate - lower,
    /// upper - estimate) (E + e) + upper e` with `E <= U + e`; `U` bounds
    /// the isotropic sum at every point, `I kd / d^2` with `d` the least
    /// distance from a point to the node's ball (`nearest`, the least
    /// distance to its centroid, less its radius).
    #[inline(always)]
    fn emitted_error(&self, node: &Node, error: DVec3, factor: Factor, nearest: f64) -> DVec3 {
        if factor == Factor::ONE {
            return error;
        }
        let clearance = nearest - f64::from(node.radius);
        let most = node.intensity * self.kd / (clearance * clearance);
        let width = (factor.estimate - factor.lower).max(factor.upper - factor.estimate);
        // Relative rounding of these few operations, far inside the
        // allowance, widened outright.
        (width * (most + 2.0 * error) + factor.upper * error) * (1.0 + 1e-12)
    }

    /// The darkest sample's estimate of the cut.
    #[inline(always)]
    pub(crate) fn steering(&self) -> DVec3 {
        let sums = core::array::from_fn(|k| self.steer_settled[k] + self.steer_waiting[k]);
        darkest(&sums)
    }

    /// Brings the samples' values up to the entries pushed since the last
    /// call, adding them to the running sums.
    #[inline(always)]
    fn sync(&mut self, tree: &crate::LightTree, list: &ErrorList) {
        let scratch = &mut *self.scratch;
        while scratch.steer.len() < list.slots() {
            let e = list.entry(scratch.steer.len() as u32);
            let values = if e.class == Class::Unbounded {
                [DVec3::ZERO; SAMPLES]
            } else {
                let node = &tree.nodes[e.node as usize];
                let f = if tree.is_oriented() {
                    let group = &self.group;
                    tree.group_factor(e.node as usize, group.centre, group.radius)
                        .estimate
                } else {
                    1.0
                };
                self.samples
                    .values(node.centroid.as_dvec3(), node.intensity * (self.kd * f))
            };
            scratch.steer.push(values);
            for (sum, v) in self.steer_waiting.iter_mut().zip(values) {
                *sum += v;
            }
        }
    }

    /// The cut as the points sum it: the waiting nodes, or the blend's
    /// weighted nodes, with the single lights; the error every point
    /// shares, before the rounding of its own sum.
    pub(crate) fn group_cut<'c>(
        &'c self,
        list: &'c mut ErrorList,
        blend: Option<&Blend>,
    ) -> GroupCut<'c> {
        let (_, resummed) = list.resum();
        let list = &*list;
        let region = self;
        let scratch = &*region.scratch;
        let error = match blend {
            Some(b) => b.error * (1.0 + scratch.weighted.len() as f64 * f64::EPSILON),
            None => resummed,
        };
        let light_error = region.light_error * (1.0 + scratch.above.len() as f64 * f64::EPSILON);
        GroupCut {
            scratch,
            list,
            blended: blend.is_some(),
            error: error + light_error,
        }
    }

    /// Recomputes the running sums of the samples' values of the waiting
    /// entries (they subtract and may drift).
    #[inline(always)]
    pub(crate) fn resum_steering(&mut self, list: &ErrorList) {
        let mut sums: [CompensatedSum; SAMPLES] = Default::default();
        for (_, slot) in list.waiting() {
            for (sum, v) in sums.iter_mut().zip(self.scratch.steer[slot as usize]) {
                sum.add(v);
            }
        }
        self.steer_waiting = sums.map(|s| s.value());
    }
}

impl<'s, S: Shader> Region<S> for Shared<'s> {
    #[inline(always)]
    fn below_horizon<V: Visibility>(_: &mut Cut<'_, S, V, Self>, _: u32) -> bool {
        false
    }

    #[inline(always)]
    fn sums_exactly<V: Visibility>(_: &Cut<'_, S, V, Self>, _: usize, _: &Node) -> bool {
        false
    }

    /// Puts a single light into the cut unless it is below every point's
    /// tangent plane or hidden from the whole group.
    #[inline(always)]
    fn light<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        leaf: usize,
        position: Vec3,
        intensity: DVec3,
        seen: Seen,
        weight: f64,
    ) {
        if intensity == DVec3::ZERO {
            return;
        }
        let region = &cut.region;
        let position_f32 = position;
        let position = position.as_dvec3();
        let intensity = intensity * weight;
        let offset = position - region.group.centre;
        let distance = offset.length();
        let height = region.group.normal.dot(offset);
        let scaled = intensity * region.kd;
        let side = region
            .group
            .side_of(height, height, distance + region.group.radius);
        if side == Side::Below {
            return;
        }
        let here = NodeRegion {
            index: leaf as u32,
            aabb: Aabb {
                min: position_f32,
                max: position_f32,
            },
            centroid: position_f32,
            radius: 0.0,
            light_count: 1,
        };
        match cut.ask(seen == Seen::Visible, &here, None) {
            None => return,
            Some(true) => {}
            Some(false) => {
                cut.region
                    .scratch
                    .shadowed
                    .push((position, intensity, Profile::ISOTROPIC));
                return;
            }
        }
        let region = &mut cut.region;
        match side {
            Side::Below => return,
            // The series of a single light is its exact term; what is left
            // is the rounding of its cosine and of the offset (see
            // `SERIES_SLACK` and `POINT_SLACK`), at the nearest distance.
            Side::Above(lowest) => {
                let nearest = region.group.nearest(distance, lowest);
                let inv = 1.0 / nearest;
                region.light_error += scaled * ((inv * inv) * (SERIES_SLACK + POINT_SLACK));
                region.spread.note(nearest, distance);
                region.scratch.above.push((position, scaled));
            }
            // Evaluated by the shader at each point.
            Side::Across(_) => {
                region
                    .scratch
                    .across
                    .push((position, intensity, Profile::ISOTROPIC))
            }
        }
        let values = region.samples.values(position, scaled);
        for (sum, v) in region.steer_settled.iter_mut().zip(values) {
            *sum += v;
        }
    }

    #[inline(always)]
    fn lights<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        leaf: usize,
        range: core::ops::Range<usize>,
        seen: Seen,
        weight: f64,
    ) {
        let tree = cut.tree;
        for k in range {
            let l = tree.lights[k];
            if tree.is_oriented() {
                let group = &cut.region.group;
                let f = tree.light_group_factor(k, group.centre, group.radius);
                if f.upper == 0.0 {
                    // Aimed away from every point of the group.
                    continue;
                }
                if f.lower < 1.0 {
                    cut.emitter(leaf, k, seen, weight, f.estimate);
                    continue;
                }
                // Its profile is 1 at every point: an isotropic light.
            }
            Self::light(cut, leaf, l.position, l.intensity.as_dvec3(), seen, weight);
        }
    }

    #[inline(always)]
    fn enter<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        index: usize,
        visible: bool,
        _weight: f64,
    ) -> Option<Entry> {
        let node = &cut.tree.nodes[index];
        let error = match cut.shared_view(node) {
            Ok(None) => return None,
            Err(()) => None,
            Ok(Some((view, nearest, distance))) => {
                let factor = cut.region.node_factor(cut.tree, index);
                if factor.upper == 0.0 {
                    // Every member aimed away from every point.
                    return None;
                }
                cut.region.spread.note(nearest, distance);
                let error = cut.shared_errors::<1>(&[node], &[view])?[0];
                Some(cut.region.emitted_error(node, error, factor, nearest))
            }
        };
        cut.shared_entry(index, visible, error)
    }

    /// The children's views first (single lights went into the cut when
    /// they were admitted), then their errors side by side, then, in the
    /// children's order, the host and the entries.
    #[inline(always)]
    fn bound_children<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        parent: usize,
        wanted: u8,
        visible: bool,
        _weight: f64,
        pending: &mut impl Pending,
    ) {
        let tree = cut.tree;
        let first = tree.nodes[parent].first_child as usize;
        let mut states = [Child::Skip; MAX_CHILDREN];
        let mut bounded = [(0usize, GroupView::default()); MAX_CHILDREN];
        let mut count = 0;
        for (k, state) in states.iter_mut().enumerate() {
            if wanted & (1 << k) == 0 {
                continue;
            }
            let node = &tree.nodes[first + k];
            *state = match cut.shared_view(node) {
                Ok(None) => Child::Skip,
                Err(()) => Child::Near,
                Ok(Some(_)) if cut.region.node_factor(tree, first + k).upper == 0.0 => {
                    // Every member aimed away from every point.
                    Child::Skip
                }
                Ok(Some((view, nearest, distance))) => {
                    cut.region.spread.note(nearest, distance);
                    bounded[count] = (k, view);
                    count += 1;
                    Child::Bound(DVec3::ZERO)
                }
            };
        }
        let done = match count {
            0 => true,
            1 => cut.errors_into::<1>(first, &mut states, &bounded[..1]),
            2..=4 => cut.errors_into::<4>(first, &mut states, &bounded[..count]),
            _ => cut.errors_into::<8>(first, &mut states, &bounded[..count]),
        };
        debug_assert!(done, "a shader that shares cuts bounds nodes for groups");
        if tree.is_oriented() {
            for &(k, view) in &bounded[..count] {
                let node = &tree.nodes[first + k];
                let factor = cut.region.node_factor(tree, first + k);
                if let Child::Bound(error) = &mut states[k] {
                    *error = cut
                        .region
                        .emitted_error(node, *error, factor, 1.0 / view.inv_nearest);
                }
            }
        }
        for (k, state) in states.iter().enumerate() {
            let error = match state {
                Child::Skip => continue,
                Child::Near => None,
                Child::Bound(error) => Some(*error),
            };
            if let Some(entry) = cut.shared_entry(first + k, visible, error) {
                pending.pending(entry);
            }
        }
    }

    #[inline(always)]
    fn sums<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, list: &mut ErrorList) -> (DVec3, DVec3) {
        cut.region.sync(cut.tree, list);
        let (_, error) = list.sums();
        (cut.region.steering() * cut.region.margin, error)
    }

    #[inline(always)]
    fn confirmed<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        list: &mut ErrorList,
    ) -> (DVec3, DVec3) {
        let (_, error) = list.resum();
        cut.region.resum_steering(list);
        (
            cut.region.steering() * cut.region.margin,
            reported_bound(error),
        )
    }

    /// What the points would spend: the shared bounds, a ray a point for
    /// each light asked point to point, and the points' sums over the
    /// entries, against [`Shared::new`]'s allowance a point; and at most
    /// [`MAX_SHARED_ENTRIES`] entries.
    #[inline(always)]
    fn affordable<V: Visibility>(
        cut: &Cut<'_, S, V, Self>,
        list: &ErrorList,
        _node: &Node,
        _visible: bool,
    ) -> bool {
        let region = &cut.region;
        let scratch = &*region.scratch;
        let entries = scratch.across.len() + scratch.above.len() + list.len();
        let rays = scratch.shadowed.len() as u64 * region.points;
        let cost =
            u64::from(cut.work.nodes) + rays + entries as u64 * region.points / ENTRIES_PER_BOUND;
        cost <= region.points * region.budget_per_point
            && entries <= MAX_SHARED_ENTRIES
            && region.layer_nodes < LAYER_NODES_MAX
    }

    #[inline(always)]
    fn taken<V: Visibility>(cut: &mut Cut<'_, S, V, Self>, slot: u32) {
        let region = &mut cut.region;
        for (sum, v) in region
            .steer_waiting
            .iter_mut()
            .zip(region.scratch.steer[slot as usize])
        {
            *sum -= v;
        }
    }

    #[inline(always)]
    fn sums_whole_scene<V: Visibility>(_: &Cut<'_, S, V, Self>, _: bool) -> bool {
        false
    }

    /// A group whose shared cut does not pay gives up instead (see
    /// `affordable`): its points are shaded one by one.
    #[inline(always)]
    fn sums_the_rest<V: Visibility>(_: &Cut<'_, S, V, Self>, _: bool) -> bool {
        false
    }

    #[inline(always)]
    fn summed_on_visible_root<V: Visibility>(_: &mut Cut<'_, S, V, Self>) -> bool {
        false
    }

    #[inline(always)]
    fn sums_in_runs<V: Visibility>(_: &Cut<'_, S, V, Self>) -> bool {
        true
    }

    fn settle<V: Visibility>(_: &mut Cut<'_, S, V, Self>, _: DVec3) {
        debug_assert!(false, "a group's entries are asked about when they enter");
    }

    #[inline(always)]
    fn host_point<V: Visibility>(cut: &Cut<'_, S, V, Self>) -> Vec3 {
        cut.region.group.centre.as_vec3()
    }

    fn nested<V: Visibility>(
        cut: &mut Cut<'_, S, V, Self>,
        nesting: &mut Nesting,
        _frame: u32,
        f: impl FnOnce(&mut Cut<'_, S, V, Self>, &mut Nesting),
    ) {
        f(cut, nesting);
    }

    fn settled_outside<V: Visibility>(_: &mut Cut<'_, S, V, Self>, _: &mut Nesting) {}
}

/// A child of a node being bounded for a group.
#[derive(Clone, Copy, Debug)]
enum Child {
    /// Not wanted, or below every plane.
    Skip,
    /// Too near the group for a shared bound.
    Near,
    /// Bounded: its shared error (once taken).
    Bound(DVec3),
}

impl<'s, S: Shader, V: Visibility> Cut<'_, S, V, Shared<'s>> {
    /// An emitter (light `light` of the tree, leaf order, of node `leaf`)
    /// whose profile varies over the group: kept for each point to
    /// evaluate with its profile (asked about point to point where the
    /// host sees it partly), unless it is below every tangent plane or
    /// hidden from the whole group; its value at the samples taken at
    /// `estimate`, the profile's value the group's bound picked.
    #[inline(always)]
    fn emitter(&mut self, leaf: usize, light: usize, seen: Seen, weight: f64, estimate: f64) {
        let tree = self.tree;
        let l = tree.lights[light];
        let intensity = l.intensity.as_dvec3() * weight;
        if intensity == DVec3::ZERO {
            return;
        }
        let position = l.position.as_dvec3();
        let group = &self.region.group;
        let offset = position - group.centre;
        let height = group.normal.dot(offset);
        if group.side_of(height, height, offset.length() + group.radius) == Side::Below {
            return;
        }
        let here = NodeRegion {
            index: leaf as u32,
            aabb: Aabb {
                min: l.position,
                max: l.position,
            },
            centroid: l.position,
            radius: 0.0,
            light_count: 1,
        };
        let profile = tree.profile(light);
        match self.ask(seen == Seen::Visible, &here, None) {
            None => return,
            Some(true) => self
                .region
                .scratch
                .across
                .push((position, intensity, profile)),
            Some(false) => {
                self.region
                    .scratch
                    .shadowed
                    .push((position, intensity, profile));
                return;
            }
        }
        let region = &mut self.region;
        let values = region
            .samples
            .values(position, intensity * (region.kd * estimate));
        for (sum, v) in region.steer_settled.iter_mut().zip(values) {
            *sum += v;
        }
    }

    /// Asks the host about `region` for the whole group, unless `visible`
    /// is known already; `None` when it is occluded, else whether it is
    /// visible. `node` (for a node rather than a single light) is counted
    /// for giving up.
    #[inline(always)]
    fn ask(&mut self, visible: bool, region: &NodeRegion, node: Option<&Node>) -> Option<bool> {
        if Self::known(visible) {
            return Some(true);
        }
        let answer = self
            .visibility
            .classify_group(&self.region.group.region, region);
        match node {
            Some(node) => self.answered(node, answer),
            None => self.work.classify_queries += 1,
        }
        match answer {
            Coverage::Occluded => None,
            Coverage::Visible => Some(true),
            Coverage::Partial => Some(false),
        }
    }

    /// The entry of node `index` (known visible for the group if
    /// `visible`) with its shared `error`, `None` where it has none (too
    /// near); `None` when the host hides it from the whole group. A node
    /// the host sees partly has no shared bound: it is refined.
    #[inline(always)]
    fn shared_entry(&mut self, index: usize, visible: bool, error: Option<DVec3>) -> Option<Entry> {
        let node = &self.tree.nodes[index];
        if node.light_count >= SLAB_MIN_LIGHTS
            && let Some(probe) = &self.region.layer_probe
            && slabs_apply(probe, self.tree, index)
        {
            self.region.layer_nodes += 1;
        }
        let visible = self.ask(visible, &node_region(node, index), Some(node))?;
        Some(match error.filter(|_| visible) {
            Some(error) => Entry::new(
                Class::Error,
                index as u32,
                Seen::Visible,
                DVec3::ZERO,
                error,
            ),
            None => Entry::new(
                Class::Unbounded,
                index as u32,
                if visible {
                    Seen::Visible
                } else {
                    Seen::Partial(None)
                },
                DVec3::ZERO,
                DVec3::ZERO,
            ),
        })
    }

    /// What every point of the group sees of `node`: `Ok(None)` for a node
    /// below every tangent plane, `Err(())` for one whose ball comes too
    /// near the group, else its view with the nearest distance from a
    /// point to its centroid and that centroid's distance from the group's
    /// centre.
    #[inline(always)]
    fn shared_view(&self, node: &Node) -> Result<Option<(GroupView, f64, f64)>, ()> {
        let group = &self.region.group;
        let centroid = node.centroid.as_dvec3();
        let distance = (centroid - group.centre).length();
        let radius = f64::from(node.radius);
        let reach = distance + radius + group.radius;
        let (lowest, depth) = match group.side(&node.aabb, reach) {
            Side::Above(lowest) => (lowest, 0.0),
            Side::Below => return Ok(None),
            Side::Across(lowest) => (0.0, -lowest),
        };
        // No point comes nearer the centroid than this (the centroid lies
        // in the box, so at least `lowest` above every plane).
        let nearest = group.nearest(distance, lowest);
        if !(nearest - radius > nearest * 2.0 * Cone::MIN_CLEARANCE) {
            return Err(());
        }
        let view = group.view(
            centroid,
            &node.aabb,
            1.0 / nearest,
            distance,
            depth,
            nearest - radius,
        );
        Ok(Some((view, nearest, distance)))
    }

    /// The shader's shared errors of `nodes` seen as `views`, `N` side by
    /// side; `None` where the shader has none.
    #[inline(always)]
    fn shared_errors<const N: usize>(
        &self,
        nodes: &[&Node; N],
        views: &[GroupView; N],
    ) -> Option<[DVec3; N]> {
        self.shader.group_errors::<N>(Seal, nodes, views)
    }

    /// The errors of the children `bounded` (`(k, view)`: child `first +
    /// k`, what the group sees of it) into their states, `N` lanes at a
    /// time; unused lanes repeat the last child. `false` where the shader
    /// has no shared errors.
    #[inline(always)]
    fn errors_into<const N: usize>(
        &self,
        first: usize,
        states: &mut [Child; MAX_CHILDREN],
        bounded: &[(usize, GroupView)],
    ) -> bool {
        let last = bounded.len() - 1;
        let pick = |i: usize| &bounded[i.min(last)];
        let tree = self.tree;
        let nodes: [&Node; N] = crate::lanes::array(&tree.nodes[first + bounded[0].0], |i| {
            &tree.nodes[first + pick(i).0]
        });
        let views = crate::lanes::array(bounded[0].1, |i| pick(i).1);
        let Some(errors) = self.shared_errors::<N>(&nodes, &views) else {
            return false;
        };
        for (&(k, _), error) in bounded.iter().zip(errors) {
            if let Child::Bound(e) = &mut states[k] {
                *e = error;
            }
        }
        true
    }
}

/// What a blend of a group's cut added, to take it out again, and the
/// blended nodes' summed error.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Blend {
    /// Lengths of the cut's three lists of single lights before the blend.
    lights: (usize, usize, usize),
    light_error: DVec3,
    steer: [DVec3; SAMPLES],
    /// The blended nodes' summed error.
    pub(crate) error: DVec3,
}

impl<'s, S: Shader, V: Visibility> Cut<'_, S, V, Shared<'s>> {
    /// Interpolation across levels for the group (see
    /// [`Threshold::with_interpolation`]): every waiting node whose error
    /// lies within `band` of the level where the list stopped is blended
    /// with its children, recursively, with the weights of [`Ramp`] (a
    /// node's priority capped at its parent's, so weights never grow down a
    /// path): the blended nodes and their weights go to the scratch's
    /// weighted list, single lights into the cut with their weights. The
    /// level is placed between the list's last two steps ([`level`]): a
    /// group's points each have their own estimate, so the blend cannot be
    /// solved for one point's target, nor a node's interval intersected
    /// with its children's, as a single point's blend is; each point's
    /// result is the weighted mixture, its bound the weighted errors.
    ///
    /// Returns what [`unblend`](Self::unblend) needs to restore the cut and
    /// the blended error, or `None` when there is nothing to blend or the
    /// blend would cost more than the group may spend.
    pub(crate) fn blend(
        &mut self,
        list: &mut ErrorList,
        threshold: &Threshold,
        outcome: &super::Outcome,
    ) -> Option<Blend> {
        let band = threshold.interpolation()?;
        let largest = list.largest();
        let at = level(outcome.last_step, outcome.after, largest);
        if list.len() == 0 || !(at > 0.0 && at.is_finite()) {
            return None;
        }
        let region = &mut self.region;
        let mark = Blend {
            lights: (
                region.scratch.across.len(),
                region.scratch.above.len(),
                region.scratch.shadowed.len(),
            ),
            light_error: region.light_error,
            steer: region.steer_settled,
            error: DVec3::ZERO,
        };
        let ramp = Ramp::new(at, band);
        let mut error = DVec3::ZERO;
        let mut blending = core::mem::take(&mut region.scratch.blending);
        let mut weighted = core::mem::take(&mut region.scratch.weighted);
        blending.clear();
        weighted.clear();
        for (e, _) in list.waiting() {
            let alpha = ramp.alpha(e.key);
            if alpha < 1.0 {
                weighted.push((e.node, 1.0 - alpha));
                error += e.error * (1.0 - alpha);
            }
            if alpha > 0.0 {
                blending.push((e.node, alpha, e.seen == Seen::Visible));
            }
        }
        let budget = region.points * region.budget_per_point;
        let mut affordable = true;
        while let Some((node, weight, visible)) = blending.pop() {
            if u64::from(self.work.nodes) > budget {
                affordable = false;
                break;
            }
            self.refine(node as usize, visible, weight, &mut |e: Entry| {
                if e.class == Class::Unbounded {
                    // No shared bound: refined fully.
                    blending.push((e.node, weight, e.seen == Seen::Visible));
                    return;
                }
                let alpha = ramp.alpha(e.key);
                if alpha < 1.0 {
                    weighted.push((e.node, weight * (1.0 - alpha)));
                    error += e.error * (weight * (1.0 - alpha));
                }
                if alpha > 0.0 {
                    blending.push((e.node, weight * alpha, true));
                }
            });
        }
        let scratch = &mut *self.region.scratch;
        scratch.blending = blending;
        scratch.weighted = weighted;
        if !affordable {
            self.unblend(mark);
            return None;
        }
        Some(Blend { error, ..mark })
    }

    /// Takes the single lights a [`blend`](Self::blend) put into the cut
    /// out again.
    pub(crate) fn unblend(&mut self, mark: Blend) {
        let (across, above, shadowed) = mark.lights;
        let region = &mut self.region;
        region.scratch.across.truncate(across);
        region.scratch.above.truncate(above);
        region.scratch.shadowed.truncate(shadowed);
        region.light_error = mark.light_error;
        region.steer_settled = mark.steer;
    }
}
