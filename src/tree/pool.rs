//! Where the build's passes run: on the calling thread, or (with the
//! `rayon` feature) spread over rayon's thread pool. Each helper gives the
//! same result either way: the parallel passes split work whose parts are
//! independent, and put the parts together in the sequential order.

/// Whether the passes of one build run on rayon's pool.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Pool {
    #[cfg(feature = "rayon")]
    parallel: bool,
}

/// Builds of fewer lights stay on the calling thread: below this the
/// pool's start-up costs more than it saves (lowered in the unit tests, as
/// [`CHEAP_PARALLEL_MIN`]). The build table of `cargo run --release -p
/// manylights-report -- bounds` times builds on one thread and on the
/// pool; `docs/tuning.md` records the comparison that set it.
#[cfg(feature = "rayon")]
const PARALLEL_MIN_LIGHTS: usize = if cfg!(test) { 1 << 10 } else { 1 << 13 };

/// Passes of cheap steps run on the pool from this many items on (see
/// [`Pool::cheap`]); the unit tests lower it, so that their trees of tens
/// of thousands of lights take every parallel path.
#[cfg(feature = "rayon")]
const CHEAP_PARALLEL_MIN: usize = if cfg!(test) { 1 << 12 } else { 1 << 19 };

impl Pool {
    /// Every pass on the calling thread.
    pub(crate) const ONE: Self = Self {
        #[cfg(feature = "rayon")]
        parallel: false,
    };

    /// Rayon's pool for a build of `lights` lights, when it has more than
    /// one thread and the build is large enough to gain from it.
    #[cfg(feature = "rayon")]
    pub(crate) fn for_lights(lights: usize) -> Self {
        Self {
            parallel: lights >= PARALLEL_MIN_LIGHTS && rayon::current_num_threads() > 1,
        }
    }

    /// This pool for a pass over `items` items that are cheap (a few
    /// nanoseconds to a few dozen each: every pass of the build but the
    /// moments): on the calling thread below [`CHEAP_PARALLEL_MIN`] items,
    /// where waking the pool's threads (up to milliseconds on a busy
    /// machine) costs more than the pass gains.
    pub(crate) fn cheap(self, items: usize) -> Self {
        #[cfg(feature = "rayon")]
        if items < CHEAP_PARALLEL_MIN {
            return Self::ONE;
        }
        let _ = items;
        self
    }

    /// Whether the passes run on rayon's pool.
    #[inline]
    pub(crate) fn parallel(self) -> bool {
        #[cfg(feature = "rayon")]
        {
            self.parallel
        }
        #[cfg(not(feature = "rayon"))]
        {
            false
        }
    }

    /// Independent parts of a pass at most, per thread of the pool: enough
    /// to even out parts of unequal cost.
    pub(crate) fn parts(self) -> usize {
        #[cfg(feature = "rayon")]
        if self.parallel {
            return 8 * rayon::current_num_threads();
        }
        1
    }

    /// [`map`](Self::map) into `out`, whose previous contents are dropped
    /// and whose memory is reused.
    pub(crate) fn map_into<T: Sync, U: Send>(
        self,
        items: &[T],
        out: &mut Vec<U>,
        f: impl Fn(&T) -> U + Sync + Send,
    ) {
        #[cfg(feature = "rayon")]
        if self.parallel {
            use rayon::prelude::*;
            items.par_iter().map(f).collect_into_vec(out);
            return;
        }
        out.clear();
        out.extend(items.iter().map(f));
    }

    /// `items.map(f)`, in order.
    pub(crate) fn map<T: Sync, U: Send>(
        self,
        items: &[T],
        f: impl Fn(&T) -> U + Sync + Send,
    ) -> Vec<U> {
        #[cfg(feature = "rayon")]
        if self.parallel {
            use rayon::prelude::*;
            return items.par_iter().map(f).collect();
        }
        items.iter().map(f).collect()
    }

    /// `out[i] = f(i)` for every `i`.
    pub(crate) fn fill<T: Send>(self, out: &mut [T], f: impl Fn(usize) -> T + Sync + Send) {
        #[cfg(feature = "rayon")]
        if self.parallel {
            use rayon::prelude::*;
            out.par_iter_mut().enumerate().for_each(|(i, x)| *x = f(i));
            return;
        }
        for (i, x) in out.iter_mut().enumerate() {
            *x = f(i);
        }
    }

    /// `items.map(f)`, in order, each item moved into `f` together with
    /// the scratch of the thread that takes it (made by `init`, once per
    /// thread), the calling thread taking items too: it asks the pool for
    /// one helper fewer than its threads and takes items from the same
    /// counter as they do. Where a helper starts late (on a busy machine the
    /// pool's threads can take milliseconds to run), the calling thread
    /// does its share, so the call is never much slower than on one
    /// thread.
    pub(crate) fn map_owned<T: Send, S, U: Send + Sync>(
        self,
        items: Vec<T>,
        init: impl Fn() -> S + Sync + Send,
        f: impl Fn(&mut S, T) -> U + Sync + Send,
    ) -> Vec<U> {
        #[cfg(feature = "rayon")]
        if self.parallel {
            use std::sync::atomic::{AtomicUsize, Ordering};
            use std::sync::{Mutex, OnceLock};
            let slots: Vec<Mutex<Option<T>>> =
                items.into_iter().map(|t| Mutex::new(Some(t))).collect();
            let results: Vec<OnceLock<U>> = slots.iter().map(|_| OnceLock::new()).collect();
            let next = AtomicUsize::new(0);
            let work = || {
                let mut scratch = init();
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(slot) = slots.get(k) else {
                        break;
                    };
                    // Each index is taken once: its item is there and its
                    // result's slot empty. A helper that panicked holding
                    // no lock poisons none.
                    let item = slot
                        .lock()
                        .ok()
                        .and_then(|mut s| s.take())
                        .expect("every item is taken once");
                    let _ = results[k].set(f(&mut scratch, item));
                }
            };
            rayon::in_place_scope(|scope| {
                for _ in 1..rayon::current_num_threads() {
                    scope.spawn(|_| work());
                }
                work();
            });
            // A panic in a helper is raised by the scope, before this.
            return results
                .into_iter()
                .map(|r| r.into_inner().expect("every item was taken"))
                .collect();
        }
        let mut scratch = init();
        items.into_iter().map(|t| f(&mut scratch, t)).collect()
    }

    /// `f` on every part, each with its own scratch from `init`.
    pub(crate) fn for_each_with<T: Send, S>(
        self,
        parts: Vec<T>,
        init: impl Fn() -> S + Sync + Send,
        f: impl Fn(&mut S, T) + Sync + Send,
    ) {
        #[cfg(feature = "rayon")]
        if self.parallel {
            use rayon::prelude::*;
            parts.into_par_iter().for_each_init(init, f);
            return;
        }
        let mut scratch = init();
        for part in parts {
            f(&mut scratch, part);
        }
    }
}
