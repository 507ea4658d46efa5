//! Choosing the cut: the paper's error list, thresholds, results, and the
//! exact reference sum.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::{DVec3, Vec3};

use crate::ShadeError;
use crate::geometry::{Cone, Surface};
use crate::shader::{NodeBound, Shader, ViewIndependent};
use crate::tree::{LightTree, Node};
use crate::visibility::{Coverage, NodeBounds, Unoccluded, Visibility};

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
    pub const fn absolute(t: f64) -> Self {
        Self {
            target: Target::Absolute(t),
            max_contribution: None,
            budget: None,
            band: None,
        }
    }

    /// Threshold on the summed error bound relative to the estimate.
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
    pub const fn exact() -> Self {
        Self::absolute(0.0)
    }

    /// Caps the work: at most `max_cost` evaluations, counting each node
    /// bound and each exact light evaluation as one. The root is always
    /// evaluated, so budgets 0 and 1 both evaluate the root only. A node is
    /// refined only if all of its children (or lights) fit in what remains.
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
    pub const fn with_max_contribution(mut self, t: f64) -> Self {
        self.max_contribution = Some(t);
        self
    }

    /// Interpolation across levels, so that the estimate varies
    /// continuously with the shading point instead of jumping where the cut
    /// changes (the seams of the paper's difference image).
    ///
    /// After the error list has met the target, let `tau` be the level at
    /// which it stopped: with `h_k` the largest error left unrefined, `h_{k-1}`
    /// the error of the last node refined, and `g_k`, `g_{k-1}` the excess of
    /// the summed error over the target after and before that refinement
    /// (`g_k <= 0 < g_{k-1}`), `tau = h_{k-1} + beta (h_k - h_{k-1})` with
    /// `beta = g_{k-1} / (g_{k-1} - g_k)`. Every
    /// unrefined node of error `e` is given a refinement weight
    /// `alpha = clamp((e - tau/band) / (tau - tau/band), 0, 1)` and replaced
    /// by `(1 - alpha) * (its estimate) + alpha * (its children's blended
    /// estimates)`, recursively (children with `e >= tau` are refined fully,
    /// as the error list would). The bound is blended the same way: a convex
    /// combination of certified estimates of the same sum is certified by
    /// the same combination of their bounds.
    ///
    /// Why this removes the seams: without it a node jumps between "used"
    /// and "refined" where the error list's decision flips; with it, a node
    /// is fully refined exactly when its error reaches the level `tau`, and
    /// its weight falls continuously to 0 as its error falls to `tau/band`.
    /// Node estimates and errors are continuous in the shading point (the
    /// bounds are built from continuous pieces), so the blend is continuous
    /// for a fixed `tau`. And `tau` is continuous where the stopping step
    /// changes: as `g_{k-1}` falls to 0, `beta -> 0` and `tau -> h_{k-1}`;
    /// on the other side the list stops one step earlier with `beta -> 1`
    /// and the same `tau`. What remains are points where two nodes of equal
    /// error swap their order at the last step; there `tau` moves by
    /// `beta` times the difference of the two candidate `h_k`.
    ///
    /// Cost: nodes with errors within the band are refined once more
    /// (partially). A budget caps the error list only; when it stops the cut
    /// there is no blending. If the blended bound misses the threshold (it
    /// can exceed the error list's when children's errors outweigh their
    /// parent's), the unblended result is returned. `band` must be finite and
    /// greater than 1 ([`ShadeError::InvalidBand`] otherwise). Measured on a
    /// street-light city along a scanline of 100,000 points (`cargo run
    /// --release --example seams`), band 2 makes the largest jump of the
    /// relative error 10 to 15 times smaller at thresholds of 1% to 20%, for
    /// about 1.25 times the evaluations and 1.45 times the time.
    pub const fn with_interpolation(mut self, band: f64) -> Self {
        self.band = Some(band);
        self
    }

    /// The interpolation band, if interpolation is on.
    pub const fn interpolation(&self) -> Option<f64> {
        self.band
    }

    /// The error target.
    pub const fn target(&self) -> Target {
        self.target
    }

    /// The maximal-contribution (specular) threshold, if any.
    pub const fn max_contribution(&self) -> Option<f64> {
        self.max_contribution
    }

    /// The budget, if any.
    pub const fn budget(&self) -> Option<u32> {
        self.budget
    }

    fn check(&self) -> Result<(), ShadeError> {
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

    #[inline]
    fn met(&self, estimate: DVec3, error: DVec3, largest: f64) -> bool {
        self.excess(estimate, error, largest) <= 0.0
    }

    /// How far the cut is from the target (`<= 0` when met), given the
    /// summed estimate and error and the largest single node error.
    #[inline]
    fn excess(&self, estimate: DVec3, error: DVec3, largest: f64) -> f64 {
        match self.target {
            Target::Absolute(t) => error.max_element() - t,
            Target::Relative(t) => error.max_element() - t * estimate.max_element(),
            Target::PerNode(t) => largest - t * estimate.max_element(),
        }
    }
}

