//! Interpolation across levels (see [`Threshold::with_interpolation`]): the
//! cut's last nodes blended with their children so the estimate is
//! continuous in the shading point.
//!
//! Four things make the blend a continuous function of the shading point:
//!
//! * **Weights from priorities.** Every node of the cut, refined by the
//!   list or not, is given a refinement weight from its priority and the
//!   level (see [`Ramp`]); with interpolation a node's priority is capped
//!   at its parent's, so weights never grow down a path, and a node whose
//!   weight is 0 has no refined descendants.
//! * **Weights that reach 1 before a bound ends.** A node whose ball comes
//!   to reach the point has no finite bound and must be refined; its
//!   weight has a floor from its clearance (see [`near`]) that reaches 1
//!   there, so the blend does not switch where the ball reaches the point.
//! * **Nested intervals.** A node's certified interval `A` and the sum `C`
//!   of its children's both hold the node's exact value, so their
//!   intersection does too; a node refined with weight `alpha` counts for
//!   `(1 - alpha) A + alpha (A ∩ C)`, which holds the exact value (a mixture
//!   of two intervals that both hold it) and lies in `A`. So refining never
//!   widens the bound, and a node counts the same whether the list refined
//!   it (a frame of [`Nesting`]) or the blend expands it (an [`Item`]):
//!   nothing changes where a node passes from one to the other. Without it,
//!   children whose summed error exceeds their parent's made the blended
//!   cut miss the threshold at some points and not at their neighbours.
//! * **A level that solves for the target.** The level is the root of the
//!   blended cut's excess over the target ([`interpolate`]), not a function
//!   of the list's last steps: those depend on the order in which the list
//!   took nodes of nearly equal priority, and placing the level from them
//!   left jumps where two such nodes traded places; the root does not.

use glam::DVec3;

use super::engine::{Cut, Region};
use super::error_list::{Class, Entry, ErrorList, Seen};
use super::point::{Point, PointScratch, reported_bound};
use super::threshold::{Target, Threshold};
use crate::geometry::Cone;
use crate::numeric::CompensatedSum;
use crate::shader::Shader;
use crate::tree::Node;
use crate::visibility::Visibility;

/// No parent: a frame of the root, or an item of a waiting entry.
pub(crate) const NO_PARENT: u32 = u32::MAX;

/// A certified interval per channel; `None` for the whole line (a node with
/// no finite bound).
type Interval = Option<(DVec3, DVec3)>;

/// A running sum of intervals, with the infinite ones counted apart (they
/// leave the sum as they entered it).
#[derive(Clone, Copy, Debug, Default)]
struct Running {
    lo: DVec3,
    hi: DVec3,
    infinite: u32,
}

impl Running {
    #[inline]
    fn add(&mut self, i: Interval) {
        match i {
            Some((lo, hi)) => {
                self.lo += lo;
                self.hi += hi;
            }
            None => self.infinite += 1,
        }
    }

    #[inline]
    fn sub(&mut self, i: Interval) {
        match i {
            Some((lo, hi)) => {
                self.lo -= lo;
                self.hi -= hi;
            }
            None => self.infinite -= 1,
        }
    }

    #[inline]
    fn interval(&self) -> Interval {
        (self.infinite == 0).then_some((self.lo, self.hi))
    }
}

/// The part of the cut the error list refined, recorded (only with
/// interpolation) so that the list's running totals and the blend can
/// intersect each refined node's interval with its children's.
#[derive(Debug, Default)]
pub(crate) struct Nesting {
    /// The shading point, as the nodes' cones see it (for [`near`]).
    pub(crate) point: DVec3,
    /// The nodes the list refined, in the order it refined them (a parent
    /// before its children).
    frames: Vec<Frame>,
    /// Per slot of the error list: the frame of the entry's parent, or
    /// [`NO_PARENT`] for the root.
    parents: Vec<u32>,
    /// What lies outside any refined node, running: the root's exact value
    /// if it was settled, else its interval or its refinement's.
    top: Running,
    /// The same, exactly: the root's settled value.
    top_settled: CompensatedSum,
    /// What lies outside any frame and counts whole at every level the
    /// blend tries (see [`expand`]), exactly settled values included.
    top_fixed_lo: CompensatedSum,
    top_fixed_hi: CompensatedSum,
    /// The magnitudes of every fixed term, frames' and items', for the
    /// rounding allowance.
    fixed_magnitude: DVec3,
    /// Accumulators of [`fold`](Self::fold) and the blend.
    top_lo: CompensatedSum,
    top_hi: CompensatedSum,
}

