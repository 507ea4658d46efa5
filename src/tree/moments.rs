//! Cartesian moments of degree at most 5, merged bottom-up with a certified
//! error bound: what makes the build linear.
//!
//! A node's statistics (first and second moments, harmonic norms of degrees
//! 3 to 5) are moments of its members about its centroid. Computing them
//! from the members at every level costs `O(n * depth)`; here each leaf sums
//! its lights once, and every other node *shifts* its children's moments to
//! its own centroid, exactly in real arithmetic:
//!
//! ```text
//! (y + t)^a / a! = sum_(b + d = a) (y^b / b!) (t^d / d!)
//! ```
//!
//! for multi-indices `a`, `b`, `d` (`y^a = y_x^a_x y_y^a_y y_z^a_z`,
//! `a! = a_x! a_y! a_z!`). The moments are kept divided by `a!`, so a shift
//! is a product of truncated polynomials, done one axis at a time.
//!
//! # Error bound
//! Per channel `k` and degree `l`, alongside the moments
//! `m_a = sum_i I_ik y_i^a / a!` the build carries two upper bounds:
//!
//! * `abs_l >= sum_i I_ik |y_i|_1^l / l!` (1-norm), which by the multinomial
//!   theorem is `sum_(|a| = l) sum_i I_ik |y_i^a| / a!`;
//! * `err_l >= sum_(|a| = l) |computed m_a - exact m_a|`.
//!
//! With `w_j = tau^j / j!`, `tau >= |t|_1`, the multinomial theorem gives
//! `sum_(|d| = j) |t^d| / d! = w_j`, so a shift maps both bounds through the
//! same triangular kernel: the exact shift of the computed moments is off by
//! at most `sum_k w_(l-k) err_k`, and `|y + t|_1 <= |y|_1 + tau` gives
//! `abs'_l <= sum_k w_(l-k) abs_k`. Rounding: each shifted moment is a sum of
//! products `T_d m_b`. The powers `t^j / j!` take four roundings a step
//! (the difference of two `f32` values behind `t`, the product with `t`,
//! the rounded `1 / j` and the product with it), at most 20 for degree 5;
//! the three one-axis stages add three products and at most five
//! additions each, and at most eight children seven more: at most about 46
//! roundings, so the computed sum is within `46 * 2^-53` of the sum of the
//! terms' magnitudes, at most `sum_k w_(l-k) (abs_k + err_k)`;
//! [`SHIFT_SLACK`] (`2^7 f64::EPSILON = 256 * 2^-53`) covers that with a
//! factor five. A leaf's direct sums: each term `I_ik y^a / a!` takes at
//! most 23 roundings (20 for the powers, two products, the intensity), and
//! the recursive sum of `n` terms `n - 1` more, so
//! `err_l = (n + 64) f64::EPSILON abs_l` covers them with a factor two.
//! The sums' multiply-adds are fused (`f64::mul_add`, one rounding where
//! the count above allows two), so these counts are upper bounds.
//!
//! Light coordinates and intensities are `f32` values, so every moment a
//! node stores is far inside `f64`'s normal range (its harmonic norms are
//! scaled by `1 / (I_k R^l)` before they are squared). Products that
//! underflow in the bounds' own arithmetic move them by at most `2^-1074`
//! each, negligible against the absolute padding of the stored norms.

use core::ops::{Add, Mul, Sub};
use std::sync::LazyLock;

use glam::{DVec3, Vec3};

use super::build::{HARMONIC_COUNT, HARMONIC_NORM_SQ, harmonic_offset, solid_harmonics_of};
use crate::PointLight;
use crate::numeric::{BUILD_LENGTH_SLACK, HARMONIC_BUILD_PAD, round_up_f32};

/// Highest degree kept.
const DEGREE: usize = 5;

/// Monomials `y^a` of degree at most 5 in three variables.
pub(crate) const MONOMIALS: usize = 56;

/// Index of the first monomial of each degree `l` (and the count, at `l = 6`).
#[cfg(test)]
const DEGREE_START: [usize; DEGREE + 2] = [0, 1, 4, 10, 20, 35, 56];

/// Exponents of each monomial, by degree, then `a_x` and `a_y` decreasing.
const EXPONENTS: [[usize; 3]; MONOMIALS] = {
    let mut out = [[0; 3]; MONOMIALS];
    let mut n = 0;
    let mut l = 0;
    while l <= DEGREE {
        let mut i = l as isize;
        while i >= 0 {
            let mut j = (l as isize) - i;
            while j >= 0 {
                out[n] = [i as usize, j as usize, l - i as usize - j as usize];
                n += 1;
                j -= 1;
            }
            i -= 1;
        }
        l += 1;
    }
    out
};

/// Index of the monomial of exponents `[i][j][k]` (`usize::MAX` above
/// degree 5).
const INDEX: [[[usize; DEGREE + 1]; DEGREE + 1]; DEGREE + 1] = {
    let mut out = [[[usize::MAX; DEGREE + 1]; DEGREE + 1]; DEGREE + 1];
    let mut n = 0;
    while n < MONOMIALS {
        let [i, j, k] = EXPONENTS[n];
        out[i][j][k] = n;
        n += 1;
    }
    out
};

/// Writes the 56 products `px[a_x] py[a_y] pz[a_z]`, lane by lane, into
/// `out` in the order of [`EXPONENTS`] (straight-line code, which lets the
/// compiler share the products `px[a_x] py[a_y]` and skip the factors 1).
macro_rules! monomial_values {
    ($out:expr, $px:ident, $py:ident, $pz:ident) => {
        monomial_values!(@ $out, $px, $py, $pz; (0, 0, 0, 0), (1, 1, 0, 0), (2, 0, 1, 0), (3, 0, 0, 1), (4, 2, 0, 0), (5, 1, 1, 0), (6, 1, 0, 1), (7, 0, 2, 0), (8, 0, 1, 1), (9, 0, 0, 2), (10, 3, 0, 0), (11, 2, 1, 0), (12, 2, 0, 1), (13, 1, 2, 0), (14, 1, 1, 1), (15, 1, 0, 2), (16, 0, 3, 0), (17, 0, 2, 1), (18, 0, 1, 2), (19, 0, 0, 3), (20, 4, 0, 0), (21, 3, 1, 0), (22, 3, 0, 1), (23, 2, 2, 0), (24, 2, 1, 1), (25, 2, 0, 2), (26, 1, 3, 0), (27, 1, 2, 1), (28, 1, 1, 2), (29, 1, 0, 3), (30, 0, 4, 0), (31, 0, 3, 1), (32, 0, 2, 2), (33, 0, 1, 3), (34, 0, 0, 4), (35, 5, 0, 0), (36, 4, 1, 0), (37, 4, 0, 1), (38, 3, 2, 0), (39, 3, 1, 1), (40, 3, 0, 2), (41, 2, 3, 0), (42, 2, 2, 1), (43, 2, 1, 2), (44, 2, 0, 3), (45, 1, 4, 0), (46, 1, 3, 1), (47, 1, 2, 2), (48, 1, 1, 3), (49, 1, 0, 4), (50, 0, 5, 0), (51, 0, 4, 1), (52, 0, 3, 2), (53, 0, 2, 3), (54, 0, 1, 4), (55, 0, 0, 5))
    };
    (@ $out:expr, $px:ident, $py:ident, $pz:ident; $(($n:literal, $a:literal, $b:literal, $c:literal)),*) => {
        $($out[$n] = product(&$px[$a], &$py[$b], &$pz[$c]);)*
    };
}

