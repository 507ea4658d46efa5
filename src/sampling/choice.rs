//! One step of the descent: the probability of each child of a node, or of
//! each light of a leaf, at one shading point.
//!
//! Sampling and the probability of a given light call the very same
//! functions here, in the same order, so both see the same bits: a child's
//! probability is computed once per step from the importances of all its
//! siblings ([`Step`]), and a leaf light's from the exact contributions of
//! the leaf's lights ([`leaf_spread`], [`Spread::share`]).

use glam::{DVec3, Vec3};

use crate::cut::emitted;
use crate::geometry::{Cone, Surface};
use crate::shader::{ChildrenOf, NodeEstimate, SUM_LIGHTS_MAX, Seal, Shader};
use crate::tree::{LightTree, MAX_CHILDREN, Node};

/// Share of every choice spread evenly over the candidates that may be lit
/// (defensive mixing, Hesterberg 1995): each such child or light gets at
/// least `DEFENSIVE_SHARE / k` of the choice among its `k` candidates,
/// whatever the importances, so no lit light's probability can round to 0
/// and a poor importance costs at most a factor `1 / (1 - DEFENSIVE_SHARE)`
/// of the second moment per level. `2^-8`: the loss (at most about 0.4% a
/// level) stays below the run-to-run noise of the report's variances, and
/// a level's smallest share, `(1 - NEAR_SHARE) 2^-8 / 8` (about
/// `2^-11.1`), keeps the product of up to 90 levels and a light's share of
/// a leaf of up to 32 above `f64::MIN_POSITIVE`.
pub(crate) const DEFENSIVE_SHARE: f64 = 1.0 / 256.0;

/// How wide a child's certified interval may be for its estimate to serve
/// as its importance: `upper <= TIGHT_RATIO * lower` (channels summed).
/// Within such an interval the estimate is within a factor `TIGHT_RATIO` of
/// the exact value either way (both lie in it). A wider interval (a node
/// near the point or straddling its tangent plane, where the lower bound
/// is often 0) says little of where the value lies: its midpoint can be
/// hundreds of times the exact value. Such a child gets the geometric
/// importance ([`geometric`]) clamped into its interval instead. 2 is the
/// measured choice: on the sphere of lights seen from orbit, ratios 2 and 4
/// gave one-sample relative variances of about 0.07 and 0.12 (the
/// geometric importance does better than the estimate already between
/// them), on the street city the same to 2%; `cargo run --release -p
/// manylights-report -- sampling` prints the variances, `docs/tuning.md`
/// records the choice.
pub(crate) const TIGHT_RATIO: f64 = 2.0;

/// The geometric importance's distance is clamped below at `R / NEAR_DIVISOR`
/// (`R` the node's radius), as pbrt-v4's `LightBounds::Importance` clamps
/// it to the node's size. A ball of lights that reaches the point
/// contributes about `I / R^2` times the mean of `R^2 / r^2` over its
/// lights, which is 3 for lights filling the ball evenly around the point,
/// and grows without bound for lights along lines or planes through it
/// (street lamps, windows of a facade): a clamp at `R` starves such nodes.
/// 4 (a factor 16 on `I / R^2`) is the measured choice: on the street city,
/// clamping at `R`, `R / 2`, `R / 4` and `R / 8` gave one-sample relative
/// variances of about 10, 2.2, 1.9 and 1.9 (`docs/tuning.md`).
pub(crate) const NEAR_DIVISOR: f64 = 4.0;

/// Share of a choice among children spread evenly over those whose ball
/// reaches the point and that are not leaves ([`Kind::Near`]): they have
/// no bound, and their geometric importance, taken about the centroid,
/// can be off by orders of magnitude either way, since what they give is
/// often carried by the few lights nearest the point (a point on the floor
/// a few centimetres from virtual lights at the foot of a wall). Each such
/// child gets at least `NEAR_SHARE / m` of the choice among its `m` near
/// siblings, at a cost of at most a factor `1 / (1 - NEAR_SHARE)` of the
/// second moment at each level where one is present. 1/16 is the measured
/// choice: on the VPL room at 10^5 virtual lights, shares 0, 1/16, 1/8 and
/// 1/4 gave mean relative variances of 6.1, 2.9, 2.8 and 2.9, while the
/// street city and the sphere of lights lost 2% at 1/16 and 4-5% at 1/8
/// (`cargo run --release -p manylights-report -- sampling`,
/// `docs/tuning.md`).
pub(crate) const NEAR_SHARE: f64 = 1.0 / 16.0;

/// The largest `f64` below 1: where a stretched `u` is clamped.
pub(crate) const ONE_BELOW: f64 = 1.0 - f64::EPSILON / 2.0;

/// The most leaf lights whose contributions a step keeps on the stack; a
/// larger leaf (coincident lights, or a leaf at the tree's depth limit) is
/// evaluated again in each pass, which gives the same values.
const LEAF_BUFFER: usize = 64;

