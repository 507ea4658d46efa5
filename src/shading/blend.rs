//! Interpolation across levels (see [`Threshold::with_interpolation`]): the
//! cut's last nodes blended with their children so the estimate is
//! continuous in the shading point.
//!
//! Two things make the blend a continuous function of the shading point:
//!
//! * **A monotone order.** With interpolation, a node's priority in the
//!   error list is capped at its parent's, so nodes are refined in
//!   decreasing priority down every path and the refined set is a function
//!   of the priorities alone: two nodes trading places changes nothing at
//!   the point where their priorities are equal. (A child's error may
//!   exceed its parent's; uncapped, refining the parent first would let the
//!   child jump the queue, and the cut would change abruptly where two
//!   priorities cross.)
//! * **Nested intervals.** A node's certified interval `A` and the sum `C`
//!   of its children's both hold the node's exact value, so their
//!   intersection does too; a node refined with weight `alpha` counts for
//!   `(1 - alpha) A + alpha (A ∩ C)`, which holds the exact value (a mixture
//!   of two intervals that both hold it) and lies in `A`. So refining never
//!   widens the bound, whether the list refined the node or the blend
//!   ramps it, and the nodes the list refined apply their intersections
//!   the same way as nodes the blend refines: nothing changes where a node
//!   passes from one to the other. Without it, children whose summed error
//!   exceeds their parent's made the blended cut miss the threshold at some
//!   points and not at their neighbours.

use glam::DVec3;

use super::error_list::{Class, Entry, ErrorList, Seen};
use super::refine::{Cut, reported_bound};
#[cfg(doc)]
use super::threshold::Threshold;
use crate::numeric::CompensatedSum;
use crate::shader::Shader;
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
    /// Accumulators of [`fold`](Self::fold) and the blend.
    top_lo: CompensatedSum,
    top_hi: CompensatedSum,
}

