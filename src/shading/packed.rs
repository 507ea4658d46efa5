//! A shared cut's estimates as structure of arrays, summed at the group's
//! points in independent lanes that the compiler vectorizes; on `x86_64`
//! the widest vectors the processor has are picked at run time.
//!
//! The estimates are packed in `f64` ([`WIDE`] lanes), or, when the cut's
//! certified error is coarse enough (at least [`NARROW_PRECISION`] of the
//! radiance it steers by) and every value fits, in `f32` ([`NARROW`] lanes,
//! twice as many a vector) in a frame scaled by powers of two; then each
//! point also sums a certified bound on its own rounding, which its
//! result's bound takes in.
//!
//! # The rounding of the `f32` sum
//!
//! Write `u = 2^-24`, `D` for the distance from the point to an entry, `I`
//! for a channel's intensity (times `kd`), `o` and `S` for its moments
//! (zero for a light), `x = |o|_1 / D`, `y = sum_e |S_e| / D^2` over the
//! six stored entries of `S`. The estimate is `I (f + o.grad f + S:hess f /
//! 2)` with `f(d) = n.d / |d|^3` at `d = c - p`. Positions and points are
//! `f32` values, so in the frame scaled by a power of two (every distance
//! at least 1, every scaled intensity at most 1/2) they are still exact,
//! and there are three sources of error:
//!
//! * The offset. `c - p` is rounded once, to `d + e` with `|e| <= u D`.
//!   The derivatives of `1/|d|` of order `l` have norm `l! / D^(l+1)` (the
//!   Legendre polynomials are at most 1, and a symmetric tensor's norm is
//!   its largest value on equal unit vectors), so the estimate's gradient
//!   is at most `I (2 + 6x + 24y) / D^3` (the full matrix's entries sum to
//!   at most twice the stored six), and `e` moves the estimate by at most
//!   `u I (2 + 6x + 24y) / D^2`.
//! * The arithmetic of one entry, taken op by op with `|n| = 1`, `|uh| =
//!   1`, `|grad| <= 2` and every Hessian weight at most 24 (to first order
//!   in `u`, constants rounded up): `1/D` within `4.01 u`, `uh` within
//!   `5.01 u` per component, `c0 = n.uh` within `9.1 u`, `first` within
//!   `109 u x`, each weight within `814 u`, the Hessian term within `767 u
//!   y`, the sum of the three within `11.2 u + 113 u x + 809 u y`, and the
//!   entry within `I (23.4 u + 137.4 u x + 1066 u y) / D^2`.
//! * The lanes' sums: in `f32` over at most [`FLUSH`] blocks, within
//!   `1.01 FLUSH u` of the sum of the terms' magnitudes, each at most `I (1
//!   + 2x + 21y) / D^2` (1.02 times that for the rounded terms), then in
//!   `f64`.
//!
//! So an entry is within `u I (38 + 166x + 1310y) / D^2` (the first two
//! parts, times 1.001 for `e`, within `u (28 + 146x + 1100y)`, the sums
//! within `10 u (1 + 2x + 21y)`), and `2^-126` (in the scaled frame) for
//! what underflows. Each point sums that envelope over the entries beside
//! its estimates, with the largest channel's `I`, in `f32` lanes too: all
//! its terms are positive, so the computed envelope is within `40 u` of
//! its value (the rounding of `1/D` included), and times `1 + 2^-16` it is
//! an upper bound. Its bound grows by `1.002 u` times that.

use glam::{DVec3, Vec3};

use crate::cut::Spread;
use crate::lanes::Real;
use crate::tree::Node;

/// `f64` entries summed side by side.
pub(crate) const WIDE: usize = 8;

/// `f32` entries summed side by side.
const NARROW: usize = 16;

/// Blocks a lane sums in its own type before adding them to its `f64`
/// sum.
const FLUSH: usize = 8;

