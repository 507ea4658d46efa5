//! The children of a node bounded together in `f32`:
//! [`Lambert`](crate::Lambert)'s multipole series bound (with the paper's
//! and the box's intervals) for eight nodes at once, from the rows of the
//! tree's node groups, in one AVX2 vector per quantity.
//!
//! Every quantity before the last step is dimensionless, in units of
//! `I_k kd_k / D^2` for a node of intensity `I_k` at distance `D` (or of
//! `D` for lengths), so that the ranges of `f32` hold whatever the scene's
//! scale; the last step multiplies by `I_k kd_k / D^2` in `f64`. The
//! formulas are those of [`Lambert`](crate::Lambert)'s docs; what follows
//! is how each is widened for `f32` rounding, so that the interval still
//! contains the exact value.
//!
//! # Rounding
//!
//! Write `u = 2^-24` (the unit roundoff of `f32`). Inputs are exact: the
//! point `p` and every stored statistic are `f32` values; the unit normal
//! `n^` is the caller's normal normalized in `f64`, then rounded to `f32`
//! (`n`, within `1.001 u` of `n^` in length). The derivations are to first
//! order in `u`, with the constants rounded up; the constants used are
//! about twice them. Lanes whose squared distance `d2` lies outside
//! `[2^-120, 2^120]`, or whose ball comes within `2^-6 D` of the point
//! (`sigma >= 1 - 2^-6`, see [`SIGMA_MAX`]), are not bounded here (the
//! caller bounds them in `f64`), so no quantity overflows, and what
//! underflows is covered by an absolute `2^-100` (in units of `I_k kd_k /
//! D^2`).
//!
//! * *The offset.* `d = fl(c - p)` is within `u |c - p|` of `c - p`, so it
//!   is the exact offset `c - p'` of a point `p'` with `|p' - p| <= u D`.
//!   Everything below bounds the node seen from `p'`, exactly; the exact
//!   sum moves by at most `|p' - p| sup |grad f| <= u D * 2.43 I / (D -
//!   R)^3` between `p'` and `p` (the gradient of `max(0, n.v) / |v|^3` has
//!   norm at most `2 / |v|^3`; the segment stays `15/16 (D - R)` from the
//!   members since `D - R > 2^-6 D`), so the final interval is widened by
//!   [`POINT`]` (D / (D - R))^3` each way.
//! * *Geometry.* `d2` within `3.01 u` (relative), `D` within `2.51 u`,
//!   `1/D` within `3.52 u`, each component of `uh = d / D` within `4.53 u`;
//!   `c0 = n . uh` within `8.6 u` of `n^ . uh^` (absolute: `1.001 u` from
//!   `n`, `4.53 u` from `uh`, `3.02 u` from the dot product), `sin_c = |n x
//!   uh|` within `11.2 u`. `sigma` is `R / D` rounded up, multiplied by `1 +
//!   2^-21` so that it is at least the exact `R / D` (`4.53 u` below it at
//!   worst, and the product is rounded): every bound below grows with
//!   `sigma`, so an overestimate keeps it valid, and `sigma < 1 - 2^-6`
//!   gives `D - R > 2^-6 D` exactly.
//! * *The paper's interval.* The cone of half-angle `delta` with `sin delta
//!   = sigma` contains the exact one; the cosines `c0 cd -+ sin_c sigma`
//!   (`cd = sqrt((1 - sigma)(1 + sigma))`, within `5.5 u`) are within `29.5
//!   u` of their exact values, and choosing the branch `c0 >= cd` wrongly
//!   costs at most `22 u` more: both ends are widened by [`COS`]. The
//!   products with `(1 + sigma)^-2` and `(1 - sigma)^-2` (each within `6 u`)
//!   are moved outward by `16 u`, relatively.
//! * *Heights above the tangent plane.* `n . (c - p)` is computed within
//!   `5.02 u D` of `n^ . (c - p)` for the true point `p` (the rounding of
//!   `c - p` included), and the box's extent `n . (x - c)` (from the centre
//!   and half extent of the stored box, itself rounded outward relative to
//!   `c`) within `8 u B`, `B` the sum over axes of the box's largest
//!   `|x_j - c_j|`; with the additions, [`HEIGHT`]` (D + B)` covers both, so
//!   the highest and lowest heights bound those of every member for `p` and
//!   for `p'`. A highest height at most 0 means every member lies at or
//!   below the plane: exactly 0. A lowest at most 0 (the box reaches the
//!   plane) is reported, and the caller decides exactly whether the box
//!   lies at or below it.
//! * *The box's bound and the clamp.* `highest / (D - R)^3` and the depth
//!   below the plane (the smaller of `sigma - c0` and `-lowest / D`, each
//!   raised by its error) are products of non-negative factors, moved up by
//!   `16 u` relatively.
//! * *The series' estimate* `E_k` (degrees 0 to 2; `x = |o_k|_1 / D`, `y =
//!   sum_e |S_k,e| / D^2` over the six stored entries, whose full matrix's
//!   entries sum to at most `2 y D^2`): with `|n| <= 1 + 1.001 u`, `|uh| =
//!   1` and `|grad| <= 2`, the gradient is within `50 u`, the degree-1 term
//!   within `65 u x`, each of the six weights (at most 24) within `424 u`,
//!   the degree-2 term within `392 u y` (the weights' errors, the six
//!   products' sum and `1 / (2 D^2)`), and the sum of the three within
//!   `11 u + 69 u x + 416 u y`. [`ESTIMATE`] takes `16 + 128 x + 1024 y`
//!   units of `u`, with `x` bounded by `1.75 sigma` (every member lies
//!   within `R` of the centroid, so `|o_k| <= R` up to the build's
//!   rounding). The `f32` storage of the moments adds `2 u (x + 33
//!   tr(S_k) / D^2)` as in the `f64` bound, and the build's `f64` sums of
//!   them `2 delta (sigma + 18 sigma^2)`, added in `f64`.
//! * *The series' remainder* is a sum of minima of products of non-negative
//!   factors (about 20 roundings), each factor either computed from the
//!   widened `sigma`, `|c0| +` [`C0`], `sin_c +` [`SIN`] and the box's
//!   reach across the axis (raised by [`ACROSS`]` B`), or `1/D` (within
//!   `3.52 u`, at most squared): it is multiplied by `1 +` [`REMAINDER`].
//! * *Scaling.* `I_k kd_k / D^2` is computed in `f64` from the `f32` `d2`,
//!   within `3.02 u` (relative) of `I_k kd_k / D'^2`: the lower end is
//!   multiplied by `1 - 4 u`, the upper by `1 + 4 u`.
//! * *One colour.* A block whose lanes' lights have one colour (see
//!   [`groups`](crate::tree::groups)) stores channel 0's moments and, per
//!   other channel `k`, the colour's spread `s_k >= r_max / r_min` (`r_i =
//!   I_k,i / I_0,i`). Every term of the Lambert sum is at least 0, so the
//!   exact `S_k / I_k` lies in `[S_0 / I_0 / s_k, s_k S_0 / I_0]`: channel
//!   `k`'s lower end is channel 0's interval's lower end (in units, with
//!   its point and moment allowances) divided by `s_k`, its upper end
//!   multiplied by `s_k`, in `f64` before the factors `1 -+ 4 u`, which
//!   cover the extra `f64` rounding (`2^-53`) with room to spare. For
//!   white or grey lights `s_k` is exactly 1 and the results are the bits
//!   the three channels' rows would give.
//!
//! A property test checks each computed quantity against the same formula
//! evaluated in `f64` (nearly exact next to these slacks) on random and
//! adversarial nodes, points and normals, within half of its allowance.

