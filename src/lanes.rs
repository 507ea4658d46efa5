//! `N` lanes of `f64` or `f32`, operated on lane by lane: the node bounds
//! are written once over this type and run with one lane (a single node)
//! or several (the children of a node, side by side). Every operation is
//! the scalar one applied to each lane, so a lane's result is the same
//! bits whatever `N` and whichever compiled copy runs; the loops are
//! fixed-length and inlined, which the compiler turns into vector
//! instructions (two 4-wide AVX2 operations for eight `f64` lanes, one
//! for eight `f32` lanes).

use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub};

/// `N` values of `f64`, one per lane: the `f64` node bounds' lanes.
pub(crate) type Lanes<const N: usize> = Wide<f64, N>;

impl<const N: usize> Lanes<N> {
    /// Lane `i` holds `f(i)`.
    #[inline(always)]
    pub(crate) fn from_fn(f: impl FnMut(usize) -> f64) -> Self {
        Wide(array(0.0, f))
    }

    /// `1 / x` per lane (one correctly rounded division).
    #[inline(always)]
    pub(crate) fn recip(self) -> Self {
        1.0 / self
    }
}

/// `[f(0), .., f(N - 1)]`, by a plain loop that the compiler unrolls and
/// inlines into each compiled copy of the caller (`core::array::from_fn`
/// goes through calls that stay out of line there).
#[inline(always)]
pub(crate) fn array<T: Copy, const N: usize>(fill: T, mut f: impl FnMut(usize) -> T) -> [T; N] {
    let mut out = [fill; N];
    for (i, out) in out.iter_mut().enumerate() {
        *out = f(i);
    }
    out
}

/// The arithmetic of `f64` lanes with one `f64` for every lane, on
/// either side.
macro_rules! scalar_binary {
    ($trait:ident, $method:ident, $op:tt) => {
        impl<const N: usize> $trait<f64> for Lanes<N> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, b: f64) -> Self {
                self.map(|a| a $op b)
            }
        }
        impl<const N: usize> $trait<Lanes<N>> for f64 {
            type Output = Lanes<N>;
            #[inline(always)]
            fn $method(self, b: Lanes<N>) -> Lanes<N> {
                b.map(|b| self $op b)
            }
        }
    };
}

scalar_binary!(Add, add, +);
scalar_binary!(Sub, sub, -);
scalar_binary!(Mul, mul, *);
scalar_binary!(Div, div, /);

impl<const N: usize> MulAssign<f64> for Lanes<N> {
    #[inline(always)]
    fn mul_assign(&mut self, b: f64) {
        *self = *self * b;
    }
}

/// A vector of three [`Lanes`], with `glam`'s order of operations.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Vec3Lanes<const N: usize> {
    pub(crate) x: Lanes<N>,
    pub(crate) y: Lanes<N>,
    pub(crate) z: Lanes<N>,
}

impl<const N: usize> Vec3Lanes<N> {
    /// Lane `i` holds `f(i)`.
    #[inline(always)]
    pub(crate) fn from_fn(mut f: impl FnMut(usize) -> [f64; 3]) -> Self {
        let v: [[f64; 3]; N] = array([0.0; 3], &mut f);
        Self {
            x: Lanes::from_fn(|i| v[i][0]),
            y: Lanes::from_fn(|i| v[i][1]),
            z: Lanes::from_fn(|i| v[i][2]),
        }
    }

    /// `(x * b.x + y * b.y) + z * b.z`, as `DVec3::dot`.
    #[inline(always)]
    pub(crate) fn dot(self, b: Self) -> Lanes<N> {
        self.x * b.x + self.y * b.y + self.z * b.z
    }

    /// The dot product with one vector for every lane, as `DVec3::dot`.
    #[inline(always)]
    pub(crate) fn dot_with(self, b: [f64; 3]) -> Lanes<N> {
        self.x * b[0] + self.y * b[1] + self.z * b[2]
    }

