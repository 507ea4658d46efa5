//! [`Ggx`]'s node bound over `N` lanes: the intervals of (P4), the BRDF's
//! range over them and the expansion (P5)-(P9), written once over
//! [`Lanes`] and run with one lane (a single node, [`Shader::bound`]) or
//! eight (the children of a node that enter the cut together,
//! [`Shader::bound_nodes`]). Every operation is the scalar one lane by
//! lane, and each branch of the scalar text a selection between its two
//! sides, so a node's bound is the same bits alone and beside others.
//!
//! [`Shader::bound`]: crate::shader::Shader::bound
//! [`Shader::bound_nodes`]: crate::shader::Shader::bound_nodes

use glam::DVec3;

use super::{
    ARITHMETIC, DIRECTION_SLACK, EXPANSION_MIN_COS, EXPANSION_MIN_HALF, F32_ENTRY, Ggx, GgxView,
    HEIGHT_RELATIVE_SLACK, OP_SLACK, PRODUCT_SLACK, UNIT_SECOND,
};
use crate::geometry::{Cone, Surface};
use crate::lanes::{Lanes, Vec3Lanes, array};
use crate::numeric::{COS_SLACK, DISTANCE_SLACK, SECOND_ORDER_SLACK};
use crate::shader::NodeEstimate;
use crate::tree::Node;

/// Per channel, `N` lanes.
type Rgb<const N: usize> = [Lanes<N>; 3];

/// Per lane `if m { x } else { y }`.
#[inline(always)]
fn select<const N: usize>(m: [bool; N], x: Lanes<N>, y: Lanes<N>) -> Lanes<N> {
    Lanes::from_fn(|i| if m[i] { x.0[i] } else { y.0[i] })
}

/// Per lane `f(i)`.
#[inline(always)]
fn mask<const N: usize>(f: impl FnMut(usize) -> bool) -> [bool; N] {
    array(false, f)
}

/// `a x b` for one vector `a` and lanes `b`, in `glam`'s order.
#[inline(always)]
fn cross<const N: usize>(a: DVec3, b: Vec3Lanes<N>) -> Vec3Lanes<N> {
    Vec3Lanes {
        x: a.y * b.z - b.y * a.z,
        y: a.z * b.x - b.z * a.x,
        z: a.x * b.y - b.x * a.y,
    }
}

/// `v * s` per lane.
#[inline(always)]
fn scaled<const N: usize>(v: Vec3Lanes<N>, s: Lanes<N>) -> Vec3Lanes<N> {
    Vec3Lanes {
        x: v.x * s,
        y: v.y * s,
        z: v.z * s,
    }
}

/// `v + w` for one vector `w`.
#[inline(always)]
fn plus<const N: usize>(v: Vec3Lanes<N>, w: DVec3) -> Vec3Lanes<N> {
    Vec3Lanes {
        x: v.x + w.x,
        y: v.y + w.y,
        z: v.z + w.z,
    }
}

/// `|v|`, as `DVec3::length`.
#[inline(always)]
fn length<const N: usize>(v: Vec3Lanes<N>) -> Lanes<N> {
    v.dot(v).sqrt()
}

/// `max(x, y, z)`, as `DVec3::max_element`.
#[inline(always)]
fn max_element<const N: usize>(v: Vec3Lanes<N>) -> Lanes<N> {
    v.x.max(v.y).max(v.z)
}

/// What the bound reads of `N` nodes and their cones.
pub(super) struct Nodes<'a, const N: usize> {
    nodes: [&'a Node; N],
    offset: Vec3Lanes<N>,
    distance: Lanes<N>,
    radius: Lanes<N>,
    axis: Vec3Lanes<N>,
    sin_half: Lanes<N>,
    cos_half: Lanes<N>,
    box_lo: Vec3Lanes<N>,
    box_hi: Vec3Lanes<N>,
}