/// Lights a leaf's sums take side by side.
const LIGHT_LANES: usize = 4;

type LightLanes = [f64; LIGHT_LANES];

/// `a b c`, lane by lane.
#[inline(always)]
fn product(a: &LightLanes, b: &LightLanes, c: &LightLanes) -> LightLanes {
    let mut out = [0.0; LIGHT_LANES];
    for k in 0..LIGHT_LANES {
        out[k] = a[k] * b[k] * c[k];
    }
    out
}

/// [`scaled_powers`] lane by lane.
#[inline(always)]
fn scaled_power_lanes(x: &LightLanes) -> [LightLanes; DEGREE + 1] {
    let mut out = [[1.0; LIGHT_LANES]; DEGREE + 1];
    for p in 1..=DEGREE {
        for k in 0..LIGHT_LANES {
            out[p][k] = out[p - 1][k] * x[k] * RECIPROCALS[p];
        }
    }
    out
}

/// `acc[ch] += v * i[ch]` per channel, lane by lane.
#[inline(always)]
fn add_products(acc: &mut [LightLanes; 3], v: &LightLanes, i: &[LightLanes; 3]) {
    for (acc, i) in acc.iter_mut().zip(i) {
        for k in 0..LIGHT_LANES {
            acc[k] = v[k].mul_add(i[k], acc[k]);
        }
    }
}

/// Per channel, its lanes' sum, pairwise (`(l0 + l1) + (l2 + l3)`), and
/// 0 in the spare lane: written as sums of the transposed lanes, so that
/// the additions are vertical.
#[inline(always)]
fn lane_sums(x: &[LightLanes; 3]) -> Lanes {
    let lane = |l: usize| [x[0][l], x[1][l], x[2][l], 0.0];
    let add = |a: Lanes, b: Lanes| [a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]];
    add(add(lane(0), lane(1)), add(lane(2), lane(3)))
}

/// Chunks of [`LIGHT_LANES`] lights whose terms a leaf's sums prepare at
/// once.
const BLOCK_CHUNKS: usize = 8;

/// Sums a pass over a block's chunks takes side by side (their
/// accumulators in registers).
const GROUP: usize = 4;

/// Sums a leaf carries per lane: the moments, then the scaled powers of
/// the 1-norms (for the bounds), then two that stay 0, so that the sums
/// come in whole groups.
const SUMS: usize = 64;

/// Where the powers of the 1-norms start among the sums.
const NORMS: usize = MONOMIALS;

/// Per channel, one sum's lanes.
type Accumulator = [LightLanes; 3];

/// One chunk's lanes: the values it adds to each sum (the monomials `y^a /
/// a!` of its offsets, the scaled powers of their 1-norms) and its
/// intensities. Padded lanes are at the centre, dark.
#[derive(Clone, Copy)]
struct ChunkTerms {
    values: [LightLanes; SUMS],
    intensity: [LightLanes; 3],
}

impl ChunkTerms {
    const ZERO: Self = Self {
        values: [[0.0; LIGHT_LANES]; SUMS],
        intensity: [[0.0; LIGHT_LANES]; 3],
    };

    /// Sets these to the terms of `chunk` (at most [`LIGHT_LANES`] lights)
    /// about `centre`; returns the largest of 0 and the lights' squared
    /// distances from `centre`, each computed in `f64` as `(x - c) . (x -
    /// c)` from the offsets the terms use.
    #[inline(always)]
    fn set(&mut self, chunk: &[PointLight], centre: DVec3) -> f64 {
        let mut y = [[0.0; LIGHT_LANES]; 3];
        let mut intensity = [[0.0; LIGHT_LANES]; 3];
        for (k, l) in chunk.iter().enumerate() {
            let offset = (l.position.as_dvec3() - centre).to_array();
            let i = l.intensity.as_dvec3().to_array();
            for axis in 0..3 {
                y[axis][k] = offset[axis];
                intensity[axis][k] = i[axis];
            }
        }
        let (px, py, pz) = (
            scaled_power_lanes(&y[0]),
            scaled_power_lanes(&y[1]),
            scaled_power_lanes(&y[2]),
        );
        monomial_values!(self.values, px, py, pz);
        let mut norm = [0.0; LIGHT_LANES];
        for k in 0..LIGHT_LANES {
            norm[k] = y[0][k].abs() + y[1][k].abs() + y[2][k].abs();
        }
        self.values[NORMS..NORMS + DEGREE + 1].copy_from_slice(&scaled_power_lanes(&norm));
        self.intensity = intensity;
        // The padded lanes' offsets are 0. A maximum is exact, so the
        // lanes' order does not matter; no distance is NaN or -0.
        let mut farthest = 0.0f64;
        for ((x, y), z) in y[0].iter().zip(&y[1]).zip(&y[2]) {
            let d2 = x * x + y * y + z * z;
            farthest = if d2 > farthest { d2 } else { farthest };
        }
        farthest
    }
}

/// Room for one block of a leaf's chunk terms, and for the accumulators
/// carried from block to block in leaves of more than one block, kept from
/// leaf to leaf.
pub(crate) struct LeafScratch {
    terms: Vec<ChunkTerms>,
    carry: Vec<Accumulator>,
}

impl LeafScratch {
    pub(crate) fn new() -> Self {
        Self {
            terms: Vec::new(),
            carry: Vec::new(),
        }
    }