use crate::lanes::{Real, Wide};
use crate::tree::groups::{BOX_HIGH, BOX_LOW, Block, CENTROID, RADIUS, widen_half};

/// `2^-24`, the unit roundoff of `f32`.
pub(crate) const U: f64 = 1.0 / 16_777_216.0;

/// Absolute widening of the cone's cosines, in units of `u` (module docs:
/// `29.5 u + 22 u`).
const COS: f64 = 64.0;
/// Absolute error allowance of the computed `c0`, in units of `u` (`8.6
/// u`).
const C0: f64 = 10.0;
/// Absolute error allowance of the computed `sin_c`, in units of `u`
/// (`11.2 u`).
const SIN: f64 = 12.0;
/// Heights above the tangent plane: allowance in units of `u (D + B)`.
const HEIGHT: f64 = 12.0;
/// The box's reach across the axis: allowance in units of `u B` (`nperp`
/// within `1.001 + 8.6 + 4.53` units of `u`, the products and sums of the
/// reach within 6 more).
const ACROSS: f64 = 24.0;
/// Relative widening of the products behind the paper's and the box's
/// bounds and of the clamp term, in units of `u`.
const PRODUCT: f64 = 16.0;
/// Relative widening of the series' remainder, in units of `u`.
const REMAINDER: f64 = 64.0;
/// The series estimate's rounding, in units of `u`: the constant, `x` and
/// `y` coefficients.
const ESTIMATE: [f64; 3] = [16.0, 128.0, 1024.0];
/// The moments' `f32` storage, in units of `u` (`f32::EPSILON = 2 u`).
const STORAGE: f64 = 2.0;
/// The point's rounding, in units of `u (D / (D - R))^3` (module docs:
/// `2.43`).
const POINT: f64 = 3.0;
/// The scaling's rounding, in units of `u`, relatively (`3.02 u`).
const SCALE: f64 = 4.0;
/// What underflow may lose, absolutely, in units of `I_k kd_k / D^2`.
const UNDERFLOW: f64 = 7.888_609_052_210_118e-31; // 2^-100
/// The range of squared distances bounded here: `[2^-120, 2^120]`.
pub(crate) const D2_RANGE: (f64, f64) = (7.523_163_845_262_64e-37, 1.329_227_995_784_916e36);
/// `1 - 2^-6`: lanes with `sigma` at or above it are left to the `f64`
/// bound. Nearer, the rounding of the offset and of `sigma`, magnified by
/// powers of `D / (D - R)`, would dominate: at this limit [`POINT`]
/// amounts to `3 u * 2^6`, about `2^-16.4`, of the node's `I kd / (D -
/// R)^2`, and `sigma`'s upward nudge (at most `8 u`) moves `(D / (D -
/// R))^2` by `16 u * 2^6`, about `2^-14`, relatively.
const SIGMA_MAX: f64 = 1.0 - 1.0 / 64.0;
/// `1 + 2^-21`, which raises a computed `R / D` above the exact one.
const SIGMA_UP: f64 = 1.0 + 1.0 / 2_097_152.0;

