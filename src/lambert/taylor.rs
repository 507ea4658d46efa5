//! The second-order Taylor interval of one node ([`BoundKind::Taylor`](super::BoundKind::Taylor),
//! derived in `proofs`), from the geometry `node` computes for every kind.

use glam::{DVec3, Vec3};

use super::Lambert;
use crate::geometry::{Cone, Surface};
use crate::numeric::{COS_SLACK, SECOND_ORDER_SLACK};
use crate::tree::Node;

/// `e^T S e` for the symmetric matrix stored as `[xx, yy, zz, xy, xz, yz]`.
#[inline(always)]
fn quadratic_form(s: &[f64; 6], e: DVec3) -> f64 {
    s[0] * e.x * e.x
        + s[1] * e.y * e.y
        + s[2] * e.z * e.z
        + 2.0 * (s[3] * e.x * e.y + s[4] * e.x * e.z + s[5] * e.y * e.z)
}

/// What the Taylor bound reads of the shared geometry, for one node.
pub(super) struct Geometry<'a> {
    pub(super) surface: &'a Surface,
    pub(super) node: &'a Node,
    pub(super) cone: &'a Cone,
    /// `I kd / D^2` per channel.
    pub(super) scale: DVec3,
    /// `n . uh`.
    pub(super) z: f64,
    /// `|n x uh|`.
    pub(super) sin_c: f64,
    /// `D / (D - R)`.
    pub(super) inv_rho: f64,
    /// Bound on `sum (f - g) / I` in units of `1/D^2`.
    pub(super) straddle: f64,
}

impl Lambert {
    /// The second-order Taylor interval `(lower, upper, estimate)`.
    #[inline]
    pub(super) fn taylor(&self, geo: &Geometry<'_>) -> (DVec3, DVec3, Option<DVec3>) {
        let (surface, node, cone, scale) = (geo.surface, geo.node, geo.cone, geo.scale);
        let n = surface.normal;
        let (z, sin_c, inv_rho) = (geo.z, geo.sin_c, geo.inv_rho);
        let inv_d = cone.inv_distance;
        let sd = cone.sin_half_angle;
        let inv_rho3 = inv_rho * inv_rho * inv_rho;
        // Second order, in units of D. Gradient of z/r^3 at the unit axis.
        let grad = n - 3.0 * z * cone.axis;
        // Its Euclidean norm bounded by its 1-norm, for the rounding slack.
        let grad_len = grad.abs().element_sum();
        let o = node.channel_offsets;
        let offsets = DVec3::new(
            grad.dot(o[0].as_dvec3()),
            grad.dot(o[1].as_dvec3()),
            grad.dot(o[2].as_dvec3()),
        ) * inv_d;
        // Euclidean norms bounded by the 1-norms (no square roots).
        let l1 = |v: Vec3| f64::from(v.abs().element_sum());
        let offset_lens = DVec3::new(l1(o[0]), l1(o[1]), l1(o[2])) * inv_d;
        let first_order = scale * offsets;
        // Taylor estimate of the smooth g = z/r^3 (not clamped at 0).
        let smooth = scale * z + first_order;
        let straddle = scale * geo.straddle;

        // Hessian entry bounds over the ball.
        // Ratios to the nearest distance, capped at 1: |a|/r, |b|/r, |z|/r.
        let ratio = |x: f64| (x * inv_rho).min(1.0);
        let z_abs_max = z.abs() + sd;
        let (r_a, r_b, r_z) = (ratio(sin_c + sd), ratio(sd), ratio(z_abs_max));
        let (t_a, t_b, t_z) = (r_a * r_a, r_b * r_b, r_z * r_z);
        let p4 = inv_rho3 * inv_rho;
        let q = z_abs_max * p4 * inv_rho;
        let h11 = q * (15.0 * t_a - 3.0).max(3.0);
        let h22 = q * (15.0 * t_b - 3.0).max(3.0);
        let h33 = 9.0 * q;
        let h12 = 15.0 * q * (r_a * r_b).min(0.5);
        let mixed_z = p4 * (15.0 * t_z - 3.0).max(3.0);
        let h13 = r_a * mixed_z;
        let h23 = r_b * mixed_z;

        // Second moments along the local frame, in units of D^2.
        // |axis - z n| = sin_c for unit n and axis.
        let e1 = if sin_c > 0.0 {
            (cone.axis - z * n) / sin_c
        } else {
            n.any_orthonormal_vector()
        };
        let e2 = n.cross(e1);
        let inv_d2 = inv_d * inv_d;
        let traces = node.mean_squared_radii() * inv_d2;
        let mut remainder_unit = DVec3::ZERO;
        for k in 0..3 {
            let cov = &node.channel_covariances[k].map(f64::from);
            let trace = traces[k];
            let pad = f32::EPSILON as f64 * trace;
            let s11 = (quadratic_form(cov, e1) * inv_d2).max(0.0) + pad;
            let s22 = (quadratic_form(cov, e2) * inv_d2).max(0.0) + pad;
            let s33 = (quadratic_form(cov, n) * inv_d2).max(0.0) + pad;
            let (d1, d2, d3) = (s11.sqrt(), s22.sqrt(), s33.sqrt());
            let per_axis = 0.5
                * (h11 * s11
                    + h22 * s22
                    + h33 * s33
                    + 2.0 * (h12 * d1 * d2 + h13 * d1 * d3 + h23 * d2 * d3));
            let isotropic = 3.0 * p4 * trace;
            remainder_unit[k] = per_axis.min(isotropic) * (1.0 + SECOND_ORDER_SLACK);
        }
        let remainder = scale * remainder_unit;
        // The cosine z carries an absolute error (up to COS_SLACK) that a
        // relative slack of |z| misses when z is near 0.
        // The build's f64 moment sums, as for the series bound.
        let sums = 2.0 * node.moment_error() * sd * (1.0 + 18.0 * sd);
        let rounding = SECOND_ORDER_SLACK * (scale * z.abs() + first_order.abs() + straddle)
            + COS_SLACK * scale
            + f32::EPSILON as f64 * scale * grad_len * offset_lens
            + scale * sums;
        let lo2 = smooth - remainder - rounding;
        let hi2 = smooth + remainder + straddle + rounding;
        (lo2, hi2, Some(smooth + 0.5 * straddle))
    }
}
