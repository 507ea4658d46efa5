//! A shared cut's estimates as structure of arrays, summed at one point in
//! [`LANES`] independent lanes that the compiler vectorizes; on `x86_64`
//! the widest vectors the processor has are picked at run time.

use glam::{DVec3, Vec3};

use crate::tree::Node;

/// Entries summed side by side.
pub(crate) const LANES: usize = 8;

/// Lanes of `f64`. Values the tree stores in `f32` (positions, moments)
/// are widened once, when the cut is packed: the conversion is exact, and
/// widening them at every point cost more than reading twice the bytes
/// (about 9% of a batch call at 10^6 lights, the same bits).
type Lanes = [f64; LANES];

/// [`LANES`] single lights: position and intensity times `kd`.
#[derive(Clone, Copy, Debug, Default)]
struct LightBlock {
    position: [Lanes; 3],
    intensity: [Lanes; 3],
}

/// [`LANES`] nodes: centroid, intensity times `kd`, and moments.
#[derive(Clone, Copy, Debug, Default)]
struct NodeBlock {
    at: LightBlock,
    /// `o_k` per channel, per axis.
    offsets: [[Lanes; 3]; 3],
    /// `S_k` per channel, entries `[xx, yy, zz, xy, xz, yz]`.
    covariances: [[Lanes; 6]; 3],
}

/// The entries of a shared cut whose estimate is the degree-2 series
/// (the Lambert bound's `degree_two_lanes`): nodes, and single lights
/// above every tangent plane (whose series is their exact term `c0`, the
/// moments being zero).
#[derive(Debug, Default)]
pub(crate) struct Packed {
    nodes: Vec<NodeBlock>,
    node_count: usize,
    lights: Vec<LightBlock>,
    light_count: usize,
}

impl Packed {
    pub(crate) fn clear(&mut self) {
        self.nodes.clear();
        self.lights.clear();
        self.node_count = 0;
        self.light_count = 0;
    }

    /// Number of entries.
    pub(crate) fn len(&self) -> usize {
        self.node_count + self.light_count
    }

    /// Adds a node, its intensity times `kd`.
    pub(crate) fn push_node(&mut self, node: &Node, kd: DVec3) {
        let lane = self.node_count % LANES;
        if lane == 0 {
            self.nodes.push(NodeBlock {
                at: LightBlock::padded(node.centroid),
                ..NodeBlock::default()
            });
        }
        let block = self.nodes.last_mut().expect("a block was just pushed");
        block.at.set(lane, node.centroid, node.intensity * kd);
        for k in 0..3 {
            for (axis, value) in node.channel_offsets[k].to_array().into_iter().enumerate() {
                block.offsets[k][axis][lane] = f64::from(value);
            }
            for (entry, value) in node.channel_covariances[k].iter().enumerate() {
                block.covariances[k][entry][lane] = f64::from(*value);
            }
        }
        self.node_count += 1;
    }

    /// Adds a single light of `intensity` (times `kd`) at `position`.
    pub(crate) fn push_light(&mut self, position: Vec3, intensity: DVec3) {
        let lane = self.light_count % LANES;
        if lane == 0 {
            self.lights.push(LightBlock::padded(position));
        }
        let block = self.lights.last_mut().expect("a block was just pushed");
        block.set(lane, position, intensity);
        self.light_count += 1;
    }

