//! The slab bound: a large node that the tangent plane runs through,
//! bounded bin by bin from its slab moments (see [`Lambert`]'s docs, "Nodes
//! the tangent plane cuts", and the tree's `slabs` module for what a bin
//! stores).

use glam::{DVec3, Vec3};

use super::{BoundKind, Lambert};
use crate::LightTree;
use crate::geometry::Surface;
use crate::numeric::{POINT_SLACK, SECOND_ORDER_SLACK};
use crate::shader::NodeEstimate;
use crate::tree::Node;
use crate::tree::slabs::{BIN_FLOATS, SLAB_BINS, SlabTable, bin_edges};

/// Relative widening of each computed piece of the slab interval for the
/// rounding of its own `f64` arithmetic: a piece is a handful of sums and
/// products of quantities whose magnitudes the widening is applied to,
/// each within a few ulps; `2^-40` leaves a wide margin.
const ARITHMETIC_SLACK: f64 = 1.0 / (1u64 << 40) as f64;

/// Per channel, `[lower, upper]` of `sum_i I_ik h_i^+ / r_i^3 / I_k`.
type Interval = (DVec3, DVec3);

/// Bounds narrower than this share of their upper end are left as they
/// are: a node the plane cuts has a far wider bound (its clamp term is
/// about its value), and the test keeps the slab bound's cost off the
/// nodes it cannot help.
const NARROW_MIN_WIDTH: f64 = 0.125;

impl Lambert {
    /// [`Shader::narrow_bound`](crate::shader::Shader::narrow_bound): the
    /// node's bound intersected with its slab interval, where the node has
    /// bins, its box straddles the tangent plane and some bin lies wholly
    /// above or below it.
    #[inline(always)]
    pub(super) fn narrow_with_slabs(
        &self,
        surface: &Surface,
        tree: &LightTree,
        index: usize,
        bound: NodeEstimate,
    ) -> NodeEstimate {
        // A bound already within a few percent of its value gains little.
        let width = (bound.upper - bound.lower).max_element();
        if self.kind == BoundKind::Paper
            || !(width > NARROW_MIN_WIDTH * bound.upper.max_element())
            || !box_is_cut(surface, &tree.nodes[index])
        {
            return bound;
        }
        self.narrow_cut(surface, tree, index, bound)
    }

    /// [`narrow_with_slabs`](Self::narrow_with_slabs) for a node whose box
    /// the plane runs through (out of line: few nodes get here).
    #[inline(never)]
    fn narrow_cut(
        &self,
        surface: &Surface,
        tree: &LightTree,
        index: usize,
        bound: NodeEstimate,
    ) -> NodeEstimate {
        let Some(axis) = tree.slabs.axis_of(index) else {
            return bound;
        };
        let node = &tree.nodes[index];
        let Some(classes) = classify(surface, node, axis) else {
            return bound;
        };
        let Some(table) = tree.slabs.of(index) else {
            return bound;
        };
        let Some((lo, hi)) = slab_interval(surface, node, table, classes) else {
            return bound;
        };
        let scale = node.intensity * self.kd;
        // Two roundings of each product.
        let lo = (lo * scale * (1.0 - 4.0 * f64::EPSILON)).max(bound.lower);
        let hi = (hi * scale * (1.0 + 4.0 * f64::EPSILON)).min(bound.upper);
        if lo.cmpgt(hi).any() {
            // Both intervals hold the exact value; they can only miss each
            // other by rounding.
            return bound;
        }
        NodeEstimate::new(0.5 * (lo + hi), lo, hi)
    }
}

/// Whether the tangent plane may run through the node's box: its heights
/// over the box, widened for rounding as in [`classify`], reach both
/// sides.
#[inline(always)]
fn box_is_cut(surface: &Surface, node: &Node) -> bool {
    let (p, n) = (surface.point, surface.normal);
    let (bmin, bmax) = (node.aabb.min.as_dvec3(), node.aabb.max.as_dvec3());
    let magnitude = bmin.abs().max(bmax.abs()).max_element() + p.abs().max_element();
    let slack = SECOND_ORDER_SLACK * magnitude;
    let middle = n.dot(0.5 * (bmin + bmax) - p);
    let reach = n.abs().dot(0.5 * (bmax - bmin)) + slack;
    middle - reach <= 0.0 && middle + reach > 0.0
}