/// A node the error list refined.
#[derive(Clone, Copy, Debug)]
struct Frame {
    /// The frame of its parent, or [`NO_PARENT`].
    parent: u32,
    /// Its priority when it was refined; infinite for a node the list had
    /// to refine whatever its error (over the maximal contribution), which
    /// the blend never un-refines.
    key: f64,
    /// Its weight's floor from its clearance (see [`near`]).
    near: f64,
    /// Its certified interval when it was refined.
    own: Interval,
    /// What its refinement settled exactly (lights, dark or error-free
    /// children).
    settled: CompensatedSum,
    /// Its children's intervals and settled values, running.
    running: Running,
    /// What it last contributed to its parent's running sum.
    current: Interval,
    /// Its settled value plus what counts whole under it at every level the
    /// blend tries.
    fixed_lo: CompensatedSum,
    fixed_hi: CompensatedSum,
    /// Accumulators of [`fold`](Nesting::fold) and the blend.
    sum_lo: CompensatedSum,
    sum_hi: CompensatedSum,
}

impl Nesting {
    pub(crate) fn clear(&mut self) {
        self.frames.clear();
        self.parents.clear();
        self.top = Running::default();
        self.top_settled = CompensatedSum::default();
    }

    /// The running sum of frame `frame`'s children (or of what lies
    /// outside any frame).
    #[inline]
    fn running(&mut self, frame: u32) -> &mut Running {
        if frame == NO_PARENT {
            &mut self.top
        } else {
            &mut self.frames[frame as usize].running
        }
    }

    /// Records an entry pushed into the next slot of the list, its parent
    /// frame `parent` (call [`finish`](Self::finish) once a refinement has
    /// pushed its children).
    #[inline]
    pub(crate) fn pushed(&mut self, e: &Entry, parent: u32) {
        self.parents.push(parent);
        self.running(parent).add(interval(e));
    }

    /// Records an exact value settled under frame `frame` (or outside any).
    #[inline]
    pub(crate) fn settled(&mut self, frame: u32, value: DVec3) {
        if value == DVec3::ZERO {
            return;
        }
        self.running(frame).add(Some((value, value)));
        if frame == NO_PARENT {
            self.top_settled.add(value);
        } else {
            self.frames[frame as usize].settled.add(value);
        }
    }

    /// Records that the list took the entry `e` from slot `slot` (to refine
    /// it or to ask about it): it leaves its parent's running sum. Returns
    /// its parent frame.
    #[inline]
    pub(crate) fn taken(&mut self, e: &Entry, slot: u32) -> u32 {
        let parent = self.parents[slot as usize];
        self.running(parent).sub(interval(e));
        parent
    }

    /// Records that the list refines `e`, just taken, under frame `parent`;
    /// returns the new frame, which contributes nothing until
    /// [`finish`](Self::finish)ed.
    #[inline]
    pub(crate) fn refined(&mut self, e: &Entry, parent: u32, near: f64) -> u32 {
        self.frames.push(Frame {
            parent,
            near,
            key: if e.class == Class::Error {
                e.key
            } else {
                f64::INFINITY
            },
            own: interval(e),
            settled: CompensatedSum::default(),
            running: Running::default(),
            current: Some((DVec3::ZERO, DVec3::ZERO)),
            fixed_lo: CompensatedSum::default(),
            fixed_hi: CompensatedSum::default(),
            sum_lo: CompensatedSum::default(),
            sum_hi: CompensatedSum::default(),
        });
        (self.frames.len() - 1) as u32
    }