    /// The terms of `lights` (at most [`BLOCK_CHUNKS`] chunks) about
    /// `centre`, room for the carried accumulators, and the lights' largest
    /// squared distance from `centre` (see [`ChunkTerms::set`]).
    #[inline(always)]
    fn block(
        &mut self,
        lights: &[PointLight],
        centre: DVec3,
    ) -> (&[ChunkTerms], &mut [Accumulator], f64) {
        let chunks = lights.len().div_ceil(LIGHT_LANES);
        if self.terms.len() < chunks {
            self.terms.resize(chunks, ChunkTerms::ZERO);
        }
        let mut farthest = 0.0f64;
        for (terms, chunk) in self.terms.iter_mut().zip(lights.chunks(LIGHT_LANES)) {
            farthest = farthest.max(terms.set(chunk, centre));
        }
        if self.carry.len() < SUMS {
            self.carry.resize(SUMS, [[0.0; LIGHT_LANES]; 3]);
        }
        (&self.terms[..chunks], &mut self.carry, farthest)
    }
}

/// Per axis, the steps of a shift along it: `(target, source, power)` with
/// `m[target] += t^power / power! * m[source]`, the source being the target
/// with `power` fewer along the axis; targets by decreasing index, so that
/// in place every source is read before it is shifted itself. The shifts
/// themselves run the lists of [`shift_steps`], which a test compares with
/// this table.
#[cfg(test)]
const SHIFT_STEPS: [[(u8, u8, u8); 70]; 3] = {
    let mut out = [[(0u8, 0u8, 0u8); 70]; 3];
    let mut axis = 0;
    while axis < 3 {
        let mut k = 0;
        let mut n = MONOMIALS;
        while n > 0 {
            n -= 1;
            let e = EXPONENTS[n];
            let mut p = 0;
            while p < e[axis] {
                let mut src = e;
                src[axis] = p;
                out[axis][k] = (
                    n as u8,
                    INDEX[src[0]][src[1]][src[2]] as u8,
                    (e[axis] - p) as u8,
                );
                k += 1;
                p += 1;
            }
        }
        assert!(k == 70);
        axis += 1;
    }
    out
};

/// A shift along one axis as straight-line code (the indices constants):
/// per step `(target, source, power)`, `m[target] += t^power / power! *
/// m[source]`, the source being the target with `power` fewer along the
/// axis; targets by decreasing index, so that in place every source is read
/// before it is shifted itself (a test checks the lists against a table
/// built from that rule).
macro_rules! shift_steps {
    ($name:ident, $table:ident: $(($t:literal, $s:literal, $p:literal)),*) => {
        /// One axis's steps, `w` the scaled powers of the offset along it.
        #[inline(always)]
        fn $name(m: &mut [Lanes; MONOMIALS], w: &[f64; DEGREE + 1]) {
            $({
                let from = m[$s];
                mul_add(&mut m[$t], &from, w[$p]);
            })*
        }
        #[cfg(test)]
        const $table: [(u8, u8, u8); 70] = [$(($t, $s, $p)),*];
    };
}

shift_steps!(shift_along_x, SHIFT_X:
    (49, 34, 1), (48, 33, 1), (47, 32, 1), (46, 31, 1), (45, 30, 1), (44, 19, 2), (44, 29, 1),
    (43, 18, 2), (43, 28, 1), (42, 17, 2), (42, 27, 1), (41, 16, 2), (41, 26, 1), (40, 9, 3),
    (40, 15, 2), (40, 25, 1), (39, 8, 3), (39, 14, 2), (39, 24, 1), (38, 7, 3), (38, 13, 2),
    (38, 23, 1), (37, 3, 4), (37, 6, 3), (37, 12, 2), (37, 22, 1), (36, 2, 4), (36, 5, 3),
    (36, 11, 2), (36, 21, 1), (35, 0, 5), (35, 1, 4), (35, 4, 3), (35, 10, 2), (35, 20, 1),
    (29, 19, 1), (28, 18, 1), (27, 17, 1), (26, 16, 1), (25, 9, 2), (25, 15, 1), (24, 8, 2),
    (24, 14, 1), (23, 7, 2), (23, 13, 1), (22, 3, 3), (22, 6, 2), (22, 12, 1), (21, 2, 3),
    (21, 5, 2), (21, 11, 1), (20, 0, 4), (20, 1, 3), (20, 4, 2), (20, 10, 1), (15, 9, 1),
    (14, 8, 1), (13, 7, 1), (12, 3, 2), (12, 6, 1), (11, 2, 2), (11, 5, 1), (10, 0, 3),
    (10, 1, 2), (10, 4, 1), (6, 3, 1), (5, 2, 1), (4, 0, 2), (4, 1, 1), (1, 0, 1)
);

shift_steps!(shift_along_y, SHIFT_Y:
    (54, 34, 1), (53, 19, 2), (53, 33, 1), (52, 9, 3), (52, 18, 2), (52, 32, 1), (51, 3, 4),
    (51, 8, 3), (51, 17, 2), (51, 31, 1), (50, 0, 5), (50, 2, 4), (50, 7, 3), (50, 16, 2),
    (50, 30, 1), (48, 29, 1), (47, 15, 2), (47, 28, 1), (46, 6, 3), (46, 14, 2), (46, 27, 1),
    (45, 1, 4), (45, 5, 3), (45, 13, 2), (45, 26, 1), (43, 25, 1), (42, 12, 2), (42, 24, 1),
    (41, 4, 3), (41, 11, 2), (41, 23, 1), (39, 22, 1), (38, 10, 2), (38, 21, 1), (36, 20, 1),
    (33, 19, 1), (32, 9, 2), (32, 18, 1), (31, 3, 3), (31, 8, 2), (31, 17, 1), (30, 0, 4),
    (30, 2, 3), (30, 7, 2), (30, 16, 1), (28, 15, 1), (27, 6, 2), (27, 14, 1), (26, 1, 3),
    (26, 5, 2), (26, 13, 1), (24, 12, 1), (23, 4, 2), (23, 11, 1), (21, 10, 1), (18, 9, 1),
    (17, 3, 2), (17, 8, 1), (16, 0, 3), (16, 2, 2), (16, 7, 1), (14, 6, 1), (13, 1, 2),
    (13, 5, 1), (11, 4, 1), (8, 3, 1), (7, 0, 2), (7, 2, 1), (5, 1, 1), (2, 0, 1)
);