/// The moments of bins `first..=last`, as stored (normalised), each
/// entry's three channels side by side, from the running sums.
#[inline(always)]
fn run(table: &SlabTable, first: usize, last: usize) -> [DVec3; BIN_FLOATS] {
    let top = &table.prefix[last];
    let mut m = [DVec3::ZERO; BIN_FLOATS];
    for (m, t) in m.iter_mut().zip(top) {
        *m = Vec3::from_array(*t).as_dvec3();
    }
    if first > 0 {
        for (m, b) in m.iter_mut().zip(&table.prefix[first - 1]) {
            *m -= Vec3::from_array(*b).as_dvec3();
        }
    }
    m
}

/// `|x| + |y| + |z|` per channel, of a vector whose components hold the
/// three channels.
#[inline(always)]
fn norm1(v: &[DVec3; 3]) -> DVec3 {
    v[0].abs() + v[1].abs() + v[2].abs()
}

/// How the tangent plane meets a node's bins: the bins' edges along the
/// axis and their heights, which bins lie wholly above and wholly below,
/// and the reach of the heights across the axis.
struct Classes {
    edges: [f64; SLAB_BINS + 1],
    heights: [f64; SLAB_BINS + 1],
    above: u32,
    below: u32,
    across: f64,
    slack: f64,
}

/// The bins' classes, or `None` where the plane does not run through the
/// node's box or no bin lies wholly above or below it.
#[inline(always)]
fn classify(surface: &Surface, node: &Node, axis: usize) -> Option<Classes> {
    let (p, n) = (surface.point, surface.normal);
    let (bmin, bmax) = (node.aabb.min.as_dvec3(), node.aabb.max.as_dvec3());
    // Heights n . (x - p): each computed within a few ulps of the
    // coordinates' magnitude, and the unit normal within a few ulps of the
    // given normal's direction (Surface), which moves a height by a few
    // ulps of |x - p|: SECOND_ORDER_SLACK of the magnitude covers both.
    let magnitude = bmin.abs().max(bmax.abs()).max_element() + p.abs().max_element();
    let slack = SECOND_ORDER_SLACK * magnitude;
    // Across the axis, the box's heights lie within `across` of `level`.
    let (centre, half) = (0.5 * (bmin + bmax), 0.5 * (bmax - bmin));
    let (mut level, mut across) = (0.0, slack);
    for i in 0..3 {
        if i != axis {
            level += n[i] * (centre[i] - p[i]);
            across += n[i].abs() * half[i];
        }
    }
    let (na, pa) = (n[axis], p[axis]);
    let height = |e: f64| na * (e - pa) + level;
    let (h0, h1) = (height(bmin[axis]), height(bmax[axis]));
    if h0.min(h1) - across > 0.0 || h0.max(h1) + across <= 0.0 {
        // Not cut: the series bound is far tighter above, and below is 0.
        return None;
    }
    // The heights of the bins' edges lie between h0 and h1: no bin lies
    // wholly above (below) unless an end does.
    if !(h0.max(h1) - across > 0.0) && !(h0.min(h1) + across <= 0.0) {
        return None;
    }
    // Heights are monotone along the axis, so the bins wholly above the
    // plane are a run from one end and those wholly below a run from the
    // other: bin j lies wholly above where both its edges' heights exceed
    // `across`, wholly below where neither exceeds `-across`.
    let edges = bin_edges(bmin[axis], bmax[axis]);
    let mut heights = [0.0; SLAB_BINS + 1];
    for (h, &e) in heights.iter_mut().zip(&edges) {
        *h = height(e);
    }
    let (mut up, mut down) = (0u32, 0u32);
    for (j, &h) in heights.iter().enumerate() {
        up |= u32::from(h - across > 0.0) << j;
        down |= u32::from(h + across <= 0.0) << j;
    }
    let bins = (1u32 << SLAB_BINS) - 1;
    let above = up & (up >> 1) & bins;
    let below = down & (down >> 1) & bins;
    if above == 0 && below == 0 {
        return None;
    }
    Some(Classes {
        edges,
        heights,
        above,
        below,
        across,
        slack,
    })
}