/// What the kernel reads of the shading point: the point and the unit
/// normal rounded to the lanes' type.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PointView<T> {
    pub(crate) p: [T; 3],
    pub(crate) n: [T; 3],
}

/// What the kernel reads of each lane's node besides its block: per
/// channel `I_k kd_k`, and the build's bound `delta` on the rounding of its
/// moments' sums ([`Node::moment_error`](crate::shader::Node::moment_error)).
#[derive(Clone, Copy, Debug)]
pub(crate) struct LaneScales<const N: usize> {
    pub(crate) intensity: [[f64; N]; 3],
    pub(crate) moment_error: [f64; N],
}

/// The children's bounds, per lane. Lanes past the group's children hold
/// values of no meaning, and so do the bounds of lanes that
/// [`LaneBounds::state`] does not call [`Lane::Bounded`] or
/// [`Lane::Reaching`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct LaneBounds<const N: usize> {
    /// Per channel, the interval's ends and its middle (the estimate).
    pub(crate) lower: [[f64; N]; 3],
    pub(crate) upper: [[f64; N]; 3],
    pub(crate) estimate: [[f64; N]; 3],
    /// The squared distance and `sigma` (at least `R / D`).
    d2: [f32; N],
    sigma: [f32; N],
    /// The upper end of the cone's cosine, widened.
    cos_hi: [f32; N],
    /// The highest and lowest heights of the box above the tangent plane,
    /// widened.
    highest: [f32; N],
    lowest: [f32; N],
}

