//! The paper's error list: the cut's unrefined nodes by decreasing priority,
//! with their running sums.

use std::cmp::Ordering;

use glam::DVec3;

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

/// The key of a slot no longer waiting (keys are at least 0).
const POPPED: f64 = -1.0;

/// No slot: the end of a bucket's list, an empty bucket.
const NONE: u32 = u32::MAX;

/// Buckets per octave of the key: the key's top four mantissa bits.
const BUCKET_SHIFT: u32 = 48;
/// Buckets in the window: 128 octaves. Keys above or below the window
/// share its top or bottom bucket; the order stays exact (a bucket is
/// searched for its largest key), only the search grows.
const BUCKETS: usize = 2048;
/// Room above the first ordinary key pushed after a clear (eight
/// octaves): the root's error rarely grows in its children.
const HEADROOM: usize = 8 * 16;

/// Unrefined nodes by decreasing (class, error), with running sums of
/// their estimates and errors and counts of the nodes that must be refined
/// whatever the error. Keeps its capacity across calls.
///
/// A bucket queue: ordinary entries go to a bucket by the exponent and top
/// four mantissa bits of their key (a 16th of an octave) and the
/// largest entry is searched for in the highest non-empty bucket, so a pop
/// costs a short scan instead of a heap's `log n` sifts of scattered
/// records, and the order is exactly that of a heap, ties going to the entry pushed first. The few
/// entries of the other classes wait in a list of their own, searched
/// first.
#[derive(Debug)]
pub(crate) struct ErrorList {
    entries: Vec<Entry>,
    /// Per slot: the key (scanned without touching the records) and the
    /// next slot in its bucket.
    keys: Vec<f64>,
    next: Vec<u32>,
    /// First slot of each bucket's list.
    heads: Box<[u32]>,
    /// Where the window starts: a key's bucket is `clamp(bits - base)`,
    /// `bits` its exponent and top mantissa bits; set by the first ordinary
    /// key since the clear.
    base: i64,
    /// Buckets up to `top` may be non-empty; none above.
    top: usize,
    /// One bit per bucket, set while the bucket holds an entry: the highest
    /// non-empty bucket is found a word at a time, not a bucket at a time
    /// (keys of one cut span tens of octaves, hundreds of buckets).
    occupied: [u64; BUCKETS / 64],
    /// The range of buckets touched since the last clear.
    touched: (usize, usize),
    /// Slots of the waiting entries of classes other than `Error`.
    special: Vec<u32>,
    /// The largest waiting entry, once searched for: (slot, the slot before
    /// it in its bucket or `NONE`, its bucket or `NONE` for a special one).
    best: Option<(u32, u32, usize)>,
    waiting: usize,
    /// Running sums; they subtract and may drift, so a stop is confirmed
    /// with [`resum`](Self::resum).
    estimate: DVec3,
    error: DVec3,
    /// Whether the sums are those of the last [`resum`](Self::resum), with
    /// no push or pop since.
    fresh: bool,
    /// The last [`resum`](Self::resum)'s bound on its own rounding.
    rounding: DVec3,
    over_contribution: u32,
    unbounded: u32,
}

impl Default for ErrorList {
    fn default() -> Self {
        Self {
            entries: Vec::new(),
            keys: Vec::new(),
            next: Vec::new(),
            // Allocated by the first `clear`, which every cut calls before
            // it pushes: a list made only to be swapped out costs nothing.
            heads: Box::default(),
            base: 0,
            top: 0,
            occupied: [0; BUCKETS / 64],
            touched: (BUCKETS, 0),
            special: Vec::new(),
            best: None,
            waiting: 0,
            estimate: DVec3::ZERO,
            error: DVec3::ZERO,
            fresh: true,
            rounding: DVec3::ZERO,
            over_contribution: 0,
            unbounded: 0,
        }
    }
}

/// `(class, key)` ordering of two waiting entries.
#[inline]
fn above(a: &Entry, b: &Entry) -> bool {
    match a.class.cmp(&b.class) {
        Ordering::Equal => a.key.total_cmp(&b.key) == Ordering::Greater,
        o => o == Ordering::Greater,
    }
}

