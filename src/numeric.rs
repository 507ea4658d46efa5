//! Rounding: the compensated sum, outward rounding to `f32`, and every
//! slack the certified bounds widen by, each with its derivation.
//!
//! The contract (see [`ShadeResult::ROUNDING_ALLOWANCE`](crate::ShadeResult::ROUNDING_ALLOWANCE))
//! lets *relative* rounding of order `1e-12` pass; everything that can
//! cancel (cosines near 0, Taylor sums whose terms cancel) is widened here by
//! an *absolute* amount instead, so no bound is lost to rounding.

use glam::DVec3;

/// Absolute widening of every cosine bound computed by
/// [`Cone::cos_range`](crate::Cone::cos_range).
///
/// The cosine and sine of the angle to the cone's axis come from a dot and a
/// cross product of unit `f64` vectors, each within a few `f64::EPSILON` of
/// the exact value; the sum-of-angles formula adds two products. `16 *
/// f64::EPSILON` (about `3.6e-15`) covers the accumulated absolute error, so
/// the returned range contains every true cosine even when it is near 0,
/// where a relative allowance would not help.
pub const COS_SLACK: f64 = 16.0 * f64::EPSILON;

/// Relative allowance for `f64` rounding in [`Lambert`](crate::Lambert)'s
/// second-order estimate: it is a sum of a handful of products, each within
/// a few ulps; the slack is applied to the magnitudes of its terms, so it
/// stays valid when they cancel. `64 * f64::EPSILON` is about `1.4e-14`.
pub const SECOND_ORDER_SLACK: f64 = 64.0 * f64::EPSILON;

/// Relative widening of a cut's summed error bound for the rounding of its
/// compensated sum: within two ulps of the sum of magnitudes (the terms are
/// non-negative); 8 leaves margin.
pub const SUM_SLACK: f64 = 8.0 * f64::EPSILON;

/// Relative inflation applied to distances and second moments computed in
/// `f64` at build time before they are rounded upward to `f32`: an `f64`
/// length of a difference carries at most a few ulps (`2^-52` each) of
/// error, so `8 * f64::EPSILON` covers it with margin.
pub const BUILD_LENGTH_SLACK: f64 = 8.0 * f64::EPSILON;

/// Relative tolerance of [`LightTree::validate`](crate::LightTree::validate)
/// when it compares a node's stored intensity with the sum of its children's:
/// both are `f64` sums of the same `f32` values in different orders, which
/// agree to `n * f64::EPSILON` relative for `n` terms; `1e-9` covers a
/// million lights with margin.
pub const SUM_TOLERANCE: f64 = 1e-9;

/// Rounds a non-negative `f64` up to the nearest `f32` at or above it, so a
/// stored radius or moment never understates the value it bounds.
#[must_use]
pub(crate) fn round_up_f32(x: f64) -> f32 {
    let y = x as f32;
    if f64::from(y) < x { y.next_up() } else { y }
}

/// Neumaier-compensated sum of `DVec3`s: accurate to about two ulps of the
/// sum of magnitudes, whatever the number of terms.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct CompensatedSum {
    sum: DVec3,
    compensation: DVec3,
}

impl CompensatedSum {
    #[inline]
    pub(crate) fn add(&mut self, term: DVec3) {
        let t = self.sum + term;
        let big = self.sum.abs().cmpge(term.abs());
        self.compensation += DVec3::select(big, (self.sum - t) + term, (term - t) + self.sum);
        self.sum = t;
    }

    #[inline]
    #[must_use]
    pub(crate) fn value(&self) -> DVec3 {
        self.sum + self.compensation
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_up_never_rounds_down() {
        for x in [0.1f64, 1.0 / 3.0, 1e-40, 3.4e38, 0.0, 1.0] {
            assert!(f64::from(round_up_f32(x)) >= x, "{x}");
        }
    }

    #[test]
    fn compensated_sum_recovers_cancelled_terms() {
        let mut s = CompensatedSum::default();
        for t in [1e16, 1.0, -1e16, 1.0] {
            s.add(DVec3::splat(t));
        }
        assert_eq!(s.value(), DVec3::splat(2.0));
    }
}
