//! Lambert's bound for a node of diffuse virtual point lights: members
//! that are one-sided cosine lobes of exponent 1 about one same axis `m`
//! (the lights instant radiosity leaves on a wall), seen from a point
//! that lies in front of all of them and whose tangent plane leaves all of
//! them above it. There each member's term is smooth in its position, and
//! a second-order expansion about the node's centroid bounds the node far
//! more tightly than the product of its isotropic interval and its
//! profile's range (which is first order in the node's size).
//!
//! # The expansion
//!
//! With `y = x - p` (member minus point), `n` the unit normal and `m' =
//! -m`, a member's term is `I kd g(y)` where `g(y) = a b / r^4`, `a = n.y`,
//! `b = m'.y`, `r = |y|` (the Lambert cosine `a / r` over `r^2`, times the
//! lobe's cosine `b / r`). Where `a > 0` and `b > 0` over the node's ball,
//! `g` is that smooth function there, and about `y0 = c - p` (`c` the
//! centroid):
//!
//! ```text
//! grad g = (b n + a m') / r^4 - 4 a b y / r^6
//! hess g = (n m'^T + m' n^T) / r^4 - 4 [(b n + a m') y^T + y (b n + a m')^T] / r^6
//!          - 4 a b I / r^6 + 24 a b y y^T / r^8
//! ```
//!
//! Summed over the members with their channel's intensities, the node's
//! channel `k` is `I_k kd_k (g + grad g . o_k + hess g : S_k / 2) + R_k`
//! (`o_k`, `S_k` the stored first and second moments about `c`).
//!
//! The remainder: `g = P f` with `P = a b` (`|P| <= r^2`, `|grad P| <= 2r`,
//! `|hess P| <= 2`, third derivative 0) and `f = r^-4`, whose `k`-th
//! derivative along a unit vector is at most `(4)_k r^(-4-k)` (the
//! Gegenbauer polynomials `C_k^(2)` are at most their value at 1, `(4)_k /
//! k!`). By Leibniz along a unit `e`, `|D^3 g[e, e, e]|` is at most `120 +
//! 3 (2)(20) + 3 (2)(4) = 264` over `r^5`, and for a symmetric tensor that
//! bounds its norm. On the segment from `c` to a member, `r >= D - R`, so
//! the member's remainder is at most `264 |h|^3 / (6 (D - R)^5)` with `h =
//! x - c` and `|h| <= R`; summed, `|R_k|` is at most `44 I_k kd_k R
//! tr(S_k) / (D - R)^5`.
//!
//! The stored moments differ from the exact ones by the build's rounding
//! bound `delta` (each entry of `o_k` within `delta R`, of `S_k` within
//! `delta R^2`, see [`Node::moment_error`]) and their rounding to `f32`
//! (`2^-24` of each entry, taken as `2^-23`); both enter the error through
//! the absolute gradient and Hessian entries.

use glam::DVec3;

use crate::geometry::{Cone, Surface};
use crate::shader::NodeEstimate;
use crate::tree::Node;

/// `(4)_3 / 3! + 3 (2)(4)_2 / 3! + 3 (2)(4)_1 / 3!`: the remainder's
/// constant `264 / 6` (module docs).
const REMAINDER: f64 = 44.0;

/// Relative rounding of a stored `f32` moment entry (`2^-24`), doubled.
const F32_ENTRY: f64 = f32::EPSILON as f64;

/// Relative allowance for the `f64` arithmetic of the expansion (a few
/// dozen operations on each term): far above their rounding, applied to
/// the sum of the terms' magnitudes so that cancellation cannot hide it.
const ARITHMETIC: f64 = 1e-13;

/// `[xx, yy, zz, xy, xz, yz]` entry of a symmetric matrix at `(i, j)`.
#[inline(always)]
fn entry(s: &[f32; 6], i: usize, j: usize) -> f64 {
    const AT: [[usize; 3]; 3] = [[0, 3, 4], [3, 1, 5], [4, 5, 2]];
    f64::from(s[AT[i][j]])
}