/// What a lane of [`LaneBounds`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Lane {
    /// Not bounded here (the caller bounds it in `f64`): `d2` out of
    /// [`D2_RANGE`], or `sigma` at least `1 - 2^-6`.
    Fallback,
    /// Every member lies at or below the tangent plane: exactly 0.
    Dark,
    /// The box reaches the tangent plane (without lying wholly below it):
    /// the bounds hold, and whether every member lies at or below the
    /// plane is for the caller to decide exactly.
    Reaching,
    /// The bounds hold.
    Bounded,
}

impl<const N: usize> LaneBounds<N> {
    /// What lane `i` holds (see [`Lane`]).
    #[inline(always)]
    pub(crate) fn state(&self, i: usize) -> Lane {
        let d2 = f64::from(self.d2[i]);
        if !(d2 >= D2_RANGE.0 && d2 <= D2_RANGE.1 && f64::from(self.sigma[i]) < SIGMA_MAX) {
            Lane::Fallback
        } else if self.cos_hi[i] <= 0.0 || self.highest[i] <= 0.0 {
            Lane::Dark
        } else if self.lowest[i] <= 0.0 {
            Lane::Reaching
        } else {
            Lane::Bounded
        }
    }
}

/// The geometry of each lane's node seen from the point (see the module
/// docs), unwidened unless said.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry<T, const N: usize> {
    pub(crate) d2: Wide<T, N>,
    pub(crate) dist: Wide<T, N>,
    pub(crate) inv_d: Wide<T, N>,
    pub(crate) uh: [Wide<T, N>; 3],
    /// `R / D`, raised by `1 + 2^-21` (at least the exact value).
    pub(crate) sigma: Wide<T, N>,
    pub(crate) c0: Wide<T, N>,
    pub(crate) sin_c: Wide<T, N>,
    /// `n . (c - p)`.
    pub(crate) height: Wide<T, N>,
    /// `n . middle` and `|n| . half` for the box's centre and half extent
    /// relative to the centroid.
    pub(crate) box_mid: Wide<T, N>,
    pub(crate) box_reach: Wide<T, N>,
    /// `B = sum_j (|middle_j| + half_j)`.
    pub(crate) box_size: Wide<T, N>,
    /// `|nperp . middle| + |nperp| . half`, `nperp = n - c0 uh`.
    pub(crate) across: Wide<T, N>,
}

/// Row `field` of a block.
#[inline(always)]
fn row<T: Real, const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    field: usize,
) -> Wide<T, N> {
    Wide::from_f32(&block.rows[field])
}

/// The harmonic norms of degree `3 + d`, channel `k`, of a block (exact
/// values of their half-precision bits).
#[inline(always)]
fn norms<T: Real, const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    k: usize,
    d: usize,
) -> Wide<T, N> {
    let row = &block.norms[3 * k + d];
    Wide(crate::lanes::array(T::default(), |i| {
        T::from_f32(widen_half(row[i]))
    }))
}

