//! Baselines (e) and (f): unbiased Monte Carlo estimators of the same sum.
//!
//! * [`PowerSampler`] (Shirley, Wang and Zimmerman 1996): pick light `i` with
//!   probability `p_i = w_i / W` proportional to its power (`w_i` its largest
//!   channel, as the crate weighs lights), by Vose's alias table (O(1) per
//!   sample: one uniform, one table entry, one light), and average
//!   `f(x_i) / p_i`. The intensities are stored pre-divided by `p_i`, so a
//!   sample costs one shader evaluation.
//! * [`TreeSampler`] (pbrt-v4's `BVHLightSampler`, Conty and Kulla 2018):
//!   descend the crate's light tree from the root, choosing a child with
//!   probability proportional to an importance `W * cos_max / d^2` (node
//!   weight; `cos_max` the largest cosine between the normal and the node's
//!   ball, from `Cone::cos_range`, 1 when the ball holds the point;
//!   `d^2 = max(D^2, R^2)`, which unlike pbrt's clamp is scale invariant),
//!   then pick a light of the leaf in proportion to its actual contribution;
//!   the estimate is `f(x) / (product of the choice probabilities)`.
//!
//! Both ignore the specular lobe when choosing (pbrt's importance does too);
//! they stay unbiased for every light with a non-zero probability, which is
//! every light above the tangent plane (all of them in the report's scenes,
//! where lights are above the floor and the eye is too). Random numbers come
//! from the scenes' generator ([`SceneRng`]).
//!
//! In an occluded scene each sample with a non-zero unoccluded contribution
//! casts one shadow ray (`visible`) and counts only if it is unblocked:
//! neither sampler knows about occluders when it chooses, as in pbrt-v4.

use std::f64::consts::{FRAC_PI_2, PI};
use std::ops::Range;

use glam::{DVec3, Vec3};
use manylights::query::WithView;
use manylights::shader::{Node, Shader, Surface};
use manylights::{Emission, Emitter, LightTree, PointLight, Query};
use rand::RngExt;

use crate::scenes::SceneRng;

/// A Monte Carlo light sampler: draws one light per sample.
pub trait LightSampler {
    /// One sample at `surface`: the drawn light's position and its
    /// contribution divided by the probability of drawing it, or `None`
    /// when the sample contributes nothing (no shadow ray is needed).
    fn draw<S: Shader>(
        &self,
        shader: &S,
        per_point: &S::PerPoint,
        surface: &Surface,
        rng: &mut SceneRng,
    ) -> Option<(Vec3, DVec3)>;

    /// Mean of `samples` estimates, each counted where `visible` (the
    /// shadow ray to the light's position) says the light is unblocked;
    /// returns the estimate and the number of shadow rays cast.
    fn estimate<S: Shader>(
        &self,
        shader: &S,
        surface: &Surface,
        rng: &mut SceneRng,
        samples: u32,
        mut visible: impl FnMut(Vec3) -> bool,
    ) -> (DVec3, u32) {
        let per_point = shader.prepare(surface);
        let mut sum = DVec3::ZERO;
        let mut rays = 0;
        for _ in 0..samples {
            if let Some((position, f)) = self.draw(shader, &per_point, surface, rng) {
                rays += 1;
                if visible(position) {
                    sum += f;
                }
            }
        }
        (sum / f64::from(samples), rays)
    }
}

/// The contribution of `light` at `surface`: the shader's exact term.
#[inline]
fn contribution<S: Shader>(
    shader: &S,
    per_point: &S::PerPoint,
    surface: &Surface,
    light: &PointLight,
) -> DVec3 {
    let (position, intensity) = (light.position.as_dvec3(), light.intensity.as_dvec3());
    shader.eval(per_point, surface, position, intensity)
}

/// One bin of Vose's alias table.
#[derive(Clone, Copy, Debug)]
struct AliasBin {
    /// Probability of keeping the bin's own light.
    threshold: f64,
    /// The light taken otherwise.
    alias: u32,
}

/// Light sampling proportional to power, with an alias table.
#[derive(Clone, Debug)]
pub struct PowerSampler {
    bins: Vec<AliasBin>,
    /// The lights with intensity divided by their probability.
    scaled: Vec<PointLight>,
}

impl PowerSampler {
    /// Builds the alias table over `lights`.
    pub fn new(lights: &[PointLight]) -> Self {
        let n = lights.len();
        let total: f64 = lights.iter().map(|l| f64::from(l.weight())).sum();
        if total.is_nan() || total <= 0.0 {
            return Self {
                bins: Vec::new(),
                scaled: Vec::new(),
            };
        }
        let mut mass: Vec<f64> = lights
            .iter()
            .map(|l| f64::from(l.weight()) * n as f64 / total)
            .collect();
        let mut bins = vec![
            AliasBin {
                threshold: 1.0,
                alias: 0,
            };
            n
        ];
        let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| mass[i] < 1.0);
        while let (Some(s), Some(&l)) = (small.pop(), large.last()) {
            bins[s] = AliasBin {
                threshold: mass[s],
                alias: l as u32,
            };
            mass[l] = (mass[l] + mass[s]) - 1.0;
            if mass[l] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        // Bins left in either list hold one unit (up to rounding): they keep
        // their own light (threshold 1).
        let scaled = lights
            .iter()
            .map(|l| {
                let w = f64::from(l.weight());
                let inv_p = if w > 0.0 { total / w } else { 0.0 };
                PointLight::new(l.position, (l.intensity.as_dvec3() * inv_p).as_vec3())
            })
            .collect();
        Self { bins, scaled }
    }
}

impl LightSampler for PowerSampler {
    fn draw<S: Shader>(
        &self,
        shader: &S,
        per_point: &S::PerPoint,
        surface: &Surface,
        rng: &mut SceneRng,
    ) -> Option<(Vec3, DVec3)> {
        let n = self.bins.len();
        if n == 0 {
            return None;
        }
        let u = rng.random::<f64>() * n as f64;
        let i = (u as usize).min(n - 1);
        let bin = self.bins[i];
        let j = if u - (i as f64) < bin.threshold {
            i
        } else {
            bin.alias as usize
        };
        let light = &self.scaled[j];
        let f = contribution(shader, per_point, surface, light);
        (f.max_element() > 0.0).then_some((light.position, f))
    }
}

/// Largest number of children of a node (the crate's octree).
const MAX_CHILDREN: usize = 8;

