//! Diffuse (Lambert) reflection with a certified node bound.
//!
//! The model: a light of intensity `I` at distance `d` in direction `w`
//! contributes `I kd max(0, n . w) / d^2` per channel, and 0 at `d = 0`.
//! [`Lambert`]'s docs state its node bounds ([`BoundKind`]) and their
//! domain; [`proofs`] derives them, every inequality with its domain, and
//! their rounding. The files, one concern each:
//!
//! * this one: [`Lambert`], [`BoundKind`], the constructors and the
//!   [`Shader`] impl, which delegates to the others;
//! * [`proofs`]: the derivations of the series and Taylor bounds and of
//!   their rounding (documentation only);
//! * [`leaf`]: a leaf's lights evaluated ([`Shader::eval_lights`]) and
//!   summed ([`Shader::sum_lights`]) in `f64`, four side by side, the sum
//!   also written with AVX2 instructions;
//! * [`node`]: the node bound in `f64` for one to eight nodes side by side:
//!   the geometry every [`BoundKind`] shares, the paper's and the box's
//!   intervals, the series' lanes, their intersection;
//! * [`series`]: the multipole series through degree 2 and the width of its
//!   remainder, over lanes;
//! * [`taylor`]: the second-order Taylor interval of one node;
//! * [`children`]: a node's children bounded together in `f32` lanes
//!   ([`Shader::bound_children_coarse`]) by [`group`]'s kernel, which holds
//!   the rounding analysis of that;
//! * [`coarse`]: the coarse sums of lights in `f32` and their rounding
//!   analysis;
//! * [`shared`]: the series bound shared by a group of shading points (the
//!   batch call).

use glam::{DVec3, Vec3};

#[cfg(test)]
mod bound_tests;
mod children;
mod coarse;
mod group;
mod leaf;
mod lobe;
mod node;
mod proofs;
mod series;
mod shared;
mod slab;
mod taylor;

pub(crate) use lobe::diffuse_lobe_bound;
pub(crate) use slab::slabs_apply;

use crate::dispatch::avx2_or;
use crate::geometry::{Cone, GroupView, Surface};
use crate::numeric::dot_of_difference;
use crate::shader::{
    ChildrenOf, NodeEstimate, Seal, Shader, ViewIndependent, colour_or_clamped, try_colour,
};
use crate::tree::Node;
use crate::{LightLanes, LightTree, PointLight, ShadeError};

/// Which node bound a shader uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum BoundKind {
    /// The paper's bound: the interval of the shading term over the node's
    /// ball, around the virtual light's value.
    Paper,
    /// The second-order Taylor bound: first-order colour correction in the
    /// estimate, Hessian bounds over the ball for the remainder, and the box
    /// refinements.
    Taylor,
    /// The dipole multipole series: the estimate sums the expansion through
    /// second order from per-channel moments, the remainder is bounded degree
    /// by degree from harmonic norms, with the box refinements.
    #[default]
    Series,
}

