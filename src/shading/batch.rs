//! Batch shading: one certified cut shared by each group of neighbouring
//! points, each point summing that cut's estimates at its own position and
//! normal.

use core::ops::Range;
#[cfg(feature = "rayon")]
use core::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
#[cfg(feature = "rayon")]
use std::sync::{Mutex, OnceLock};

use glam::{DVec3, Vec3};

use super::blend;
use super::error_list::{Class, Entry, ErrorList, Seen};
use super::grouping::{GROUP_NORMAL_SPREAD, Groups, groups, points_box};
use super::packed::{Limits, Packed, Spread};
use super::refine::{region, reported_bound};
use super::{Accepts, Query, ShadeResult, Shading, Stop, Target, Threshold};
use crate::ShadeError;
use crate::geometry::{Aabb, Cone, Surface};
use crate::lambert::{SharedView, shared_width, shared_widths};
use crate::lanes::array;
use crate::numeric::{
    CompensatedSum, DISTANCE_SLACK, POINT_SLACK, SECOND_ORDER_SLACK, SERIES_SLACK,
};
use crate::shader::Shader;
use crate::tree::{LightTree, MAX_CHILDREN, Node};
use crate::visibility::{Coverage, NodeRegion, PointGroup, Visibility};

/// What a batch call did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct BatchStats {
    /// Groups of points that shared a cut.
    pub groups: u32,
    /// Points shaded through a shared cut.
    pub shared_points: u32,
    /// Points shaded on their own: all of them when the call cannot share
    /// (see [`Shading::shade_batch`]), else those of groups too scattered to
    /// share and those whose own check missed the threshold.
    pub points_alone: u32,
    /// Node bounds computed for the shared cuts (each point's own work is in
    /// its [`ShadeResult`]).
    pub shared_evaluations: u64,
    /// Classifications asked of the host for whole groups
    /// ([`Visibility::classify_group`]).
    pub shared_classifications: u64,
}

impl core::ops::AddAssign for BatchStats {
    fn add_assign(&mut self, other: Self) {
        self.groups += other.groups;
        self.shared_points += other.shared_points;
        self.points_alone += other.points_alone;
        self.shared_evaluations += other.shared_evaluations;
        self.shared_classifications += other.shared_classifications;
    }
}

/// With interpolation, a group's cut also serves the points of other groups
/// within this share of the largest side of its points' box (its halo), and
/// each point blends the results of its own group and of the groups whose
/// halo holds it (see [`blend_halos`]). A group of 128 pixels is about 11
/// pixels across, so a quarter blends over about 3 pixels on each side of
/// a border. On a scanline of 128-point groups, a sixteenth left jumps of
/// 2.2e-5, an eighth 1.2e-5, a quarter 7.0e-6; over a 128 x 16 patch of
/// points (borders along both axes) an eighth left 3.4e-5, three
/// sixteenths 2.0e-5, a quarter 1.4e-5 (point-by-point interpolation:
/// 2.6e-5 on the scanline). On a 320 x 180 camera view of the street city
/// at 10^6 lights an interpolated call took 2.4, 2.9 and 3.6 us per pixel
/// (2.0 with no halo), in scratch timings of an earlier version; the
/// current one takes 4.0 us with a quarter and 2.3 us with no halo.
const HALO_SHARE: f64 = 0.25;
/// Fewest points worth a shared cut: smaller groups are shaded point by
/// point.
const GROUP_MIN_POINTS: usize = 4;
/// What a group's shared cut may cost, per point, before the group is
/// shaded point by point: this share of what a point shaded on its own
/// costs (node bounds, single lights and host queries), as measured on the
/// points shaded alone so far in the chunk of groups; at least
/// [`MIN_BUDGET_PER_POINT`]. (At 10^6 lights, certified 1%: 1.44-1.46 us
/// per pixel with 0.6, 1.53 with 0.4, 1.56-1.58 with 0.25, and no gain
/// from 0.8 to 1.5; the `city` example about the same with 0.4 and 0.6,
/// slower with 1.0.)
const BUDGET_SHARE: f64 = 0.6;
const MIN_BUDGET_PER_POINT: u64 = 32;
/// Groups shaded with one running estimate of the cost of a point shaded
/// alone, started afresh for each chunk (so that a batch shaded over
/// threads, chunk by chunk, gives the same results). Chunks are what the
/// threads take, one at a time as each finishes its last, so they are
/// small: a few groups cost far more than the rest, and a chunk should not
/// tie them to others. One group a chunk: each group's first cut then
/// starts from the least budget (about 2% more time on one thread than
/// chunks of 4, from more points shaded alone).
const CHUNK_RUNS: usize = 1;
/// Entries a point sums over a shared cut in the time of one shared node
/// bound (measured: about 50 instructions an entry, 1,500 a bound).
const ENTRIES_PER_BOUND: u64 = 32;
/// Lights a point shaded alone evaluates exactly in the time of one node
/// bound, in the estimate of what a point costs alone.
const LIGHTS_PER_BOUND: f64 = 4.0;
/// Most entries in a shared cut: the lanes' sums are certified up to
/// `2^16` terms (see `packed_bound`).
const MAX_CUT_ITEMS: usize = 1 << 15;
/// The shared cut aims at this fraction of the representative point's
/// estimate for a relative target, leaving room for points darker than it.
const FIRST_MARGIN: f64 = 0.9;
/// Rounds of further refinement for the points of a group that missed
/// their target, before they are shaded on their own.
const ROUNDS: usize = 3;

/// The points of a group: indices into the queries, the points of other
/// groups in its halo with their blend weights, and the group's place in
/// the batch's list of groups.
#[derive(Clone, Copy, Debug)]
struct Members<'a> {
    points: &'a [u32],
    halo: &'a [(u32, f64)],
    run: u32,
}

/// A group's halo: points of other groups (indices into the queries) with
/// their blend weights.
type Halo = Vec<(u32, f64)>;

/// Sets its flag when dropped.
#[cfg(feature = "rayon")]
struct Leaving<'a>(&'a AtomicBool);

#[cfg(feature = "rayon")]
impl Drop for Leaving<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

/// What the workers of a parallel call share once the groups are formed.
#[cfg(feature = "rayon")]
struct Setup {
    /// The queries in Morton order.
    order: Vec<u32>,
    /// The groups, ranges of `order`.
    runs: Vec<Range<usize>>,
    /// Each group's halo.
    halos: Vec<Halo>,
    /// The chunks in the order the workers take them, by index.
    queue: Vec<(f64, usize)>,
}

#[cfg(feature = "rayon")]
impl Setup {
    /// The groups of chunk `k` (the chunks of `shade_batch`).
    fn chunk(&self, k: usize) -> &[Range<usize>] {
        self.runs.chunks(CHUNK_RUNS).nth(k).unwrap_or_default()
    }
}

/// The caller's results, written by the workers of a parallel call in
/// place, each at the indices of the chunks it took.
///
/// Writing through a pointer is one of the crate's unsafe blocks
/// (`shade_batch_parallel` allows it for that one closure): the
/// chunks' points are disjoint (the groups split a permutation of the
/// queries), each chunk is taken by one worker, so no two threads write one
/// result and none reads them, and the slice is borrowed mutably for as
/// long as the workers run. Gathering results written in Morton order
/// instead cost 0.5-1 ms after the workers (random reads of 80-byte
/// results), and filling that buffer 0.15 ms before them, of a 30-40 ms
/// call on two threads; writing in place, the call took 1.8% less time
/// (median of 25 paired rounds at 10^6 lights, certified 1%), and it
/// allocates no second set of results.
#[cfg(feature = "rayon")]
struct Output<'a> {
    start: *mut ShadeResult,
    len: usize,
    results: core::marker::PhantomData<&'a mut [ShadeResult]>,
}

// SAFETY: see `Output`: the workers write disjoint results.
#[cfg(feature = "rayon")]
#[allow(unsafe_code)]
unsafe impl Sync for Output<'_> {}

#[cfg(feature = "rayon")]
impl<'a> Output<'a> {
    fn new(results: &'a mut [ShadeResult]) -> Self {
        Self {
            start: results.as_mut_ptr(),
            len: results.len(),
            results: core::marker::PhantomData,
        }
    }

    /// Writes result `i`.
    ///
    /// # Safety
    /// No other thread reads or writes result `i` meanwhile.
    #[allow(unsafe_code)]
    unsafe fn write(&self, i: usize, result: ShadeResult) {
        assert!(i < self.len, "a result within the batch");
        // SAFETY: `i` is in bounds, the slice is borrowed for `'a`, and the
        // caller writes it alone.
        unsafe { self.start.add(i).write(result) };
    }
}

