//! [`Lambert`]'s node bound in `f64` (see its docs, and `proofs` for the
//! derivations), for one to [`GROUP`] nodes side by side, one lane each:
//! the geometry every [`BoundKind`] shares ([`Prefix`]: the cone, the
//! paper's interval, the box's heights and the clamp term), the series'
//! interval over the same lanes, and each node's intersection of intervals
//! with its rare cases. The Taylor interval, one node at a time, is
//! `taylor`'s.

use glam::DVec3;

use super::series::{Rgb, WidthInput, degree_two_lanes, rgb, series_width};
use super::taylor::Geometry;
use super::{BoundKind, Lambert};
use crate::dispatch::avx2_or;
use crate::geometry::{Cone, Surface};
use crate::lanes::{Lanes, Vec3Lanes, array};
use crate::numeric::{COS_SLACK, SECOND_ORDER_SLACK, SERIES_SLACK};
use crate::shader::NodeEstimate;
use crate::tree::Node;

/// The rounding of a node's stored per-channel first moment `o_k`
/// ([`Node::channel_offsets`]) beyond the build's `moment_error`, in units
/// of the radius: `|o_k| <= R`, stored in `f32` (half an ulp, `2^-24`
/// relative, per coordinate), dotted with a unit normal (three terms), with
/// a factor of 4 to spare: `2^-22`.
const CHORD_MOMENT_SLACK: f64 = 1.0 / 4_194_304.0;

/// Nodes bounded side by side by
/// [`Shader::bound_nodes`](crate::shader::Shader::bound_nodes): two 4-wide AVX2
/// vectors of `f64`.
const GROUP: usize = 8;

impl Lambert {
    /// [`Shader::bound`](crate::shader::Shader::bound): one node, one lane.
    #[inline]
    pub(super) fn bound_one(&self, surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        let mut out = [NodeEstimate::ZERO];
        self.bound_group(surface, &[node], core::slice::from_ref(cone), &mut out);
        out[0]
    }

    /// [`Shader::bound_nodes`](crate::shader::Shader::bound_nodes): [`GROUP`] nodes
    /// at a time.
    #[inline(always)]
    pub(super) fn bound_chunks(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        let chunks = nodes.chunks(GROUP).zip(cones.chunks(GROUP));
        for ((nodes, cones), out) in chunks.zip(out.chunks_mut(GROUP)) {
            self.bound_group(surface, nodes, cones, out);
        }
    }

    /// Up to [`GROUP`] nodes side by side: on `x86_64` processors with
    /// AVX2, in a copy compiled for AVX2 (the same bits, see
    /// [`dispatch`](crate::dispatch)). Out of line, so that the bound is
    /// compiled once, not into every copy of the cut.
    // Not `with_avx2`: its closure stays out of line, with no AVX2 instructions (measured).
    #[inline(never)]
    fn bound_group(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        avx2_or!(
            Self::bound_group_avx2,
            Self::bound_group_inlined,
            self,
            surface,
            nodes,
            cones,
            out
        );
    }

    /// [`bound_group`](Self::bound_group) compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn bound_group_avx2(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        self.bound_group_inlined(surface, nodes, cones, out);
    }

    /// One lane for one node, four (one AVX2 vector) for up to four
    /// nodes, eight for more.
    #[inline(always)]
    fn bound_group_inlined(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        if let ([node], [cone], [out]) = (nodes, cones, &mut *out) {
            let [estimate] = self.bound_lanes(surface, &[node], &[cone]);
            *out = estimate;
        } else if nodes.len() <= 4 {
            self.bound_padded::<4>(surface, nodes, cones, out);
        } else {
            self.bound_padded::<GROUP>(surface, nodes, cones, out);
        }
    }

    /// `N` lanes for at most `N` nodes; unused lanes repeat the last node
    /// and their results are dropped.
    #[inline(always)]
    fn bound_padded<const N: usize>(
        &self,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        let count = nodes.len().min(cones.len());
        let last = count.max(1) - 1;
        let node_lanes: [&Node; N] = array(nodes[0], |i| nodes[i.min(last)]);
        let cone_lanes: [&Cone; N] = array(&cones[0], |i| &cones[i.min(last)]);
        let estimates = self.bound_lanes(surface, &node_lanes, &cone_lanes);
        for (out, estimate) in out.iter_mut().zip(estimates).take(count) {
            *out = estimate;
        }
    }
}