/// Why the cut stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stop {
    /// The threshold was met: [`ShadeResult::error_bound`] satisfies it.
    ThresholdMet,
    /// The budget ran out first; the bound is still certified but may exceed
    /// the threshold (and is infinite if a node containing the shading point
    /// was left unrefined).
    Budget,
}

/// Radiance at a shading point with its certified error bound and its cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadeResult {
    /// Estimated RGB radiance.
    pub radiance: DVec3,
    /// Certified bound on `|radiance - exact|` per channel, up to
    /// [`ROUNDING_ALLOWANCE`](crate::ROUNDING_ALLOWANCE) of the exact value (see
    /// the crate docs).
    pub error_bound: DVec3,
    /// Node bounds computed.
    pub nodes_evaluated: u32,
    /// Single lights evaluated exactly.
    pub lights_evaluated: u32,
    /// Visibility classifications asked of the host.
    pub classify_queries: u32,
    /// Point-to-point visibility queries asked of the host (a standard ray
    /// tracer asks one per light).
    pub point_queries: u32,
    /// Why the cut stopped.
    pub stop: Stop,
}

impl ShadeResult {
    /// `nodes_evaluated + lights_evaluated`: the work, in the units of
    /// [`Threshold::with_budget`].
    pub fn cost(&self) -> u32 {
        self.nodes_evaluated + self.lights_evaluated
    }
}

/// Relative widening of the summed error bound for the rounding of its
/// compensated sum (a few ulps; 8 leaves margin).
const SUM_SLACK: f64 = 8.0 * f64::EPSILON;

/// Priority classes of the error list, refined in this order.
const CLASS_ERROR: u8 = 0;
/// Above the maximal-contribution threshold.
const CLASS_OVER_CONTRIBUTION: u8 = 1;
/// No finite bound: the node's ball reaches the shading point.
const CLASS_UNBOUNDED: u8 = 2;

/// An unrefined node of the cut.
#[derive(Clone, Copy, Debug)]
struct Entry {
    class: u8,
    /// Largest channel of the error bound: the error list's key.
    key: f64,
    node: u32,
    /// The node is known to be fully visible (no visibility query needed
    /// below it).
    visible: bool,
    estimate: DVec3,
    error: DVec3,
}

/// What the heap of the error list orders: an entry's class and key, and
/// where its record lies. Kept to 16 bytes so that sifting is cheap.
#[derive(Clone, Copy, Debug)]
struct Key {
    key: f64,
    slot: u32,
    class: u8,
}

impl PartialEq for Key {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Key {}
impl PartialOrd for Key {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Key {
    #[inline]
    fn cmp(&self, other: &Self) -> Ordering {
        self.class
            .cmp(&other.class)
            .then(self.key.total_cmp(&other.key))
    }
}

/// The paper's error list: unrefined nodes by decreasing (class, error),
/// their records in a side vector. Both keep their capacity across calls.
#[derive(Debug, Default)]
struct ErrorList {
    heap: BinaryHeap<Key>,
    entries: Vec<Entry>,
}

impl ErrorList {
    fn clear(&mut self) {
        self.heap.clear();
        self.entries.clear();
    }

