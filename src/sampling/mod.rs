//! Light sampling for path tracers from the same tree: one light per
//! shading point with its exact probability ([`LightSampler`]), and an
//! unbiased estimate of the whole sum from a certified cut with one light
//! sampled per node ([`Shading::shade_stochastic`](crate::Shading::shade_stochastic)).

mod choice;
mod stochastic;

use crate::shader::Shader;
use crate::shading::{Accepts, Query};
use crate::tree::LightTree;

pub(crate) use choice::At;
pub use stochastic::Stochastic;
pub(crate) use stochastic::{Tally, shade_stochastic};

/// A light chosen by [`LightSampler::sample`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sampled {
    /// The light's index in the caller's slice (the slice the tree was
    /// built from; see [`LightTree::original_index`]).
    pub light: usize,
    /// The probability that [`sample`](LightSampler::sample) returns this
    /// light at this query: the same bits as
    /// [`pmf`](LightSampler::pmf) gives for it.
    pub pmf: f64,
}

/// Chooses one light per shading point for a path tracer, with its
/// probability, by descending the [`LightTree`] (as pbrt-v4's
/// `BVHLightSampler` and Cycles' light tree do), each child chosen in
/// proportion to an importance built from the shader's *certified* bound.
///
/// Create one with [`LightTree::sampler`]; it holds the tree, the shader and
/// the map from the caller's light indices to the tree's order (4 bytes a
/// light), needs no scratch, and is `Send + Sync` when the shader is, so
/// one sampler serves every thread. [`sample`](Self::sample) and
/// [`pmf`](Self::pmf) cost `O(depth)` bounds of a node's children plus the
/// exact terms of one leaf's lights, and allocate nothing.
///
/// # The importance and what it guarantees
///
/// At each node the descent bounds the children at the query
/// ([`Shader::bound`], or the crate's shaders' coarse bounds of children
/// side by side; channels summed) and gives each child an importance that
/// estimates its contribution, the certified bound serving as the zero
/// test and as a clamp:
///
/// ```text
/// dark child (no intensity, lights at or below the horizon plane,
///             certified upper bound 0, a single light whose term is 0)  0
/// single light (or coincident lights)                       its exact term
/// tight interval (upper <= 2 lower)                          its estimate
/// leaf whose ball reaches the point            its lights' terms summed
/// wide interval [lower, upper]      kappa g clamped into [lower, upper]
/// other child whose ball reaches the point (no bound)           kappa g
/// ```
///
/// `g = I c / max(D^2, (R / 4)^2)` is a geometric importance after
/// pbrt-v4's `LightBounds::Importance`: `I` the node's intensity, `D` the
/// distance to its centroid, `R` its radius, `c` the mean clamped cosine
/// of its lights against the shader's horizon vector, their heights above
/// the tangent plane modelled as uniform with the variance of the node's
/// second moments (where the ball reaches the point, over the clamped
/// distance and at least 1/4). Over emitters `g` is also scaled by the
/// node's emission towards the point: its members' profile at the node's
/// mean axis for the mean clamped cosine of the point's height above
/// their emitting planes, modelled as the heights above the tangent plane
/// are, over the distance (the profile at the direction from the centroid
/// alone starves a node whose centroid lies behind the point though its
/// members nearest the point face it). `kappa` is
/// the largest ratio of importance to `g` among the single or tightly
/// bounded siblings (1 when none). The shader's estimate is close to the
/// exact contribution where the interval is tight (far nodes); where it is
/// wide (nodes near the point or straddling its tangent plane, lower bound
/// often 0) its midpoint can be hundreds of times the exact value, and `g`
/// follows the contribution far better, while the clamp keeps it within
/// what is certified. The distance clamp at `R / 4` rather than `R` keeps
/// nodes whose ball reaches the point from being starved: their lights
/// along lines and planes through the point give far more than `I / R^2`.
/// A child is then chosen with probability `(1 - 2^-8) q / Q + 2^-8 / k`,
/// `q` its importance, `Q` the sum over the `k` children that may be lit
/// (defensive mixing: no lit child's share can round to 0, and a poor
/// importance costs at most about 0.4% of the second moment per level);
/// where some children's balls reach the point (and they are not leaves),
/// those `m` children also share `1/16` of the choice evenly: the choice is
/// `(1 - 1/16)` times the above plus `1 / (16 m)` for each of them. Their
/// importance has no bound to lean on, and what they give is often carried
/// by the few lights nearest the point, which no estimate about their
/// centroid sees; the even share keeps such a child's probability at
/// least `1 / (16 m)` however far its importance misses, at a cost of at
/// most 7% of the second moment per level. In
/// a leaf, a light is chosen in proportion to its exact term
/// ([`Shader::eval`], channels summed), mixed the same way over the lights
/// that contribute.
///
/// Guarantees, for a shader whose bounds meet [`NodeEstimate`]'s contract
/// and whose [`horizon`](Shader::horizon) is honest:
///
/// * a child certified dark is never chosen while a sibling may be lit;
/// * every light whose exact term is positive has a positive probability:
///   each of its ancestors may be lit (its bound's upper end is at least
///   that term), so gets at least `(15/16) 2^-8 / 8` of its parent's
///   choice, and the light at least `2^-8 / n` of its leaf's `n`; the
///   product stays above `f64::MIN_POSITIVE` for trees of up to 90 levels
///   and leaves of up to 32 lights (the default builder's trees are far
///   shallower: 8 levels for a million lights of the street city). So the
///   one-sample estimate `f / pmf` is unbiased;
/// * the probabilities of all lights sum to 1 (to rounding, about `1e-15`
///   per level) whenever `sample` returns a light. Bounds are conservative,
///   so a node that may be lit can have children all certified dark (a
///   dead end); its children of non-zero intensity are then chosen evenly,
///   and the sample's term is 0, as it would be for any of them;
/// * `sample` returns `None` only for an empty tree or a root certified
///   dark at the query; every light's `pmf` is then 0.
///
/// [`NodeEstimate`]: crate::shader::NodeEstimate
///
/// # The random number
///
/// `sample` takes one uniform `u` in `[0, 1)` and reuses it down the tree:
/// at each choice, `u` falls in one child's interval of the cumulative
/// probabilities and is stretched back to `[0, 1)` over that interval
/// (`(u - below) / p`), as pbrt-v4's `SampleDiscrete` does. Each choice
/// spends the bits that tell its interval apart: after a light of
/// probability `P` has been reached, what is left of `u` resolves `2^-53 /
/// P`, so for lights down to `P = 2^-40` the last choice still sees steps
/// of `2^-13` of its range. A `u` outside `[0, 1)` is clamped into it and
/// NaN is read as 0 (the descent never panics); pass well-distributed
/// numbers.
///
/// ```
/// use glam::Vec3;
/// use manylights::{Lambert, LightTree, PointLight, Query};
///
/// let lights: Vec<PointLight> = (0..1000)
///     .map(|i| PointLight::new(Vec3::new((i % 40) as f32, (i / 40) as f32, 3.0), Vec3::ONE))
///     .collect();
/// let tree = LightTree::build(&lights)?;
/// let sampler = tree.sampler(Lambert::new(Vec3::splat(0.8)));
/// let query = Query::new(Vec3::new(10.0, 10.0, 0.0), Vec3::Z)?;
/// let sampled = sampler.sample(&query, 0.37).expect("lit");
/// assert_eq!(sampler.pmf(&query, sampled.light).to_bits(), sampled.pmf.to_bits());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct LightSampler<'t, S: Shader> {
    tree: &'t LightTree,
    shader: S,
    /// Per light of the caller's slice, its index in the tree's leaf order.
    leaf_of: Vec<u32>,
}