/// Whether the slab bound applies to node `index` of `tree` seen from
/// `surface` (it has bins, the plane runs through its box, and some bin
/// lies wholly above or below the plane).
pub(crate) fn slabs_apply(surface: &Surface, tree: &LightTree, index: usize) -> bool {
    tree.slabs
        .axis_of(index)
        .is_some_and(|axis| classify(surface, &tree.nodes[index], axis).is_some())
}

/// The slab interval of the node (in units of each channel's intensity,
/// before `kd`) for the bins' `classes`, or `None` where the node's ball
/// reaches the point.
#[inline(always)]
fn slab_interval(
    surface: &Surface,
    node: &Node,
    table: &SlabTable,
    classes: Classes,
) -> Option<Interval> {
    let Classes {
        edges,
        heights,
        above,
        below,
        across,
        slack,
    } = classes;
    let (p, n) = (surface.point, surface.normal);
    let (bmin, bmax) = (node.aabb.min.as_dvec3(), node.aabb.max.as_dvec3());
    let axis = table.axis as usize;
    let bins = (1u32 << SLAB_BINS) - 1;
    let c = node.centroid.as_dvec3();
    let r = f64::from(node.radius);
    let to_centroid = c - p;
    let distance = to_centroid.length();
    // Every member lies within r of c: between distance - r and distance +
    // r of the point (the length within a few ulps).
    let gap = distance * (1.0 - 8.0 * f64::EPSILON) - r;
    if !(gap > 0.0) {
        return None;
    }
    let reach_out = distance * (1.0 + 8.0 * f64::EPSILON) + r;
    let hc = n.dot(to_centroid);
    let hca = hc.abs();
    let slice_of = |lo: usize, hi: usize| -> (DVec3, DVec3) {
        let (mut a, mut b) = (bmin, bmax);
        a[axis] = edges[lo];
        b[axis] = edges[hi];
        (a, b)
    };
    // A run difference of two stored values is within twice their bound.
    let tau = 2.0 * f64::from(table.error);
    let mut lower = DVec3::ZERO;
    let mut upper = DVec3::ZERO;
    // The bins the plane cuts: by the chord of h^+ over each slice's
    // heights.
    let mut cut = !(above | below) & bins;
    while cut != 0 {
        let j = cut.trailing_zeros() as usize;
        cut &= cut - 1;
        let (a, b) = (heights[j], heights[j + 1]);
        let (low, high) = ((a.min(b) - across).min(0.0), a.max(b) + across);
        let (lo, hi) = slice_of(j, j + 1);
        let (near, far) = box_distances(0.5 * (lo + hi) - p, 0.5 * (hi - lo), slack);
        let (near, far) = (near.max(gap), far.min(reach_out));
        let (near3, far3) = (near * near * near, far * far * far);
        let m = run(table, j, j);
        let w = m[0];
        let first = r * (n.x * m[1] + n.y * m[2] + n.z * m[3]);
        // s = sum w h over the bin, with the error of the stored moments
        // (W within tau, each entry of m1 within tau R) and of the heights.
        let s = hc * w + first;
        let err =
            tau * (hca + 2.0 * r) + (w + tau) * slack + ARITHMETIC_SLACK * (hca * w + first.abs());
        let w_hi = w + tau;
        let rise = s + err - low * w_hi;
        let rise = rise + ARITHMETIC_SLACK * (s.abs() + err - low * w_hi);
        let chord = high * rise / (high - low);
        let hinge_hi = chord.min(high * w_hi).max(DVec3::ZERO);
        let hinge_lo = (s - err).max(DVec3::ZERO);
        lower += hinge_lo / far3;
        upper += hinge_hi / near3;
    }
    // The bins wholly above: one second-order bound for all of them.
    if above != 0 {
        let first_bin = above.trailing_zeros() as usize;
        let last_bin = 31 - above.leading_zeros() as usize;
        let hull = slice_of(first_bin, last_bin + 1);
        let (hull_near, hull_far) =
            box_distances(0.5 * (hull.0 + hull.1) - p, 0.5 * (hull.1 - hull.0), slack);
        let geometry = AboveGeometry {
            p,
            c,
            r,
            hull,
            hull_near,
            near: hull_near.max(gap),
            far: hull_far.min(reach_out),
        };
        let sums = Weighted::new(&run(table, first_bin, last_bin), n, r, hc, slack, tau);
        let (lo, hi) = above_interval(&sums, &geometry);
        lower += lo;
        upper += hi;
    }
    // The shading point itself is within a rounding of the caller's: the
    // sum moves by at most 2^-53 D 2 / gap^3 per unit of intensity (see
    // POINT_SLACK). And each member's height along the unit normal is
    // within `slack` of its height along the given normal's direction,
    // which moves the sum by at most slack / gap^3 per unit of intensity
    // (the pieces above carry it against their own distances, the
    // expansion against the distance of its centre).
    let gap3 = gap * gap * gap;
    let point = (POINT_SLACK * distance * 2.0 * 1.5 + 2.0 * slack) / gap3;
    let lower = (lower * (1.0 - ARITHMETIC_SLACK) - DVec3::splat(point)).max(DVec3::ZERO);
    let upper = upper * (1.0 + ARITHMETIC_SLACK) + DVec3::splat(point);
    Some((lower, upper))
}

