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

/// The 56 values `px[a_x] py[a_y] pz[a_z]`, in the order of [`EXPONENTS`]
/// (straight-line code: no table lookups in the leaves' loop).
macro_rules! monomial_values {
    ($px:ident, $py:ident, $pz:ident) => {
        monomial_values!(@ $px, $py, $pz; (0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (2, 0, 0), (1, 1, 0), (1, 0, 1), (0, 2, 0), (0, 1, 1), (0, 0, 2), (3, 0, 0), (2, 1, 0), (2, 0, 1), (1, 2, 0), (1, 1, 1), (1, 0, 2), (0, 3, 0), (0, 2, 1), (0, 1, 2), (0, 0, 3), (4, 0, 0), (3, 1, 0), (3, 0, 1), (2, 2, 0), (2, 1, 1), (2, 0, 2), (1, 3, 0), (1, 2, 1), (1, 1, 2), (1, 0, 3), (0, 4, 0), (0, 3, 1), (0, 2, 2), (0, 1, 3), (0, 0, 4), (5, 0, 0), (4, 1, 0), (4, 0, 1), (3, 2, 0), (3, 1, 1), (3, 0, 2), (2, 3, 0), (2, 2, 1), (2, 1, 2), (2, 0, 3), (1, 4, 0), (1, 3, 1), (1, 2, 2), (1, 1, 3), (1, 0, 4), (0, 5, 0), (0, 4, 1), (0, 3, 2), (0, 2, 3), (0, 1, 4), (0, 0, 5))
    };
    (@ $px:ident, $py:ident, $pz:ident; $(($a:literal, $b:literal, $c:literal)),*) => {
        [$($px[$a] * $py[$b] * $pz[$c]),*]
    };
}

/// Per axis, the steps of a shift along it: `(target, source, power)` with
/// `m[target] += t^power / power! * m[source]`, the source being the target
/// with `power` fewer along the axis; targets by decreasing index, so that
/// in place every source is read before it is shifted itself.
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

/// Relative rounding allowance of one shift (see the module docs).
const SHIFT_SLACK: f64 = 128.0 * f64::EPSILON;

/// Four lanes: the three channels and a spare, so that channel loops
/// vectorise.
type Lanes = [f64; 4];

const ZERO: Lanes = [0.0; 4];

#[inline(always)]
fn mul_add(acc: &mut Lanes, a: &Lanes, s: f64) {
    for (x, y) in acc.iter_mut().zip(a) {
        *x += y * s;
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
        out.set_to_lights(lights, centre);
        out
    }

    /// Sets these to the moments of `lights` about `centre`, summed
    /// directly.
    #[inline(always)]
    pub(crate) fn set_to_lights(&mut self, lights: &[PointLight], centre: DVec3) {
        self.clear();
        for l in lights {
            let y = l.position.as_dvec3() - centre;
            let i = l.intensity.as_dvec3();
            let lanes = [i.x, i.y, i.z, 0.0];
            let (px, py, pz) = (scaled_powers(y.x), scaled_powers(y.y), scaled_powers(y.z));
            let values: [f64; MONOMIALS] = monomial_values!(px, py, pz);
            for (acc, v) in self.m.iter_mut().zip(values) {
                mul_add(acc, &lanes, v);
            }
            let s = scaled_powers(y.x.abs() + y.y.abs() + y.z.abs());
            for (acc, p) in self.abs.iter_mut().zip(s) {
                mul_add(acc, &lanes, p);
            }
        }
        let slack = (lights.len() as f64 + 64.0) * f64::EPSILON;
        for (abs, err) in self.abs.iter_mut().zip(self.err.iter_mut()) {
            for (a, e) in abs.iter_mut().zip(err.iter_mut()) {
                *a *= 1.0 + slack;
                *e = *a * slack;
            }
        }
    }

    /// Sets every moment and bound to 0.
    #[inline(always)]
    pub(crate) fn clear(&mut self) {
        *self = Self::ZERO;
    }

    /// Adds these moments, taken about a centre `c'`, shifted to a centre
    /// `c` with `t = c' - c` (so `x - c = (x - c') + t`), into `sum`; the
    /// moments themselves are left shifted, their bounds unchanged.
    #[inline(always)]
    pub(crate) fn shift_into(&mut self, t: DVec3, sum: &mut Self) {
        let m = &mut self.m;
        for (axis, tv) in t.to_array().into_iter().enumerate() {
            if tv == 0.0 {
                continue;
            }
            let w = scaled_powers(tv);
            for &(target, source, power) in &SHIFT_STEPS[axis] {
                let from = m[usize::from(source)];
                mul_add(&mut m[usize::from(target)], &from, w[usize::from(power)]);
            }
        }
        for (acc, v) in sum.m.iter_mut().zip(m.iter()) {
            for (a, b) in acc.iter_mut().zip(v) {
                *a += b;
            }
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
                sum.abs[l][ch] += abs[ch] * grow * grow;
                sum.err[l][ch] += err[ch] * grow * grow;
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
        if r > 0.0 {
            for (c, terms) in harmonics.iter_mut().zip(&tables.terms) {
                for &(row, n, w) in terms {
                    mul_add(&mut c[usize::from(row)], &self.m[usize::from(n)], w);
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
                let mut power = i * r * r;
                for (d, (degree, gain)) in harmonics.iter().zip(tables.error_gain).enumerate() {
                    let l = d + 3;
                    power *= r;
                    let error = gain * (self.err[l][ch] + SHIFT_SLACK * self.abs[l][ch]);
                    // 1 / (I_k R^l), with a few roundings that `grow` covers;
                    // applied before squaring, which could underflow.
                    let scale = 1.0 / power;
                    let sq: f64 = degree.iter().map(|c| (c[ch] * scale).powi(2)).sum();
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

/// The Schmidt semi-normalised solid harmonics of degrees 3 to 5 as
/// linear forms in the scaled moments.
struct HarmonicTables {
    /// Per degree 3 to 5, the non-zero weights `N_j P_(j,a) a!` as
    /// `(j - first j of the degree, a, weight)`, with `P_(j,a)` the
    /// coefficient of `y^a` in the unnormalised harmonic `j` and `N_j` its
    /// normalisation.
    terms: [Vec<(u8, u8, f64)>; 3],
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
    let terms = [3, 4, 5].map(|l| {
        let mut out = Vec::new();
        let rows = &weights[harmonic_offset(l)..harmonic_offset(l) + 2 * l + 1];
        for (j, row) in rows.iter().enumerate() {
            for (n, &w) in row.iter().enumerate() {
                if w != 0.0 {
                    out.push((j as u8, n as u8, w));
                }
            }
        }
        out
    });
    HarmonicTables { terms, error_gain }
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