/// Diffuse reflection: a light of intensity `I` at distance `d` in direction
/// `w` contributes `I * kd * max(0, n . w) / d^2` (per channel; a light at
/// `d = 0` contributes 0).
///
/// # Node bound
/// For a node of intensity `I`, centroid `c`, radius `R`, seen at distance
/// `D = |c - p| > R` (a [`Cone`] with half-angle `delta`, `sin delta = R/D`,
/// and angle `theta_c` between `n` and the axis), three bounds are available
/// ([`BoundKind`]). All hold per channel `k`, whenever the cone exists
/// (`D - R > D * MIN_CLEARANCE`, see [`Cone::new`]), for any unit normal,
/// including nodes that straddle the tangent plane.
///
/// **Paper's bound** (slides "Diffuse Reflection Error Bound"):
///
/// ```text
/// I kd max(0, cos(theta_c + delta)) / (D + R)^2
///     <= exact <= I kd max(0, cos(max(0, theta_c - delta))) / (D - R)^2
/// ```
///
/// with the cosines from [`Cone::cos_range`] (sines and cosines, never
/// `acos`). The estimate is the virtual light, `I kd max(0, cos theta_c) / D^2`.
/// A ball wholly below the tangent plane contributes exactly 0.
///
/// **Box refinements** (with [`BoundKind::Taylor`] and [`BoundKind::Series`]),
/// from the node's tight box ([`Node::aabb`]) with `z_lo`, `z_hi` the lowest
/// and highest `n.(x - p)` over it: if `z_hi <= 0` every member is at or
/// below the tangent plane and the node is exactly 0; always
/// `exact <= I kd z_hi / (D - R)^3` (as `cos/d^2 = z/d^3`). Both refined
/// bounds work with the smooth `g(x) = n.(x - p) / |x - p|^3` and account
/// for the clamp `f = max(0, g)` separately: `f - g` is non-zero only below
/// the tangent plane, where `0 <= f - g = -z/d^3 <= depth / (D - R)^3`, with
/// `depth = max(0, min(R - n.(c - p), -z_lo))` how far the members reach
/// below the plane. So if `sum_i I_ik g(x_i)` lies in `[A, B]`, the exact
/// value lies in `kd_k [A, B + I_k depth / (D - R)^3]`; the extra term
/// vanishes when the box lies above the plane, which keeps the bound
/// continuous in `p` as a node crosses it. Each refined interval is
/// intersected with the paper's and the box's.
///
/// **The chord** (with [`BoundKind::Series`], in `f64`). Every member's
/// height `z_i = n.(x_i - p)` lies in `[z_lo, z_hi]`, where `max(0, -z)`
/// is convex, so it lies below the chord through `(z_lo, -z_lo)` and
/// `(z_hi, 0)`: `max(0, -z_i) <= -z_lo (z_hi - z_i) / (z_hi - z_lo)`.
/// Summed with the weights `I_ik`, whose mean height is `zbar_k = n.(c -
/// p) + n.o_k` ([`Node::channel_offsets`]),
/// `sum_i I_ik max(0, -z_i) <= I_k (-z_lo) (z_hi - zbar_k) / (z_hi -
/// z_lo)`, so the clamp term is `I_k min(depth, chord_k) / (D - R)^3` with
/// `chord_k = -z_lo (z_hi - zbar_k) / (z_hi - z_lo)`. For a node cut in
/// half by the plane that is about half the depth term. `zbar_k` is
/// widened downward by its inputs' rounding: `64 eps` of the coordinates'
/// magnitude for `n.(c - p)`, and `(2 delta + 2^-22) R` for `n.o_k` (the
/// build's moment rounding `delta` on `sqrt(3)` entries, and the `f32`
/// storage). The bounds in `f32` lanes keep the depth term.
///
/// **Multipole series** ([`BoundKind::Series`], the default). With `uh` the
/// unit axis from `p` to `c`, `c0 = n . uh`, `sigma = R / D`, and per
/// channel `k` the node's intensity `I_k`, first moment `o_k`
/// ([`Node::channel_offsets`]) and second moment matrix `S_k`
/// ([`Node::channel_covariances`]), the members' multipole expansion of `g`
/// about `c`, summed through degree 2, is
///
/// ```text
/// E_k = I_k / D^2 [c0 + (n.o_k - 3 c0 uh.o_k) / D
///                  + (15 c0 uh.S_k.uh - 3 c0 tr S_k - 6 uh.S_k.n) / (2 D^2)]
/// ```
///
/// and the rest, `rho_k`, is bounded degree by degree from the node's
/// harmonic norms ([`Node::harmonic_norms`]) for degrees 3 to 5 and in
/// closed form from degree 6 (the expansion converges for `sigma < 1`):
/// `sum_i I_ik g(x_i)` lies in `[E_k - rho_k, E_k + rho_k]`, which the
/// clamp term widens upward; intersected with the paper's interval and the
/// box's, times `kd_k`. The estimate is the final interval's midpoint,
/// which minimises the certified error
/// `max(estimate - lower, upper - estimate)`.
///
/// **Second-order Taylor bound** ([`BoundKind::Taylor`]). Per channel, the
/// members' sum of `g` is its Taylor expansion about `c` through first
/// order, `I_k g(c) + grad g(c) . (I_k o_k)`, plus a remainder bounded from
/// bounds on the Hessian of `g` over the ball and the second moments `S_k`
/// (along a frame with `e3 = n`, or isotropically, whichever is smaller):
/// the error is second order. The interval, widened upward by the clamp
/// term, is intersected with the paper's and the box's, times `kd_k`; the
/// estimate, the Taylor sum plus half the clamp term, is clamped into it.
///
/// # Nodes the tangent plane cuts
/// Where the tangent plane runs through a thin layer of lights (a roof
/// among street lamps at its height), every node near the layer straddles
/// it and the clamp term is as large as the node's value, however far the
/// node lies: the cut would walk down to the leaves. A tree built with
/// [`TreeBuilder::slab_moments`](crate::TreeBuilder::slab_moments) (the
/// default) keeps, for each node of at least 64 lights, its lights' moments
/// in 16 slices ("bins") across the thinnest axis `a` of its box, finer at
/// both faces: per bin and channel `W = sum I_ik`, `m1 = sum I_ik y`,
/// `M2 = sum I_ik y y^T` and `m3 = sum I_ik |y|^2 y` with `y = x - c`.
/// With [`BoundKind::Series`] or [`BoundKind::Taylor`], a node whose box the
/// plane runs through and which has a bin wholly above or below the plane
/// gets a second interval, intersected with the others (the estimate is
/// then the midpoint). Each bin's slice of the box has heights in
/// `[z-_j, z+_j]`, and per channel (`h_i` a member's height, `d_i` its
/// distance to `p`):
///
/// * a bin wholly below the plane (`z+_j <= 0`) contributes exactly 0;
/// * a bin the plane cuts: with `s_j = sum I_ik h_i = n.(c - p) W + n.m1`,
///   the convexity of `h^+` on `[z-_j, z+_j]` gives
///   `max(0, s_j) <= sum I_ik h_i^+ <= z+_j (s_j - z-_j W) / (z+_j - z-_j)`,
///   divided by the greatest and the least member distance cubed (from the
///   slice and the node's ball);
/// * the bins wholly above, together (a run from one end, as heights are
///   monotone along `a`): their sum is `sum_i u_i / d_i^3` with the
///   non-negative weights `u_i = I_ik h_i`, whose sums `U = sum u_i`,
///   `V = sum u_i y_i` and `Q = sum u_i |y_i|^2` are linear in the bins'
///   moments (`U = n.(c - p) W + n.m1`, `V = M2 n + n.(c - p) m1`,
///   `Q = n.m3 + n.(c - p) tr M2`). Taylor's theorem for `|x - p|^-3` about
///   any point `q` of the bins' hull, whose Hessian has eigenvalues
///   `-3 / r^5` (twice) and `12 / r^5` at distance `r`, gives
///
///   ```text
///   sum u_i / d_i^3 = U / |q - p|^3 - 3 (q - p).(V - U e) / |q - p|^5 + rem,
///   -3/2 S / d^5 <= rem <= 6 S / d^5,   S = Q - 2 e.V + U |e|^2 >= 0,
///   ```
///
///   with `e = q - c` and `d` the least distance from `p` to a segment from
///   `q` to a member (the hull's distance, or the ball's when `q` lies in
///   the ball). `q` is the weights' centroid `c + V / U` summed over the
///   channels, moved into the hull, so the first-order term nearly
///   vanishes; the interval is intersected with `[U / D_S^3, U / d_S^3]`
///   over the hull's members.
///
/// The moments are stored in `f32`, divided by `I_k R^j` (degree `j`), as
/// running sums over the bins; each within `2^-24 + 2 (n + 32) f64::EPSILON`
/// of its exact value (`n` the node's lights), and a run of bins within
/// twice that; every piece is widened by that, by `64 eps` of the
/// coordinates' magnitude for each height (the whole interval once more by
/// that over `(D - R)^3`), and by `2^-40` of its own magnitudes for its
/// arithmetic. On the street city at 10^6 lights, points
/// on roofs inside the lamps' layer drop from about 64,000 evaluations to
/// about 2,800 (see the repository's `docs/performance.md`). The batch
/// call's shared cuts do not use the bins: a group whose tangent plane at
/// its centre cuts a few nodes that way is shaded point by point. With
/// interpolation ([`Threshold::with_interpolation`](crate::Threshold::with_interpolation))
/// the bins are not used either: the slab interval changes where a bin
/// crosses the tangent plane, and the blend needs estimates continuous in
/// the point.
///
/// Every piece of the paper's, the series and the Taylor bounds is
/// continuous in `p`, so a node's estimate and error are too (the slab
/// interval is not, which is why interpolation does without it). The derivations of the series and Taylor bounds, every
/// inequality with its domain, are in the crate's source
/// (`src/lambert/proofs.rs`).
///
/// # Rounding
/// Every bound is widened by its own rounding: cosine bounds by
/// `16 f64::EPSILON`, the series by `1024 f64::EPSILON` of its terms'
/// magnitudes and `2 f64::EPSILON` for the offset `c - p`, the Taylor bound
/// by `64 f64::EPSILON` of its terms' magnitudes, both also for
/// the `f32` storage of the moments and for the build's `f64` sums of them
/// ([`Node::moment_error`](crate::shader::Node::moment_error)); stored diagonals of `S_k` and harmonic norms
/// are rounded upward at build time. Each allowance is derived with the
/// bounds (`src/lambert/proofs.rs`).
///
/// **Single precision.** [`Shader::bound_children_coarse`] evaluates the
/// same series, paper and box intervals for a node's children side by side
/// in `f32` lanes, every quantity dimensionless (in units of `D` and of
/// `I_k kd_k / D^2`) so that `f32`'s range holds at any scale, and the
/// final scaling in `f64`. Each step is widened by its own `f32` rounding,
/// derived operation by operation (`c0` within `8.6 u`, the degree-0 to 2
/// estimate within `u (11 + 69 x + 416 y)` with `u = 2^-24`, `x = |o_k|_1 /
/// D`, `y` the stored `S_k`'s magnitudes over `D^2`, the offset's rounding
/// as a point moved by `u D`, and so on; the allowances used are about
/// twice these), and a test checks every step against the same formula in
/// `f64`. Children with squared distances outside `[2^-120, 2^120]`, or
/// whose ball comes within `2^-6 D` of the point (where the offset's
/// rounding, magnified by `(D / (D - R))^3`, would dominate), are bounded
/// in `f64` as above. The harmonic norms are read from half-precision
/// copies rounded upward (at most `2^-10` larger).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lambert {
    kd: DVec3,
    kind: BoundKind,
}