impl<'a, const N: usize> Nodes<'a, N> {
    #[inline(always)]
    pub(super) fn new(nodes: [&'a Node; N], cones: [&Cone; N]) -> Self {
        Self {
            nodes,
            offset: Vec3Lanes::from_fn(|i| cones[i].offset.to_array()),
            distance: Lanes::from_fn(|i| cones[i].distance),
            radius: Lanes::from_fn(|i| cones[i].radius),
            axis: Vec3Lanes::from_fn(|i| cones[i].axis.to_array()),
            sin_half: Lanes::from_fn(|i| cones[i].sin_half_angle),
            cos_half: Lanes::from_fn(|i| cones[i].cos_half_angle),
            box_lo: Vec3Lanes::from_fn(|i| nodes[i].aabb.min.as_dvec3().to_array()),
            box_hi: Vec3Lanes::from_fn(|i| nodes[i].aabb.max.as_dvec3().to_array()),
        }
    }

    /// The cone's `cos_range` of a unit direction: the range of the
    /// cosine between `dir` and the directions of the cone.
    #[inline(always)]
    fn cos_range(&self, dir: DVec3) -> (Lanes<N>, Lanes<N>) {
        let cos_c = self.axis.dot_with(dir.to_array());
        let sin_c = length(cross(dir, self.axis));
        let (sd, cd) = (self.sin_half, self.cos_half);
        let inside = mask(|i| cos_c.0[i] >= cd.0[i]);
        let hi = select(inside, Lanes::splat(1.0), cos_c * cd + sin_c * sd);
        let lo = cos_c * cd - sin_c * sd;
        (
            (lo - COS_SLACK).max(Lanes::splat(-1.0)),
            (hi + COS_SLACK).min(Lanes::splat(1.0)),
        )
    }
}

/// What [`Ggx`]'s bounds know of `N` nodes at a point: the intervals of
/// `n.l` (`a`), `v.h` (`c`) and `sin theta_h` (`s`) over their lit
/// members, each widened to hold what `eval` computes; a lower bound on
/// `|l + v|` over each node, and on its distance from the point (0 if it
/// may reach it).
#[derive(Clone, Copy, Debug)]
pub(super) struct Ranges<const N: usize> {
    pub(super) a: (Lanes<N>, Lanes<N>),
    pub(super) c: (Lanes<N>, Lanes<N>),
    pub(super) s: (Lanes<N>, Lanes<N>),
    pub(super) h_min: Lanes<N>,
    pub(super) near: Lanes<N>,
}

impl Ggx {
    /// `D` at `s^2 = sin^2 theta_h` ((P2) in the module's text).
    #[inline(always)]
    fn distribution_lanes<const N: usize>(&self, s2: Lanes<N>) -> Lanes<N> {
        let t = self.alpha2 + self.k * s2;
        self.alpha2 / (core::f64::consts::PI * (t * t))
    }

    /// `Vis(a) = G2 / (4 (n.l)(n.v))` at `a = n.l` ((P1)).
    #[inline(always)]
    fn visibility_lanes<const N: usize>(&self, view: &GgxView, a: Lanes<N>) -> Lanes<N> {
        let m_a = (self.alpha2 + self.k * (a * a)).sqrt();
        0.5 / (view.nv * m_a + a * view.m_v)
    }

    /// Schlick's `F` at `c = v.h`, per channel.
    #[inline(always)]
    fn fresnel_lanes<const N: usize>(&self, c: Lanes<N>) -> Rgb<N> {
        let t = (1.0 - c).max(Lanes::splat(0.0));
        let t2 = t * t;
        let w = t2 * t2 * t;
        [0, 1, 2].map(|k| self.f0[k] + (1.0 - self.f0[k]) * w)
    }