impl LightTree {
    /// A light sampler for `shader` over this tree (see [`LightSampler`]).
    #[must_use]
    pub fn sampler<S: Shader>(&self, shader: S) -> LightSampler<'_, S> {
        let mut leaf_of = vec![0u32; self.order.len()];
        for (leaf, &original) in self.order.iter().enumerate() {
            leaf_of[original as usize] = leaf as u32;
        }
        LightSampler {
            tree: self,
            shader,
            leaf_of,
        }
    }
}

/// The tree summarised, the shader in full.
impl<S: Shader + core::fmt::Debug> core::fmt::Debug for LightSampler<'_, S> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("LightSampler")
            .field("tree", self.tree)
            .field("shader", &self.shader)
            .finish_non_exhaustive()
    }
}

impl<'t, S: Shader> LightSampler<'t, S> {
    /// The tree.
    #[must_use]
    pub fn tree(&self) -> &'t LightTree {
        self.tree
    }

    /// The shader.
    #[must_use]
    pub fn shader(&self) -> &S {
        &self.shader
    }

    /// Chooses one light for `query` with the uniform number `u` in `[0,
    /// 1)` (see the type's docs for how `u` is used, and its clamp): the
    /// light's index in the caller's slice and the probability of choosing
    /// it, or `None` when the tree is empty or certified dark at the query.
    /// `f / pmf`, with `f` the light's exact term, is an unbiased estimate
    /// of the sum over all lights.
    #[must_use]
    pub fn sample<M>(&self, query: &Query<M>, u: f64) -> Option<Sampled>
    where
        S: Accepts<M>,
    {
        let at = At::new(self.tree, &self.shader, query.surface());
        let (leaf, pmf) = crate::dispatch::with_avx2(
            #[inline(always)]
            || choice::descend(&at, 0, u),
        )?;
        Some(Sampled {
            light: self.tree.original_index(leaf),
            pmf,
        })
    }

    /// The probability that [`sample`](Self::sample) returns `light` (an
    /// index in the caller's slice) at `query`: the same descent, retraced
    /// without a random number, so for the light `sample` returns the same
    /// bits as its [`Sampled::pmf`]. 0 for an index out of range.
    #[must_use]
    pub fn pmf<M>(&self, query: &Query<M>, light: usize) -> f64
    where
        S: Accepts<M>,
    {
        let Some(&leaf) = self.leaf_of.get(light) else {
            return 0.0;
        };
        let at = At::new(self.tree, &self.shader, query.surface());
        crate::dispatch::with_avx2(
            #[inline(always)]
            || choice::probability(&at, 0, leaf as usize),
        )
    }

    /// Every light's probability at `query` in one pass over the tree:
    /// `visit(light, pmf)` once for each light, `light` its index in the
    /// caller's slice (visited in the tree's leaf order, not the slice's),
    /// `pmf` the same bits as [`pmf`](Self::pmf) gives it. Costs the
    /// bounds of every node's children and every light's exact term, once
    /// (`pmf` for each light in turn would cost `O(depth)` each), and
    /// allocates nothing.
    ///
    /// For checking a sampler (the probabilities sum to 1, no lit light has
    /// probability 0) and for the one-sample estimate's exact variance,
    /// `sum_i f_i^2 / pmf_i - F^2` with `F = sum_i f_i`: a variance
    /// measured from samples misses the rare lights whose `f / pmf` is
    /// huge, and so reads low exactly where a sampler is poor.
    ///
    /// ```
    /// use glam::Vec3;
    /// use manylights::{Lambert, LightTree, PointLight, Query};
    ///
    /// let lights: Vec<PointLight> = (0..500)
    ///     .map(|i| PointLight::new(Vec3::new((i % 25) as f32, (i / 25) as f32, 2.0), Vec3::ONE))
    ///     .collect();
    /// let tree = LightTree::build(&lights)?;
    /// let sampler = tree.sampler(Lambert::new(Vec3::splat(0.5)));
    /// let query = Query::new(Vec3::new(3.0, 4.0, 0.0), Vec3::Z)?;
    /// let mut total = 0.0;
    /// sampler.for_each_pmf(&query, |light, pmf| {
    ///     assert_eq!(pmf.to_bits(), sampler.pmf(&query, light).to_bits());
    ///     total += pmf;
    /// });
    /// assert!((total - 1.0).abs() < 1e-12);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn for_each_pmf<M>(&self, query: &Query<M>, mut visit: impl FnMut(usize, f64))
    where
        S: Accepts<M>,
    {
        let at = At::new(self.tree, &self.shader, query.surface());
        let tree = self.tree;
        crate::dispatch::with_avx2(
            #[inline(always)]
            || {
                choice::each_probability(&at, 0, &mut |leaf, pmf| {
                    visit(tree.original_index(leaf), pmf);
                });
            },
        );
    }
}
