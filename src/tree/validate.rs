//! The tree's public invariant checker.

use glam::DVec3;

use super::harmonics::{HARMONIC_COUNT, harmonic_norms, solid_harmonics};
use super::layout::LightTree;
use super::node::MAX_CHILDREN;
use crate::ValidationError;
use crate::numeric::SUM_TOLERANCE;

impl LightTree {
    /// Checks the tree's invariants and returns the first one broken.
    ///
    /// * Every node's light range is the concatenation of its children's, of
    ///   which it has at most 8, and the root's is every light: each light
    ///   lies in exactly one leaf.
    /// * The index map back to the caller's order is a permutation.
    /// * Every node's intensity is the sum of its children's (leaves: of
    ///   their lights), to `f64` rounding.
    /// * Every member light lies inside its node's stored ball (`|x - c| <= R`)
    ///   and box; the stored diagonal second moments of each channel are at
    ///   least the members' (they are rounded upward), and so are the
    ///   harmonic norms (recomputed from the members).
    /// * Every stored value is finite.
    /// * The copy of each node's statistics laid out beside its siblings'
    ///   (read when a node's children are bounded together) holds exactly
    ///   the node's values, its box relative to the centroid rounded
    ///   outward ([`ValidationError::MomentMismatch`] otherwise).
    ///
    /// Time `O(n * depth)`. Property tests call it on every tree they build.
    ///
    /// # Errors
    /// The first [`ValidationError`] found.
    pub fn validate(&self) -> Result<(), ValidationError> {
        let n = self.lights.len();
        if self.order.len() != n {
            return Err(ValidationError::BadCover);
        }
        let mut seen = vec![false; n];
        for &k in &self.order {
            let k = k as usize;
            if k >= n || seen[k] {
                return Err(ValidationError::BadCover);
            }
            seen[k] = true;
        }
        if n == 0 {
            return if self.nodes.is_empty() {
                Ok(())
            } else {
                Err(ValidationError::BadCover)
            };
        }
        if self.nodes.is_empty() || self.nodes[0].lights() != (0..n) {
            return Err(ValidationError::BadCover);
        }
        let mut leaf_cover = 0usize;
        for (i, node) in self.nodes.iter().enumerate() {
            let finite = node.intensity.is_finite()
                && node.weight.is_finite()
                && node.centroid.is_finite()
                && node.radius.is_finite()
                && node.channel_offsets.iter().all(|o| o.is_finite())
                && node
                    .channel_covariances
                    .iter()
                    .flatten()
                    .all(|v| v.is_finite())
                && node.harmonic_norms.iter().all(|q| q.is_finite());
            if !finite {
                return Err(ValidationError::NonFinite { node: i });
            }
            let range = node.lights();
            if range.end > n {
                return Err(ValidationError::BadChildRange { node: i });
            }
            let members = &self.lights[range.clone()];
            let sum = if node.is_leaf() {
                leaf_cover += range.len();
                members
                    .iter()
                    .map(|l| l.intensity.as_dvec3())
                    .sum::<DVec3>()
            } else {
                let children = node.children();
                if children.start <= i
                    || children.end > self.nodes.len()
                    || children.len() > MAX_CHILDREN
                {
                    return Err(ValidationError::BadChildRange { node: i });
                }
                let mut next = range.start;
                let mut sum = DVec3::ZERO;
                for child in &self.nodes[children] {
                    if child.lights().start != next || child.light_count == 0 {
                        return Err(ValidationError::BadChildRange { node: i });
                    }
                    next = child.lights().end;
                    sum += child.intensity;
                }
                if next != range.end {
                    return Err(ValidationError::BadChildRange { node: i });
                }
                sum
            };
            let tol = SUM_TOLERANCE * node.intensity.max_element().max(sum.max_element());
            if (sum - node.intensity).abs().max_element() > tol {
                return Err(ValidationError::IntensityMismatch { node: i });
            }
            let c = node.centroid.as_dvec3();
            let r = f64::from(node.radius);
            let aabb = node.aabb;
            let inv_radius = if r > 0.0 { 1.0 / r } else { 0.0 };
            let mut second = [DVec3::ZERO; 3];
            let mut moments = [[0.0f64; HARMONIC_COUNT]; 3];
            for (k, l) in members.iter().enumerate() {
                let d = l.position.as_dvec3() - c;
                if d.length() > r || !aabb.contains(l.position) {
                    return Err(ValidationError::LightOutsideBounds {
                        node: i,
                        light: range.start + k,
                    });
                }
                let intensity = l.intensity.as_dvec3();
                let harmonics = solid_harmonics(d * inv_radius);
                for ch in 0..3 {
                    second[ch] += intensity[ch] * d * d;
                    for (acc, h) in moments[ch].iter_mut().zip(harmonics) {
                        *acc += intensity[ch] * h;
                    }
                }
            }
            let recomputed = harmonic_norms(&moments, node.intensity, members.len());
            for ch in 0..3 {
                let stored = node.channel_covariances[ch];
                let weight = node.intensity[ch] * (1.0 + SUM_TOLERANCE);
                for axis in 0..3 {
                    if second[ch][axis] > f64::from(stored[axis]) * weight {
                        return Err(ValidationError::MomentMismatch { node: i });
                    }
                }
                for (stored, fresh) in node.harmonic_norms.iter().zip(&recomputed) {
                    // Both are rounded upward from sums of the same terms
                    // (in another order: the build reorders lights later).
                    if f64::from(fresh[ch]) > f64::from(stored[ch]) * (1.0 + SUM_TOLERANCE) {
                        return Err(ValidationError::MomentMismatch { node: i });
                    }
                }
            }
        }
        if leaf_cover != n {
            return Err(ValidationError::BadCover);
        }
        if let Some(node) = self.groups.first_mismatch(&self.nodes, &self.lights) {
            return Err(ValidationError::MomentMismatch { node });
        }
        Ok(())
    }
}