/// The shading point as the descent reads it.
pub(crate) struct At<'a, S: Shader> {
    pub(crate) tree: &'a LightTree,
    pub(crate) shader: &'a S,
    pub(crate) per_point: S::PerPoint,
    pub(crate) surface: &'a Surface,
    /// The shader's [`horizon`](Shader::horizon) at the point.
    pub(crate) horizon: Option<Vec3>,
}

impl<'a, S: Shader> At<'a, S> {
    /// The point of `surface` for `shader` over `tree`.
    #[inline(always)]
    pub(crate) fn new(tree: &'a LightTree, shader: &'a S, surface: &'a Surface) -> Self {
        Self {
            tree,
            shader,
            per_point: shader.prepare(surface),
            surface,
            horizon: shader.horizon(surface),
        }
    }
}

/// What a child is known to contribute before the weights are set.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// Certified to contribute exactly 0: no intensity, every light at or
    /// below the horizon plane, a certified upper bound of 0, or a single
    /// light whose exact term is 0.
    Dark,
    /// An exact term, or the estimate of a tight certified interval
    /// ([`TIGHT_RATIO`]): the importance itself (channels summed, positive,
    /// possibly infinite), and the scale of the geometric importance.
    Known(f64),
    /// A wide certified interval `[lower, upper]` (channels summed, `upper
    /// > 0`): the geometric importance clamped into it.
    Loose(f64, f64),
    /// No finite bound: the child's ball reaches the point (or its bound
    /// came out NaN), and it is not a leaf (a leaf's lights are then summed
    /// exactly instead). It gets the geometric importance (see
    /// [`Step::of`]).
    Near,
    /// To be bounded.
    Wanted,
}

/// The channels of `v` summed: the scalar every importance is measured in.
#[inline(always)]
pub(crate) fn scalar(v: DVec3) -> f64 {
    v.x + v.y + v.z
}

/// The kind of an exact term (channels summed): dark unless positive; NaN
/// (which only a shader outside the crate can give) counts as dark.
#[inline(always)]
fn exact(value: f64) -> Kind {
    if value > 0.0 {
        Kind::Known(value)
    } else {
        Kind::Dark
    }
}

/// The kind of a bounded child (channels summed): dark when the certified
/// upper bound is 0 in every channel; its estimate when the interval is
/// tight (`upper <= TIGHT_RATIO lower`, [`TIGHT_RATIO`]); [`Kind::Loose`]
/// otherwise; [`Kind::Near`] for a bound with a NaN.
#[inline(always)]
fn bounded(bound: &NodeEstimate) -> Kind {
    let upper = scalar(bound.upper);
    let lower = scalar(bound.lower).max(0.0);
    let estimate = scalar(bound.estimate);
    if upper.is_nan() || estimate.is_nan() || lower.is_nan() {
        return Kind::Near;
    }
    if bound.upper.max_element() <= 0.0 {
        return Kind::Dark;
    }
    if upper <= TIGHT_RATIO * lower {
        // The estimate clamped into the interval (a shader's estimate
        // should lie in it already). A positive upper bound whose
        // importance underflows still may be lit: the smallest positive
        // number keeps it a candidate.
        Kind::Known(estimate.max(lower).min(upper).max(f64::MIN_POSITIVE))
    } else {
        Kind::Loose(lower.min(upper), upper)
    }
}

/// What needs no bound of node `index`: dark nodes, nodes whose lights lie
/// in one plane at or below the horizon, single (or coincident) lights,
/// evaluated exactly; the rest is [`Kind::Wanted`].
#[inline(always)]
fn admit<S: Shader>(at: &At<'_, S>, index: usize) -> Kind {
    let node = &at.tree.nodes[index];
    if node.intensity == DVec3::ZERO {
        return Kind::Dark;
    }
    if let (Some(horizon), Some(plane)) = (at.horizon, at.tree.node_plane(index))
        && at.tree.plane_at_or_below(plane, at.surface.point, horizon)
    {
        return Kind::Dark;
    }
    if node.radius == 0.0 && at.tree.is_oriented() {
        // Coincident emitters: their profiles may differ.
        let mut sum = 0.0;
        each_light(at, node.lights(), |_, value| sum += value);
        return exact(sum);
    }
    if node.radius == 0.0 {
        // Coincident lights (or one): one light of the summed intensity at
        // the centroid, as the cut takes them.
        let value = at.shader.eval(
            &at.per_point,
            at.surface,
            node.centroid.as_dvec3(),
            node.intensity,
        );
        return exact(scalar(value));
    }
    Kind::Wanted
}