/// The `f32` sums are used when the cut's error is at least this share of
/// the radiance steering it (a relative target of `2.4e-4` or coarser):
/// their rounding is then a small part of each point's bound.
const NARROW_PRECISION: f64 = 1.0 / 4096.0;

/// `2^-24`, the unit roundoff of `f32`.
const U32: f64 = 1.0 / 16_777_216.0;

/// An entry's rounding envelope: `38 + 166x + 1310y` (module docs), its
/// constants raised by `2^-16` for the envelope's own rounding.
const ENVELOPE: [f64; 3] = [
    38.0 * ENVELOPE_PAD,
    166.0 * ENVELOPE_PAD,
    1310.0 * ENVELOPE_PAD,
];
const ENVELOPE_PAD: f64 = 1.0 + 1.0 / 65_536.0;

/// The largest distance, in nearest distances, for the `f32` sum (so that
/// squares stay far from `f32::MAX`).
const MAX_REACH: f64 = 1_099_511_627_776.0; // 2^40

/// The largest coordinate, in the scaled frame, for the `f32` sum.
const MAX_COORDINATE: f64 = 1.267_650_600_228_229_4e30; // 2^100

/// `N` single lights: position, intensity times `kd`, and (`f32` only)
/// the rounding envelope's constant term `38 max_k I_k`.
#[derive(Clone, Copy, Debug)]
struct LightBlock<T, const N: usize> {
    position: [[T; N]; 3],
    intensity: [[T; N]; 3],
    envelope: [T; N],
}

/// `N` nodes: centroid, intensity times `kd`, moments, and (`f32` only)
/// the rounding envelope's `x` and `y` coefficients.
#[derive(Clone, Copy, Debug)]
struct NodeBlock<T, const N: usize> {
    at: LightBlock<T, N>,
    /// `o_k` per channel, per axis.
    offsets: [[[T; N]; 3]; 3],
    /// `S_k` per channel, entries `[xx, yy, zz, xy, xz, yz]`.
    covariances: [[[T; N]; 6]; 3],
    /// `166 max_k I_k |o_k|_1` and `1310 max_k I_k sum_e |S_k,e|`.
    envelope: [[T; N]; 2],
}

/// An entry's values in some frame.
#[derive(Default)]
struct Values<T> {
    position: [T; 3],
    intensity: [T; 3],
    offsets: [[T; 3]; 3],
    covariances: [[T; 6]; 3],
    /// The envelope's coefficients of 1, `1/D` and `1/D^2` (without the
    /// `1/D^2` all three carry).
    envelope: [T; 3],
}

/// Entries in blocks of `N` lanes.
#[derive(Debug)]
struct Blocks<T, const N: usize> {
    nodes: Vec<NodeBlock<T, N>>,
    node_count: usize,
    lights: Vec<LightBlock<T, N>>,
    light_count: usize,
}

impl<T, const N: usize> Default for Blocks<T, N> {
    fn default() -> Self {
        Self {
            nodes: Vec::new(),
            node_count: 0,
            lights: Vec::new(),
            light_count: 0,
        }
    }
}

/// What an entry's lane shares between its terms: `1/D`, `1/D^2`, the unit
/// axis and `c0 = n . uh`, computed as [`Cone::new`](crate::shader::Cone::new)
/// does.
struct Geometry<T> {
    inv_d: T,
    inv_d2: T,
    uh: [T; 3],
    c0: T,
}

impl<T: Real, const N: usize> LightBlock<T, N> {
    /// A block whose lanes all sit at `position` with zero intensity:
    /// finite, so unused lanes add exactly 0.
    fn padded(position: [T; 3]) -> Self {
        Self {
            position: [[position[0]; N], [position[1]; N], [position[2]; N]],
            intensity: [[T::default(); N]; 3],
            envelope: [T::default(); N],
        }
    }