impl Lambert {
    /// Diffuse albedo `kd` per channel, each finite and `>= 0`.
    ///
    /// Debug builds assert that; release builds keep results finite by
    /// reading NaN or negative channels as 0 and infinite ones as
    /// `f32::MAX`. [`Lambert::try_new`] returns an error instead.
    #[must_use]
    pub fn new(kd: Vec3) -> Self {
        Self {
            kd: colour_or_clamped(kd, "kd"),
            kind: BoundKind::Series,
        }
    }

    /// Like [`Lambert::new`], but refuses a NaN, infinite or negative channel.
    ///
    /// # Errors
    /// [`ShadeError::InvalidMaterial`].
    pub fn try_new(kd: Vec3) -> Result<Self, ShadeError> {
        Ok(Self {
            kd: try_colour(kd, "kd must be finite and >= 0")?,
            kind: BoundKind::Series,
        })
    }

    /// Selects the node bound (default [`BoundKind::Series`]).
    #[must_use]
    pub const fn with_bound(mut self, kind: BoundKind) -> Self {
        self.kind = kind;
        self
    }

    /// The albedo.
    #[must_use]
    pub fn kd(&self) -> DVec3 {
        self.kd
    }
}

impl Shader for Lambert {
    type PerPoint = ();

    /// Always `Some(kd)`, whichever [`BoundKind`]: shared cuts use their own
    /// bound (the series, enlarged over the group of points).
    #[inline]
    fn diffuse_albedo(&self, _: Seal) -> Option<DVec3> {
        Some(self.kd)
    }