/// Whether the descent starting at node `index` finds nothing: the node is
/// certified to contribute 0 (see [`Kind::Dark`]).
#[inline(always)]
pub(crate) fn start_is_dark<S: Shader>(at: &At<'_, S>, index: usize) -> bool {
    match admit(at, index) {
        Kind::Dark => true,
        Kind::Wanted => {
            let node = &at.tree.nodes[index];
            node.cone(at.surface.point).is_some_and(|cone| {
                let bound = at.shader.bound(&at.per_point, at.surface, node, &cone);
                let bound = emitted(bound, at.tree.factor(index, &cone));
                bounded(&bound) == Kind::Dark
            })
        }
        Kind::Known(_) | Kind::Loose(..) | Kind::Near => false,
    }
}

/// The geometric importance of a node, after pbrt-v4's
/// `LightBounds::Importance` for isotropic emitters with a softer cosine:
/// `I c / max(D^2, (R / NEAR_DIVISOR)^2)`, with `I` the intensity's
/// channels summed, `D` the distance from the point to the centroid, `R`
/// the radius, and `c` the mean clamped cosine [`soft_cosine`] of the
/// node's lights against the shader's horizon vector (1 when the shader
/// has no horizon; where the ball reaches the point, the same mean cosine
/// over the clamped distance, at least [`NEAR_COSINE_FLOOR`]). It is what
/// the node would give through a constant BRDF; `Step::of` scales it by
/// the shader's measured ratio.
#[inline(always)]
fn geometric(node: &Node, point: DVec3, horizon: Option<DVec3>) -> f64 {
    let radius = f64::from(node.radius);
    let offset = node.centroid.as_dvec3() - point;
    let d2 = offset.length_squared();
    let clamp = radius / NEAR_DIVISOR;
    let floor = d2.max(clamp * clamp);
    if !(floor > 0.0) {
        return 0.0;
    }
    let cosine = match horizon {
        Some(axis) if d2 > radius * radius => soft_cosine(node, offset, d2, axis),
        Some(axis) => soft_cosine(node, offset, floor, axis).max(NEAR_COSINE_FLOOR),
        _ => 1.0,
    };
    let g = scalar(node.intensity) * cosine / floor;
    if g.is_finite() { g } else { 0.0 }
}

/// The least cosine [`geometric`] gives a node whose ball reaches the
/// point: there the modelled heights say little about lights that
/// surround the point, and a cosine of 0 starves nodes that carry much of
/// the light (with no floor the mean one-sample variance rose 13-fold on
/// the street city). A cosine of 1 there instead gives a flat node around
/// the point, in its tangent plane (virtual lights on a ceiling, seen from
/// the ceiling), far more than it is worth. `cargo run --release -p
/// manylights-report -- sampling` measures it (`docs/tuning.md`).
const NEAR_COSINE_FLOOR: f64 = 0.25;

/// `sqrt(3)`: the half-width of the uniform distribution of unit variance.
const UNIFORM_HALF_WIDTH: f64 = 1.732_050_807_568_877_2;

/// The mean clamped cosine `max(0, a . (x - p)) / D` of a node's lights
/// seen from outside its ball (`offset = c - p`, `d2 = D^2`, `a` the unit
/// horizon vector), the distances taken as `D`: the heights `a . (x - c)`
/// of the lights above the centroid's are modelled as uniform on `[-w,
/// w]`, `w = sqrt(3) sigma` of the same variance `sigma^2 = a^T S a` (the
/// node's second moments `S` about the centroid, intensity-weighted over
/// the channels), at most `R`. With `h = a . offset` the mean of `max(0, h
/// + u)` is then `h` for `h >= w`, 0 for `h <= -w`, and `(h + w)^2 / (4 w)`
/// between: a node straddling the tangent plane gets the part of it above
/// the plane, where pbrt-v4's cone widening gives the whole node the
/// cosine of its nearest edge. On the sphere of lights seen from orbit
/// this cut the one-sample variance about four times (`docs/tuning.md`).
#[inline(always)]
fn soft_cosine(node: &Node, offset: DVec3, d2: f64, axis: DVec3) -> f64 {
    let height = axis.dot(offset);
    let quadratic = |m: &[f32; 6]| {
        let [xx, yy, zz, xy, xz, yz] = m.map(f64::from);
        axis.x * axis.x * xx
            + axis.y * axis.y * yy
            + axis.z * axis.z * zz
            + 2.0 * (axis.x * axis.y * xy + axis.x * axis.z * xz + axis.y * axis.z * yz)
    };
    let [s0, s1, s2] = &node.channel_covariances;
    let i = node.intensity;
    let total = scalar(i);
    let variance = if total > 0.0 {
        (i.x * quadratic(s0) + i.y * quadratic(s1) + i.z * quadratic(s2)) / total
    } else {
        0.0
    };
    let width = (UNIFORM_HALF_WIDTH * variance.max(0.0).sqrt()).min(f64::from(node.radius));
    let mean = if height >= width {
        height
    } else if height <= -width {
        0.0
    } else {
        (height + width) * (height + width) / (4.0 * width)
    };
    (mean / d2.sqrt()).clamp(0.0, 1.0)
}

