//! What steers a group's cut: a few points spread over the group whose
//! virtual-light estimates stand for the group's darkest point against a
//! relative target, and how far the cut's entries lie from the points.

use glam::DVec3;

/// Points of a group whose estimates steer a shared cut's relative target.
pub(crate) const SAMPLES: usize = 4;

/// Points of a group whose estimates steer the shared cut: at most
/// [`SAMPLES`] spread over the group.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Samples {
    /// Points and unit normals, by coordinate (so that the samples' values
    /// are computed side by side).
    points: [[f64; SAMPLES]; 3],
    normals: [[f64; SAMPLES]; 3],
}

impl Samples {
    /// The samples `pick(0..SAMPLES)` (points and unit normals).
    pub(crate) fn new(pick: impl Fn(usize) -> (DVec3, DVec3)) -> Self {
        let picked: [(DVec3, DVec3); SAMPLES] = core::array::from_fn(pick);
        Self {
            points: core::array::from_fn(|axis| core::array::from_fn(|k| picked[k].0[axis])),
            normals: core::array::from_fn(|axis| core::array::from_fn(|k| picked[k].1[axis])),
        }
    }

    /// A virtual light's value `I kd max(0, n.w) / d^2` at each sample
    /// (`intensity` already times `kd`): an estimate good enough to steer.
    #[inline(always)]
    pub(crate) fn values(&self, position: DVec3, intensity: DVec3) -> [DVec3; SAMPLES] {
        let mut g = [0.0f64; SAMPLES];
        for (k, g) in g.iter_mut().enumerate() {
            let u = [
                position.x - self.points[0][k],
                position.y - self.points[1][k],
                position.z - self.points[2][k],
            ];
            let d2 = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
            let height =
                self.normals[0][k] * u[0] + self.normals[1][k] * u[1] + self.normals[2][k] * u[2];
            // A light on a sample (d = 0) counts 0.
            let value = height.max(0.0) / (d2 * d2.sqrt());
            *g = if d2 > 0.0 { value } else { 0.0 };
        }
        g.map(|g| intensity * g)
    }
}

/// The sum of the darkest sample (smallest largest channel).
#[inline(always)]
pub(crate) fn darkest(sums: &[DVec3; SAMPLES]) -> DVec3 {
    let mut least = sums[0];
    for s in &sums[1..] {
        if s.max_element() < least.max_element() {
            least = *s;
        }
    }
    least
}

/// How far the entries a group's points sum lie from them: what the
/// points' packed sums need to pick their precision.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Spread {
    /// The smallest distance from any point to an entry's centroid less
    /// its radius, over the entries.
    pub(crate) nearest: f64,
    /// The largest distance from the group's centre to an entry's
    /// centroid.
    pub(crate) farthest: f64,
}

impl Default for Spread {
    fn default() -> Self {
        Self {
            nearest: f64::INFINITY,
            farthest: 0.0,
        }
    }
}

impl Spread {
    #[inline(always)]
    pub(crate) fn note(&mut self, nearest: f64, distance: f64) {
        self.nearest = self.nearest.min(nearest);
        self.farthest = self.farthest.max(distance);
    }
}
