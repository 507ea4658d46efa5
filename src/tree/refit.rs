//! Refitting: new positions and intensities, the same grouping.

use super::check::check_lights;
use super::layout::LightTree;
use super::pool::Pool;
use super::statistics_pass::fill_nodes;
use crate::{BuildError, PointLight};

impl LightTree {
    /// Moves and re-weights the lights without rebuilding the hierarchy (for
    /// animated lights): every node's statistics are recomputed from the new
    /// values, the grouping is kept.
    ///
    /// `lights` is in the caller's original order and must have the length
    /// the tree was built with. Bounds stay certified after a refit (they are
    /// recomputed, not extrapolated); only their tightness depends on the
    /// lights having stayed near their groups. Time as for a build's
    /// statistics: linear, but for the radii's search for each node's
    /// farthest member.
    ///
    /// # Errors
    /// The same [`BuildError`]s as building, checked before anything changes;
    /// [`BuildError::LightCountMismatch`] when the length differs.
    pub fn refit(&mut self, lights: &[PointLight]) -> Result<(), BuildError> {
        self.refit_on(lights, Pool::ONE)
    }

    /// [`refit`](Self::refit) spread over rayon's thread pool (with the
    /// `rayon` feature): the same nodes, bit for bit, and the same errors.
    /// Trees of fewer than 8,192 lights, or a pool of one thread, refit on
    /// the calling thread.
    ///
    /// # Errors
    /// As [`refit`](Self::refit).
    #[cfg(feature = "rayon")]
    pub fn refit_parallel(&mut self, lights: &[PointLight]) -> Result<(), BuildError> {
        self.refit_on(lights, Pool::for_lights(lights.len()))
    }

    fn refit_on(&mut self, lights: &[PointLight], pool: Pool) -> Result<(), BuildError> {
        if lights.len() != self.lights.len() {
            return Err(BuildError::LightCountMismatch {
                expected: self.lights.len(),
                got: lights.len(),
            });
        }
        check_lights(lights, pool.cheap(lights.len()))?;
        let order = &self.order;
        pool.cheap(order.len())
            .fill(&mut self.lights, |i| lights[order[i] as usize]);
        fill_nodes(self, pool);
        Ok(())
    }
}
