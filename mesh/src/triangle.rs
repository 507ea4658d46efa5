//! The segment-triangle test of the shadow rays and the test of a triangle
//! (or a planar quad of two) blocking every segment between two boxes.
//!
//! # The test
//!
//! For a segment from `o` to `q` (`d = q - o`) and a triangle `(a, b, c)`,
//! all relative to `o` (`A = a - o`, ...), in `f64`:
//!
//! * the *edge functions* `U = d . (B x C)`, `V = d . (C x A)`,
//!   `W = d . (A x B)`: the line through `o` and `q` passes through the
//!   triangle when they share a sign (not all zero);
//! * `det = U + V + W = d . N` and `T = A . (B x C) = N . A`, `N` the
//!   triangle's normal: the line crosses the triangle's plane at parameter
//!   `T / det`, which must lie in `[t_min, 1]` (`t_min` the
//!   self-intersection offset over the segment's length).
//!
//! Each edge function depends on the edge's two vertices only, through
//! their cross product, which is exactly antisymmetric in floating point
//! (`x y - z w` and `z w - x y` round to opposite values, and so do their
//! dot products with `d`): two triangles sharing an edge compute exactly
//! opposite values for it, so a segment through the shared edge hits one
//! of them (the test is watertight along shared edges).
//!
//! # Rounding
//!
//! Coordinates are `f32`; their differences are formed in `f64`, where
//! they are exact whenever the two exponents differ by at most 29 (and
//! within `2^-53` relative otherwise), and every predicate is a sum of
//! products of three differences, computed with at most about ten
//! roundings of `2^-53`: its error is below `2^-46 M^3`, `M` a bound on the
//! coordinates' differences (`6 M^3` bounds the sum of the terms' absolute
//! values). A blocker is accepted only when every predicate clears
//! [`PREDICATE_SLACK`]` M^3` at every pair of corners; each predicate is
//! affine in the segment's start and in its end separately, so it then
//! clears it, less twice the error, at every pair of points of the two
//! boxes, and the computed predicates of every segment have the signs of a
//! hit.

use glam::{DVec3, Vec3};
use manylights::Aabb;

use crate::bvh::distinct_corners;

/// A predicate of a blocker must exceed this times `M^3` (`M` bounding the
/// differences of the coordinates involved) at every pair of corners: far
/// above the predicates' rounding error, below `2^-46 M^3` (see the module
/// documentation), and far below any predicate of a segment that passes
/// through a triangle by more than a rounding error.
pub const PREDICATE_SLACK: f64 = 1.0 / (1u64 << 40) as f64;

/// The three edge normals of the triangle `v` seen from `o`, `B x C`,
/// `C x A`, `A x B` (relative to `o`), and `T = A . (B x C)`.
#[inline(always)]
fn edges(o: DVec3, v: &[Vec3; 3]) -> ([DVec3; 3], DVec3, f64) {
    let [a, b, c] = v.map(|p| p.as_dvec3() - o);
    let bc = b.cross(c);
    ([bc, c.cross(a), a.cross(b)], a, a.dot(bc))
}

/// Whether the segment from `from` to `to` crosses the closed triangle `v`
/// at a parameter in `[t_min, 1]` (see the module documentation).
#[inline]
pub(crate) fn crosses(from: Vec3, to: Vec3, t_min: f64, v: &[Vec3; 3]) -> bool {
    let o = from.as_dvec3();
    let d = to.as_dvec3() - o;
    let ([bc, ca, ab], _, t) = edges(o, v);
    let (u, w, x) = (d.dot(bc), d.dot(ca), d.dot(ab));
    let positive = u >= 0.0 && w >= 0.0 && x >= 0.0;
    let negative = u <= 0.0 && w <= 0.0 && x <= 0.0;
    if !(positive || negative) {
        return false;
    }
    let det = u + w + x;
    if det == 0.0 {
        return false;
    }
    let s = det.signum();
    s * t >= t_min * (s * det) && s * (det - t) >= 0.0
}

