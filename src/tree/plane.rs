//! Coplanar nodes: nodes whose lights all lie exactly in one plane, found
//! when the tree is built, so that a shading point whose tangent plane is
//! exactly parallel to that plane and not below it (lights on a tilted
//! roof, shading the roof or a point just above it) is recognised as
//! receiving exactly nothing from the whole node.
//!
//! Axis-aligned boxes already settle a plane perpendicular to an axis
//! exactly (a box of zero thickness lies in its tangent plane); a tilted
//! plane needs a statistic exact along its normal. Both tests here are
//! exact: coordinates are `f32` values, which on a common power-of-two grid
//! are integers; where they fit in [`GRID_BITS`] bits the determinants are
//! computed in `i128` without rounding, and elsewhere no plane is recorded
//! (the ordinary bounds apply, as for any node).

use glam::{DVec3, Vec3};

use super::layout::{LightTree, NO_PLANE};
use super::node::Node;
use super::notes::Notes;
use super::pool::Pool;
use crate::numeric::dot_of_difference;

/// Bits of the integers coordinates become on a node's grid: differences
/// take 41 bits, the plane's normal (a cross product of differences) 83,
/// and its dot product with a difference (three products summed) under
/// 126, within `i128`. The normal's cross product with a caller's normal
/// (41-bit integers on their own grid) stays under 126 bits too.
const GRID_BITS: i32 = 40;

/// Nodes of fewer lights are not examined: a cut sums small nodes light by
/// light soon enough.
const MIN_LIGHTS: u32 = 8;

/// Lights tried for a third point spanning the plane.
const SEARCH: usize = 64;

/// The grid of spacing `2^e`, `e` chosen from the largest magnitude of the
/// coordinates to be placed on it so that every one is below
/// `2^GRID_BITS` cells.
#[derive(Clone, Copy, Debug)]
struct Grid {
    /// `2^-e`.
    scale: f64,
}

impl Grid {
    /// The grid for coordinates of magnitude at most `largest` (an `f32`
    /// value); `None` where `2^-e` leaves the `f64` range.
    fn for_largest(largest: f64) -> Option<Self> {
        if largest == 0.0 {
            return Some(Self { scale: 1.0 });
        }
        // largest < 2^(exponent + 1); cells of 2^(exponent + 1 - GRID_BITS).
        let exponent = ((largest.to_bits() >> 52) & 0x7ff) as i32 - 1023;
        let scale = power_of_two(GRID_BITS - 1 - exponent)?;
        Some(Self { scale })
    }

    /// The integer coordinates of an `f32`-valued point, `None` when a
    /// coordinate is not a whole number of cells (its exponent is too far
    /// below the largest) or exceeds the grid.
    fn point(&self, p: DVec3) -> Option<[i64; 3]> {
        let mut out = [0i64; 3];
        for (k, o) in out.iter_mut().enumerate() {
            // A power-of-two scaling is exact away from overflow and
            // underflow, both excluded by the range of `f32` values.
            let v = p[k] * self.scale;
            // Below 2^GRID_BITS (which NaN is not), `v as i64` drops the
            // fraction and is exact back in `f64`: equal to `v` exactly
            // when `v` is a whole number.
            if !(v.abs() < GRID_LIMIT) {
                return None;
            }
            let i = v as i64;
            if i as f64 != v {
                return None;
            }
            *o = i;
        }
        Some(out)
    }
}

/// `2^GRID_BITS`, the bound of a grid's integer coordinates.
const GRID_LIMIT: f64 = (1u64 << GRID_BITS) as f64;

/// `2^k` built from its bits, `None` outside `f64`'s normal range (for an
/// `f32` coordinate's grid `k` lies in `[-88, 188]`).
fn power_of_two(k: i32) -> Option<f64> {
    (-1022..=1023)
        .contains(&k)
        .then(|| f64::from_bits(((k + 1023) as u64) << 52))
}

/// Integer coordinates of `f32`-valued points on the [`Grid`] of their
/// largest magnitude, or `None`.
fn on_grid<const N: usize>(points: [DVec3; N]) -> Option<[[i64; 3]; N]> {
    let largest = points
        .iter()
        .map(|p| p.abs().max_element())
        .fold(0.0f64, f64::max);
    let grid = Grid::for_largest(largest)?;
    let mut out = [[0i64; 3]; N];
    for (p, o) in points.iter().zip(&mut out) {
        *o = grid.point(*p)?;
    }
    Some(out)
}

fn sub(a: [i64; 3], b: [i64; 3]) -> [i128; 3] {
    [
        i128::from(a[0]) - i128::from(b[0]),
        i128::from(a[1]) - i128::from(b[1]),
        i128::from(a[2]) - i128::from(b[2]),
    ]
}

