//! Writing a shader: the [`Shader`] trait (exact evaluation of one light, a
//! certified bound for a node), the [`NodeEstimate`] it returns, and the
//! geometry and node data a bound reads ([`Surface`], [`Cone`], [`Node`]
//! and its [`Aabb`](crate::Aabb)).
//!
//! A renderer that uses the crate's shaders ([`Lambert`](crate::Lambert),
//! [`Phong`](crate::Phong), [`Combined`](crate::Combined)) needs nothing
//! from this module.

use glam::{DVec3, Vec3};

use crate::geometry::GroupView;
pub use crate::geometry::{Cone, Surface};
pub use crate::ggx::GgxView;
pub use crate::phong::Mirror;
pub use crate::tree::Node;
use crate::{LightLanes, PointLight, ShadeError};

/// The token of the [`Shader`] trait's crate-internal methods (the fast
/// paths of the crate's own shaders: sums and bounds in `f32` lanes, bounds
/// for groups of points). It lives in a private module, so a shader outside
/// the crate can neither call nor override those methods; their defaults
/// are what a custom shader gets, and need nothing from it.
mod sealed {
    #[derive(Clone, Copy, Debug)]
    pub struct Seal;

    /// The children of node `parent` of `tree` whose bits are set in
    /// `wanted` (child `first_child + i` is bit `i`).
    #[derive(Clone, Copy, Debug)]
    pub struct ChildrenOf<'t> {
        pub tree: &'t crate::tree::LightTree,
        pub parent: usize,
        pub wanted: u8,
    }
}

pub(crate) use sealed::{ChildrenOf, Seal};

/// The most lights the cut passes to one [`Shader::sum_lights`] call.
pub(crate) const SUM_LIGHTS_MAX: usize = 16;

/// The most lights the cut passes to one call of
/// [`Shader::sum_lights_coarse`].
pub(crate) const COARSE_LIGHTS_MAX: usize = 64;

/// A node's estimated contribution with a certified interval around it, per
/// RGB channel.
///
/// Contract: for every channel `k`, the exact contribution of the node's
/// lights (as [`Shader::eval`] summed over them would give in exact
/// arithmetic) lies in `[lower[k], upper[k]]`, and
/// `lower[k] <= estimate[k] <= upper[k]`. The node's error is then at most
/// `max(estimate - lower, upper - estimate)` per channel. Rounding: relative
/// errors of order `1e-12` in the three values are allowed (the crate's
/// [`ROUNDING_ALLOWANCE`](crate::ShadeResult::ROUNDING_ALLOWANCE) absorbs them), absolute
/// ones are not: where a value can cancel, widen it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeEstimate {
    /// The estimate used for the node.
    pub estimate: DVec3,
    /// Certified lower bound (per channel).
    pub lower: DVec3,
    /// Certified upper bound (per channel); also the node's *maximal
    /// contribution* used by the specular criterion.
    pub upper: DVec3,
}

impl NodeEstimate {
    /// A node that contributes nothing, with no error.
    pub const ZERO: Self = Self {
        estimate: DVec3::ZERO,
        lower: DVec3::ZERO,
        upper: DVec3::ZERO,
    };

    /// Error of the estimate per channel: `max(estimate - lower, upper -
    /// estimate)`.
    #[inline(always)]
    #[must_use]
    pub fn error(&self) -> DVec3 {
        (self.estimate - self.lower).max(self.upper - self.estimate)
    }

    /// The interval `[lower, upper]` with `estimate` clamped into it.
    #[inline(always)]
    #[must_use]
    pub fn new(estimate: DVec3, lower: DVec3, upper: DVec3) -> Self {
        Self {
            estimate: estimate.clamp(lower, upper.max(lower)),
            lower,
            upper: upper.max(lower),
        }
    }
}

/// A reflectance model with a bound for groups of lights.
///
/// An implementation gives the exact contribution of one point light and a
/// certified [`NodeEstimate`] for a whole node of the
/// [`LightTree`](crate::LightTree) from the node's stored data alone. The
/// crate's cut (see [`Shading`](crate::Shading)) refines nodes until the
/// bounds meet the requested threshold, and is only as certified as the
/// bounds: a custom shader must guarantee [`NodeEstimate`]'s contract for
/// every node whose [`Cone`] exists (nodes whose ball reaches the shading
/// point have no cone and are always refined).
///
/// Everything is computed in `f64`. Per shading point the shader derives
/// what it needs once ([`prepare`](Self::prepare), e.g. Phong's mirror
/// direction) and gets it back in every call. Implementations that need no
/// view direction also implement the marker [`ViewIndependent`], which
/// unlocks the view-less shading calls.
///
/// # Writing one
/// Three methods are required. `eval` must be the model (the exact
/// reference, [`Shading::exact_query`](crate::Shading::exact_query), sums
/// it); `bound` may use the node's intensity, ball ([`Cone`]), box, weight,
/// first and second moments ([`Node`]'s accessors document each). The
/// simplest valid bound is the interval of the model over the ball:
/// smallest and largest value of the BRDF times `1/(D + R)^2` and `1/(D -
/// R)^2`, times the node's intensity. Three more are optional:
/// [`eval_lights`](Self::eval_lights) and [`bound_nodes`](Self::bound_nodes)
/// to evaluate several lights or bound several nodes side by side, and
/// [`horizon`](Self::horizon) to let the cut settle coplanar nodes below
/// the surface without bounding them. The crate's own shaders have further
/// fast paths (sums and bounds in `f32` lanes, bounds for groups of points)
/// that are not part of the trait a custom shader implements.
pub trait Shader {
    /// Per-shading-point data the shader derives once per call (for Phong,
    /// the mirror direction), passed back to `eval` and `bound`.
    type PerPoint: Copy;