    fn set(&mut self, lane: usize, v: &Values<T>) {
        for axis in 0..3 {
            self.position[axis][lane] = v.position[axis];
            self.intensity[axis][lane] = v.intensity[axis];
        }
        self.envelope[lane] = v.envelope[0];
    }

    #[inline(always)]
    fn geometry(&self, l: usize, p: [T; 3], n: [T; 3]) -> Geometry<T> {
        let u = [
            self.position[0][l] - p[0],
            self.position[1][l] - p[1],
            self.position[2][l] - p[2],
        ];
        let distance = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
        let inv_d = T::of(1.0) / distance;
        let uh = [u[0] * inv_d, u[1] * inv_d, u[2] * inv_d];
        Geometry {
            inv_d,
            inv_d2: inv_d * inv_d,
            uh,
            c0: n[0] * uh[0] + n[1] * uh[1] + n[2] * uh[2],
        }
    }
}

/// Lane sums: estimates per channel, and rounding envelopes.
type Sums<T, const N: usize> = ([[T; N]; 3], [T; N]);

impl<T: Real, const N: usize> Blocks<T, N> {
    fn clear(&mut self) {
        self.nodes.clear();
        self.lights.clear();
        self.node_count = 0;
        self.light_count = 0;
    }

    fn push_node(&mut self, v: &Values<T>) {
        let lane = self.node_count % N;
        if lane == 0 {
            self.nodes.push(NodeBlock {
                at: LightBlock::padded(v.position),
                offsets: [[[T::default(); N]; 3]; 3],
                covariances: [[[T::default(); N]; 6]; 3],
                envelope: [[T::default(); N]; 2],
            });
        }
        let block = self.nodes.last_mut().expect("a block was just pushed");
        block.at.set(lane, v);
        for k in 0..3 {
            for axis in 0..3 {
                block.offsets[k][axis][lane] = v.offsets[k][axis];
            }
            for entry in 0..6 {
                block.covariances[k][entry][lane] = v.covariances[k][entry];
            }
        }
        block.envelope[0][lane] = v.envelope[1];
        block.envelope[1][lane] = v.envelope[2];
        self.node_count += 1;
    }

    fn push_light(&mut self, v: &Values<T>) {
        let lane = self.light_count % N;
        if lane == 0 {
            self.lights.push(LightBlock::padded(v.position));
        }
        let block = self.lights.last_mut().expect("a block was just pushed");
        block.set(lane, v);
        self.light_count += 1;
    }

    /// The sum of every entry's degree-2 estimate at `p` with unit normal
    /// `n`, and (in `f32`) of their rounding envelopes: the operations of
    /// the Lambert bound's `degree_two_lanes` and of the node bound's scale
    /// `I kd / D^2`, lane by lane (for a light, whose moments are zero, the
    /// terms that vanish exactly are skipped: the same bits). Each lane adds
    /// its entries in order, [`FLUSH`] blocks at a time into `f64`, and the
    /// lanes are added last.
    // Index loops: iterator chains here made the batch call slower
    // (`docs/tuning.md`; `cargo run --release -p manylights-report --
    // batch` measures it).
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn sum(&self, p: [T; 3], n: [T; 3]) -> ([f64; 3], f64) {
        let mut total = ([[0.0f64; N]; 3], [0.0f64; N]);
        for chunk in self.lights.chunks(FLUSH) {
            widen_into(&mut total, light_terms(chunk, p, n));
        }
        for chunk in self.nodes.chunks(FLUSH) {
            widen_into(&mut total, node_terms(chunk, p, n));
        }
        let (mut sums, mut envelope) = ([0.0; 3], 0.0);
        for l in 0..N {
            for k in 0..3 {
                sums[k] += total.0[k][l];
            }
            envelope += total.1[l];
        }
        (sums, envelope)
    }
}

/// Adds lane sums into `f64` lanes.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn widen_into<T: Real, const N: usize>(total: &mut Sums<f64, N>, (acc, envelope): Sums<T, N>) {
    for l in 0..N {
        for k in 0..3 {
            total.0[k][l] += acc[k][l].widen();
        }
        total.1[l] += envelope[l].widen();
    }
}