/// [`Geometry`] of a block's lanes.
#[inline(always)]
pub(crate) fn geometry<T: Real, const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    at: &PointView<T>,
) -> Geometry<T, N> {
    let [px, py, pz] = at.p.map(Wide::splat);
    let [nx, ny, nz] = at.n.map(Wide::splat);
    let dx = row(block, CENTROID) - px;
    let dy = row(block, CENTROID + 1) - py;
    let dz = row(block, CENTROID + 2) - pz;
    let d2 = dx * dx + dy * dy + dz * dz;
    let dist = d2.sqrt();
    let inv_d = Wide::of(1.0) / dist;
    let uh = [dx * inv_d, dy * inv_d, dz * inv_d];
    let sigma = row(block, RADIUS) * inv_d * Wide::of(SIGMA_UP);
    let c0 = nx * uh[0] + ny * uh[1] + nz * uh[2];
    let cross = [
        ny * uh[2] - uh[1] * nz,
        nz * uh[0] - uh[2] * nx,
        nx * uh[1] - uh[0] * ny,
    ];
    let sin_c = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
    let height = nx * dx + ny * dy + nz * dz;
    let half_of = Wide::of(0.5);
    let mut middle = [Wide::of(0.0); 3];
    let mut half = [Wide::of(0.0); 3];
    for axis in 0..3 {
        let (lo, hi) = (row(block, BOX_LOW + axis), row(block, BOX_HIGH + axis));
        middle[axis] = (lo + hi) * half_of;
        half[axis] = (hi - lo) * half_of;
    }
    let box_mid = nx * middle[0] + ny * middle[1] + nz * middle[2];
    let box_reach = nx.abs() * half[0] + ny.abs() * half[1] + nz.abs() * half[2];
    let box_size =
        (middle[0].abs() + half[0]) + (middle[1].abs() + half[1]) + (middle[2].abs() + half[2]);
    let perp = [nx - c0 * uh[0], ny - c0 * uh[1], nz - c0 * uh[2]];
    let across = (perp[0] * middle[0] + perp[1] * middle[1] + perp[2] * middle[2]).abs()
        + (perp[0].abs() * half[0] + perp[1].abs() * half[1] + perp[2].abs() * half[2]);
    Geometry {
        d2,
        dist,
        inv_d,
        uh,
        sigma,
        c0,
        sin_c,
        height,
        box_mid,
        box_reach,
        box_size,
        across,
    }
}

/// The weights of the series through degree 2 that every channel shares
/// (see [`degree_two_lanes`](super::series)): the gradient `n - 3 c0 uh`
/// (times `1/D`, applied to `o_k`) and the six weights of `S_k`'s entries
/// `[xx, yy, zz, xy, xz, yz]` (times `1 / (2 D^2)`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SeriesWeights<T, const N: usize> {
    pub(crate) grad: [Wide<T, N>; 3],
    pub(crate) second: [Wide<T, N>; 6],
    pub(crate) half_inv_d2: Wide<T, N>,
}

/// [`SeriesWeights`] for the lanes' geometry.
#[inline(always)]
pub(crate) fn series_weights<T: Real, const N: usize>(
    at: &PointView<T>,
    g: &Geometry<T, N>,
) -> SeriesWeights<T, N> {
    let [nx, ny, nz] = at.n.map(Wide::splat);
    let [ux, uy, uz] = g.uh;
    let three_c0 = Wide::of(3.0) * g.c0;
    let a = Wide::of(15.0) * g.c0;
    let two_a = a + a;
    let six = Wide::of(6.0);
    SeriesWeights {
        grad: [nx - three_c0 * ux, ny - three_c0 * uy, nz - three_c0 * uz],
        second: [
            a * ux * ux - three_c0 - six * ux * nx,
            a * uy * uy - three_c0 - six * uy * ny,
            a * uz * uz - three_c0 - six * uz * nz,
            two_a * ux * uy - six * (ux * ny + uy * nx),
            two_a * ux * uz - six * (ux * nz + uz * nx),
            two_a * uy * uz - six * (uy * nz + uz * ny),
        ],
        half_inv_d2: Wide::of(0.5) * (g.inv_d * g.inv_d),
    }
}