/// What every bound kind computes for `N` nodes seen from one point, one
/// lane each (see [`Lambert`]'s docs).
struct Prefix<const N: usize> {
    /// Unit axes `uh`.
    axis: Vec3Lanes<N>,
    /// `1 / D`.
    inv_d: Lanes<N>,
    /// `sigma = R / D`.
    sd: Lanes<N>,
    /// `c0 = n . uh`.
    z: Lanes<N>,
    /// `|n x uh|`.
    sin_c: Lanes<N>,
    /// The paper's upper cosine bound.
    cos_hi: Lanes<N>,
    /// `D / (D - R)`.
    inv_rho: Lanes<N>,
    /// The box, relative to nothing (its `f32` corners in `f64`).
    box_min: Vec3Lanes<N>,
    box_max: Vec3Lanes<N>,
    /// Lowest and highest `n . (x - p)` over the box, widened outward by
    /// the rounding of the box's support function (a few ulps of the
    /// coordinates' magnitude).
    lowest: Lanes<N>,
    highest: Lanes<N>,
    /// Bound on `sum (f - g) / I` in units of `1/D^2`: the depth term.
    straddle: Lanes<N>,
    /// The same per channel, the smaller of the depth term and the chord
    /// term (see [`Lambert`]'s docs).
    straddle_rgb: Rgb<N>,
    /// `I kd / D^2`.
    scale: Rgb<N>,
    /// The paper's interval and the virtual light.
    virtual_light: Rgb<N>,
    lower: Rgb<N>,
    upper: Rgb<N>,
    /// `I kd z_hi / (D - R)^3`.
    box_upper: Rgb<N>,
}