/// The importance of `node` seen from `surface`: `W cos_max / max(D^2, R^2)`.
#[inline]
fn importance(node: &Node, surface: &Surface) -> f64 {
    let radius = f64::from(node.radius());
    let d2 = (node.centroid().as_dvec3() - surface.point)
        .length_squared()
        .max(radius * radius);
    if d2.is_nan() || d2 <= 0.0 {
        // Coincident lights on the shading point contribute 0.
        return 0.0;
    }
    let cos_max = match node.cone(surface.point) {
        Some(cone) => cone.cos_range(surface.normal).1.max(0.0),
        None => 1.0,
    };
    node.weight() * cos_max / d2
}

/// Index `k` such that `u` falls in the `k`-th of the consecutive intervals
/// of lengths `weights` (`u` in `[0, sum)`); rounding past the end picks the
/// last positive weight.
#[inline]
fn choose(weights: &[f64], mut u: f64) -> usize {
    let mut last = 0;
    for (k, &w) in weights.iter().enumerate() {
        if w > 0.0 {
            last = k;
            if u < w {
                return k;
            }
            u -= w;
        }
    }
    last
}

/// Importance sampling down the light tree.
#[derive(Clone, Copy, Debug)]
pub struct TreeSampler<'t> {
    tree: &'t LightTree,
}

impl<'t> TreeSampler<'t> {
    /// A sampler over `tree`.
    pub fn new(tree: &'t LightTree) -> Self {
        Self { tree }
    }
}

impl LightSampler for TreeSampler<'_> {
    fn draw<S: Shader>(
        &self,
        shader: &S,
        per_point: &S::PerPoint,
        surface: &Surface,
        rng: &mut SceneRng,
    ) -> Option<(Vec3, DVec3)> {
        let nodes = self.tree.nodes();
        let mut node = nodes.first()?;
        let mut pdf = 1.0;
        while !node.is_leaf() {
            let children = node.children();
            debug_assert!(children.len() <= MAX_CHILDREN);
            let mut weights = [0.0; MAX_CHILDREN];
            let mut total = 0.0;
            for (w, child) in weights.iter_mut().zip(&nodes[children.clone()]) {
                *w = importance(child, surface);
                total += *w;
            }
            if total.is_nan() || total <= 0.0 {
                return None;
            }
            let pick = choose(&weights[..children.len()], rng.random::<f64>() * total);
            pdf *= weights[pick] / total;
            node = &nodes[children.start + pick];
        }
        // In the leaf, choose in proportion to the actual contribution.
        let eval = |light: &PointLight| contribution(shader, per_point, surface, light);
        let leaf = &self.tree.lights()[node.lights()];
        let total: f64 = leaf.iter().map(|l| eval(l).max_element()).sum();
        if total.is_nan() || total <= 0.0 {
            return None;
        }
        let mut u = rng.random::<f64>() * total;
        let mut chosen = None;
        for light in leaf {
            let f = eval(light);
            let c = f.max_element();
            if c > 0.0 {
                chosen = Some((light.position, f, c));
                if u < c {
                    break;
                }
                u -= c;
            }
        }
        chosen.map(|(position, f, c)| (position, f * (total / (c * pdf))))
    }
}

// ---------------------------------------------------------------------
// One-sample light samplers with their probabilities, for the `sampling`
// part: each returns a light of the caller's slice and the probability of
// choosing it, from one uniform number reused down the tree (stretched
// over the chosen interval, as pbrt-v4's `SampleDiscrete` does).
// ---------------------------------------------------------------------

/// A light sampler that returns the probability of what it chose.
pub trait OneSample {
    /// One light for `query` from `u` in `[0, 1)`: its index in the
    /// caller's slice and its probability, or `None` (no sample).
    fn pick(&self, query: &Query<WithView>, u: f64) -> Option<(usize, f64)>;

    /// Every light's probability at `query` into `out` (indexed as the
    /// caller's slice, zeroed by the caller): what [`pick`](Self::pick)
    /// returns for each, from one pass over the tree.
    fn probabilities(&self, query: &Query<WithView>, out: &mut [f64]);
}

/// A sampler that descends the crate's tree choosing each node's children
/// and a leaf's lights by probabilities at the shading point (pbrt-v4's and
/// Cycles' importances): a [`OneSample`] by [`descend_tree`] and
/// [`walk_tree`].
trait TreeWeights {
    /// The tree.
    fn tree(&self) -> &LightTree;
    /// The probabilities of `children` (the first at node `first`) at
    /// point `p` with normal `n`; `false` for no sample.
    fn weigh(&self, p: DVec3, n: DVec3, first: usize, children: &[Node], out: &mut [f64]) -> bool;
    /// The probabilities of a leaf's `lights` (the first at leaf index
    /// `first`); `false` for no sample.
    fn leaf(
        &self,
        p: DVec3,
        n: DVec3,
        first: usize,
        lights: &[PointLight],
        out: &mut [f64],
    ) -> bool;
}

impl<T: TreeWeights> OneSample for T {
    fn pick(&self, query: &Query<WithView>, u: f64) -> Option<(usize, f64)> {
        let (p, n) = (query.surface().point, query.surface().normal);
        descend_tree(
            self.tree(),
            u,
            |first, children, out| self.weigh(p, n, first, children, out),
            |first, lights, out| self.leaf(p, n, first, lights, out),
        )
    }

    fn probabilities(&self, query: &Query<WithView>, out: &mut [f64]) {
        let (p, n) = (query.surface().point, query.surface().normal);
        walk_tree(
            self.tree(),
            &mut |first, children, out| self.weigh(p, n, first, children, out),
            &mut |first, lights, out| self.leaf(p, n, first, lights, out),
            out,
        );
    }
}

/// A node's children's probabilities, as [`descend_tree`]'s `weigh`.
type Weigh<'a> = dyn FnMut(usize, &[Node], &mut [f64]) -> bool + 'a;
/// A leaf's lights' probabilities, as [`descend_tree`]'s `leaf`.
type LeafWeigh<'a> = dyn FnMut(usize, &[PointLight], &mut [f64]) -> bool + 'a;

/// The probability of every light under [`descend_tree`]'s choices, written
/// into `out` (indexed as the caller's slice): the same `weigh` and `leaf`
/// at every node, the probabilities multiplied in the same order.
fn walk_tree(tree: &LightTree, weigh: &mut Weigh<'_>, leaf: &mut LeafWeigh<'_>, out: &mut [f64]) {
    fn visit(
        tree: &LightTree,
        index: usize,
        pdf: f64,
        weigh: &mut Weigh<'_>,
        leaf: &mut LeafWeigh<'_>,
        out: &mut [f64],
    ) {
        let nodes = tree.nodes();
        let node = &nodes[index];
        if node.is_leaf() {
            let range = node.lights();
            let mut p = vec![0.0; range.len()];
            if leaf(range.start, &tree.lights()[range.clone()], &mut p) {
                for (i, pi) in p.iter().enumerate() {
                    out[tree.original_index(range.start + i)] = pdf * pi;
                }
            }
            return;
        }
        let children = node.children();
        let mut p = [0.0; 64];
        let p = &mut p[..children.len()];
        if !weigh(children.start, &nodes[children.clone()], p) {
            return;
        }
        for (i, &pi) in p.iter().enumerate() {
            if pi > 0.0 {
                visit(tree, children.start + i, pdf * pi, weigh, leaf, out);
            }
        }
    }
    if !tree.nodes().is_empty() {
        visit(tree, 0, 1.0, weigh, leaf, out);
    }
}