/// A group's result for a point of its halo, with its blend weight.
#[derive(Clone, Copy, Debug)]
struct HaloResult {
    point: u32,
    run: u32,
    weight: f64,
    result: ShadeResult,
}

/// What shading groups gives besides each point's own result.
#[derive(Debug, Default)]
struct Outcome {
    stats: BatchStats,
    halo: Vec<HaloResult>,
}

/// Where a group of points lies: a ball of points and a cone of normals,
/// all widened for rounding.
#[derive(Clone, Copy, Debug)]
struct Group {
    centre: DVec3,
    /// Unit (to rounding) mean normal `n0`.
    normal: DVec3,
    /// Every point lies within this distance of `centre`.
    radius: f64,
    /// Largest `n0 . (p - centre)` over the points, at least 0.
    rise: f64,
    /// Largest `n0 . (centre - p)` over the points, at least 0.
    drop: f64,
    /// Largest `|n_p - n0|` over the points' exact unit normals.
    tilt: f64,
    /// The points as the host sees them.
    region: PointGroup,
}

impl Group {
    fn new(surfaces: impl Iterator<Item = Surface> + Clone) -> Self {
        let (mut sum_p, mut sum_n, mut count) = (DVec3::ZERO, DVec3::ZERO, 0.0);
        let mut first_normal = DVec3::Z;
        for s in surfaces.clone() {
            if count == 0.0 {
                first_normal = s.normal;
            }
            sum_p += s.point;
            sum_n += s.normal;
            count += 1.0;
        }
        let centre = sum_p / count;
        let normal = sum_n.try_normalize().unwrap_or(first_normal);
        let (mut radius, mut rise, mut drop, mut tilt) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        let mut count = 0;
        for s in surfaces {
            let at = s.point.as_vec3();
            (lo, hi, count) = (lo.min(at), hi.max(at), count + 1);
            let offset = s.point - centre;
            radius = radius.max(offset.length());
            let height = normal.dot(offset);
            rise = rise.max(height);
            drop = drop.max(-height);
            tilt = tilt.max((s.normal - normal).length());
        }
        // Lengths and dots of f64 differences: a few ulps of the magnitudes
        // involved; the surfaces' unit normals are within a few ulps of the
        // exact ones.
        let pad = 8.0 * f64::EPSILON * (centre.abs().max_element() + radius);
        Self {
            centre,
            normal,
            radius: radius * (1.0 + DISTANCE_SLACK) + pad,
            rise: rise * (1.0 + DISTANCE_SLACK) + pad,
            drop: drop * (1.0 + DISTANCE_SLACK) + pad,
            tilt: tilt * (1.0 + DISTANCE_SLACK) + 16.0 * f64::EPSILON,
            region: PointGroup {
                aabb: Aabb { min: lo, max: hi },
                count,
            },
        }
    }

    /// What every point of the group sees of `node`, at centroid distance
    /// `distance` from the centre, for [`shared_width`]: the heights
    /// `n . (c - p)` are within `|n0 . (c - centre)| + max(rise, drop) +
    /// tilt |c - p|` and `|c - p| <= distance + radius`, so `|c0|` is at most
    /// that over the nearest distance; the box's heights about the centroid
    /// along `n0` bound `|n0 . (x - c)|`.
    #[inline(always)]
    fn view(&self, node: &Node, inv_nearest: f64, distance: f64) -> SharedView {
        let centroid = node.centroid.as_dvec3();
        let far = (distance + self.radius) * (1.0 + DISTANCE_SLACK);
        let centre_height = self.normal.dot(centroid - self.centre).abs();
        let height = centre_height + self.rise.max(self.drop) + self.tilt * far;
        let cosine = height * (1.0 + DISTANCE_SLACK) * inv_nearest
            + 16.0 * f64::EPSILON * (centroid.abs().max_element() + far) * inv_nearest;
        let (lo, hi) = node
            .aabb
            .extent_along(centroid, self.normal, SECOND_ORDER_SLACK);
        SharedView {
            inv_nearest,
            cosine,
            height: lo.abs().max(hi.abs()),
            tilt: self.tilt,
        }
    }

    /// Where members boxed by `aabb` within `reach` of every point lie
    /// against every point's tangent plane.
    ///
    /// For a point `p` with unit normal `n` and a member `x`,
    /// `n.(x - p) = n0.(x - c) + n0.(c - p) + (n - n0).(x - p)`: the first
    /// term ranges over the box's extent along `n0`, the second over
    /// `[-rise, drop]`, the third within `tilt * |x - p|`.
    #[inline(always)]
    fn side(&self, aabb: &Aabb, reach: f64) -> Side {
        let (lo, hi) = aabb.extent_along(self.centre, self.normal, SECOND_ORDER_SLACK);
        self.side_of(lo, hi, reach)
    }

    /// [`side`](Self::side) for members whose heights `n0 . (x - centre)`
    /// lie in `[lo, hi]` up to the rounding of an `f64` dot product of
    /// a difference (covered by the margin).
    #[inline(always)]
    fn side_of(&self, lo: f64, hi: f64, reach: f64) -> Side {
        let spread = self.tilt * reach * (1.0 + DISTANCE_SLACK);
        let margin =
            16.0 * f64::EPSILON * (lo.abs() + hi.abs() + self.rise + self.drop + spread + reach);
        let lowest = lo - self.rise - spread - margin;
        if lowest > 0.0 {
            Side::Above(lowest)
        } else if hi + self.drop + spread + margin < 0.0 {
            Side::Below
        } else {
            Side::Across(lowest)
        }
    }

    /// A lower bound on the distance from every point to a member at least
    /// `distance` from the centre and at least `lowest` above every
    /// tangent plane (a unit normal's height is at most the distance).
    #[inline(always)]
    fn nearest(&self, distance: f64, lowest: f64) -> f64 {
        (distance * (1.0 - DISTANCE_SLACK) - self.radius).max(lowest)
    }
}

/// Where members lie against the tangent planes of a group's points.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Side {
    /// Strictly above every plane, each member at least this high.
    Above(f64),
    /// Strictly below every plane: they contribute exactly 0.
    Below,
    /// On both sides of some plane, reaching at most this far (negated)
    /// below any.
    Across(f64),
}

/// Points of a group whose estimates steer the shared cut's relative
/// target: at most [`SAMPLES`] spread along the group's Morton order.
#[derive(Clone, Copy, Debug)]
struct Samples {
    /// Points and unit normals, by coordinate (so that the four samples'
    /// values are computed side by side).
    points: [[f64; SAMPLES]; 3],
    normals: [[f64; SAMPLES]; 3],
}

/// Points steering a shared cut.
const SAMPLES: usize = 4;

impl Samples {
    fn new<M>(queries: &[Query<M>], members: &[u32]) -> Self {
        let last = members.len() - 1;
        let pick = |k: usize| queries[members[k * last / (SAMPLES - 1)] as usize].surface();
        Self {
            points: core::array::from_fn(|axis| core::array::from_fn(|k| pick(k).point[axis])),
            normals: core::array::from_fn(|axis| core::array::from_fn(|k| pick(k).normal[axis])),
        }
    }

    /// A virtual light's value `I kd max(0, n.w) / d^2` at each sample
    /// (`intensity` already times `kd`): an estimate good enough to steer.
    #[inline(always)]
    fn values(&self, position: DVec3, intensity: DVec3) -> [DVec3; SAMPLES] {
        let mut g = [0.0f64; SAMPLES];
        for (k, g) in g.iter_mut().enumerate() {
            let u = [
                position.x - self.points[0][k],
                position.y - self.points[1][k],
                position.z - self.points[2][k],
            ];
            let d2 = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
            let height =
                self.normals[0][k] * u[0] + self.normals[1][k] * u[1] + self.normals[2][k] * u[2];
            // A light on a sample (d = 0) counts 0.
            let value = height.max(0.0) / (d2 * d2.sqrt());
            *g = if d2 > 0.0 { value } else { 0.0 };
        }
        g.map(|g| intensity * g)
    }
}

/// The sum of the darkest sample (smallest largest channel).
#[inline(always)]
fn darkest(sums: &[DVec3; SAMPLES]) -> DVec3 {
    let mut least = sums[0];
    for s in &sums[1..] {
        if s.max_element() < least.max_element() {
            least = *s;
        }
    }
    least
}

