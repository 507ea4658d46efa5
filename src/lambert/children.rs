//! [`Lambert`]'s bound of a node's children together
//! ([`Shader::bound_children_coarse`]): the children's block read by
//! [`group`]'s kernel in `f32` lanes (whose rounding analysis is there),
//! each lane scaled by `I_k kd_k` in `f64`; children the lanes cannot take
//! are bounded one by one in `f64` ([`Shader::bound`]).

use glam::DVec3;

use super::{BoundKind, Lambert, group};
use crate::dispatch::avx2_or;
use crate::geometry::Surface;
use crate::shader::{ChildrenOf, NodeEstimate, Shader};
use crate::tree::Node;
use crate::tree::groups::{Block, with_block};

impl Lambert {
    /// [`Shader::bound_children_coarse`]: with [`BoundKind::Series`], the
    /// children of `parent` side by side in `f32` lanes ([`group`]), or
    /// `false` where they cannot be (another bound, no block, a point that
    /// is not an `f32` value).
    #[inline]
    pub(super) fn bound_children(
        &self,
        surface: &Surface,
        children: ChildrenOf<'_>,
        out: &mut [Option<NodeEstimate>],
    ) -> bool {
        let ChildrenOf {
            tree,
            parent,
            wanted,
        } = children;
        if self.kind != BoundKind::Series {
            return false;
        }
        let Some(node) = tree.nodes().get(parent) else {
            return false;
        };
        let Some(group) = tree.groups.children(parent) else {
            return false;
        };
        let p = surface.point.as_vec3();
        if p.as_dvec3() != surface.point {
            return false;
        }
        let at = group::PointView {
            p: p.to_array(),
            n: surface.normal.as_vec3().to_array(),
        };
        let children = &tree.nodes()[node.children()];
        with_block!(group, block => {
            let lanes = group_bounds(block, &at, &self.scales(children));
            self.fill_children(surface, children, wanted, &lanes, out);
        });
        true
    }

    /// What the group kernel reads of the children besides their block:
    /// `I_k kd_k` and the build's rounding bound of their moments; lanes
    /// past the children repeat the last child, as the block does.
    #[inline(always)]
    fn scales<const N: usize>(&self, children: &[Node]) -> group::LaneScales<N> {
        let last = children.len().max(1) - 1;
        let mut scales = group::LaneScales {
            intensity: [[0.0; N]; 3],
            moment_error: [0.0; N],
        };
        for i in 0..N {
            let Some(child) = children.get(i.min(last)) else {
                break;
            };
            let scale = child.intensity * self.kd;
            for k in 0..3 {
                scales.intensity[k][i] = scale[k];
            }
            scales.moment_error[i] = child.moment_error();
        }
        scales
    }

    /// The wanted children's results from their lanes (see
    /// [`Shader::bound_children_coarse`]).
    #[inline(always)]
    fn fill_children<const N: usize>(
        &self,
        surface: &Surface,
        children: &[Node],
        wanted: u8,
        lanes: &group::LaneBounds<N>,
        out: &mut [Option<NodeEstimate>],
    ) {
        for (i, (child, out)) in children.iter().zip(out.iter_mut()).enumerate() {
            if wanted & (1 << i) == 0 {
                continue;
            }
            *out = match lanes.state(i) {
                group::Lane::Fallback => child
                    .cone(surface.point)
                    .map(|cone| self.bound(&(), surface, child, &cone)),
                group::Lane::Dark => Some(NodeEstimate::ZERO),
                group::Lane::Reaching
                    if child
                        .aabb
                        .lies_at_or_below(surface.point, surface.given_normal) =>
                {
                    Some(NodeEstimate::ZERO)
                }
                group::Lane::Reaching | group::Lane::Bounded => {
                    let lane = |v: &[[f64; N]; 3]| DVec3::new(v[0][i], v[1][i], v[2][i]);
                    Some(NodeEstimate {
                        estimate: lane(&lanes.estimate),
                        lower: lane(&lanes.lower),
                        upper: lane(&lanes.upper),
                    })
                }
            };
        }
    }
}

/// A block's bounds ([`group::lane_bounds`]): on `x86_64` processors with
/// AVX2, in a copy compiled for AVX2 (the same bits, see
/// [`dispatch`](crate::dispatch)). Out of line, compiled once per block
/// width.
// Not `with_avx2`: its closure stays out of line, with no AVX2 instructions (measured).
#[inline(never)]
fn group_bounds<const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    at: &group::PointView<f32>,
    scales: &group::LaneScales<N>,
) -> group::LaneBounds<N> {
    avx2_or!(group_bounds_avx2, group::lane_bounds, block, at, scales)
}

/// [`group::lane_bounds`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn group_bounds_avx2<const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    at: &group::PointView<f32>,
    scales: &group::LaneScales<N>,
) -> group::LaneBounds<N> {
    group::lane_bounds(block, at, scales)
}
