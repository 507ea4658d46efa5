//! The multipole series bound ([`BoundKind::Series`](super::BoundKind)),
//! written over [`Lanes`]: one node, or up to eight side by side.

use glam::DVec3;

use crate::lanes::{Lanes, Vec3Lanes};
use crate::numeric::{POINT_SLACK, SERIES_SLACK};
use crate::tree::Node;

/// Per channel, one value per lane.
pub(super) type Rgb<const N: usize> = [Lanes<N>; 3];

/// `[f(0), f(1), f(2)]`.
#[inline(always)]
pub(super) fn rgb<const N: usize>(mut f: impl FnMut(usize) -> Lanes<N>) -> Rgb<N> {
    [f(0), f(1), f(2)]
}

/// The tail sums from degree 6 for `sigma < 1` and `inv_rho = 1 / (1 - sigma)`:
/// `G1 = sum_(j>=0) (7 + j) sigma^j = 7 / (1 - sigma) + sigma / (1 - sigma)^2`
/// and `G2 = sum_(j>=0) (6 + j)(7 + j) / 2 sigma^j
/// = [42 / (1 - sigma) + 13 sigma / (1 - sigma)^2 + sigma (1 + sigma) / (1 - sigma)^3] / 2`
/// (from `sum j sigma^j = sigma / (1 - sigma)^2` and
/// `sum j^2 sigma^j = sigma (1 + sigma) / (1 - sigma)^3`).
#[inline(always)]
pub(super) fn tail_sums<const N: usize>(
    sigma: Lanes<N>,
    inv_rho: Lanes<N>,
) -> (Lanes<N>, Lanes<N>) {
    let g1 = 7.0 * inv_rho + sigma * inv_rho * inv_rho;
    let g2 = 0.5 * inv_rho * (42.0 + inv_rho * sigma * (13.0 + (1.0 + sigma) * inv_rho));
    (g1, g2)
}

/// What the series width reads of each lane's node and point.
pub(super) struct WidthInput<const N: usize> {
    /// `1 / D`.
    pub(super) inv_d: Lanes<N>,
    /// `sigma = R / D`.
    pub(super) sigma: Lanes<N>,
    /// `D / (D - R)`.
    pub(super) inv_rho: Lanes<N>,
    /// `|c0|`, widened.
    pub(super) ac: Lanes<N>,
    /// `nu^2`, widened.
    pub(super) nu2: Lanes<N>,
    /// `hperp / D`, widened.
    pub(super) hperp: Lanes<N>,
}

/// The width of the series interval, per channel in units of `I_k / D^2`:
/// the remainder from degree 3 (harmonic norms for degrees 3 to 5, the tail
/// from degree 6; see [`Lambert`](super::Lambert)) and the rounding slack.
#[inline(always)]
pub(super) fn series_width<const N: usize>(nodes: &[&Node; N], w: &WidthInput<N>) -> Rgb<N> {
    let (inv_d, sigma, inv_rho) = (w.inv_d, w.sigma, w.inv_rho);
    let (ac, nu2, hperp) = (w.ac, w.nu2, w.hperp);
    let inv_d2 = inv_d * inv_d;
    let c2 = ac * ac;
    // A_m for m = 3, 4, 5.
    let harmonic = |m: f64| (c2 * (m + 1.0) * (m + 1.0) + nu2 * (0.5 * m * (m + 1.0))).sqrt();
    let harmonics = [harmonic(3.0), harmonic(4.0), harmonic(5.0)];
    // Tail from degree 6.
    let (g1, g2) = tail_sums(sigma, inv_rho);
    let sigma3 = sigma * sigma * sigma;
    let widen = 1.0 + SERIES_SLACK * inv_rho;
    let moment_error = Lanes::from_fn(|i| nodes[i].moment_error());
    let sums = 2.0 * moment_error * sigma * (1.0 + 18.0 * sigma);
    let point = POINT_SLACK * inv_rho * inv_rho * inv_rho;
    let mut width = [Lanes::splat(0.0); 3];
    for (k, width) in width.iter_mut().enumerate() {
        // Euclidean norms of the offsets bounded by their 1-norms.
        let o = Vec3Lanes::from_fn(|i| nodes[i].channel_offsets[k].as_dvec3().to_array());
        let offset_lens = o.abs().element_sum() * inv_d;
        let cov = |j: usize| Lanes::from_fn(|i| f64::from(nodes[i].channel_covariances[k][j]));
        let mu2 = (cov(0) + cov(1) + cov(2)) * inv_d2;
        let mut remainder = Lanes::splat(0.0);
        // mu_(m-1) <= sigma^(m-3) mu_2 and sigma^m, from m = 3.
        let mut mu_prev = mu2;
        let mut sigma_m = sigma3;
        for (d, harmonic) in harmonics.into_iter().enumerate() {
            let m = (d + 3) as f64;
            let q = Lanes::from_fn(|i| f64::from(nodes[i].harmonic_norms[d][k])) * sigma_m;
            let across = q * (ac * (m + 1.0)) + mu_prev * (hperp * 0.5 * m * (m + 1.0));
            remainder += (q * harmonic).min(across);
            mu_prev *= sigma;
            sigma_m *= sigma;
        }
        // mu_5 = mu_prev, mu_6 <= sigma mu_5.
        let tail = mu_prev * sigma * g1;
        remainder += tail.min(tail * ac + mu_prev * (hperp * g2));
        let slack = SERIES_SLACK * (1.0 + offset_lens + mu2)
            + f32::EPSILON as f64 * (offset_lens + 33.0 * mu2)
            + sums
            + point;
        *width = remainder * widen + slack;
    }
    width
}

