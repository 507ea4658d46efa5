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
use manylights::shader::{Node, Shader, Surface};
use manylights::{LightTree, PointLight};
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