    /// The intervals of `n.l`, `v.h` and `sin theta_h` over the nodes'
    /// points (their balls and boxes), widened to hold what `eval`
    /// computes for each member (the module's text), with the bounds on
    /// `|l + v|` and on the distance that the expansion also reads.
    #[inline(always)]
    pub(super) fn ranges<const N: usize>(
        &self,
        view: &GgxView,
        surface: &Surface,
        nodes: &Nodes<'_, N>,
    ) -> Ranges<N> {
        let (n, v, b) = (surface.normal, surface.view, view.nv);
        let p = surface.point;
        let (zero, one) = (Lanes::<N>::splat(0.0), Lanes::<N>::splat(1.0));

        // a = n.l over the node, true values: cone, then box.
        let (cone_lo, cone_hi) = nodes.cos_range(n);
        let (centre, half) = Vec3Lanes::centre_and_half(nodes.box_lo, nodes.box_hi);
        let (z_lo, z_hi) = {
            let middle = centre.minus(p.to_array()).dot_with(n.to_array());
            let reach = half.dot_with(n.abs().to_array());
            let magnitude = max_element(centre.abs()) + max_element(half) + p.abs().max_element();
            let slack = SECOND_ORDER_SLACK * magnitude;
            (middle - reach - slack, middle + reach + slack)
        };
        let (box_near, box_far) = {
            let nearest = Vec3Lanes {
                x: Lanes::splat(p.x).max(nodes.box_lo.x).min(nodes.box_hi.x) - p.x,
                y: Lanes::splat(p.y).max(nodes.box_lo.y).min(nodes.box_hi.y) - p.y,
                z: Lanes::splat(p.z).max(nodes.box_lo.z).min(nodes.box_hi.z) - p.z,
            };
            let (lo, hi) = (
                nodes.box_lo.minus(p.to_array()).abs(),
                nodes.box_hi.minus(p.to_array()).abs(),
            );
            let farthest = Vec3Lanes {
                x: lo.x.max(hi.x),
                y: lo.y.max(hi.y),
                z: lo.z.max(hi.z),
            };
            (
                length(nearest) * (1.0 - DISTANCE_SLACK),
                length(farthest) * (1.0 + DISTANCE_SLACK),
            )
        };
        let (distance, radius) = (nodes.distance, nodes.radius);
        let near = (distance - radius).max(zero) * (1.0 - DISTANCE_SLACK);
        let near = near.max(box_near);
        let far = ((distance + radius) * (1.0 + DISTANCE_SLACK)).min(box_far);
        let a_hi = cone_hi + DIRECTION_SLACK;
        let a_hi = select(
            mask(|i| near.0[i] > 0.0),
            a_hi.min(z_hi.max(zero) / near * (1.0 + OP_SLACK)),
            a_hi,
        );
        let a_lo = cone_lo - DIRECTION_SLACK;
        let a_lo = select(
            mask(|i| z_lo.0[i] > 0.0 && far.0[i] > 0.0),
            a_lo.max(z_lo / far * (1.0 - OP_SLACK)),
            a_lo,
        );
        let (a_lo, a_hi) = (a_lo.max(zero).min(one), a_hi.max(zero).min(one));

        // c = v.h = sqrt((1 + v.l) / 2) >= (a + b) / 2, true values.
        let (vl_lo, vl_hi) = nodes.cos_range(v);
        // `cos_range`'s lower end is `cos(theta_c + delta)`, which is not
        // the minimum once `theta_c + delta > pi` (then `sin(theta_c +
        // delta) < 0`): there the cone reaches `-v` and the minimum is -1.
        let cos_c = nodes.axis.dot_with(v.to_array());
        let sin_c = length(cross(v, nodes.axis));
        let past = sin_c * nodes.cos_half + cos_c * nodes.sin_half;
        let vl_lo = select(mask(|i| past.0[i] <= DIRECTION_SLACK), -one, vl_lo);
        let half_root = |x: Lanes<N>| (0.5 * (1.0 + x)).max(zero).sqrt();
        let c_lo = (half_root(vl_lo - DIRECTION_SLACK) * (1.0 - OP_SLACK))
            .max(0.5 * (a_lo + b) * (1.0 - OP_SLACK));
        let c_hi = (half_root(vl_hi + DIRECTION_SLACK) * (1.0 + OP_SLACK))
            .min(one)
            .max(c_lo);

        // s = sin theta_h, true values: the ratio n.h = (a + b) / (2 c).
        let sine_of = |cos: Lanes<N>| {
            let cos = cos.max(zero).min(one);
            ((1.0 - cos) * (1.0 + cos)).sqrt()
        };
        let nh_lo = (a_lo + b) / (2.0 * c_hi) * (1.0 - OP_SLACK);
        let s_hi = sine_of(nh_lo) * (1.0 + OP_SLACK);
        let s_lo = select(
            mask(|i| c_lo.0[i] > 0.0),
            sine_of((a_hi + b) / (2.0 * c_lo) * (1.0 + OP_SLACK)) * (1.0 - OP_SLACK),
            zero,
        );
        // |l + v| = 2 v.h >= n.(l + v) = a + b.
        let h_min = (2.0 * c_lo).max(a_lo + b);

        // The half-vector cone.
        let axis_sum = plus(nodes.axis, v);
        let h_len = length(axis_sum);
        // |l - l_c| <= 2 sin(delta / 2) = sqrt(2 sin^2 delta / (1 + cos delta)).
        let (sd, cd) = (nodes.sin_half, nodes.cos_half);
        let eps = (2.0 * sd * sd / (1.0 + cd)).sqrt() * (1.0 + OP_SLACK) + DIRECTION_SLACK;
        // |H_c| is within about 20 u of the computed length.
        let h_c = h_len - DIRECTION_SLACK;
        let in_cone = mask(|i| h_c.0[i] > eps.0[i]);
        let sin_h = (eps / h_c * (1.0 + OP_SLACK)).min(one);
        let cos_h = ((1.0 - sin_h) * (1.0 + sin_h)).sqrt();
        let cos_c = axis_sum.dot_with(n.to_array()) / h_len;
        let sin_c = length(cross(n, axis_sum)) / h_len;
        let cone_s_lo = select(
            mask(|i| cos_c.0[i] >= cos_h.0[i]),
            zero,
            select(
                mask(|i| cos_c.0[i] * cos_h.0[i] + sin_c.0[i] * sin_h.0[i] <= 0.0),
                one,
                sin_c * cos_h - cos_c * sin_h,
            ),
        );
        let cone_s_hi = select(
            mask(|i| cos_c.0[i] * cos_h.0[i] - sin_c.0[i] * sin_h.0[i] <= 0.0),
            one,
            sin_c * cos_h + cos_c * sin_h,
        );
        let h_min = select(in_cone, h_min.max(h_c - eps), h_min);
        let s_lo = select(in_cone, s_lo.max(cone_s_lo), s_lo);
        let s_hi = select(in_cone, s_hi.min(cone_s_hi), s_hi);

        // Widen to the computed quantities of `eval`.
        let slack = DIRECTION_SLACK * (1.0 + 1.0 / h_min);
        Ranges {
            a: (
                (a_lo * (1.0 - HEIGHT_RELATIVE_SLACK) - DIRECTION_SLACK).max(zero),
                (a_hi * (1.0 + HEIGHT_RELATIVE_SLACK) + DIRECTION_SLACK).min(one),
            ),
            c: (
                (c_lo - DIRECTION_SLACK).max(zero),
                (c_hi + DIRECTION_SLACK).min(one),
            ),
            s: (
                (s_lo - slack).max(zero).min(one),
                (s_hi + slack).max(zero).min(one),
            ),
            h_min,
            near,
        }
    }