    /// Carries a change of frame `frame`'s running sum up to the totals:
    /// each frame on the way contributes its own interval intersected with
    /// its children's.
    #[inline]
    pub(crate) fn finish(&mut self, mut frame: u32) {
        while frame != NO_PARENT {
            let f = &mut self.frames[frame as usize];
            let now = intersect(f.own, f.running.interval());
            let before = std::mem::replace(&mut f.current, now);
            if before == now {
                return;
            }
            let parent = f.parent;
            let running = self.running(parent);
            running.sub(before);
            running.add(now);
            frame = parent;
        }
    }

    /// The running totals as `(estimate, error)`, an infinite error while a
    /// node with no finite bound waits. They subtract and may drift: a stop
    /// is confirmed with [`fold`](Self::fold).
    #[inline]
    pub(crate) fn totals(&self) -> (DVec3, DVec3) {
        match self.top.interval() {
            Some((lo, hi)) => {
                let half = 0.5 * (hi - lo);
                (lo + half, half)
            }
            None => (DVec3::ZERO, DVec3::INFINITY),
        }
    }

    /// The totals recomputed from scratch with compensated sums, as the
    /// radiance and certified bound of the cut: the waiting entries and
    /// what the list settled, each refined node's interval intersected with
    /// its children's.
    pub(crate) fn fold(&mut self, list: &ErrorList) -> (DVec3, DVec3) {
        self.reset_sums(false);
        let mut magnitude = DVec3::ZERO;
        for (e, slot) in list.waiting() {
            let (lo, hi) = bounds(interval(e));
            self.add::<true>(self.parents[slot as usize], lo, hi, &mut magnitude);
        }
        self.fold_frames::<true>(magnitude, &Ramp::FULL)
    }

    /// Starts every accumulator from its fixed terms (see [`expand`]) if
    /// `fixed`, else from the exact values settled under it.
    fn reset_sums(&mut self, fixed: bool) {
        for f in &mut self.frames {
            (f.sum_lo, f.sum_hi) = if fixed {
                (f.fixed_lo, f.fixed_hi)
            } else {
                (f.settled, f.settled)
            };
        }
        (self.top_lo, self.top_hi) = if fixed {
            (self.top_fixed_lo, self.top_fixed_hi)
        } else {
            (self.top_settled, self.top_settled)
        };
    }

    /// Adds an interval to the accumulators of frame `frame` (or of what
    /// lies outside any), compensated if `EXACT`.
    #[inline]
    fn add<const EXACT: bool>(&mut self, frame: u32, lo: DVec3, hi: DVec3, magnitude: &mut DVec3) {
        let (sum_lo, sum_hi) = self.sums(frame, false);
        accumulate::<EXACT>(sum_lo, sum_hi, lo, hi);
        *magnitude += lo.abs() + hi.abs();
    }

    /// The accumulators of frame `frame` (or of what lies outside any):
    /// its fixed terms (see [`expand`]) or its running sums.
    #[inline]
    fn sums(&mut self, frame: u32, fixed: bool) -> (&mut CompensatedSum, &mut CompensatedSum) {
        match (frame == NO_PARENT, fixed) {
            (true, true) => (&mut self.top_fixed_lo, &mut self.top_fixed_hi),
            (true, false) => (&mut self.top_lo, &mut self.top_hi),
            (false, true) => {
                let f = &mut self.frames[frame as usize];
                (&mut f.fixed_lo, &mut f.fixed_hi)
            }
            (false, false) => {
                let f = &mut self.frames[frame as usize];
                (&mut f.sum_lo, &mut f.sum_hi)
            }
        }
    }

    /// Adds an interval to the fixed terms of frame `frame` (or of what
    /// lies outside any).
    #[inline]
    fn add_fixed(&mut self, frame: u32, lo: DVec3, hi: DVec3) {
        let (sum_lo, sum_hi) = self.sums(frame, true);
        accumulate::<true>(sum_lo, sum_hi, lo, hi);
        self.fixed_magnitude += lo.abs() + hi.abs();
    }

