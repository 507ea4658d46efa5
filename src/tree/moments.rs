//! Cartesian moments of degree at most 5, merged bottom-up with a certified
//! error bound: what makes the build linear. Here the moments, their
//! indexing and their shift to a new centre; a leaf's direct sums are in
//! [`leaf_moments`](super::leaf_moments), and what a node stores, read off
//! its moments, in [`moment_statistics`](super::moment_statistics).
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

use glam::DVec3;

/// Highest degree kept.
pub(super) const DEGREE: usize = 5;

/// Monomials `y^a` of degree at most 5 in three variables.
pub(super) const MONOMIALS: usize = 56;

/// Index of the first monomial of each degree `l` (and the count, at `l = 6`).
#[cfg(test)]
pub(super) const DEGREE_START: [usize; DEGREE + 2] = [0, 1, 4, 10, 20, 35, 56];

/// Exponents of each monomial, by degree, then `a_x` and `a_y` decreasing.
pub(super) const EXPONENTS: [[usize; 3]; MONOMIALS] = {
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
pub(super) const INDEX: [[[usize; DEGREE + 1]; DEGREE + 1]; DEGREE + 1] = {
    let mut out = [[[usize::MAX; DEGREE + 1]; DEGREE + 1]; DEGREE + 1];
    let mut n = 0;
    while n < MONOMIALS {
        let [i, j, k] = EXPONENTS[n];
        out[i][j][k] = n;
        n += 1;
    }
    out
};

/// `p!` for `p = 0..=5`.
pub(super) const FACTORIALS: [f64; DEGREE + 1] = [1.0, 1.0, 2.0, 6.0, 24.0, 120.0];

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
pub(super) const SHIFT_SLACK: f64 = 128.0 * f64::EPSILON;

/// Four lanes: the three channels and a spare, so that channel loops
/// vectorise.
pub(super) type Lanes = [f64; 4];

pub(super) const ZERO: Lanes = [0.0; 4];

#[inline(always)]
pub(super) fn mul_add(acc: &mut Lanes, a: &Lanes, s: f64) {
    for (x, y) in acc.iter_mut().zip(a) {
        *x = y.mul_add(s, *x);
    }
}

/// A node's moments about a centre, per channel in lanes 0 to 2, with
/// their bounds (module docs).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Moments {
    /// `sum_i I_ik y_i^a / a!` per monomial `a`.
    pub(super) m: [Lanes; MONOMIALS],
    /// Per degree: upper bound on `sum_i I_ik |y_i|_1^l / l!`.
    pub(super) abs: [Lanes; DEGREE + 1],
    /// Per degree: upper bound on the summed errors of the degree's moments.
    pub(super) err: [Lanes; DEGREE + 1],
}

/// `1 / p`, rounded.
pub(super) const RECIPROCALS: [f64; DEGREE + 1] = [1.0, 1.0, 0.5, 1.0 / 3.0, 0.25, 0.2];

/// `x^p / p!` for `p = 0..=5`, each step one product with `x` and one
/// with a rounded `1 / p` (no division).
#[inline(always)]
pub(super) fn scaled_powers(x: f64) -> [f64; DEGREE + 1] {
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
}

/// Lights of random positions and colours for the moments' tests: `count`
/// of them in the cube of side `spread` from `offset`.
#[cfg(test)]
pub(super) fn test_lights(
    seed: u64,
    count: usize,
    spread: f32,
    offset: glam::Vec3,
) -> Vec<crate::PointLight> {
    let mut state = seed | 1;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    (0..count)
        .map(|_| {
            let p = glam::Vec3::new(uniform(), uniform(), uniform()) * spread + offset;
            let i = glam::Vec3::new(uniform(), uniform() * 10.0, uniform() * 0.1);
            crate::PointLight::new(p, i)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_straight_line_shifts_follow_the_table() {
        assert_eq!(SHIFT_X, SHIFT_STEPS[0]);
        assert_eq!(SHIFT_Y, SHIFT_STEPS[1]);
        assert_eq!(SHIFT_Z, SHIFT_STEPS[2]);
    }
}