/// The spread of one choice: how many candidates may be lit, and the
/// normalisation of their importances. Computed once per choice and read by
/// [`share`](Self::share) for each candidate, in sampling and for a given
/// light's probability alike.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Spread {
    /// Candidates that may be lit (`k`).
    lit: u32,
    /// The largest importance of a candidate that may be lit; after
    /// [`normalise`](Self::normalise), 0 when it is 0 or infinite. The
    /// importances are divided by it rather than multiplied by its inverse:
    /// a subnormal largest importance (a glossy lobe's far tail) has no
    /// finite inverse, and `q / max` stays in `[0, 1]` for every finite `q`.
    max: f64,
    /// Whether some importance is `+inf` (those then share the weighted part
    /// of the choice).
    infinite: bool,
    /// The sum of the normalised importances.
    total: f64,
}

impl Spread {
    /// An empty spread, to be fed every candidate twice: first with
    /// [`count`](Self::count), then with [`add`](Self::add), in the same
    /// order.
    #[inline(always)]
    fn new() -> Self {
        Self {
            lit: 0,
            max: 0.0,
            infinite: false,
            total: 0.0,
        }
    }

    /// First pass: a candidate of `importance` (non-negative or `+inf`)
    /// that may be lit if `may`.
    #[inline(always)]
    fn count(&mut self, importance: f64, may: bool) {
        if may {
            self.lit += 1;
            self.max = self.max.max(importance);
        }
    }

    /// Between the passes: whether the largest importance is infinite (it
    /// is then set to 0, and the infinite ones share the weighted part).
    #[inline(always)]
    fn normalise(&mut self) {
        self.infinite = self.max == f64::INFINITY;
        if !(self.max > 0.0) || self.infinite {
            self.max = 0.0;
        }
    }

    /// Second pass: the same candidate again, its normalised importance
    /// added to the total.
    #[inline(always)]
    fn add(&mut self, importance: f64, may: bool) {
        if may {
            self.total += self.normalised(importance);
        }
    }

    /// An importance divided by the largest (1 for an infinite one among
    /// infinite ones, 0 for the others then).
    #[inline(always)]
    fn normalised(&self, importance: f64) -> f64 {
        if self.infinite {
            f64::from(u8::from(importance == f64::INFINITY))
        } else if self.max > 0.0 {
            importance / self.max
        } else {
            0.0
        }
    }

    /// The probability of a candidate of `importance` that may be lit (`may`):
    /// `(1 - DEFENSIVE_SHARE) q / Q + DEFENSIVE_SHARE / k` with `q` its
    /// normalised importance and `Q` their sum, or `1 / k` when every
    /// importance is 0; 0 for a candidate that is not lit.
    #[inline(always)]
    pub(crate) fn share(&self, importance: f64, may: bool) -> f64 {
        if !may || self.lit == 0 {
            return 0.0;
        }
        let k = f64::from(self.lit);
        if self.total > 0.0 {
            (1.0 - DEFENSIVE_SHARE) * (self.normalised(importance) / self.total)
                + DEFENSIVE_SHARE / k
        } else {
            1.0 / k
        }
    }
}

/// The probabilities of the children of one node.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Step {
    /// Number of children.
    pub(crate) len: usize,
    /// Each child's probability, in the order of the node array.
    pub(crate) p: [f64; MAX_CHILDREN],
}

/// A cone for the unused slots of a batch of cones.
const NO_CONE: Cone = Cone {
    offset: DVec3::ZERO,
    distance: 0.0,
    inv_distance: 0.0,
    axis: DVec3::ZERO,
    radius: 0.0,
    sin_half_angle: 0.0,
    cos_half_angle: 0.0,
};