    /// The largest priority of a frame the blend may un-refine: above
    /// `band` times it, every such frame counts for its own interval.
    fn highest_key(&self) -> Option<f64> {
        self.frames
            .iter()
            .map(|f| f.key)
            .filter(|k| k.is_finite())
            .reduce(f64::max)
    }

    /// Folds the frames' accumulators into their parents', children first,
    /// each frame weighted by `ramp`, and returns the midpoint and
    /// half-width of the total: certified if `EXACT` (compensated sums),
    /// else plain sums, for a search.
    fn fold_frames<const EXACT: bool>(
        &mut self,
        mut magnitude: DVec3,
        ramp: &Ramp,
    ) -> (DVec3, DVec3) {
        for f in (0..self.frames.len()).rev() {
            let fr = &self.frames[f];
            let parent = fr.parent;
            let alpha = ramp.weight(fr.key, fr.near);
            let (lo, hi) = nest(
                alpha,
                bounds(fr.own),
                &fr.sum_lo,
                &fr.sum_hi,
                &mut magnitude,
            );
            self.add::<EXACT>(parent, lo, hi, &mut magnitude);
        }
        let (lo, hi) = (self.top_lo.value(), self.top_hi.value());
        if !(lo.is_finite() && hi.is_finite()) {
            return (DVec3::ZERO, DVec3::INFINITY);
        }
        // Every operation rounds by at most a few ulps of its operands:
        // compensated sums (two ulps of the sum of their terms'
        // magnitudes), a mixture of two endpoints (three roundings), a max
        // or min (exact), and the final midpoint and half-width; none
        // multiplies an earlier error by more than 1 (weights are in
        // [0, 1]; an intersection moves an end by at most as much as its
        // operands do). `magnitude` holds every term added to a sum and
        // every mixture's operands; eight units of roundoff of it cover
        // them all.
        // The midpoint is `lo + half`, exactly `lo` for a point interval
        // (halving a subnormal end would round it); below the normal range
        // the relative allowance underflows, and two of the smallest
        // subnormals cover the halving of the width.
        let magnitude = magnitude + lo.abs() + hi.abs();
        let rounding = 8.0 * f64::EPSILON * magnitude;
        let half = 0.5 * (hi - lo);
        let tiny = DVec3::select(
            half.cmpgt(DVec3::ZERO),
            DVec3::splat(2.0 * f64::from_bits(1)),
            DVec3::ZERO,
        );
        (lo + half, reported_bound(half + rounding + tiny))
    }
}

/// The certified interval an entry counts for: its estimate plus or minus
/// its counted error; the whole line for a node with no finite bound.
#[inline]
fn interval(e: &Entry) -> Interval {
    if e.class == Class::Unbounded {
        return None;
    }
    let (estimate, error) = e.counted();
    Some((estimate - error, estimate + error))
}

/// An interval's ends, infinite for the whole line.
#[inline]
fn bounds(i: Interval) -> (DVec3, DVec3) {
    i.unwrap_or((DVec3::NEG_INFINITY, DVec3::INFINITY))
}

/// The intersection of two intervals that both hold the exact value; where
/// rounding leaves them disjoint in a channel, the gap between them.
#[inline]
fn intersect(a: Interval, b: Interval) -> Interval {
    match (a, b) {
        (Some((a_lo, a_hi)), Some((b_lo, b_hi))) => {
            let (lo, hi) = (a_lo.max(b_lo), a_hi.min(b_hi));
            Some((lo.min(hi), lo.max(hi)))
        }
        (Some(a), None) => Some(a),
        (None, b) => b,
    }
}