    #[inline]
    fn push(&mut self, e: Entry) {
        let slot = self.entries.len() as u32;
        self.heap.push(Key {
            key: e.key,
            slot,
            class: e.class,
        });
        self.entries.push(e);
    }

    #[inline]
    fn peek(&self) -> Option<&Entry> {
        self.heap.peek().map(|k| &self.entries[k.slot as usize])
    }

    #[inline]
    fn pop(&mut self) -> Option<Entry> {
        self.heap.pop().map(|k| self.entries[k.slot as usize])
    }

    fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }

    /// The unrefined entries, in no particular order.
    fn iter(&self) -> impl Iterator<Item = &Entry> {
        self.heap.iter().map(|k| &self.entries[k.slot as usize])
    }
}

/// A shading session: a tree, a shader and reusable scratch space.
///
/// Create one per thread with [`LightTree::shading`]; after the first few
/// calls have grown its scratch, shading allocates nothing.
///
/// The view-less calls ([`shade`](Self::shade),
/// [`shade_exact`](Self::shade_exact) and their `_occluded` forms) exist only
/// for [`ViewIndependent`] shaders, so a view-dependent shader such as
/// [`Phong`](crate::Phong) cannot be called without a view.
#[derive(Debug)]
pub struct Shading<'t, S: Shader> {
    tree: &'t LightTree,
    shader: S,
    list: ErrorList,
    blend_stack: Vec<(u32, f64, bool)>,
}

impl LightTree {
    /// A shading session for `shader` over this tree.
    pub fn shading<S: Shader>(&self, shader: S) -> Shading<'_, S> {
        Shading {
            tree: self,
            shader,
            list: ErrorList::default(),
            blend_stack: Vec::new(),
        }
    }
}

/// Neumaier-compensated sum of `DVec3`s: accurate to about two ulps of the
/// sum of magnitudes, whatever the number of terms.
#[derive(Clone, Copy, Default)]
pub(crate) struct CompensatedSum {
    sum: DVec3,
    compensation: DVec3,
}

impl CompensatedSum {
    #[inline]
    pub(crate) fn add(&mut self, term: DVec3) {
        let t = self.sum + term;
        let big = self.sum.abs().cmpge(term.abs());
        self.compensation += DVec3::select(big, (self.sum - t) + term, (term - t) + self.sum);
        self.sum = t;
    }

    #[inline]
    pub(crate) fn value(&self) -> DVec3 {
        self.sum + self.compensation
    }
}

/// Counters and sums of one call.
#[derive(Default)]
struct Tally {
    /// Exact leaves and nodes that need no refinement.
    settled: CompensatedSum,
    estimate: DVec3,
    error: DVec3,
    nodes: u32,
    lights: u32,
    classify: u32,
    point: u32,
    over_contribution: u32,
    unbounded: u32,
}

fn surface(point: Vec3, normal: Vec3, view: Option<Vec3>) -> Result<Surface, ShadeError> {
    if !point.is_finite() {
        return Err(ShadeError::NonFinitePoint);
    }
    let unit = |v: Vec3| -> Option<DVec3> {
        let v = v.as_dvec3();
        let len = v.length();
        (len.is_finite() && len > 0.0).then(|| v / len)
    };
    let normal = unit(normal).ok_or(ShadeError::InvalidNormal)?;
    let view = match view {
        Some(v) => unit(v).ok_or(ShadeError::InvalidView)?,
        None => DVec3::ZERO,
    };
    Ok(Surface {
        point: point.as_dvec3(),
        normal,
        view,
    })
}