impl ErrorList {
    /// Empties the list (the first time, allocates its buckets).
    pub(crate) fn clear(&mut self) {
        if self.heads.is_empty() {
            self.heads = vec![NONE; BUCKETS].into_boxed_slice();
        }
        let (lo, hi) = self.touched;
        if lo <= hi {
            self.heads[lo..=hi].fill(NONE);
            self.occupied[lo / 64..=hi / 64].fill(0);
        }
        self.touched = (BUCKETS, 0);
        self.top = 0;
        self.entries.clear();
        self.keys.clear();
        self.next.clear();
        self.special.clear();
        self.best = None;
        self.waiting = 0;
        self.estimate = DVec3::ZERO;
        self.error = DVec3::ZERO;
        self.fresh = true;
        self.rounding = DVec3::ZERO;
        self.over_contribution = 0;
        self.unbounded = 0;
    }

    /// The bucket of a non-negative key (NaN, which no entry carries, would
    /// land in the top bucket).
    #[inline]
    fn bucket(&self, key: f64) -> usize {
        let bits = (key.max(0.0).to_bits() >> BUCKET_SHIFT) as i64;
        (bits - self.base).clamp(0, BUCKETS as i64 - 1) as usize
    }

    /// Adds an entry; returns its slot, the number of entries pushed
    /// before it since the last [`clear`](Self::clear).
    #[inline(always)]
    pub(crate) fn push(&mut self, e: Entry) -> u32 {
        match e.class {
            Class::Unbounded => self.unbounded += 1,
            Class::OverContribution => self.over_contribution += 1,
            Class::Error => {}
        }
        let (estimate, error) = e.counted();
        self.estimate += estimate;
        self.error += error;
        self.fresh = false;
        let slot = self.entries.len() as u32;
        self.entries.push(e);
        self.keys.push(e.key.max(0.0));
        self.waiting += 1;
        if e.class == Class::Error {
            if self.touched.0 > self.touched.1 {
                // The first ordinary key since the clear places the window.
                let bits = (e.key.max(0.0).to_bits() >> BUCKET_SHIFT) as i64;
                self.base = bits + HEADROOM as i64 - BUCKETS as i64 + 1;
            }
            let b = self.bucket(e.key);
            self.next.push(self.heads[b]);
            self.heads[b] = slot;
            self.occupied[b / 64] |= 1 << (b % 64);
            self.top = self.top.max(b);
            self.touched = (self.touched.0.min(b), self.touched.1.max(b));
            // A new entry at the head of the best one's bucket changes the
            // slot before it; one in a higher bucket may be the new best.
            if let Some((_, _, best_bucket)) = self.best
                && best_bucket != NONE as usize
                && b >= best_bucket
            {
                self.best = None;
            }
        } else {
            self.next.push(NONE);
            self.special.push(slot);
            self.best = None;
        }
        slot
    }

    /// Finds (and remembers) the largest waiting entry.
    #[inline(always)]
    fn find_best(&mut self) -> Option<(u32, u32, usize)> {
        if self.best.is_some() {
            return self.best;
        }
        if let Some((i, &slot)) = self.special.iter().enumerate().reduce(|a, b| {
            if above(&self.entries[*b.1 as usize], &self.entries[*a.1 as usize]) {
                b
            } else {
                a
            }
        }) {
            self.best = Some((slot, i as u32, NONE as usize));
            return self.best;
        }
        if self.waiting == 0 {
            return None;
        }
        if self.heads[self.top] == NONE {
            // The highest occupied bucket below: some entry is waiting, so
            // some bit is set.
            let mut word = self.top / 64;
            let mut bits = self.occupied[word] & (u64::MAX >> (63 - self.top % 64));
            while bits == 0 && word > 0 {
                word -= 1;
                bits = self.occupied[word];
            }
            if bits == 0 {
                debug_assert!(false, "a waiting entry but no occupied bucket");
                return None;
            }
            self.top = word * 64 + 63 - bits.leading_zeros() as usize;
        }
        let mut slot = self.heads[self.top];
        let (mut best, mut best_prev, mut best_key) = (slot, NONE, self.keys[slot as usize]);
        loop {
            let next = self.next[slot as usize];
            if next == NONE {
                break;
            }
            let prev = slot;
            slot = next;
            let key = self.keys[slot as usize];
            if key >= best_key {
                (best, best_prev, best_key) = (slot, prev, key);
            }
        }
        self.best = Some((best, best_prev, self.top));
        self.best
    }

