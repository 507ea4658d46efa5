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

use glam::{DVec3, Vec3};
use manylights::query::WithView;
use manylights::shader::{Node, Shader, Surface};
use manylights::{LightTree, PointLight, Query};
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

/// pbrt-v4's `LightBounds` of an isotropic emitter group: a box, the summed
/// power `phi` (each light's largest channel, the `4 pi` left out: it
/// cancels), the emission cone `cos_o = cos(pi)` about an arbitrary axis
/// and the falloff `cos_e = cos(pi / 2)`.
#[derive(Clone, Copy, Debug)]
struct PbrtBounds {
    min: DVec3,
    max: DVec3,
    phi: f64,
}

/// pbrt-v4's `LightBounds::Importance` for isotropic emitters (its
/// `src/pbrt/lights.cpp`), in `f64`: the squared distance to the box's
/// centre clamped below by half the diagonal's length (a length against a
/// squared length, as written there), the emission angle widened by the
/// box's bounding sphere (`theta_b`, the whole sphere when the point is
/// inside it), and the incidence angle `|n . w_i|` narrowed by `theta_b`.
fn pbrt_importance(b: &PbrtBounds, p: DVec3, n: DVec3) -> f64 {
    // Isotropic emission: theta_o = pi, theta_e = pi / 2.
    let (cos_o, cos_e) = (-1.0f64, 0.0f64);
    let axis = DVec3::Z;
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
    let cos_w = axis.dot(wi);
    let sin_w = safe_sqrt(1.0 - cos_w * cos_w);
    let sin_o = safe_sqrt(1.0 - cos_o * cos_o);
    let cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, cos_o);
    let sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, cos_o);
    let cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
    if cos_p <= cos_e {
        return 0.0;
    }
    let mut importance = b.phi * cos_p / d2;
    let cos_i = wi.dot(n).abs();
    let sin_i = safe_sqrt(1.0 - cos_i * cos_i);
    importance *= cos_sub_clamped(sin_i, cos_i, sin_b, cos_b);
    importance.max(0.0)
}

/// pbrt-v4's `BVHLightSampler` descent on the crate's tree (its
/// `src/pbrt/lightsamplers.h`): at each node a child with probability in
/// proportion to `pbrt_importance` of its bounds (the node's box and
/// summed largest channels), no sample when every child's is 0; in a leaf
/// (pbrt's leaves hold one light each, the crate's up to 32) a light in
/// proportion to its own importance as a point (`phi |cos| / d^2`).
pub struct PbrtPick<'t> {
    tree: &'t LightTree,
}

impl<'t> PbrtPick<'t> {
    /// The sampler over `tree`.
    pub fn new(tree: &'t LightTree) -> Self {
        Self { tree }
    }
}

/// A node's pbrt bounds.
fn node_bounds(node: &Node) -> PbrtBounds {
    let b = node.aabb();
    PbrtBounds {
        min: b.min.as_dvec3(),
        max: b.max.as_dvec3(),
        phi: node.weight(),
    }
}

