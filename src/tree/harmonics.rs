//! The real regular solid harmonics of degrees 3, 4 and 5: the multipole
//! terms behind every node's harmonic norms
//! ([`Node::harmonic_norms`](crate::shader::Node::harmonic_norms)).
//!
//! For degree `l` and order `m = 0..=l` the harmonic is `r^l P_l^m(cos
//! theta)` times `cos(m phi)` and (for `m >= 1`) `sin(m phi)`, with `P_l^m`
//! the associated Legendre function without the Condon-Shortley phase.
//! Written in Cartesian coordinates it is `(x + i y)^m T_lm(z, r^2)`, whose
//! real and imaginary parts give the cosine and sine harmonics, where
//! `T_lm = r^(l-m) P_l^(m)(z / r)` is the `m`-th derivative of the Legendre
//! polynomial `P_l` made homogeneous of degree `l - m`: a polynomial, so
//! the same code serves `f64` values and the polynomials whose monomials
//! [`moment_statistics`](super::moment_statistics) reads off.
//!
//! Scaled by the square roots of [`HARMONIC_NORM_SQ`] (Schmidt
//! semi-normalisation, `(2 - [m = 0]) (l - m)! / (l + m)!`), the harmonics
//! of one degree satisfy the addition theorem
//! `sum_j R_lj(a) R_lj(b) = |a|^l |b|^l P_l(a^ . b^)` (`a^` the unit vector
//! along `a`). At `a = b` it reads `sum_j R_lj(a)^2 = |a|^(2l)`: the norm
//! of a node's degree-`l` multipole `sum_i I_i R_l(y_i)` is the square root
//! of the double sum `sum_ij I_i I_j |y_i|^l |y_j|^l P_l(y^_i . y^_j)` that
//! the bounds read, which [`harmonic_norms`] takes from the `2l + 1`
//! harmonic moments instead of from every pair of members. A test checks
//! the theorem, and so the recurrence and the normalisation, on random
//! points to `2^11 f64::EPSILON`, the evaluation error that
//! [`HARMONIC_BUILD_PAD`] assumes.

use core::ops::{Add, Mul, Sub};

use glam::{DVec3, Vec3};

use crate::numeric::{BUILD_LENGTH_SLACK, HARMONIC_BUILD_PAD, round_up_f32};

/// Number of real solid harmonics of degrees 3, 4 and 5: `7 + 9 + 11`.
pub(crate) const HARMONIC_COUNT: usize = 27;

/// Index of the first harmonic of degree `l` (3, 4 or 5) in the output of
/// [`solid_harmonics`].
pub(crate) const fn harmonic_offset(l: usize) -> usize {
    // Degrees below l hold sum_{j=3}^{l-1} (2j + 1) = l^2 - 9 harmonics.
    l * l - 9
}

/// Squared Schmidt semi-normalisation of each output of [`solid_harmonics`]:
/// `(2 - [m = 0]) (l - m)! / (l + m)!` for degree `l`, order `m`.
pub(crate) const HARMONIC_NORM_SQ: [f64; HARMONIC_COUNT] = {
    const fn factorial(k: usize) -> f64 {
        let mut f = 1.0;
        let mut i = 2;
        while i <= k {
            f *= i as f64;
            i += 1;
        }
        f
    }
    let mut out = [0.0; HARMONIC_COUNT];
    let mut l = 3;
    while l <= 5 {
        let mut m = 0;
        while m <= l {
            let v = factorial(l - m) / factorial(l + m);
            if m == 0 {
                out[harmonic_offset(l)] = v;
            } else {
                out[harmonic_offset(l) + 2 * m - 1] = 2.0 * v;
                out[harmonic_offset(l) + 2 * m] = 2.0 * v;
            }
            m += 1;
        }
        l += 1;
    }
    out
};

/// The real regular solid harmonics of degrees 3, 4 and 5 at `y`, without
/// their normalisation: for degree `l` and order `m = 0..=l`,
/// `r^l P_l^m(cos theta)` times `cos(m phi)` and (for `m >= 1`)
/// `sin(m phi)`, in that order. Multiplied by the square roots of
/// [`HARMONIC_NORM_SQ`] they are Schmidt semi-normalised, for which the
/// addition theorem reads `sum_j R_lj(a) R_lj(b) = |a|^l |b|^l P_l(a^ . b^)`;
/// the sum of squares of one degree is `|y|^(2l)`.
///
/// Evaluated as `(x + i y)^m T_lm(z, r^2)` with
/// `T_lm = r^(l-m) P_l^(m)(z / r)`, the `m`-th derivative of the Legendre
/// polynomial made homogeneous (no Condon-Shortley phase; signs cancel in
/// every product the crate forms).
#[inline]
pub(crate) fn solid_harmonics(y: DVec3) -> [f64; HARMONIC_COUNT] {
    solid_harmonics_of(y.x, y.y, y.z)
}