/// `u` stretched back to `[0, 1)` over the interval `[below, below + p)`
/// it fell in.
#[inline]
fn stretch(u: f64, below: f64, p: f64) -> f64 {
    ((u - below) / p).clamp(0.0, 1.0 - f64::EPSILON / 2.0)
}

/// The index whose interval of the cumulative `probabilities` holds `u`,
/// its probability and `u` stretched over it; the last positive one when
/// rounding leaves `u` past the sum; `None` when none is positive.
#[inline]
fn invert(probabilities: &[f64], u: f64) -> Option<(usize, f64, f64)> {
    let mut below = 0.0;
    let mut last = None;
    for (i, &p) in probabilities.iter().enumerate() {
        if p > 0.0 {
            last = Some((i, p, below));
            if u < below + p {
                break;
            }
            below += p;
        }
    }
    last.map(|(i, p, below)| (i, p, stretch(u, below, p)))
}

/// Light sampling in proportion to power (Shirley, Wang and Zimmerman 1996;
/// pbrt-v4's `PowerLightSampler`): light `i` with probability `w_i / W`
/// (`w_i` its largest channel), through Vose's alias table.
#[derive(Clone, Debug)]
pub struct PowerPick {
    bins: Vec<AliasBin>,
    /// Each light's probability.
    probability: Vec<f64>,
}

impl PowerPick {
    /// The table over `lights` (the caller's slice).
    pub fn new(lights: &[PointLight]) -> Self {
        let table = PowerSampler::new(lights);
        let total: f64 = lights.iter().map(|l| f64::from(l.weight())).sum();
        let probability = lights
            .iter()
            .map(|l| f64::from(l.weight()) / total)
            .collect();
        Self {
            bins: table.bins,
            probability,
        }
    }
}

impl OneSample for PowerPick {
    fn pick(&self, _: &Query<WithView>, u: f64) -> Option<(usize, f64)> {
        let n = self.bins.len();
        if n == 0 {
            return None;
        }
        let scaled = u * n as f64;
        let i = (scaled as usize).min(n - 1);
        let bin = self.bins[i];
        let j = if scaled - (i as f64) < bin.threshold {
            i
        } else {
            bin.alias as usize
        };
        Some((j, self.probability[j]))
    }

    fn probabilities(&self, _: &Query<WithView>, out: &mut [f64]) {
        out.copy_from_slice(&self.probability);
    }
}

/// The crate's sampler ([`manylights::LightSampler`]) as a [`OneSample`].
pub struct CratePick<'t, S: Shader> {
    /// The sampler.
    pub sampler: manylights::LightSampler<'t, S>,
}

impl<S: Shader> OneSample for CratePick<'_, S> {
    fn pick(&self, query: &Query<WithView>, u: f64) -> Option<(usize, f64)> {
        let s = self.sampler.sample(query, u)?;
        Some((s.light, s.pmf))
    }

    fn probabilities(&self, query: &Query<WithView>, out: &mut [f64]) {
        self.sampler
            .for_each_pmf(query, |light, pmf| out[light] = pmf);
    }
}

/// `cos(a - b)` from the sines and cosines of `a` and `b`, as pbrt-v4's
/// clamped subtraction: 1 when `a <= b` (`cos a >= cos b`).
#[inline]
fn cos_sub_clamped(sin_a: f64, cos_a: f64, sin_b: f64, cos_b: f64) -> f64 {
    if cos_a > cos_b {
        1.0
    } else {
        cos_a * cos_b + sin_a * sin_b
    }
}

/// `sin(a - b)` likewise: 0 when `a <= b`.
#[inline]
fn sin_sub_clamped(sin_a: f64, cos_a: f64, sin_b: f64, cos_b: f64) -> f64 {
    if cos_a > cos_b {
        0.0
    } else {
        sin_a * cos_b - cos_a * sin_b
    }
}

/// `sqrt(max(0, x))`.
#[inline]
fn safe_sqrt(x: f64) -> f64 {
    x.max(0.0).sqrt()
}

/// `acos` of `x` clamped into `[-1, 1]`.
#[inline]
fn safe_acos(x: f64) -> f64 {
    x.clamp(-1.0, 1.0).acos()
}

/// The angle between unit vectors `a` and `b`, from the half chord
/// (accurate near 0 and `pi`, as pbrt-v4's `AngleBetween`).
fn angle_between(a: DVec3, b: DVec3) -> f64 {
    if a.dot(b) < 0.0 {
        PI - 2.0 * ((a + b).length() / 2.0).clamp(-1.0, 1.0).asin()
    } else {
        2.0 * ((b - a).length() / 2.0).clamp(-1.0, 1.0).asin()
    }
}

/// The unit axis of a profile (`None` for an isotropic one or a zero
/// axis, which the build refuses).
fn unit_axis(axis: Vec3) -> Option<DVec3> {
    let a = axis.as_dvec3().normalize_or_zero();
    (a != DVec3::ZERO).then_some(a)
}

/// pbrt-v4's `LightBounds` (its `src/pbrt/lights.h`) of an emitter or a
/// group of them: a box, the power `phi` (in units of `4 pi` times the
/// largest channel of an isotropic light's intensity: the `4 pi` cancels
/// in every ratio), the cone of emitter axes (`axis`, `cos_o`), the
/// falloff past it (`cos_e`) and whether some member emits along both
/// ends of its axis.
#[derive(Clone, Copy, Debug)]
struct PbrtBounds {
    min: DVec3,
    max: DVec3,
    phi: f64,
    axis: DVec3,
    cos_o: f64,
    cos_e: f64,
    two_sided: bool,
}

impl PbrtBounds {
    /// An isotropic emitter's orientation bounds (pbrt-v4's
    /// `PointLight::Bounds`): `theta_o = pi` about `+z`, `theta_e = pi / 2`.
    const ISOTROPIC: (DVec3, f64, f64, bool) = (DVec3::Z, -1.0, 0.0, false);