    /// Derives the per-point data.
    fn prepare(&self, surface: &Surface) -> Self::PerPoint;

    /// Exact RGB contribution of one light of `intensity` at `position`.
    fn eval(
        &self,
        point: &Self::PerPoint,
        surface: &Surface,
        position: DVec3,
        intensity: DVec3,
    ) -> DVec3;

    /// Certified bound for all lights of `node`, seen under `cone`.
    fn bound(
        &self,
        point: &Self::PerPoint,
        surface: &Surface,
        node: &Node,
        cone: &Cone,
    ) -> NodeEstimate;

    /// Evaluates several lights: `out[i]` receives exactly what
    /// [`eval`](Self::eval) gives for `lights[i]` (both slices have the same
    /// length; past the shorter, entries are ignored and `out` is left as it
    /// was). The cut calls it with a leaf's lights, so that a shader can
    /// evaluate them side by side in vector registers, as [`Lambert`] does;
    /// the default evaluates them one by one.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    fn eval_lights(
        &self,
        point: &Self::PerPoint,
        surface: &Surface,
        lights: &[PointLight],
        out: &mut [DVec3],
    ) {
        for (light, out) in lights.iter().zip(out) {
            *out = self.eval(
                point,
                surface,
                light.position.as_dvec3(),
                light.intensity.as_dvec3(),
            );
        }
    }

    /// Bounds several nodes seen from one point: `out[i]` receives exactly
    /// what [`bound`](Self::bound) gives for `nodes[i]` under `cones[i]`
    /// (the three slices have the same length; past the shortest, entries
    /// are ignored and `out` is left as it was). The cut calls it with the
    /// children of a node that enter it together, so that a shader can
    /// bound them side by side in vector registers, as [`Lambert`]'s series
    /// bound does; the default bounds them one by one.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    fn bound_nodes(
        &self,
        point: &Self::PerPoint,
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        for ((node, cone), out) in nodes.iter().zip(cones).zip(out) {
            *out = self.bound(point, surface, node, cone);
        }
    }

    /// A vector `a` such that [`eval`](Self::eval) is exactly 0 for every
    /// light at or below the plane through the shading point perpendicular
    /// to `a` (`a . (x - p) <= 0` exactly, for `a` as returned). The cut
    /// then settles as 0, without bounding it, a node whose lights all lie
    /// exactly in one plane parallel to that one and not above it (lights
    /// on a tilted roof, seen from a point of the roof).
    /// [`Lambert`](crate::Lambert) returns the given normal; the default,
    /// `None`, claims nothing.
    fn horizon(&self, surface: &Surface) -> Option<Vec3> {
        let _ = surface;
        None
    }

    // The crate's own fast paths: hidden, sealed by `Seal` (a custom shader
    // can neither call nor override them), each with a default that needs
    // nothing of the shader. When the cut calls them is its policy
    // (`cut::policy`); their docs give their contracts.

    /// The sum of what [`eval`](Self::eval) gives for each of `lights`: what
    /// the cut adds for lights known visible, at most [`SUM_LIGHTS_MAX`] a
    /// call.
    ///
    /// Contract: every term is non-negative (as `eval`'s must be), and the
    /// result may differ from the exact sum of the exact terms by each
    /// term's own relative rounding (as `eval`'s) and by the rounding of a
    /// plain `f64` sum of the terms in any order, at most `lights.len()`
    /// roundings (relative, the terms being non-negative): both are far
    /// inside the crate's
    /// [`ROUNDING_ALLOWANCE`](crate::ShadeResult::ROUNDING_ALLOWANCE). The
    /// default sums [`eval_lights`](Self::eval_lights) in order;
    /// [`Lambert`] sums four lights at a time in vector registers.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    #[doc(hidden)]
    fn sum_lights(
        &self,
        _: Seal,
        point: &Self::PerPoint,
        surface: &Surface,
        lights: &[PointLight],
    ) -> DVec3 {
        let mut values = [DVec3::ZERO; SUM_LIGHTS_MAX];
        let mut sum = DVec3::ZERO;
        for lights in lights.chunks(SUM_LIGHTS_MAX) {
            let values = &mut values[..lights.len()];
            self.eval_lights(point, surface, lights, values);
            for value in values.iter() {
                sum += *value;
            }
        }
        sum
    }

    /// A cheaper sum of the model's terms for `lights`, known visible,
    /// with a certified bound on its error: `Some((sum, error))` with
    /// `|sum - exact| <= error` per channel, `exact` the exact sum of the
    /// exact terms; or `None` where the shader has no such sum, or the
    /// lights (or the point) fall outside the range it handles.
    ///
    /// At most [`COARSE_LIGHTS_MAX`] lights a call. The cut adds `error`
    /// to the bound it reports. The default returns `None`. [`Lambert`]
    /// sums in `f32`, eight lights side by side; a sum of shaders
    /// ([`Combined`](crate::Combined)) where either term does, the other
    /// term adding its [`sum_lights`](Self::sum_lights).
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    #[doc(hidden)]
    fn sum_lights_coarse(
        &self,
        _: Seal,
        point: &Self::PerPoint,
        surface: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        let _ = (point, surface, lights);
        None
    }

    /// The plain `f64` sum of the model's terms for `lights`, known
    /// visible, with a certified bound on its error: `Some((sum, error))`
    /// with `|sum - exact| <= error` per channel, as
    /// [`sum_lights_coarse`](Self::sum_lights_coarse), or `None` (the
    /// default). Where that coarse sum's error is too large for the cut
    /// (lights within a hair of the tangent plane, whose `f32` heights
    /// are mostly rounding), this one costs a few `f64` operations a light,
    /// where [`sum_lights`](Self::sum_lights) takes the error-free dot
    /// products behind every such term's sign. At most
    /// [`COARSE_LIGHTS_MAX`] lights a call. [`Lambert`] bounds the plain
    /// heights' rounding by their magnitudes; a sum of shaders
    /// ([`Combined`](crate::Combined)) where either term does, the other
    /// adding its [`sum_lights`](Self::sum_lights).
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    #[doc(hidden)]
    fn sum_lights_plain(
        &self,
        _: Seal,
        point: &Self::PerPoint,
        surface: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        let _ = (point, surface, lights);
        None
    }

    /// [`sum_lights_coarse`](Self::sum_lights_coarse) of the `count`
    /// lights that `lanes` hold side by side (light `8 j + k` in lane `k`
    /// of `lanes[j]`; at most 64 lights, `count` of them, the spare lanes
    /// of the last group repeating the last light): `Some` of a sum and a
    /// certified bound on its error as there, or `None` (the default).
    /// [`Lambert`] gives the same bits as its `sum_lights_coarse`, loading
    /// each quantity of eight lights with one instruction instead of
    /// gathering them.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    #[doc(hidden)]
    fn sum_lanes_coarse(
        &self,
        _: Seal,
        point: &Self::PerPoint,
        surface: &Surface,
        lanes: &[LightLanes],
        count: usize,
    ) -> Option<(DVec3, DVec3)> {
        let _ = (point, surface, lanes, count);
        None
    }

    /// [`sum_lanes_coarse`](Self::sum_lanes_coarse) of a whole small
    /// scene in one call: the `count` lights that `lanes` hold side by side
    /// (as there, but more of them, at most 1,024), with a certified bound
    /// on the error of the sum: `Some((sum, error))` with `|sum - exact| <=
    /// error` per channel, or `None` (the default). [`Lambert`] sums blocks
    /// of 64 lights as its `sum_lanes_coarse` does and adds their lanes in
    /// `f64`, so that one call sets up and finishes the sum instead of one
    /// per block.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    #[doc(hidden)]
    fn sum_scene_coarse(
        &self,
        _: Seal,
        point: &Self::PerPoint,
        surface: &Surface,
        lanes: &[LightLanes],
        count: usize,
    ) -> Option<(DVec3, DVec3)> {
        let _ = (point, surface, lanes, count);
        None
    }

    /// Bounds the `children` of a node together, coarsely: for each child
    /// `first_child + i` whose bit `i` is set in `wanted`,
    /// `out[i]` receives `Some` of a certified bound of the child (as
    /// [`bound`](Self::bound) gives, but computed in single precision,
    /// each end at most about `2^-13` of the child's `I kd / (D - R)^2`
    /// wider),
    /// or `None` where the child's ball comes too near the point for a
    /// finite bound (within [`Cone::MIN_CLEARANCE`], relatively, as
    /// [`Cone::new`] decides); the other entries of `out` are left alone. Returns `false`, setting nothing, where the
    /// shader has no such bound (the default), for a leaf or an index out
    /// of range, and for a point that is not an `f32` value; the caller
    /// then bounds each child with [`bound_nodes`](Self::bound_nodes).
    ///
    /// [`Lambert`] with its default
    /// [`BoundKind::Series`](crate::BoundKind::Series) bounds the children
    /// side by side in one vector of four or eight `f32` lanes; a sum of
    /// shaders ([`Combined`](crate::Combined)) does where either of its
    /// terms does, the other term bounding each child as
    /// [`bound`](Self::bound) does.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    #[doc(hidden)]
    fn bound_children_coarse(
        &self,
        _: Seal,
        point: &Self::PerPoint,
        surface: &Surface,
        children: ChildrenOf<'_>,
        out: &mut [Option<NodeEstimate>],
    ) -> bool {
        let _ = (point, surface, children, out);
        false
    }

    /// Whether [`narrow_bound`](Self::narrow_bound) narrows bounds from the
    /// tree's slab moments (the default: no).
    #[inline]
    #[doc(hidden)]
    fn narrows_with_slabs(&self, _: Seal) -> bool {
        false
    }

    /// `bound`, a certified bound of node `index` of `tree` from this
    /// point, narrowed where the shader can narrow it from what the tree
    /// keeps beside its nodes; the default returns it unchanged.
    /// [`Lambert`] narrows the bound of a large node that the tangent plane
    /// runs through from the node's slab moments (see its docs, "Nodes the
    /// tangent plane cuts").
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    #[doc(hidden)]
    fn narrow_bound(
        &self,
        _: Seal,
        point: &Self::PerPoint,
        surface: &Surface,
        tree: &crate::LightTree,
        index: usize,
        bound: NodeEstimate,
    ) -> NodeEstimate {
        let _ = (point, surface, tree, index);
        bound
    }

    /// The albedo `kd` if this shader is exactly diffuse reflection: if
    /// [`eval`](Self::eval) is [`Lambert`](crate::Lambert)'s term with this
    /// albedo (up to rounding), whatever the view: the batch call then
    /// shares cuts between neighbouring points, each point summing the
    /// diffuse estimates of the cut's nodes
    /// ([`group_errors`](Self::group_errors) bounds them); for `None` (the
    /// default) it shades each point on its own.
    #[doc(hidden)]
    fn diffuse_albedo(&self, _: Seal) -> Option<DVec3> {
        None
    }

    /// For a shader whose [`diffuse_albedo`](Self::diffuse_albedo) is
    /// `Some`: each node's error shared by every point of a group that
    /// sees it as its [`GroupView`] (the node bound for one point, taken at
    /// the worst distance, cosine and heights over the group, plus the
    /// clamp term where members reach below some point's tangent plane),
    /// `N` nodes side by side; `None` where the shader has no such bound.
    /// For every point `p` of the group, the exact contribution of a
    /// node's lights lies within that error of the diffuse estimate at `p`
    /// (the degree-2 multipole series of the node's moments, with
    /// intensities times the albedo).
    #[doc(hidden)]
    #[inline]
    fn group_errors<const N: usize>(
        &self,
        _: Seal,
        nodes: &[&Node; N],
        views: &[GroupView; N],
    ) -> Option<[DVec3; N]> {
        let _ = (nodes, views);
        None
    }
}