/// A node the error list refined.
#[derive(Clone, Copy, Debug)]
struct Frame {
    /// The frame of its parent, or [`NO_PARENT`].
    parent: u32,
    /// Its certified interval when it was refined.
    own: Interval,
    /// What its refinement settled exactly (lights, dark or error-free
    /// children).
    settled: CompensatedSum,
    /// Its children's intervals and settled values, running.
    running: Running,
    /// What it last contributed to its parent's running sum.
    current: Interval,
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
    pub(crate) fn refined(&mut self, e: &Entry, parent: u32) -> u32 {
        self.frames.push(Frame {
            parent,
            own: interval(e),
            settled: CompensatedSum::default(),
            running: Running::default(),
            current: Some((DVec3::ZERO, DVec3::ZERO)),
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
        self.reset_sums();
        let mut magnitude = DVec3::ZERO;
        for (e, slot) in list.waiting() {
            let (lo, hi) = bounds(interval(e));
            self.add(self.parents[slot as usize], lo, hi, &mut magnitude);
        }
        self.fold_frames(magnitude)
    }

    /// Sets every accumulator to the exact values settled under it.
    fn reset_sums(&mut self) {
        for f in &mut self.frames {
            f.sum_lo = f.settled;
            f.sum_hi = f.settled;
        }
        self.top_lo = self.top_settled;
        self.top_hi = self.top_settled;
    }

    /// Adds an interval to the accumulators of frame `frame` (or of what
    /// lies outside any).
    #[inline]
    fn add(&mut self, frame: u32, lo: DVec3, hi: DVec3, magnitude: &mut DVec3) {
        let (sum_lo, sum_hi) = if frame == NO_PARENT {
            (&mut self.top_lo, &mut self.top_hi)
        } else {
            let f = &mut self.frames[frame as usize];
            (&mut f.sum_lo, &mut f.sum_hi)
        };
        sum_lo.add(lo);
        sum_hi.add(hi);
        *magnitude += lo.abs() + hi.abs();
    }

    /// Folds the frames' accumulators into their parents', children first,
    /// and returns the midpoint and certified half-width of the total.
    fn fold_frames(&mut self, mut magnitude: DVec3) -> (DVec3, DVec3) {
        for f in (0..self.frames.len()).rev() {
            let fr = self.frames[f];
            let (lo, hi) = nest(1.0, bounds(fr.own), &fr.sum_lo, &fr.sum_hi, &mut magnitude);
            self.add(fr.parent, lo, hi, &mut magnitude);
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

/// A node the blend refines (with weight `alpha`), waiting for its
/// children's intervals.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Item {
    node: u32,
    /// The item of its parent, or [`NO_PARENT`] for a waiting entry, whose
    /// result goes to `frame`.
    parent: u32,
    frame: u32,
    alpha: f64,
    /// Its priority, the cap of its children's.
    key: f64,
    visible: bool,
    lo: DVec3,
    hi: DVec3,
    sum_lo: CompensatedSum,
    sum_hi: CompensatedSum,
}

/// The level at which the error list stopped, for the blend: between the
/// key of the last refinement (where the list would have stopped one step
/// earlier) and the largest key left, in proportion to where the excess
/// over the target crossed zero, so that it is continuous where the
/// stopping step changes.
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

/// Blends every unrefined node of `list` whose priority lies within `band`
/// of `level` with its children, recursively, and intersects every refined
/// node's interval with its children's (the list's, recorded in
/// `nesting`, and the blend's). Returns the blended radiance and certified
/// bound, or `None` when there is nothing to blend or blending would exceed
/// the budget.
pub(crate) fn blend<S: Shader, V: Visibility>(
    cut: &mut Cut<'_, S, V>,
    list: &ErrorList,
    nesting: &mut Nesting,
    items: &mut Vec<Item>,
    level: f64,
    band: f64,
) -> Option<(DVec3, DVec3)> {
    if list.len() == 0 || !(level > 0.0 && level.is_finite()) {
        return None;
    }
    let floor = level / band;
    let ramp = |e: &Entry| {
        if e.class == Class::Unbounded {
            1.0
        } else {
            ((e.key - floor) / (level - floor)).clamp(0.0, 1.0)
        }
    };
    // Operands' magnitudes, for the rounding allowance.
    let mut magnitude = DVec3::ZERO;
    nesting.reset_sums();
    items.clear();
    // Waiting entries: kept whole (alpha = 0) in their parent's sum, or
    // refined by the blend.
    for (e, slot) in list.waiting() {
        let frame = nesting.parents[slot as usize];
        let alpha = ramp(e);
        if alpha > 0.0 {
            items.push(item(e, NO_PARENT, frame, alpha));
        } else {
            let (lo, hi) = bounds(interval(e));
            nesting.add(frame, lo, hi, &mut magnitude);
        }
    }
    // Expand breadth-first: every item is refined once, its children kept
    // whole or appended as items (parents before children).
    let mut next = 0;
    while next < items.len() {
        let it = items[next];
        let node = cut.tree.nodes[it.node as usize];
        if !cut.can_refine(&node, it.visible) {
            return None;
        }
        let parent = next as u32;
        let outer = std::mem::take(&mut cut.settled);
        cut.refine(&node, it.visible, 1.0, |mut e| {
            e.key = e.key.min(it.key);
            let alpha = ramp(&e);
            if alpha > 0.0 {
                items.push(item(&e, parent, it.frame, alpha));
            } else {
                let (lo, hi) = bounds(interval(&e));
                let p = &mut items[parent as usize];
                p.sum_lo.add(lo);
                p.sum_hi.add(hi);
                magnitude += lo.abs() + hi.abs();
            }
        });
        let settled = std::mem::replace(&mut cut.settled, outer).value();
        let p = &mut items[next];
        p.sum_lo.add(settled);
        p.sum_hi.add(settled);
        magnitude += 2.0 * settled.abs();
        next += 1;
    }
    // Fold children into parents: the items in reverse, then the frames.
    for i in (0..items.len()).rev() {
        let it = items[i];
        let (lo, hi) = nest(
            it.alpha,
            (it.lo, it.hi),
            &it.sum_lo,
            &it.sum_hi,
            &mut magnitude,
        );
        if it.parent == NO_PARENT {
            nesting.add(it.frame, lo, hi, &mut magnitude);
        } else {
            let p = &mut items[it.parent as usize];
            p.sum_lo.add(lo);
            p.sum_hi.add(hi);
            magnitude += lo.abs() + hi.abs();
        }
    }
    let (radiance, bound) = nesting.fold_frames(magnitude);
    bound.is_finite().then_some((radiance, bound))
}

/// An item for `e`, refined with weight `alpha`.
#[inline]
fn item(e: &Entry, parent: u32, frame: u32, alpha: f64) -> Item {
    let (lo, hi) = bounds(interval(e));
    Item {
        node: e.node,
        parent,
        frame,
        alpha,
        key: e.key,
        visible: e.seen == Seen::Visible,
        lo,
        hi,
        sum_lo: CompensatedSum::default(),
        sum_hi: CompensatedSum::default(),
    }
}