/// The lights' terms, summed lane by lane (in the lanes' type).
#[inline(always)]
fn light_terms<T: Real, const N: usize>(
    blocks: &[LightBlock<T, N>],
    p: [T; 3],
    n: [T; 3],
) -> Sums<T, N> {
    let mut acc = [[T::default(); N]; 3];
    let mut envelope = [T::default(); N];
    for b in blocks {
        for l in 0..N {
            let g = b.geometry(l, p, n);
            for (k, sum) in acc.iter_mut().enumerate() {
                sum[l] += b.intensity[k][l] * g.inv_d2 * g.c0;
            }
            if T::ROUNDED {
                envelope[l] += b.envelope[l] * g.inv_d2;
            }
        }
    }
    (acc, envelope)
}

/// The nodes' degree-2 series, summed lane by lane (in the lanes' type).
#[inline(always)]
fn node_terms<T: Real, const N: usize>(
    blocks: &[NodeBlock<T, N>],
    p: [T; 3],
    n: [T; 3],
) -> Sums<T, N> {
    let mut acc = [[T::default(); N]; 3];
    let mut envelope = [T::default(); N];
    let (three, six, fifteen, half) = (T::of(3.0), T::of(6.0), T::of(15.0), T::of(0.5));
    for b in blocks {
        for l in 0..N {
            let g = b.at.geometry(l, p, n);
            let uh = g.uh;
            let three_c0 = three * g.c0;
            let grad = [
                n[0] - three_c0 * uh[0],
                n[1] - three_c0 * uh[1],
                n[2] - three_c0 * uh[2],
            ];
            let (a, c) = (fifteen * g.c0, three * g.c0);
            let two_a = a + a;
            let weights = [
                a * uh[0] * uh[0] - c - six * uh[0] * n[0],
                a * uh[1] * uh[1] - c - six * uh[1] * n[1],
                a * uh[2] * uh[2] - c - six * uh[2] * n[2],
                two_a * uh[0] * uh[1] - six * (uh[0] * n[1] + uh[1] * n[0]),
                two_a * uh[0] * uh[2] - six * (uh[0] * n[2] + uh[2] * n[0]),
                two_a * uh[1] * uh[2] - six * (uh[1] * n[2] + uh[2] * n[1]),
            ];
            let half_inv_d2 = half * (g.inv_d * g.inv_d);
            for (k, sum) in acc.iter_mut().enumerate() {
                let o = &b.offsets[k];
                let first = (grad[0] * o[0][l] + grad[1] * o[1][l] + grad[2] * o[2][l]) * g.inv_d;
                let s = &b.covariances[k];
                let mut form = T::default();
                for (entry, weight) in s.iter().zip(weights) {
                    form += entry[l] * weight;
                }
                let series = g.c0 + first + form * half_inv_d2;
                sum[l] += b.at.intensity[k][l] * g.inv_d2 * series;
            }
            if T::ROUNDED {
                let [x, y] = [b.envelope[0][l], b.envelope[1][l]];
                let factor = b.at.envelope[l] + g.inv_d * (x + g.inv_d * y);
                envelope[l] += factor * g.inv_d2;
            }
        }
    }
    (acc, envelope)
}

/// The `f32` frame: positions times `scale`, intensities times
/// `intensity`, sums times `out = 1 / (intensity * scale^2)`; all powers of
/// two.
#[derive(Clone, Copy, Debug, Default)]
struct Frame {
    scale: f64,
    intensity: f64,
    out: f64,
}

/// `x` in `f32`, rounded up, never down (for positive `x` far from the
/// range's ends).
fn up(x: f64) -> f32 {
    (x * (1.0 + 1.0 / 1_048_576.0)) as f32
}