    /// The series width at the group's worst view ([`shared::errors`]).
    #[inline(always)]
    fn group_errors<const N: usize>(
        &self,
        _: Seal,
        nodes: &[&Node; N],
        views: &[GroupView; N],
    ) -> Option<[DVec3; N]> {
        Some(shared::errors::<N>(self.kd, nodes, views))
    }

    #[inline]
    fn prepare(&self, _surface: &Surface) {}

    /// The given normal: [`eval`](Shader::eval) takes the exact sign of
    /// `N . (x - p)` and returns 0 where it is at most 0.
    #[inline]
    fn horizon(&self, surface: &Surface) -> Option<Vec3> {
        Some(surface.given_normal)
    }

    /// The model's term `I kd max(0, n.w) / d^2` with `n = N / |N|` for the
    /// given normal `N`, computed as `N.(x - p) / (|N| d^3)`. For a
    /// `position` holding `f32` values (every light's), the sign of `N.(x -
    /// p)` is exact and its value within `2^-40` relative, within about
    /// `f64::EPSILON` near the plane (error-free transformations): a light
    /// in the tangent plane
    /// contributes exactly 0, one barely above it its value to a few ulps.
    #[inline(always)]
    fn eval(&self, _: &(), surface: &Surface, position: DVec3, intensity: DVec3) -> DVec3 {
        let normal = surface.given_normal.as_dvec3();
        let height = dot_of_difference(normal, position, surface.point);
        // Lights at or below the tangent plane contribute nothing; so does a
        // light on the shading point (d = 0), whose height is exactly 0.
        if !(height > 0.0) {
            return DVec3::ZERO;
        }
        let d2 = (position - surface.point).length_squared();
        // |N| d^3 = d^2 sqrt(|N|^2 d^2): one square root.
        let scale = d2 * (normal.length_squared() * d2).sqrt();
        intensity * self.kd * (height / scale)
    }