/// [`solid_harmonics`] for any ring: `f64` values, or polynomials to read
/// off each harmonic's monomials.
#[inline]
pub(crate) fn solid_harmonics_of<T>(x: T, y: T, z: T) -> [T; HARMONIC_COUNT]
where
    T: Copy + Add<Output = T> + Sub<Output = T> + Mul<Output = T> + Mul<f64, Output = T>,
{
    let r2 = x * x + y * y + z * z;
    let (z2, r4) = (z * z, r2 * r2);
    let z3 = z2 * z;
    // (x + i y)^m = c_m + i s_m.
    let (c1, s1) = (x, y);
    let (c2, s2) = (c1 * x - s1 * y, c1 * y + s1 * x);
    let (c3, s3) = (c2 * x - s2 * y, c2 * y + s2 * x);
    let (c4, s4) = (c3 * x - s3 * y, c3 * y + s3 * x);
    let (c5, s5) = (c4 * x - s4 * y, c4 * y + s4 * x);
    let t30 = (z3 * 5.0 - z * r2 * 3.0) * 0.5;
    let t31 = (z2 * 15.0 - r2 * 3.0) * 0.5;
    let t32 = z * 15.0;
    let t40 = (z2 * z2 * 35.0 - z2 * r2 * 30.0 + r4 * 3.0) * 0.125;
    let t41 = (z3 * 35.0 - z * r2 * 15.0) * 0.5;
    let t42 = (z2 * 105.0 - r2 * 15.0) * 0.5;
    let t43 = z * 105.0;
    let t50 = (z3 * z2 * 63.0 - z3 * r2 * 70.0 + z * r4 * 15.0) * 0.125;
    let t51 = (z2 * z2 * 315.0 - z2 * r2 * 210.0 + r4 * 15.0) * 0.125;
    let t52 = (z3 * 315.0 - z * r2 * 105.0) * 0.5;
    let t53 = (z2 * 945.0 - r2 * 105.0) * 0.5;
    let t54 = z * 945.0;
    [
        t30,
        t31 * c1,
        t31 * s1,
        t32 * c2,
        t32 * s2,
        c3 * 15.0,
        s3 * 15.0,
        t40,
        t41 * c1,
        t41 * s1,
        t42 * c2,
        t42 * s2,
        t43 * c3,
        t43 * s3,
        c4 * 105.0,
        s4 * 105.0,
        t50,
        t51 * c1,
        t51 * s1,
        t52 * c2,
        t52 * s2,
        t53 * c3,
        t53 * s3,
        t54 * c4,
        t54 * s4,
        c5 * 945.0,
        s5 * 945.0,
    ]
}

/// Harmonic norms of degrees 3 to 5 per channel (rounded upward, see
/// [`HARMONIC_BUILD_PAD`]) from the unnormalised moments `moments[k]` of
/// channel `k` (sums of `I_ik` times [`solid_harmonics`] of `y_i / R` over
/// `terms` members) and the channel intensities.
pub(crate) fn harmonic_norms(
    moments: &[[f64; HARMONIC_COUNT]; 3],
    intensity: DVec3,
    terms: usize,
) -> [Vec3; 3] {
    let pad = (terms as f64 + HARMONIC_BUILD_PAD) * f64::EPSILON;
    let mut out = [Vec3::ZERO; 3];
    for (d, norms) in out.iter_mut().enumerate() {
        let l = d + 3;
        let range = harmonic_offset(l)..harmonic_offset(l) + 2 * l + 1;
        for k in 0..3 {
            if intensity[k] > 0.0 {
                let sq: f64 = moments[k][range.clone()]
                    .iter()
                    .zip(&HARMONIC_NORM_SQ[range.clone()])
                    .map(|(c, n)| c * c * n)
                    .sum();
                let q = sq.sqrt() / intensity[k];
                norms[k] = round_up_f32((q + pad) * (1.0 + BUILD_LENGTH_SLACK));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `P_l(x)` by the three-term recurrence.
    fn legendre(l: usize, x: f64) -> f64 {
        let (mut p0, mut p1) = (1.0, x);
        for k in 2..=l {
            (p0, p1) = (
                p1,
                ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64,
            );
        }
        p1
    }

    /// The addition theorem `sum_j N_j^2 R_lj(a) R_lj(b) = |a|^l |b|^l
    /// P_l(a^ . b^)` on points of the unit ball: it checks the recurrence,
    /// the normalisation and, to `2^11 eps`, the evaluation error that
    /// `HARMONIC_BUILD_PAD` assumes.
    #[test]
    fn solid_harmonics_satisfy_the_addition_theorem() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..10_000 {
            let a = DVec3::new(uniform(), uniform(), uniform());
            let b = DVec3::new(uniform(), uniform(), uniform());
            if a.length() > 1.0 || b.length() > 1.0 || a.length() == 0.0 || b.length() == 0.0 {
                continue;
            }
            let (ha, hb) = (solid_harmonics(a), solid_harmonics(b));
            for l in 3..=5 {
                let range = harmonic_offset(l)..harmonic_offset(l) + 2 * l + 1;
                let sum: f64 = range.map(|j| HARMONIC_NORM_SQ[j] * ha[j] * hb[j]).sum();
                let cos = (a.dot(b) / (a.length() * b.length())).clamp(-1.0, 1.0);
                let expected =
                    a.length().powi(l as i32) * b.length().powi(l as i32) * legendre(l, cos);
                let scale = a.length().powi(l as i32) * b.length().powi(l as i32);
                assert!(
                    (sum - expected).abs() <= 2048.0 * f64::EPSILON * scale,
                    "degree {l}: {sum} against {expected}"
                );
            }
        }
    }
}