/// The node's certified interval where the expansion holds: every member
/// of `node` (seen under `cone` from `surface`'s point) a one-sided
/// cosine lobe of exponent 1 about the unit `axis`, albedo `kd`; `None`
/// where the ball reaches either plane (`a <= 0` or `b <= 0` somewhere on
/// it), where the member's terms have a kink.
#[inline]
pub(crate) fn diffuse_lobe_bound(
    node: &Node,
    surface: &Surface,
    cone: &Cone,
    axis: DVec3,
    kd: DVec3,
) -> Option<NodeEstimate> {
    let n = surface.normal;
    let m = -axis;
    let y = cone.offset;
    let (d, radius) = (cone.distance, cone.radius);
    let (a, b) = (n.dot(y), m.dot(y));
    // Clear of both planes by the ball's radius, with room for the
    // rounding of the dot products and of the unit vectors.
    let clear = radius + 1e-12 * d;
    if !(a > clear && b > clear) {
        return None;
    }
    let near = d - radius;
    if !(near > 0.0) {
        return None;
    }
    let r2 = d * d;
    let inv_r2 = 1.0 / r2;
    let inv_r4 = inv_r2 * inv_r2;
    let inv_r6 = inv_r4 * inv_r2;
    let ab = a * b;
    let g0 = ab * inv_r4;
    let mixed = b * n + a * m;
    let grad = mixed * inv_r4 - y * (4.0 * ab * inv_r6);
    let mut hess = [[0.0f64; 3]; 3];
    for (i, row) in hess.iter_mut().enumerate() {
        for (j, h) in row.iter_mut().enumerate() {
            let diagonal = if i == j { 1.0 } else { 0.0 };
            *h = (n[i] * m[j] + m[i] * n[j]) * inv_r4
                - 4.0 * (mixed[i] * y[j] + y[i] * mixed[j]) * inv_r6
                - 4.0 * ab * inv_r6 * diagonal
                + 24.0 * ab * inv_r6 * inv_r2 * y[i] * y[j];
        }
    }
    let near5 = {
        let n2 = near * near;
        n2 * n2 * near
    };
    let delta = node.moment_error();
    let intensity = node.intensity * kd;
    let mut estimate = DVec3::ZERO;
    let mut error = DVec3::ZERO;
    for k in 0..3 {
        if intensity[k] == 0.0 {
            continue;
        }
        let o = node.channel_offsets[k].as_dvec3();
        let s = &node.channel_covariances[k];
        let first = grad.dot(o);
        let mut second = 0.0;
        let mut second_abs = 0.0;
        let mut moments = 0.0;
        for (i, row) in hess.iter().enumerate() {
            for (j, &h) in row.iter().enumerate() {
                let sij = entry(s, i, j);
                second += h * sij;
                second_abs += (h * sij).abs();
                moments += h.abs() * (delta * radius * radius + F32_ENTRY * sij.abs());
            }
        }
        second *= 0.5;
        let first_moments: f64 = (0..3)
            .map(|i| grad[i].abs() * (delta * radius + F32_ENTRY * o[i].abs()))
            .sum();
        let trace = (entry(s, 0, 0) + entry(s, 1, 1) + entry(s, 2, 2)) * (1.0 + 2.0 * F32_ENTRY)
            + 3.0 * delta * radius * radius;
        let trace = trace.min(radius * radius).max(0.0);
        let remainder = REMAINDER * radius * trace / near5;
        let arithmetic = ARITHMETIC * (g0.abs() + first.abs() + 0.5 * second_abs);
        estimate[k] = intensity[k] * (g0 + first + second);
        error[k] = intensity[k] * (remainder + first_moments + 0.5 * moments + arithmetic);
    }
    let lower = (estimate - error).max(DVec3::ZERO);
    Some(NodeEstimate::new(estimate, lower, estimate + error))
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::emission::Emission;
    use crate::{Lambert, LightTree, PointLight};

    /// A wall of VPLs at `x = 0` facing `+x`, seen from points in front of
    /// it: every node the expansion takes holds its exact sum, and is far
    /// tighter than the node's radius would make a first-order bound.
    #[test]
    fn the_expansion_holds_every_node_it_takes() {
        let mut seed = 11u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) as f32
        };
        let lights: Vec<_> = (0..3000)
            .map(|_| {
                let at = Vec3::new(0.0, 10.0 * next(), 3.0 * next());
                let colour = Vec3::new(next(), next(), next()) + Vec3::splat(0.1);
                PointLight::new(at, colour).with_emission(Emission::cosine(Vec3::X, 1.0))
            })
            .collect();
        let tree = LightTree::builder()
            .max_leaf_lights(4)
            .build_emitters(&lights)
            .unwrap();
        let kd = DVec3::new(0.7, 0.5, 0.3);
        let shading = tree.shading(Lambert::new(kd.as_vec3()));
        let mut taken = 0;
        for _ in 0..200 {
            let p = Vec3::new(0.5 + 8.0 * next(), 12.0 * next() - 1.0, 4.0 * next() - 0.5);
            let normal = Vec3::new(next() - 0.9, next() - 0.5, next() - 0.5);
            let Ok(surface) = Surface::new(p, normal, None) else {
                continue;
            };
            for (index, node) in tree.nodes().iter().enumerate() {
                let Some(cone) = node.cone(surface.point) else {
                    continue;
                };
                let Some(b) = diffuse_lobe_bound(node, &surface, &cone, DVec3::X, kd) else {
                    continue;
                };
                taken += 1;
                let mut exact = DVec3::ZERO;
                for i in node.lights() {
                    let l = tree.lights()[i];
                    let c = tree.profile(i).factor(l.position, surface.point);
                    let d = l.position.as_dvec3() - surface.point;
                    let h = surface.normal.dot(d);
                    if h > 0.0 {
                        exact += l.intensity.as_dvec3() * kd * (h * c / d.length().powi(3));
                    }
                }
                let slack = 1e-9 * exact.max_element();
                assert!(
                    (b.lower - exact).max_element() <= slack
                        && (exact - b.upper).max_element() <= slack,
                    "node {index}: {exact} outside [{}, {}]",
                    b.lower,
                    b.upper
                );
            }
        }
        assert!(taken > 1000, "{taken}");
        let _ = shading;
    }
}