shift_steps!(shift_along_z, SHIFT_Z:
    (55, 0, 5), (55, 3, 4), (55, 9, 3), (55, 19, 2), (55, 34, 1), (54, 2, 4), (54, 8, 3),
    (54, 18, 2), (54, 33, 1), (53, 7, 3), (53, 17, 2), (53, 32, 1), (52, 16, 2), (52, 31, 1),
    (51, 30, 1), (49, 1, 4), (49, 6, 3), (49, 15, 2), (49, 29, 1), (48, 5, 3), (48, 14, 2),
    (48, 28, 1), (47, 13, 2), (47, 27, 1), (46, 26, 1), (44, 4, 3), (44, 12, 2), (44, 25, 1),
    (43, 11, 2), (43, 24, 1), (42, 23, 1), (40, 10, 2), (40, 22, 1), (39, 21, 1), (37, 20, 1),
    (34, 0, 4), (34, 3, 3), (34, 9, 2), (34, 19, 1), (33, 2, 3), (33, 8, 2), (33, 18, 1),
    (32, 7, 2), (32, 17, 1), (31, 16, 1), (29, 1, 3), (29, 6, 2), (29, 15, 1), (28, 5, 2),
    (28, 14, 1), (27, 13, 1), (25, 4, 2), (25, 12, 1), (24, 11, 1), (22, 10, 1), (19, 0, 3),
    (19, 3, 2), (19, 9, 1), (18, 2, 2), (18, 8, 1), (17, 7, 1), (15, 1, 2), (15, 6, 1),
    (14, 5, 1), (12, 4, 1), (9, 0, 2), (9, 3, 1), (8, 2, 1), (6, 1, 1), (3, 0, 1)
);

/// Relative rounding allowance of one shift (see the module docs).
const SHIFT_SLACK: f64 = 128.0 * f64::EPSILON;

/// Four lanes: the three channels and a spare, so that channel loops
/// vectorise.
type Lanes = [f64; 4];

const ZERO: Lanes = [0.0; 4];

#[inline(always)]
fn mul_add(acc: &mut Lanes, a: &Lanes, s: f64) {
    for (x, y) in acc.iter_mut().zip(a) {
        *x = y.mul_add(s, *x);
    }
}

/// A node's moments about a centre, per channel in lanes 0 to 2, with
/// their bounds (module docs).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Moments {
    /// `sum_i I_ik y_i^a / a!` per monomial `a`.
    m: [Lanes; MONOMIALS],
    /// Per degree: upper bound on `sum_i I_ik |y_i|_1^l / l!`.
    abs: [Lanes; DEGREE + 1],
    /// Per degree: upper bound on the summed errors of the degree's moments.
    err: [Lanes; DEGREE + 1],
}

/// `1 / p`, rounded.
const RECIPROCALS: [f64; DEGREE + 1] = [1.0, 1.0, 0.5, 1.0 / 3.0, 0.25, 0.2];

/// `x^p / p!` for `p = 0..=5`, each step one product with `x` and one
/// with a rounded `1 / p` (no division).
#[inline(always)]
fn scaled_powers(x: f64) -> [f64; DEGREE + 1] {
    let mut out = [1.0; DEGREE + 1];
    for p in 1..=DEGREE {
        out[p] = out[p - 1] * x * RECIPROCALS[p];
    }
    out
}

impl Moments {
    pub(crate) const ZERO: Self = Self {
        m: [ZERO; MONOMIALS],
        abs: [ZERO; DEGREE + 1],
        err: [ZERO; DEGREE + 1],
    };

    /// The moments of `lights` about `centre`, summed directly.
    #[cfg(test)]
    pub(crate) fn of_lights(lights: &[PointLight], centre: DVec3) -> Self {
        let mut out = Self::ZERO;
        let _ = out.set_to_lights(lights, centre, &mut LeafScratch::new());
        out
    }

    /// Sets these to the moments of `lights` about `centre`, summed
    /// directly: [`LIGHT_LANES`] lights side by side, each lane summing its
    /// lights' terms in order, the lanes added pairwise at the end (a sum
    /// of `n` terms in any order rounds each term at most `n - 1` times;
    /// the padded lanes add exact zeros).
    ///
    /// The lights are taken a block of [`BLOCK_CHUNKS`] chunks at a time:
    /// the chunks' terms first (into `scratch`), then [`GROUP`] sums at a
    /// time over the block's chunks, their accumulators in registers
    /// rather than in memory. Each sum still takes its terms in the
    /// lights' order, so the order of the sums changes no bit.
    ///
    /// Returns the largest of 0 and the lights' squared distances from
    /// `centre`, each computed in `f64` as `(x - c) . (x - c)` (a node's
    /// radius, read off the offsets the terms use rather than in a pass of
    /// its own).
    #[inline(always)]
    pub(crate) fn set_to_lights(
        &mut self,
        lights: &[PointLight],
        centre: DVec3,
        scratch: &mut LeafScratch,
    ) -> f64 {
        const BLOCK: usize = BLOCK_CHUNKS * LIGHT_LANES;
        let blocks = lights.len().div_ceil(BLOCK);
        let mut farthest = 0.0f64;
        for (k, block) in lights.chunks(BLOCK).enumerate() {
            let (terms, carry, far) = scratch.block(block, centre);
            farthest = farthest.max(far);
            self.sum_block(terms, carry, k == 0, k + 1 == blocks);
        }
        if lights.is_empty() {
            self.sum_block(&[], &mut [], true, true);
        }
        let slack = (lights.len() as f64 + 64.0) * f64::EPSILON;
        for (a, e) in self.abs.iter_mut().zip(self.err.iter_mut()) {
            for (a, e) in a.iter_mut().zip(e.iter_mut()) {
                *a *= 1.0 + slack;
                *e = *a * slack;
            }
        }
        farthest
    }