impl Step {
    /// The children of node `parent` (not a leaf) at the point `at`.
    ///
    /// Each child is weighed by its importance: 0 when it is dark; its
    /// exact term for a single light; its estimate when its certified
    /// interval is tight ([`TIGHT_RATIO`]); its lights' exact terms summed
    /// for a leaf whose ball reaches the point. The others, a wide interval
    /// or no bound (the ball reaches the point), get `kappa g` with `g` the
    /// [`geometric`] importance, clamped into the certified interval where
    /// there is one; `kappa` is the largest ratio of importance to `g`
    /// among the single or tightly bounded siblings (how much the shader
    /// gives per unit of `g` where that is known; 1 when no sibling tells,
    /// the children then being weighed by `g` and their intervals alone).
    /// Then [`Spread::share`] sets the probabilities.
    ///
    /// When no child may be lit (every one certified dark though the parent
    /// was not: the bounds are conservative), the choice falls back to the
    /// children of non-zero intensity, evenly: the sample then contributes
    /// 0, and the probabilities still sum to 1.
    #[inline(always)]
    pub(crate) fn of<S: Shader>(at: &At<'_, S>, parent: usize) -> Self {
        let tree = at.tree;
        let node = &tree.nodes[parent];
        let first = node.first_child as usize;
        let len = (node.child_count as usize).min(MAX_CHILDREN);
        let mut kind = [Kind::Dark; MAX_CHILDREN];
        let mut wanted = 0u8;
        for (i, k) in kind.iter_mut().enumerate().take(len) {
            *k = admit(at, first + i);
            if *k == Kind::Wanted {
                wanted |= 1 << i;
            }
        }
        // Each bounded child's emission factor estimate (1 for isotropic
        // lights and for children not bounded under a cone).
        let mut emission = [1.0f64; MAX_CHILDREN];
        if wanted != 0 {
            bound_wanted(at, parent, first, wanted, &mut kind, &mut emission);
        }
        // The geometric importance's scale: the largest importance per
        // unit of it among the single or tightly bounded children (before
        // the near leaves' exact sums join them: an exact sum near the point
        // is no measure of the shader's scale).
        let point = at.surface.point;
        let horizon = at
            .horizon
            .map(|h| h.as_dvec3().normalize_or_zero())
            .filter(|h| *h != DVec3::ZERO);
        let mut g = [0.0f64; MAX_CHILDREN];
        let mut kappa = 0.0f64;
        for (i, k) in kind.iter().enumerate().take(len) {
            match *k {
                Kind::Known(importance) => {
                    g[i] = geometric(&tree.nodes[first + i], point, horizon) * emission[i];
                    let ratio = importance / g[i];
                    if g[i] > 0.0 && ratio.is_finite() {
                        kappa = kappa.max(ratio);
                    }
                }
                Kind::Loose(..) | Kind::Near => {
                    g[i] = geometric(&tree.nodes[first + i], point, horizon) * emission[i];
                }
                Kind::Dark | Kind::Wanted => {}
            }
        }
        let scale = if kappa > 0.0 { kappa } else { 1.0 };
        for (i, k) in kind.iter_mut().enumerate().take(len) {
            if *k == Kind::Near && tree.nodes[first + i].is_leaf() {
                *k = near_leaf(at, first + i);
            }
        }
        let mut importance = [0.0f64; MAX_CHILDREN];
        let mut may = [false; MAX_CHILDREN];
        for i in 0..len {
            (importance[i], may[i]) = match kind[i] {
                Kind::Known(v) => (v, true),
                // A positive upper bound whose importance underflows still
                // may be lit: the smallest positive number keeps it a
                // candidate. (`max` ignores a NaN product.)
                Kind::Loose(lower, upper) => (
                    (scale * g[i]).max(lower).min(upper).max(f64::MIN_POSITIVE),
                    true,
                ),
                Kind::Near => (scale * g[i], true),
                Kind::Dark | Kind::Wanted => (0.0, false),
            };
        }
        if !may[..len].iter().any(|&m| m) {
            // A dead end: every child certified dark.
            for (m, child) in may[..len].iter_mut().zip(&tree.nodes[first..]) {
                *m = child.intensity != DVec3::ZERO;
            }
        }
        let mut spread = Spread::new();
        for i in 0..len {
            spread.count(importance[i], may[i]);
        }
        spread.normalise();
        for i in 0..len {
            spread.add(importance[i], may[i]);
        }
        let mut p = [0.0; MAX_CHILDREN];
        for i in 0..len {
            p[i] = spread.share(importance[i], may[i]);
        }
        // The near children's even share (they may all be lit: no bound
        // says otherwise).
        let near = kind[..len].iter().filter(|k| **k == Kind::Near).count();
        if near > 0 {
            let even = NEAR_SHARE / near as f64;
            for (pi, k) in p.iter_mut().zip(&kind).take(len) {
                *pi = (1.0 - NEAR_SHARE) * *pi + if *k == Kind::Near { even } else { 0.0 };
            }
        }
        Self { len, p }
    }
}