    /// Four lights at a time side by side, with the very same operations
    /// per light as [`eval`](Shader::eval) (lights within about 0.1 degree
    /// of the tangent plane, whose height needs the compensated or exact
    /// dot product, go through `eval` itself): the same results, bit for
    /// bit.
    #[inline]
    fn eval_lights(&self, _: &(), surface: &Surface, lights: &[PointLight], out: &mut [DVec3]) {
        self.eval_group(surface, lights, out);
    }

    /// Four lights at a time side by side, each lane summing its lights'
    /// `intensity * height / (|N| d^3)` where the height is positive (the
    /// terms of [`eval`](Shader::eval) before `kd`, the height accepted as
    /// `eval` accepts it); lights within about 0.1 degree of the tangent
    /// plane go through `eval` itself.
    #[inline]
    fn sum_lights(&self, _: Seal, _: &(), surface: &Surface, lights: &[PointLight]) -> DVec3 {
        self.sum_group(surface, lights)
    }

    /// The plain `f64` sum, four lights side by side, each height's
    /// rounding bounded by its magnitude (see `PLAIN_HEIGHT_ERROR` in the
    /// source): for any lights and point in the supported range.
    #[inline]
    fn sum_lights_plain(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        Some(self.sum_plain(surface, lights))
    }

    /// In `f32`, eight lights side by side: within `32 * 2^-24` of `kd`
    /// times `sum max_k I_k / d^2` over the lights (per channel), for
    /// squared distances between `2^-60` and `2^60` and intensities up to
    /// `2^40` (else `None`), at a point that is an `f32` value.
    #[inline]
    fn sum_lights_coarse(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        avx2_or!(
            coarse::sum_avx2,
            coarse::sum_baseline,
            self.kd,
            surface,
            lights
        )
    }

    /// The same bits as [`sum_lights_coarse`](Shader::sum_lights_coarse)
    /// on the same lights, each quantity of eight lights loaded at once.
    #[inline]
    fn sum_lanes_coarse(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        lanes: &[LightLanes],
        count: usize,
    ) -> Option<(DVec3, DVec3)> {
        avx2_or!(
            coarse::sum_lanes_avx2,
            coarse::sum_lanes_baseline,
            self.kd,
            surface,
            lanes,
            count
        )
    }

    /// Blocks of 64 lights summed as by
    /// [`sum_lanes_coarse`](Shader::sum_lanes_coarse), their lanes added
    /// in `f64`: the same bound (see the rounding analysis of the coarse
    /// sums), one call for the whole scene.
    #[inline]
    fn sum_scene_coarse(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        lanes: &[LightLanes],
        count: usize,
    ) -> Option<(DVec3, DVec3)> {
        avx2_or!(
            coarse::sum_scene_lanes_avx2,
            coarse::sum_scene_lanes_baseline,
            self.kd,
            surface,
            lanes,
            count
        )
    }