    /// The bounds of `light` emitting with `emission` (pbrt-v4's `Bounds`
    /// of the light it stands for):
    ///
    /// * isotropic: a `PointLight`, power `4 pi I`;
    /// * a cosine lobe `c^k`: a small `DiffuseAreaLight` for `k = 1` (its
    ///   normal cone `theta_o = 0`, `theta_e = pi / 2`, power `pi I`, twice
    ///   that two-sided); other exponents keep `theta_e = pi / 2` (the
    ///   lobe is 0 past it; pbrt-v4 has no such light) with their power
    ///   `2 pi I / (k + 1)`, twice that two-sided;
    /// * a spot: a `SpotLight`, `cos_o` the inner cone's cosine,
    ///   `theta_e` the outer angle less the inner, power `4 pi I` (as
    ///   pbrt-v4 keeps it, the cone's solid angle left out).
    fn of_light(light: &PointLight, emission: &Emission) -> Self {
        let x = light.position.as_dvec3();
        let w = f64::from(light.weight());
        let (phi, (axis, cos_o, cos_e, two_sided)) = match *emission {
            Emission::Cosine {
                axis,
                exponent,
                two_sided,
            } => match unit_axis(axis) {
                Some(axis) => {
                    let sides = if two_sided { 2.0 } else { 1.0 };
                    let k = f64::from(exponent);
                    (sides * w / (2.0 * (k + 1.0)), (axis, 1.0, 0.0, two_sided))
                }
                None => (w, Self::ISOTROPIC),
            },
            Emission::Spot {
                axis,
                inner_angle,
                outer_angle,
                two_sided,
            } => match unit_axis(axis) {
                Some(axis) => {
                    let (inner, outer) = (f64::from(inner_angle), f64::from(outer_angle));
                    (w, (axis, inner.cos(), (outer - inner).cos(), two_sided))
                }
                None => (w, Self::ISOTROPIC),
            },
            // Isotropic, and any profile this report does not know: the
            // whole sphere bounds it.
            _ => (w, Self::ISOTROPIC),
        };
        Self {
            min: x,
            max: x,
            phi,
            axis,
            cos_o,
            cos_e,
            two_sided,
        }
    }
}

/// pbrt-v4's `DirectionCone` union (its `src/pbrt/util/vecmath.cpp`): the
/// cone about `a` if it holds `b`'s, and conversely; else the cone spanning
/// both, its axis turned from `a`'s towards `b`'s; the whole sphere (about
/// `+z`) when that reaches `pi` or the axes are parallel.
fn cone_union(a: (DVec3, f64), b: (DVec3, f64)) -> (DVec3, f64) {
    let (theta_a, theta_b) = (safe_acos(a.1), safe_acos(b.1));
    let theta_d = angle_between(a.0, b.0);
    if (theta_d + theta_b).min(PI) <= theta_a {
        return a;
    }
    if (theta_d + theta_a).min(PI) <= theta_b {
        return b;
    }
    let theta_o = (theta_a + theta_d + theta_b) / 2.0;
    let whole = (DVec3::Z, -1.0);
    if theta_o >= PI {
        return whole;
    }
    let theta_r = theta_o - theta_a;
    let wr = a.0.cross(b.0);
    if wr.length_squared() == 0.0 {
        return whole;
    }
    // `a` turned by `theta_r` about `wr` (perpendicular to it).
    let towards = wr.normalize().cross(a.0);
    let w = (a.0 * theta_r.cos() + towards * theta_r.sin()).normalize();
    (w, theta_o.cos())
}

/// pbrt-v4's `Union` of two `LightBounds`, the box aside (the caller keeps
/// the tree's): the union of the axis cones, the smaller `cos_e`, summed
/// power; a bound of zero power is left out.
fn pbrt_union(a: &PbrtBounds, b: &PbrtBounds) -> PbrtBounds {
    if a.phi == 0.0 {
        return *b;
    }
    if b.phi == 0.0 {
        return *a;
    }
    let (axis, cos_o) = cone_union((a.axis, a.cos_o), (b.axis, b.cos_o));
    PbrtBounds {
        min: a.min.min(b.min),
        max: a.max.max(b.max),
        phi: a.phi + b.phi,
        axis,
        cos_o,
        cos_e: a.cos_e.min(b.cos_e),
        two_sided: a.two_sided | b.two_sided,
    }
}

/// pbrt-v4's `LightBounds::Importance` (its `src/pbrt/lights.cpp`), in
/// `f64`: the squared distance to the box's centre clamped below by half
/// the diagonal's length (a length against a squared length, as written
/// there); the angle between the cone's axis and the direction to the
/// point (`theta_w`, folded for a two-sided bound) narrowed by the cone
/// (`theta_o`) and by the box's bounding sphere (`theta_b`, the whole
/// sphere when the point is inside it), 0 past `theta_e`; and the
/// incidence angle `|n . w_i|` narrowed by `theta_b`. Isotropic bounds
/// (`theta_o = pi`, `theta_e = pi / 2`) leave only distance and incidence.
fn pbrt_importance(b: &PbrtBounds, p: DVec3, n: DVec3) -> f64 {
    let pc = (b.min + b.max) * 0.5;
    let diagonal = (b.max - b.min).length();
    let d2 = p.distance_squared(pc).max(diagonal / 2.0);
    // BoundSubtendedDirections: the box's bounding sphere seen from p.
    let radius = diagonal / 2.0;
    let cos_b = if p.distance_squared(pc) < radius * radius {
        -1.0
    } else {
        safe_sqrt(1.0 - radius * radius / p.distance_squared(pc))
    };
    let sin_b = safe_sqrt(1.0 - cos_b * cos_b);
    let wi = (p - pc).normalize_or_zero();
    let mut cos_w = b.axis.dot(wi);
    if b.two_sided {
        cos_w = cos_w.abs();
    }
    let sin_w = safe_sqrt(1.0 - cos_w * cos_w);
    let sin_o = safe_sqrt(1.0 - b.cos_o * b.cos_o);
    let cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, b.cos_o);
    let sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, b.cos_o);
    let cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
    if cos_p <= b.cos_e {
        return 0.0;
    }
    let mut importance = b.phi * cos_p / d2;
    let cos_i = wi.dot(n).abs();
    let sin_i = safe_sqrt(1.0 - cos_i * cos_i);
    importance *= cos_sub_clamped(sin_i, cos_i, sin_b, cos_b);
    importance.max(0.0)
}

/// Each light's emission profile in the tree's leaf order: `emitters`
/// (the caller's slice, which the tree was built from) through
/// [`LightTree::original_index`]; isotropic without them.
fn leaf_emissions(tree: &LightTree, emitters: Option<&[Emitter]>) -> Vec<Emission> {
    (0..tree.len())
        .map(|i| emitters.map_or(Emission::Isotropic, |e| e[tree.original_index(i)].emission))
        .collect()
}