    /// The entry that would be refined next.
    #[inline(always)]
    pub(crate) fn peek(&mut self) -> Option<&Entry> {
        let (slot, _, _) = self.find_best()?;
        Some(&self.entries[slot as usize])
    }

    /// Removes the largest waiting entry; returns it with its slot.
    #[inline(always)]
    pub(crate) fn pop_slot(&mut self) -> Option<(Entry, u32)> {
        let (slot, prev, bucket) = self.find_best()?;
        self.best = None;
        if bucket == NONE as usize {
            // `prev` holds the index in the special list.
            self.special.swap_remove(prev as usize);
        } else {
            let next = self.next[slot as usize];
            if prev == NONE {
                self.heads[bucket] = next;
                if next == NONE {
                    self.occupied[bucket / 64] &= !(1 << (bucket % 64));
                }
            } else {
                self.next[prev as usize] = next;
            }
        }
        self.waiting -= 1;
        self.keys[slot as usize] = POPPED;
        let e = self.entries[slot as usize];
        match e.class {
            Class::Unbounded => self.unbounded -= 1,
            Class::OverContribution => self.over_contribution -= 1,
            Class::Error => {}
        }
        let (estimate, error) = e.counted();
        self.estimate -= estimate;
        self.error -= error;
        self.fresh = false;
        Some((e, slot))
    }

    /// The largest error waiting (0 when empty).
    #[inline]
    pub(crate) fn largest(&mut self) -> f64 {
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

    /// Recomputes the sums from scratch, replaces the running ones with them
    /// and returns them, the error sum raised by the rounding of both sums
    /// (at once if nothing was pushed or popped since the last time).
    ///
    /// The waiting entries are summed in four interleaved plain sums, added
    /// pairwise: independent additions rather than one compensated chain,
    /// whose steps each wait on the one before: a share of a shading point
    /// worth saving (`docs/tuning.md`; `cargo run --release -p
    /// manylights-report -- scaling` measures it). A sum
    /// of `n` terms in any order is within `(n - 1) eps` of the exact sum
    /// of their magnitudes (Higham, *Accuracy and Stability of Numerical
    /// Algorithms*, 2002, section 4.2; `eps = f64::EPSILON / 2`), so
    /// `(n + 1) f64::EPSILON` of the estimates' and errors' magnitudes,
    /// added to the error sum, covers both sums' rounding.
    pub(crate) fn resum(&mut self) -> (DVec3, DVec3) {
        if !self.fresh {
            let mut estimate = [DVec3::ZERO; 4];
            let mut magnitude = [DVec3::ZERO; 4];
            let mut error = [DVec3::ZERO; 4];
            let mut n = 0;
            for (e, _) in self.waiting() {
                let (e, r) = e.counted();
                estimate[n % 4] += e;
                magnitude[n % 4] += e.abs();
                error[n % 4] += r;
                n += 1;
            }
            let total = |v: [DVec3; 4]| (v[0] + v[1]) + (v[2] + v[3]);
            self.estimate = total(estimate);
            self.error = total(error);
            self.rounding = (total(magnitude) + self.error) * ((n as f64 + 1.0) * f64::EPSILON);
            self.fresh = true;
        }
        (self.estimate, self.error + self.rounding)
    }

    /// Number of entries pushed since the last [`clear`](Self::clear)
    /// (the next entry's slot).
    #[inline(always)]
    pub(crate) fn slots(&self) -> usize {
        self.entries.len()
    }

    /// The entry pushed into slot `slot`.
    #[inline(always)]
    pub(crate) fn entry(&self, slot: u32) -> &Entry {
        &self.entries[slot as usize]
    }

    /// Number of waiting entries.
    pub(crate) fn len(&self) -> usize {
        self.waiting
    }

    /// The waiting entries with their slots, in the order they were pushed.
    pub(crate) fn waiting(&self) -> impl Iterator<Item = (&Entry, u32)> + '_ {
        self.entries
            .iter()
            .zip(&self.keys)
            .enumerate()
            .filter(|(_, (_, key))| **key >= 0.0)
            .map(|(s, (e, _))| (e, s as u32))
    }
}