fn cross(u: [i128; 3], v: [i128; 3]) -> [i128; 3] {
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

fn dot(u: [i128; 3], v: [i128; 3]) -> i128 {
    u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
}

/// Three lights of `node` spanning a plane that holds them all, exactly;
/// `None` if they are collinear, not coplanar, or off the grid of the
/// node's box (which bounds every light's coordinates).
fn spanning_plane(tree: &LightTree, node: &Node) -> Option<[u32; 3]> {
    let range = node.lights();
    let first = range.start;
    let lights = &tree.lights[range];
    let n = lights.len();
    // Four lights certainly off one plane: then no plane holds them all,
    // whichever three the exact test would take. The first three and the
    // last, in two or three cache lines (the exact test reads them too).
    if n >= 4 {
        let at = |k: usize| lights[k].position;
        if certainly_not_coplanar(at(0), at(1), at(2), at(n - 1)) {
            return None;
        }
    }
    let grid = Grid::for_largest(f64::from(
        node.aabb.min.abs().max(node.aabb.max.abs()).max_element(),
    ))?;
    let point = |k: usize| grid.point(lights[k].position.as_dvec3());
    let a = point(0)?;
    let b = (1..lights.len()).find(|&k| point(k).is_some_and(|p| p != a))?;
    let ab = sub(point(b)?, a);
    // Lights on a line (a row of lamps) span no plane; the search for a
    // third point off the line gives up after a few.
    let (c, normal) = (b + 1..lights.len().min(b + 1 + SEARCH)).find_map(|k| {
        let normal = cross(ab, sub(point(k)?, a));
        (normal != [0; 3]).then_some((k, normal))
    })?;
    // |normal| < 2^83 and |d - a| < 2^41 per coordinate: the dot product
    // stays under 2^126. Lights spread through the run first: most nodes
    // that are not planar show it at once.
    for k in [n - 1, n / 2, n / 4, 3 * n / 4].into_iter().chain(1..n) {
        if dot(normal, sub(point(k)?, a)) != 0 {
            return None;
        }
    }
    Some([first as u32, (first + b) as u32, (first + c) as u32])
}

/// Whether the four points certainly do not lie in one plane: the sign of
/// their orientation determinant is certain, and not zero. Shewchuk's
/// filter (*Adaptive precision floating-point arithmetic and fast robust
/// geometric predicates*, Discrete Comput. Geom. 18, 1997, `orient3d`'s
/// first stage): the determinant of the differences to `d`, computed in
/// `f64`, is within `(7 + 56 eps) eps` times its permanent (the same sum
/// of products with every term's magnitude) of the exact one, `eps =
/// 2^-53`. The `f32` coordinates' differences and their products neither
/// overflow nor underflow in `f64` (their magnitudes lie between `2^-447`
/// and `2^183`, or are 0). False says nothing: the exact test decides.
pub(super) fn certainly_not_coplanar(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> bool {
    /// Shewchuk's `o3derrboundA`, with his `epsilon` (half an ulp of 1).
    const BOUND: f64 = (7.0 + 56.0 * HALF_ULP) * HALF_ULP;
    const HALF_ULP: f64 = f64::EPSILON / 2.0;
    let d = d.as_dvec3();
    let (a, b, c) = (a.as_dvec3() - d, b.as_dvec3() - d, c.as_dvec3() - d);
    let (bc, cb) = (b.x * c.y, c.x * b.y);
    let (ca, ac) = (c.x * a.y, a.x * c.y);
    let (ab, ba) = (a.x * b.y, b.x * a.y);
    let det = a.z * (bc - cb) + b.z * (ca - ac) + c.z * (ab - ba);
    let permanent = (bc.abs() + cb.abs()) * a.z.abs()
        + (ca.abs() + ac.abs()) * b.z.abs()
        + (ab.abs() + ba.abs()) * c.z.abs();
    det.abs() > BOUND * permanent
}

/// Whether the node's brightest channel's covariance is far from singular,
/// so that its lights cannot all lie in one plane: a filter that spares
/// most nodes the exact test (skipping a node only forgoes a shortcut).
fn clearly_solid(node: &Node) -> bool {
    let k = node.intensity.max_position();
    if node.intensity[k] <= 0.0 {
        return false;
    }
    let [xx, yy, zz, xy, xz, yz] = node.channel_covariances[k].map(f64::from);
    let det = xx * (yy * zz - yz * yz) - xy * (xy * zz - yz * xz) + xz * (xy * yz - yy * xz);
    let trace = xx + yy + zz;
    // Coplanar lights have a singular covariance; its stored entries are
    // rounded to `f32` (relative 2^-24), which moves the determinant by
    // far less than this.
    det > SOLID * trace * trace * trace
}

/// See [`clearly_solid`].
const SOLID: f64 = 1e-3;

/// Records the plane of every node whose lights are exactly coplanar (a
/// node's whole subtree shares its plane) unless its box is flat along an
/// axis, which the box already settles. Examined parents first, stopping
/// at the first coplanar node of each path: `O(n depth)` in the
/// worst case, far less where lights leave the plane early (a check fails
/// at the first light off it).
///
/// Nodes that the statistics pass `notes` knew to hold four lights off one
/// plane are not examined: no plane holds all their lights.
pub(super) fn record_planes(tree: &mut LightTree, notes: &[Notes], pool: Pool) {
    tree.planes.clear();
    tree.node_planes.clear();
    if tree.nodes.is_empty() {
        return;
    }
    let examined = |i: usize, node: &Node| {
        node.light_count >= MIN_LIGHTS
            && (node.aabb.max - node.aabb.min).min_element() > 0.0
            && !notes.get(i).is_some_and(|n| n.off_plane)
            && !clearly_solid(node)
    };
    // On a pool, every node's own plane is looked for first, side by side;
    // the pass below then takes those it would have looked for.
    let spanned = if pool.parallel() {
        let tree = &*tree;
        let mut spanned = vec![None; tree.nodes.len()];
        pool.fill(&mut spanned, |i| {
            let node = &tree.nodes[i];
            if examined(i, node) {
                spanning_plane(tree, node)
            } else {
                None
            }
        });
        spanned
    } else {
        Vec::new()
    };
    // Parents come before their children in the node array: one pass in
    // that order (reading the nodes in sequence) hands each node's plane
    // down before its children are reached.
    let mut planes = vec![NO_PLANE; tree.nodes.len()];
    let mut found = Vec::new();
    for (i, node) in tree.nodes.iter().enumerate() {
        let mut plane = planes[i];
        if plane == NO_PLANE
            && let Some(triple) = match spanned.get(i) {
                Some(triple) => *triple,
                None if examined(i, node) => spanning_plane(tree, node),
                None => None,
            }
        {
            found.push(triple);
            plane = (found.len() - 1) as u32;
        }
        if plane != NO_PLANE {
            planes[i] = plane;
            planes[node.children()].fill(plane);
        }
    }
    // Scenes without a tilted plane of lights keep no per-node table.
    if !found.is_empty() {
        tree.planes = found;
        tree.node_planes = planes;
    }
}

impl LightTree {
    /// Whether every light of the plane `plane` lies at or below the
    /// tangent plane of `point` with normal `normal`: `normal` is exactly
    /// perpendicular to the lights' plane, so `normal . (x - point)` takes
    /// one value over the plane (that of a spanning light, whose sign is
    /// exact), and that value is at most 0.
    pub(crate) fn plane_at_or_below(&self, plane: u32, point: DVec3, normal: Vec3) -> bool {
        let [a, b, c] = self.planes[plane as usize].map(|k| self.lights[k as usize].position);
        let (a, b, c) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
        let (Some([pa, pb, pc]), Some([n])) = (on_grid([a, b, c]), on_grid([normal.as_dvec3()]))
        else {
            return false;
        };
        let across = cross(sub(pb, pa), sub(pc, pa));
        let n = [i128::from(n[0]), i128::from(n[1]), i128::from(n[2])];
        cross(across, n) == [0; 3] && dot_of_difference(normal.as_dvec3(), a, point) <= 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::PointLight;

    fn tree(points: impl Iterator<Item = Vec3>) -> LightTree {
        let lights: Vec<PointLight> = points.map(|p| PointLight::new(p, Vec3::ONE)).collect();
        LightTree::build(&lights).unwrap()
    }

    fn tilted(i: i32, j: i32) -> Vec3 {
        Vec3::new(i as f32, j as f32, (2 * i - 3 * j) as f32 * 0.25)
    }

    #[test]
    fn a_tilted_grid_is_one_plane() {
        let t = tree((0..40 * 40).map(|k| tilted(k % 40, k / 40)));
        assert_eq!(t.planes.len(), 1);
        assert!((0..t.nodes.len()).all(|i| t.node_plane(i) == Some(0)));
        // The plane holds (0, 0, 0); its normal is (-2, 3, 4) (any length,
        // either sign), and no other.
        let (p, n) = (DVec3::ZERO, Vec3::new(-2.0, 3.0, 4.0));
        assert!(t.plane_at_or_below(0, p, n));
        assert!(t.plane_at_or_below(0, p, -0.5 * n));
        assert!(!t.plane_at_or_below(0, p, Vec3::new(-2.0, 3.0, 4.000_001)));
        // A point a hair above the plane along `n` sees it below; a hair
        // below, above (facing `n`) or below (facing `-n`).
        let (up, down) = (DVec3::new(0.0, 0.0, 1e-30), DVec3::new(0.0, 0.0, -1e-30));
        assert!(t.plane_at_or_below(0, up, n));
        assert!(!t.plane_at_or_below(0, down, n));
        assert!(t.plane_at_or_below(0, down, -n));
    }

    #[test]
    fn one_light_an_ulp_off_the_plane_breaks_it() {
        let mut points: Vec<Vec3> = (0..40 * 40).map(|k| tilted(k % 40, k / 40)).collect();
        let z = &mut points[777].z;
        *z = f32::from_bits(z.to_bits() + 1);
        let t = tree(points.into_iter());
        // The root and the nodes holding that light have no plane; the rest
        // do.
        assert_eq!(t.node_plane(0), None);
        assert!((0..t.nodes.len()).any(|i| t.node_plane(i).is_some()));
        let moved = t.order.iter().position(|&k| k == 777).unwrap();
        for (i, n) in t.nodes.iter().enumerate() {
            if n.lights().contains(&moved) {
                assert_eq!(t.node_plane(i), None);
            }
        }
    }

    #[test]
    fn a_refit_records_the_planes_anew() {
        let points: Vec<Vec3> = (0..40 * 40).map(|k| tilted(k % 40, k / 40)).collect();
        let mut t = tree(points.iter().copied());
        let mut lights: Vec<PointLight> = points
            .iter()
            .map(|&p| PointLight::new(p, Vec3::ONE))
            .collect();
        lights[5].position.z += 0.5;
        t.refit(&lights).unwrap();
        assert_eq!(t.node_plane(0), None);
        let flat: Vec<PointLight> = points
            .iter()
            .map(|&p| PointLight::new(p * 2.0, Vec3::ONE))
            .collect();
        t.refit(&flat).unwrap();
        assert!((0..t.nodes.len()).all(|i| t.node_plane(i) == Some(0)));
    }

    #[test]
    fn scattered_lights_and_flat_boxes_record_nothing() {
        // A Kronecker sequence: well spread, no four consecutive points in
        // a plane.
        let spread = |k: f64, alpha: f64| ((k * alpha).fract() * 100.0) as f32;
        let t = tree((0..5000).map(|k| {
            let k = f64::from(k);
            Vec3::new(
                spread(k, 0.618_034),
                spread(k, 0.414_214),
                spread(k, 0.732_051),
            )
        }));
        assert!(t.planes.is_empty() && t.node_planes.is_empty());
        // Lamps at one height: the boxes are flat, which settles their plane.
        let t = tree((0..2000).map(|k| Vec3::new((k % 50) as f32, (k / 50) as f32, 6.0)));
        assert!(t.planes.is_empty());
    }

    #[test]
    fn the_float_filter_never_rejects_coplanar_points() {
        // Points exactly in tilted planes (whole numbers below 2^24, scaled
        // by powers of two, which keeps them there), whose `f64`
        // determinant rounds (its products reach 2^66): the filter must
        // leave them to the exact test.
        let mut state = 1u64;
        let mut next = |m: i64| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            ((state >> 33) as i64 % (2 * m + 1) - m) as f32
        };
        for scale in [1.0f32, 2f32.powi(-60), 2f32.powi(20), 2f32.powi(45)] {
            for _ in 0..2000 {
                let (p, q) = (next(7), next(7));
                let mut point = || {
                    let (i, j) = (next(1 << 20), next(1 << 20));
                    Vec3::new(i, j, p * i + q * j) * scale
                };
                let [a, b, c, d] = [point(), point(), point(), point()];
                assert!(!certainly_not_coplanar(a, b, c, d), "{a} {b} {c} {d}");
            }
        }
        // Clearly solid, and an ulp off a plane at a coordinate of 1.
        let one_up = f32::from_bits(1f32.to_bits() + 1);
        assert!(certainly_not_coplanar(
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(0.0, 0.0, 1.0)
        ));
        assert!(certainly_not_coplanar(
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, one_up)
        ));
    }

    #[test]
    fn powers_of_two_are_exact() {
        for k in -1100..1100 {
            let normal = (-1022..=1023).contains(&k);
            assert_eq!(power_of_two(k), normal.then(|| 2.0f64.powi(k)), "2^{k}");
        }
    }

    #[test]
    fn coordinates_off_a_common_grid_are_not_claimed() {
        // 2^-30 next to 2^20: no 40-bit grid holds both.
        assert!(
            on_grid([
                DVec3::new(1048576.0, 0.0, 0.0),
                DVec3::splat(2f64.powi(-30))
            ])
            .is_none()
        );
        // Whole numbers of one power-of-two cell, in proportion.
        let [o] = on_grid([DVec3::new(3.0, -1.0, 0.5)]).unwrap();
        assert!(o[0] == -3 * o[1] && o[1] == -2 * o[2] && o[2] > 0);
    }
}