/// The `f32` frame for a cut spread as `spread` within `limits`, or `None`
/// when some value would fall outside its range.
fn narrow_frame(spread: Spread, limits: Limits) -> Option<Frame> {
    let positive = |x: f64| x > 0.0 && x.is_finite();
    // Every distance from a point to an entry is at most `farthest +
    // radius`.
    if !(positive(spread.nearest)
        && spread.farthest + limits.radius <= MAX_REACH * spread.nearest
        && positive(limits.brightest))
    {
        return None;
    }
    // Lengths in units of `2^j`, at most half the nearest distance,
    // intensities in units of `2^k`, at least twice the brightest: every
    // distance at least 1, every intensity at most 1/2. (Both logarithms
    // are finite, within `f64`'s exponents.)
    let j = spread.nearest.log2().floor() as i32 - 1;
    let k = limits.brightest.log2().ceil() as i32 + 1;
    let out = k - 2 * j;
    let normal = -1000..=1000;
    if !(normal.contains(&j) && normal.contains(&k) && normal.contains(&out)) {
        return None;
    }
    let frame = Frame {
        scale: 2f64.powi(-j),
        intensity: 2f64.powi(-k),
        out: 2f64.powi(out),
    };
    (limits.extent.max(spread.farthest) * frame.scale <= MAX_COORDINATE).then_some(frame)
}

/// One point's packed sum and the bound on its rounding: per channel,
/// `|value - S| <= rounding`, with `S` the entries' estimates summed in
/// exact arithmetic at the point (0 for a sum in `f64` lanes, whose
/// rounding the cut's bound covers; see the module's docs).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PackedSum {
    pub(crate) value: DVec3,
    pub(crate) rounding: DVec3,
}

/// What every entry of a cut lies within: intensities (times `kd`, any
/// channel) at most `brightest`, coordinates (and the points') at most
/// `extent` in magnitude (the tree's root and the group's ball bound
/// them); the points lie within `radius` of the group's centre.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Limits {
    pub(crate) brightest: f64,
    pub(crate) extent: f64,
    pub(crate) radius: f64,
}

/// The entries of a shared cut whose estimate is the degree-2 series
/// (the Lambert bound's `degree_two_lanes`): nodes, and single lights
/// above every tangent plane (whose series is their exact term `c0`, the
/// moments being zero).
#[derive(Debug, Default)]
pub(crate) struct Packed {
    wide: Blocks<f64, WIDE>,
    narrow: Blocks<f32, NARROW>,
    /// The `f32` frame, when the entries are packed in `f32`.
    frame: Option<Frame>,
    /// Per channel, the entries with some intensity.
    lit: DVec3,
}

impl Packed {
    /// Starts packing a cut whose certified error is `error`, its entries
    /// within `limits` and spread about the group as `spread` says: in
    /// `f32` when that frame holds them and `error` is at least
    /// [`NARROW_PRECISION`] of `radiance` (the darkest sample's), else in
    /// `f64`.
    pub(crate) fn start(&mut self, error: DVec3, radiance: DVec3, spread: Spread, limits: Limits) {
        self.wide.clear();
        self.narrow.clear();
        self.lit = DVec3::ZERO;
        self.frame = if error.max_element() >= NARROW_PRECISION * radiance.max_element() {
            narrow_frame(spread, limits)
        } else {
            None
        };
    }

    /// Number of entries.
    pub(crate) fn len(&self) -> usize {
        self.wide.node_count
            + self.wide.light_count
            + self.narrow.node_count
            + self.narrow.light_count
    }