/// Folds `of` over node `index`'s subtree bottom-up, writing every node's
/// value into `out`: a leaf's from its lights (leaf-order indices), an
/// inner node's from its children's.
fn fold_nodes<T: Copy>(
    tree: &LightTree,
    index: usize,
    out: &mut [T],
    leaf: &impl Fn(Range<usize>) -> T,
    inner: &impl Fn(&[T]) -> T,
) -> T {
    let node = &tree.nodes()[index];
    let value = if node.is_leaf() {
        leaf(node.lights())
    } else {
        let children = node.children();
        for child in children.clone() {
            out[child] = fold_nodes(tree, child, out, leaf, inner);
        }
        inner(&out[children])
    };
    out[index] = value;
    value
}

/// pbrt-v4's `BVHLightSampler` descent on the crate's tree (its
/// `src/pbrt/lightsamplers.h`): at each node a child with probability in
/// proportion to `pbrt_importance` of its bounds (the node's box, its
/// members' summed power and the union of their orientation bounds), no
/// sample when every child's is 0; in a leaf (pbrt's leaves hold one light
/// each, the crate's up to 32) a light in proportion to the importance of
/// its own bounds.
pub struct PbrtPick<'t> {
    tree: &'t LightTree,
    /// Each node's bounds, in the tree's node order.
    nodes: Vec<PbrtBounds>,
    /// Each light's bounds, in the tree's leaf order.
    lights: Vec<PbrtBounds>,
}

impl<'t> PbrtPick<'t> {
    /// The sampler over `tree`, built from `emitters` when it was built
    /// from emitters (`None`: isotropic lights). Every node's bounds are
    /// computed once here, bottom-up: for isotropic lights the node's box
    /// and summed largest channels with the whole sphere's cone, as
    /// before emitters existed.
    pub fn new(tree: &'t LightTree, emitters: Option<&[Emitter]>) -> Self {
        let emissions = leaf_emissions(tree, emitters);
        let lights: Vec<PbrtBounds> = tree
            .lights()
            .iter()
            .zip(&emissions)
            .map(|(l, e)| PbrtBounds::of_light(l, e))
            .collect();
        let all = tree.nodes();
        let placeholder = PbrtBounds::of_light(&PointLight::default(), &Emission::Isotropic);
        let mut nodes = vec![placeholder; all.len()];
        if !all.is_empty() {
            let merge = |bounds: &mut dyn Iterator<Item = PbrtBounds>| {
                let first = bounds.next().expect("a node has members");
                bounds.fold(first, |a, b| pbrt_union(&a, &b))
            };
            fold_nodes(
                tree,
                0,
                &mut nodes,
                &|range| merge(&mut lights[range].iter().copied()),
                &|children| merge(&mut children.iter().copied()),
            );
            // The tree's boxes; isotropic lights keep the tree's summed
            // weights (the orientation bounds are the whole sphere's).
            for (b, node) in nodes.iter_mut().zip(all) {
                let aabb = node.aabb();
                (b.min, b.max) = (aabb.min.as_dvec3(), aabb.max.as_dvec3());
                if emitters.is_none() {
                    b.phi = node.weight();
                }
            }
        }
        Self {
            tree,
            nodes,
            lights,
        }
    }
}

/// Descends `tree` choosing children by `weigh` (given the index of the
/// first child and the children; writes their probabilities into the slice;
/// `false` for no sample) and a leaf's lights by `leaf` (given the leaf
/// order index of the first light and the lights; likewise), reusing `u`.
fn descend_tree(
    tree: &LightTree,
    mut u: f64,
    mut weigh: impl FnMut(usize, &[Node], &mut [f64]) -> bool,
    mut leaf: impl FnMut(usize, &[PointLight], &mut [f64]) -> bool,
) -> Option<(usize, f64)> {
    let nodes = tree.nodes();
    let mut node = nodes.first()?;
    let mut pdf = 1.0;
    let mut p = [0.0; 64];
    while !node.is_leaf() {
        let children = node.children();
        let probabilities = &mut p[..children.len()];
        if !weigh(children.start, &nodes[children.clone()], probabilities) {
            return None;
        }
        let (i, pi, stretched) = invert(probabilities, u)?;
        pdf *= pi;
        u = stretched;
        node = &nodes[children.start + i];
    }
    let range = node.lights();
    let lights = &tree.lights()[range.clone()];
    let mut big;
    let probabilities = if lights.len() <= p.len() {
        &mut p[..lights.len()]
    } else {
        big = vec![0.0; lights.len()];
        &mut big[..]
    };
    if !leaf(range.start, lights, probabilities) {
        return None;
    }
    let (i, pi, _) = invert(probabilities, u)?;
    Some((tree.original_index(range.start + i), pdf * pi))
}

/// Writes `weights / sum` into `out`; `false` when the sum is not positive.
fn normalise(out: &mut [f64]) -> bool {
    let total: f64 = out.iter().sum();
    if !(total > 0.0) || !total.is_finite() {
        return false;
    }
    out.iter_mut().for_each(|w| *w /= total);
    true
}

impl TreeWeights for PbrtPick<'_> {
    fn tree(&self) -> &LightTree {
        self.tree
    }

    fn weigh(&self, p: DVec3, n: DVec3, first: usize, children: &[Node], out: &mut [f64]) -> bool {
        for (w, b) in out
            .iter_mut()
            .zip(&self.nodes[first..first + children.len()])
        {
            *w = pbrt_importance(b, p, n);
        }
        normalise(out)
    }

    fn leaf(
        &self,
        p: DVec3,
        n: DVec3,
        first: usize,
        lights: &[PointLight],
        out: &mut [f64],
    ) -> bool {
        for (w, b) in out
            .iter_mut()
            .zip(&self.lights[first..first + lights.len()])
        {
            *w = pbrt_importance(b, p, n);
        }
        normalise(out)
    }
}

/// Rec. 709 luminance: Cycles' `linear_rgb_to_gray` for its default
/// colour space, the energy of its light tree.
fn luminance(c: DVec3) -> f64 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Cycles' `light_tree_cos_bounding_box_angle`: the cosine of the largest
/// angle between the direction to the box's centre and to its corners, -1
/// when the point is strictly inside the box.
fn cycles_cos_box(min: DVec3, max: DVec3, p: DVec3, to_centre: DVec3) -> f64 {
    if p.cmpgt(min).all() && p.cmplt(max).all() {
        return -1.0;
    }
    let mut cos_u = 1.0f64;
    for i in 0..8 {
        let corner = DVec3::new(
            if i & 1 != 0 { max.x } else { min.x },
            if i & 2 != 0 { max.y } else { min.y },
            if i & 4 != 0 { max.z } else { min.z },
        );
        cos_u = cos_u.min(to_centre.dot((corner - p).normalize_or_zero()));
    }
    cos_u
}