impl<const N: usize> Prefix<N> {
    #[inline(always)]
    fn new(kd: DVec3, surface: &Surface, nodes: &[&Node; N], cones: &[&Cone; N]) -> Self {
        let n = surface.normal;
        let axis = Vec3Lanes::from_fn(|i| cones[i].axis.to_array());
        let inv_d = Lanes::from_fn(|i| cones[i].inv_distance);
        let sd = Lanes::from_fn(|i| cones[i].sin_half_angle);
        let cd = Lanes::from_fn(|i| cones[i].cos_half_angle);
        // cos and sin of the angle between the normal and the axis, and the
        // range of the cosine over the ball (Cone::cos_range_from).
        let z = axis.dot_with(n.to_array());
        let cross = Vec3Lanes {
            x: n.y * axis.z - axis.y * n.z,
            y: n.z * axis.x - axis.z * n.x,
            z: n.x * axis.y - axis.x * n.y,
        };
        let sin_c = cross.dot(cross).sqrt();
        let hi = Lanes::select_ge(z, cd, Lanes::splat(1.0), z * cd + sin_c * sd);
        let lo = z * cd - sin_c * sd;
        let cos_lo = (lo - COS_SLACK).max(Lanes::splat(-1.0));
        let cos_hi = (hi + COS_SLACK).min(Lanes::splat(1.0));
        let zero = Lanes::splat(0.0);

        let inv_d2 = inv_d * inv_d;
        let scale: Rgb<N> = rgb(|k| Lanes::from_fn(|i| nodes[i].intensity[k]) * kd[k] * inv_d2);
        // D / (D - R): the nearest member's distance in units of D, inverted.
        let inv_rho = (1.0 - sd).recip();
        let far = (1.0 + sd).recip();
        let (far_falloff, z_plus) = (far * far, z.max(zero));
        let lower_cos = cos_lo.max(zero) * far_falloff;
        let upper_cos = cos_hi * inv_rho * inv_rho;

        // Heights of the box above the tangent plane (Aabb::extent_along).
        let box_min = Vec3Lanes::from_fn(|i| nodes[i].aabb.min.as_dvec3().to_array());
        let box_max = Vec3Lanes::from_fn(|i| nodes[i].aabb.max.as_dvec3().to_array());
        let p = surface.point;
        let (centre, half) = Vec3Lanes::centre_and_half(box_min, box_max);
        let from_point = centre.minus(p.to_array());
        let middle = from_point.dot_with(n.to_array());
        let reach = half.dot_with(n.abs().to_array());
        let largest = |v: Vec3Lanes<N>| v.x.max(v.y.max(v.z));
        let magnitude = largest(centre.abs()) + largest(half) + p.abs().max_element();
        let slack = SECOND_ORDER_SLACK * magnitude;
        let lowest = middle - reach - slack;
        let highest = middle + reach + slack;

        let inv_rho3 = inv_rho * inv_rho * inv_rho;
        // A second upper bound on cos/d^2 = z/d^3 over the members:
        // (highest z in the box) / (D - R)^3, much tighter than the paper's
        // for flat clusters barely above the plane.
        let box_cos = highest * inv_d * inv_rho3;
        // f = max(0, g) exceeds g only below the tangent plane, where
        // 0 <= f - g = -z/r^3 <= depth / (D - R)^3, depth being how far the
        // members reach below the plane: at most R - n.(c - p) (the ball) and
        // at most the box's depth. Zero when the box lies above the plane,
        // and continuous as a node crosses it. In units of 1/D^2.
        let depth = (sd - z).min(-lowest * inv_d).max(zero);
        // The chord: on [lowest, highest] the convex (-h)^+ lies below the
        // line through (lowest, -lowest) and (highest, 0), so
        // sum_i I_ik (-h_i)^+ <= I_k (-lowest) (highest - hbar_k) / (highest
        // - lowest), hbar_k = n.(c - p) + n.o_k the members' mean height for
        // channel k. hbar_k is widened downward by the rounding of its
        // inputs (n.o_k within (2 moment_error + 2^-22) R: sqrt(3) entries of
        // moment_error R each, and the f32 storage, see
        // CHORD_MOMENT_SLACK) so that the chord stays above.
        let c = Vec3Lanes::from_fn(|i| nodes[i].centroid.as_dvec3().to_array());
        let centre_height = c.minus(p.to_array()).dot_with(n.to_array());
        let radius = Lanes::from_fn(|i| f64::from(nodes[i].radius));
        let moment_slack = (Lanes::from_fn(|i| 2.0 * f64::from(nodes[i].moment_error))
            + CHORD_MOMENT_SLACK)
            * radius;
        let span = highest - lowest;
        let below = (-lowest).max(zero);
        let straddle_rgb = rgb(|k| {
            let o = Vec3Lanes::from_fn(|i| nodes[i].channel_offsets[k].as_dvec3().to_array());
            let mean = centre_height + o.dot_with(n.to_array()) - moment_slack - slack;
            let room = (highest - mean).max(zero).min(span);
            let chord = below * (room / span.max(Lanes::splat(f64::MIN_POSITIVE)));
            depth.min(chord * inv_d) * inv_rho3
        });
        Self {
            axis,
            inv_d,
            sd,
            z,
            sin_c,
            cos_hi,
            inv_rho,
            box_min,
            box_max,
            lowest,
            highest,
            straddle: depth * inv_rho3,
            straddle_rgb,
            scale,
            virtual_light: rgb(|k| scale[k] * z_plus),
            lower: rgb(|k| scale[k] * lower_cos),
            upper: rgb(|k| scale[k] * upper_cos),
            box_upper: rgb(|k| scale[k] * box_cos),
        }
    }
}

/// Lane `i` of a per-channel value.
#[inline(always)]
fn lane<const N: usize>(v: &Rgb<N>, i: usize) -> DVec3 {
    DVec3::new(v[0].0[i], v[1].0[i], v[2].0[i])
}