    /// Adds a node, its intensity times `kd`.
    pub(crate) fn push_node(&mut self, node: &Node, kd: DVec3) {
        let intensity = node.intensity * kd;
        self.lit += DVec3::select(intensity.cmpgt(DVec3::ZERO), DVec3::ONE, DVec3::ZERO);
        let Some(frame) = self.frame else {
            let mut v = Values::<f64> {
                position: node.centroid.as_dvec3().to_array(),
                intensity: intensity.to_array(),
                ..Values::default()
            };
            for k in 0..3 {
                for axis in 0..3 {
                    v.offsets[k][axis] = f64::from(node.channel_offsets[k][axis]);
                }
                for e in 0..6 {
                    v.covariances[k][e] = f64::from(node.channel_covariances[k][e]);
                }
            }
            return self.wide.push_node(&v);
        };
        let (scale, scale2, dim) = (frame.scale, frame.scale * frame.scale, frame.intensity);
        let mut v = Values::<f32>::default();
        let (mut offset, mut spread, mut brightest) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..3 {
            let intensity = intensity[k] * dim;
            v.position[k] = (f64::from(node.centroid[k]) * scale) as f32;
            v.intensity[k] = intensity as f32;
            let (mut o1, mut s6) = (0.0, 0.0);
            for axis in 0..3 {
                let o = f64::from(node.channel_offsets[k][axis]) * scale;
                v.offsets[k][axis] = o as f32;
                o1 += o.abs();
            }
            for e in 0..6 {
                let s = f64::from(node.channel_covariances[k][e]) * scale2;
                v.covariances[k][e] = s as f32;
                s6 += s.abs();
            }
            brightest = brightest.max(intensity);
            offset = offset.max(intensity * o1);
            spread = spread.max(intensity * s6);
        }
        v.envelope = [
            up(ENVELOPE[0] * brightest),
            up(ENVELOPE[1] * offset),
            up(ENVELOPE[2] * spread),
        ];
        self.narrow.push_node(&v);
    }

    /// Adds a single light of `intensity` (times `kd`) at `position`.
    pub(crate) fn push_light(&mut self, position: Vec3, intensity: DVec3) {
        self.lit += DVec3::select(intensity.cmpgt(DVec3::ZERO), DVec3::ONE, DVec3::ZERO);
        let Some(frame) = self.frame else {
            return self.wide.push_light(&Values {
                position: position.as_dvec3().to_array(),
                intensity: intensity.to_array(),
                ..Values::default()
            });
        };
        let mut v = Values::<f32>::default();
        let mut brightest = 0.0f64;
        for k in 0..3 {
            let intensity = intensity[k] * frame.intensity;
            v.position[k] = (f64::from(position[k]) * frame.scale) as f32;
            v.intensity[k] = intensity as f32;
            brightest = brightest.max(intensity);
        }
        v.envelope[0] = up(ENVELOPE[0] * brightest);
        self.narrow.push_light(&v);
    }

    /// The sum of every entry's degree-2 estimate at `point` (an `f32`
    /// value, as a `Surface`'s) with unit normal `normal`, in `f32` when
    /// [`start`](Self::start) chose that frame (with the bound on that
    /// rounding).
    ///
    /// Every entry must lie farther from the point than its radius (the
    /// shared cut guarantees it), so `D > 0`; and the point must lie within
    /// the group that [`start`](Self::start) was told of.
    /// Compiled for AVX-512F or AVX2 where the processor has them
    /// ([`dispatch`](crate::dispatch); a vector then holds 8 or 4 `f64`, 16
    /// or 8 `f32` lanes). Rust never fuses a multiply and an add, so the
    /// results are the same bits.
    pub(crate) fn sum(&self, point: DVec3, normal: DVec3) -> PackedSum {
        crate::dispatch::with_avx512f_or_avx2(
            #[inline(always)]
            || self.sum_lanes(point, normal),
        )
    }