    /// Adds one block's chunks to the accumulators of the sums: from 0 if
    /// `first`, else from `carry`; into `carry` unless `last`, when their
    /// lanes' sums go into `self.m` and `self.abs`.
    // Calling the AVX2 copy is one of the crate's unsafe blocks (see
    // `dispatch`).
    #[allow(unsafe_code)]
    #[inline(always)]
    fn sum_block(
        &mut self,
        terms: &[ChunkTerms],
        carry: &mut [Accumulator],
        first: bool,
        last: bool,
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::dispatch::avx2_fma() {
                // SAFETY: the processor has AVX2 and FMA
                // (`dispatch::avx2_fma` checked).
                unsafe { self.sum_block_avx2(terms, carry, first, last) };
                return;
            }
        }
        for start in (0..SUMS).step_by(GROUP) {
            let mut acc = [[[0.0; LIGHT_LANES]; 3]; GROUP];
            if !first {
                acc.copy_from_slice(&carry[start..start + GROUP]);
            }
            for t in terms {
                for (acc, v) in acc.iter_mut().zip(&t.values[start..start + GROUP]) {
                    add_products(acc, v, &t.intensity);
                }
            }
            if !last {
                carry[start..start + GROUP].copy_from_slice(&acc);
                continue;
            }
            for (s, acc) in (start..).zip(&acc) {
                if s < NORMS {
                    self.m[s] = lane_sums(acc);
                } else if s < NORMS + DEGREE + 1 {
                    self.abs[s - NORMS] = lane_sums(acc);
                }
            }
        }
    }

    /// [`sum_block`](Self::sum_block) with AVX2 and FMA instructions: the
    /// same fused multiply-adds lane by lane, and the lanes' sums as
    /// `(l0 + l1) + (l2 + l3)` by horizontal additions, so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn sum_block_avx2(
        &mut self,
        terms: &[ChunkTerms],
        carry: &mut [Accumulator],
        first: bool,
        last: bool,
    ) {
        use crate::dispatch::lane_of;
        use core::arch::x86_64::{
            __m256d, _mm256_add_pd, _mm256_fmadd_pd, _mm256_hadd_pd, _mm256_permute2f128_pd,
            _mm256_set_pd, _mm256_setzero_pd,
        };
        let load = |a: &LightLanes| _mm256_set_pd(a[3], a[2], a[1], a[0]);
        let lanes = |v: __m256d| [lane_of(v, 0), lane_of(v, 1), lane_of(v, 2), lane_of(v, 3)];
        let zero = _mm256_setzero_pd();
        for start in (0..SUMS).step_by(GROUP) {
            let mut acc = [[zero; 3]; GROUP];
            if !first {
                for (acc, carried) in acc.iter_mut().zip(&carry[start..start + GROUP]) {
                    *acc = carried.map(|c| load(&c));
                }
            }
            for t in terms {
                let [i0, i1, i2] = t.intensity.map(|i| load(&i));
                for (acc, v) in acc.iter_mut().zip(&t.values[start..start + GROUP]) {
                    let v = load(v);
                    acc[0] = _mm256_fmadd_pd(v, i0, acc[0]);
                    acc[1] = _mm256_fmadd_pd(v, i1, acc[1]);
                    acc[2] = _mm256_fmadd_pd(v, i2, acc[2]);
                }
            }
            if !last {
                for (carried, acc) in carry[start..start + GROUP].iter_mut().zip(&acc) {
                    *carried = acc.map(lanes);
                }
                continue;
            }
            for (s, [c0, c1, c2]) in (start..).zip(acc) {
                if s > NORMS + DEGREE {
                    break;
                }
                // (c0 l0 + c0 l1, c1 l0 + c1 l1, c0 l2 + c0 l3, c1 l2 + c1 l3)
                // and (c2 l0 + c2 l1, 0, c2 l2 + c2 l3, 0): their halves added.
                let (a, b) = (_mm256_hadd_pd(c0, c1), _mm256_hadd_pd(c2, zero));
                let sum = _mm256_add_pd(
                    _mm256_permute2f128_pd::<0x20>(a, b),
                    _mm256_permute2f128_pd::<0x31>(a, b),
                );
                if s < NORMS {
                    self.m[s] = lanes(sum);
                } else {
                    self.abs[s - NORMS] = lanes(sum);
                }
            }
        }
    }

    /// Adds these moments, taken about a centre `c'`, shifted to a centre
    /// `c` with `t = c' - c` (so `x - c = (x - c') + t`), into `sum`; the
    /// moments themselves are left shifted, their bounds unchanged.
    #[inline(always)]
    pub(crate) fn shift_into(&mut self, t: DVec3, sum: &mut Self) {
        self.shift::<true>(t, sum);
    }

    /// [`shift_into`](Self::shift_into) a sum of zeros: sets `sum` to these
    /// moments shifted, with their bounds through the kernel, without
    /// clearing it first (a node's first child). The same bits as clearing
    /// `sum` and adding: every moment and bound is a sum of terms that
    /// starts from `+0`, so it is never `-0` (a rounded sum is `-0` only
    /// when both its terms are), and `+0 + x` is `x` for any other `x`.
    #[inline(always)]
    pub(crate) fn shift_to(&mut self, t: DVec3, sum: &mut Self) {
        self.shift::<false>(t, sum);
    }

    /// [`shift_into`](Self::shift_into) if `ADD`, else
    /// [`shift_to`](Self::shift_to).
    #[inline(always)]
    fn shift<const ADD: bool>(&mut self, t: DVec3, sum: &mut Self) {
        let m = &mut self.m;
        for (axis, tv) in t.to_array().into_iter().enumerate() {
            if tv == 0.0 {
                continue;
            }
            let w = scaled_powers(tv);
            match axis {
                0 => shift_along_x(m, &w),
                1 => shift_along_y(m, &w),
                _ => shift_along_z(m, &w),
            }
        }
        if ADD {
            for (acc, v) in sum.m.iter_mut().zip(m.iter()) {
                for (a, b) in acc.iter_mut().zip(v) {
                    *a += b;
                }
            }
        } else {
            sum.m = *m;
        }
        // The bounds through the kernel w_j = tau^j / j!.
        let tau = (t.x.abs() + t.y.abs() + t.z.abs()) * (1.0 + 4.0 * f64::EPSILON);
        let w = scaled_powers(tau);
        let grow = 1.0 + SHIFT_SLACK;
        for l in 0..=DEGREE {
            let mut abs = ZERO;
            let mut err = ZERO;
            for k in 0..=l {
                mul_add(&mut abs, &self.abs[k], w[l - k]);
                let mut e = self.err[k];
                mul_add(&mut e, &self.abs[k], SHIFT_SLACK);
                mul_add(&mut err, &e, w[l - k]);
            }
            for ch in 0..4 {
                let (abs, err) = (abs[ch] * grow * grow, err[ch] * grow * grow);
                if ADD {
                    sum.abs[l][ch] += abs;
                    sum.err[l][ch] += err;
                } else {
                    (sum.abs[l][ch], sum.err[l][ch]) = (abs, err);
                }
            }
        }
    }

    /// The node statistics the moments give, for a node of `lights`
    /// members, channel intensities `intensity` and stored radius `radius`
    /// (the moments being about its stored centroid).
    #[inline(always)]
    pub(crate) fn statistics(&self, intensity: DVec3, radius: f32, lights: usize) -> Statistics {
        let r = f64::from(radius);
        let mut out = Statistics {
            offsets: [Vec3::ZERO; 3],
            covariances: [[0.0; 6]; 3],
            harmonic_norms: [Vec3::ZERO; 3],
            moment_error: 0.0,
        };
        let grow = 1.0 + SHIFT_SLACK;
        let mut relative_error = 0.0f64;
        let tables = &*HARMONIC_TABLES;
        let pad = 2.0 * (lights as f64 + HARMONIC_BUILD_PAD) * f64::EPSILON;
        // Per degree 3 to 5, the harmonic moments (unscaled).
        let mut harmonics = [[ZERO; 11]; 3];
        // Per degree, `1 / (I_k R^l)` and the squared norm of the scaled
        // harmonic moments, the channels side by side (a channel without
        // intensity, and the spare lane, are computed and never used).
        let mut scales = [ZERO; 3];
        let mut squares = [ZERO; 3];
        if r > 0.0 {
            harmonic_moments(&self.m, &tables.weights, &mut harmonics);
            let mut power = [0.0; 4];
            for ch in 0..3 {
                power[ch] = intensity[ch] * r * r;
            }
            for ((degree, scale), square) in harmonics.iter().zip(&mut scales).zip(&mut squares) {
                for ch in 0..4 {
                    power[ch] *= r;
                    // 1 / (I_k R^l), with a few roundings that `grow`
                    // covers; applied before squaring, which could
                    // underflow.
                    scale[ch] = 1.0 / power[ch];
                }
                *square = [-0.0; 4];
                for row in degree {
                    for ch in 0..4 {
                        square[ch] += (row[ch] * scale[ch]).powi(2);
                    }
                }
            }
        }
        for ch in 0..3 {
            let i = intensity[ch];
            if !(i > 0.0) {
                continue;
            }
            // Products with the reciprocal: two roundings where a division
            // takes one; the error term below and BUILD_LENGTH_SLACK carry
            // the difference.
            let inv_i = 1.0 / i;
            let m = |a: usize, b: usize, c: usize| self.m[INDEX[a][b][c]][ch];
            out.offsets[ch] = Vec3::new(
                (m(1, 0, 0) * inv_i) as f32,
                (m(0, 1, 0) * inv_i) as f32,
                (m(0, 0, 1) * inv_i) as f32,
            );
            // Entries of the second moment: a! m_a; diagonals (a! = 2)
            // rounded upward past their error.
            let e2 = 2.0 * self.err[2][ch];
            let up = |v: f64| round_up_f32((v + e2) * inv_i * (1.0 + BUILD_LENGTH_SLACK));
            out.covariances[ch] = [
                up(2.0 * m(2, 0, 0)),
                up(2.0 * m(0, 2, 0)),
                up(2.0 * m(0, 0, 2)),
                (m(1, 1, 0) * inv_i) as f32,
                (m(1, 0, 1) * inv_i) as f32,
                (m(0, 1, 1) * inv_i) as f32,
            ];
            if r > 0.0 {
                // The sums' errors, and 4 f64::EPSILON of each entry's
                // magnitude for the products with 1 / I_k.
                let rounding = 4.0 * f64::EPSILON;
                let first = self.err[1][ch] + rounding * self.abs[1][ch];
                let second = 2.0 * (self.err[2][ch] + rounding * self.abs[2][ch]);
                relative_error = relative_error
                    .max(first * inv_i / r)
                    .max(second * inv_i / (r * r));
                for (d, gain) in tables.error_gain.into_iter().enumerate() {
                    let l = d + 3;
                    let error = gain * (self.err[l][ch] + SHIFT_SLACK * self.abs[l][ch]);
                    let (scale, sq) = (scales[d][ch], squares[d][ch]);
                    let q = (sq.sqrt() * grow + error * scale) * grow * grow + pad;
                    out.harmonic_norms[d][ch] = round_up_f32(q * (1.0 + BUILD_LENGTH_SLACK));
                }
            } else {
                // Coincident members: every moment about the centroid is 0;
                // the pad alone, as for any node.
                for norms in &mut out.harmonic_norms {
                    norms[ch] = round_up_f32(pad * (1.0 + BUILD_LENGTH_SLACK));
                }
            }
        }
        out.moment_error = round_up_f32(relative_error * grow);
        out
    }
}