/// The multipole series through degree 2 of channel `k`, in units of `I_k
/// / D^2` (unwidened): `c0 + (n.o - 3 c0 uh.o) / D + (15 c0 uh.S.uh - 3 c0
/// tr S - 6 uh.S.n) / (2 D^2)`.
#[inline(always)]
pub(crate) fn estimate<T: Real, const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    g: &Geometry<T, N>,
    w: &SeriesWeights<T, N>,
    k: usize,
) -> Wide<T, N> {
    let o = |a: usize| row::<T, N, R, M>(block, Block::<N, R, M>::offset_row(k, a));
    let first = (w.grad[0] * o(0) + w.grad[1] * o(1) + w.grad[2] * o(2)) * g.inv_d;
    let mut second = Wide::of(0.0);
    for (e, weight) in w.second.into_iter().enumerate() {
        second += row::<T, N, R, M>(block, Block::<N, R, M>::covariance_row(k, e)) * weight;
    }
    g.c0 + first + second * w.half_inv_d2
}

/// What the series' remainder shares between channels: the widened
/// `|c0|`, `hperp / D`, the harmonic factors `A_m` (`m = 3, 4, 5`) and the
/// tail sums `G1`, `G2` (see [`tail_sums`](super::series)).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RemainderTerms<T, const N: usize> {
    pub(crate) ac: Wide<T, N>,
    pub(crate) hperp: Wide<T, N>,
    pub(crate) harmonic: [Wide<T, N>; 3],
    pub(crate) g1: Wide<T, N>,
    pub(crate) g2: Wide<T, N>,
}

/// [`RemainderTerms`] from the widened `|c0|`, `nu^2` and `hperp / D`.
#[inline(always)]
pub(crate) fn remainder_terms<T: Real, const N: usize>(
    g: &Geometry<T, N>,
    ac: Wide<T, N>,
    nu2: Wide<T, N>,
    hperp: Wide<T, N>,
) -> RemainderTerms<T, N> {
    let sigma = g.sigma;
    let one = Wide::of(1.0);
    let inv_rho = one / (one - sigma);
    let c2 = ac * ac;
    let harmonic = |m: f64| {
        (c2 * Wide::of((m + 1.0) * (m + 1.0)) + nu2 * Wide::of(0.5 * m * (m + 1.0))).sqrt()
    };
    RemainderTerms {
        ac,
        hperp,
        harmonic: [harmonic(3.0), harmonic(4.0), harmonic(5.0)],
        g1: Wide::of(7.0) * inv_rho + sigma * inv_rho * inv_rho,
        g2: Wide::of(0.5)
            * inv_rho
            * (Wide::of(42.0) + inv_rho * sigma * (Wide::of(13.0) + (one + sigma) * inv_rho)),
    }
}

/// The series' remainder from degree 3 of channel `k`, in units of `I_k /
/// D^2` (as [`series_width`](super::series)'s, unwidened), with `mu_2 =
/// tr(S_k) / D^2`.
#[inline(always)]
pub(crate) fn remainder<T: Real, const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    g: &Geometry<T, N>,
    r: &RemainderTerms<T, N>,
    mu2: Wide<T, N>,
    k: usize,
) -> Wide<T, N> {
    let sigma = g.sigma;
    let mut total = Wide::of(0.0);
    let mut mu_prev = mu2;
    let mut sigma_m = sigma * sigma * sigma;
    for d in 0..3 {
        let m = (d + 3) as f64;
        let q = norms::<T, N, R, M>(block, k, d) * sigma_m;
        let across =
            q * (r.ac * Wide::of(m + 1.0)) + mu_prev * (r.hperp * Wide::of(0.5 * m * (m + 1.0)));
        total += (q * r.harmonic[d]).min(across);
        mu_prev *= sigma;
        sigma_m *= sigma;
    }
    let tail = mu_prev * sigma * r.g1;
    total += tail.min(tail * r.ac + mu_prev * (r.hperp * r.g2));
    total
}