/// The multipole series of `g` through degree 2, summed over each lane's
/// node's members, per channel in units of `I_k / D^2` (see
/// [`Lambert`](super::Lambert)'s docs), for the unit normal `n` and the
/// lanes' unit axes `uh` and `1 / D`:
/// `c0 + (n.o - 3 c0 uh.o) / D + (15 c0 uh.S.uh - 3 c0 tr S - 6 uh.S.n) / (2 D^2)`.
/// The node bound and the shared cuts of batch shading both evaluate it
/// here, so its rounding is the one [`SERIES_SLACK`] accounts for.
#[inline(always)]
pub(super) fn degree_two_lanes<const N: usize>(
    n: DVec3,
    uh: Vec3Lanes<N>,
    inv_d: Lanes<N>,
    nodes: &[&Node; N],
) -> Rgb<N> {
    let c0 = uh.dot_with(n.to_array());
    let grad = Vec3Lanes::scaled_from(n.to_array(), 3.0 * c0, uh);
    // The degree-2 bracket is linear in S: one weight per stored entry
    // [xx, yy, zz, xy, xz, yz], shared by the three channels.
    let (a, b) = (15.0 * c0, 3.0 * c0);
    let weights = [
        a * uh.x * uh.x - b - 6.0 * uh.x * n.x,
        a * uh.y * uh.y - b - 6.0 * uh.y * n.y,
        a * uh.z * uh.z - b - 6.0 * uh.z * n.z,
        2.0 * a * uh.x * uh.y - 6.0 * (uh.x * n.y + uh.y * n.x),
        2.0 * a * uh.x * uh.z - 6.0 * (uh.x * n.z + uh.z * n.x),
        2.0 * a * uh.y * uh.z - 6.0 * (uh.y * n.z + uh.z * n.y),
    ];
    let half_inv_d2 = 0.5 * inv_d * inv_d;
    let mut series = [Lanes::splat(0.0); 3];
    for (k, series) in series.iter_mut().enumerate() {
        let o = Vec3Lanes::from_fn(|i| nodes[i].channel_offsets[k].as_dvec3().to_array());
        let first = grad.dot(o) * inv_d;
        let mut second = Lanes::splat(0.0);
        for (j, weight) in weights.into_iter().enumerate() {
            second += Lanes::from_fn(|i| f64::from(nodes[i].channel_covariances[k][j])) * weight;
        }
        *series = c0 + first + second * half_inv_d2;
    }
    series
}

#[cfg(test)]
mod tests {
    use super::tail_sums;
    use crate::lanes::Wide;

    /// The closed forms of the tail sums against the series summed term by
    /// term.
    #[test]
    fn tail_sums_match_their_series() {
        for i in 0..=99 {
            let sigma = f64::from(i) / 100.0;
            let (g1, g2) = tail_sums(Wide::<f64, 1>([sigma]), Wide([1.0 / (1.0 - sigma)]));
            let (g1, g2) = (g1.0[0], g2.0[0]);
            let (mut s1, mut s2, mut power) = (0.0, 0.0, 1.0);
            for j in 0..20_000 {
                let j = f64::from(j);
                s1 += (7.0 + j) * power;
                s2 += (6.0 + j) * (7.0 + j) / 2.0 * power;
                power *= sigma;
            }
            assert!(
                (g1 - s1).abs() <= 1e-12 * s1,
                "G1 at {sigma}: {g1} against {s1}"
            );
            assert!(
                (g2 - s2).abs() <= 1e-12 * s2,
                "G2 at {sigma}: {g2} against {s2}"
            );
        }
    }
}