    /// The sum itself, inlined into each compiled copy of
    /// [`sum`](Self::sum). (No closures inside: one would be compiled out
    /// of line, without the copy's target features.)
    #[inline(always)]
    fn sum_lanes(&self, point: DVec3, normal: DVec3) -> PackedSum {
        let Some(frame) = self.frame else {
            let (sum, _) = self.wide.sum(point.to_array(), normal.to_array());
            return PackedSum {
                value: DVec3::from_array(sum),
                rounding: DVec3::ZERO,
            };
        };
        // The point is an `f32` value, so exactly scaled.
        let p = (point * frame.scale).as_vec3().to_array();
        let (sum, envelope) = self.narrow.sum(p, normal.as_vec3().to_array());
        // `2^-126` per lit entry for what underflows.
        let underflow = self.lit * f64::from(f32::MIN_POSITIVE);
        let rounding = DVec3::splat(envelope * (1.002 * U32)) + underflow;
        PackedSum {
            value: DVec3::from_array(sum) * frame.out,
            rounding: DVec3::select(
                self.lit.cmpgt(DVec3::ZERO),
                rounding * frame.out,
                DVec3::ZERO,
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};
    use proptest::prelude::*;

    use super::*;
    use crate::{LightTree, PointLight};

    /// A tree over `count` lights clustered in a few blobs above the plane
    /// `z = 0`, about `origin`.
    fn tree(seed: u64, count: usize, origin: Vec3, size: f32) -> LightTree {
        let mut state = seed;
        let mut next = move || crate::testing::uniform(&mut state);
        let centres: Vec<Vec3> = (0..4)
            .map(|_| Vec3::new(next() - 0.5, next() - 0.5, 0.2 * next()) * size)
            .collect();
        let lights: Vec<PointLight> = (0..count)
            .map(|i| {
                let c = centres[i % centres.len()];
                let spread = Vec3::new(next() - 0.5, next() - 0.5, next()) * (0.3 * size);
                let colour = Vec3::new(next(), next() * 1e-3, 1e3 * next() * next());
                PointLight::new(origin + c + spread + Vec3::Z * (0.05 * size), colour)
            })
            .collect();
        LightTree::build(&lights).unwrap()
    }

    /// Packs a cut of `tree` for `points` (each node whose centroid lies
    /// farther from every point than `clearance` times its radius, else its
    /// children or lights) twice, in `f32` and in `f64`, and returns both
    /// sums at every point.
    fn both_sums(
        tree: &LightTree,
        points: &[(DVec3, DVec3)],
        clearance: f64,
        kd: DVec3,
    ) -> (Vec<PackedSum>, Vec<PackedSum>) {
        let centre = points.iter().map(|p| p.0).sum::<DVec3>() / points.len() as f64;
        let nearest = |c: DVec3| {
            points
                .iter()
                .map(|p| (c - p.0).length())
                .fold(f64::INFINITY, f64::min)
        };
        let mut cut = Vec::new();
        let mut lights = Vec::new();
        let mut stack = vec![0usize];
        let mut spread = Spread::default();
        while let Some(i) = stack.pop() {
            let node = &tree.nodes[i];
            let c = node.centroid.as_dvec3();
            if nearest(c) > clearance * f64::from(node.radius) && node.radius > 0.0 {
                spread.note(nearest(c) * 0.999, (c - centre).length());
                cut.push(i);
            } else if node.is_leaf() {
                for k in node.lights() {
                    let l = tree.lights[k];
                    let at = l.position.as_dvec3();
                    spread.note(nearest(at) * 0.999, (at - centre).length());
                    lights.push((l.position, l.intensity.as_dvec3() * kd));
                }
            } else {
                stack.extend(node.children());
            }
        }
        let root = &tree.nodes[0];
        let extent = points
            .iter()
            .map(|p| p.0.abs().max_element())
            .fold(0.0, f64::max)
            .max(f64::from(
                root.aabb.min.abs().max(root.aabb.max.abs()).max_element(),
            ));
        let radius = points
            .iter()
            .map(|p| (p.0 - centre).length())
            .fold(0.0, f64::max);
        let limits = Limits {
            brightest: (root.intensity * kd).max_element(),
            extent,
            radius,
        };
        let mut sums = [Vec::new(), Vec::new()];
        for (narrow, sums) in [true, false].into_iter().zip(&mut sums) {
            let mut packed = Packed::default();
            // A coarse error packs in `f32`, an error of 0 in `f64`.
            let error = DVec3::splat(if narrow { 1.0 } else { 0.0 });
            packed.start(error, DVec3::ONE, spread, limits);
            assert_eq!(packed.frame.is_some(), narrow);
            for &i in &cut {
                packed.push_node(&tree.nodes[i], kd);
            }
            for &(position, intensity) in &lights {
                packed.push_light(position, intensity);
            }
            sums.extend(points.iter().map(|&(p, n)| packed.sum(p, n)));
        }
        let [narrow, wide] = sums;
        (narrow, wide)
    }

    proptest! {
        /// The `f32` sums lie within their stated rounding of the `f64`
        /// sums (whose own rounding is some `2^-40` of that), on groups of
        /// tilted points far from the origin, for cuts whose nodes come as
        /// near as 1.05 radii (large moment terms) and lights as near as
        /// the lights are.
        #[test]
        fn narrow_sums_keep_within_their_rounding(
            seed in 1u64..u64::MAX,
            count in 1usize..400,
            far in prop_oneof![Just(0.0f32), 1e3f32..1e6],
            size in 0.5f32..500.0,
            clearance in prop_oneof![Just(1.05f64), 1.05f64..20.0],
            tilts in proptest::collection::vec((-1.0f32..1.0, -1.0f32..1.0, 0.05f32..1.0), 1..40),
            spots in proptest::collection::vec((-0.5f32..0.5, -0.5f32..0.5, -0.02f32..0.0), 40),
        ) {
            let origin = Vec3::new(far, -0.5 * far, 0.0);
            let tree = tree(seed, count, origin, size);
            let points: Vec<(DVec3, DVec3)> = tilts
                .iter()
                .zip(&spots)
                .map(|(&(x, y, z), &(a, b, c))| {
                    let p = origin + Vec3::new(a, b, c) * size;
                    (p.as_dvec3(), Vec3::new(x, y, z).normalize().as_dvec3())
                })
                .collect();
            let kd = DVec3::new(0.9, 0.5, 0.2);
            let (narrow, wide) = both_sums(&tree, &points, clearance, kd);
            for (n, w) in narrow.iter().zip(&wide) {
                prop_assert_eq!(w.rounding, DVec3::ZERO);
                let miss = (n.value - w.value).abs();
                prop_assert!(
                    miss.cmple(n.rounding).all(),
                    "f32 {} f64 {} rounding {}",
                    n.value,
                    w.value,
                    n.rounding
                );
            }
        }
    }

    #[test]
    fn a_cut_too_fine_for_f32_is_packed_in_f64() {
        let spread = Spread {
            nearest: 1.0,
            farthest: 10.0,
        };
        let limits = Limits {
            brightest: 1.0,
            extent: 10.0,
            radius: 1.0,
        };
        let mut packed = Packed::default();
        packed.start(DVec3::splat(1e-6), DVec3::ONE, spread, limits);
        assert!(packed.frame.is_none());
        packed.start(DVec3::splat(1e-3), DVec3::ONE, spread, limits);
        assert!(packed.frame.is_some());
        // Distances beyond the frame's reach.
        let far = Spread {
            nearest: 1e-13,
            farthest: 1.0,
        };
        packed.start(DVec3::splat(1e-3), DVec3::ONE, far, limits);
        assert!(packed.frame.is_none());
        // A group far wider than its nearest entry is near.
        let wide = Limits {
            radius: 1e13,
            ..limits
        };
        packed.start(DVec3::splat(1e-3), DVec3::ONE, spread, wide);
        assert!(packed.frame.is_none());
        // No entry noted (nearest distance infinite).
        packed.start(DVec3::splat(1e-3), DVec3::ONE, Spread::default(), limits);
        assert!(packed.frame.is_none());
    }
}