/// Marker for shaders whose result does not depend on the view direction
/// (such as [`Lambert`](crate::Lambert)); only they can be shaded with the
/// view-less calls ([`Shading::shade`](crate::Shading::shade)), so a view
/// dependent shader called without a view does not compile.
pub trait ViewIndependent: Shader {}

/// The colour for a convenience constructor: `debug_assert!`s that it is
/// valid; a release build keeps results finite by reading NaN and negative
/// channels as 0 and infinite ones as `f32::MAX`.
pub(crate) fn colour_or_clamped(v: Vec3, what: &'static str) -> DVec3 {
    debug_assert!(
        v.is_finite() && v.min_element() >= 0.0,
        "{what} must be finite and >= 0 per channel, got {v} (use try_new for an error)"
    );
    let f = |x: f32| -> f64 {
        if x.is_nan() || x < 0.0 {
            0.0
        } else {
            f64::from(x.min(f32::MAX))
        }
    };
    DVec3::new(f(v.x), f(v.y), f(v.z))
}

/// [`ShadeError::InvalidMaterial`] for a colour that is not finite and `>= 0`.
pub(crate) fn try_colour(v: Vec3, message: &'static str) -> Result<DVec3, ShadeError> {
    if v.is_finite() && v.min_element() >= 0.0 {
        Ok(v.as_dvec3())
    } else {
        Err(ShadeError::InvalidMaterial(message))
    }
}