impl<'t, S: Shader> Shading<'t, S> {
    /// The tree.
    pub fn tree(&self) -> &'t LightTree {
        self.tree
    }

    /// The shader.
    pub fn shader(&self) -> &S {
        &self.shader
    }

    /// Shades `point` seen from direction `view` (towards the eye), with no
    /// occluders.
    ///
    /// Normals and views are normalized; see [`shade`](Self::shade).
    ///
    /// # Errors
    /// As [`shade`](Self::shade), plus [`ShadeError::InvalidView`].
    pub fn shade_view(
        &mut self,
        point: Vec3,
        normal: Vec3,
        view: Vec3,
        threshold: Threshold,
    ) -> Result<ShadeResult, ShadeError> {
        self.run(point, normal, Some(view), threshold, &mut Unoccluded)
    }

    /// [`shade_view`](Self::shade_view) with the host's visibility.
    ///
    /// # Errors
    /// As [`shade_view`](Self::shade_view).
    pub fn shade_view_occluded<V: Visibility>(
        &mut self,
        point: Vec3,
        normal: Vec3,
        view: Vec3,
        threshold: Threshold,
        visibility: &mut V,
    ) -> Result<ShadeResult, ShadeError> {
        self.run(point, normal, Some(view), threshold, visibility)
    }

    /// The exact model summed over every light, seen from `view`.
    ///
    /// # Errors
    /// [`ShadeError::NonFinitePoint`], [`ShadeError::InvalidNormal`],
    /// [`ShadeError::InvalidView`].
    pub fn shade_exact_view(
        &self,
        point: Vec3,
        normal: Vec3,
        view: Vec3,
    ) -> Result<DVec3, ShadeError> {
        self.exact(point, normal, Some(view), &mut Unoccluded)
    }

    /// [`shade_exact_view`](Self::shade_exact_view) with point-to-point
    /// visibility `V_i` from the host for every light.
    ///
    /// # Errors
    /// As [`shade_exact_view`](Self::shade_exact_view).
    pub fn shade_exact_view_occluded<V: Visibility>(
        &self,
        point: Vec3,
        normal: Vec3,
        view: Vec3,
        visibility: &mut V,
    ) -> Result<DVec3, ShadeError> {
        self.exact(point, normal, Some(view), visibility)
    }

    fn exact<V: Visibility>(
        &self,
        point: Vec3,
        normal: Vec3,
        view: Option<Vec3>,
        visibility: &mut V,
    ) -> Result<DVec3, ShadeError> {
        let surface = surface(point, normal, view)?;
        let frame = self.shader.frame(&surface);
        let mut sum = CompensatedSum::default();
        for light in &self.tree.lights {
            if !V::ALWAYS_VISIBLE && !visibility.visible(point, light.position) {
                continue;
            }
            let term = self.shader.eval(
                &frame,
                &surface,
                light.position.as_dvec3(),
                light.intensity.as_dvec3(),
            );
            sum.add(term);
        }
        Ok(sum.value())
    }

    /// Evaluates node `index` entering the cut with blend weight `weight`:
    /// settles it into `call.tally.settled` (exact single lights, dark,
    /// occluded or error-free nodes), or returns it as an unrefined entry.
    #[inline]
    fn evaluate<V: Visibility>(
        &self,
        index: usize,
        mut visible: bool,
        weight: f64,
        call: &mut Call<'_, S::Frame, V>,
    ) -> Option<Entry> {
        let node: &Node = &self.tree.nodes[index];
        if node.intensity == DVec3::ZERO {
            // Dark node: exactly zero whatever its geometry, even when its
            // ball holds the shading point; no query is needed.
            return None;
        }
        if node.light_count == 1 {
            let light = self.tree.lights[node.first_light as usize];
            self.exact_light(light.position, light.intensity, visible, weight, call);
            return None;
        }
        let mut partial = false;
        if !V::ALWAYS_VISIBLE && !visible {
            call.tally.classify += 1;
            match call
                .visibility
                .classify(call.point, &node_bounds(self.tree, index))
            {
                Coverage::Occluded => return None,
                Coverage::Visible => visible = true,
                Coverage::Partial => partial = true,
            }
        }
        call.tally.nodes += 1;
        let Some(cone) = Cone::new(call.surface.point, node) else {
            return Some(Entry {
                class: CLASS_UNBOUNDED,
                key: f64::INFINITY,
                node: index as u32,
                visible,
                estimate: DVec3::ZERO,
                error: DVec3::ZERO,
            });
        };
        let mut bound = self.shader.bound(&call.frame, &call.surface, node, &cone);
        if partial {
            // Partially occluded: anything between 0 and the unoccluded upper
            // bound. The host's visible fraction only moves the estimate.
            let fraction = call
                .visibility
                .visible_fraction(call.point, &node_bounds(self.tree, index));
            let estimate = match fraction {
                Some(f) if f.is_finite() => bound.estimate * f64::from(f.clamp(0.0, 1.0)),
                _ => 0.5 * bound.upper,
            };
            bound = NodeBound::new(estimate, DVec3::ZERO, bound.upper);
        }
        let error = bound.error();
        let key = error.max_element();
        let over = call
            .max_contribution
            .is_some_and(|m| bound.upper.max_element() > m);
        if key <= 0.0 && !over {
            // Nothing to gain by refining (e.g. below the horizon).
            call.tally.settled.add(bound.estimate * weight);
            return None;
        }
        Some(Entry {
            class: if over {
                CLASS_OVER_CONTRIBUTION
            } else {
                CLASS_ERROR
            },
            key,
            node: index as u32,
            visible,
            estimate: bound.estimate,
            error,
        })
    }

    /// Adds one light's exact contribution, times `weight`, asking the host
    /// for point-to-point visibility unless the light is known visible.
    #[inline]
    fn exact_light<V: Visibility>(
        &self,
        position: Vec3,
        intensity: Vec3,
        visible: bool,
        weight: f64,
        call: &mut Call<'_, S::Frame, V>,
    ) {
        if !V::ALWAYS_VISIBLE && !visible {
            call.tally.point += 1;
            if !call.visibility.visible(call.point, position) {
                return;
            }
        }
        call.tally.lights += 1;
        let value = self.shader.eval(
            &call.frame,
            &call.surface,
            position.as_dvec3(),
            intensity.as_dvec3(),
        );
        call.tally.settled.add(value * weight);
    }

    /// Refines `node`: its lights exactly if it is a leaf, its children
    /// otherwise, each with blend weight `weight`; children that need
    /// refinement are passed to `pending`.
    #[inline]
    fn refine<V: Visibility>(
        &self,
        node: &Node,
        visible: bool,
        weight: f64,
        call: &mut Call<'_, S::Frame, V>,
        mut pending: impl FnMut(Entry, &mut Call<'_, S::Frame, V>),
    ) {
        if node.is_leaf() {
            for k in node.lights() {
                let l = self.tree.lights[k];
                self.exact_light(l.position, l.intensity, visible, weight, call);
            }
        } else {
            for child in node.children() {
                if let Some(entry) = self.evaluate(child, visible, weight, call) {
                    pending(entry, call);
                }
            }
        }
    }

    /// Sums of the error list, recomputed from scratch (the running sums
    /// subtract and may drift).
    fn heap_sums(&self) -> (DVec3, DVec3) {
        let mut estimate = CompensatedSum::default();
        let mut error = CompensatedSum::default();
        for e in self.list.iter() {
            estimate.add(e.estimate);
            error.add(e.error);
        }
        (estimate.value(), error.value())
    }

    fn run<V: Visibility>(
        &mut self,
        point: Vec3,
        normal: Vec3,
        view: Option<Vec3>,
        threshold: Threshold,
        visibility: &mut V,
    ) -> Result<ShadeResult, ShadeError> {
        threshold.check()?;
        let surface = surface(point, normal, view)?;
        let mut call = Call {
            frame: self.shader.frame(&surface),
            surface,
            point,
            max_contribution: threshold.max_contribution,
            visibility,
            tally: Tally::default(),
        };
        let mut heap = core::mem::take(&mut self.list);
        heap.clear();
        // Adds an entry to the error list and the running sums.
        let push = |heap: &mut ErrorList, e: Entry, tally: &mut Tally| {
            match e.class {
                CLASS_UNBOUNDED => tally.unbounded += 1,
                CLASS_OVER_CONTRIBUTION => tally.over_contribution += 1,
                _ => {}
            }
            tally.estimate += e.estimate;
            tally.error += e.error;
            heap.push(e);
        };
        if !self.tree.nodes.is_empty()
            && let Some(root) = self.evaluate(0, false, 1.0, &mut call)
        {
            push(&mut heap, root, &mut call.tally);
        }
        let budget = threshold.budget.unwrap_or(u32::MAX).max(1);
        let mut stop = Stop::ThresholdMet;
        // The excess before, and the key of, the last refinement: they place
        // the interpolation level between the last two steps.
        let mut last_step: Option<(f64, f64)> = None;
        loop {
            let t = &mut call.tally;
            let largest = heap.peek().map_or(0.0, |e| e.key);
            if t.unbounded == 0
                && t.over_contribution == 0
                && threshold.met(t.settled.value() + t.estimate, t.error, largest)
            {
                self.list = heap;
                (t.estimate, t.error) = self.heap_sums();
                heap = core::mem::take(&mut self.list);
                if threshold.met(t.settled.value() + t.estimate, t.error, largest) {
                    break;
                }
            }
            let Some(top) = heap.peek().copied() else {
                break;
            };
            let node = self.tree.nodes[top.node as usize];
            let cost = if node.is_leaf() {
                node.light_count
            } else {
                node.child_count
            };
            if t.nodes.saturating_add(t.lights).saturating_add(cost) > budget {
                stop = Stop::Budget;
                break;
            }
            heap.pop();
            last_step = Some((
                threshold.excess(t.settled.value() + t.estimate, t.error, largest),
                top.key,
            ));
            match top.class {
                CLASS_UNBOUNDED => t.unbounded -= 1,
                CLASS_OVER_CONTRIBUTION => t.over_contribution -= 1,
                _ => {}
            }
            t.estimate -= top.estimate;
            t.error -= top.error;
            self.refine(&node, top.visible, 1.0, &mut call, |e, call| {
                push(&mut heap, e, &mut call.tally)
            });
        }
        self.list = heap;
        let (estimate, error) = self.heap_sums();
        let unbounded = call.tally.unbounded > 0;
        let mut radiance = call.tally.settled.value() + estimate;
        let mut error = error;
        if let (Some(band), Stop::ThresholdMet) = (threshold.band, stop) {
            // The level: between the last refined key (where the error list
            // would have stopped one step earlier) and the largest key left,
            // in proportion to where the excess crossed zero, so that it is
            // continuous where the stopping step changes.
            let top = self.list.peek().map_or(0.0, |e| e.key);
            let level = match last_step {
                Some((before, key)) if before > 0.0 && before.is_finite() => {
                    let after = threshold.excess(radiance, error, top);
                    let beta = (before / (before - after)).clamp(0.0, 1.0);
                    key + beta * (top - key)
                }
                _ => top,
            };
            // The blend refines no node less than the error list did, so the
            // largest single error cannot grow; only the sum is re-checked.
            if let Some((r, e)) = self.blend(level, band, &mut call)
                && threshold.met(r, e, 0.0)
            {
                (radiance, error) = (r, e);
            }
        }
        // The compensated sums are within a few ulps of the sums of
        // magnitudes: what that leaves of the estimate's rounding is within
        // ROUNDING_ALLOWANCE of the exact value (terms are non-negative); the
        // error sum's own rounding is folded in here.
        let error_bound = if unbounded {
            DVec3::INFINITY
        } else {
            error * (1.0 + SUM_SLACK)
        };
        let t = &call.tally;
        Ok(ShadeResult {
            radiance,
            error_bound,
            nodes_evaluated: t.nodes,
            lights_evaluated: t.lights,
            classify_queries: t.classify,
            point_queries: t.point,
            stop,
        })
    }

    /// Interpolation across levels (see [`Threshold::with_interpolation`]):
    /// blends every unrefined node whose error lies within `band` of the
    /// error list's final level with its children, recursively. Returns the
    /// blended radiance and error bound, or `None` when there is nothing to
    /// blend. Consumes the error list.
    fn blend<V: Visibility>(
        &mut self,
        level: f64,
        band: f64,
        call: &mut Call<'_, S::Frame, V>,
    ) -> Option<(DVec3, DVec3)> {
        if self.list.is_empty() || !(level > 0.0 && level.is_finite()) {
            return None;
        }
        let floor = level / band;
        let ramp = |key: f64| ((key - floor) / (level - floor)).clamp(0.0, 1.0);
        let mut estimate = CompensatedSum::default();
        let mut error = CompensatedSum::default();
        let mut stack = core::mem::take(&mut self.blend_stack);
        stack.clear();
        // Each pending node carries the product of the refinement weights of
        // its ancestors; its own share (1 - alpha) keeps its virtual-light
        // estimate and the rest (alpha) goes to its children.
        let mut settle = |e: Entry, weight: f64, stack: &mut Vec<(u32, f64, bool)>| {
            let alpha = if e.class == CLASS_UNBOUNDED {
                1.0
            } else {
                ramp(e.key)
            };
            estimate.add(e.estimate * (weight * (1.0 - alpha)));
            error.add(e.error * (weight * (1.0 - alpha)));
            if alpha > 0.0 {
                stack.push((e.node, weight * alpha, e.visible));
            }
        };
        for k in self.list.heap.drain() {
            settle(self.list.entries[k.slot as usize], 1.0, &mut stack);
        }
        while let Some((index, weight, visible)) = stack.pop() {
            let node = self.tree.nodes[index as usize];
            self.refine(&node, visible, weight, call, |e, _| {
                settle(e, weight, &mut stack)
            });
        }
        self.blend_stack = stack;
        Some((call.tally.settled.value() + estimate.value(), error.value()))
    }
}

