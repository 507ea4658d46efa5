//! The paper's error list: the cut's unrefined nodes by decreasing priority,
//! with their running sums.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::DVec3;

use crate::numeric::CompensatedSum;

/// Why a node is waiting in the error list, in the order classes are
/// refined: a node that may not stay in the cut comes before any error.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Class {
    /// An ordinary node, keyed by its error.
    Error,
    /// Its upper bound exceeds the maximal-contribution (specular)
    /// threshold.
    OverContribution,
    /// No finite bound: the node's ball reaches the shading point.
    Unbounded,
}

/// What the host has said about an entry's visibility.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Seen {
    /// Fully visible: the unoccluded interval holds.
    Visible,
    /// Not asked yet: anything in `[0, unoccluded upper bound]`.
    Unknown,
    /// Partially occluded: still anything in `[0, upper]`, estimated at the
    /// host's visible fraction when it gives one, else at the middle.
    Partial(Option<f32>),
}

/// An entry of the cut: a node not refined (or not asked about) yet.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Entry {
    pub(crate) class: Class,
    /// Largest channel of the counted error: the error list's key.
    pub(crate) key: f64,
    pub(crate) node: u32,
    pub(crate) seen: Seen,
    /// The unoccluded estimate and its error.
    pub(crate) estimate: DVec3,
    pub(crate) error: DVec3,
}

impl Entry {
    /// An entry with its key set from what it counts for.
    #[inline]
    pub(crate) fn new(class: Class, node: u32, seen: Seen, estimate: DVec3, error: DVec3) -> Self {
        let mut e = Self {
            class,
            key: 0.0,
            node,
            seen,
            estimate,
            error,
        };
        e.key = match class {
            Class::Unbounded => f64::INFINITY,
            _ => e.counted().1.max_element(),
        };
        e
    }

    /// The estimate and certified error the entry counts for in the cut.
    /// Unless it is known visible, its contribution lies anywhere in `[0,
    /// up]` with `up = estimate + error` (at least the unoccluded upper
    /// bound): estimated at the middle (error `up / 2`, the smallest
    /// possible), or at the host's visible fraction of the unoccluded
    /// estimate (error the larger distance to an end).
    #[inline]
    pub(crate) fn counted(&self) -> (DVec3, DVec3) {
        match self.seen {
            Seen::Visible => (self.estimate, self.error),
            Seen::Unknown | Seen::Partial(None) => {
                let half = 0.5 * (self.estimate + self.error);
                (half, half)
            }
            Seen::Partial(Some(fraction)) => {
                let up = self.estimate + self.error;
                let estimate = (self.estimate * f64::from(fraction)).clamp(DVec3::ZERO, up);
                (estimate, estimate.max(up - estimate))
            }
        }
    }
}

/// What the heap orders: an entry's class and key, and where its record
/// lies. Kept to 16 bytes so that sifting is cheap.
#[derive(Clone, Copy, Debug)]
struct Key {
    key: f64,
    slot: u32,
    class: Class,
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

/// Unrefined nodes by decreasing (class, error), their records in a side
/// vector, with running sums of their estimates and errors and counts of
/// the nodes that must be refined whatever the error. Keeps its capacity
/// across calls.
#[derive(Debug, Default)]
pub(crate) struct ErrorList {
    heap: BinaryHeap<Key>,
    entries: Vec<Entry>,
    /// Running sums; they subtract and may drift, so a stop is confirmed
    /// with [`resum`](Self::resum).
    estimate: DVec3,
    error: DVec3,
    over_contribution: u32,
    unbounded: u32,
}

impl ErrorList {
    pub(crate) fn clear(&mut self) {
        self.heap.clear();
        self.entries.clear();
        self.estimate = DVec3::ZERO;
        self.error = DVec3::ZERO;
        self.over_contribution = 0;
        self.unbounded = 0;
    }

    /// Adds an entry; returns its slot, the number of entries pushed
    /// before it since the last [`clear`](Self::clear).
    #[inline]
    pub(crate) fn push(&mut self, e: Entry) -> u32 {
        match e.class {
            Class::Unbounded => self.unbounded += 1,
            Class::OverContribution => self.over_contribution += 1,
            Class::Error => {}
        }
        let (estimate, error) = e.counted();
        self.estimate += estimate;
        self.error += error;
        let slot = self.entries.len() as u32;
        self.heap.push(Key {
            key: e.key,
            slot,
            class: e.class,
        });
        self.entries.push(e);
        slot
    }

    /// The entry that would be refined next.
    #[inline]
    pub(crate) fn peek(&self) -> Option<&Entry> {
        self.heap.peek().map(|k| &self.entries[k.slot as usize])
    }

    #[inline]
    pub(crate) fn pop(&mut self) -> Option<Entry> {
        self.pop_slot().map(|(e, _)| e)
    }

    /// [`pop`](Self::pop), with the entry's slot.
    #[inline]
    pub(crate) fn pop_slot(&mut self) -> Option<(Entry, u32)> {
        let slot = self.heap.pop()?.slot;
        let e = self.entries[slot as usize];
        match e.class {
            Class::Unbounded => self.unbounded -= 1,
            Class::OverContribution => self.over_contribution -= 1,
            Class::Error => {}
        }
        let (estimate, error) = e.counted();
        self.estimate -= estimate;
        self.error -= error;
        Some((e, slot))
    }

    /// The largest error waiting (0 when empty).
    #[inline]
    pub(crate) fn largest(&self) -> f64 {
        self.peek().map_or(0.0, |e| e.key)
    }

    /// Whether every waiting node may stay in the cut: none is unbounded or
    /// over the maximal contribution.
    #[inline]
    pub(crate) fn may_stop(&self) -> bool {
        self.unbounded == 0 && self.over_contribution == 0
    }

    /// Whether a node with no finite bound is waiting.
    pub(crate) fn has_unbounded(&self) -> bool {
        self.unbounded > 0
    }

    /// Running sums of the waiting estimates and errors.
    #[inline]
    pub(crate) fn sums(&self) -> (DVec3, DVec3) {
        (self.estimate, self.error)
    }

    /// Recomputes the sums from scratch with compensated summation, replaces
    /// the running ones with them and returns them.
    pub(crate) fn resum(&mut self) -> (DVec3, DVec3) {
        let mut estimate = CompensatedSum::default();
        let mut error = CompensatedSum::default();
        for k in &self.heap {
            let (e, r) = self.entries[k.slot as usize].counted();
            estimate.add(e);
            error.add(r);
        }
        (self.estimate, self.error) = (estimate.value(), error.value());
        (self.estimate, self.error)
    }

    /// Number of waiting entries.
    pub(crate) fn len(&self) -> usize {
        self.heap.len()
    }

    /// The waiting entries with their slots, in no particular order.
    pub(crate) fn waiting(&self) -> impl Iterator<Item = (&Entry, u32)> + '_ {
        self.heap
            .iter()
            .map(|k| (&self.entries[k.slot as usize], k.slot))
    }

    /// Removes every waiting entry, in no particular order.
    pub(crate) fn drain(&mut self) -> impl Iterator<Item = Entry> + '_ {
        let entries = &self.entries;
        self.heap.drain().map(|k| entries[k.slot as usize])
    }
}