/// What a shared cut holds and what it has spent, kept between calls.
#[derive(Debug, Default)]
pub(crate) struct BatchScratch {
    list: ErrorList,
    /// Single lights of the cut on both sides of some tangent plane,
    /// evaluated exactly at each point: position and intensity.
    lights: Vec<(DVec3, DVec3)>,
    /// Single lights of the cut that the host saw partially from the
    /// group: asked point-to-point and evaluated exactly at each point.
    shadowed: Vec<(DVec3, DVec3)>,
    /// Single lights of the cut above every tangent plane: position,
    /// intensity times `kd`.
    above: Vec<(DVec3, DVec3)>,
    /// The nodes and the lights above every plane, packed for the points'
    /// sums.
    packed: Packed,
    /// Nodes of a blended cut with their weights.
    weighted: Vec<(u32, f64)>,
    /// Each entry's values at the samples, by slot.
    steer: Vec<[DVec3; SAMPLES]>,
    /// Each member's result in the current round, and whether it missed
    /// its target (to be shaded on its own).
    results: Vec<ShadeResult>,
    alone: Vec<bool>,
    /// The halo points' results over the group's cut, in the current round.
    halo_results: Vec<ShadeResult>,
    /// Nodes a blend still has to refine: index, weight, known visible.
    blending: Vec<(u32, f64, bool)>,
    /// Running estimate of what a point shaded alone costs (0: none yet).
    alone_cost: f64,
}

/// One group's cut in the making.
struct SharedCut<'a, V> {
    tree: &'a LightTree,
    visibility: &'a mut V,
    classifications: u64,
    kd: DVec3,
    group: Group,
    /// The points whose estimates steer a relative target.
    samples: Samples,
    /// The samples' values of the cut's single lights.
    steer_settled: [DVec3; SAMPLES],
    /// The summed errors of the single lights above every plane (times
    /// `kd`), summed plainly (see [`packed_bound`]).
    light_error: DVec3,
    /// How far the entries that may be packed lie from the group.
    spread: Spread,
    /// Running sums of the samples' values of the waiting entries.
    steer_waiting: [DVec3; SAMPLES],
    evaluations: u64,
    /// Points in the group.
    points: u64,
    /// What the cut may cost per point (see [`BUDGET_SHARE`]).
    budget_per_point: u64,
    /// The excess over the target before the last refinement and that
    /// node's key, and the excess where the loop stopped: they place the
    /// interpolation level.
    last_step: Option<(f64, f64)>,
    after: f64,
}

/// What a blend of a shared cut added, to take it out again, and the
/// blended nodes' summed error.
#[derive(Clone, Copy, Debug)]
struct Blend {
    /// Lengths of the cut's three lists of single lights before the blend.
    lights: (usize, usize, usize),
    light_error: DVec3,
    steer: [DVec3; SAMPLES],
    error: DVec3,
}

/// A node entering a shared cut.
#[derive(Clone, Copy, Debug)]
struct Entering {
    /// Visible from every point of the group.
    visible: bool,
    /// The shared error, for a node the shared bound covers.
    error: Option<DVec3>,
}

/// The cut grew past its allowance: the group is shaded point by point.
struct TooCostly;

/// What the group sees of a node to be bounded, before its width.
#[derive(Clone, Copy, Debug)]
struct Pending {
    view: SharedView,
    /// How far members reach below some point's tangent plane (0 if none).
    depth: f64,
    /// The nearest distance less the node's radius.
    gap: f64,
    /// No point nearer the centroid than `nearest`, which lies `distance`
    /// from the group's centre.
    nearest: f64,
    distance: f64,
}

/// A child of a node being refined, between the passes of
/// [`SharedCut::refine`].
#[derive(Clone, Copy, Debug)]
enum Child {
    /// Dark, a single light (already in the cut) or below every plane.
    Skip,
    /// Too near the group for a shared bound.
    Near,
    /// Bounded: its view and (once taken) its width.
    Bound(Pending, DVec3),
}