/// What the bound of the bins wholly above the plane reads besides their
/// sums.
struct AboveGeometry {
    p: DVec3,
    c: DVec3,
    r: f64,
    /// The box holding the bins' slices, the least distance from the point
    /// to it, and the least and greatest to a member in it.
    hull: (DVec3, DVec3),
    hull_near: f64,
    near: f64,
    far: f64,
}

/// The three channels' sums over the bins wholly above the plane, side by
/// side, with bounds on their errors: `U = sum w h`, `V = sum w h y`,
/// `Q = sum w h |y|^2`.
struct Weighted {
    u: DVec3,
    u_err: DVec3,
    /// The components of `V`.
    v: [DVec3; 3],
    v_err: DVec3,
    q: DVec3,
    q_err: DVec3,
}

impl Weighted {
    /// From the summed normalised moments `m` (`W`, `m1`, `M2`, `m3` as
    /// stored), for the unit normal `n`, the node's radius `r` and the
    /// centroid's height `hc`: the stored values' errors (`tau`, `tau R`,
    /// `tau R^2`, `tau R^3` per entry), the heights' (`slack`) and the
    /// arithmetic's.
    #[inline(always)]
    fn new(m: &[DVec3; BIN_FLOATS], n: DVec3, r: f64, hc: f64, slack: f64, tau: f64) -> Self {
        let (r2, r3) = (r * r, r * r * r);
        let w = m[0];
        let m1 = [m[1] * r, m[2] * r, m[3] * r];
        let (xx, yy, zz) = (m[4] * r2, m[5] * r2, m[6] * r2);
        let (xy, xz, yz) = (m[7] * r2, m[8] * r2, m[9] * r2);
        let m3 = [m[10] * r3, m[11] * r3, m[12] * r3];
        let m2n = [
            xx * n.x + xy * n.y + xz * n.z,
            xy * n.x + yy * n.y + yz * n.z,
            xz * n.x + yz * n.y + zz * n.z,
        ];
        let trace = xx + yy + zz;
        let hca = hc.abs();
        let m1_len = norm1(&m1);
        let n_m3 = n.x * m3[0] + n.y * m3[1] + n.z * m3[2];
        Self {
            u: hc * w + (n.x * m1[0] + n.y * m1[1] + n.z * m1[2]),
            u_err: tau * (hca + 2.0 * r)
                + (w + tau) * slack
                + ARITHMETIC_SLACK * (hca * w + m1_len),
            v: [
                m2n[0] + hc * m1[0],
                m2n[1] + hc * m1[1],
                m2n[2] + hc * m1[2],
            ],
            v_err: tau * (3.0 * r2 + 2.0 * hca * r)
                + (m1_len + 2.0 * tau * r) * slack
                + ARITHMETIC_SLACK * (norm1(&m2n) + hca * m1_len),
            q: n_m3 + hc * trace,
            q_err: tau * (2.0 * r3 + 3.0 * hca * r2)
                + (trace.abs() + 3.0 * tau * r2) * slack
                + ARITHMETIC_SLACK * (norm1(&m3) + hca * trace.abs()),
        }
    }
}