    /// `a . self` per lane in plain `f64`, `(a_x x + a_y y) + a_z z`, and
    /// the magnitude `|a_x x| + |a_y y| + |a_z z|` its rounding is measured
    /// against (as `plain_dot_of_difference` gives them for `self = x -
    /// p`).
    #[inline(always)]
    pub(crate) fn plain_dot(self, a: [f64; 3]) -> (Lanes<N>, Lanes<N>) {
        let terms = Self {
            x: a[0] * self.x,
            y: a[1] * self.y,
            z: a[2] * self.z,
        };
        (terms.element_sum(), terms.abs().element_sum())
    }

    /// `x + y + z`, as `DVec3::element_sum`.
    #[inline(always)]
    pub(crate) fn element_sum(self) -> Lanes<N> {
        self.x + self.y + self.z
    }

    #[inline(always)]
    pub(crate) fn abs(self) -> Self {
        Self {
            x: self.x.abs(),
            y: self.y.abs(),
            z: self.z.abs(),
        }
    }

    /// `self - p`, the same point subtracted in every lane.
    #[inline(always)]
    pub(crate) fn minus(self, p: [f64; 3]) -> Self {
        Self {
            x: self.x - p[0],
            y: self.y - p[1],
            z: self.z - p[2],
        }
    }

    /// `n - s v` per lane, for one vector `n`, as `n - s * v` with `DVec3`.
    #[inline(always)]
    pub(crate) fn scaled_from(n: [f64; 3], s: Lanes<N>, v: Self) -> Self {
        Self {
            x: n[0] - s * v.x,
            y: n[1] - s * v.y,
            z: n[2] - s * v.z,
        }
    }

    /// The centre `(lo + hi) / 2` and half extent `(hi - lo) / 2` of boxes.
    #[inline(always)]
    pub(crate) fn centre_and_half(lo: Self, hi: Self) -> (Self, Self) {
        let f = |lo: Lanes<N>, hi: Lanes<N>| (0.5 * (lo + hi), 0.5 * (hi - lo));
        let ((cx, hx), (cy, hy), (cz, hz)) = (f(lo.x, hi.x), f(lo.y, hi.y), f(lo.z, hi.z));
        (
            Self {
                x: cx,
                y: cy,
                z: cz,
            },
            Self {
                x: hx,
                y: hy,
                z: hz,
            },
        )
    }
}

impl<const N: usize> Sub for Vec3Lanes<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        Self {
            x: self.x - b.x,
            y: self.y - b.y,
            z: self.z - b.z,
        }
    }
}

/// A number lanes are written over: `f64` or `f32`, every operation the
/// IEEE one (correctly rounded, never fused).
pub(crate) trait Real:
    Copy
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
{
    /// Whether sums in this type carry their rounding envelope (`f32`).
    const ROUNDED: bool;
    /// A constant, rounded to nearest (exact for the small constants and
    /// powers of two the crate writes).
    fn of(x: f64) -> Self;
    /// From an `f32` (exact in both).
    fn from_f32(x: f32) -> Self;
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    fn widen(self) -> f64;
}