impl<V: Visibility> SharedCut<'_, V> {
    /// Asks the host about `region` for the whole group, unless `visible`
    /// is known already; `None` when it is occluded, else whether it is
    /// visible.
    #[inline(always)]
    fn ask(&mut self, visible: bool, region: &NodeRegion) -> Option<bool> {
        if visible || V::ALWAYS_VISIBLE {
            return Some(true);
        }
        self.classifications += 1;
        match self.visibility.classify_group(&self.group.region, region) {
            Coverage::Occluded => None,
            Coverage::Visible => Some(true),
            Coverage::Partial => Some(false),
        }
    }

    /// Puts a single light into the cut unless it is below every point's
    /// tangent plane or hidden from the whole group (`visible` when its
    /// node is known visible; `leaf` is its node, for the host).
    #[inline(always)]
    fn light(
        &mut self,
        scratch: &mut BatchScratch,
        (position, intensity): (DVec3, DVec3),
        visible: bool,
        leaf: usize,
        weight: f64,
    ) {
        if intensity == DVec3::ZERO {
            return;
        }
        let intensity = intensity * weight;
        let offset = position - self.group.centre;
        let distance = offset.length();
        let height = self.group.normal.dot(offset);
        let scaled = intensity * self.kd;
        let side = self
            .group
            .side_of(height, height, distance + self.group.radius);
        if side == Side::Below {
            return;
        }
        let at = position.as_vec3();
        let here = NodeRegion {
            index: leaf as u32,
            aabb: Aabb { min: at, max: at },
            centroid: at,
            radius: 0.0,
            light_count: 1,
        };
        match self.ask(visible, &here) {
            None => return,
            Some(true) => {}
            Some(false) => {
                scratch.shadowed.push((position, intensity));
                return;
            }
        }
        match side {
            Side::Below => return,
            // The series of a single light is its exact term; what is left
            // is the rounding of its cosine and of the offset (see
            // `SERIES_SLACK` and `POINT_SLACK`), at the nearest distance.
            Side::Above(lowest) => {
                let nearest = self.group.nearest(distance, lowest);
                let inv = 1.0 / nearest;
                self.light_error += scaled * ((inv * inv) * (SERIES_SLACK + POINT_SLACK));
                self.spread.note(nearest, distance);
                scratch.above.push((position, scaled));
            }
            // Evaluated by the shader at each point.
            Side::Across(_) => scratch.lights.push((position, intensity)),
        }
        let values = self.samples.values(position, scaled);
        for (sum, v) in self.steer_settled.iter_mut().zip(values) {
            *sum += v;
        }
    }

    /// Enters node `index`: dropped when dark or below every tangent plane,
    /// a single light when its radius is 0, else an entry of the error list
    /// (to be refined whatever its error when the shared bound does not
    /// apply).
    #[inline(always)]
    fn enter(&mut self, scratch: &mut BatchScratch, index: usize, visible: bool) {
        if let Some(entering) = self.entering(scratch, index, visible, 1.0) {
            self.push(scratch, index, entering);
        }
    }

    /// Puts node `index` into the error list as `entering` says.
    #[inline(always)]
    fn push(&mut self, scratch: &mut BatchScratch, index: usize, entering: Entering) {
        let node = &self.tree.nodes[index];
        let seen = if entering.visible {
            Seen::Visible
        } else {
            Seen::Partial(None)
        };
        let (entry, values) = match entering.error {
            Some(error) => (
                Entry::new(
                    Class::Error,
                    index as u32,
                    Seen::Visible,
                    DVec3::ZERO,
                    error,
                ),
                self.samples
                    .values(node.centroid.as_dvec3(), node.intensity * self.kd),
            ),
            None => (
                Entry::new(
                    Class::Unbounded,
                    index as u32,
                    seen,
                    DVec3::ZERO,
                    DVec3::ZERO,
                ),
                [DVec3::ZERO; SAMPLES],
            ),
        };
        let slot = scratch.list.push(entry) as usize;
        debug_assert_eq!(slot, scratch.steer.len());
        scratch.steer.push(values);
        for (sum, v) in self.steer_waiting.iter_mut().zip(values) {
            *sum += v;
        }
    }

    /// What node `index` (known visible for the group if `visible`) is for
    /// the shared cut: `None` when it drops out (dark, below every plane,
    /// hidden) or was a single light (put in the cut with blend `weight`),
    /// else whether it is visible and its shared error, if it has one (none
    /// when too near, across some plane or partly hidden: it must be
    /// refined).
    #[inline(always)]
    fn entering(
        &mut self,
        scratch: &mut BatchScratch,
        index: usize,
        visible: bool,
        weight: f64,
    ) -> Option<Entering> {
        let node = &self.tree.nodes[index];
        if node.intensity == DVec3::ZERO {
            return None;
        }
        if node.radius == 0.0 {
            let light = (node.centroid.as_dvec3(), node.intensity);
            self.light(scratch, light, visible, index, weight);
            return None;
        }
        self.evaluations += 1;
        let bound = self.shared_bound(node);
        if bound == Ok(None) {
            return None;
        }
        let visible = self.ask(visible, &region(node, index))?;
        Some(Entering {
            visible,
            error: bound.ok().flatten().filter(|_| visible),
        })
    }

    /// Refines `node` with blend `weight`: its lights into the cut, or each
    /// child through `child(index, entering)`.
    #[inline(always)]
    fn refine(
        &mut self,
        scratch: &mut BatchScratch,
        index: u32,
        visible: bool,
        weight: f64,
        mut child: impl FnMut(&mut Self, &mut BatchScratch, usize, Entering),
    ) {
        let tree = self.tree;
        let node = &tree.nodes[index as usize];
        if node.is_leaf() {
            for k in node.lights() {
                let l = tree.lights[k];
                let light = (l.position.as_dvec3(), l.intensity.as_dvec3());
                self.light(scratch, light, visible, index as usize, weight);
            }
            return;
        }
        // The children's widths are taken side by side: first each child's
        // geometry (single lights go into the cut here), then the widths in
        // lanes, then, in the children's order, the host and `child`.
        // At most `MAX_CHILDREN` (the builder's octree; `validate` checks it).
        let children = node.children();
        let first = children.start;
        let mut states = [Child::Skip; MAX_CHILDREN];
        let mut bounded = [(0usize, 0usize, SharedView::default()); MAX_CHILDREN];
        let mut count = 0;
        for (k, c) in children.clone().enumerate() {
            let node = &tree.nodes[c];
            if node.intensity == DVec3::ZERO {
                continue;
            }
            if node.radius == 0.0 {
                let light = (node.centroid.as_dvec3(), node.intensity);
                self.light(scratch, light, visible, c, weight);
                continue;
            }
            self.evaluations += 1;
            states[k] = match self.shared_view(node) {
                Ok(None) => Child::Skip,
                Err(()) => Child::Near,
                Ok(Some(pending)) => {
                    self.spread.note(pending.nearest, pending.distance);
                    bounded[count] = (k, c, pending.view);
                    count += 1;
                    Child::Bound(pending, DVec3::ZERO)
                }
            };
        }
        match count {
            0 => {}
            1 => self.widths::<1>(&mut states, &bounded[..1]),
            2..=4 => self.widths::<4>(&mut states, &bounded[..count]),
            _ => self.widths::<8>(&mut states, &bounded[..count]),
        }
        for (k, state) in states.iter().enumerate().take(children.len()) {
            let c = first + k;
            let node = &tree.nodes[c];
            let error = match state {
                Child::Skip => continue,
                Child::Near => None,
                Child::Bound(pending, width) => Some(self.shared_error(node, pending, *width)),
            };
            let Some(visible) = self.ask(visible, &region(node, c)) else {
                continue;
            };
            let error = error.filter(|_| visible);
            child(self, scratch, c, Entering { visible, error });
        }
    }

    /// The widths of the children `bounded` (`(k, index, view)`: the
    /// `k`-th child, node `index`, what the group sees of it) into their
    /// states, `N` lanes at a time; unused lanes repeat the last child.
    #[inline(always)]
    fn widths<const N: usize>(
        &self,
        states: &mut [Child; MAX_CHILDREN],
        bounded: &[(usize, usize, SharedView)],
    ) {
        let last = bounded.len() - 1;
        let pick = |i: usize| &bounded[i.min(last)];
        let tree = self.tree;
        let nodes: [&Node; N] = array(&tree.nodes[bounded[0].1], |i| &tree.nodes[pick(i).1]);
        let views = array(bounded[0].2, |i| pick(i).2);
        let widths = shared_widths::<N>(&nodes, &views);
        for (&(k, _, _), width) in bounded.iter().zip(widths) {
            if let Child::Bound(_, w) = &mut states[k] {
                *w = width;
            }
        }
    }

    /// The node's error shared by every point of the group (the series
    /// width, plus the clamp term for members below some point's tangent
    /// plane); `Ok(None)` for a node below every tangent plane, `Err(())`
    /// for one whose ball comes too near the group.
    #[inline(always)]
    fn shared_bound(&mut self, node: &Node) -> Result<Option<DVec3>, ()> {
        Ok(self.shared_view(node)?.map(|pending| {
            self.spread.note(pending.nearest, pending.distance);
            let width = shared_width(node, &pending.view);
            self.shared_error(node, &pending, width)
        }))
    }

    /// [`shared_bound`](Self::shared_bound) up to the width: what the group
    /// sees of the node.
    #[inline(always)]
    fn shared_view(&self, node: &Node) -> Result<Option<Pending>, ()> {
        let group = &self.group;
        let distance = (node.centroid.as_dvec3() - group.centre).length();
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
        let inv_nearest = 1.0 / nearest;
        Ok(Some(Pending {
            view: group.view(node, inv_nearest, distance),
            depth,
            gap: nearest - radius,
            nearest,
            distance,
        }))
    }

    /// [`shared_bound`](Self::shared_bound) from the node's view and series
    /// width.
    #[inline(always)]
    fn shared_error(&self, node: &Node, pending: &Pending, width: DVec3) -> DVec3 {
        let inv_nearest = pending.view.inv_nearest;
        let intensity = node.intensity * self.kd;
        let mut error = intensity * (inv_nearest * inv_nearest) * width;
        if pending.depth > 0.0 {
            // Members below some point's tangent plane: the clamp makes the
            // exact sum exceed the smooth one by at most `I kd depth /
            // (D - R)^3` at that point (see `Lambert`'s docs), `depth` how
            // far they reach below its plane, at most `-lowest` here.
            let gap = pending.gap;
            error += intensity * (pending.depth / (gap * gap * gap)) * (1.0 + 16.0 * f64::EPSILON);
        }
        error
    }

    /// Blends every waiting node whose error lies within `band` of `level`
    /// with its children, recursively, as the single-point cut does (see
    /// [`Threshold::with_interpolation`]): the blended nodes and their
    /// weights go to `scratch.weighted`, single lights into the cut with
    /// their weights. Returns what [`unblend`](Self::unblend) needs to
    /// restore the cut and the blended error, or `None` when there is
    /// nothing to blend or the blend would cost more than the group's
    /// budget.
    fn blend(&mut self, scratch: &mut BatchScratch, level: f64, band: f64) -> Option<Blend> {
        if scratch.list.len() == 0 || !(level > 0.0 && level.is_finite()) {
            return None;
        }
        let mark = Blend {
            lights: (
                scratch.lights.len(),
                scratch.above.len(),
                scratch.shadowed.len(),
            ),
            light_error: self.light_error,
            steer: self.steer_settled,
            error: DVec3::ZERO,
        };
        let floor = level / band;
        let ramp = |key: f64| ((key - floor) / (level - floor)).clamp(0.0, 1.0);
        let mut error = DVec3::ZERO;
        scratch.blending.clear();
        scratch.weighted.clear();
        for (e, _) in scratch.list.waiting() {
            let alpha = ramp(e.key);
            if alpha < 1.0 {
                scratch.weighted.push((e.node, 1.0 - alpha));
                error += e.error * (1.0 - alpha);
            }
            if alpha > 0.0 {
                scratch
                    .blending
                    .push((e.node, alpha, e.seen == Seen::Visible));
            }
        }
        let budget = self.points * self.budget_per_point;
        while let Some((node, weight, visible)) = scratch.blending.pop() {
            if self.evaluations > budget {
                self.unblend(scratch, mark);
                return None;
            }
            self.refine(scratch, node, visible, weight, |_, scratch, c, e| {
                let c = c as u32;
                match e.error {
                    Some(child_error) => {
                        let alpha = ramp(child_error.max_element());
                        if alpha < 1.0 {
                            scratch.weighted.push((c, weight * (1.0 - alpha)));
                            error += child_error * (weight * (1.0 - alpha));
                        }
                        if alpha > 0.0 {
                            scratch.blending.push((c, weight * alpha, true));
                        }
                    }
                    // No shared bound: refined fully.
                    None => scratch.blending.push((c, weight, e.visible)),
                }
            });
        }
        Some(Blend { error, ..mark })
    }

    /// Takes the single lights a [`blend`](Self::blend) put into the cut
    /// out again.
    fn unblend(&mut self, scratch: &mut BatchScratch, mark: Blend) {
        let (lights, above, shadowed) = mark.lights;
        scratch.lights.truncate(lights);
        scratch.above.truncate(above);
        scratch.shadowed.truncate(shadowed);
        self.light_error = mark.light_error;
        self.steer_settled = mark.steer;
    }

    /// The darkest sample's estimate of the cut.
    #[inline(always)]
    fn steering(&self) -> DVec3 {
        let sums = core::array::from_fn(|k| self.steer_settled[k] + self.steer_waiting[k]);
        darkest(&sums)
    }

    /// Recomputes the running sums of the samples' values of the waiting
    /// entries (they subtract and may drift).
    #[inline(always)]
    fn resum_steering(&mut self, scratch: &BatchScratch) {
        let mut sums: [CompensatedSum; SAMPLES] = Default::default();
        for (_, slot) in scratch.list.waiting() {
            for (sum, v) in sums.iter_mut().zip(scratch.steer[slot as usize]) {
                sum.add(v);
            }
        }
        self.steer_waiting = sums.map(|s| s.value());
    }

    /// The error list's loop over the shared bounds until `met` holds for
    /// the representative's estimate and the summed error.
    #[inline(always)]
    fn run(
        &mut self,
        scratch: &mut BatchScratch,
        mut excess: impl FnMut(DVec3, DVec3, f64) -> f64,
    ) -> Result<(), TooCostly> {
        loop {
            let mut before = f64::INFINITY;
            if scratch.list.may_stop() {
                let largest = scratch.list.largest();
                let (_, error) = scratch.list.sums();
                before = excess(self.steering(), error, largest);
                if before <= 0.0 {
                    let (_, error) = scratch.list.resum();
                    self.resum_steering(scratch);
                    before = excess(self.steering(), error, largest);
                    if before <= 0.0 {
                        self.after = before;
                        return Ok(());
                    }
                }
            }
            let Some((top, slot)) = scratch.list.pop_slot() else {
                self.after = f64::NEG_INFINITY;
                return Ok(());
            };
            self.last_step = Some((before, top.key));
            for (sum, v) in self
                .steer_waiting
                .iter_mut()
                .zip(scratch.steer[slot as usize])
            {
                *sum -= v;
            }
            let entries = scratch.lights.len() + scratch.above.len() + scratch.list.len();
            // A light asked point-to-point costs each point a ray, about a
            // node bound.
            let rays = scratch.shadowed.len() as u64 * self.points;
            let cost = self.evaluations + rays + entries as u64 * self.points / ENTRIES_PER_BOUND;
            if cost > self.points * self.budget_per_point || entries > MAX_CUT_ITEMS {
                return Err(TooCostly);
            }
            if let Some(next) = scratch.list.peek() {
                self.tree.prefetch_refinement(next.node as usize);
            }
            let visible = top.seen == Seen::Visible;
            self.refine(scratch, top.node, visible, 1.0, |cut, scratch, c, e| {
                cut.push(scratch, c, e);
            });
        }
    }
}