/// Bounds the children of `parent` whose bits are set in `wanted`
/// (`first` its first child), setting their kinds: together and coarsely
/// where the shader can ([`Shader::bound_children_coarse`]), else under
/// their cones ([`Shader::bound_nodes`]); a child with no cone is
/// [`Kind::Near`]. For emitters, each child also gets an estimate of its
/// emission towards the point in `emission` ([`soft_emission`]; under the
/// child's cone, clamped into the range [`LightTree::factor`] certifies),
/// which scales its geometric importance:
/// a node of lights aimed away from the point is worth less than its
/// intensity says, as pbrt-v4's importance weighs a node by the cosine of
/// its emission cone. (Virtual lights on a ceiling, facing down, seen
/// from a point on the ceiling among them: their emission towards it is
/// about 0, and so is what they give.)
#[inline(always)]
fn bound_wanted<S: Shader>(
    at: &At<'_, S>,
    parent: usize,
    first: usize,
    wanted: u8,
    kind: &mut [Kind; MAX_CHILDREN],
    emission: &mut [f64; MAX_CHILDREN],
) {
    let tree = at.tree;
    let bits = (0..MAX_CHILDREN).filter(|i| wanted & (1 << i) != 0);
    let mut coarse = [None; MAX_CHILDREN];
    let children = ChildrenOf {
        tree,
        parent,
        wanted,
    };
    if !tree.is_oriented()
        && at
            .shader
            .bound_children_coarse(Seal, &at.per_point, at.surface, children, &mut coarse)
    {
        for i in bits {
            kind[i] = match &coarse[i] {
                Some(bound) => bounded(bound),
                None => Kind::Near,
            };
        }
        return;
    }
    let mut slots = [0usize; MAX_CHILDREN];
    let mut cones = [NO_CONE; MAX_CHILDREN];
    let mut nodes: [&Node; MAX_CHILDREN] = [&tree.nodes[first]; MAX_CHILDREN];
    let mut len = 0;
    for i in bits {
        let node = &tree.nodes[first + i];
        match node.cone(at.surface.point) {
            Some(cone) => {
                (slots[len], cones[len], nodes[len]) = (i, cone, node);
                len += 1;
            }
            None => {
                kind[i] = Kind::Near;
                emission[i] = soft_emission(at, first + i, None);
            }
        }
    }
    let mut bounds = [NodeEstimate::ZERO; MAX_CHILDREN];
    at.shader.bound_nodes(
        &at.per_point,
        at.surface,
        &nodes[..len],
        &cones[..len],
        &mut bounds[..len],
    );
    for (k, (slot, bound)) in slots[..len].iter().zip(&bounds[..len]).enumerate() {
        let factor = tree.factor(first + *slot, &cones[k]);
        emission[*slot] = soft_emission(at, first + *slot, Some((factor.lower, factor.upper)));
        kind[*slot] = bounded(&emitted(*bound, factor));
    }
}

/// An estimate of node `index`'s emission towards the point, which scales
/// its geometric importance: its members' profile at a *soft* cosine, the
/// mean of `max(0, w . (p - x)) / D` over its members `x`, with `w` the
/// node's mean axis, their heights along `w` modelled as uniform with the
/// variance of the node's second moments (as [`soft_cosine`] models the
/// heights above the tangent plane), and `D` the distance from the
/// centroid (clamped as [`geometric`] clamps it). The profile at the
/// direction from the centroid alone gives 0 to a node whose centroid
/// lies behind the point's plane across `w` though some of its members lie
/// in front of it (virtual lights on a wall seen from a point just off
/// that wall, beside a cabinet's face), and the descent then starves the
/// node that holds the point's nearest lights. `within`: the certified
/// range of the members' profile from the point, where the node is
/// bounded under a cone; the estimate is clamped into it.
#[inline(always)]
fn soft_emission<S: Shader>(at: &At<'_, S>, index: usize, within: Option<(f64, f64)>) -> f64 {
    let tree = at.tree;
    let Some(cone) = tree.node_cone(index) else {
        return 1.0;
    };
    let (axis, two_sided) = cone.mean_axis();
    let estimate = if cone.is_isotropic() {
        1.0
    } else if axis == DVec3::ZERO {
        cone.estimate_at(0.0)
    } else {
        let node = &tree.nodes[index];
        let offset = node.centroid.as_dvec3() - at.surface.point;
        let clamp = f64::from(node.radius) / NEAR_DIVISOR;
        let d2 = offset.length_squared().max(clamp * clamp);
        if !(d2 > 0.0) {
            return cone.estimate_at(1.0);
        }
        let front = soft_cosine(node, offset, d2, -axis);
        let cosine = if two_sided {
            (front + soft_cosine(node, offset, d2, axis)).min(1.0)
        } else {
            front
        };
        cone.estimate_at(cosine)
    };
    match within {
        Some((lower, upper)) => estimate.max(lower).min(upper),
        None => estimate,
    }
}

/// A leaf child with no bound (its ball reaches the point): its lights'
/// exact terms summed, which is its exact contribution, so it is dark
/// exactly when every light of it is. Leaves hold few lights (32 with the
/// default builder) and only those near the point lack a bound.
#[inline(always)]
fn near_leaf<S: Shader>(at: &At<'_, S>, index: usize) -> Kind {
    let mut sum = 0.0;
    each_light(at, at.tree.nodes[index].lights(), |_, value| {
        sum += sanitised(value)
    });
    exact(sum)
}

/// The exact contributions (channels summed) of the lights of `range`
/// (leaf order), each passed to `f` with its index in leaf order, a chunk
/// of [`SUM_LIGHTS_MAX`] at a time ([`Shader::eval_lights`]).
#[inline(always)]
fn each_light<S: Shader>(
    at: &At<'_, S>,
    range: core::ops::Range<usize>,
    mut f: impl FnMut(usize, f64),
) {
    let mut values = [DVec3::ZERO; SUM_LIGHTS_MAX];
    let mut index = range.start;
    let tree = at.tree;
    for lights in tree.lights[range].chunks(SUM_LIGHTS_MAX) {
        let values = &mut values[..lights.len()];
        at.shader
            .eval_lights(&at.per_point, at.surface, lights, values);
        for (light, value) in lights.iter().zip(values.iter()) {
            let value = if tree.is_oriented() {
                *value * tree.profile(index).factor(light.position, at.surface.point)
            } else {
                *value
            };
            f(index, scalar(value));
            index += 1;
        }
    }
}