/// A node the blend refines (with weight `alpha` at the level being
/// tried), waiting for its children's intervals.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Item {
    node: u32,
    /// The item of its parent, or [`NO_PARENT`] for a waiting entry, whose
    /// result goes to `frame`.
    parent: u32,
    frame: u32,
    /// Its priority, the cap of its children's.
    key: f64,
    /// Its weight's floor from its clearance (see [`near`]).
    near: f64,
    visible: bool,
    lo: DVec3,
    hi: DVec3,
    /// What its refinement settled exactly plus its children that count
    /// whole at every level tried.
    fixed_lo: CompensatedSum,
    fixed_hi: CompensatedSum,
    sum_lo: CompensatedSum,
    sum_hi: CompensatedSum,
}

/// Refinement weights at a level: nodes of priority at least `level` are
/// refined fully, and the weight falls linearly to 0 at `floor = level /
/// band`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ramp {
    level: f64,
    floor: f64,
}

impl Ramp {
    /// Every node refined fully: the error list's own cut.
    const FULL: Self = Self {
        level: f64::NEG_INFINITY,
        floor: f64::NEG_INFINITY,
    };

    pub(crate) fn new(level: f64, band: f64) -> Self {
        Self {
            level,
            floor: level / band,
        }
    }

    /// The weight of a node of priority `key` whose clearance sets the
    /// floor `near` (see [`near`]).
    #[inline]
    pub(crate) fn weight(&self, key: f64, near: f64) -> f64 {
        self.alpha(key).max(near)
    }

    /// The weight of a node of priority `key` (infinite for a node with no
    /// finite bound, always refined).
    #[inline]
    pub(crate) fn alpha(&self, key: f64) -> f64 {
        if key >= self.level {
            1.0
        } else {
            ((key - self.floor) / (self.level - self.floor)).clamp(0.0, 1.0)
        }
    }
}

/// The floor of a node's weight from its clearance: 1 where its ball
/// reaches the point (where it has no finite bound and must be refined),
/// falling linearly in the clearance `q = (D - R) / D` (`D` the distance
/// from the point to the node's centre, `R` its radius) to 0 at
/// [`NEAR_CLEARANCE`] (`D = 1.5 R`), and 0 for a node that is a single
/// point. A node whose ball nears the point has a bound that grows without
/// limit; the floor makes its weight reach 1 before its bound does, so
/// that the blend changes continuously where the ball comes to reach the
/// point, as it does where a priority crosses the level.
#[inline]
pub(crate) fn near(node: &Node, point: DVec3) -> f64 {
    let radius = f64::from(node.radius);
    if radius == 0.0 {
        return 0.0;
    }
    let distance = (node.centroid.as_dvec3() - point).length();
    // `Cone::new` refuses the ball at a clearance of `MIN_CLEARANCE` or
    // less: the floor is 1 there.
    let clearance = (distance - radius) / distance - Cone::MIN_CLEARANCE;
    if !(clearance > 0.0) {
        return 1.0;
    }
    (1.0 - clearance / NEAR_CLEARANCE).clamp(0.0, 1.0)
}

/// The clearance `(D - R) / D` at and beyond which a node's weight has no
/// floor (see [`near`]): `D = 1.5 R`.
const NEAR_CLEARANCE: f64 = 1.0 / 3.0;

/// The level at which the error list stopped, for the per-node target
/// (whose excess does not depend on the blend) and the batch call's shared
/// cuts: between the key of the last refinement (where the list would have
/// stopped one step earlier) and the largest key left, in proportion to
/// where the excess over the target crossed zero, so that it is continuous
/// where the stopping step changes.
pub(crate) fn level(last_step: Option<(f64, f64)>, after: f64, top: f64) -> f64 {
    match last_step {
        Some((before, key)) if before > 0.0 && before.is_finite() => {
            let beta = (before / (before - after)).clamp(0.0, 1.0);
            key + beta * (top - key)
        }
        _ => top,
    }
}