/// What [`Moments::statistics`] gives a node.
pub(crate) struct Statistics {
    pub(crate) offsets: [Vec3; 3],
    pub(crate) covariances: [[f32; 6]; 3],
    pub(crate) harmonic_norms: [Vec3; 3],
    /// Upper bound `delta` on the error of every entry of the `f64` first
    /// and second moment sums, in units of `I_k R` and `I_k R^2`.
    pub(crate) moment_error: f32,
}

/// Non-zero weights of the harmonics of degrees 3 to 5 in the scaled
/// moments: 16, 28 and 46 of them.
const HARMONIC_TERMS: usize = 90;

/// The harmonic moments as straight-line code: per harmonic (its degree
/// `d` from 3, its row `r` within the degree, as [`solid_harmonics`]
/// orders them) its terms `(a, k)`: the monomial `a` of each non-zero
/// weight, by increasing `a`, and the weight's place `k` in
/// [`HarmonicTables::weights`]. [`HARMONIC_TABLES`] checks the lists
/// against the harmonics' expansion when it builds the weights.
///
/// [`solid_harmonics`]: super::build::solid_harmonics
macro_rules! harmonic_rows {
    ($(($d:literal, $r:literal): [$(($a:literal, $k:literal)),*]),*) => {
        /// The harmonic moments (unscaled) of the moments `m`, into `out`
        /// per degree and row (rows past a degree's `2l + 1` untouched):
        /// each row's terms fused-multiply-added in order of their
        /// monomials into a sum from 0, an independent chain per row.
        #[inline(always)]
        fn harmonic_moments(
            m: &[Lanes; MONOMIALS],
            w: &[f64; HARMONIC_TERMS],
            out: &mut [[Lanes; 11]; 3],
        ) {
            $({
                let mut acc = ZERO;
                $(mul_add(&mut acc, &m[$a], w[$k]);)*
                out[$d][$r] = acc;
            })*
        }

        /// Per harmonic, its degree (from 3), row and terms `(a, k)`, as
        /// [`harmonic_moments`] sums them.
        const HARMONIC_ROWS: &[(usize, usize, &[(usize, usize)])] =
            &[$(($d, $r, &[$(($a, $k)),*])),*];
    };
}

