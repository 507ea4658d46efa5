//! [`Lambert`](super::Lambert)'s bound for a group of shading points: the
//! series width taken at the group's worst view of a node, and the clamp
//! term where members reach below some point's tangent plane.

use glam::DVec3;

use super::series::{WidthInput, series_width};
use crate::geometry::GroupView;
use crate::lanes::{Lanes, array};
use crate::numeric::SERIES_SLACK;
use crate::tree::Node;

/// The width of the series interval shared by every shading point of a
/// group, per channel in units of `I_k / D^2` (`D` the group's nearest
/// distance, [`GroupView`]): for each point `p`, the smooth sum (`g`
/// unclamped) over the members of `node` lies within that width times
/// `I_k kd_k / D^2` of `I_k kd_k / D_p^2` times the series through degree 2
/// at `p`; where members lie below `p`'s tangent plane the exact sum
/// exceeds the smooth one by at most the clamp term of
/// [`Lambert`](super::Lambert)'s docs, which [`errors`] adds.
///
/// Why it holds: the width of the series bound at `p` is a sum of terms
/// that grow as `D_p` falls (`sigma = R / D_p`, `|o_k| / D_p`,
/// `tr(S_k) / D_p^2`, the tail sums, `D_p / (D_p - R)`) and as `|c0|` and
/// `hperp` grow, so it is largest at the smallest distance with the largest
/// `|c0|` and `hperp`; `A_m^2 = c0^2 (m+1)^2 + nu^2 m (m+1) / 2` with
/// `nu <= 1`; `|nperp . y| <= |n . y| + |c0| |uh . y|`,
/// `|n . y| <= |n0 . y| + |n - n0| |y|` and `|y| <= R` give
/// `hperp <= height + (tilt + |c0|) R`; and `I_k / D_p^2 <= I_k / D^2`.
///
/// `N` nodes side by side, each lane through exactly the operations of one
/// node alone (the same bits).
#[inline(always)]
pub(crate) fn widths<const N: usize>(nodes: &[&Node; N], views: &[GroupView; N]) -> [DVec3; N] {
    let mut input = WidthInput {
        inv_d: Lanes::splat(0.0),
        sigma: Lanes::splat(0.0),
        inv_rho: Lanes::splat(0.0),
        ac: Lanes::splat(0.0),
        nu2: Lanes::splat(1.0),
        hperp: Lanes::splat(0.0),
    };
    for (i, (node, view)) in nodes.iter().zip(views).enumerate() {
        let inv_d = view.inv_nearest;
        let radius = f64::from(node.radius);
        let sigma = radius * inv_d;
        let ac = view.cosine.min(1.0) + SERIES_SLACK;
        input.inv_d.0[i] = inv_d;
        input.sigma.0[i] = sigma;
        input.inv_rho.0[i] = 1.0 / (1.0 - sigma);
        input.ac.0[i] = ac;
        input.hperp.0[i] = (view.height + (view.tilt + ac + SERIES_SLACK) * radius) * inv_d;
    }
    let [x, y, z] = series_width::<N>(nodes, &input);
    array(DVec3::ZERO, |i| DVec3::new(x.0[i], y.0[i], z.0[i]))
}

/// Each node's error shared by every point of the group: `I kd / D^2`
/// times its [`widths`], and where members reach `depth` below some
/// point's tangent plane the clamp term: the exact sum exceeds the smooth
/// one by at most `I kd depth / (D - R)^3` at that point (see
/// [`Lambert`](super::Lambert)'s docs), `D - R` at least the view's gap.
#[inline(always)]
pub(crate) fn errors<const N: usize>(
    kd: DVec3,
    nodes: &[&Node; N],
    views: &[GroupView; N],
) -> [DVec3; N] {
    let widths = widths::<N>(nodes, views);
    array(DVec3::ZERO, |i| {
        let (node, view) = (nodes[i], &views[i]);
        let intensity = node.intensity * kd;
        let inv_nearest = view.inv_nearest;
        let mut error = intensity * (inv_nearest * inv_nearest) * widths[i];
        if view.depth > 0.0 {
            let gap = view.gap;
            error += intensity * (view.depth / (gap * gap * gap)) * (1.0 + 16.0 * f64::EPSILON);
        }
        error
    })
}