/// What a refined node counts for: `(1 - alpha) A + alpha (A ∩ C)` for its
/// own interval `A = [lo, hi]` and its children's sum `C` (see
/// [`intersect`] where rounding leaves them disjoint). Adds the magnitudes
/// of the operands to `magnitude`, for the rounding allowance.
#[inline]
fn nest(
    alpha: f64,
    (lo, hi): (DVec3, DVec3),
    sum_lo: &CompensatedSum,
    sum_hi: &CompensatedSum,
    magnitude: &mut DVec3,
) -> (DVec3, DVec3) {
    if alpha <= 0.0 {
        *magnitude += lo.abs() + hi.abs();
        return (lo, hi);
    }
    let (c_lo, c_hi) = (sum_lo.value(), sum_hi.value());
    let (i_lo, i_hi) = bounds(intersect(Some((lo, hi)), Some((c_lo, c_hi))));
    *magnitude += c_lo.abs() + c_hi.abs();
    if alpha >= 1.0 {
        return (i_lo, i_hi);
    }
    *magnitude += lo.abs() + hi.abs();
    (
        lo * (1.0 - alpha) + i_lo * alpha,
        hi * (1.0 - alpha) + i_hi * alpha,
    )
}

/// Interpolation across levels after the error list (in `scratch`) met
/// `threshold` with `radiance` and `bound`: the blended radiance and
/// certified bound, or `None` to keep the list's cut (no interpolation
/// asked for, nothing refined, a target the blend cannot meet, or a budget
/// the blend would exceed).
///
/// The level `tau` is where the blended cut just meets the target:
/// `g(tau) = 0` for the excess `g` of the blend at level `tau` over the
/// target. `g` is continuous in `tau` and in the shading point, and
/// non-decreasing in `tau` (a lower level refines more, which never widens
/// an interval, and moves the estimate by at most what it narrows the
/// bound), so its root is a continuous function of the shading point,
/// whatever order the list refined nodes of nearly equal priority in. The
/// list's cut brackets it: the blend at the last refinement's priority
/// refines at least as much as the list did, so it meets the target, and
/// above the largest priority times `band` it refines nothing. The root is
/// found by regula falsi (Illinois) on `ln tau`, each step a fold of the
/// blend's arena, which is expanded once, for the lowest level tried.
/// The per-node target's excess does not depend on the blend; it keeps
/// the level placed between the list's last two steps ([`level`]).
pub(crate) fn interpolate<S: Shader, V: Visibility>(
    cut: &mut Cut<'_, S, V, Point<'_, S>>,
    scratch: &mut PointScratch,
    threshold: &Threshold,
    last_step: Option<(f64, f64)>,
    radiance: DVec3,
    bound: DVec3,
) -> Option<(DVec3, DVec3)> {
    let band = threshold.interpolation()?;
    let PointScratch {
        list,
        nesting,
        items,
    } = scratch;
    let top = list.largest();
    let after = threshold.excess(radiance, bound, top);
    let list = &*list;
    if list.len() == 0 {
        return None;
    }
    if matches!(threshold.target(), Target::PerNode(_)) {
        let level = level(last_step, after, top);
        if !(level > 0.0 && level.is_finite() && expand(cut, list, nesting, items, level, band)) {
            return None;
        }
        return Some(fold_at::<true>(nesting, items, &Ramp::new(level, band)));
    }
    let (_, lowest) = last_step?;
    let highest = nesting.highest_key()?.max(lowest) * band;
    if !(lowest > 0.0 && highest.is_finite() && expand(cut, list, nesting, items, lowest, band)) {
        return None;
    }
    // The search sums plainly: a level counts as meeting the target only
    // with a margin for the plain sums' rounding, so that the certified
    // fold at the level found meets it too.
    let excess = |(r, e): (DVec3, DVec3)| {
        threshold.excess(r, e, 0.0) + PLAIN_SLACK * (r.abs() + e).max_element()
    };
    let mut at = |tau: f64| {
        let folded = fold_at::<false>(nesting, items, &Ramp::new(tau, band));
        (folded, excess(folded))
    };
    let ((_, bound), g_lo) = at(lowest);
    if !(g_lo <= 0.0) {
        return None;
    }
    // The least refined level known to meet the target.
    let mut best = lowest;
    // Above the list's last step times `band` the blend refines less than
    // the list did before that step, which missed the target; failing that,
    // above the largest priority times `band` it refines nothing.
    let (mut upper, mut g_up) = (lowest * band, 0.0);
    for candidate in [lowest * band, highest] {
        let (_, g) = at(candidate);
        (upper, g_up) = (candidate, g);
        if g > 0.0 {
            break;
        }
        best = candidate;
    }
    if g_up > 0.0 {
        // Illinois (regula falsi that halves the stale end's value) on `1 /
        // tau`, in which every weight is linear between its clamps.
        let (mut a, mut b) = (1.0 / lowest, 1.0 / upper);
        let (mut fa, mut fb) = (g_lo, g_up);
        let mut g_best = g_lo;
        let tolerance = ROOT_TOLERANCE * bound.max_element();
        let mut side = 0;
        for _ in 0..ROOT_STEPS {
            if g_best >= -tolerance || !(a - b > ROOT_SPAN * a) {
                break;
            }
            let c = (a + (b - a) * (fa / (fa - fb))).clamp(b, a);
            let (_, g) = at(1.0 / c);
            if g <= 0.0 {
                (a, fa, best, g_best) = (c, g, 1.0 / c, g);
                if side < 0 {
                    fb *= 0.5;
                }
                side = -1;
            } else {
                (b, fb) = (c, g);
                if side > 0 {
                    fa *= 0.5;
                }
                side = 1;
            }
        }
    }
    // The search summed plainly; the result is summed again, certified
    // (and where that misses the target after all, the most refined level
    // tried is).
    let found = fold_at::<true>(nesting, items, &Ramp::new(best, band));
    if threshold.met(found.0, found.1, 0.0) || best == lowest {
        return Some(found);
    }
    Some(fold_at::<true>(nesting, items, &Ramp::new(lowest, band)))
}

