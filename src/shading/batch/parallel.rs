//! The batch call over rayon's thread pool: the same groups and chunks as
//! on one thread, each chunk shaded by some thread with a session of its
//! own, so the results are the same bits.

use core::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use super::{Batch, BatchStats, Outcome, halo};
use crate::shader::Shader;
use crate::shading::grouping::points_box;
use crate::shading::{Accepts, Query, Shading};
use crate::visibility::Visibility;
use crate::{ShadeError, ShadeResult, Threshold};

/// What a worker shaded: each result with its query's index, and what its
/// chunks gave besides.
type Shaded = Result<(Vec<(u32, ShadeResult)>, Outcome), ShadeError>;

impl<S: Shader> Shading<'_, S> {
    /// [`shade_batch`](Self::shade_batch) spread over rayon's thread pool:
    /// the same groups are formed and shaded in chunks, each chunk on some
    /// thread with a session of its own (the shader and the visibility host
    /// cloned), so the results are the same bits as `shade_batch`'s.
    /// Without shared cuts, chunks of the batch are shaded point by point
    /// on the threads.
    ///
    /// Allocation: what `shade_batch` allocates, a session per thread, and
    /// each thread's results until they are put in place.
    ///
    /// # Errors
    /// As [`shade_batch`](Self::shade_batch).
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
        let batch = Batch::new(queries, &threshold);
        let queue = widest_first(&batch);
        let next = AtomicUsize::new(0);
        let shaded: Mutex<Vec<Shaded>> = Mutex::new(Vec::new());
        // Each worker takes the next chunk in the queue as it finishes its
        // last, with a session of its own reused from chunk to chunk (a
        // chunk's results depend neither on what the session shaded before
        // nor on the order).
        let work = || {
            let mut shading = session();
            let mut visibility = visibility.clone();
            let (mut written, mut out) = (Vec::new(), Outcome::default());
            let done = loop {
                let Some(&k) = queue.get(next.fetch_add(1, Ordering::Relaxed)) else {
                    break Ok(());
                };
                let mut write = |i: usize, r| written.push((i as u32, r));
                let chunk = shading.shade_chunk(
                    &batch,
                    k,
                    threshold,
                    &mut visibility,
                    &mut write,
                    &mut out,
                );
                if let Err(e) = chunk {
                    break Err(e);
                }
            };
            if let Ok(mut all) = shaded.lock() {
                all.push(done.map(|()| (written, out)));
            }
        };
        rayon::scope(|scope| {
            for _ in 1..rayon::current_num_threads().max(1) {
                scope.spawn(|_| work());
            }
            work();
        });
        // The results are put in place here, after the workers, rather than
        // written by each worker into `results` through a shared pointer: no
        // unsafe block here, for a small cost (`docs/tuning.md`).
        let mut out = Outcome::default();
        for worker in shaded.into_inner().unwrap_or_default() {
            let (written, mut outcome) = worker?;
            for (i, r) in written {
                results[i as usize] = r;
            }
            out.stats += outcome.stats;
            out.halo.append(&mut outcome.halo);
        }
        halo::blend_halos(results, out.halo, &threshold);
        Ok(out.stats)
    }
}

/// The chunks of `batch` in the order the workers take them: those whose
/// points spread widest first. Those are the costly ones (a group that
/// spans blocks near the horizon is shaded point by point), and left for
/// the end one would keep the other threads waiting. `cargo run --release
/// -p manylights-report -- batch`, unpinned, prints the call's speed-up
/// over one thread; `docs/tuning.md` records it against Morton order.
fn widest_first<M>(batch: &Batch<'_, M>) -> Vec<usize> {
    let mut queue: Vec<(f64, usize)> = (0..batch.chunks())
        .map(|k| {
            let (_, runs) = batch.chunk(k);
            let places = runs[0].start..runs[runs.len() - 1].end;
            let (lo, hi) = points_box(batch.queries, &batch.order[places]);
            (-(hi - lo).max_element(), k)
        })
        .collect();
    queue.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    queue.into_iter().map(|(_, k)| k).collect()
}