    /// The interval `[f_lo, f_hi]` of the BRDF over the nodes' lit
    /// members ((P4) in the module's text), from their [`Ranges`].
    #[inline(always)]
    pub(super) fn brdf_range<const N: usize>(
        &self,
        view: &GgxView,
        r: &Ranges<N>,
    ) -> (Rgb<N>, Rgb<N>) {
        let ((a_lo, a_hi), (c_lo, c_hi), (s_lo, s_hi)) = (r.a, r.c, r.s);
        let hi = self.distribution_lanes(s_lo * s_lo) * self.visibility_lanes(view, a_lo);
        let lo = self.distribution_lanes(s_hi * s_hi) * self.visibility_lanes(view, a_hi);
        let (f_hi, f_lo) = (self.fresnel_lanes(c_lo), self.fresnel_lanes(c_hi));
        (
            [0, 1, 2].map(|k| (f_lo[k] * lo * (1.0 - PRODUCT_SLACK)).max(Lanes::splat(0.0))),
            [0, 1, 2].map(|k| f_hi[k] * hi * (1.0 + PRODUCT_SLACK)),
        )
    }

    /// (P5)-(P9): the nodes' intervals from the second-order expansion of
    /// their members' terms about their centroids, and the lanes where it
    /// holds: not where a node's box or ball may reach the point, a
    /// member may have `n.l` below [`EXPANSION_MIN_COS`], or `|l + v|` may
    /// come within [`EXPANSION_MIN_HALF`] of 0 over it (the product bound
    /// alone serves those).
    #[inline(always)]
    #[allow(clippy::too_many_lines)]
    pub(super) fn expansion<const N: usize>(
        &self,
        view: &GgxView,
        surface: &Surface,
        nodes: &Nodes<'_, N>,
        r: &Ranges<N>,
    ) -> ([bool; N], Rgb<N>, Rgb<N>) {
        let near = r.near;
        let ((a_lo, a_hi), (s_lo, s_hi)) = (r.a, r.s);
        let h_min = r.h_min;
        let holds = mask(|i| {
            near.0[i] > 0.0
                && h_min.0[i] > EXPANSION_MIN_HALF
                && a_lo.0[i] > EXPANSION_MIN_COS
                && s_lo.0[i] <= s_hi.0[i]
        });
        let (n, v, b) = (surface.normal, surface.view, view.nv);
        let (alpha2, k) = (self.alpha2, self.k);
        let pi = core::f64::consts::PI;
        let zero = Lanes::<N>::splat(0.0);
        let (near2, near3) = (near * near, near * near * near);

        // The distribution over r^2, g = D / r^2: at y0 = c - p, its
        // gradient, and the bounds (P6) over the node.
        let y = nodes.offset;
        let d = nodes.distance;
        let l = nodes.axis;
        let m = plus(l, v);
        let mu = length(m);
        let h = Vec3Lanes {
            x: m.x / mu,
            y: m.y / mu,
            z: m.z / mu,
        };
        let t = h.dot_with(n.to_array());
        let q0 = alpha2
            + k * {
                let c = cross(n, h);
                c.dot(c)
            };
        let d0 = alpha2 / (pi * q0 * q0);
        let d_prime = 4.0 * k * t * d0 / q0;
        let inv_r = 1.0 / d;
        let inv_r2 = inv_r * inv_r;
        let g0 = d0 * inv_r2;
        // tilt = n - h t, then minus l (l . tilt).
        let tilt = Vec3Lanes::scaled_from(n.to_array(), t, h);
        let tilt = tilt - scaled(l, l.dot(tilt));
        let grad_g = scaled(tilt, d_prime / mu * inv_r2 * inv_r) - scaled(y, 2.0 * g0 * inv_r2);

        let t_hi = ((1.0 - s_lo) * (1.0 + s_lo)).max(zero).sqrt();
        let q = |s: Lanes<N>| alpha2 + k * (s * s);
        let q_lo = q(s_lo);
        let d_hi = alpha2 / (pi * q_lo * q_lo);
        let d_prime_hi = 4.0 * k * alpha2 * t_hi / (pi * q_lo * q_lo * q_lo);
        // sup of s^2 / q^4, s^2 / q^3 and s / q^3 over [s_lo, s_hi]: each
        // rises to its critical point k s^2 = alpha^2 / j and falls after.
        let at_critical = |j: f64| {
            if k > 0.0 {
                Lanes::splat((alpha2 / (j * k)).sqrt()).max(s_lo).min(s_hi)
            } else {
                s_lo
            }
        };
        let (s4, s3, s1) = (at_critical(3.0), at_critical(2.0), at_critical(5.0));
        let (q4, q3, q1) = (q(s4), q(s3), q(s1));
        let sup_s2_q4 = s4 * s4 / ((q4 * q4) * (q4 * q4));
        let sup_s2_q3 = s3 * s3 / (q3 * q3 * q3);
        let sup_s_q3 = s1 / (q1 * q1 * q1);
        let second_s2 =
            alpha2 / pi * (24.0 * k * k * t_hi * t_hi * sup_s2_q4 + 4.0 * k * sup_s2_q3);
        let first_s = 4.0 * k * alpha2 * t_hi / pi * sup_s_q3;
        let g_sup = d_hi / near2;
        let g1_sup = (first_s / h_min + 2.0 * d_hi) / near3;
        let g2_sup = ((second_s2 + d_prime_hi * t_hi + first_s) / (h_min * h_min)
            + (4.0 + UNIT_SECOND) * first_s / h_min
            + 6.0 * d_hi)
            / (near2 * near2);

        let radius = nodes.radius;
        let delta = Lanes::<N>::from_fn(|i| nodes.nodes[i].moment_error());

        // The rest, K = phi(a) F(c) with phi(a) = a Vis(a): at the
        // centroid, its gradient, and the bounds (P7) over the node.
        let m_of = |a: Lanes<N>| (alpha2 + k * a * a).sqrt();
        let u_of = |a: Lanes<N>| b * m_of(a) + a * view.m_v;
        let phi = |a: Lanes<N>| 0.5 * a / u_of(a);
        let phi_prime = |a: Lanes<N>| {
            let u = u_of(a);
            0.5 * b * alpha2 / (m_of(a) * u * u)
        };
        let a0 = l.dot_with(n.to_array());
        let c0 = 0.5 * mu;
        let one_minus = |c: Lanes<N>| (1.0 - c).max(zero);
        let c_lo = r.c.0;
        let (w0, w_lo) = (one_minus(c0), one_minus(c_lo));
        let fresnel_prime = |w: Lanes<N>| {
            let w4 = 5.0 * (w * w) * (w * w);
            [0, 1, 2].map(|c| (1.0 - self.f0[c]) * w4)
        };
        let (phi0, phi1_0) = (phi(a0), phi_prime(a0));
        let f_at0 = self.fresnel_lanes(c0);
        let k0 = f_at0.map(|f| f * phi0);
        let grad_a = scaled(Vec3Lanes::scaled_from(n.to_array(), a0, l), inv_r);
        let grad_c = scaled(h - scaled(l, l.dot(h)), 0.5 * inv_r);
        let f1_at0 = fresnel_prime(w0);

        let phi_hi = phi(a_hi);
        let phi1 = phi_prime(a_lo);
        let phi2 = {
            let (m_hi, m_lo) = (m_of(a_hi), m_of(a_lo));
            let (u_hi, u_lo) = (u_of(a_hi), u_of(a_lo));
            let numerator =
                (k * a_hi / m_hi) * u_hi + 2.0 * m_hi * (b * k * a_hi / m_hi + view.m_v);
            b * alpha2 * numerator / (2.0 * m_lo * m_lo * u_lo * u_lo * u_lo)
        };
        let f_hi = self.fresnel_lanes(c_lo);
        let f1 = fresnel_prime(w_lo);
        let w3 = 20.0 * w_lo * w_lo * w_lo;

        // (P7): the product's second derivative; the rounding (P9).
        let epsilon = 2.0 / self.alpha * DIRECTION_SLACK * (1.0 + 1.0 / h_min)
            + PRODUCT_SLACK
            + 64.0 * DIRECTION_SLACK * (1.0 / a_lo + 1.0 / h_min)
            + ARITHMETIC;
        let (mut lower, mut upper) = ([zero; 3], [zero; 3]);
        for c in 0..3 {
            let f2 = (1.0 - self.f0[c]) * w3;
            let k_sup = f_hi[c] * phi_hi;
            let k1_sup = (f_hi[c] * phi1 + f1[c] * (0.5 * phi_hi)) / near;
            let k2_sup = (f_hi[c] * (phi2 + UNIT_SECOND * phi1)
                + f1[c] * phi1
                + f2 * (0.25 * phi_hi)
                + f1[c] * (0.5 * phi_hi * (UNIT_SECOND + 1.0 / h_min)))
                / near2;
            let hessian =
                (k_sup * g2_sup + k1_sup * (2.0 * g1_sup) + k2_sup * g_sup) * (1.0 + OP_SLACK);
            let delta_k = f_hi[c] * (phi1 * (HEIGHT_RELATIVE_SLACK * a_hi + DIRECTION_SLACK))
                + f1[c] * (phi_hi * DIRECTION_SLACK);
            let value_round = (k_sup * epsilon + delta_k) * g_sup;
            let grad_round = (k_sup * g1_sup + k1_sup * g_sup) * epsilon
                + delta_k * g1_sup
                + k2_sup * (g_sup * near * 8.0 * DIRECTION_SLACK);

            // The second moments' traces, and the first moments' terms
            // with their rounding.
            let trace = Lanes::<N>::from_fn(|i| {
                let s = &nodes.nodes[i].channel_covariances[c];
                f64::from(s[0]) + f64::from(s[1]) + f64::from(s[2])
            });
            let trace = (trace * (1.0 + 2.0 * F32_ENTRY) + 3.0 * delta * radius * radius)
                .min(radius * radius)
                .max(zero);
            let o = Vec3Lanes::<N>::from_fn(|i| {
                nodes.nodes[i].channel_offsets[c].as_dvec3().to_array()
            });
            let value = g0 * k0[c];
            let grad_k = scaled(grad_a, phi1_0 * f_at0[c]) - scaled(grad_c, phi0 * f1_at0[c]);
            let grad = Vec3Lanes {
                x: grad_g.x * k0[c] + grad_k.x * g0,
                y: grad_g.y * k0[c] + grad_k.y * g0,
                z: grad_g.z * k0[c] + grad_k.z * g0,
            };
            let entry = |g: Lanes<N>, o: Lanes<N>| {
                (g.abs() + grad_round) * (delta * radius + F32_ENTRY * o.abs())
                    + grad_round * o.abs()
            };
            let moments = entry(grad.x, o.x) + entry(grad.y, o.y) + entry(grad.z, o.z);
            let first = grad.dot(o);
            let error =
                0.5 * hessian * trace + moments + value_round + ARITHMETIC * (value + first.abs());
            let centre = value + first;
            let intensity = Lanes::<N>::from_fn(|i| nodes.nodes[i].intensity[c]);
            let lit = mask(|i| intensity.0[i] != 0.0);
            lower[c] = select(lit, intensity * (centre - error).max(zero), zero);
            upper[c] = select(lit, intensity * (centre + error), zero);
        }
        (holds, lower, upper)
    }