/// Cycles' bounding cone (its `scene/light_tree.h` `OrientationBounds`):
/// every member's axis lies within `theta_o` of `axis`, and each emits
/// only within `theta_e` past its own axis.
#[derive(Clone, Copy, Debug)]
struct CyclesCone {
    axis: DVec3,
    theta_o: f64,
    theta_e: f64,
}

/// How much an axis may already stick out of a cone for Cycles' merge to
/// keep that cone: its `5e-4` radians.
const CYCLES_MERGE_SLACK: f64 = 5e-4;

/// How opposite two axes must be (their cosine below this) for Cycles'
/// merge to take any axis perpendicular to the wider one: its `-0.9995`.
const CYCLES_OPPOSITE: f64 = -0.9995;

impl CyclesCone {
    /// A point light's cone (`theta_o = pi`, `theta_e = pi / 2`; the axis
    /// is arbitrary).
    const POINT: Self = Self {
        axis: DVec3::Z,
        theta_o: PI,
        theta_e: FRAC_PI_2,
    };

    /// Cycles' `merge` (its `scene/light_tree.cpp`): the wider cone if it
    /// holds the other (within [`CYCLES_MERGE_SLACK`]); else the cone
    /// spanning both, its axis turned from the wider one's towards the
    /// other's; `theta_e` the larger.
    fn merge(self, other: Self) -> Self {
        let (a, b) = if other.theta_o > self.theta_o {
            (other, self)
        } else {
            (self, other)
        };
        let cos_ab = a.axis.dot(b.axis);
        let theta_d = safe_acos(cos_ab);
        let theta_e = a.theta_e.max(b.theta_e);
        if a.theta_o + CYCLES_MERGE_SLACK >= (theta_d + b.theta_o).min(PI) {
            return Self { theta_e, ..a };
        }
        let theta_o = (theta_d + a.theta_o + b.theta_o) * 0.5;
        if theta_o >= PI {
            return Self {
                axis: a.axis,
                theta_o: PI,
                theta_e,
            };
        }
        let axis = if cos_ab < CYCLES_OPPOSITE {
            a.axis.any_orthonormal_vector()
        } else {
            let theta_r = theta_o - a.theta_o;
            let ortho = (b.axis - a.axis * cos_ab).normalize_or_zero();
            a.axis * theta_r.cos() + ortho * theta_r.sin()
        };
        Self {
            axis,
            theta_o,
            theta_e,
        }
    }
}

/// One light of Cycles' tree as the report stands it in.
#[derive(Clone, Copy, Debug)]
enum CyclesEmitter {
    /// A point light: in a leaf, a disk facing the point (`theta_o = 0`
    /// about the direction from the light to the point).
    Point,
    /// An oriented emitter with its own cone; `front_only`: an area light,
    /// which Cycles gives importance 0 from behind its plane.
    Oriented { cone: CyclesCone, front_only: bool },
}

impl CyclesEmitter {
    /// The Cycles light `emission` stands for, and its cone in the tree:
    ///
    /// * isotropic: a point light (`theta_o = pi`, `theta_e = pi / 2`);
    /// * a one-sided cosine lobe: a small area light (`theta_o = 0` about
    ///   its axis, `theta_e` half its spread, `pi / 2`; other exponents
    ///   than 1 kept at `pi / 2`, where the lobe ends); two-sided: as a
    ///   double-sided emissive triangle, any axis in its plane with
    ///   `theta_o = pi / 2`;
    /// * a spot: a spot light (`theta_o = 0`, `theta_e` its outer angle,
    ///   half Cycles' spot angle); two-sided as the double-sided triangle
    ///   with the same `theta_e`.
    fn of(emission: &Emission) -> (Self, CyclesCone) {
        let oriented = |axis: Vec3, theta_e: f64, two_sided: bool, front_only: bool| {
            let Some(m) = unit_axis(axis) else {
                return (Self::Point, CyclesCone::POINT);
            };
            let cone = if two_sided {
                CyclesCone {
                    axis: m.any_orthonormal_vector(),
                    theta_o: FRAC_PI_2,
                    theta_e,
                }
            } else {
                CyclesCone {
                    axis: m,
                    theta_o: 0.0,
                    theta_e,
                }
            };
            let front_only = front_only && !two_sided;
            (Self::Oriented { cone, front_only }, cone)
        };
        match *emission {
            Emission::Cosine {
                axis, two_sided, ..
            } => oriented(axis, FRAC_PI_2, two_sided, true),
            Emission::Spot {
                axis,
                outer_angle,
                two_sided,
                ..
            } => oriented(axis, f64::from(outer_angle), two_sided, false),
            _ => (Self::Point, CyclesCone::POINT),
        }
    }
}

/// Cycles' `light_tree_importance` (its `kernel/light/tree.h`) at a
/// surface without transmission, for a cluster or an emitter seen under
/// `cos_u` (its box's or 1 for a point) at `distance` (minimum and maximum
/// distance alike): `(max, min)` importances. The incidence term narrowed
/// and widened by `theta_u`; the outgoing term from the angle `theta`
/// between the cone's axis and the direction to the point, narrowed by
/// `theta_u` and `theta_o` (0 past `theta_e`) for the maximum, widened for
/// the minimum (0 unless the whole cluster lies within `theta_e -
/// theta_o`). A point light's cone (`theta_o = 0` about the direction to
/// the point) gives both `E cos_i / d^2`; a group of point lights
/// (`theta_o = pi`) an outgoing term 1 and a minimum 0.
fn cycles_importance(
    n: DVec3,
    to_centre: DVec3,
    cos_u: f64,
    distance: f64,
    energy: f64,
    cone: &CyclesCone,
) -> (f64, f64) {
    let sin_u = safe_sqrt(1.0 - cos_u * cos_u);
    let cos_i = to_centre.dot(n);
    let sin_i = safe_sqrt(1.0 - cos_i * cos_i);
    let cos_min_incidence = if cos_i >= cos_u {
        1.0
    } else {
        cos_i * cos_u + sin_i * sin_u
    };
    if cos_min_incidence < 0.0 {
        return (0.0, 0.0);
    }
    let cos_max_incidence = (cos_i * cos_u - sin_i * sin_u).max(0.0);
    // The axis exactly along the direction to the point: 1, as Cycles
    // special-cases it.
    let (cos_t, sin_t) = if cone.axis == -to_centre {
        (1.0, 0.0)
    } else {
        let c = cone.axis.dot(-to_centre);
        (c, safe_sqrt(1.0 - c * c))
    };
    let cos_t_minus_u = cos_t * cos_u + sin_t * sin_u;
    let (sin_o, cos_o) = cone.theta_o.sin_cos();
    // `theta_o = pi` holds every direction (`cos(theta - theta_u) >=
    // cos(pi)`), whatever the rounding of the cosines.
    let cos_min_outgoing = if cos_t >= cos_u || cos_t_minus_u >= cos_o || cone.theta_o >= PI {
        1.0
    } else if cone.theta_o + cone.theta_e > PI
        || cos_t_minus_u > (cone.theta_o + cone.theta_e).cos()
    {
        let sin_t_minus_u = safe_sqrt(1.0 - cos_t_minus_u * cos_t_minus_u);
        cos_t_minus_u * cos_o + sin_t_minus_u * sin_o
    } else {
        return (0.0, 0.0);
    };
    let d2 = distance * distance;
    let max = (cos_min_incidence * energy * cos_min_outgoing / d2).abs();
    let cos_t_plus_u = cos_t * cos_u - sin_t * sin_u;
    let min = if cone.theta_e - cone.theta_o < 0.0
        || cos_t < 0.0
        || cos_u < 0.0
        || cos_t_plus_u < (cone.theta_e - cone.theta_o).cos()
    {
        0.0
    } else {
        let sin_t_plus_u = safe_sqrt(1.0 - cos_t_plus_u * cos_t_plus_u);
        let cos_max_outgoing = cos_t_plus_u * cos_o - sin_t_plus_u * sin_o;
        (cos_max_incidence * energy * cos_max_outgoing / d2).abs()
    };
    (max, min)
}