harmonic_rows!(
    (0, 0): [(12, 0), (17, 1), (19, 2)],
    (0, 1): [(10, 3), (13, 4), (15, 5)],
    (0, 2): [(11, 6), (16, 7), (18, 8)],
    (0, 3): [(12, 9), (17, 10)],
    (0, 4): [(14, 11)],
    (0, 5): [(10, 12), (13, 13)],
    (0, 6): [(11, 14), (16, 15)],
    (1, 0): [(20, 16), (23, 17), (25, 18), (30, 19), (32, 20), (34, 21)],
    (1, 1): [(22, 22), (27, 23), (29, 24)],
    (1, 2): [(24, 25), (31, 26), (33, 27)],
    (1, 3): [(20, 28), (25, 29), (30, 30), (32, 31)],
    (1, 4): [(21, 32), (26, 33), (28, 34)],
    (1, 5): [(22, 35), (27, 36)],
    (1, 6): [(24, 37), (31, 38)],
    (1, 7): [(20, 39), (23, 40), (30, 41)],
    (1, 8): [(21, 42), (26, 43)],
    (2, 0): [(37, 44), (42, 45), (44, 46), (51, 47), (53, 48), (55, 49)],
    (2, 1): [(35, 50), (38, 51), (40, 52), (45, 53), (47, 54), (49, 55)],
    (2, 2): [(36, 56), (41, 57), (43, 58), (50, 59), (52, 60), (54, 61)],
    (2, 3): [(37, 62), (44, 63), (51, 64), (53, 65)],
    (2, 4): [(39, 66), (46, 67), (48, 68)],
    (2, 5): [(35, 69), (38, 70), (40, 71), (45, 72), (47, 73)],
    (2, 6): [(36, 74), (41, 75), (43, 76), (50, 77), (52, 78)],
    (2, 7): [(37, 79), (42, 80), (51, 81)],
    (2, 8): [(39, 82), (46, 83)],
    (2, 9): [(35, 84), (38, 85), (45, 86)],
    (2, 10): [(36, 87), (41, 88), (50, 89)]
);

/// The Schmidt semi-normalised solid harmonics of degrees 3 to 5 as
/// linear forms in the scaled moments.
struct HarmonicTables {
    /// The non-zero weights `N_j P_(j,a) a!` of each harmonic `j` (by
    /// degree, then row) in monomial `a`, by increasing `a`, as
    /// [`harmonic_moments`] takes them, with `P_(j,a)` the coefficient of
    /// `y^a` in the unnormalised harmonic `j` and `N_j` its normalisation.
    weights: [f64; HARMONIC_TERMS],
    /// Per degree: `sqrt(sum_j max_a |weight_ja|^2)` (widened by a relative
    /// `2^-40`), so that the harmonic moments' error vector has norm at most
    /// this times the summed error of the degree's moments.
    error_gain: [f64; 3],
}

static HARMONIC_TABLES: LazyLock<HarmonicTables> = LazyLock::new(|| {
    let var = |axis: usize| {
        let mut p = Poly([0.0; MONOMIALS]);
        let mut e = [0; 3];
        e[axis] = 1;
        p.0[INDEX[e[0]][e[1]][e[2]]] = 1.0;
        p
    };
    let harmonics = solid_harmonics_of(var(0), var(1), var(2));
    let mut weights = [[0.0; MONOMIALS]; HARMONIC_COUNT];
    let mut error_gain = [0.0; 3];
    for (j, (row, poly)) in weights.iter_mut().zip(harmonics).enumerate() {
        let norm = HARMONIC_NORM_SQ[j].sqrt();
        let mut largest = 0.0f64;
        for (n, (w, c)) in row.iter_mut().zip(poly.0).enumerate() {
            let [a, b, d] = EXPONENTS[n];
            let factorial = FACTORIALS[a] * FACTORIALS[b] * FACTORIALS[d];
            *w = norm * c * factorial;
            largest = largest.max(w.abs());
        }
        let degree = if j < harmonic_offset(4) {
            0
        } else if j < harmonic_offset(5) {
            1
        } else {
            2
        };
        error_gain[degree] += largest * largest;
    }
    for g in &mut error_gain {
        *g = g.sqrt() * (1.0 + 2f64.powi(-40));
    }
    // The weights in the order of the straight-line rows, which must list
    // exactly each harmonic's non-zero weights.
    let mut flat = [0.0; HARMONIC_TERMS];
    let mut taken = 0;
    for (j, &(d, r, terms)) in HARMONIC_ROWS.iter().enumerate() {
        assert_eq!(harmonic_offset(d + 3) + r, j, "rows in order");
        let nonzero: Vec<usize> = (0..MONOMIALS).filter(|&a| weights[j][a] != 0.0).collect();
        let listed: Vec<usize> = terms.iter().map(|&(a, _)| a).collect();
        assert_eq!(nonzero, listed, "harmonic {j}: its non-zero weights");
        for &(a, k) in terms {
            assert_eq!(k, taken, "weights in order");
            flat[k] = weights[j][a];
            taken += 1;
        }
    }
    assert_eq!(taken, HARMONIC_TERMS);
    HarmonicTables {
        weights: flat,
        error_gain,
    }
});

const FACTORIALS: [f64; DEGREE + 1] = [1.0, 1.0, 2.0, 6.0, 24.0, 120.0];

/// A polynomial of degree at most 5 in three variables (products truncated),
/// used once to expand the solid harmonics into monomials.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Poly([f64; MONOMIALS]);

impl Add for Poly {
    type Output = Self;
    fn add(mut self, other: Self) -> Self {
        for (a, b) in self.0.iter_mut().zip(other.0) {
            *a += b;
        }
        self
    }
}

impl Sub for Poly {
    type Output = Self;
    fn sub(mut self, other: Self) -> Self {
        for (a, b) in self.0.iter_mut().zip(other.0) {
            *a -= b;
        }
        self
    }
}

impl Mul<f64> for Poly {
    type Output = Self;
    fn mul(mut self, s: f64) -> Self {
        for a in &mut self.0 {
            *a *= s;
        }
        self
    }
}