/// The certified bound reported for a shared cut's summed `error` whose
/// points sum `entries` packed estimates: the compensated sums' allowance of
/// [`reported_bound`], and the lanes' plain sums. A plain sum of `m` terms
/// is within `m * 2^-53` of the sum of their magnitudes; each term lies
/// within its error of a non-negative exact value, so that is at most
/// `m * 2^-53 (exact + error)`: the exact part falls within the rounding
/// allowance (`m <= 2^16`), the error part is added here.
fn packed_bound(error: DVec3, entries: usize) -> DVec3 {
    let lane_terms = (entries / super::packed::WIDE + 2) as f64;
    reported_bound(error) * (1.0 + lane_terms * f64::EPSILON)
}

/// Each group's halo when `threshold` interpolates (none otherwise, and
/// none for Lightcuts' per-node target): the points of other groups whose
/// distance to the group's points' box is less than the halo width,
/// [`HALO_SHARE`] of the box's largest side, and whose normals lie within
/// [`GROUP_NORMAL_SPREAD`] of the group's first; each with the weight
/// `1 - distance / width`, which is 1 on the box and falls to 0 at the
/// halo's edge.
fn halos<M>(
    queries: &[Query<M>],
    order: &[u32],
    runs: &[Range<usize>],
    threshold: &Threshold,
) -> Vec<Halo> {
    if threshold.interpolation().is_none() || matches!(threshold.target(), Target::PerNode(_)) {
        return Vec::new();
    }
    let surface = |k: usize| queries[order[k] as usize].surface();
    let boxes: Vec<(DVec3, DVec3, f64)> = runs
        .iter()
        .map(|run| {
            let (lo, hi) = points_box(queries, &order[run.clone()]);
            (lo, hi, HALO_SHARE * (hi - lo).max_element())
        })
        .collect();
    let mut halos = vec![Vec::new(); runs.len()];
    // The points of group `s` in the halo of group `r`.
    let mut add = |r: usize, s: usize| {
        let (lo, hi, width) = boxes[r];
        let first = surface(runs[r].start).normal;
        for k in runs[s].clone() {
            let at = surface(k);
            let distance = (lo - at.point).max(at.point - hi).max(DVec3::ZERO).length();
            if distance < width && (at.normal - first).length() <= GROUP_NORMAL_SPREAD {
                halos[r].push((order[k], 1.0 - distance / width));
            }
        }
    };
    // The pairs of groups whose boxes, grown by their halo widths, meet: a
    // sweep along x over the grown boxes.
    let mut by_x: Vec<usize> = (0..runs.len()).collect();
    by_x.sort_by(|&a, &b| (boxes[a].0.x - boxes[a].2).total_cmp(&(boxes[b].0.x - boxes[b].2)));
    let mut active: Vec<usize> = Vec::new();
    for &r in &by_x {
        let (lo, hi, width) = boxes[r];
        active.retain(|&s| boxes[s].1.x + boxes[s].2 >= lo.x - width);
        for &s in &active {
            let (lo_s, hi_s, width_s) = boxes[s];
            let meet = (lo - width).cmple(hi_s + width_s).all()
                && (lo_s - width_s).cmple(hi + width).all();
            if meet {
                add(r, s);
                add(s, r);
            }
        }
        active.push(r);
    }
    halos
}

/// Blends each point's own result with the results of the groups whose
/// halo holds it, weighted by the halo weights (its own with weight 1).
///
/// Each result is within its certified bound of the exact value, so a
/// weighted mean with non-negative weights is within the weighted mean of
/// the bounds; the mean of `m` non-negative terms rounds within
/// `(2m + 2)` ulps, and `2m + 4` are added to the bound, relative to the
/// blended value. A point keeps its own result when that missed its
/// target, or when the blend would.
///
/// Inside a group every weight but its own falls continuously to 0 at the
/// halo's edge, so the blend changes continuously from one group to the
/// next: the seams that two groups' different cuts leave at their border
/// are spread over the halo.
fn blend_halos(results: &mut [ShadeResult], mut halo: Vec<HaloResult>, threshold: &Threshold) {
    halo.sort_unstable_by_key(|h| (h.point, h.run));
    for same in halo.chunk_by(|a, b| a.point == b.point) {
        let own = &mut results[same[0].point as usize];
        if own.stop != Stop::ThresholdMet {
            continue;
        }
        let (mut weight, mut radiance, mut bound) = (1.0, own.radiance, own.error_bound);
        let mut blended = *own;
        for h in same {
            weight += h.weight;
            radiance += h.result.radiance * h.weight;
            bound += h.result.error_bound * h.weight;
            blended.nodes_evaluated = blended
                .nodes_evaluated
                .saturating_add(h.result.nodes_evaluated);
            blended.lights_evaluated = blended
                .lights_evaluated
                .saturating_add(h.result.lights_evaluated);
            blended.point_queries = blended.point_queries.saturating_add(h.result.point_queries);
        }
        let rounding = (2 * same.len() + 6) as f64 * f64::EPSILON;
        blended.radiance = radiance / weight;
        blended.error_bound = bound / weight * (1.0 + rounding) + blended.radiance * rounding;
        // No largest node error: halos are only formed for relative and
        // absolute targets, whose check does not read it.
        if threshold.met(blended.radiance, blended.error_bound, 0.0) {
            *own = blended;
        }
    }
}

