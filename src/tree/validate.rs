//! The tree's public invariant checker.

use glam::DVec3;

use super::harmonics::{HARMONIC_COUNT, harmonic_norms, solid_harmonics};
use super::layout::LightTree;
use super::node::{MAX_CHILDREN, Node};
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
        self.check_order()?;
        let n = self.lights.len();
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
            check_finite(i, node)?;
            let sum = self.check_ranges(i, node)?;
            if node.is_leaf() {
                leaf_cover += node.lights().len();
            }
            check_intensity(i, node, sum)?;
            let members = self.member_moments(i, node)?;
            check_moments(i, node, &members)?;
        }
        if leaf_cover != n {
            return Err(ValidationError::BadCover);
        }
        if let Some(node) = self.groups.first_mismatch(&self.nodes, &self.lights) {
            return Err(ValidationError::MomentMismatch { node });
        }
        Ok(())
    }

    /// That the index map back to the caller's order is a permutation of
    /// the lights' indices.
    fn check_order(&self) -> Result<(), ValidationError> {
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
        Ok(())
    }

    /// That node `i`'s light range lies within the lights and, if it has
    /// children, that they follow it, are at most [`MAX_CHILDREN`], and
    /// their ranges, none empty, are its own in order. Returns the sum of
    /// the intensities of its lights (a leaf) or children.
    fn check_ranges(&self, i: usize, node: &Node) -> Result<DVec3, ValidationError> {
        let range = node.lights();
        if range.end > self.lights.len() {
            return Err(ValidationError::BadChildRange { node: i });
        }
        if node.is_leaf() {
            return Ok(self.lights[range]
                .iter()
                .map(|l| l.intensity.as_dvec3())
                .sum::<DVec3>());
        }
        let children = node.children();
        if children.start <= i || children.end > self.nodes.len() || children.len() > MAX_CHILDREN {
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
        Ok(sum)
    }

    /// The moments of node `i`'s lights about its stored centroid, checking
    /// on the way that each lies in its stored ball and box.
    fn member_moments(&self, i: usize, node: &Node) -> Result<MemberMoments, ValidationError> {
        let range = node.lights();
        let c = node.centroid.as_dvec3();
        let r = f64::from(node.radius);
        let aabb = node.aabb;
        let inv_radius = if r > 0.0 { 1.0 / r } else { 0.0 };
        let mut out = MemberMoments {
            second: [DVec3::ZERO; 3],
            harmonics: [[0.0f64; HARMONIC_COUNT]; 3],
            count: range.len(),
        };
        for (k, l) in self.lights[range.clone()].iter().enumerate() {
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
                out.second[ch] += intensity[ch] * d * d;
                for (acc, h) in out.harmonics[ch].iter_mut().zip(harmonics) {
                    *acc += intensity[ch] * h;
                }
            }
        }
        Ok(out)
    }
}

/// The moments of a node's lights about its stored centroid, as
/// [`validate`](LightTree::validate) recomputes them.
struct MemberMoments {
    /// Per channel, the diagonal second moments `sum_i I_ik (x_i - c)^2`
    /// (per axis).
    second: [DVec3; 3],
    /// Per channel, the sums of `I_ik` times [`solid_harmonics`] of
    /// `(x_i - c) / R`.
    harmonics: [[f64; HARMONIC_COUNT]; 3],
    /// The number of lights summed.
    count: usize,
}

/// That every value node `i` stores is finite.
fn check_finite(i: usize, node: &Node) -> Result<(), ValidationError> {
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
    if finite {
        Ok(())
    } else {
        Err(ValidationError::NonFinite { node: i })
    }
}

/// That node `i`'s intensity is `sum`, its lights' or children's, to
/// [`SUM_TOLERANCE`].
fn check_intensity(i: usize, node: &Node, sum: DVec3) -> Result<(), ValidationError> {
    let tol = SUM_TOLERANCE * node.intensity.max_element().max(sum.max_element());
    if (sum - node.intensity).abs().max_element() > tol {
        return Err(ValidationError::IntensityMismatch { node: i });
    }
    Ok(())
}

/// That node `i`'s stored diagonal second moments and harmonic norms are at
/// least those of its lights, `members`, to [`SUM_TOLERANCE`].
fn check_moments(i: usize, node: &Node, members: &MemberMoments) -> Result<(), ValidationError> {
    let recomputed = harmonic_norms(&members.harmonics, node.intensity, members.count);
    for ch in 0..3 {
        let stored = node.channel_covariances[ch];
        let weight = node.intensity[ch] * (1.0 + SUM_TOLERANCE);
        for (axis, &diagonal) in stored[..3].iter().enumerate() {
            if members.second[ch][axis] > f64::from(diagonal) * weight {
                return Err(ValidationError::MomentMismatch { node: i });
            }
        }
        for (stored, fresh) in node.harmonic_norms.iter().zip(&recomputed) {
            // Both are rounded upward from sums of the same terms (in
            // another order: the build reorders lights later).
            if f64::from(fresh[ch]) > f64::from(stored[ch]) * (1.0 + SUM_TOLERANCE) {
                return Err(ValidationError::MomentMismatch { node: i });
            }
        }
    }
    Ok(())
}
