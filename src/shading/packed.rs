//! A shared cut's node estimates as structure of arrays, summed at one
//! point in [`LANES`] independent lanes that the compiler vectorizes; on
//! `x86_64` the widest vectors the processor has are picked at run time.

use glam::{DVec3, Vec3};

use crate::tree::Node;

/// Entries summed side by side.
pub(crate) const LANES: usize = 8;

type Lanes = [f64; LANES];
/// Values stored in `f32` in the tree, kept so (their `f64` conversion is
/// exact) to halve the bytes each point reads.
type Lanes32 = [f32; LANES];

/// [`LANES`] entries: each field holds one value per lane.
#[derive(Clone, Copy, Debug, Default)]
struct Block {
    centroid: [Lanes32; 3],
    /// `I_k kd_k` per channel.
    intensity: [Lanes; 3],
    /// `o_k` per channel, per axis.
    offsets: [[Lanes32; 3]; 3],
    /// `S_k` per channel, entries `[xx, yy, zz, xy, xz, yz]`.
    covariances: [[Lanes32; 6]; 3],
}

/// The entries of a shared cut whose estimate is the degree-2 series
/// ([`degree_two`](crate::lambert::degree_two)): nodes, and single lights
/// (zero moments) above every tangent plane.
#[derive(Debug, Default)]
pub(crate) struct Packed {
    blocks: Vec<Block>,
    len: usize,
}

impl Packed {
    pub(crate) fn clear(&mut self) {
        self.blocks.clear();
        self.len = 0;
    }

    /// Number of entries.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Adds a node, its intensity times `kd`.
    pub(crate) fn push_node(&mut self, node: &Node, kd: DVec3) {
        let o = node.channel_offsets;
        let s = node.channel_covariances;
        let lane = self.lane(node.centroid, node.intensity * kd);
        let block = self.blocks.last_mut().expect("lane() made a block");
        for k in 0..3 {
            for axis in 0..3 {
                block.offsets[k][axis][lane] = o[k][axis];
            }
            for (entry, value) in s[k].iter().enumerate() {
                block.covariances[k][entry][lane] = *value;
            }
        }
    }

    /// Adds a single light of `intensity` times `kd` at `position`.
    pub(crate) fn push_light(&mut self, position: Vec3, intensity: DVec3) {
        self.lane(position, intensity);
    }

    /// Claims the next lane for an entry at `centroid` of `intensity`
    /// (moments zero until set) and returns its index in the last block.
    fn lane(&mut self, centroid: Vec3, intensity: DVec3) -> usize {
        let lane = self.len % LANES;
        if lane == 0 {
            // Unused lanes keep this entry's centroid with zero intensity:
            // finite, and they add exactly 0.
            let mut block = Block::default();
            for axis in 0..3 {
                block.centroid[axis] = [centroid[axis]; LANES];
            }
            self.blocks.push(block);
        }
        let block = self.blocks.last_mut().expect("a block was just pushed");
        for axis in 0..3 {
            block.centroid[axis][lane] = centroid[axis];
            block.intensity[axis][lane] = intensity[axis];
        }
        self.len += 1;
        lane
    }

    /// The sum of every entry's degree-2 estimate at `point` with unit
    /// normal `normal`: the operations of
    /// [`degree_two`](crate::lambert::degree_two) and of the node bound's
    /// scale `I kd / D^2`, lane by lane. Each lane adds its entries in
    /// order (`len / LANES` roundings per channel), and the lanes are added
    /// last.
    ///
    /// Every entry's centroid must lie farther from `point` than its
    /// radius (the shared cut guarantees it), so `D > 0`.
    // The crate's only unsafe code: calling the copies compiled for wider
    // vectors once the processor is known to have them.
    #[allow(unsafe_code)]
    pub(crate) fn sum(&self, point: DVec3, normal: DVec3) -> DVec3 {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the processor has AVX-512F, checked just above.
                return unsafe { self.sum_avx512(point, normal) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor has AVX2, checked just above.
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
        for b in &self.blocks {
            for l in 0..LANES {
                let u = [
                    f64::from(b.centroid[0][l]) - p[0],
                    f64::from(b.centroid[1][l]) - p[1],
                    f64::from(b.centroid[2][l]) - p[2],
                ];
                let distance = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
                let inv_d = 1.0 / distance;
                let uh = [u[0] * inv_d, u[1] * inv_d, u[2] * inv_d];
                let c0 = n[0] * uh[0] + n[1] * uh[1] + n[2] * uh[2];
                let three_c0 = 3.0 * c0;
                let grad = [
                    n[0] - three_c0 * uh[0],
                    n[1] - three_c0 * uh[1],
                    n[2] - three_c0 * uh[2],
                ];
                let (a, bb) = (15.0 * c0, 3.0 * c0);
                let weights = [
                    a * uh[0] * uh[0] - bb - 6.0 * uh[0] * n[0],
                    a * uh[1] * uh[1] - bb - 6.0 * uh[1] * n[1],
                    a * uh[2] * uh[2] - bb - 6.0 * uh[2] * n[2],
                    2.0 * a * uh[0] * uh[1] - 6.0 * (uh[0] * n[1] + uh[1] * n[0]),
                    2.0 * a * uh[0] * uh[2] - 6.0 * (uh[0] * n[2] + uh[2] * n[0]),
                    2.0 * a * uh[1] * uh[2] - 6.0 * (uh[1] * n[2] + uh[2] * n[1]),
                ];
                let half_inv_d2 = 0.5 * (inv_d * inv_d);
                let inv_d2 = inv_d * inv_d;
                for k in 0..3 {
                    let o = &b.offsets[k];
                    let first = (grad[0] * f64::from(o[0][l])
                        + grad[1] * f64::from(o[1][l])
                        + grad[2] * f64::from(o[2][l]))
                        * inv_d;
                    let s = &b.covariances[k];
                    let mut form = 0.0;
                    for e in 0..6 {
                        form += f64::from(s[e][l]) * weights[e];
                    }
                    let series = c0 + first + form * half_inv_d2;
                    acc[k][l] += b.intensity[k][l] * inv_d2 * series;
                }
            }
        }
        let total = |k: usize| acc[k].iter().sum::<f64>();
        DVec3::new(total(0), total(1), total(2))
    }
}