/// The bounds of a block's lanes (see the module docs), each end in `f64`
/// units of radiance: the `f32` interval times `I_k kd_k / D^2`. A
/// one-colour block's channel 0 stands for the others, widened by their
/// colour spreads (module docs, *One colour*).
#[inline(always)]
pub(crate) fn lane_bounds<const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    at: &PointView<f32>,
    scales: &LaneScales<N>,
) -> LaneBounds<N> {
    let w = |x: f64| Wide::<f32, N>::of(x);
    let u = |units: f64| w(units * U);
    let zero = w(0.0);
    let one = w(1.0);
    let g = geometry(block, at);
    let sigma = g.sigma;
    let (c0, sin_c) = (g.c0, g.sin_c);

    // The paper's interval.
    let one_minus = one - sigma;
    let one_plus = one + sigma;
    let inv_rho = one / one_minus;
    let far = one / one_plus;
    let cd = (one_minus * one_plus).sqrt();
    let cos_hi = (Wide::select_ge(c0, cd, one, c0 * cd + sin_c * sigma) + u(COS)).min(one);
    let cos_lo = (c0 * cd - sin_c * sigma - u(COS)).max(-one);
    let lower_paper = cos_lo.max(zero) * far * far * (one - u(PRODUCT));
    let upper_paper = cos_hi * inv_rho * inv_rho * (one + u(PRODUCT));
    let inv_rho3 = inv_rho * inv_rho * inv_rho;

    // Heights of the box above the tangent plane.
    let slack = u(HEIGHT) * (g.dist + g.box_size);
    let highest = g.height + g.box_mid + g.box_reach + slack;
    let lowest = g.height + g.box_mid - g.box_reach - slack;
    let grow = one + u(PRODUCT);
    let box_upper = highest * g.inv_d * inv_rho3 * grow;
    let ball_depth = sigma - c0 + u(C0 + 2.0);
    let box_depth = -lowest * g.inv_d * (one + u(8.0));
    let straddle = ball_depth.min(box_depth).max(zero) * inv_rho3 * grow;
    let upper_geometric = upper_paper.min(box_upper);

    // The series, its inputs widened.
    let weights = series_weights(at, &g);
    let nu = sin_c + u(SIN);
    let terms = remainder_terms(
        &g,
        c0.abs() + u(C0),
        nu * nu,
        (g.across + u(ACROSS) * g.box_size) * g.inv_d * (one + u(8.0)),
    );
    let point = u(POINT) * inv_rho3 + w(UNDERFLOW);
    let inv_d2 = g.inv_d * g.inv_d;
    let mut lo = [zero; 3];
    let mut hi = [zero; 3];
    // Per lane, the largest `lo - hi` over the channels: positive where
    // the intervals are disjoint in some channel.
    let mut disjoint = w(f64::from(f32::MIN));
    // `x = |o_k|_1 / D` enters only the slacks: every member lies within
    // `R` of the centroid, so the stored offsets have `|o_k| <= R (1 +
    // delta) (1 + u)` and `x <= sqrt(3) (1 + delta + u) sigma`, at most
    // `1.75 sigma` for any build rounding `delta` below 1% (it is about
    // `1e-12`).
    let x = w(1.75) * sigma;
    for k in 0..Block::<N, R, M>::CHANNELS {
        let e = estimate(block, &g, &weights, k);
        let s = |e: usize| row::<f32, N, R, M>(block, Block::<N, R, M>::covariance_row(k, e));
        // The stored diagonal entries are at least 0 (rounded upward).
        let trace = s(0) + s(1) + s(2);
        let entries = trace + s(3).abs() + s(4).abs() + s(5).abs();
        let mu2 = trace * inv_d2;
        let y = entries * inv_d2;
        let rest = remainder(block, &g, &terms, mu2, k);
        let width = rest * (one + u(REMAINDER))
            + u(ESTIMATE[0])
            + u(ESTIMATE[1]) * x
            + u(ESTIMATE[2]) * y
            + u(STORAGE) * (x + w(33.0) * mu2)
            + w(UNDERFLOW);
        lo[k] = lower_paper.max(e - width);
        hi[k] = upper_geometric.min(e + width + straddle);
        disjoint = disjoint.max(lo[k] - hi[k]);
    }

    to_radiance(
        block,
        scales,
        &Unscaled {
            lo,
            hi,
            lower_paper,
            upper_paper,
            disjoint,
            point,
            sigma,
            d2: g.d2,
            cos_hi,
            highest,
            lowest,
        },
    )
}