/// Whether a leaf light of exact contribution `value` may be chosen, in a
/// leaf where `any` light contributes: every light that contributes, or
/// every light when none does (a dead end).
#[inline(always)]
fn leaf_may(value: f64, any: bool) -> bool {
    !any || value > 0.0
}

/// The spread of a leaf's choice over its lights `range`: in proportion to
/// their exact contributions, with the defensive share ([`Spread::share`]);
/// when no light contributes, evenly. Also whether any contributes, and
/// the contributions themselves where they fit on the stack.
#[inline(always)]
fn leaf_spread<S: Shader>(
    at: &At<'_, S>,
    range: core::ops::Range<usize>,
    buffer: &mut [f64; LEAF_BUFFER],
) -> (Spread, bool) {
    let start = range.start;
    let kept = range.len() <= LEAF_BUFFER;
    let mut any = false;
    each_light(at, range.clone(), |i, value| {
        any |= value > 0.0;
        if kept {
            buffer[i - start] = value;
        }
    });
    let mut spread = Spread::new();
    for pass in 0..2 {
        let mut feed = |value: f64| {
            let (importance, may) = (sanitised(value), leaf_may(value, any));
            if pass == 0 {
                spread.count(importance, may);
            } else {
                spread.add(importance, may);
            }
        };
        if kept {
            buffer[..range.len()].iter().for_each(|&v| feed(v));
        } else {
            each_light(at, range.clone(), |_, v| feed(v));
        }
        if pass == 0 {
            spread.normalise();
        }
    }
    (spread, any)
}

/// An exact contribution as an importance: NaN (from a shader outside the
/// crate) as 0.
#[inline(always)]
fn sanitised(value: f64) -> f64 {
    if value > 0.0 { value } else { 0.0 }
}

/// Chooses a light of the leaf lights `range` with `u` in `[0, 1)`: its
/// index in leaf order and its probability.
#[inline(always)]
pub(crate) fn leaf_pick<S: Shader>(
    at: &At<'_, S>,
    range: core::ops::Range<usize>,
    u: f64,
) -> (usize, f64) {
    let mut buffer = [0.0; LEAF_BUFFER];
    let (spread, any) = leaf_spread(at, range.clone(), &mut buffer);
    let mut picker = Picker::new(u);
    if range.len() <= LEAF_BUFFER {
        for (k, &value) in buffer[..range.len()].iter().enumerate() {
            if picker.offer(k, spread.share(sanitised(value), leaf_may(value, any))) {
                break;
            }
        }
    } else {
        let start = range.start;
        each_light(at, range.clone(), |i, value| {
            picker.offer(
                i - start,
                spread.share(sanitised(value), leaf_may(value, any)),
            );
        });
    }
    let (k, p, _) = picker.chosen();
    (range.start + k, p)
}

/// The probability that [`leaf_pick`] chooses light `light` (leaf order,
/// inside `range`).
#[inline(always)]
pub(crate) fn leaf_probability<S: Shader>(
    at: &At<'_, S>,
    range: core::ops::Range<usize>,
    light: usize,
) -> f64 {
    let mut buffer = [0.0; LEAF_BUFFER];
    let (spread, any) = leaf_spread(at, range.clone(), &mut buffer);
    let value = if range.len() <= LEAF_BUFFER {
        buffer[light - range.start]
    } else {
        let mut value = 0.0;
        each_light(at, range, |i, v| {
            if i == light {
                value = v;
            }
        });
        value
    };
    spread.share(sanitised(value), leaf_may(value, any))
}

/// Inversion of the discrete distribution given one probability at a time:
/// the first candidate whose cumulative probability exceeds `u`, and `u`
/// stretched over that candidate's share to `[0, 1)` for the next choice.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Picker {
    u: f64,
    /// The probabilities offered so far, summed.
    below: f64,
    /// The last candidate of positive probability: `(index, probability,
    /// cumulative below it)`.
    last: Option<(usize, f64, f64)>,
    done: bool,
}

impl Picker {
    /// A choice with `u` in `[0, 1)`.
    #[inline(always)]
    pub(crate) fn new(u: f64) -> Self {
        Self {
            u,
            below: 0.0,
            last: None,
            done: false,
        }
    }

    /// Offers candidate `index` of probability `p`: `true` once one is
    /// chosen (further offers are ignored).
    #[inline(always)]
    pub(crate) fn offer(&mut self, index: usize, p: f64) -> bool {
        if self.done {
            return true;
        }
        if p > 0.0 {
            self.last = Some((index, p, self.below));
            if self.u < self.below + p {
                self.done = true;
                return true;
            }
            self.below += p;
        }
        false
    }