    /// With [`BoundKind::Series`], the children side by side in `f32`
    /// lanes (see the `group` module's rounding analysis), each scaled by
    /// `I_k kd_k / D^2` in `f64`; children too far or too near for `f32`
    /// (squared distances outside `[2^-120, 2^120]`, or a ball within
    /// `2^-6 D` of the point) go through [`bound`](Shader::bound), and a
    /// box reaching the tangent plane is tested exactly, as there.
    #[inline]
    fn bound_children_coarse(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        children: ChildrenOf<'_>,
        out: &mut [Option<NodeEstimate>],
    ) -> bool {
        self.bound_children(surface, children, out)
    }

    #[inline]
    fn narrows_with_slabs(&self, _: Seal) -> bool {
        self.kind != BoundKind::Paper
    }

    #[inline(always)]
    fn narrow_bound(
        &self,
        _: Seal,
        _: &(),
        surface: &Surface,
        tree: &LightTree,
        index: usize,
        bound: NodeEstimate,
    ) -> NodeEstimate {
        self.narrow_with_slabs(surface, tree, index, bound)
    }

    #[inline]
    fn bound(&self, _: &(), surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        self.bound_one(surface, node, cone)
    }

    /// Eight nodes at a time, side by side in vector registers, with the
    /// very same operations per node as [`bound`](Shader::bound): the same
    /// results, bit for bit.
    #[inline(always)]
    fn bound_nodes(
        &self,
        _: &(),
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        self.bound_chunks(surface, nodes, cones, out);
    }
}