impl Real for f64 {
    const ROUNDED: bool = false;
    #[inline(always)]
    fn of(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn from_f32(x: f32) -> Self {
        f64::from(x)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn widen(self) -> f64 {
        self
    }
}

impl Real for f32 {
    const ROUNDED: bool = true;
    #[inline(always)]
    fn of(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn from_f32(x: f32) -> Self {
        x
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f32::abs(self)
    }
    #[inline(always)]
    fn widen(self) -> f64 {
        f64::from(self)
    }
}

/// `N` values of a [`Real`], operated on lane by lane (four or eight `f32`
/// lanes fill one SSE or AVX2 vector): the children of a node bounded
/// together. Every operation is the scalar one per lane, so a lane's result
/// is the same bits in every compiled copy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Wide<T, const N: usize>(pub(crate) [T; N]);

impl<T: Real, const N: usize> Wide<T, N> {
    /// The same value in every lane.
    #[inline(always)]
    pub(crate) const fn splat(x: T) -> Self {
        Self([x; N])
    }

    /// The constant `x` in every lane.
    #[inline(always)]
    pub(crate) fn of(x: f64) -> Self {
        Self::splat(T::of(x))
    }

    /// A row of `f32` values.
    #[inline(always)]
    pub(crate) fn from_f32(row: &[f32; N]) -> Self {
        Self(array(T::default(), |i| T::from_f32(row[i])))
    }

    /// Each lane widened to `f64`.
    #[inline(always)]
    pub(crate) fn widen(self) -> Wide<f64, N> {
        Wide(array(0.0, |i| self.0[i].widen()))
    }

    #[inline(always)]
    fn map(self, f: impl Fn(T) -> T) -> Self {
        Self(array(T::default(), |i| f(self.0[i])))
    }

    #[inline(always)]
    fn zip(self, b: Self, f: impl Fn(T, T) -> T) -> Self {
        Self(array(T::default(), |i| f(self.0[i], b.0[i])))
    }

    /// Per lane `if a < b { a } else { b }`: the smaller, and `b` if either
    /// is NaN (like `f64::min` when `b` is not NaN).
    #[inline(always)]
    pub(crate) fn min(self, b: Self) -> Self {
        self.zip(b, |a, b| if a < b { a } else { b })
    }

    /// Per lane `if a > b { a } else { b }`: the larger, and `b` if either
    /// is NaN (like `f64::max` when `b` is not NaN).
    #[inline(always)]
    pub(crate) fn max(self, b: Self) -> Self {
        self.zip(b, |a, b| if a > b { a } else { b })
    }

    #[inline(always)]
    pub(crate) fn abs(self) -> Self {
        self.map(T::abs)
    }

    #[inline(always)]
    pub(crate) fn sqrt(self) -> Self {
        self.map(T::sqrt)
    }

    /// Per lane `if a >= b { x } else { y }`.
    #[inline(always)]
    pub(crate) fn select_ge(a: Self, b: Self, x: Self, y: Self) -> Self {
        Self(array(T::default(), |i| {
            if a.0[i] >= b.0[i] { x.0[i] } else { y.0[i] }
        }))
    }
}

macro_rules! wide_binary {
    ($trait:ident, $method:ident, $op:tt) => {
        impl<T: Real, const N: usize> $trait for Wide<T, N> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, b: Self) -> Self {
                self.zip(b, |a, b| a $op b)
            }
        }
    };
}

wide_binary!(Add, add, +);
wide_binary!(Sub, sub, -);
wide_binary!(Mul, mul, *);
wide_binary!(Div, div, /);

impl<T: Real, const N: usize> Neg for Wide<T, N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(|a| -a)
    }
}

impl<T: Real, const N: usize> AddAssign for Wide<T, N> {
    #[inline(always)]
    fn add_assign(&mut self, b: Self) {
        *self = *self + b;
    }
}

impl<T: Real, const N: usize> MulAssign for Wide<T, N> {
    #[inline(always)]
    fn mul_assign(&mut self, b: Self) {
        *self = *self * b;
    }
}

#[cfg(test)]
mod tests {
    use super::Wide;

    /// `min` and `max` agree with `f64::min` and `f64::max` whenever the
    /// second operand is a number, NaN first operands included.
    #[test]
    fn min_and_max_match_the_scalar_ones_for_a_numeric_second_operand() {
        let values = [f64::NAN, -1.0, 0.0, 0.5, f64::INFINITY, f64::NEG_INFINITY];
        for a in values {
            for b in values.into_iter().filter(|b| !b.is_nan()) {
                let (x, y) = (Wide::<f64, 1>([a]), Wide::<f64, 1>([b]));
                assert_eq!(x.min(y).0[0], a.min(b), "min({a}, {b})");
                assert_eq!(x.max(y).0[0], a.max(b), "max({a}, {b})");
            }
        }
    }
}