    /// The chosen candidate, its probability and the stretched `u`: the last
    /// candidate of positive probability when rounding left `u` past the
    /// sum; `(0, 0, 0)` when no candidate had any.
    #[inline(always)]
    pub(crate) fn chosen(&self) -> (usize, f64, f64) {
        match self.last {
            Some((index, p, below)) => {
                let stretched = ((self.u - below) / p).clamp(0.0, ONE_BELOW);
                (index, p, stretched)
            }
            None => (0, 0.0, 0.0),
        }
    }
}

/// `u` as the descent takes it: clamped into `[0, 1)`, NaN read as 0.
#[inline(always)]
pub(crate) fn clamped(u: f64) -> f64 {
    if u >= 0.0 { u.min(ONE_BELOW) } else { 0.0 }
}

/// Chooses a light below node `start` with `u`: its index in leaf order
/// and the probability of choosing it, `None` when the node is certified
/// dark.
#[inline(always)]
pub(crate) fn descend<S: Shader>(at: &At<'_, S>, start: usize, u: f64) -> Option<(usize, f64)> {
    let tree = at.tree;
    if start >= tree.nodes.len() || start_is_dark(at, start) {
        return None;
    }
    let (mut index, mut p, mut u) = (start, 1.0f64, clamped(u));
    loop {
        let node = &tree.nodes[index];
        if node.is_leaf() {
            let (light, leaf) = leaf_pick(at, node.lights(), u);
            return Some((light, p * leaf));
        }
        let step = Step::of(at, index);
        let mut picker = Picker::new(u);
        for (i, &pi) in step.p[..step.len].iter().enumerate() {
            if picker.offer(i, pi) {
                break;
            }
        }
        let (i, pi, stretched) = picker.chosen();
        if pi == 0.0 {
            // Only a node of no intensity has no child to choose, and the
            // descent never enters one.
            return None;
        }
        p *= pi;
        u = stretched;
        index = node.first_child as usize + i;
    }
}

/// The probability that [`descend`] from node `start` chooses the light
/// `light` (leaf order): the same steps, following the child whose light
/// range holds it.
#[inline(always)]
pub(crate) fn probability<S: Shader>(at: &At<'_, S>, start: usize, light: usize) -> f64 {
    let tree = at.tree;
    let Some(node) = tree.nodes.get(start) else {
        return 0.0;
    };
    if !node.lights().contains(&light) || start_is_dark(at, start) {
        return 0.0;
    }
    let (mut index, mut p) = (start, 1.0f64);
    loop {
        let node = &tree.nodes[index];
        if node.is_leaf() {
            return p * leaf_probability(at, node.lights(), light);
        }
        let step = Step::of(at, index);
        let first = node.first_child as usize;
        let Some(i) = (0..step.len).find(|&i| tree.nodes[first + i].lights().contains(&light))
        else {
            return 0.0;
        };
        if step.p[i] == 0.0 {
            return 0.0;
        }
        p *= step.p[i];
        index = first + i;
    }
}

/// Visits every light below node `start` (leaf order) with the probability
/// that [`descend`] from `start` chooses it: the same steps as
/// [`probability`] takes for each, in one pass over the tree, so each
/// light's probability has the same bits as [`probability`] gives it. A
/// child of probability 0 (certified dark, or below a dark start) passes
/// 0 to each of its lights.
pub(crate) fn each_probability<S: Shader>(
    at: &At<'_, S>,
    start: usize,
    visit: &mut impl FnMut(usize, f64),
) {
    let Some(node) = at.tree.nodes.get(start) else {
        return;
    };
    if start_is_dark(at, start) {
        node.lights().for_each(|light| visit(light, 0.0));
        return;
    }
    walk(at, start, 1.0, visit);
}

/// [`each_probability`] below node `index`, reached with probability `p`.
fn walk<S: Shader>(at: &At<'_, S>, index: usize, p: f64, visit: &mut impl FnMut(usize, f64)) {
    let tree = at.tree;
    let node = &tree.nodes[index];
    if node.is_leaf() {
        let range = node.lights();
        let mut buffer = [0.0; LEAF_BUFFER];
        let (spread, any) = leaf_spread(at, range.clone(), &mut buffer);
        let mut share = |light: usize, value: f64| {
            visit(
                light,
                p * spread.share(sanitised(value), leaf_may(value, any)),
            );
        };
        if range.len() <= LEAF_BUFFER {
            for (k, &value) in buffer[..range.len()].iter().enumerate() {
                share(range.start + k, value);
            }
        } else {
            each_light(at, range, share);
        }
        return;
    }
    let step = Step::of(at, index);
    let first = node.first_child as usize;
    for (i, &pi) in step.p[..step.len].iter().enumerate() {
        if pi == 0.0 {
            tree.nodes[first + i]
                .lights()
                .for_each(|light| visit(light, 0.0));
        } else {
            walk(at, first + i, p * pi, visit);
        }
    }
}