    /// The sum of every entry's degree-2 estimate at `point` with unit
    /// normal `normal`: the operations of
    /// the Lambert bound's `degree_two_lanes` and of the node bound's
    /// scale `I kd / D^2`, lane by lane (for a light, whose moments are
    /// zero, the terms that vanish exactly are skipped: the same bits).
    /// Each lane adds its entries in order (at most `len / LANES + 1`
    /// roundings per channel), and the lanes are added last.
    ///
    /// Every entry must lie farther from `point` than its radius (the shared
    /// cut guarantees it), so `D > 0`.
    // Calling the copies compiled for wider vectors once the processor is
    // known to have them is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    pub(crate) fn sum(&self, point: DVec3, normal: DVec3) -> DVec3 {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::dispatch::avx512f() {
                // SAFETY: the processor has AVX-512F (`dispatch` checked).
                return unsafe { self.sum_avx512(point, normal) };
            }
            if crate::dispatch::avx2() {
                // SAFETY: the processor has AVX2 (`dispatch` checked).
                return unsafe { self.sum_avx2(point, normal) };
            }
        }
        self.sum_lanes(point, normal)
    }

    /// [`sum`](Self::sum) compiled for AVX-512 (8 lanes a vector). Rust
    /// never fuses a multiply and an add, so the results are the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn sum_avx512(&self, point: DVec3, normal: DVec3) -> DVec3 {
        self.sum_lanes(point, normal)
    }

    /// [`sum`](Self::sum) compiled for AVX2 (4 lanes a vector).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sum_avx2(&self, point: DVec3, normal: DVec3) -> DVec3 {
        self.sum_lanes(point, normal)
    }

    /// The sum itself, inlined into each of the above.
    #[inline(always)]
    fn sum_lanes(&self, point: DVec3, normal: DVec3) -> DVec3 {
        let mut acc = [[0.0f64; LANES]; 3];
        let (p, n) = (point.to_array(), normal.to_array());
        for b in &self.lights {
            for l in 0..LANES {
                let g = b.geometry(l, p, n);
                for (k, sum) in acc.iter_mut().enumerate() {
                    sum[l] += b.intensity[k][l] * g.inv_d2 * g.c0;
                }
            }
        }
        for b in &self.nodes {
            for l in 0..LANES {
                let g = b.at.geometry(l, p, n);
                let uh = g.uh;
                let three_c0 = 3.0 * g.c0;
                let grad = [
                    n[0] - three_c0 * uh[0],
                    n[1] - three_c0 * uh[1],
                    n[2] - three_c0 * uh[2],
                ];
                let (a, c) = (15.0 * g.c0, 3.0 * g.c0);
                let weights = [
                    a * uh[0] * uh[0] - c - 6.0 * uh[0] * n[0],
                    a * uh[1] * uh[1] - c - 6.0 * uh[1] * n[1],
                    a * uh[2] * uh[2] - c - 6.0 * uh[2] * n[2],
                    2.0 * a * uh[0] * uh[1] - 6.0 * (uh[0] * n[1] + uh[1] * n[0]),
                    2.0 * a * uh[0] * uh[2] - 6.0 * (uh[0] * n[2] + uh[2] * n[0]),
                    2.0 * a * uh[1] * uh[2] - 6.0 * (uh[1] * n[2] + uh[2] * n[1]),
                ];
                let half_inv_d2 = 0.5 * (g.inv_d * g.inv_d);
                for (k, sum) in acc.iter_mut().enumerate() {
                    let o = &b.offsets[k];
                    let first =
                        (grad[0] * o[0][l] + grad[1] * o[1][l] + grad[2] * o[2][l]) * g.inv_d;
                    let s = &b.covariances[k];
                    let mut form = 0.0;
                    for (entry, weight) in s.iter().zip(weights) {
                        form += entry[l] * weight;
                    }
                    let series = g.c0 + first + form * half_inv_d2;
                    sum[l] += b.at.intensity[k][l] * g.inv_d2 * series;
                }
            }
        }
        let total = |k: usize| acc[k].iter().sum::<f64>();
        DVec3::new(total(0), total(1), total(2))
    }
}

/// What an entry's lane shares between its terms: `1/D`, `1/D^2`, the unit
/// axis and `c0 = n . uh`, computed as [`Cone::new`](crate::Cone::new)
/// does.
struct Geometry {
    inv_d: f64,
    inv_d2: f64,
    uh: [f64; 3],
    c0: f64,
}

impl LightBlock {
    /// A block whose lanes all sit at `position` with zero intensity:
    /// finite, so unused lanes add exactly 0.
    fn padded(position: Vec3) -> Self {
        let mut block = Self::default();
        for axis in 0..3 {
            block.position[axis] = [f64::from(position[axis]); LANES];
        }
        block
    }

    fn set(&mut self, lane: usize, position: Vec3, intensity: DVec3) {
        for axis in 0..3 {
            self.position[axis][lane] = f64::from(position[axis]);
            self.intensity[axis][lane] = intensity[axis];
        }
    }

    #[inline(always)]
    fn geometry(&self, l: usize, p: [f64; 3], n: [f64; 3]) -> Geometry {
        let u = [
            self.position[0][l] - p[0],
            self.position[1][l] - p[1],
            self.position[2][l] - p[2],
        ];
        let distance = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
        let inv_d = 1.0 / distance;
        let uh = [u[0] * inv_d, u[1] * inv_d, u[2] * inv_d];
        Geometry {
            inv_d,
            inv_d2: inv_d * inv_d,
            uh,
            c0: n[0] * uh[0] + n[1] * uh[1] + n[2] * uh[2],
        }
    }
}