/// The plain sums' rounding allowed for in the search, relative to the
/// radiance and bound (a million terms' worth of `f64` roundings).
const PLAIN_SLACK: f64 = 1e-9;
/// Steps of the root search for the level, at most.
const ROOT_STEPS: u32 = 40;
/// The search stops once the blend's excess is within this fraction of its
/// bound below zero: the estimate then moves by about as much between
/// neighbouring points, far below any threshold.
const ROOT_TOLERANCE: f64 = 1e-4;
/// Or once the bracket on `ln tau` is this narrow (relative).
const ROOT_SPAN: f64 = 1e-14;

/// Expands the blend's arena for every level at or above `lowest`: the
/// waiting entries and, recursively, the children whose weight at `lowest`
/// is positive become items; everything else counts whole at every such
/// level (children's keys are capped at their parents', so weights only
/// fall with the level) and is summed once into the fixed terms of its
/// item or frame. `false` when the expansion would exceed the budget.
fn expand<S: Shader, V: Visibility>(
    cut: &mut Cut<'_, S, V, Point<'_, S>>,
    list: &ErrorList,
    nesting: &mut Nesting,
    items: &mut Vec<Item>,
    lowest: f64,
    band: f64,
) -> bool {
    let ramp = Ramp::new(lowest, band);
    for f in &mut nesting.frames {
        f.fixed_lo = f.settled;
        f.fixed_hi = f.settled;
    }
    nesting.top_fixed_lo = nesting.top_settled;
    nesting.top_fixed_hi = nesting.top_settled;
    nesting.fixed_magnitude = DVec3::ZERO;
    items.clear();
    let point = cut.region.surface.point;
    for (e, slot) in list.waiting() {
        let frame = nesting.parents[slot as usize];
        let near = near(&cut.tree.nodes[e.node as usize], point);
        if ramp.weight(e.key, near) > 0.0 {
            items.push(item(e, near, NO_PARENT, frame));
        } else {
            let (lo, hi) = bounds(interval(e));
            nesting.add_fixed(frame, lo, hi);
        }
    }
    // Breadth-first: every item is refined once, its children kept whole or
    // appended as items (parents before children).
    let mut next = 0;
    while next < items.len() {
        let (node, visible, key, frame) = {
            let it = &items[next];
            (it.node, it.visible, it.key, it.frame)
        };
        let tree = cut.tree;
        if !<Point<'_, S> as Region<S>>::affordable(cut, list, &tree.nodes[node as usize], visible)
        {
            return false;
        }
        let parent = next as u32;
        let outer = std::mem::take(&mut cut.region.settled);
        let magnitude = &mut nesting.fixed_magnitude;
        cut.refine(node as usize, visible, 1.0, &mut |mut e: Entry| {
            // Children's priorities are capped at their parent's, but a
            // child with no finite bound (its ball reaches the point) is
            // refined at every level its parent is: its interval is the
            // whole line, and a weight below 1 would mix that in.
            if e.class != Class::Unbounded {
                e.key = e.key.min(key);
            }
            let near = near(&tree.nodes[e.node as usize], point);
            if ramp.weight(e.key, near) > 0.0 {
                items.push(item(&e, near, parent, frame));
            } else {
                let (lo, hi) = bounds(interval(&e));
                let p = &mut items[parent as usize];
                p.fixed_lo.add(lo);
                p.fixed_hi.add(hi);
                *magnitude += lo.abs() + hi.abs();
            }
        });
        let settled = std::mem::replace(&mut cut.region.settled, outer).value();
        let p = &mut items[next];
        p.fixed_lo.add(settled);
        p.fixed_hi.add(settled);
        nesting.fixed_magnitude += 2.0 * settled.abs();
        next += 1;
    }
    true
}