/// A block's `f32` intervals in units of `I_k kd_k / D^2`, with what
/// [`to_radiance`] needs of the geometry.
struct Unscaled<const N: usize> {
    lo: [Wide<f32, N>; 3],
    hi: [Wide<f32, N>; 3],
    lower_paper: Wide<f32, N>,
    upper_paper: Wide<f32, N>,
    /// Per lane, the largest `lo - hi` over the channels.
    disjoint: Wide<f32, N>,
    /// The point's allowance.
    point: Wide<f32, N>,
    sigma: Wide<f32, N>,
    d2: Wide<f32, N>,
    cos_hi: Wide<f32, N>,
    highest: Wide<f32, N>,
    lowest: Wide<f32, N>,
}

/// The second half of [`lane_bounds`]: the intervals `u` in `f64` units of
/// radiance, with the point's and the moments' allowances.
#[inline(always)]
fn to_radiance<const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    scales: &LaneScales<N>,
    u: &Unscaled<N>,
) -> LaneBounds<N> {
    let zero = Wide::<f32, N>::of(0.0);
    let Unscaled {
        lo,
        hi,
        lower_paper,
        upper_paper,
        disjoint,
        point,
        sigma,
        d2,
        cos_hi,
        highest,
        lowest,
    } = *u;
    // In f64: the scale, and the build's rounding of the moments' sums
    // (`2 delta (sigma + 18 sigma^2)`, as in the f64 bound).
    let sigma64 = sigma.widen();
    let delta = Wide(scales.moment_error);
    let sums = Wide::of(2.0) * delta * sigma64 * (Wide::of(1.0) + Wide::of(18.0) * sigma64);
    let inv_d2_64 = Wide::of(1.0) / d2.widen();
    let (down, up) = (Wide::of(1.0 - SCALE * U), Wide::of(1.0 + SCALE * U));
    let point64 = point.widen();
    let mut lower = [[0.0; N]; 3];
    let mut upper = [[0.0; N]; 3];
    let mut estimate = [[0.0; N]; 3];
    // Per stored channel, the interval's ends in units with the point's
    // and the moments' allowances. Both intervals contain the exact value;
    // if rounding beyond the allowances ever made them disjoint, the
    // paper's holds.
    let mut ends = [(Wide::of(0.0), Wide::of(0.0)); 3];
    for (c, ends) in ends.iter_mut().enumerate().take(Block::<N, R, M>::CHANNELS) {
        let a = Wide::select_ge(zero, disjoint, lo[c], lower_paper).widen();
        let b = Wide::select_ge(zero, disjoint, hi[c], upper_paper).widen();
        *ends = (a - point64 - sums, b + point64 + sums);
    }
    for k in 0..3 {
        // A one-colour block's channel 0 stands for the others.
        let c = k.min(Block::<N, R, M>::CHANNELS - 1);
        let (a, b) = ends[c];
        let scale = Wide(scales.intensity[k]) * inv_d2_64;
        let (l, h) = if c == k {
            (a * scale * down, b * scale * up)
        } else {
            // Channel 0's interval, divided and multiplied by the colour's
            // spread (exactly 1 for white lights: the same bits as above).
            let spread = row::<f32, N, R, M>(block, Block::<N, R, M>::spread_row(k)).widen();
            (a * scale / spread * down, b * scale * spread * up)
        };
        let l = l.max(Wide::of(0.0));
        lower[k] = l.0;
        upper[k] = h.0;
        estimate[k] = (Wide::of(0.5) * (l + h)).0;
    }
    LaneBounds {
        lower,
        upper,
        estimate,
        d2: d2.0,
        sigma: sigma.0,
        cos_hi: cos_hi.0,
        highest: highest.0,
        lowest: lowest.0,
    }
}

#[cfg(test)]
#[path = "group_tests.rs"]
mod tests;