    /// (P4): `[f_lo Q_lo, f_hi Q_hi]` from Lambert's intervals `q`,
    /// intersected with the expansion's intervals ((P5)-(P9)) where it
    /// holds, for nodes of more than one light.
    #[inline(always)]
    pub(super) fn product_lanes<const N: usize>(
        &self,
        view: &GgxView,
        surface: &Surface,
        nodes: &Nodes<'_, N>,
        q: &[NodeEstimate; N],
    ) -> [NodeEstimate; N] {
        let r = self.ranges(view, surface, nodes);
        let (f_lo, f_hi) = self.brdf_range(view, &r);
        let (holds, lo, hi) = self.expansion(view, surface, nodes, &r);
        array(NodeEstimate::ZERO, |i| {
            if q[i].upper.max_element() <= 0.0 {
                return NodeEstimate::ZERO;
            }
            let at = |v: &Rgb<N>| DVec3::new(v[0].0[i], v[1].0[i], v[2].0[i]);
            let mut lower = q[i].lower.max(DVec3::ZERO) * at(&f_lo);
            let mut upper = q[i].upper * at(&f_hi);
            if holds[i] && nodes.nodes[i].light_count() > 1 {
                lower = lower.max(at(&lo));
                upper = upper.min(at(&hi)).max(lower);
            }
            NodeEstimate::new(0.5 * (lower + upper), lower, upper)
        })
    }
}