/// Whether the triangles `tris` (one, or two sharing an edge and forming a
/// planar convex quad), with the edges `outer` (for each triangle, which
/// of its edges `bc`, `ca`, `ab` lie on the quad's boundary), block every
/// segment from a point of `from` to a point of `to` robustly: every
/// segment's computed test hits one of them (see the module documentation),
/// at a parameter of at least `t_min_bound`, which must be at least the
/// offset over the length of every such segment.
///
/// `m` bounds the coordinates' differences (`M`).
pub(crate) fn blocks(
    tris: &[[Vec3; 3]],
    outer: &[[bool; 3]],
    from: &Aabb,
    to: &Aabb,
    t_min_bound: f64,
    m: f64,
) -> bool {
    let slack = PREDICATE_SLACK * m * m * m;
    let (mut ends, mut count) = ([DVec3::ZERO; 8], 0);
    for q in distinct_corners(to) {
        ends[count] = q.as_dvec3();
        count += 1;
    }
    let ends = &ends[..count];
    let mut sign = 0.0;
    for p in distinct_corners(from) {
        let o = p.as_dvec3();
        for (tri, outer) in tris.iter().zip(outer) {
            let (normals, _, t) = edges(o, tri);
            if sign == 0.0 {
                sign = t.signum();
            }
            for &q in ends {
                let d = q - o;
                let [u, w, x] = normals.map(|n| sign * d.dot(n));
                let det = u + w + x;
                let st = sign * t;
                // The quad's outer edges, each clear of the segment.
                for (value, &edge) in [u, w, x].iter().zip(outer) {
                    if edge && !(*value >= slack) {
                        return false;
                    }
                }
                // The crossing, inside the segment's range, for each
                // triangle.
                if !(st - t_min_bound * det >= slack && det - st >= slack) {
                    return false;
                }
            }
        }
    }
    sign != 0.0
}

/// Whether no segment from a point of `from` to a point of `to` can hit the
/// triangle `v` past the offset, robustly: every segment meets the
/// triangle's plane (if at all) at a parameter below `t_min_bound`, which
/// must be at most `1` and at most the offset over the length of every
/// such segment. This is the surface a shading point lies on (or one it
/// faces from within the offset), which its shadow rays skip.
///
/// Every predicate, `s det = s d . N` (the segment crosses the plane in
/// one direction, `s` its sign) and `t_min_bound s det - s T` (the crossing
/// comes before `t_min_bound`), must clear [`PREDICATE_SLACK`]` M^3` at
/// every pair of corners. Both are affine in each end separately, so they
/// clear it, less twice their error, at every pair of points, and the shadow
/// ray's computed test `s T >= t_min (s det)` fails for every segment: its
/// `t_min` is at least `t_min_bound`, and its roundings are far below the
/// slack (see the module documentation).
pub(crate) fn clears(v: &[Vec3; 3], from: &Aabb, to: &Aabb, t_min_bound: f64, m: f64) -> bool {
    let slack = PREDICATE_SLACK * m * m * m;
    let (mut ends, mut count) = ([DVec3::ZERO; 8], 0);
    for q in distinct_corners(to) {
        ends[count] = q.as_dvec3();
        count += 1;
    }
    let ends = &ends[..count];
    let mut sign = 0.0;
    for p in distinct_corners(from) {
        let o = p.as_dvec3();
        let ([bc, ca, ab], _, t) = edges(o, v);
        for &q in ends {
            // As the shadow ray sums it.
            let d = q - o;
            let det = d.dot(bc) + d.dot(ca) + d.dot(ab);
            if sign == 0.0 {
                sign = det.signum();
            }
            let (sdet, st) = (sign * det, sign * t);
            if !(sdet >= slack && t_min_bound * sdet - st >= slack) {
                return false;
            }
        }
    }
    sign != 0.0
}
