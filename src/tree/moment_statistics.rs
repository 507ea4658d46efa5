//! What a node stores, read off its moments about its centroid: the
//! channel offsets and second moments, the harmonic norms of degrees 3 to
//! 5 (the solid harmonics written as linear forms in the moments), and the
//! bound on their rounding (see [`moments`](super::moments)' docs).

use core::ops::{Add, Mul, Sub};
use std::sync::LazyLock;

use glam::{DVec3, Vec3};

use super::harmonics::{HARMONIC_COUNT, HARMONIC_NORM_SQ, harmonic_offset, solid_harmonics_of};
use super::moments::{
    DEGREE, EXPONENTS, FACTORIALS, INDEX, Lanes, MONOMIALS, Moments, SHIFT_SLACK, ZERO, mul_add,
};
use crate::numeric::{BUILD_LENGTH_SLACK, HARMONIC_BUILD_PAD, round_up_f32};

impl Moments {
    /// The node statistics the moments give, for a node of `lights`
    /// members, channel intensities `intensity` and stored radius `radius`
    /// (the moments being about its stored centroid).
    #[inline(always)]
    pub(super) fn statistics(&self, intensity: DVec3, radius: f32, lights: usize) -> Statistics {
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
        let ScaledHarmonics { scales, squares } = self.scaled_harmonics(intensity, r, tables);
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

    /// The harmonic moments of degrees 3 to 5, scaled, of a node of channel
    /// intensities `intensity` and stored radius `r` (see
    /// [`ScaledHarmonics`]), from the weights of `tables`.
    #[inline(always)]
    fn scaled_harmonics(
        &self,
        intensity: DVec3,
        r: f64,
        tables: &HarmonicTables,
    ) -> ScaledHarmonics {
        let mut out = ScaledHarmonics {
            scales: [ZERO; 3],
            squares: [ZERO; 3],
        };
        if r > 0.0 {
            // Per degree 3 to 5, the harmonic moments (unscaled).
            let mut harmonics = [[ZERO; 11]; 3];
            harmonic_moments(&self.m, &tables.weights, &mut harmonics);
            let mut power = [0.0; 4];
            for ch in 0..3 {
                power[ch] = intensity[ch] * r * r;
            }
            let ScaledHarmonics { scales, squares } = &mut out;
            for ((degree, scale), square) in harmonics.iter().zip(scales).zip(squares) {
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
        out
    }
}

/// Per degree 3 to 5, `1 / (I_k R^l)` and the squared norm of the harmonic
/// moments scaled by it, the channels side by side (a channel without
/// intensity, and the spare lane, are computed and never used); zeros for
/// a node of radius 0.
struct ScaledHarmonics {
    scales: [Lanes; 3],
    squares: [Lanes; 3],
}

/// What [`Moments::statistics`] gives a node.
pub(super) struct Statistics {
    /// Per channel, the first moment over the intensity: `o_k`.
    pub(super) offsets: [Vec3; 3],
    /// Per channel, the second moments over the intensity: `S_k`.
    pub(super) covariances: [[f32; 6]; 3],
    /// Per degree 3, 4, 5, the three channels' harmonic norms.
    pub(super) harmonic_norms: [Vec3; 3],
    /// Upper bound `delta` on the error of every entry of the `f64` first
    /// and second moment sums, in units of `I_k R` and `I_k R^2`.
    pub(super) moment_error: f32,
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
/// [`solid_harmonics`]: super::harmonics::solid_harmonics
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

/// A polynomial of degree at most 5 in three variables (products truncated),
/// used once to expand the solid harmonics into monomials.
#[derive(Clone, Copy, Debug)]
struct Poly([f64; MONOMIALS]);

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
    use glam::Vec3;

    use super::*;
    use crate::tree::harmonics::solid_harmonics;
    use crate::tree::moments::test_lights as lights;

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