/// Cycles' light tree descent on the crate's tree: each child chosen with
/// probability `0.5 (p_max + p_min)`, `p_max` in proportion to its
/// maximum importance and `p_min` to its minimum (evenly over the children
/// of positive maximum importance when every minimum is 0, as for groups of
/// point lights); a node's distance clamped below by half its box's half
/// diagonal; a node whose box lies behind the tangent plane has
/// importance 0. In a leaf, its lights likewise as single emitters: point
/// lights as disks facing the point, oriented ones with their own cones
/// (an area light also 0 from behind). Each node's cone (the merge of its
/// members') is computed once, bottom-up.
pub struct CyclesPick<'t> {
    tree: &'t LightTree,
    /// Each node's cone, in the tree's node order.
    nodes: Vec<CyclesCone>,
    /// Each light as an emitter, in the tree's leaf order.
    lights: Vec<CyclesEmitter>,
}

impl<'t> CyclesPick<'t> {
    /// The sampler over `tree`, built from `emitters` when it was built
    /// from emitters (`None`: isotropic lights, every cone a point
    /// light's).
    pub fn new(tree: &'t LightTree, emitters: Option<&[Emitter]>) -> Self {
        let (lights, cones): (Vec<CyclesEmitter>, Vec<CyclesCone>) = leaf_emissions(tree, emitters)
            .iter()
            .map(CyclesEmitter::of)
            .unzip();
        let mut nodes = vec![CyclesCone::POINT; tree.nodes().len()];
        if !nodes.is_empty() {
            let merge = |cones: &[CyclesCone]| {
                let (first, rest) = cones.split_first().expect("a node has members");
                rest.iter().fold(*first, |a, b| a.merge(*b))
            };
            fold_nodes(
                tree,
                0,
                &mut nodes,
                &|range| merge(&cones[range]),
                &|children| merge(children),
            );
        }
        Self {
            tree,
            nodes,
            lights,
        }
    }
}

/// Cycles' `light_tree_node_importance` of a node of the crate's tree
/// with cone `cone` at `p` with normal `n`: 0 when its box lies behind the
/// tangent plane; else seen under its box's angle from the box's centre,
/// the distance clamped below by half the box's half diagonal.
fn cycles_node_importance(node: &Node, cone: &CyclesCone, p: DVec3, n: DVec3) -> (f64, f64) {
    let b = node.aabb();
    let (bmin, bmax) = (b.min.as_dvec3(), b.max.as_dvec3());
    let centre = 0.5 * (bmin + bmax);
    let extent = bmax - centre;
    if n.dot(centre - p) + n.abs().dot(extent.abs()) <= 0.0 {
        return (0.0, 0.0);
    }
    let distance = (centre - p).length();
    let to_centre = (centre - p) / distance;
    let cos_u = cycles_cos_box(bmin, bmax, p, to_centre);
    let distance = distance.max(0.5 * (centre - bmax).length());
    let energy = luminance(node.intensity());
    cycles_importance(n, to_centre, cos_u, distance, energy, cone)
}

/// Cycles' `light_tree_emitter_importance` of one light at `p` with
/// normal `n`: a point light as a disk facing the point, an oriented one
/// under its own cone (an area light 0 from behind its plane); 0 for a
/// light on the point.
fn cycles_light_importance(
    light: &PointLight,
    emitter: &CyclesEmitter,
    p: DVec3,
    n: DVec3,
) -> (f64, f64) {
    let offset = light.position.as_dvec3() - p;
    let distance = offset.length();
    if distance == 0.0 {
        return (0.0, 0.0);
    }
    let to_light = offset / distance;
    let cone = match emitter {
        CyclesEmitter::Point => CyclesCone {
            axis: -to_light,
            theta_o: 0.0,
            theta_e: FRAC_PI_2,
        },
        CyclesEmitter::Oriented { cone, front_only } => {
            if *front_only && !(cone.axis.dot(to_light) < 0.0) {
                return (0.0, 0.0);
            }
            *cone
        }
    };
    let energy = luminance(light.intensity.as_dvec3());
    cycles_importance(n, to_light, 1.0, distance, energy, &cone)
}

/// Cycles' choice `0.5 (max_i / sum max + min_i / sum min)` of the
/// `(max, min)` importances in `out` (as pairs packed by the caller: max
/// in `out`, min in `min`), written into `out`.
fn cycles_mix(out: &mut [f64], min: &[f64]) -> bool {
    let total_max: f64 = out.iter().sum();
    if !(total_max > 0.0) {
        return false;
    }
    let total_min: f64 = min.iter().sum();
    let positive = out.iter().filter(|&&m| m > 0.0).count() as f64;
    for (w, &lo) in out.iter_mut().zip(min) {
        let p_min = if total_min > 0.0 {
            lo / total_min
        } else if *w > 0.0 {
            1.0 / positive
        } else {
            0.0
        };
        *w = 0.5 * (*w / total_max + p_min);
    }
    true
}