/// Descends `tree` choosing children by `weigh` (the probabilities of a
/// node's children, written into the slice; `false` for no sample) and a
/// leaf's lights by `leaf` (likewise), reusing `u`.
fn descend_tree(
    tree: &LightTree,
    mut u: f64,
    mut weigh: impl FnMut(&[Node], &mut [f64]) -> bool,
    mut leaf: impl FnMut(&[PointLight], &mut [f64]) -> bool,
) -> Option<(usize, f64)> {
    let nodes = tree.nodes();
    let mut node = nodes.first()?;
    let mut pdf = 1.0;
    let mut p = [0.0; 64];
    while !node.is_leaf() {
        let children = node.children();
        let probabilities = &mut p[..children.len()];
        if !weigh(&nodes[children.clone()], probabilities) {
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
    if !leaf(lights, probabilities) {
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

impl OneSample for PbrtPick<'_> {
    fn pick(&self, query: &Query<WithView>, u: f64) -> Option<(usize, f64)> {
        let (p, n) = (query.surface().point, query.surface().normal);
        descend_tree(
            self.tree,
            u,
            |children, out| {
                for (w, child) in out.iter_mut().zip(children) {
                    *w = pbrt_importance(&node_bounds(child), p, n);
                }
                normalise(out)
            },
            |lights, out| {
                for (w, light) in out.iter_mut().zip(lights) {
                    let x = light.position.as_dvec3();
                    let b = PbrtBounds {
                        min: x,
                        max: x,
                        phi: f64::from(light.weight()),
                    };
                    *w = pbrt_importance(&b, p, n);
                }
                normalise(out)
            },
        )
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

/// Cycles' `light_tree_importance` for isotropic point emitters
/// (`theta_o = pi`, `theta_e = pi / 2`; its `kernel/light/tree.h`) at a
/// surface without transmission: `(max, min)` importances. For a group of
/// such emitters the outgoing term is 1 and the minimum importance 0 (the
/// emission cone is wider than `theta_e`); for a single point emitter
/// (`theta_o = 0` about the direction to the point) both are `E cos_i /
/// d^2`.
fn cycles_importance(
    n: DVec3,
    to_centre: DVec3,
    cos_u: f64,
    distance: f64,
    energy: f64,
    single: bool,
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
    let d2 = distance * distance;
    let max = (cos_min_incidence * energy / d2).abs();
    let min = if single {
        (cos_max_incidence * energy / d2).abs()
    } else {
        0.0
    };
    (max, min)
}

/// Cycles' light tree descent on the crate's tree: each child chosen with
/// probability `0.5 (p_max + p_min)`, `p_max` in proportion to its
/// maximum importance and `p_min` to its minimum (evenly over the children
/// of positive maximum importance when every minimum is 0, as for groups of
/// point lights); a node's distance clamped below by half its box's half
/// diagonal; a node whose box lies behind the tangent plane has
/// importance 0. In a leaf, its lights likewise as single emitters.
pub struct CyclesPick<'t> {
    tree: &'t LightTree,
}

impl<'t> CyclesPick<'t> {
    /// The sampler over `tree`.
    pub fn new(tree: &'t LightTree) -> Self {
        Self { tree }
    }
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

impl OneSample for CyclesPick<'_> {
    fn pick(&self, query: &Query<WithView>, u: f64) -> Option<(usize, f64)> {
        let (p, n) = (query.surface().point, query.surface().normal);
        let mut min = [0.0f64; 64];
        let mut lows_kept = [0.0f64; 64];
        descend_tree(
            self.tree,
            u,
            |children, out| {
                for ((w, lo), child) in out.iter_mut().zip(min.iter_mut()).zip(children) {
                    let b = child.aabb();
                    let (bmin, bmax) = (b.min.as_dvec3(), b.max.as_dvec3());
                    let centre = 0.5 * (bmin + bmax);
                    let extent = bmax - centre;
                    // Behind the tangent plane: importance 0.
                    if n.dot(centre - p) + n.abs().dot(extent.abs()) <= 0.0 {
                        (*w, *lo) = (0.0, 0.0);
                        continue;
                    }
                    let distance = (centre - p).length();
                    let to_centre = (centre - p) / distance;
                    let cos_u = cycles_cos_box(bmin, bmax, p, to_centre);
                    let distance = distance.max(0.5 * (centre - bmax).length());
                    let energy = luminance(child.intensity());
                    (*w, *lo) = cycles_importance(n, to_centre, cos_u, distance, energy, false);
                }
                cycles_mix(out, &min[..out.len()])
            },
            |lights, out| {
                let mut spare;
                let lows = if lights.len() <= lows_kept.len() {
                    &mut lows_kept[..lights.len()]
                } else {
                    spare = vec![0.0; lights.len()];
                    &mut spare[..]
                };
                for ((w, lo), light) in out.iter_mut().zip(lows.iter_mut()).zip(lights) {
                    let offset = light.position.as_dvec3() - p;
                    let distance = offset.length();
                    if distance == 0.0 {
                        (*w, *lo) = (0.0, 0.0);
                        continue;
                    }
                    let energy = luminance(light.intensity.as_dvec3());
                    (*w, *lo) =
                        cycles_importance(n, offset / distance, 1.0, distance, energy, true);
                }
                cycles_mix(out, lows)
            },
        )
    }
}