/// The blend at the weights of `ramp`, over the arena [`expand`] built
/// for a level at or below `ramp`'s: the radiance and bound, certified if
/// `EXACT` (else summed plainly, for the search).
fn fold_at<const EXACT: bool>(
    nesting: &mut Nesting,
    items: &mut [Item],
    ramp: &Ramp,
) -> (DVec3, DVec3) {
    nesting.reset_sums(true);
    let mut magnitude = nesting.fixed_magnitude;
    for it in items.iter_mut() {
        it.sum_lo = it.fixed_lo;
        it.sum_hi = it.fixed_hi;
    }
    // Children into parents: the items in reverse, then the frames.
    for i in (0..items.len()).rev() {
        let it = &items[i];
        let (parent, frame) = (it.parent, it.frame);
        let (lo, hi) = nest(
            ramp.weight(it.key, it.near),
            (it.lo, it.hi),
            &it.sum_lo,
            &it.sum_hi,
            &mut magnitude,
        );
        if parent == NO_PARENT {
            nesting.add::<EXACT>(frame, lo, hi, &mut magnitude);
        } else {
            let p = &mut items[parent as usize];
            accumulate::<EXACT>(&mut p.sum_lo, &mut p.sum_hi, lo, hi);
            magnitude += lo.abs() + hi.abs();
        }
    }
    nesting.fold_frames::<EXACT>(magnitude, ramp)
}

/// Adds an interval's ends to their sums, compensated if `EXACT`.
#[inline]
fn accumulate<const EXACT: bool>(
    sum_lo: &mut CompensatedSum,
    sum_hi: &mut CompensatedSum,
    lo: DVec3,
    hi: DVec3,
) {
    if EXACT {
        sum_lo.add(lo);
        sum_hi.add(hi);
    } else {
        sum_lo.add_plain(lo);
        sum_hi.add_plain(hi);
    }
}

/// An item for `e`.
#[inline]
fn item(e: &Entry, near: f64, parent: u32, frame: u32) -> Item {
    let (lo, hi) = bounds(interval(e));
    Item {
        node: e.node,
        parent,
        frame,
        key: e.key,
        near,
        visible: e.seen == Seen::Visible,
        lo,
        hi,
        fixed_lo: CompensatedSum::default(),
        fixed_hi: CompensatedSum::default(),
        sum_lo: CompensatedSum::default(),
        sum_hi: CompensatedSum::default(),
    }
}