impl ViewIndependent for Lambert {}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};

    use super::{BoundKind, Lambert};
    use crate::dispatch::baseline;
    use crate::shader::{Cone, Node, NodeEstimate, Shader, Surface};
    use crate::{Combined, LightTree, Phong, PointLight};

    fn bits(e: &NodeEstimate) -> [u64; 9] {
        let mut out = [0; 9];
        let values = [e.estimate, e.lower, e.upper].map(|v| v.to_array());
        for (out, v) in out.iter_mut().zip(values.iter().flatten()) {
            *out = v.to_bits();
        }
        out
    }

    /// Every node's children bounded together ([`Shader::bound_nodes`], up
    /// to eight side by side, in both compiled copies) give exactly the bits
    /// of bounding each alone ([`Shader::bound`]), for every bound kind and
    /// a sum of shaders, from points above, below and among the lights; and
    /// lights evaluated together ([`Shader::eval_lights`]) the bits of each
    /// alone, lights in and next to the tangent plane included.
    fn check<S: Shader>(shader: &S, tree: &LightTree, surface: &Surface) -> usize {
        let point = shader.prepare(surface);
        let mut compared = 0;
        for parent in tree.nodes() {
            let (nodes, cones): (Vec<&Node>, Vec<Cone>) = tree.nodes()[parent.children()]
                .iter()
                .filter_map(|c| Some((c, c.cone(surface.point)?)))
                .unzip();
            let single: Vec<NodeEstimate> = nodes
                .iter()
                .zip(&cones)
                .map(|(n, c)| shader.bound(&point, surface, n, c))
                .collect();
            for copy in [false, true] {
                let mut together = vec![NodeEstimate::ZERO; nodes.len()];
                let run = |out: &mut [NodeEstimate]| {
                    shader.bound_nodes(&point, surface, &nodes, &cones, out);
                };
                if copy {
                    baseline(|| run(&mut together));
                } else {
                    run(&mut together);
                }
                for (a, b) in single.iter().zip(&together) {
                    assert_eq!(bits(a), bits(b), "{a:?} against {b:?}");
                }
            }
            compared += nodes.len();
        }
        // Lights, with some in the tangent plane and just off it.
        let mut lights = tree.lights().to_vec();
        for (k, light) in lights.iter_mut().enumerate().step_by(7) {
            let n = surface.given_normal;
            let offset = [0.0, 1e-7, -1e-7][k % 3];
            light.position =
                surface.point.as_vec3() + n.any_orthonormal_vector() * 3.0 + n * offset;
        }
        let single: Vec<[u64; 3]> = lights
            .iter()
            .map(|l| {
                let v = shader.eval(
                    &point,
                    surface,
                    l.position.as_dvec3(),
                    l.intensity.as_dvec3(),
                );
                v.to_array().map(f64::to_bits)
            })
            .collect();
        for copy in [false, true] {
            let mut together = vec![DVec3::ZERO; lights.len()];
            let run = |out: &mut [DVec3]| shader.eval_lights(&point, surface, &lights, out);
            if copy {
                baseline(|| run(&mut together));
            } else {
                run(&mut together);
            }
            for (a, b) in single.iter().zip(&together) {
                assert_eq!(*a, b.to_array().map(f64::to_bits), "{b}");
            }
        }
        compared
    }

    #[test]
    fn nodes_bounded_together_give_the_bits_of_each_alone() {
        let mut state = 3u64;
        let mut u = || crate::testing::uniform(&mut state);
        let lights: Vec<PointLight> = (0..12000)
            .map(|_| {
                let p = Vec3::new(u() * 40.0 - 20.0, u() * 40.0 - 20.0, u() * 6.0);
                PointLight::new(p, Vec3::new(u(), u() * 3.0, u() * 0.1))
            })
            .collect();
        let tree = LightTree::build(&lights).unwrap();
        let mut compared = 0;
        for (point, normal) in [
            (Vec3::new(1.0, 2.0, 0.0), Vec3::Z),
            (Vec3::new(-5.0, 3.0, 3.0), Vec3::new(0.3, -0.2, 1.0)),
            (Vec3::new(25.0, 0.0, 2.0), Vec3::new(-1.0, 0.0, 0.001)),
            (Vec3::new(0.0, 0.0, 10.0), Vec3::NEG_Z),
        ] {
            let view = Vec3::new(0.2, -0.4, 1.0);
            let surface = Surface::new(point, normal, Some(view)).unwrap();
            for kind in [BoundKind::Series, BoundKind::Taylor, BoundKind::Paper] {
                let lambert = Lambert::new(Vec3::new(0.8, 0.5, 0.3)).with_bound(kind);
                compared += check(&lambert, &tree, &surface);
            }
            let glossy = Combined::new(
                Lambert::new(Vec3::splat(0.4)),
                Phong::new(Vec3::splat(0.3), 30.0),
            );
            compared += check(&glossy, &tree, &surface);
        }
        assert!(compared > 10_000, "{compared} nodes compared");
    }

    /// Slices of different lengths: entries past the shortest are ignored
    /// and their outputs left alone, with no panic.
    #[test]
    fn mismatched_slices_leave_the_extra_outputs_alone() {
        let lights: Vec<PointLight> = (0..200)
            .map(|i| PointLight::new(Vec3::new(i as f32, (i % 7) as f32, 3.0), Vec3::ONE))
            .collect();
        let tree = LightTree::build(&lights).unwrap();
        let surface = Surface::new(Vec3::new(-5.0, 0.0, 0.0), Vec3::Z, None).unwrap();
        let nodes: Vec<&Node> = tree.nodes().iter().take(6).collect();
        let cones: Vec<Cone> = nodes
            .iter()
            .map(|n| n.cone(surface.point).unwrap())
            .collect();
        let lambert = Lambert::new(Vec3::ONE);
        let mark = NodeEstimate::new(DVec3::splat(-1.0), DVec3::splat(-1.0), DVec3::splat(-1.0));
        for (n, c) in [(6, 2), (2, 6), (6, 5), (1, 0), (0, 1)] {
            let mut out = [mark; 6];
            lambert.bound_nodes(&(), &surface, &nodes[..n], &cones[..c], &mut out);
            for (i, out) in out.iter().enumerate() {
                if i < n.min(c) {
                    assert_eq!(*out, lambert.bound(&(), &surface, nodes[i], &cones[i]));
                } else {
                    assert_eq!(*out, mark, "entry {i} of {n} nodes and {c} cones");
                }
            }
        }
        let mut out = [DVec3::splat(-1.0); 5];
        lambert.eval_lights(&(), &surface, &lights[..3], &mut out);
        assert_eq!(out[3], DVec3::splat(-1.0));
        assert!(out[..3].iter().all(|v| v.min_element() >= 0.0));
    }
}