impl<S: Shader> Shading<'_, S> {
    /// Shades a batch of queries into `results` (one per query, same order),
    /// each with the certified contract of
    /// [`shade_query`](Self::shade_query): radiance, certified error bound,
    /// its own cost, and why it stopped.
    ///
    /// Nothing is assumed of the order or layout of the queries; neighbouring
    /// points (a tile of an image, a patch of surface) share work.
    ///
    /// # How points share a cut
    /// The points are sorted along a Morton curve of their positions over
    /// the batch's bounding cube, and grouped by the cells of the Morton
    /// (octree) subdivision: each group is a cell holding at most 128
    /// points, cut further into runs whose normals lie within about 29
    /// degrees of the run's first. For each run the crate picks one cut
    /// through the tree with the error list, bounding each node once for the whole
    /// group: nodes below every point's tangent plane drop out, the others
    /// are bounded by the degree-2 multipole series with its remainder taken
    /// at the group's nearest distance to the node and largest cosine (valid
    /// for every point and normal of the group), plus the clamp term where
    /// members reach below some point's tangent plane; nodes whose ball
    /// comes too near the group are refined, down to single lights. Each
    /// point then sums, at its own position and normal, the cut's node
    /// estimates and single lights; its certified bound is the cut's summed
    /// error.
    ///
    /// A relative target is aimed at with the darkest of four points spread
    /// over the run (virtual-light estimates, with a margin); a point that
    /// still misses its own target gets up to three further shared
    /// refinements and is then shaded on its own. Without interpolation, a
    /// point that met its target keeps the result of the round it met it
    /// in; with interpolation every point of the run takes the last round's
    /// cut. A run whose shared cut
    /// costs more than a share of what its points would cost alone (a
    /// running estimate from the points shaded alone; before there is one,
    /// a small fixed budget, and a run over it first shades one point
    /// alone for the estimate) is shaded point by point, as are runs of
    /// fewer than four points.
    ///
    /// # Group borders with interpolation
    /// Two groups' cuts differ as wholes, so without more the error would
    /// jump where one group ends and the next begins. With interpolation
    /// (relative or absolute targets) each group's cut also serves the
    /// points of other groups within a quarter of the largest side of its
    /// points' box (its halo; only points whose normals are within the
    /// group's normal spread): the group's geometry, and so its certified
    /// bound, takes them in, and each is summed over the cut. A point's
    /// result is then the mean of its own group's result (weight 1) and of
    /// the results of the groups whose halo holds it, each weighted by
    /// `1 - d / w` (`d` its distance to that group's box, `w` the halo's
    /// width). The weights fall to 0 continuously at each halo's edge, so
    /// the result changes continuously across a border. The bound is the
    /// weighted mean of the bounds plus the rounding of the means; a point
    /// keeps its own result when the blend would miss its target. Along a
    /// scanline of 2,048 ground points in the report's city at 10^6 lights,
    /// the largest jump of the relative error between neighbours fell from
    /// 1.95e-4 to 7.0e-6 (below point-by-point interpolation's 2.6e-5), and
    /// over a 128 x 16 patch of points from 7.5e-5 to 1.4e-5. The halo
    /// costs: on a 320 x 180 camera view of the street city at 10^6
    /// lights, certified 1%, one call with interpolation took 4.0-4.1 us per
    /// pixel, 2.3 us with no halo and 1.5 us without interpolation (two
    /// scratch timings).
    ///
    /// A point's [`ShadeResult::nodes_evaluated`] then counts the node
    /// estimates it summed (cheaper than bounds) and
    /// [`lights_evaluated`](ShadeResult::lights_evaluated) the single
    /// lights, over every cut it blends; the shared bounds are counted once,
    /// in the returned [`BatchStats`].
    ///
    /// With occluders, a host that classifies nodes for whole groups
    /// ([`Visibility::classify_group`]) is asked once per group about each
    /// node the cut takes: hidden nodes drop out, visible ones are shared
    /// as without occluders, partly hidden ones are refined, and a single
    /// light still partly hidden is asked point-to-point by each point
    /// (counted in its [`point_queries`](ShadeResult::point_queries)).
    ///
    /// Cuts are shared for shaders that are purely diffuse
    /// ([`Shader::diffuse_albedo`]), with [`Unoccluded`](crate::Unoccluded)
    /// or a host that classifies groups, and a threshold without a budget or
    /// maximal contribution. Otherwise every point is
    /// shaded on its own, with the same results as calling
    /// [`shade_query`](Self::shade_query) for each.
    ///
    /// Speed: on a 10^6-light street city seen from above the streets, one
    /// core, certified 1% per pixel, the batch call took about 1.1 us per
    /// pixel of a 320 x 180 image, about 1,500 times less than a vectorized
    /// exact sum and 11 times less than shading each pixel on its own, and
    /// 0.7 us per pixel of the same shot at 1280 x 720 (about 2,400 times
    /// less than the exact sum): denser pixels share cuts over smaller
    /// patches of ground (`cargo run --release -p manylights-report --
    /// batch`).
    ///
    /// Rounding: where a group's cut is coarse (its certified error at
    /// least `2^-12` of the radiance it aims at), each point sums it in
    /// `f32` lanes and its bound includes a certified bound on that sum's
    /// rounding (see the crate's docs on the certified bound).
    ///
    /// Allocation: a call allocates its Morton order and group list (linear
    /// in the batch); the session's scratch space is reused across calls.
    ///
    /// # Errors
    /// [`ShadeError::BatchLength`] when `results` is not as long as
    /// `queries`; the threshold errors of [`shade_query`](Self::shade_query).
    pub fn shade_batch<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        threshold: Threshold,
        mut visibility: V,
        results: &mut [ShadeResult],
    ) -> Result<BatchStats, ShadeError>
    where
        S: Accepts<M>,
    {
        if queries.len() != results.len() {
            return Err(ShadeError::BatchLength {
                queries: queries.len(),
                results: results.len(),
            });
        }
        threshold.check()?;
        let mut stats = BatchStats::default();
        if !self.shares::<V>(&threshold) {
            for (query, result) in queries.iter().zip(results.iter_mut()) {
                *result = self.shade_query(query, threshold, &mut visibility)?;
            }
            stats.points_alone = queries.len() as u32;
            return Ok(stats);
        }
        let Groups { order, runs } = groups(queries);
        let halos = halos(queries, &order, &runs, &threshold);
        let mut out = Outcome::default();
        for (k, chunk) in runs.chunks(CHUNK_RUNS).enumerate() {
            let (points, write) = ((queries, order.as_slice()), &mut |i, r| results[i] = r);
            let groups = (k * CHUNK_RUNS, chunk, halos.as_slice());
            self.shade_chunk(points, groups, threshold, &mut visibility, write, &mut out)?;
        }
        blend_halos(results, out.halo, &threshold);
        Ok(out.stats)
    }

    /// [`shade_batch`](Self::shade_batch) spread over rayon's thread pool:
    /// the same groups are formed (on the calling thread, while the pool's
    /// threads wake up and wait for them) and shaded in chunks, each chunk
    /// on some thread with a session of its own (the shader and the
    /// visibility host cloned), so the results are the same bits as
    /// `shade_batch`'s. Without shared cuts, chunks of the batch are shaded
    /// point by point on the threads.
    ///
    /// Allocation: what `shade_batch` allocates, and a session per thread
    /// (the threads write their results in place).
    ///
    /// # Errors
    /// As [`shade_batch`](Self::shade_batch).
    #[cfg(feature = "rayon")]
    #[allow(unsafe_code)]
    pub fn shade_batch_parallel<M, V>(
        &self,
        queries: &[Query<M>],
        threshold: Threshold,
        visibility: V,
        results: &mut [ShadeResult],
    ) -> Result<BatchStats, ShadeError>
    where
        M: Sync,
        S: Accepts<M> + Clone + Send + Sync,
        V: Visibility + Clone + Send + Sync,
    {
        use rayon::prelude::*;

        if queries.len() != results.len() {
            return Err(ShadeError::BatchLength {
                queries: queries.len(),
                results: results.len(),
            });
        }
        threshold.check()?;
        let session = || self.tree.shading(self.shader.clone());
        if !self.shares::<V>(&threshold) {
            const CHUNK: usize = 64;
            results
                .par_chunks_mut(CHUNK)
                .zip(queries.par_chunks(CHUNK))
                .try_for_each_init(session, |shading, (out, chunk)| {
                    let mut visibility = visibility.clone();
                    for (r, q) in out.iter_mut().zip(chunk) {
                        *r = shading.shade_query(q, threshold, &mut visibility)?;
                    }
                    Ok::<_, ShadeError>(())
                })?;
            return Ok(BatchStats {
                points_alone: queries.len() as u32,
                ..BatchStats::default()
            });
        }
        // The calling thread forms the groups while the pool's other threads
        // wake up and wait for them: a sleeping thread can take milliseconds
        // to wake on a shared machine, about as long as the grouping, and
        // woken only once the groups were formed one often started 1-4 ms
        // after the other (of 30-40 ms). Grouping on the threads instead
        // (codes, and halves of the sort) took longer than on one: 2.1-2.8
        // ms against 1.3-1.6 for 57,600 points.
        let ready: OnceLock<Setup> = OnceLock::new();
        let output = Output::new(results);
        let next = AtomicUsize::new(0);
        let outcomes = Mutex::new(Vec::new());
        let workers = rayon::current_num_threads().max(1);
        // Each worker shades with a session of its own, reused from chunk
        // to chunk (a chunk's results do not depend on what the session
        // shaded before, nor on the order).
        let work = |setup: &Setup| {
            let mut shading = session();
            let mut out = Outcome::default();
            let result = loop {
                // Each place in the queue is taken once, so each chunk is
                // shaded by one worker.
                let taken = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(_, k)) = setup.queue.get(taken) else {
                    break Ok(());
                };
                let done = shading.shade_chunk(
                    (queries, setup.order.as_slice()),
                    (k * CHUNK_RUNS, setup.chunk(k), setup.halos.as_slice()),
                    threshold,
                    &mut visibility.clone(),
                    // SAFETY: the point is in this chunk alone, which this
                    // worker alone took (see `Output`).
                    &mut |i, r| unsafe { output.write(i, r) },
                    &mut out,
                );
                if let Err(e) = done {
                    break Err(e);
                }
            };
            if let Ok(mut all) = outcomes.lock() {
                all.push(result.map(|()| out));
            }
        };
        // Set when the calling thread leaves the scope, even by a panic, so
        // that no worker waits forever.
        let done = AtomicBool::new(false);
        let wait = || loop {
            if let Some(setup) = ready.get() {
                break Some(setup);
            }
            if done.load(Ordering::Acquire) {
                break None;
            }
            std::thread::yield_now();
        };
        // In place: the groups are formed on the calling thread, and the
        // waiting workers go to the pool at once.
        rayon::in_place_scope(|scope| {
            for _ in 1..workers {
                scope.spawn(|_| {
                    if let Some(setup) = wait() {
                        work(setup);
                    }
                });
            }
            let _leaving = Leaving(&done);
            let Groups { order, runs } = groups(queries);
            // The chunks whose points spread widest go first: those are the
            // costly ones (a group that spans blocks near the horizon is
            // shaded point by point), and left for the end one would keep
            // the other thread waiting (at 10^6 lights, certified 1%: 1.85x
            // and 1.88x one thread on two cores against 1.67x and 1.64x in
            // Morton order, the exact sum's own 1.97-2.00x in the same
            // runs).
            let mut queue: Vec<(f64, usize)> = runs
                .chunks(CHUNK_RUNS)
                .enumerate()
                .map(|(k, chunk)| {
                    let places = chunk[0].start..chunk[chunk.len() - 1].end;
                    let (lo, hi) = points_box(queries, &order[places]);
                    (-(hi - lo).max_element(), k)
                })
                .collect();
            queue.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let halos = halos(queries, &order, &runs, &threshold);
            let setup = Setup {
                order,
                runs,
                halos,
                queue,
            };
            work(ready.get_or_init(|| setup));
        });
        let mut out = Outcome::default();
        for outcome in outcomes.into_inner().unwrap_or_default() {
            let mut outcome = outcome?;
            out.stats += outcome.stats;
            out.halo.append(&mut outcome.halo);
        }
        blend_halos(results, out.halo, &threshold);
        Ok(out.stats)
    }

    /// Shades the groups `runs` (ranges of `order`, indices into `queries`),
    /// one chunk: the estimate of what a point costs alone starts afresh, so
    /// a chunk gives the same results whichever thread shades it.
    fn shade_chunk<M, V: Visibility>(
        &mut self,
        (queries, order): (&[Query<M>], &[u32]),
        (first, runs, halos): (usize, &[Range<usize>], &[Halo]),
        threshold: Threshold,
        visibility: &mut V,
        write: &mut impl FnMut(usize, ShadeResult),
        out: &mut Outcome,
    ) -> Result<(), ShadeError>
    where
        S: Accepts<M>,
    {
        self.scratch.batch.alone_cost = 0.0;
        for (k, run) in runs.iter().enumerate() {
            let members = Members {
                points: &order[run.clone()],
                halo: halos.get(first + k).map_or(&[], Vec::as_slice),
                run: (first + k) as u32,
            };
            self.shade_members(queries, members, threshold, visibility, write, out)?;
        }
        Ok(())
    }

    /// Whether a batch call with this threshold and visibility shares cuts.
    fn shares<V: Visibility>(&self, threshold: &Threshold) -> bool {
        (V::ALWAYS_VISIBLE || V::CLASSIFIES_GROUPS)
            && self.shader.diffuse_albedo().is_some()
            && threshold.budget().is_none()
            && threshold.max_contribution().is_none()
    }

    /// Shades the queries `members` (indices into `queries`) as one group,
    /// or point by point when a shared cut does not pay; each result goes
    /// to `write(index, result)`, each halo point's to `out`.
    fn shade_members<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        members: Members<'_>,
        threshold: Threshold,
        visibility: &mut V,
        write: &mut impl FnMut(usize, ShadeResult),
        out: &mut Outcome,
    ) -> Result<(), ShadeError>
    where
        S: Accepts<M>,
    {
        let points = members.points;
        if points.len() < GROUP_MIN_POINTS {
            for &i in points {
                let i = i as usize;
                write(
                    i,
                    self.shade_alone(&queries[i], threshold, &mut *visibility)?,
                );
            }
            out.stats.points_alone += points.len() as u32;
            return Ok(());
        }
        // Without an estimate yet of what sharing must beat, the shared cut
        // gets the least budget; if that is too little, the first point is
        // shaded alone for an estimate.
        let unknown = self.scratch.batch.alone_cost == 0.0;
        match self.shade_shared(queries, members, &threshold, visibility, &mut out.stats) {
            Ok(()) => {
                for (k, &i) in points.iter().enumerate() {
                    let i = i as usize;
                    if self.scratch.batch.alone[k] {
                        write(
                            i,
                            self.shade_alone(&queries[i], threshold, &mut *visibility)?,
                        );
                    } else {
                        write(i, self.scratch.batch.results[k]);
                    }
                }
                let halo = members.halo.iter().zip(&self.scratch.batch.halo_results);
                out.halo
                    .extend(halo.map(|(&(point, weight), &result)| HaloResult {
                        point,
                        run: members.run,
                        weight,
                        result,
                    }));
                Ok(())
            }
            Err(TooCostly) if unknown => {
                let i = points[0] as usize;
                write(
                    i,
                    self.shade_alone(&queries[i], threshold, &mut *visibility)?,
                );
                out.stats.points_alone += 1;
                let rest = Members {
                    points: &points[1..],
                    ..members
                };
                self.shade_members(queries, rest, threshold, visibility, write, out)
            }
            // Sharing does not pay here: every point on its own. (Splitting
            // the group in halves and trying again cost more in cuts that
            // failed than the halves saved: at 10^6 lights, certified 15%,
            // 0.81-0.82 against 0.86-0.88 us per pixel; the `city` example
            // 1.81 s against 1.90-2.01 s.)
            Err(TooCostly) => {
                for &i in points {
                    let i = i as usize;
                    write(
                        i,
                        self.shade_alone(&queries[i], threshold, &mut *visibility)?,
                    );
                }
                out.stats.points_alone += points.len() as u32;
                Ok(())
            }
        }
    }

    /// [`shade_query`](Self::shade_query) for a point of a batch shaded on
    /// its own, its cost (node bounds, lights, host queries) folded into the
    /// running estimate that sets the groups' budgets.
    fn shade_alone<M, V: Visibility>(
        &mut self,
        query: &Query<M>,
        threshold: Threshold,
        visibility: V,
    ) -> Result<ShadeResult, ShadeError>
    where
        S: Accepts<M>,
    {
        let r = self.shade_query(query, threshold, visibility)?;
        // Lights summed exactly cost a fraction of a node bound each.
        let cost = f64::from(r.nodes_evaluated)
            + f64::from(r.lights_evaluated) / LIGHTS_PER_BOUND
            + f64::from(r.classify_queries)
            + f64::from(r.point_queries);
        let estimate = &mut self.scratch.batch.alone_cost;
        *estimate = if *estimate == 0.0 {
            cost.max(1.0)
        } else {
            0.875 * *estimate + 0.125 * cost
        };
        Ok(r)
    }

    /// Picks a shared cut for `members` and shades them through it; fills
    /// the scratch results and marks the members that still need shading on
    /// their own. On `x86_64` processors with AVX2, a copy compiled for AVX2
    /// (the same bits, see [`dispatch`](crate::dispatch)).
    // Calling the AVX2 copy is one of the crate's unsafe blocks.
    #[allow(unsafe_code)]
    fn shade_shared<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        members: Members<'_>,
        threshold: &Threshold,
        visibility: &mut V,
        stats: &mut BatchStats,
    ) -> Result<(), TooCostly> {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::dispatch::avx2() {
                // SAFETY: the processor has AVX2 (`dispatch::avx2` checked).
                return unsafe {
                    self.shade_shared_avx2(queries, members, threshold, visibility, stats)
                };
            }
        }
        self.shade_shared_inlined(queries, members, threshold, visibility, stats)
    }

    /// [`shade_shared`](Self::shade_shared) compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn shade_shared_avx2<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        members: Members<'_>,
        threshold: &Threshold,
        visibility: &mut V,
        stats: &mut BatchStats,
    ) -> Result<(), TooCostly> {
        self.shade_shared_inlined(queries, members, threshold, visibility, stats)
    }

    /// The shared cut itself, inlined into each of the above.
    #[inline(always)]
    fn shade_shared_inlined<M, V: Visibility>(
        &mut self,
        queries: &[Query<M>],
        members: Members<'_>,
        threshold: &Threshold,
        visibility: &mut V,
        stats: &mut BatchStats,
    ) -> Result<(), TooCostly> {
        let Some(kd) = self.shader.diffuse_albedo() else {
            return Err(TooCostly);
        };
        // The group's geometry takes in its halo: the cut serves those points
        // too.
        let halo = members.halo.iter().map(|h| &h.0);
        let surfaces = (members.points.iter().chain(halo)).map(|&i| *queries[i as usize].surface());
        let group = Group::new(surfaces);
        let samples = Samples::new(queries, members.points);
        let mut scratch = core::mem::take(&mut self.scratch.batch);
        let outcome = self.shared_cut(
            (queries, members),
            threshold,
            visibility,
            stats,
            (kd, group, samples),
            &mut scratch,
        );
        self.scratch.batch = scratch;
        outcome
    }

    /// [`shade_shared`](Self::shade_shared) with its scratch taken out.
    #[inline(always)]
    fn shared_cut<M, V: Visibility>(
        &self,
        (queries, group_members): (&[Query<M>], Members<'_>),
        threshold: &Threshold,
        visibility: &mut V,
        stats: &mut BatchStats,
        (kd, group, samples): (DVec3, Group, Samples),
        scratch: &mut BatchScratch,
    ) -> Result<(), TooCostly> {
        let members = group_members.points;
        scratch.list.clear();
        scratch.steer.clear();
        scratch.lights.clear();
        scratch.shadowed.clear();
        scratch.above.clear();
        let mut cut = SharedCut {
            tree: self.tree,
            visibility,
            classifications: 0,
            kd,
            group,
            samples,
            steer_settled: [DVec3::ZERO; SAMPLES],
            light_error: DVec3::ZERO,
            spread: Spread::default(),
            steer_waiting: [DVec3::ZERO; SAMPLES],
            evaluations: 0,
            points: members.len() as u64,
            budget_per_point: ((BUDGET_SHARE * scratch.alone_cost) as u64)
                .max(MIN_BUDGET_PER_POINT),
            last_step: None,
            after: 0.0,
        };
        if !self.tree.nodes.is_empty() {
            cut.enter(scratch, 0, false);
        }
        // Every entry lies within the root's box and is at most the root's
        // intensity (blend weights are at most 1); the points lie within
        // the group's ball.
        let limits = self.tree.nodes.first().map_or(
            Limits {
                brightest: 0.0,
                extent: 0.0,
                radius: cut.group.radius,
            },
            |root| Limits {
                brightest: (root.intensity * kd).max_element(),
                extent: f64::from(root.aabb.min.abs().max(root.aabb.max.abs()).max_element())
                    .max(cut.group.centre.abs().max_element() + cut.group.radius),
                radius: cut.group.radius,
            },
        );
        let mut margin = FIRST_MARGIN;
        scratch.alone.clear();
        scratch.alone.resize(members.len(), false);
        scratch.results.clear();
        scratch.results.resize(members.len(), ShadeResult::EMPTY);
        for round in 0..ROUNDS {
            let outcome = cut.run(scratch, |estimate, error, largest| {
                threshold.excess(estimate * margin, reported_bound(error), largest)
            });
            let (_, error) = scratch.list.resum();
            let largest = scratch.list.largest();
            // Interpolation across levels: the cut's last nodes blended
            // with their children, for now (the next round refines the
            // unblended cut further).
            let blended = match (&outcome, threshold.interpolation()) {
                (Ok(()), Some(band)) => {
                    let level = blend::level(cut.last_step, cut.after, largest);
                    cut.blend(scratch, level, band)
                }
                _ => None,
            };
            stats.shared_evaluations += cut.evaluations;
            stats.shared_classifications += cut.classifications;
            (cut.evaluations, cut.classifications) = (0, 0);
            outcome?;
            // The points' sums over the cut.
            let error = match &blended {
                Some(b) => b.error * (1.0 + scratch.weighted.len() as f64 * f64::EPSILON),
                None => error,
            };
            let light_error = cut.light_error * (1.0 + scratch.above.len() as f64 * f64::EPSILON);
            let error = error + light_error;
            scratch
                .packed
                .start(error, cut.steering(), cut.spread, limits);
            match &blended {
                Some(_) => {
                    for &(node, weight) in &scratch.weighted {
                        let node = &self.tree.nodes[node as usize];
                        scratch.packed.push_node(node, kd * weight);
                    }
                }
                None => {
                    for (e, _) in scratch.list.waiting() {
                        let node = &self.tree.nodes[e.node as usize];
                        scratch.packed.push_node(node, kd);
                    }
                }
            }
            for &(position, intensity) in &scratch.above {
                scratch.packed.push_light(position.as_vec3(), intensity);
            }
            let bound = packed_bound(error, scratch.packed.len());
            let nodes = scratch.packed.len() as u32 - scratch.above.len() as u32;
            let lights =
                (scratch.lights.len() + scratch.above.len() + scratch.shadowed.len()) as u32;
            // A point's result over this round's cut.
            let shared = |radiance, point_queries, rounding| ShadeResult {
                radiance,
                error_bound: bound + rounding,
                nodes_evaluated: nodes,
                lights_evaluated: lights,
                classify_queries: 0,
                point_queries,
                stop: Stop::ThresholdMet,
            };
            let mut darkest = f64::INFINITY;
            // Without interpolation a point that met its target on an
            // earlier round keeps that result: the further rounds are for
            // the points that missed. (Interpolated points all take the last
            // round's blend, which keeps the group's image smooth.)
            let keep_met = round > 0 && threshold.interpolation().is_none();
            for (k, &i) in members.iter().enumerate() {
                if keep_met && !scratch.alone[k] {
                    continue;
                }
                let (radiance, rays, rounding) =
                    self.point_sum(&queries[i as usize], scratch, cut.visibility);
                scratch.results[k] = shared(radiance, rays, rounding);
                let alone = !threshold.met(radiance, scratch.results[k].error_bound, largest);
                scratch.alone[k] = alone;
                if alone {
                    darkest = darkest.min(radiance.max_element());
                }
            }
            // The halo's points over the same cut (interpolation only).
            scratch.halo_results.clear();
            for &(i, _) in group_members.halo {
                let (radiance, rays, rounding) =
                    self.point_sum(&queries[i as usize], scratch, cut.visibility);
                scratch.halo_results.push(shared(radiance, rays, rounding));
            }
            if let Some(b) = blended {
                cut.unblend(scratch, b);
            }
            cut.resum_steering(scratch);
            let reference = cut.steering().max_element();
            if darkest == f64::INFINITY || round + 1 == ROUNDS {
                break;
            }
            // Aim below the darkest point that missed, if it is bright
            // enough to be worth it.
            let next = 0.9 * darkest / reference;
            if !(next > 0.05 * margin && next < margin) {
                break;
            }
            margin = next;
        }
        let shared = scratch.alone.iter().filter(|a| !**a).count() as u32;
        stats.groups += 1;
        stats.shared_points += shared;
        stats.points_alone += members.len() as u32 - shared;
        Ok(())
    }

    /// One point's sum over the shared cut in `scratch`, clamped at 0 (the
    /// exact value is non-negative), the point-to-point queries it asked,
    /// and the bound on the rounding of its packed sum when that was in
    /// `f32` (else 0).
    #[inline(always)]
    fn point_sum<M, V: Visibility>(
        &self,
        query: &Query<M>,
        scratch: &BatchScratch,
        visibility: &mut V,
    ) -> (DVec3, u32, DVec3) {
        let surface = query.surface();
        let mut sum = CompensatedSum::default();
        let mut rays = 0;
        if !scratch.lights.is_empty() || !scratch.shadowed.is_empty() {
            let per_point = self.shader.prepare(surface);
            for &(position, intensity) in &scratch.lights {
                sum.add(self.shader.eval(&per_point, surface, position, intensity));
            }
            for &(position, intensity) in &scratch.shadowed {
                let value = self.shader.eval(&per_point, surface, position, intensity);
                if value != DVec3::ZERO {
                    rays += 1;
                    if visibility.visible(query.point(), position.as_vec3()) {
                        sum.add(value);
                    }
                }
            }
        }
        let packed = scratch.packed.sum(surface.point, surface.normal);
        sum.add(packed.value);
        (sum.value().max(DVec3::ZERO), rays, packed.rounding)
    }
}