/// The state of one shading call.
struct Call<'v, F, V> {
    surface: Surface,
    frame: F,
    point: Vec3,
    max_contribution: Option<f64>,
    visibility: &'v mut V,
    tally: Tally,
}

fn node_bounds(tree: &LightTree, index: usize) -> NodeBounds {
    let node = &tree.nodes[index];
    NodeBounds {
        index: index as u32,
        aabb: node.bbox,
        centroid: node.centroid,
        radius: node.radius,
        light_count: node.light_count,
    }
}

impl<S: ViewIndependent> Shading<'_, S> {
    /// Shades `point` with unit-or-not `normal` (normalized here), with no
    /// occluders, refining the cut until `threshold` is met.
    ///
    /// # Errors
    /// [`ShadeError::NonFinitePoint`], [`ShadeError::InvalidNormal`] (zero or
    /// non-finite normal), [`ShadeError::InvalidThreshold`] (NaN or negative).
    pub fn shade(
        &mut self,
        point: Vec3,
        normal: Vec3,
        threshold: Threshold,
    ) -> Result<ShadeResult, ShadeError> {
        self.run(point, normal, None, threshold, &mut Unoccluded)
    }

    /// [`shade`](Self::shade) with the host's visibility.
    ///
    /// # Errors
    /// As [`shade`](Self::shade).
    pub fn shade_occluded<V: Visibility>(
        &mut self,
        point: Vec3,
        normal: Vec3,
        threshold: Threshold,
        visibility: &mut V,
    ) -> Result<ShadeResult, ShadeError> {
        self.run(point, normal, None, threshold, visibility)
    }

    /// The exact model (crate docs, "The model") summed over every light in
    /// `f64` with compensated summation: the reference `shade` is certified
    /// against.
    ///
    /// # Errors
    /// [`ShadeError::NonFinitePoint`], [`ShadeError::InvalidNormal`].
    pub fn shade_exact(&self, point: Vec3, normal: Vec3) -> Result<DVec3, ShadeError> {
        self.exact(point, normal, None, &mut Unoccluded)
    }

    /// [`shade_exact`](Self::shade_exact) with point-to-point visibility.
    ///
    /// # Errors
    /// As [`shade_exact`](Self::shade_exact).
    pub fn shade_exact_occluded<V: Visibility>(
        &self,
        point: Vec3,
        normal: Vec3,
        visibility: &mut V,
    ) -> Result<DVec3, ShadeError> {
        self.exact(point, normal, None, visibility)
    }
}