impl Lambert {
    /// The node bound of [`Lambert`]'s docs for `N` nodes, one lane each:
    /// the geometry and the series side by side, then each node's
    /// intersection of intervals and its rare cases (a ball or box below the
    /// tangent plane, the exact test for a box reaching it).
    #[inline(always)]
    fn bound_lanes<const N: usize>(
        &self,
        surface: &Surface,
        nodes: &[&Node; N],
        cones: &[&Cone; N],
    ) -> [NodeEstimate; N] {
        let g = Prefix::new(self.kd, surface, nodes, cones);
        let series = if self.kind == BoundKind::Series {
            Some(series_lanes(&g, surface, nodes, cones))
        } else {
            None
        };
        array(NodeEstimate::ZERO, |i| {
            if g.cos_hi.0[i] <= 0.0 {
                // The whole ball lies below the tangent plane.
                return NodeEstimate::ZERO;
            }
            let (virtual_light, lower) = (lane(&g.virtual_light, i), lane(&g.lower, i));
            let upper = lane(&g.upper, i);
            if self.kind == BoundKind::Paper {
                return NodeEstimate::new(virtual_light, lower, upper);
            }
            let (lowest, highest) = (g.lowest.0[i], g.highest.0[i]);
            // Whether the box lies at or below the plane is decided exactly,
            // with no slack, so that a box lying exactly in the plane is
            // recognised as contributing 0; only a box reaching below the
            // plane (lowest <= 0, a necessary condition) needs the test.
            if highest <= 0.0
                || (lowest <= 0.0
                    && highest > 0.0
                    && nodes[i]
                        .aabb
                        .lies_at_or_below(surface.point, surface.given_normal))
            {
                return NodeEstimate::ZERO;
            }
            let upper = upper.min(lane(&g.box_upper, i));
            let (lo2, hi2, estimate) = match &series {
                Some((lo2, hi2)) => (lane(lo2, i), lane(hi2, i), None),
                None => self.taylor(&Geometry {
                    surface,
                    node: nodes[i],
                    cone: cones[i],
                    scale: lane(&g.scale, i),
                    z: g.z.0[i],
                    sin_c: g.sin_c.0[i],
                    inv_rho: g.inv_rho.0[i],
                    straddle: g.straddle.0[i],
                }),
            };
            let lo = lower.max(lo2);
            let hi = upper.min(hi2);
            if lo.cmpgt(hi).any() {
                // Both intervals contain the exact value, so they overlap up
                // to rounding; keep the paper's interval if they do not.
                debug_assert!(
                    (lo - hi).max_element() <= 1e-9 * upper.max_element(),
                    "disjoint bounds: paper [{lower}, {upper}] second [{lo2}, {hi2}]"
                );
                return NodeEstimate::new(virtual_light, lower, upper);
            }
            match estimate {
                Some(estimate) => NodeEstimate::new(estimate, lo, hi),
                // The midpoint minimises the certified error.
                None => NodeEstimate::new(0.5 * (lo + hi), lo, hi),
            }
        })
    }
}

/// The multipole series interval `(lower, upper)` of the smooth sum for each
/// lane, widened upward by the clamp term; the estimate is the final
/// interval's midpoint.
#[inline(always)]
fn series_lanes<const N: usize>(
    g: &Prefix<N>,
    surface: &Surface,
    nodes: &[&Node; N],
    cones: &[&Cone; N],
) -> (Rgb<N>, Rgb<N>) {
    let n = surface.normal;
    let (uh, c0, inv_d) = (g.axis, g.z, g.inv_d);
    let series = degree_two_lanes(n, uh, inv_d, nodes);
    // Remainder in units of I_k / D^2. The quantities it grows with,
    // widened for their input rounding (see SERIES_SLACK).
    let ac = c0.abs() + SERIES_SLACK;
    let nu = g.sin_c + SERIES_SLACK;
    // hperp / D: the box's reach across the axis, from the box corners
    // relative to c (each difference one rounding of a value <= R).
    let nperp = Vec3Lanes::scaled_from(n.to_array(), c0, uh);
    let c = Vec3Lanes::from_fn(|i| nodes[i].centroid.as_dvec3().to_array());
    let (middle, half) = Vec3Lanes::centre_and_half(g.box_min - c, g.box_max - c);
    let reach = nperp.dot(middle).abs() + nperp.abs().dot(half);
    let radius = Lanes::from_fn(|i| cones[i].radius);
    let hperp = (reach + SERIES_SLACK * radius) * inv_d;
    let width = series_width(
        nodes,
        &WidthInput {
            inv_d,
            sigma: g.sd,
            inv_rho: g.inv_rho,
            ac,
            nu2: nu * nu,
            hperp,
        },
    );
    let lo2 = rgb(|k| g.scale[k] * (series[k] - width[k]));
    let hi2 = rgb(|k| g.scale[k] * (series[k] + width[k] + g.straddle_rgb[k]));
    (lo2, hi2)
}