impl Mul for Poly {
    type Output = Self;
    fn mul(self, other: Self) -> Self {
        let mut out = [0.0; MONOMIALS];
        for (p, &x) in self.0.iter().enumerate() {
            if x == 0.0 {
                continue;
            }
            for (q, &y) in other.0.iter().enumerate() {
                let (a, b) = (EXPONENTS[p], EXPONENTS[q]);
                let e = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
                if y != 0.0 && e[0] + e[1] + e[2] <= DEGREE {
                    out[INDEX[e[0]][e[1]][e[2]]] += x * y;
                }
            }
        }
        Self(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tree::build::solid_harmonics;

    fn lights(seed: u64, count: usize, spread: f32, offset: Vec3) -> Vec<PointLight> {
        let mut state = seed | 1;
        let mut uniform = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..count)
            .map(|_| {
                let p = Vec3::new(uniform(), uniform(), uniform()) * spread + offset;
                let i = Vec3::new(uniform(), uniform() * 10.0, uniform() * 0.1);
                PointLight::new(p, i)
            })
            .collect()
    }

    /// Shifting moments to a new centre agrees with summing about it
    /// directly, within the two error bounds, and the bounds stay small.
    #[test]
    fn the_straight_line_shifts_follow_the_table() {
        assert_eq!(SHIFT_X, SHIFT_STEPS[0]);
        assert_eq!(SHIFT_Y, SHIFT_STEPS[1]);
        assert_eq!(SHIFT_Z, SHIFT_STEPS[2]);
    }

    #[test]
    fn shifted_moments_match_direct_sums_within_their_bounds() {
        for seed in 1..40u64 {
            let a = lights(seed, 7, 2.0, Vec3::new(1.0, -3.0, 0.5));
            let b = lights(seed * 31, 12, 0.5, Vec3::new(-2.0, 1.0, 4.0));
            let centre = DVec3::new(0.25, -0.5, 1.75);
            let mut sum = Moments::ZERO;
            for group in [&a, &b] {
                let c = group[0].position.as_dvec3();
                let mut moments = Moments::of_lights(group, c);
                moments.shift_into(c - centre, &mut sum);
            }
            let all: Vec<PointLight> = a.iter().chain(&b).copied().collect();
            let direct = Moments::of_lights(&all, centre);
            for l in 0..=DEGREE {
                for ch in 0..3 {
                    let diff: f64 = (DEGREE_START[l]..DEGREE_START[l + 1])
                        .map(|n| (sum.m[n][ch] - direct.m[n][ch]).abs())
                        .sum();
                    let allowed = sum.err[l][ch] + direct.err[l][ch];
                    assert!(diff <= allowed, "degree {l}: {diff} > {allowed}");
                    assert!(sum.abs[l][ch] >= direct.abs[l][ch] * (1.0 - 1e-12));
                    assert!(sum.err[l][ch] <= 1e-11 * sum.abs[l][ch]);
                }
            }
        }
    }

    /// A leaf's direct sums, over one chunk, part of one, whole blocks
    /// and blocks carried into the next: within their error bound of the
    /// same sums taken light by light (the bound covering that sum's own
    /// rounding too), their 1-norm bounds above them, and the copy for
    /// AVX2 and FMA the same bits as the baseline.
    #[test]
    fn direct_sums_match_sums_light_by_light() {
        for count in [1, 3, 4, 5, 31, 32, 33, 64, 70, 100] {
            let group = lights(count as u64 * 7 + 1, count, 4.0, Vec3::new(-3.0, 2.0, 1.0));
            let centre = DVec3::new(-1.5, 3.5, 2.0);
            let moments = Moments::of_lights(&group, centre);
            let baseline = crate::dispatch::baseline(|| Moments::of_lights(&group, centre));
            assert_eq!(moments.m, baseline.m, "{count} lights");
            assert_eq!(moments.abs, baseline.abs, "{count} lights");
            assert_eq!(moments.err, baseline.err, "{count} lights");
            let mut plain = [[0.0f64; 3]; MONOMIALS];
            let mut norms = [[0.0f64; 3]; DEGREE + 1];
            for l in &group {
                let y = l.position.as_dvec3() - centre;
                let i = l.intensity.as_dvec3();
                let norm = y.x.abs() + y.y.abs() + y.z.abs();
                for (n, [a, b, c]) in EXPONENTS.into_iter().enumerate() {
                    let v = y.x.powi(a as i32) * y.y.powi(b as i32) * y.z.powi(c as i32)
                        / (FACTORIALS[a] * FACTORIALS[b] * FACTORIALS[c]);
                    for ch in 0..3 {
                        plain[n][ch] += v * i[ch];
                    }
                }
                for (d, acc) in norms.iter_mut().enumerate() {
                    for ch in 0..3 {
                        *acc.get_mut(ch).unwrap() += norm.powi(d as i32) / FACTORIALS[d] * i[ch];
                    }
                }
            }
            for l in 0..=DEGREE {
                for ch in 0..3 {
                    let range = DEGREE_START[l]..DEGREE_START[l + 1];
                    let diff: f64 = range.map(|n| (moments.m[n][ch] - plain[n][ch]).abs()).sum();
                    assert!(
                        diff <= 2.0 * moments.err[l][ch],
                        "{count} lights, degree {l}: {diff} > 2 * {}",
                        moments.err[l][ch]
                    );
                    assert!(
                        moments.abs[l][ch] >= norms[l][ch],
                        "{count} lights, degree {l}"
                    );
                    assert!(moments.abs[l][ch] <= norms[l][ch] * (1.0 + 1e-12));
                }
            }
        }
    }

    /// The harmonic norms from the moment tables agree with the norms of
    /// the solid harmonics summed light by light, and bound them.
    #[test]
    fn harmonic_norms_from_moments_match_the_direct_ones() {
        for seed in 1..40u64 {
            let group = lights(seed, 25, 3.0, Vec3::new(5.0, 1.0, -2.0));
            let centre = DVec3::new(6.5, 2.5, -0.5);
            let r = group
                .iter()
                .map(|l| (l.position.as_dvec3() - centre).length())
                .fold(0.0, f64::max) as f32;
            let intensity: DVec3 = group.iter().map(|l| l.intensity.as_dvec3()).sum();
            let stats = Moments::of_lights(&group, centre).statistics(intensity, r, group.len());
            let mut moments = [[0.0f64; HARMONIC_COUNT]; 3];
            for l in &group {
                let h = solid_harmonics((l.position.as_dvec3() - centre) / f64::from(r));
                for (ch, channel) in moments.iter_mut().enumerate() {
                    for (acc, v) in channel.iter_mut().zip(h) {
                        *acc += f64::from(l.intensity[ch]) * v;
                    }
                }
            }
            for d in 0..3 {
                let l = d + 3;
                for ch in 0..3 {
                    let sq: f64 = (harmonic_offset(l)..harmonic_offset(l) + 2 * l + 1)
                        .map(|j| moments[ch][j] * moments[ch][j] * HARMONIC_NORM_SQ[j])
                        .sum();
                    let direct = sq.sqrt() / intensity[ch];
                    let stored = f64::from(stats.harmonic_norms[d][ch]);
                    assert!(stored >= direct, "degree {l}: {stored} < {direct}");
                    assert!(
                        stored <= direct * (1.0 + 1e-6) + 1e-9,
                        "degree {l}: {stored} against {direct}"
                    );
                }
            }
        }
    }
}
