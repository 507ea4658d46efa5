//! Refitting: new positions and intensities, the same grouping.

use super::build::{check_lights, fill_statistics};
use super::layout::LightTree;
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
    /// statistics: linear, plus the radii's `O(n * depth)` distance checks.
    ///
    /// # Errors
    /// The same [`BuildError`]s as building, checked before anything changes;
    /// [`BuildError::LightCountMismatch`] when the length differs.
    pub fn refit(&mut self, lights: &[PointLight]) -> Result<(), BuildError> {
        if lights.len() != self.lights.len() {
            return Err(BuildError::LightCountMismatch {
                expected: self.lights.len(),
                got: lights.len(),
            });
        }
        check_lights(lights)?;
        for (slot, &k) in self.lights.iter_mut().zip(&self.order) {
            *slot = lights[k as usize];
        }
        fill_statistics(self);
        super::plane::record_planes(self);
        Ok(())
    }
}