impl TreeWeights for CyclesPick<'_> {
    fn tree(&self) -> &LightTree {
        self.tree
    }

    fn weigh(&self, p: DVec3, n: DVec3, first: usize, children: &[Node], out: &mut [f64]) -> bool {
        let mut min = [0.0f64; 64];
        let cones = &self.nodes[first..first + children.len()];
        for (((w, lo), child), cone) in out.iter_mut().zip(min.iter_mut()).zip(children).zip(cones)
        {
            (*w, *lo) = cycles_node_importance(child, cone, p, n);
        }
        cycles_mix(out, &min[..out.len()])
    }

    fn leaf(
        &self,
        p: DVec3,
        n: DVec3,
        first: usize,
        lights: &[PointLight],
        out: &mut [f64],
    ) -> bool {
        let mut lows_kept = [0.0f64; 64];
        let mut spare;
        let lows = if lights.len() <= lows_kept.len() {
            &mut lows_kept[..lights.len()]
        } else {
            spare = vec![0.0; lights.len()];
            &mut spare[..]
        };
        let emitters = &self.lights[first..first + lights.len()];
        for (((w, lo), light), emitter) in out
            .iter_mut()
            .zip(lows.iter_mut())
            .zip(lights)
            .zip(emitters)
        {
            (*w, *lo) = cycles_light_importance(light, emitter, p, n);
        }
        cycles_mix(out, lows)
    }
}

#[cfg(test)]
mod tests {
    use manylights::shader::Shader;
    use manylights::{Lambert, Query};
    use rand::RngExt;

    use super::*;
    use crate::scenes::rng;

    /// Slack on angles for the `f64` rounding of the cones' `acos`,
    /// normalisations and turns: a few hundred ulps of `pi`.
    const ANGLE_ROUNDING: f64 = 1e-12;

    /// A few thousand emitters of every profile in a 4 m cube.
    fn emitters(count: usize, seed: u64) -> Vec<Emitter> {
        let mut rng = rng(seed);
        let unit = |rng: &mut crate::scenes::SceneRng| loop {
            let v = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            if v.length_squared() > 0.01 && v.length_squared() <= 1.0 {
                return v;
            }
        };
        (0..count)
            .map(|i| {
                let position = Vec3::new(
                    rng.random_range(0.0..4.0),
                    rng.random_range(0.0..4.0),
                    rng.random_range(0.0..4.0),
                );
                let intensity = Vec3::new(
                    rng.random_range(0.1..1.0),
                    rng.random_range(0.1..1.0),
                    rng.random_range(0.1..1.0),
                );
                let axis = unit(&mut rng);
                let outer: f32 = rng.random_range(0.2..1.5);
                let inner = outer * rng.random_range(0.0..1.0);
                let emission = match i % 6 {
                    0 => Emission::Isotropic,
                    1 => Emission::cosine(axis, 1.0),
                    2 => Emission::cosine(axis, 1.0).two_sided(),
                    3 => Emission::cosine(axis, 4.0),
                    4 => Emission::spot(axis, inner, outer),
                    _ => Emission::spot(axis, inner, outer).two_sided(),
                };
                PointLight::new(position, intensity).with_emission(emission)
            })
            .collect()
    }

    /// Every node's cone holds its members' cones: exactly (up to
    /// rounding) for pbrt-v4's union, within Cycles' merge slack per merge
    /// for Cycles'.
    #[test]
    fn node_cones_hold_their_members() {
        let emitters = emitters(3000, 7);
        let tree = LightTree::build_emitters(&emitters).unwrap();
        let pbrt = PbrtPick::new(&tree, Some(&emitters));
        let cycles = CyclesPick::new(&tree, Some(&emitters));
        let (_, cones): (Vec<_>, Vec<_>) = leaf_emissions(&tree, Some(&emitters))
            .iter()
            .map(CyclesEmitter::of)
            .unzip();
        let largest_leaf = tree.nodes().iter().map(|n| n.light_count()).max().unwrap();
        let merges = (largest_leaf + tree.depth() as usize) as f64;
        for (index, node) in tree.nodes().iter().enumerate() {
            let (b, c) = (&pbrt.nodes[index], &cycles.nodes[index]);
            for i in node.lights() {
                let l = &pbrt.lights[i];
                let spread = angle_between(b.axis, l.axis) + safe_acos(l.cos_o);
                assert!(
                    spread.min(PI) <= safe_acos(b.cos_o) + ANGLE_ROUNDING,
                    "node {index} light {i}"
                );
                assert!(b.cos_e <= l.cos_e && (b.two_sided || !l.two_sided));
                let m = &cones[i];
                let spread = angle_between(c.axis, m.axis) + m.theta_o;
                assert!(spread.min(PI) <= c.theta_o + CYCLES_MERGE_SLACK * merges);
                assert!(c.theta_e >= m.theta_e);
            }
        }
    }

    /// Wherever a light lights the point (a positive Lambert term and
    /// profile), pbrt-v4's importance of the light and of every node
    /// holding it is positive, and so is Cycles' maximum importance of the
    /// light: neither sampler misses a lit light through its cones.
    #[test]
    fn lit_lights_have_positive_importance() {
        let emitters = emitters(2000, 11);
        let tree = LightTree::build_emitters(&emitters).unwrap();
        let pbrt = PbrtPick::new(&tree, Some(&emitters));
        let cycles = CyclesPick::new(&tree, Some(&emitters));
        let emissions = leaf_emissions(&tree, Some(&emitters));
        let lambert = Lambert::new(Vec3::ONE);
        let mut rng = rng(13);
        let mut checked = 0;
        for _ in 0..40 {
            let p = Vec3::new(
                rng.random_range(-1.0..5.0),
                rng.random_range(-1.0..5.0),
                rng.random_range(-1.0..5.0),
            );
            let normal = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            let Ok(query) = Query::new(p, normal) else {
                continue;
            };
            let surface = query.surface();
            let (pd, nd) = (surface.point, surface.normal);
            let lit: Vec<bool> = tree
                .lights()
                .iter()
                .zip(&emissions)
                .map(|(l, e)| {
                    let f =
                        lambert.eval(&(), surface, l.position.as_dvec3(), l.intensity.as_dvec3());
                    f.max_element() > 0.0 && e.factor(l.position, p) > 0.0
                })
                .collect();
            for (i, light) in tree.lights().iter().enumerate() {
                if lit[i] {
                    checked += 1;
                    assert!(
                        pbrt_importance(&pbrt.lights[i], pd, nd) > 0.0,
                        "pbrt light {i}"
                    );
                    let (max, _) = cycles_light_importance(light, &cycles.lights[i], pd, nd);
                    assert!(max > 0.0, "Cycles light {i}");
                }
            }
            for (index, node) in tree.nodes().iter().enumerate() {
                if lit[node.lights()].iter().any(|&l| l) {
                    assert!(
                        pbrt_importance(&pbrt.nodes[index], pd, nd) > 0.0,
                        "pbrt node {index}"
                    );
                }
            }
        }
        assert!(checked > 1000, "{checked} lit lights");
    }
}
