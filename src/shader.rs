//! The `Shader` trait: exact evaluation of one light, a certified bound for a
//! node.

use glam::{DVec3, Vec3};

use crate::geometry::{Cone, Surface};
use crate::tree::{LightTree, Node};
use crate::{LightLanes, PointLight, ShadeError};

/// The most lights the cut passes to one [`Shader::sum_lights`] call.
pub(crate) const SUM_LIGHTS_MAX: usize = 16;

/// The most lights the cut passes to one call of
/// [`Shader::sum_lights_coarse`].
pub(crate) const COARSE_LIGHTS_MAX: usize = 64;

/// The smallest relative target for which the cut uses
/// [`Shader::sum_lights_coarse`]: `2^-12`, about `2.4e-4`.
pub(crate) const COARSE_TARGET_MIN: f64 = 1.0 / 4096.0;

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
/// certified [`NodeEstimate`] for a whole node of the [`LightTree`]
/// from the node's stored data alone. The crate's cut (see
/// [`Shading`](crate::Shading)) refines nodes until the bounds meet the
/// requested threshold, and is only as certified as the bounds: a custom
/// shader must guarantee [`NodeEstimate`]'s contract for every node whose
/// [`Cone`] exists (nodes whose ball reaches the shading point have no cone
/// and are always refined).
///
/// Everything is computed in `f64`. Per shading point the shader derives
/// what it needs once ([`prepare`](Self::prepare), e.g. Phong's mirror
/// direction) and gets it back in every call. Implementations that need no view
/// direction also implement the marker [`ViewIndependent`], which unlocks the
/// view-less shading calls.
///
/// # Writing one
/// `eval` must be the model (the exact reference,
/// [`Shading::exact_query`](crate::Shading::exact_query), sums it); `bound` may
/// use the node's intensity, ball ([`Cone`]), weight, first and second
/// moments ([`Node`]'s accessors document each). The simplest valid bound is
/// the interval of the model over the ball: smallest and largest value of the
/// BRDF times `1/(D + R)^2` and `1/(D - R)^2`, times the node's intensity.
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

    /// The sum of what [`eval`](Self::eval) gives for each of `lights`: what
    /// the cut adds for lights known visible. The cut passes at most 16
    /// lights a call.
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
    fn sum_lights(
        &self,
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
    /// The cut calls it, at most 64 lights a call, in place of
    /// [`sum_lights`](Self::sum_lights) when the threshold is a relative
    /// target of at least `2^-12` (about `2.4e-4`; without interpolation
    /// across levels), and keeps a result only where its
    /// `error` is at most `1/32` of the target times `sum`, channel by
    /// channel; the errors join the reported bound, so they take at most
    /// a thirty-second of the target. The default returns `None`.
    /// [`Lambert`] sums in `f32`, eight lights side by side; a sum of
    /// shaders ([`Combined`]) where either term does, the other term adding
    /// its [`sum_lights`](Self::sum_lights).
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    fn sum_lights_coarse(
        &self,
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
    /// certified bound on its error as there, or `None`. The cut calls it
    /// where it sums a whole small scene, whose lights it keeps side by
    /// side for this, and the scene's
    /// [`sum_scene_coarse`](Self::sum_scene_coarse) is not kept, 64
    /// lights at a time, and calls `sum_lights_coarse` on the same lights
    /// where it returns `None`; the default returns `None`. [`Lambert`]
    /// gives the same bits as its `sum_lights_coarse`, loading each
    /// quantity of eight lights with one instruction instead of gathering
    /// them.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    fn sum_lanes_coarse(
        &self,
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
    /// (as there, but more of them; the cut passes at most 1,024), with
    /// a certified bound on the error of the sum: `Some((sum, error))` with
    /// `|sum - exact| <= error` per channel, or `None`. The cut calls it
    /// first where it sums a whole small scene, and keeps the result on the
    /// same terms as a [`sum_lights_coarse`](Self::sum_lights_coarse);
    /// where it returns `None` or its error is too large, the cut sums the
    /// scene 64 lights at a time as before. The default returns `None`.
    /// [`Lambert`] sums blocks of 64 lights as its `sum_lanes_coarse`
    /// does and adds their lanes in `f64`, so that one call sets up and
    /// finishes the sum instead of one per block.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    fn sum_scene_coarse(
        &self,
        point: &Self::PerPoint,
        surface: &Surface,
        lanes: &[LightLanes],
        count: usize,
    ) -> Option<(DVec3, DVec3)> {
        let _ = (point, surface, lanes, count);
        None
    }

    /// Bounds the children of node `parent` of `tree` together, coarsely:
    /// for each child `first_child + i` whose bit `i` is set in `wanted`,
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
    /// The cut calls it with the children it would bound, in place of
    /// [`bound_nodes`](Self::bound_nodes), when the threshold is a
    /// relative target of at least `2^-12` (about `2.4e-4`; without
    /// interpolation across levels), where its coarser rounding is
    /// usually a negligible part of the target, and until the cut has
    /// evaluated 512 nodes: seen at a grazing angle a node is worth a small
    /// fraction of `I kd / D^2`, the rounding's scale, and a cut that long
    /// bounds in `f64` from then on. [`Lambert`] with its default
    /// [`BoundKind::Series`](crate::BoundKind::Series) bounds the children
    /// side by side in one vector of four or eight `f32` lanes; a sum of shaders
    /// ([`Combined`]) does where either of its terms does, the other term
    /// bounding each child as [`bound`](Self::bound) does.
    ///
    /// [`Lambert`]: crate::Lambert
    #[inline]
    fn bound_children_coarse(
        &self,
        point: &Self::PerPoint,
        surface: &Surface,
        tree: &LightTree,
        parent: usize,
        wanted: u8,
        out: &mut [Option<NodeEstimate>],
    ) -> bool {
        let _ = (point, surface, tree, parent, wanted, out);
        false
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

    /// The albedo `kd` if this shader is exactly diffuse reflection: if
    /// [`eval`](Self::eval) is [`Lambert`](crate::Lambert)'s term with this
    /// albedo (up to rounding), whatever the view. Batch shading
    /// ([`Shading::shade_batch`](crate::Shading::shade_batch)) then shares
    /// cuts between neighbouring points with the crate's own diffuse
    /// bounds; for `None` (the default) it shades each point on its own.
    fn diffuse_albedo(&self) -> Option<DVec3> {
        None
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
}

/// Marker for shaders whose result does not depend on the view direction
/// (such as [`Lambert`](crate::Lambert)); only they can be shaded with the
/// view-less calls ([`Shading::shade`](crate::Shading::shade)), so a view
/// dependent shader called without a view does not compile.
pub trait ViewIndependent: Shader {}

/// The sum of two shaders, e.g. `Combined::new(Lambert::new(kd),
/// Phong::new(ks, e))`: contributions add, and so do bounds (the sum of two
/// certified intervals is a certified interval of the sum).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Combined<A, B> {
    /// First term.
    pub first: A,
    /// Second term.
    pub second: B,
}

impl<A, B> Combined<A, B> {
    /// `first + second`.
    #[must_use]
    pub const fn new(first: A, second: B) -> Self {
        Self { first, second }
    }
}

impl<A: Shader, B: Shader> Shader for Combined<A, B> {
    type PerPoint = (A::PerPoint, B::PerPoint);

    #[inline]
    fn prepare(&self, surface: &Surface) -> Self::PerPoint {
        (self.first.prepare(surface), self.second.prepare(surface))
    }

    /// The sum of the two terms, for a light at `x` of intensity `i`.
    #[inline]
    fn eval(&self, point: &Self::PerPoint, surface: &Surface, x: DVec3, i: DVec3) -> DVec3 {
        self.first.eval(&point.0, surface, x, i) + self.second.eval(&point.1, surface, x, i)
    }

    /// Each term's [`eval_lights`](Shader::eval_lights), added light by
    /// light: the same values as [`eval`](Shader::eval).
    #[inline]
    fn eval_lights(
        &self,
        p: &Self::PerPoint,
        s: &Surface,
        lights: &[PointLight],
        out: &mut [DVec3],
    ) {
        let n = lights.len().min(out.len());
        let (lights, out) = (&lights[..n], &mut out[..n]);
        self.first.eval_lights(&p.0, s, lights, out);
        let mut second = [DVec3::ZERO; SUM_LIGHTS_MAX];
        for (lights, out) in lights
            .chunks(SUM_LIGHTS_MAX)
            .zip(out.chunks_mut(SUM_LIGHTS_MAX))
        {
            let second = &mut second[..lights.len()];
            self.second.eval_lights(&p.1, s, lights, second);
            for (a, b) in out.iter_mut().zip(second.iter()) {
                *a += *b;
            }
        }
    }

    /// The two terms' [`sum_lights`](Shader::sum_lights), added.
    #[inline]
    fn sum_lights(&self, p: &Self::PerPoint, s: &Surface, lights: &[PointLight]) -> DVec3 {
        self.first.sum_lights(&p.0, s, lights) + self.second.sum_lights(&p.1, s, lights)
    }

    /// Coarse where a term has a coarse sum, the other term's
    /// [`sum_lights`](Shader::sum_lights) where it has none (Phong beside
    /// a coarse Lambert), added; `None` where neither term has one. The
    /// error is the coarse sums' plus `f64::EPSILON` of the total for the
    /// last addition.
    #[inline]
    fn sum_lights_coarse(
        &self,
        p: &Self::PerPoint,
        s: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        let first = self.first.sum_lights_coarse(&p.0, s, lights);
        let second = self.second.sum_lights_coarse(&p.1, s, lights);
        let (a, b) = match (first, second) {
            (None, None) => return None,
            (Some(a), Some(b)) => (a, b),
            (Some(a), None) => (a, (summed(&self.second, &p.1, s, lights), DVec3::ZERO)),
            (None, Some(b)) => ((summed(&self.first, &p.0, s, lights), DVec3::ZERO), b),
        };
        let sum = a.0 + b.0;
        Some((sum, a.1 + b.1 + sum * f64::EPSILON))
    }

    /// The sum of the two intervals, for per-point data `p` and surface `s`.
    #[inline]
    fn bound(&self, p: &Self::PerPoint, s: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        added(
            &self.first.bound(&p.0, s, node, cone),
            &self.second.bound(&p.1, s, node, cone),
        )
    }

    #[inline]
    fn bound_nodes(
        &self,
        p: &Self::PerPoint,
        s: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        let mut second = [NodeEstimate::ZERO; 8];
        let chunks = nodes.chunks(8).zip(cones.chunks(8));
        for ((nodes, cones), out) in chunks.zip(out.chunks_mut(8)) {
            self.first.bound_nodes(&p.0, s, nodes, cones, out);
            let second = &mut second[..out.len()];
            self.second.bound_nodes(&p.1, s, nodes, cones, second);
            for (a, b) in out.iter_mut().zip(second.iter()) {
                *a = added(a, b);
            }
        }
    }

    /// Both terms' bounds, added child by child (`None` where either gives
    /// none): coarse where a term has coarse bounds, the other term's
    /// [`bound`](Shader::bound) under each child's cone where it has none
    /// (Phong beside a coarse Lambert); `false` where neither term has
    /// them.
    #[inline]
    fn bound_children_coarse(
        &self,
        p: &Self::PerPoint,
        s: &Surface,
        tree: &LightTree,
        parent: usize,
        wanted: u8,
        out: &mut [Option<NodeEstimate>],
    ) -> bool {
        let len = out.len().min(crate::tree::MAX_CHILDREN);
        let mut first = [None; crate::tree::MAX_CHILDREN];
        let mut second = [None; crate::tree::MAX_CHILDREN];
        // Into scratch, so that `out` is left alone if neither term has
        // coarse bounds.
        let first_coarse =
            self.first
                .bound_children_coarse(&p.0, s, tree, parent, wanted, &mut first[..len]);
        let second_coarse =
            self.second
                .bound_children_coarse(&p.1, s, tree, parent, wanted, &mut second[..len]);
        if !first_coarse && !second_coarse {
            return false;
        }
        let Some(node) = tree.nodes().get(parent) else {
            return false;
        };
        let children = &tree.nodes()[node.children()];
        for (i, child) in children.iter().enumerate().take(len) {
            if wanted & (1 << i) == 0 {
                continue;
            }
            // The term without coarse bounds, as `bound_nodes` would give
            // it: no cone (a ball reaching the point) leaves the child
            // without a bound.
            let cone = if first_coarse && second_coarse {
                None
            } else {
                child.cone(s.point)
            };
            let a = if first_coarse {
                first[i]
            } else {
                cone.map(|c| self.first.bound(&p.0, s, child, &c))
            };
            let b = if second_coarse {
                second[i]
            } else {
                cone.map(|c| self.second.bound(&p.1, s, child, &c))
            };
            out[i] = match (a, b) {
                (Some(a), Some(b)) => Some(added(&a, &b)),
                _ => None,
            };
        }
        true
    }

    /// Diffuse when both terms are: the albedos add.
    #[inline]
    fn diffuse_albedo(&self) -> Option<DVec3> {
        Some(self.first.diffuse_albedo()? + self.second.diffuse_albedo()?)
    }

    /// Both terms vanish below the same plane.
    #[inline]
    fn horizon(&self, surface: &Surface) -> Option<Vec3> {
        let a = self.first.horizon(surface)?;
        (self.second.horizon(surface)? == a).then_some(a)
    }
}

/// The interval of a sum of two shaders' terms: the ends and estimates
/// added.
#[inline]
fn added(a: &NodeEstimate, b: &NodeEstimate) -> NodeEstimate {
    NodeEstimate {
        estimate: a.estimate + b.estimate,
        lower: a.lower + b.lower,
        upper: a.upper + b.upper,
    }
}

/// `shader`'s [`Shader::sum_lights`] over any number of `lights`, at most
/// [`SUM_LIGHTS_MAX`] a call.
#[inline]
fn summed<S: Shader>(shader: &S, p: &S::PerPoint, s: &Surface, lights: &[PointLight]) -> DVec3 {
    lights
        .chunks(SUM_LIGHTS_MAX)
        .map(|l| shader.sum_lights(p, s, l))
        .sum()
}

impl<A: ViewIndependent, B: ViewIndependent> ViewIndependent for Combined<A, B> {}

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
