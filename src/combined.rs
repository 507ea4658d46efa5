//! The sum of two shaders.

use glam::{DVec3, Vec3};

use crate::PointLight;
use crate::geometry::{Cone, GroupView, Surface};
use crate::shader::{ChildrenOf, NodeEstimate, SUM_LIGHTS_MAX, Seal, Shader, ViewIndependent};
use crate::tree::Node;

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
    fn sum_lights(&self, _: Seal, p: &Self::PerPoint, s: &Surface, lights: &[PointLight]) -> DVec3 {
        self.first.sum_lights(Seal, &p.0, s, lights) + self.second.sum_lights(Seal, &p.1, s, lights)
    }

    /// Coarse where a term has a coarse sum, the other term's
    /// [`sum_lights`](Shader::sum_lights) where it has none (Phong beside
    /// a coarse Lambert), added; `None` where neither term has one. The
    /// error is the coarse sums' plus `f64::EPSILON` of the total for the
    /// last addition.
    #[inline]
    fn sum_lights_coarse(
        &self,
        _: Seal,
        p: &Self::PerPoint,
        s: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        let first = self.first.sum_lights_coarse(Seal, &p.0, s, lights);
        let second = self.second.sum_lights_coarse(Seal, &p.1, s, lights);
        self.added(first, second, p, s, lights)
    }

    #[inline]
    fn sum_lights_plain(
        &self,
        _: Seal,
        p: &Self::PerPoint,
        s: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        let first = self.first.sum_lights_plain(Seal, &p.0, s, lights);
        let second = self.second.sum_lights_plain(Seal, &p.1, s, lights);
        self.added(first, second, p, s, lights)
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
        _: Seal,
        p: &Self::PerPoint,
        s: &Surface,
        children: ChildrenOf<'_>,
        out: &mut [Option<NodeEstimate>],
    ) -> bool {
        let ChildrenOf {
            tree,
            parent,
            wanted,
        } = children;
        let len = out.len().min(crate::tree::MAX_CHILDREN);
        let mut first = [None; crate::tree::MAX_CHILDREN];
        let mut second = [None; crate::tree::MAX_CHILDREN];
        // Into scratch, so that `out` is left alone if neither term has
        // coarse bounds.
        let first_coarse =
            self.first
                .bound_children_coarse(Seal, &p.0, s, children, &mut first[..len]);
        let second_coarse =
            self.second
                .bound_children_coarse(Seal, &p.1, s, children, &mut second[..len]);
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
    fn diffuse_albedo(&self, _: Seal) -> Option<DVec3> {
        Some(self.first.diffuse_albedo(Seal)? + self.second.diffuse_albedo(Seal)?)
    }

    /// Both terms' shared errors, added node by node; `None` where either
    /// has none.
    #[inline]
    fn group_errors<const N: usize>(
        &self,
        _: Seal,
        nodes: &[&Node; N],
        views: &[GroupView; N],
    ) -> Option<[DVec3; N]> {
        let a = self.first.group_errors::<N>(Seal, nodes, views)?;
        let b = self.second.group_errors::<N>(Seal, nodes, views)?;
        Some(core::array::from_fn(|i| a[i] + b[i]))
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
        .map(|l| shader.sum_lights(Seal, p, s, l))
        .sum()
}

impl<A: Shader, B: Shader> Combined<A, B> {
    /// The terms' sums over `lights` with their errors, `first` and
    /// `second` as the terms gave them: a term that gave none adds its
    /// [`sum_lights`](Shader::sum_lights) (no error counted for it), and
    /// the total carries `f64::EPSILON` of itself for the last addition;
    /// `None` where neither term gave one.
    #[inline]
    fn added(
        &self,
        first: Option<(DVec3, DVec3)>,
        second: Option<(DVec3, DVec3)>,
        p: &<Self as Shader>::PerPoint,
        s: &Surface,
        lights: &[PointLight],
    ) -> Option<(DVec3, DVec3)> {
        let (a, b) = match (first, second) {
            (None, None) => return None,
            (Some(a), Some(b)) => (a, b),
            (Some(a), None) => (a, (summed(&self.second, &p.1, s, lights), DVec3::ZERO)),
            (None, Some(b)) => ((summed(&self.first, &p.0, s, lights), DVec3::ZERO), b),
        };
        let sum = a.0 + b.0;
        Some((sum, a.1 + b.1 + sum * f64::EPSILON))
    }
}

impl<A: ViewIndependent, B: ViewIndependent> ViewIndependent for Combined<A, B> {}