/// Per channel, `[lower, upper]` of `sum_i w_i h_i / r_i^3` over the
/// lights of the bins wholly above the plane, from their sums `s`: the
/// heights are positive there, so the sum is of `|x - p|^-3` under the
/// non-negative weights `w h`, expanded to second order about one point
/// `a` shared by the channels (the three channels' weights' centroid; see
/// [`Lambert`]'s docs).
#[inline(always)]
fn above_interval(s: &Weighted, g: &AboveGeometry) -> Interval {
    let (p, c, r) = (g.p, g.c, g.r);
    let near3 = g.near * g.near * g.near;
    let far3 = g.far * g.far * g.far;
    // The plain interval: every member between near and far of the point.
    let lower = (s.u - s.u_err).max(DVec3::ZERO) / far3;
    let upper = (s.u + s.u_err).max(DVec3::ZERO) / near3;
    let u_all = s.u.element_sum();
    if !(u_all > 0.0) {
        return (lower, upper);
    }
    // The expansion point a: the weights' centroid c + V / U over the three
    // channels, moved into the hull. Any point of the hull serves: the
    // identity below holds for every a.
    let v_all = DVec3::new(
        s.v[0].element_sum(),
        s.v[1].element_sum(),
        s.v[2].element_sum(),
    );
    let a = (c + v_all / u_all).clamp(g.hull.0, g.hull.1);
    let delta = a - c;
    let dl = delta.length();
    // Segments from a to the members stay in the hull, and in the ball
    // when a is in it.
    let segment_near = if dl <= r * (1.0 - 1e-6) {
        g.near
    } else {
        g.hull_near
    };
    if !(segment_near > 0.0) {
        return (lower, upper);
    }
    let to_a = a - p;
    let ra2 = to_a.length_squared();
    let ra = ra2.sqrt();
    let ra3 = ra2 * ra;
    let inv_ra4 = 1.0 / (ra2 * ra2);
    // The Hessian of |x - p|^-3 has eigenvalues -3 / r^5 (twice) and
    // 12 / r^5; the remainder's integral form halves them.
    let inv_sn5 = 1.0 / segment_near.powi(5);
    let dl2 = dl * dl;
    // sum w h |x - a|^2 = Q - 2 delta.V + U |delta|^2, and
    // sum w h (x - a) = V - U delta.
    let v_len = norm1(&s.v);
    let delta_v = delta.x * s.v[0] + delta.y * s.v[1] + delta.z * s.v[2];
    let spread = s.q - 2.0 * delta_v + s.u * dl2;
    let spread_err = s.q_err
        + 2.0 * dl * s.v_err
        + s.u_err * dl2
        + ARITHMETIC_SLACK * (s.q.abs() + 2.0 * dl * v_len + s.u * dl2);
    let spread_hi = (spread + spread_err).max(DVec3::ZERO);
    // The gradient of |x - p|^-3 at a is -3 (a - p) / |a - p|^5.
    let moment_along = to_a.x * (s.v[0] - s.u * delta.x)
        + to_a.y * (s.v[1] - s.u * delta.y)
        + to_a.z * (s.v[2] - s.u * delta.z);
    let first = -3.0 * moment_along * (inv_ra4 / ra);
    let first_err = 3.0 * inv_ra4 * (s.v_err + dl * s.u_err)
        + ARITHMETIC_SLACK * 3.0 * inv_ra4 * (v_len + s.u * dl);
    let centre = s.u / ra3;
    let centre_err = s.u_err / ra3 + ARITHMETIC_SLACK * centre.abs();
    let below = 1.5 * spread_hi * inv_sn5;
    let above = 6.0 * spread_hi * inv_sn5;
    let err = centre_err + first_err + ARITHMETIC_SLACK * (below + above + first.abs());
    let lo = (centre + first - below - err).max(lower);
    let hi = (centre + first + above + err).min(upper);
    // Channels whose sum is within its error of 0, or whose intervals
    // miss by rounding, keep the plain interval.
    let take = s.u.cmpgt(s.u_err) & lo.cmple(hi);
    (
        DVec3::select(take, lo, lower),
        DVec3::select(take, hi, upper),
    )
}

/// Least and greatest distance from the point to a box whose centre lies
/// at `offset` from it, of half extents `half`, widened for rounding:
/// `offset` and `half` are within a few ulps of the coordinates'
/// magnitude, which `slack` covers per component.
#[inline(always)]
fn box_distances(offset: DVec3, half: DVec3, slack: f64) -> (f64, f64) {
    let offset = offset.abs();
    let grow = DVec3::splat(slack);
    let near = (offset - half - grow).max(DVec3::ZERO).length() * (1.0 - 8.0 * f64::EPSILON);
    let far = (offset + half + grow).length() * (1.0 + 8.0 * f64::EPSILON);
    (near, far)
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};
    use proptest::prelude::*;

    use super::slab_interval;
    use crate::lambert::bound_tests::cases;
    use crate::shader::{Shader, Surface};
    use crate::{Lambert, LightTree, PointLight};

    fn unit() -> impl Strategy<Value = Vec3> {
        (-1.0f32..=1.0, 0.0f32..core::f32::consts::TAU).prop_map(|(z, phi)| {
            let s = (1.0 - z * z).max(0.0).sqrt();
            Vec3::new(s * phi.cos(), s * phi.sin(), z)
        })
    }

    /// Lights in a slab of thickness `10^t` about a plane through `origin`
    /// (`10^o` from the origin of coordinates) with normal `axis`, `size`
    /// across; colours from a small palette with channels exactly 0 at
    /// times.
    fn slab_lights(
        count: usize,
        origin: Vec3,
        axis: Vec3,
        thickness: f32,
        size: f32,
        seed: u64,
    ) -> Vec<PointLight> {
        let a = axis.normalize();
        let b = a.any_orthonormal_vector();
        let c = a.cross(b);
        let mut state = seed | 1;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let palette = [
            Vec3::new(1.0, 0.55, 0.2),
            Vec3::new(0.85, 0.9, 1.0),
            Vec3::new(0.0, 2.0, 0.5),
            Vec3::new(3.0, 0.0, 0.0),
        ];
        (0..count)
            .map(|i| {
                let position = origin
                    + b * (size * uniform())
                    + c * (size * uniform())
                    + a * (thickness * uniform());
                let scale = 1.0 + 4.0 * (uniform() + 0.5);
                PointLight::new(position, palette[i % palette.len()] * scale)
            })
            .collect()
    }

    /// Every node's slab interval holds the exact sum of its lights' terms,
    /// per channel, up to the contract's relative allowance.
    fn check_tree(tree: &LightTree, surface: &Surface) -> Result<usize, TestCaseError> {
        let shader = Lambert::new(Vec3::ONE);
        let mut checked = 0;
        for (index, node) in tree.nodes().iter().enumerate() {
            let Some(table) = tree.slabs.of(index) else {
                continue;
            };
            let Some(classes) = super::classify(surface, node, table.axis as usize) else {
                continue;
            };
            let Some((lo, hi)) = slab_interval(surface, node, table, classes) else {
                continue;
            };
            checked += 1;
            let mut exact = DVec3::ZERO;
            for light in &tree.lights()[node.lights()] {
                exact += shader.eval(
                    &(),
                    surface,
                    light.position.as_dvec3(),
                    light.intensity.as_dvec3(),
                );
            }
            let (lo, hi) = (lo * node.intensity, hi * node.intensity);
            for k in 0..3 {
                let allowance = 1e-9 * exact[k];
                prop_assert!(
                    lo[k] <= exact[k] + allowance && exact[k] <= hi[k] + allowance,
                    "node {index} channel {k}: exact {} outside [{}, {}]",
                    exact[k],
                    lo[k],
                    hi[k]
                );
                prop_assert!(lo[k] >= 0.0 && lo[k] <= hi[k]);
            }
        }
        Ok(checked)
    }

    proptest! {
        #![proptest_config(cases(48))]

        /// Slabs of thickness `10^-6` to `10` about planes at every tilt, far
        /// from the origin or near it, the point inside the slab or near
        /// it, its normal the plane's or tilted off it by up to a radian,
        /// either side.
        #[test]
        fn slab_intervals_hold_the_exact_sums(
            count in 200usize..4000,
            axis in unit(),
            thickness in -6.0f32..=1.0,
            far in -1.0f32..=5.0,
            size in 1.0f32..=300.0,
            seed in any::<u64>(),
            h in -2.0f32..=2.0,
            tilt in (-7.0f32..=0.0, unit(), any::<bool>(), any::<bool>()),
        ) {
            let origin = Vec3::new(0.3, -0.7, 0.5) * 10f32.powf(far);
            let thickness = 10f32.powf(thickness);
            let lights = slab_lights(count, origin, axis, thickness, size, seed);
            let tree = LightTree::build(&lights).unwrap();
            let a = axis.normalize();
            let b = a.any_orthonormal_vector();
            let c = a.cross(b);
            let (angle, off, exact_plane, flip) = tilt;
            let n = if exact_plane { a } else { (a + off * 10f32.powf(angle)).normalize() };
            let n = if flip { -n } else { n };
            // Points across the slab and past its edge.
            for (u, v) in [(0.0, 0.0), (0.45, 0.1), (-0.3, 0.4), (0.5, -0.5), (0.8, 0.2)] {
                let p = origin + (b * u + c * v) * size + a * (thickness * h);
                if let Ok(surface) = Surface::new(p, n, None) {
                    check_tree(&tree, &surface)?;
                }
            }
        }
    }

    /// The slab property above reaches the bound: over a fixed run of its
    /// kind of scenes, many node intervals are checked.
    #[test]
    fn slab_scenes_exercise_the_bound() {
        let mut checked = 0;
        for seed in 0..12u64 {
            let axis = Vec3::new(0.01 * seed as f32 - 0.06, 0.02, 1.0).normalize();
            let thickness = 10f32.powf(-(seed as f32) / 2.0);
            let lights = slab_lights(3000, Vec3::splat(50.0), axis, thickness, 200.0, seed);
            let tree = LightTree::build(&lights).unwrap();
            let b = axis.any_orthonormal_vector();
            let c = axis.cross(b);
            for (u, v) in [
                (0.0, 0.0),
                (0.3, 0.1),
                (-0.45, 0.2),
                (0.2, -0.3),
                (-0.1, 0.4),
            ] {
                let p = Vec3::splat(50.0) + (b * u + c * v) * 200.0;
                let surface = Surface::new(p, axis, None).unwrap();
                checked += check_tree(&tree, &surface).unwrap();
            }
        }
        assert!(checked >= 60, "{checked} node intervals checked");
    }

    /// The street layout the bound is for: lamps in a layer 1 unit thick,
    /// a roof point inside it, normal up. The intervals are checked, and
    /// many nodes get one, most of them far narrower than the depth of
    /// their box below the plane allows.
    #[test]
    fn roof_points_get_slab_intervals() {
        let mut lights = Vec::new();
        for i in 0..4000 {
            let (x, y) = ((i % 80) as f32 * 6.0, (i / 80) as f32 * 7.0);
            let z = 5.5 + ((i * 37) % 101) as f32 / 100.0;
            lights.push(PointLight::new(
                Vec3::new(x, y, z),
                Vec3::new(1.0, 0.55, 0.2) * 40.0,
            ));
        }
        let tree = LightTree::build(&lights).unwrap();
        let surface = Surface::new(Vec3::new(200.5, 150.5, 6.0), Vec3::Z, None).unwrap();
        let checked = check_tree(&tree, &surface).unwrap();
        assert!(checked >= 10, "{checked} nodes bounded from their slabs");
    }
}
